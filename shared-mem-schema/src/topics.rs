//! Service topics, relative to a namespace (`<namespace>/<topic>`), so that
//! several stacks (parallel tests) can share one machine.

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
