//! What the 1 kHz loop shares with its low-priority monitor thread.

use std::sync::atomic::{AtomicU32, AtomicU64};

/// Fault code of a silent hardware (the control law's codes are
/// [`rt_controller::cycle::fault_code`]'s).
pub const FAULT_HARDWARE_SILENT: u32 = 100;
/// Fault code of a robot error: a communication constraint violation (the
/// robot missed too many commands).
pub const FAULT_ROBOT_COMMUNICATION: u32 = 101;
/// Fault code of a robot error: one of the robot's limits (joint or
/// Cartesian position, velocity, torque, power) was violated.
pub const FAULT_ROBOT_LIMIT: u32 = 102;
/// Fault code of a robot error: a collision or other reflex stopped it.
pub const FAULT_ROBOT_REFLEX: u32 = 103;
/// Fault code of any other robot error (emergency stop, a command the robot
/// refused, a lost connection, a protocol error).
pub const FAULT_ROBOT_OTHER: u32 = 104;
/// Fault code of the external F/T sensor (`wrench = "net_ft"`): silent for
/// longer than its time-out, or reporting a fault in its status word.
pub const FAULT_FT_SENSOR: u32 = 105;

/// Fault code of the daemon's own error while it held the arm (a service
/// of the stack failed): the loop ended, so it is recorded as a fault.
pub const FAULT_DAEMON_ERROR: u32 = 106;

/// State the loop shares with its low-priority monitor thread (logging,
/// systemd watchdog) through atomics only.
#[derive(Debug, Default)]
pub struct Shared {
    /// Cycles run (the watchdog is fed only while it advances).
    pub heartbeat: AtomicU64,
    /// [`shared_mem_schema::ControllerMode`] as u32.
    pub mode: AtomicU32,
    /// Fault code (see [`rt_controller::cycle::fault_code`]).
    pub fault_code: AtomicU32,
    /// Garbage actions counted so far.
    pub garbage_actions: AtomicU64,
    /// Actions dropped from the full action queue so far.
    pub overflow_actions: AtomicU64,
    /// Hardware states skipped (superseded before a cycle) so far.
    pub skipped_states: AtomicU64,
    /// Overruns so far.
    pub overruns: AtomicU64,
    /// Failed publications to and receives from the learner so far
    /// ([`crate::Stats`]' `publish_errors` + `receive_errors`).
    pub learner_io_errors: AtomicU64,
    /// Stale actions dropped so far (every reason).
    pub stale_actions: AtomicU64,
    /// Faults latched so far (Fault or hardware-lost entered), counted by
    /// the loop so that the monitor misses none between its looks.
    pub faults_latched: AtomicU64,
    /// The fault code of the last one latched (stored before the count).
    pub latched_code: AtomicU32,
    /// Faults cleared by a reset command so far.
    pub resets: AtomicU64,
    /// Reset commands refused so far.
    pub commands_refused: AtomicU64,
    /// `header.seq` of the last controller command handled.
    pub command_seq: AtomicU64,
    /// Its result (`ControllerCommand::RESULT_*`).
    pub command_result: AtomicU32,
}
