//! # hw-sim
//!
//! Owns the simulated hardware that stands in for the robot: a rapier world
//! with a 7-DoF torque-controlled arm built from a `robot-model` URDF, the
//! peg-in-hole tasks (square, triangle, semicircle and hexagon pegs), a 6-axis
//! wrist force/torque sensor read at every physics step, a fixed RGB-D camera
//! with ground-truth optical flow, perturbations and episode metrics. Its
//! binary (arriving with the real-time stack) serves that world over shared
//! memory in real-time or lockstep mode.
//!
//! It must not contain controller logic: torques come in, sensor readings go
//! out.
