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

use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

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

/// Fields every message starts with.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Pod, Zeroable)]
pub struct Header {
    /// [`SCHEMA_VERSION`] of the sender.
    pub schema_version: u32,
    /// Message-specific flags (see each message).
    pub flags: u32,
    /// Sender's sequence number, +1 per message of this stream.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` at publication, ns (one clock for all processes of
    /// a machine, so latencies between them can be measured).
    pub t_mono_ns: u64,
    /// Hardware (simulated) time of the data, ns.
    pub t_hw_ns: u64,
    /// Episode the data belongs to (hw-sim's reset counter; 0 before any).
    pub episode: u64,
}

impl Header {
    /// A header of this schema version.
    pub fn new(seq: u64, t_mono_ns: u64, t_hw_ns: u64, episode: u64) -> Self {
        Self {
            schema_version: SCHEMA_VERSION,
            flags: 0,
            seq,
            t_mono_ns,
            t_hw_ns,
            episode,
        }
    }
}

/// Robot → controller, every hardware cycle (1 kHz).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct HardwareState {
    /// Header; `flags` bits: [`HardwareState::BRAKES_ENGAGED`].
    pub header: Header,
    /// Hardware step index since start (lockstep: the command for this
    /// state must carry it in [`TorqueCommand::state_step`]).
    pub step: u64,
    /// Sequence number of the torque command applied during the step that
    /// led to this state (0: none yet).
    pub applied_command_seq: u64,
    /// Used entries of the joint arrays.
    pub n_joints: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint positions, rad (or m).
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities, rad/s.
    pub v: [f64; MAX_JOINTS],
    /// Joint torques applied (measured), N·m.
    pub tau_measured: [f64; MAX_JOINTS],
    /// Wrist wrench the tool exerts on the flange in the F/T sensor frame:
    /// force (N) then moment (N·m).
    pub wrench: [f64; 6],
}

impl HardwareState {
    /// Flag: no valid torque command, the brakes hold the arm.
    pub const BRAKES_ENGAGED: u32 = 1;

    /// All zeros but the joint count and the schema version.
    pub fn empty(n_joints: usize) -> Self {
        Self {
            header: Header::new(0, 0, 0, 0),
            step: 0,
            applied_command_seq: 0,
            n_joints: n_joints as u32,
            reserved: 0,
            q: [0.0; MAX_JOINTS],
            v: [0.0; MAX_JOINTS],
            tau_measured: [0.0; MAX_JOINTS],
            wrench: [0.0; 6],
        }
    }
}

/// Controller → robot, every control cycle.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct TorqueCommand {
    /// Header.
    pub header: Header,
    /// [`HardwareState::step`] of the state this command answers.
    pub state_step: u64,
    /// Sequence number of the newest policy action reflected in `tau`
    /// (0: none).
    pub action_seq: u64,
    /// Used entries of `tau`.
    pub n_joints: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint torques, N·m.
    pub tau: [f64; MAX_JOINTS],
}

impl TorqueCommand {
    /// All zeros but the joint count and the schema version.
    pub fn empty(n_joints: usize) -> Self {
        Self {
            header: Header::new(0, 0, 0, 0),
            state_step: 0,
            action_seq: 0,
            n_joints: n_joints as u32,
            reserved: 0,
            tau: [0.0; MAX_JOINTS],
        }
    }
}

/// Controller → learner, every control cycle (1 kHz).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct SensorFrame {
    /// Header (`t_hw_ns` is the hardware time of the state).
    pub header: Header,
    /// Hardware step of the state.
    pub step: u64,
    /// Sequence number of the newest action reflected in `tau_cmd`.
    pub action_seq: u64,
    /// Used entries of the joint arrays.
    pub n_joints: u32,
    /// Controller mode ([`ControllerMode`] as u32).
    pub mode: u32,
    /// Fault code after this cycle, as [`ControllerStatus::fault_code`] (0:
    /// none).
    pub fault_code: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint positions, rad.
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities, rad/s.
    pub v: [f64; MAX_JOINTS],
    /// Torques commanded this cycle, N·m.
    pub tau_cmd: [f64; MAX_JOINTS],
    /// Torques measured, N·m.
    pub tau_measured: [f64; MAX_JOINTS],
    /// End-effector position in the base frame, m.
    pub ee_pos_m: [f64; 3],
    /// End-effector orientation in the base frame, quaternion (x, y, z, w).
    pub ee_quat_xyzw: [f64; 4],
    /// End-effector twist in the base frame: linear (m/s) then angular
    /// (rad/s).
    pub ee_twist: [f64; 6],
    /// Wrist wrench in the F/T sensor frame: force (N) then moment (N·m).
    pub wrench: [f64; 6],
}

