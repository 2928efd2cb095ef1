//! # rt-controller
//!
//! Owns the control law of the stack, run at 1 kHz: the trajectory generator
//! that turns the latest 20 Hz policy action (Δx, Δy, Δz, Δroll of the
//! end-effector) into a smooth Cartesian reference, the Cartesian impedance
//! law, operational-space control (Λ = (J M⁻¹ Jᵀ)⁻¹), the QP torque-limit
//! filter and the safety supervisor, as a pure step `(state, action) →
//! torques`. Its binary (arriving with the real-time stack) is the daemon that
//! wraps that step with shared-memory I/O, real-time set-up and a hardware
//! backend (simulator or Franka).
//!
//! It must not allocate, lock or block in the 1 kHz path, and it must not do
//! any learning. Kinematics and dynamics come from `robot-model`.
