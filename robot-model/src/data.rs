//! The preallocated workspace every algorithm writes into.

use crate::model::Model;
use crate::spatial::{Force, Inertia, Motion, Se3};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};

/// Workspace for one [`Model`]: made once, then reused by every call so that
/// no algorithm allocates. Fields are public for reading results; what each
/// algorithm fills is stated on the algorithm.
#[derive(Clone, Debug)]
pub struct Data {
    /// Per joint: its frame in its parent joint's frame at the current q.
    pub li_m_i: Vec<Se3>,
    /// Per joint: its frame in the base frame.
    pub o_m_i: Vec<Se3>,
    /// Per joint: spatial velocity of its body, in its own frame.
    pub v: Vec<Motion>,
    /// Per joint: spatial acceleration of its body, in its own frame
    /// (without the gravity offset).
    pub a: Vec<Motion>,
    /// Per joint: spatial acceleration including the gravity offset (RNEA).
    pub a_gf: Vec<Motion>,
    /// Per joint: spatial force transmitted by the joint, in its frame (RNEA).
    pub f: Vec<Force>,
    /// Per joint: composite inertia of its subtree, in its frame (CRBA).
    pub ic: Vec<Inertia>,
    /// Joint torques from [`crate::rnea`].
    pub tau: DVector<f64>,
    /// Generalised gravity from [`crate::gravity`].
    pub g: DVector<f64>,
    /// Nonlinear effects `C(q,v) v + g(q)` from [`crate::nonlinear_effects`].
    pub nle: DVector<f64>,
    /// Joint-space mass matrix (full, symmetric) from [`crate::crba`].
    pub mass: DMatrix<f64>,
    /// Lower Cholesky factor of the mass matrix (forward dynamics).
    pub chol: DMatrix<f64>,
    /// Joint accelerations from [`crate::forward_dynamics`].
    pub ddq: DVector<f64>,
    /// Coriolis matrix from [`crate::coriolis_matrix`].
    pub coriolis: DMatrix<f64>,
    // Coriolis-matrix scratch, per joint, in the base frame.
    pub(crate) c_s: Vec<Vector6<f64>>,
    pub(crate) c_sdot: Vec<Vector6<f64>>,
    pub(crate) c_ic: Vec<Matrix6<f64>>,
    pub(crate) c_bc: Vec<Matrix6<f64>>,
}

impl Data {
    /// A workspace sized for `model`.
    pub fn new(model: &Model) -> Self {
        let nj = model.njoints();
        let nv = model.nv();
        Self {
            li_m_i: vec![Se3::IDENTITY; nj],
            o_m_i: vec![Se3::IDENTITY; nj],
            v: vec![Motion::ZERO; nj],
            a: vec![Motion::ZERO; nj],
            a_gf: vec![Motion::ZERO; nj],
            f: vec![Force::ZERO; nj],
            ic: vec![Inertia::ZERO; nj],
            tau: DVector::zeros(nv),
            g: DVector::zeros(nv),
            nle: DVector::zeros(nv),
            mass: DMatrix::zeros(nv, nv),
            chol: DMatrix::zeros(nv, nv),
            ddq: DVector::zeros(nv),
            coriolis: DMatrix::zeros(nv, nv),
            c_s: vec![Vector6::zeros(); nj],
            c_sdot: vec![Vector6::zeros(); nj],
            c_ic: vec![Matrix6::zeros(); nj],
            c_bc: vec![Matrix6::zeros(); nj],
        }
    }
}

impl Model {
    /// A workspace for this model (same as [`Data::new`]).
    pub fn create_data(&self) -> Data {
        Data::new(self)
    }
}