/// The episode stages of the paper's evaluation (Sec. "Evaluation
/// metrics"), ordered: a later stage implies the earlier ones were reached.
/// On the wire as [`Stage::code`], in text (logs, events) as
/// [`Stage::name`].
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
#[repr(u32)]
pub enum Stage {
    /// The peg never touched the box.
    #[default]
    Failed = 0,
    /// The peg touched the box.
    Touched = 1,
    /// The peg's tip went into the hole.
    Inserted = 2,
    /// The peg's tip reached the hole's bottom.
    Completed = 3,
}

impl Stage {
    /// All stages, in order.
    pub const ALL: [Stage; 4] = [
        Stage::Failed,
        Stage::Touched,
        Stage::Inserted,
        Stage::Completed,
    ];

    /// The wire code.
    pub fn code(self) -> u32 {
        self as u32
    }

    /// The stage of a wire code; an unknown code reads as failed.
    pub fn from_code(code: u32) -> Self {
        Self::ALL
            .get(code as usize)
            .copied()
            .unwrap_or(Stage::Failed)
    }

    /// Lower-case name: failed, touched, inserted or completed.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Failed => "failed",
            Stage::Touched => "touched",
            Stage::Inserted => "inserted",
            Stage::Completed => "completed",
        }
    }
}

impl core::fmt::Display for Stage {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Learner → controller, 20 Hz: the paper's action, a displacement of the
/// end-effector target.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct PolicyAction {
    /// Header (`t_hw_ns`: hardware time of the observation it answers).
    pub header: Header,
    /// Lockstep only: the hardware step at which the controller applies it
    /// (0: as soon as it arrives, the deployed behaviour).
    pub apply_at_step: u64,
    /// Position step (x, y, z) in the base frame, m.
    pub delta_pos_m: [f64; 3],
    /// Roll step about the base z axis, rad.
    pub delta_roll_rad: f64,
}

impl PolicyAction {
    /// An action to apply as soon as it arrives, from the policy's vector
    /// (Δx, Δy, Δz in m, Δroll in rad).
    pub fn new(seq: u64, t_mono_ns: u64, delta: [f64; 4]) -> Self {
        let [x, y, z, roll] = delta;
        Self {
            header: Header::new(seq, t_mono_ns, 0, 0),
            apply_at_step: 0,
            delta_pos_m: [x, y, z],
            delta_roll_rad: roll,
        }
    }

    /// The policy's vector (Δx, Δy, Δz in m, Δroll in rad).
    pub fn delta(&self) -> [f64; 4] {
        let [x, y, z] = self.delta_pos_m;
        [x, y, z, self.delta_roll_rad]
    }
}

/// A calibrated pinhole camera (square pixels, no distortion): the one
/// calibration type of the stack, carried in every [`CameraFrame`], logged
/// with it, and what the flow labeler and the simulator's camera are built
/// from.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    Pod,
    Zeroable,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct CameraCalibration {
    /// Image width, pixels (≤ [`MAX_IMAGE_WIDTH`] in a message).
    pub width: u32,
    /// Image height, pixels (≤ [`MAX_IMAGE_HEIGHT`] in a message).
    pub height: u32,
    /// Focal length, pixels.
    pub focal_px: f64,
    /// Principal point (x, y), pixels.
    pub principal_px: [f64; 2],
    /// Camera position in the base frame, m. Camera axes: x right, y down,
    /// z forward (optical).
    pub pose_pos_m: [f64; 3],
    /// Camera orientation in the base frame, quaternion (x, y, z, w).
    pub pose_quat_xyzw: [f64; 4],
}

