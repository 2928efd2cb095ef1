//! # rt-controller-daemon
//!
//! Owns the daemon that runs rt-controller's control cycle on a robot at
//! 1 kHz: its TOML configuration ([`config`], also what the learner's
//! orchestrator writes), real-time set-up ([`rt`], [`rt_alloc`]), the loop,
//! the shared-memory transport to the learner, and the hardware backends:
//! the simulator ([`backend::SimBackend`], hw-sim over shared memory), a
//! Franka robot through `franka-rs` ([`franka`], behind the default `franka`
//! feature; docs/franka.md; run against a simulated FR3 only, never a
//! physical one) and an ATI Net F/T wrist sensor ([`netft`]). The
//! `rt-controller` binary is its entry point (docs/operation.md).
//!
//! It is the only crate of the workspace that links franka-rs. It must not
//! depend on the learner or the simulator, and the control law stays in
//! `rt_controller` (this crate adds I/O, never control).
//!
//! One cycle: read the hardware state → take the next action without
//! waiting → [`rt_controller::cycle::ControlCycle::cycle`] (the same code the
//! learner's fast path runs) → send torques → publish the sensor frame
//! (and, every `status_period_ms`, the status). Files: [`backend`] (the
//! hardware trait and the simulator backend), [`franka`] (the Franka
//! backend), [`netft`] (the external F/T sensor), `queue` (actions),
//! [`shared`] (atomics for the monitor thread), [`stats`], [`control`] (one
//! cycle), `run` (the loop). Nothing in a cycle locks or blocks (except the
//! Franka backend's wait for the robot's state, which clocks the loop, and
//! franka-rs's internal mutex; docs/franka.md), and our code allocates
//! nothing; iceoryx2 0.10 itself takes one small block per publication,
//! freed at send (tests/daemon_alloc.rs pins that down exactly), and
//! clarabel a fixed set per solve. The daemon serves those from lock-free
//! static pools ([`rt_alloc`]), so the loop never reaches the heap
//! (tests/daemon_rt_alloc.rs).
//!
//! Transport choices: every input is *polled* (an iceoryx2 `receive` costs
//! about 1 µs) rather than waited on with an event listener, whose wake-up
//! costs 55–110 µs here: the loop already wakes on its own deadline, and in
//! hardware-clocked mode a spin-then-yield poll reacts in microseconds.
//! Outputs are plain publications, which never wait for subscribers.

mod admission;
pub mod backend;
pub mod config;
pub mod control;
pub mod fault_record;
#[cfg(feature = "franka")]
pub mod franka;
pub mod netft;
mod queue;
pub mod rt;
pub mod rt_alloc;
mod run;
pub mod shared;
pub mod stats;

pub use backend::{Hardware, HardwareError, SimBackend};
pub use control::{CycleOutcome, Daemon, DaemonError};
#[cfg(feature = "franka")]
pub use franka::FrankaBackend;
pub use netft::NetFt;
pub use rt_controller::cycle::fault_code;
pub use shared::{
    FAULT_DAEMON_ERROR, FAULT_FT_SENSOR, FAULT_HARDWARE_SILENT, FAULT_ROBOT_COMMUNICATION,
    FAULT_ROBOT_LIMIT, FAULT_ROBOT_OTHER, FAULT_ROBOT_REFLEX, Shared,
};
pub use stats::{RunSummary, Stats};

/// The `rt-controller` binary's exit statuses (docs/operation.md): the
/// systemd unit restarts only after [`exit::ERROR`] and a crash.
pub mod exit {
    /// Stopped on request, no fault latched.
    pub const CLEAN: i32 = 0;
    /// An error that left no fault (the hardware never came at start-up, a
    /// service could not be opened): a restart may succeed.
    pub const ERROR: i32 = 1;
    /// A bad configuration or command line: a restart gives the same.
    pub const CONFIG: i32 = 2;
    /// A fault: latched in this run, or on record from an earlier one (the
    /// start was refused). Only `rt-controller reset` lets it start again.
    pub const FAULT: i32 = 3;
}
