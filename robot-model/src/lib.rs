//! # robot-model
//!
//! Owns the robot description and the rigid-body algorithms the rest of the
//! stack computes with: URDF → [`Model`] (immutable: kinematic tree,
//! inertias, limits, frames, geometry) and [`Data`] (a preallocated
//! workspace), and free functions over `(model, data, q, v, a)` for forward
//! kinematics, frame Jacobians and J̇v, the mass matrix (CRBA), inverse
//! dynamics (RNEA), gravity, nonlinear effects, the Coriolis matrix, energies
//! and forward dynamics.
//!
//! It must not allocate after [`Data`] is made (the 1 kHz controller calls
//! it), and it must know nothing of controllers or simulators.
//!
//! Conventions: SI units; 6-D vectors and Jacobian rows are linear first,
//! then angular; poses are `nalgebra::Isometry3<f64>` at the API boundary;
//! fixed joints are folded into their parent body and every link, joint and
//! user frame is addressable by name.
//!
//! ```
//! use robot_model::{Model, LoadOptions, Reference};
//! let urdf = r#"<robot name="pendulum">
//!   <link name="base"/>
//!   <link name="arm"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
//!     <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
//!   <joint name="hinge" type="continuous"><parent link="base"/><child link="arm"/>
//!     <axis xyz="0 1 0"/></joint>
//! </robot>"#;
//! let model = Model::from_urdf_str(urdf, &LoadOptions::default()).unwrap();
//! let mut data = model.create_data();
//! let m = robot_model::crba(&model, &mut data, &[0.3]);
//! assert!((m[(0, 0)] - 0.25).abs() < 1e-12); // m l² for a point mass
//! ```

pub mod algorithms;
pub mod data;
pub mod descriptions;
pub mod error;
pub mod model;
pub mod spatial;
pub mod urdf;

pub use algorithms::dynamics::{
    cholesky_factor, cholesky_solve_in_place, coriolis_matrix, crba, forward_dynamics, gravity,
    kinetic_energy, nonlinear_effects, potential_energy, rnea,
};
pub use algorithms::kinematics::{
    Reference, center_of_mass, forward_kinematics, forward_kinematics_second_order,
    frame_acceleration, frame_jacobian, frame_jdot_v, frame_placement, frame_se3, frame_velocity,
};
pub use data::Data;
pub use error::{DynamicsError, ModelError};
pub use model::{
    Frame, FrameId, FrameKind, GeometryObject, GeometryRole, Joint, JointId, JointKind,
    JointLimits, Model, Shape,
};
pub use urdf::{LoadOptions, MissingLimits};