impl std::fmt::Display for CameraCalibration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.pose_pos_m;
        let [qx, qy, qz, qw] = self.pose_quat_xyzw;
        write!(
            f,
            "{}×{} px, focal {:.2} px, at ({x:.4}, {y:.4}, {z:.4}) m, \
             quaternion ({qx:.4}, {qy:.4}, {qz:.4}, {qw:.4})",
            self.width, self.height, self.focal_px
        )
    }
}

impl CameraCalibration {
    /// Whether `other` is the same camera: the same image size, focal
    /// length and principal point within 10⁻³ px, position within 0.1 mm and
    /// orientation within about 10⁻³ rad (`q` and `−q` are one rotation).
    /// The tolerances absorb a calibration's round trip through f32 or text,
    /// not a moved camera: a learned encoder sees a camera moved by a few
    /// millimetres as a different scene.
    pub fn same_camera(&self, other: &Self) -> bool {
        let near =
            |a: &[f64], b: &[f64], tol: f64| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
        let dot = |a: &[f64; 4], b: &[f64; 4]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (qa, qb) = (&self.pose_quat_xyzw, &other.pose_quat_xyzw);
        let norms = (dot(qa, qa) * dot(qb, qb)).sqrt();
        // |q̂a·q̂b| = cos(θ/2) for a rotation θ between them: θ ≤ 10⁻³ rad.
        // A zero (or non-finite) quaternion is no orientation: no match.
        norms > 1e-12
            && norms.is_finite()
            && (dot(qa, qb) / norms).abs() >= (0.5e-3f64).cos()
            && self.width == other.width
            && self.height == other.height
            && (self.focal_px - other.focal_px).abs() <= 1e-3
            && near(&self.principal_px, &other.principal_px, 1e-3)
            && near(&self.pose_pos_m, &other.pose_pos_m, 1e-4)
    }
}

/// Robot (camera driver) → learner, 20 Hz: an RGB-D image with its
/// calibration. Only the first `width × height` pixels of each buffer are
/// meaningful.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct CameraFrame {
    /// Header (`t_hw_ns`: exposure time).
    pub header: Header,
    /// Frame counter since start.
    pub index: u64,
    /// The image size and the camera's intrinsics and pose.
    pub calibration: CameraCalibration,
    /// RGB, row-major, 3 bytes per pixel.
    pub rgb: [u8; MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT * 3],
    /// Depth along the optical axis, m, row-major (0: no return).
    pub depth_m: [f32; MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT],
}

/// The controller's mode as carried in messages.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerMode {
    /// Holding the start pose, no action yet.
    Idle = 0,
    /// Following actions.
    Running = 1,
    /// Holding the last target (actions stopped).
    Holding = 2,
    /// Latched safe state.
    Fault = 3,
    /// No hardware state: no torques sent.
    HardwareLost = 4,
}

impl ControllerMode {
    /// Decodes a `mode` field; `None` for unknown values.
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Idle,
            1 => Self::Running,
            2 => Self::Holding,
            3 => Self::Fault,
            4 => Self::HardwareLost,
            _ => return None,
        })
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Running => "running",
            Self::Holding => "holding",
            Self::Fault => "fault",
            Self::HardwareLost => "hardware-lost",
        }
    }
}

/// A histogram of durations in 1 µs bins, cumulative since start.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct LatencyHistogram {
    /// Samples recorded.
    pub count: u64,
    /// Samples at or above `HISTOGRAM_BINS` µs.
    pub overflow: u64,
    /// Largest sample, ns.
    pub max_ns: u64,
    /// Sum of samples, ns.
    pub sum_ns: u64,
    /// `bins[i]`: samples in [i, i+1) µs.
    pub bins: [u32; HISTOGRAM_BINS],
}

impl LatencyHistogram {
    /// An empty histogram.
    pub const EMPTY: Self = Self {
        count: 0,
        overflow: 0,
        max_ns: 0,
        sum_ns: 0,
        bins: [0; HISTOGRAM_BINS],
    };

