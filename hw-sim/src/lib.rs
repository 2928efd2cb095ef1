//! # hw-sim
//!
//! Owns the simulated hardware that stands in for the robot: a rapier world
//! with a 7-DoF torque-controlled arm built from a `robot-model` URDF, the
//! peg-in-hole tasks (square, triangle, semicircle and hexagon pegs), a 6-axis
//! wrist force/torque sensor read at every physics step, a fixed RGB-D camera
//! with ground-truth optical flow, perturbations and episode metrics, and the
//! robot's side of the wire messages ([`hardware::SimHardware`]: state out,
//! torque command in, brakes). Its binary serves that world over shared
//! memory in real-time or lockstep mode.
//!
//! It must not contain controller logic: torques come in, sensor readings go
//! out.
//!
//! ```
//! use hw_sim::{World, WorldConfig};
//! let mut world = World::new(WorldConfig::default()).unwrap();
//! let tau = vec![0.0; 7];
//! world.step(&tau).unwrap();
//! assert_eq!(world.step_index(), 1);
//! ```

pub mod camera;
pub mod config;
pub mod convert;
pub mod hardware;
pub mod reset;
pub mod shapes;
pub mod world;

pub use camera::{CameraFrame, Class};
pub use config::WorldConfig;
pub use hardware::SimHardware;
pub use shapes::PegShape;
pub use shared_mem_schema::Stage;
pub use shared_mem_schema::config::{ConfigFileError, FieldError};
/// The stack's shared utilities, here for the simulator's own modules.
pub use stack_common::{png, rng};
pub use world::{SensorReadings, SimError, TaskState, World};
