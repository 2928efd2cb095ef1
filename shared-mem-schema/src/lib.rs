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
pub mod topics;
pub mod transport;

mod camera;
mod controller;
mod message;
mod robot;
mod sim;

pub use camera::{CameraCalibration, CameraFrame, MAX_IMAGE_HEIGHT, MAX_IMAGE_WIDTH};
pub use controller::{
    ControllerCommand, ControllerMode, ControllerStatus, HISTOGRAM_BINS, LatencyHistogram,
};
pub use message::{Header, Message, OLDEST_RECORDED_VERSION, SCHEMA_VERSION, write_text};
pub use robot::{HardwareState, MAX_JOINTS, PolicyAction, SensorFrame, TorqueCommand};
pub use sim::{EpisodeReport, MAX_CONFIG_BYTES, MAX_MESSAGE_BYTES, SimCommand, Stage};

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
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_round_trip() {
        let mut a = PolicyAction::boxed_zeroed();
        a.header = Header::new(7, 1, 2, 3);
        a.delta_pos_m = [0.1, -0.2, 0.3];
        a.delta_roll_rad = -0.0;
        let b = PolicyAction::read_from(a.as_bytes()).unwrap();
        assert_eq!(a.as_bytes(), b.as_bytes());
        assert!(PolicyAction::read_from(&a.as_bytes()[1..]).is_none());
        let cam = CameraFrame::boxed_zeroed();
        assert!(cam.rgb.iter().all(|&x| x == 0));
    }

    #[test]
    fn text_truncates_on_char_boundary() {
        let mut buf = [0xffu8; 5];
        let n = write_text(&mut buf, "ab€d");
        assert_eq!(n, 5);
        let n = write_text(&mut buf, "abcd€");
        assert_eq!(n, 4);
        assert_eq!(&buf, b"abcd\0");
        assert_eq!(ControllerMode::from_u32(3), Some(ControllerMode::Fault));
        assert_eq!(ControllerMode::from_u32(9), None);
    }
}