    /// Records one duration (never allocates).
    pub fn record(&mut self, ns: u64) {
        self.count += 1;
        self.sum_ns = self.sum_ns.saturating_add(ns);
        self.max_ns = self.max_ns.max(ns);
        let us = (ns / 1000) as usize;
        match self.bins.get_mut(us) {
            Some(b) => *b = b.saturating_add(1),
            None => self.overflow += 1,
        }
    }

    /// The `p`-quantile (0..=1), µs, as the upper edge of its bin; the
    /// maximum when it falls in the overflow; 0 when empty.
    pub fn quantile_us(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((p.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, &b) in self.bins.iter().enumerate() {
            seen += u64::from(b);
            if seen >= rank {
                return (i + 1) as f64;
            }
        }
        self.max_ns as f64 / 1000.0
    }

    /// Mean, µs.
    pub fn mean_us(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64 / 1000.0
        }
    }
}

/// Controller → anyone, ~10 Hz: mode, counters and timing.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct ControllerStatus {
    /// Header.
    pub header: Header,
    /// Control cycles run.
    pub cycles: u64,
    /// Cycles that started after their deadline had passed a whole period.
    pub overruns: u64,
    /// Actions received.
    pub actions_received: u64,
    /// Actions applied (clamped included).
    pub actions_accepted: u64,
    /// Garbage actions (NaN, out of range, wrong schema) counted and ignored.
    pub actions_rejected: u64,
    /// Actions dropped unread because the controller's action queue was
    /// full (the oldest goes): a flood, not bad values.
    pub actions_overflow: u64,
    /// Valid actions ignored (fault or hold).
    pub actions_ignored: u64,
    /// Times the action stream went silent past the timeout.
    pub action_timeouts: u64,
    /// Faults raised.
    pub faults: u64,
    /// Cycles without a new hardware state.
    pub hardware_misses: u64,
    /// Hardware states never controlled: a newer one had arrived by the
    /// cycle (their steps have no sensor frame).
    pub hardware_states_skipped: u64,
    /// Sequence number of the newest action applied.
    pub last_action_seq: u64,
    /// Actions dropped as stale because the observation they answer is
    /// older than the controller's `safety.max_action_age_s` (hardware
    /// time), or their sender stamped none.
    pub actions_too_old: u64,
    /// Actions dropped as stale because they answer an observation the
    /// hardware has not made yet (a hardware time after the current state's).
    pub actions_from_future: u64,
    /// Actions dropped as stale because they answer another episode.
    pub actions_other_episode: u64,
    /// Actions dropped as stale because their sequence number is not above
    /// the newest one applied this episode (a replay).
    pub actions_replayed: u64,
    /// Faults (the control law's, or a silent hardware) cleared by a
    /// [`ControllerCommand::RESET`].
    pub resets: u64,
    /// `header.seq` of the last [`ControllerCommand`] handled (0: none).
    pub command_seq: u64,
    /// Controller mode ([`ControllerMode`] as u32).
    pub mode: u32,
    /// Fault reason code (0: none; see rt-controller's docs).
    pub fault_code: u32,
    /// 1 when the real-time set-up (memory lock, SCHED_FIFO) succeeded.
    pub realtime: u32,
    /// Result of the command `command_seq`: a `ControllerCommand::RESULT_*`
    /// (0 before any).
    pub command_result: u32,
    /// Wake-up latency of each cycle past its absolute deadline.
    pub wakeup_latency: LatencyHistogram,
    /// Compute time of each cycle (read state → torques sent → frame
    /// published).
    pub compute: LatencyHistogram,
    /// From an action's publication to the first torque command that
    /// reflects it.
    pub action_latency: LatencyHistogram,
}

/// Operator or learner → controller: leaving a latched fault. The daemon
/// answers in [`ControllerStatus`] (`command_seq`, `command_result`,
/// `resets`), published at once.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct ControllerCommand {
    /// Header (`seq`: the request id echoed in
    /// [`ControllerStatus::command_seq`]; `episode`: the hardware episode
    /// the sender saw, for the log).
    pub header: Header,
    /// What to do ([`ControllerCommand::RESET`]).
    pub command: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

