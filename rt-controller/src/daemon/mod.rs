//! The daemon around the control step: hardware backends, the 1 kHz loop,
//! actions, sensor frames, status and timing statistics.
//!
//! One cycle: read the hardware state → take the next action without
//! waiting → [`crate::cycle::ControlCycle::cycle`] (the same code the fast
//! path runs) → send torques → publish the sensor frame (and, every
//! `status_period_ms`, the status). Files: [`backend`] (the hardware trait
//! and the simulator backend), [`franka`] (the Franka backend), `queue` (actions), [`shared`] (atomics for
//! the monitor thread), [`stats`], [`control`] (one cycle), `run` (the loop). Nothing in a cycle locks or
//! blocks (except the Franka backend's wait for the robot's state, which
//! clocks the loop, and franka-rs's internal mutex; docs/franka.md), and our
//! code allocates nothing; iceoryx2 0.10 itself takes one
//! small block per publication, freed at send (tests/daemon_alloc.rs pins
//! that down exactly), and clarabel a fixed set per solve. The daemon serves
//! those from lock-free static pools ([`rt_alloc`]), so the loop never
//! reaches the heap (tests/daemon_rt_alloc.rs).
//!
//! Transport choices: every input is *polled* (an iceoryx2 `receive` costs
//! about 1 µs) rather than waited on with an event listener, whose wake-up
//! costs 55–110 µs here: the loop already wakes on its own deadline, and in
//! hardware-clocked mode a spin-then-yield poll reacts in microseconds.
//! Outputs are plain publications, which never wait for subscribers.

pub mod backend;
pub mod config;
pub mod control;
pub mod franka;
pub mod netft;
mod queue;
pub mod rt;
pub mod rt_alloc;
mod run;
pub mod shared;
pub mod stats;

pub use crate::cycle::fault_code;
pub use backend::{Hardware, HardwareError, SimBackend};
pub use control::{CycleOutcome, Daemon, DaemonError};
pub use franka::FrankaBackend;
pub use shared::{
    FAULT_FT_SENSOR, FAULT_HARDWARE_SILENT, FAULT_ROBOT_COMMUNICATION, FAULT_ROBOT_LIMIT,
    FAULT_ROBOT_OTHER, FAULT_ROBOT_REFLEX, Shared,
};
pub use stats::{RunSummary, Stats};
