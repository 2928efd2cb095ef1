//! # shared-mem-schema
//!
//! Owns every message that crosses a process boundary in the stack: the 1 kHz
//! hardware state and torque command exchanged with the (simulated) robot,
//! the 1 kHz sensor frame, the 20 Hz policy action, the camera frame, the
//! controller status, and the simulator's episode commands and reports. Each
//! is a fixed-size `#[repr(C)]` struct without implicit padding, usable
//! zero-copy over iceoryx2 and writable byte for byte into logs.
//!
//! Service names and the schema version live here too. [`transport`] opens a
//! service with the version as a service attribute, so two processes built
//! from different schema versions refuse to talk, with an error that names
//! both versions. Besides the handshake, the crate holds only what every
//! node shares: the process plumbing ([`process`]: monotonic clock, absolute
//! sleeps, termination signals), configuration checks and files
//! ([`config`]: the field-naming error every node's validation returns), the
//! hardware-time stamping, and the conversions of its own types (an action
//! to and from the policy's vector, a [`Stage`] to and from its wire code).
//! It must not depend on any other crate of this workspace.

pub mod config;
pub mod process;
pub mod transport;

mod camera;
mod controller;
mod message;
mod robot;
mod sim;

pub use camera::{CameraCalibration, CameraFrame};
pub use controller::{ControllerCommand, ControllerMode, ControllerStatus, LatencyHistogram};
pub use message::{Header, Message, write_text};
pub use robot::{HardwareState, PolicyAction, SensorFrame, TorqueCommand};
pub use sim::{EpisodeReport, SimCommand, Stage};

/// Version of the message layout. Bump it whenever any message's layout or
/// meaning changes; peers built from different versions refuse to talk.
pub const SCHEMA_VERSION: u32 = 3;

/// Joint arrays hold this many entries; `n_joints` says how many are used.
pub const MAX_JOINTS: usize = 8;
/// Largest camera image width carried by [`CameraFrame`], pixels.
pub const MAX_IMAGE_WIDTH: usize = 256;
/// Largest camera image height carried by [`CameraFrame`], pixels.
pub const MAX_IMAGE_HEIGHT: usize = 256;
/// Capacity of [`SimCommand::config_toml`], bytes.
pub const MAX_CONFIG_BYTES: usize = 16 * 1024;
/// Capacity of [`EpisodeReport::message`], bytes.
pub const MAX_MESSAGE_BYTES: usize = 256;
/// Bins of a [`LatencyHistogram`] (1 µs each).
pub const HISTOGRAM_BINS: usize = 2000;

/// The stack's two clocks, the one source of their periods: the hardware
/// and the controller step at 1 kHz, the policy acts (and the camera shoots)
/// at 20 Hz. Configuration defaults are derived from these.
pub mod rates {
    /// Control (and physics) period, ns.
    pub const CONTROL_PERIOD_NS: u64 = 1_000_000;
    /// Control (and physics) period, s.
    pub const CONTROL_PERIOD_S: f64 = CONTROL_PERIOD_NS as f64 * 1e-9;
    /// Control steps per policy action (and per camera frame).
    pub const ACTION_PERIOD_STEPS: u64 = 50;
    /// Policy period, ns.
    pub const ACTION_PERIOD_NS: u64 = ACTION_PERIOD_STEPS * CONTROL_PERIOD_NS;
    /// Policy period, s.
    pub const ACTION_PERIOD_S: f64 = ACTION_PERIOD_NS as f64 * 1e-9;
}

/// Service topics, relative to a namespace (`<namespace>/<topic>`), so that
/// several stacks (parallel tests) can share one machine.
pub mod topics {
    /// hw-sim → rt-controller, 1 kHz: [`crate::HardwareState`].
    pub const HARDWARE_STATE: &str = "hw/state";
    /// rt-controller → hw-sim, 1 kHz: [`crate::TorqueCommand`].
    pub const TORQUE_COMMAND: &str = "hw/torque";
    /// hw-sim → learner, 20 Hz: [`crate::CameraFrame`].
    pub const CAMERA: &str = "hw/camera";
    /// learner → hw-sim: [`crate::SimCommand`].
    pub const SIM_COMMAND: &str = "sim/command";
    /// hw-sim → learner, 20 Hz and after each command: [`crate::EpisodeReport`].
    pub const EPISODE: &str = "sim/episode";
    /// rt-controller → learner, 1 kHz: [`crate::SensorFrame`].
    pub const SENSOR: &str = "ctrl/sensor";
    /// rt-controller → anyone, ~10 Hz: [`crate::ControllerStatus`].
    pub const STATUS: &str = "ctrl/status";
    /// operator or learner → rt-controller: [`crate::ControllerCommand`].
    pub const CONTROLLER_COMMAND: &str = "ctrl/command";
    /// learner → rt-controller, 20 Hz: [`crate::PolicyAction`].
    pub const ACTION: &str = "policy/action";
}

/// Namespace used when none is given.
pub const DEFAULT_NAMESPACE: &str = "vt";

/// Full service name of `topic` in `namespace`.
pub fn service_name(namespace: &str, topic: &str) -> String {
    format!("{namespace}/{topic}")
}

/// A hardware time in seconds as [`Header::t_hw_ns`] stamps it (rounded to
/// the nanosecond). Every stamping goes through here, and every reading
/// through [`hw_time_s`], so the control law sees the same `now` whether the
/// simulator is in another process or in the same one (lockstep runs are
/// bit-identical to the fast path).
pub fn hw_time_ns(t_s: f64) -> u64 {
    (t_s * 1e9).round() as u64
}

/// Seconds of a [`Header::t_hw_ns`] stamp.
pub fn hw_time_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}