impl ControllerCommand {
    /// Leave Fault (or a silent hardware's fault) for Idle, holding the
    /// pose the arm then has.
    pub const RESET: u32 = 1;
    /// Result: a fault was latched and is cleared.
    pub const RESULT_CLEARED: u32 = 1;
    /// Result: there was no fault to clear (nothing changed).
    pub const RESULT_NO_FAULT: u32 = 2;
    /// Result: refused, the hardware is still silent (no state within
    /// `hardware_timeout_ms`); the fault stays latched.
    pub const RESULT_HARDWARE_SILENT: u32 = 3;
    /// Result: refused, not a known command.
    pub const RESULT_UNKNOWN: u32 = 4;

    /// A reset request with id `seq`, sent at `t_mono_ns` by a sender that
    /// saw hardware episode `episode`.
    pub fn reset(seq: u64, t_mono_ns: u64, episode: u64) -> Self {
        Self {
            header: Header::new(seq, t_mono_ns, 0, episode),
            command: Self::RESET,
            reserved: 0,
        }
    }

    /// Text of a `RESULT_*` code.
    pub fn result_name(result: u32) -> &'static str {
        match result {
            0 => "none",
            Self::RESULT_CLEARED => "cleared",
            Self::RESULT_NO_FAULT => "no fault to clear",
            Self::RESULT_HARDWARE_SILENT => "refused: the hardware is silent",
            Self::RESULT_UNKNOWN => "refused: unknown command",
            _ => "?",
        }
    }
}

/// Learner → hw-sim: episode control.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct SimCommand {
    /// Header (`seq` is the request id echoed in [`EpisodeReport`]).
    pub header: Header,
    /// What to do ([`SimCommand::RESET`], [`SimCommand::SHUTDOWN`]).
    pub command: u32,
    /// Used bytes of `config_toml`.
    pub config_len: u32,
    /// Seed of the new episode.
    pub seed: u64,
    /// TOML of the simulator's world configuration (UTF-8); empty: keep the
    /// current configuration.
    pub config_toml: [u8; MAX_CONFIG_BYTES],
}

impl SimCommand {
    /// Start a new episode (new box pose, arm at its start pose).
    pub const RESET: u32 = 1;
    /// Stop the simulator process.
    pub const SHUTDOWN: u32 = 2;
}

/// hw-sim → learner: the episode and task state, at 20 Hz and after each
/// command (the simulator's ground truth; a real cell has none of it).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct EpisodeReport {
    /// Header (`episode`: the current episode).
    pub header: Header,
    /// `seq` of the last command handled (0: none).
    pub command_seq: u64,
    /// Seed of the current episode.
    pub seed: u64,
    /// Hardware step of the report.
    pub step: u64,
    /// Result of the last command: [`EpisodeReport::OK`] or
    /// [`EpisodeReport::REJECTED`] (reason in `message`).
    pub command_result: u32,
    /// Peg: 0 none, 1 square, 2 triangle, 3 semicircle, 4 hexagon.
    pub peg: u32,
    /// Stage now, [`Stage::code`]: 0 failed (not touched), 1 touched, 2
    /// inserted, 3 completed.
    pub stage_now: u32,
    /// Best stage reached this episode (same codes).
    pub best_stage: u32,
    /// 1 when the peg touches the box.
    pub in_contact: u32,
    /// Used bytes of `message`.
    pub message_len: u32,
    /// Peg tip relative to the hole's top centre, hole frame, m.
    pub s_m: [f64; 3],
    /// Peg roll relative to the hole, wrapped by its symmetry, rad.
    pub s_psi_rad: f64,
    /// Hole top-centre position in the base frame, m.
    pub hole_pos_m: [f64; 3],
    /// Hole orientation in the base frame, quaternion (x, y, z, w).
    pub hole_quat_xyzw: [f64; 4],
    /// Peg width (outline scale), m.
    pub peg_width_m: f64,
    /// Hole depth, m.
    pub hole_depth_m: f64,
    /// UTF-8 text: the reason a command was rejected.
    pub message: [u8; MAX_MESSAGE_BYTES],
}

impl EpisodeReport {
    /// The command was carried out.
    pub const OK: u32 = 0;
    /// The command was refused; `message` says why.
    pub const REJECTED: u32 = 1;

    /// The stage reached at this step.
    pub fn stage_now(&self) -> Stage {
        Stage::from_code(self.stage_now)
    }

    /// The best stage reached this episode so far.
    pub fn best_stage(&self) -> Stage {
        Stage::from_code(self.best_stage)
    }

    /// The message text (lossy UTF-8).
    pub fn message_text(&self) -> String {
        let n = (self.message_len as usize).min(MAX_MESSAGE_BYTES);
        String::from_utf8_lossy(&self.message[..n]).into_owned()
    }
}

/// Copies `text` into a fixed buffer, truncated at a character boundary;
/// returns the bytes used.
pub fn write_text(buf: &mut [u8], text: &str) -> u32 {
    let mut n = text.len().min(buf.len());
    while !text.is_char_boundary(n) {
        n -= 1;
    }
    buf[..n].copy_from_slice(&text.as_bytes()[..n]);
    buf[n..].fill(0);
    n as u32
}

// The derives of `Pod` reject padding; these pin the layouts the schema
// version stands for.
const H: usize = 40;
const J: usize = 8 * MAX_JOINTS;
const _: () = assert!(size_of::<Header>() == H);
const _: () = assert!(size_of::<HardwareState>() == H + 16 + 8 + 3 * J + 48);
const _: () = assert!(size_of::<TorqueCommand>() == H + 16 + 8 + J);
const _: () = assert!(size_of::<SensorFrame>() == H + 16 + 16 + 4 * J + 8 * 19);
const _: () = assert!(size_of::<PolicyAction>() == H + 8 + 32);
const _: () = assert!(
    size_of::<CameraFrame>()
        == H + 8 + 8 + 8 + 16 + 24 + 32 + MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT * 7
);
const _: () = assert!(size_of::<LatencyHistogram>() == 32 + 4 * HISTOGRAM_BINS);
const _: () =
    assert!(size_of::<ControllerStatus>() == H + 144 + 16 + 3 * size_of::<LatencyHistogram>());
const _: () = assert!(size_of::<ControllerCommand>() == H + 8);
const _: () = assert!(size_of::<SimCommand>() == H + 16 + MAX_CONFIG_BYTES);
const _: () = assert!(size_of::<EpisodeReport>() == H + 24 + 24 + 8 * 13 + MAX_MESSAGE_BYTES);

/// A message type with its topic. Messages are plain old data (`bytemuck`):
/// their bytes are what logs store and what travels.
pub trait Message: Pod + ZeroCopySend + core::fmt::Debug {
    /// Its topic (see [`topics`]).
    const TOPIC: &'static str;
    /// Its type name, as written into logs next to [`SCHEMA_VERSION`].
    const NAME: &'static str;
    /// Its header.
    fn header(&self) -> &Header;

    /// A boxed all-zero message, built on the heap (camera frames and
    /// commands are too large for a thread's stack).
    fn boxed_zeroed() -> Box<Self> {
        bytemuck::zeroed_box()
    }

    /// The message's bytes (native endianness).
    fn as_bytes(&self) -> &[u8] {
        bytemuck::bytes_of(self)
    }

    /// A boxed copy of the message whose bytes are `bytes` (any alignment);
    /// `None` when the length differs from the message's size.
    fn read_from(bytes: &[u8]) -> Option<Box<Self>> {
        if bytes.len() != size_of::<Self>() {
            return None;
        }
        let mut b = Self::boxed_zeroed();
        bytemuck::bytes_of_mut(&mut *b).copy_from_slice(bytes);
        Some(b)
    }
}

macro_rules! message {
    ($t:ty, $topic:expr, $name:expr) => {
        impl Message for $t {
            const TOPIC: &'static str = $topic;
            const NAME: &'static str = $name;
            fn header(&self) -> &Header {
                &self.header
            }
        }
    };
}

message!(HardwareState, topics::HARDWARE_STATE, "HardwareState");
message!(TorqueCommand, topics::TORQUE_COMMAND, "TorqueCommand");
message!(SensorFrame, topics::SENSOR, "SensorFrame");
message!(PolicyAction, topics::ACTION, "PolicyAction");
message!(CameraFrame, topics::CAMERA, "CameraFrame");
message!(ControllerStatus, topics::STATUS, "ControllerStatus");
message!(
    ControllerCommand,
    topics::CONTROLLER_COMMAND,
    "ControllerCommand"
);
message!(SimCommand, topics::SIM_COMMAND, "SimCommand");
message!(EpisodeReport, topics::EPISODE, "EpisodeReport");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_camera_within_round_trip_not_moved() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let a = CameraCalibration {
            width: 128,
            height: 128,
            focal_px: 175.8,
            principal_px: [64.0, 64.0],
            pose_pos_m: [0.9, -0.24, 0.77],
            pose_quat_xyzw: [h, 0.0, 0.0, h],
        };
        assert!(a.same_camera(&a));
        // The same rotation written as -q, and an f32 round trip.
        let mut b = a;
        b.pose_quat_xyzw = a.pose_quat_xyzw.map(|x| -x);
        b.pose_pos_m = a.pose_pos_m.map(|x| x as f32 as f64);
        b.focal_px = a.focal_px as f32 as f64;
        assert!(a.same_camera(&b));
        let moved = |f: &dyn Fn(&mut CameraCalibration)| {
            let mut c = a;
            f(&mut c);
            !a.same_camera(&c) && !c.same_camera(&a)
        };
        assert!(moved(&|c| c.width = 64));
        assert!(moved(&|c| c.height = 96));
        assert!(moved(&|c| c.focal_px += 0.5));
        assert!(moved(&|c| c.principal_px[1] += 0.5));
        assert!(moved(&|c| c.pose_pos_m[2] += 0.001));
        // Turned about z by θ: the same within 10⁻³ rad, not beyond; a
        // quaternion of another norm is the same rotation.
        let turned = |theta: f64, scale: f64| {
            let (s, k) = ((theta / 2.0).sin(), (theta / 2.0).cos());
            let mut c = a;
            c.pose_quat_xyzw = [h * k, h * s, h * s, h * k].map(|x| x * scale);
            c
        };
        assert!(a.same_camera(&turned(0.8e-3, 1.0)));
        assert!(a.same_camera(&turned(0.0, 2.0)));
        assert!(!a.same_camera(&turned(1.5e-3, 1.0)));
        assert!(!a.same_camera(&turned(0.01, 1.0)));
        // Just inside and outside the other tolerances.
        let same = |f: &dyn Fn(&mut CameraCalibration)| {
            let mut c = a;
            f(&mut c);
            a.same_camera(&c) && c.same_camera(&a)
        };
        assert!(same(&|c| c.pose_pos_m[0] += 0.8e-4));
        assert!(moved(&|c| c.pose_pos_m[0] += 2e-4));
        assert!(same(&|c| c.focal_px += 0.8e-3));
        assert!(moved(&|c| c.focal_px += 2e-3));
        // No orientation matches nothing, itself included.
        assert!(!CameraCalibration::default().same_camera(&CameraCalibration::default()));
    }

    #[test]
    fn histogram_quantiles() {
        let mut h = LatencyHistogram::EMPTY;
        assert_eq!(h.quantile_us(0.5), 0.0);
        for us in 0..100u64 {
            h.record(us * 1000 + 500);
        }
        assert_eq!(h.count, 100);
        assert_eq!(h.quantile_us(0.5), 50.0);
        assert_eq!(h.quantile_us(0.99), 99.0);
        assert_eq!(h.quantile_us(1.0), 100.0);
        h.record(10_000_000);
        assert_eq!(h.overflow, 1);
        assert_eq!(h.quantile_us(1.0), 10_000.0);
        assert!((h.mean_us() - (4950.0 + 50.0 + 10_000.0) / 101.0).abs() < 1e-9);
    }

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
