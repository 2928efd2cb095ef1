//! Operational-space control (Khatib 1995), the form of the paper's
//! controller figure:
//!
//! ```text
//! Λ = (J M⁻¹ Jᵀ)⁻¹            task-space inertia (regularised near singularities)
//! f = Λ (a_u − J̇v)             task force for the commanded acceleration
//! J̄ = M⁻¹ Jᵀ Λ                 dynamically consistent inverse
//! τ = Jᵀ f + Nᵀ τ₀ + h(q, v)   Nᵀ = I − Jᵀ J̄ᵀ
//! τ₀ = M (k_p (q_rest − q) − k_v v)   posture, projected into the null space
//! ```
//!
//! Adding the whole of `h` is the usual simplification: its task part
//! `Jᵀ J̄ᵀ h` is exactly OSC's `μ + p`, and its null-space part `Nᵀ h` only
//! compensates gravity and Coriolis of the self-motion.
//!
//! Everything is written into preallocated buffers; nothing allocates.

use crate::linalg::{mul_into, tr_mul_into};
use nalgebra::{DMatrix, DVector, Dyn, Matrix6, Matrix6xX, OMatrix, SymmetricEigen, U6, Vector6};
use robot_model::cholesky_solve_in_place;

/// Workspace and results of one OSC evaluation.
#[derive(Debug, Clone)]
pub struct OscData {
    /// `M⁻¹`.
    pub minv: DMatrix<f64>,
    /// `J M⁻¹` (6×n).
    pub j_minv: Matrix6xX<f64>,
    /// `M⁻¹ Jᵀ` (n×6).
    pub minv_jt: OMatrix<f64, Dyn, U6>,
    /// `Λ⁻¹ = J M⁻¹ Jᵀ`.
    pub lambda_inv: Matrix6<f64>,
    /// The (damped) task-space inertia `Λ`.
    pub lambda: Matrix6<f64>,
    /// Smallest eigenvalue of `Λ⁻¹`: goes to zero at a singularity.
    pub min_sigma: f64,
    /// `J̄ = M⁻¹ Jᵀ Λ` (n×6).
    pub jbar: OMatrix<f64, Dyn, U6>,
    /// `Nᵀ = I − Jᵀ J̄ᵀ` (n×n).
    pub null_t: DMatrix<f64>,
    /// `J̄ J` scratch (n×n).
    jbar_j: DMatrix<f64>,
    /// The task force `f`.
    pub force: Vector6<f64>,
    /// The null-space posture torque `Nᵀ τ₀`.
    pub tau_null: DVector<f64>,
    /// The OSC torque `τ`.
    pub tau: DVector<f64>,
    scratch: DVector<f64>,
    tau0: DVector<f64>,
}

impl OscData {
    /// Buffers for a robot with `nv` joints.
    pub fn new(nv: usize) -> Self {
        Self {
            minv: DMatrix::zeros(nv, nv),
            j_minv: Matrix6xX::zeros(nv),
            minv_jt: OMatrix::<f64, Dyn, U6>::zeros(nv),
            lambda_inv: Matrix6::zeros(),
            lambda: Matrix6::zeros(),
            min_sigma: 0.0,
            jbar: OMatrix::<f64, Dyn, U6>::zeros(nv),
            null_t: DMatrix::zeros(nv, nv),
            jbar_j: DMatrix::zeros(nv, nv),
            force: Vector6::zeros(),
            tau_null: DVector::zeros(nv),
            tau: DVector::zeros(nv),
            scratch: DVector::zeros(nv),
            tau0: DVector::zeros(nv),
        }
    }
}

/// Inputs of one OSC evaluation: the robot's dynamics at the current state.
pub struct OscInputs<'a> {
    /// Joint positions.
    pub q: &'a [f64],
    /// Joint velocities.
    pub v: &'a [f64],
    /// Mass matrix `M(q)`.
    pub mass: &'a DMatrix<f64>,
    /// Lower Cholesky factor of `M`.
    pub chol: &'a DMatrix<f64>,
    /// Nonlinear effects `h = C v + g`.
    pub h: &'a DVector<f64>,
    /// Task Jacobian in the base frame (6×n, linear rows first).
    pub jac: &'a Matrix6xX<f64>,
    /// `J̇ v` in the base frame.
    pub jdot_v: &'a Vector6<f64>,
    /// Commanded task acceleration `a_u`.
    pub a_u: &'a Vector6<f64>,
    /// Posture the null-space term pulls towards.
    pub rest_q: &'a [f64],
}

/// `M⁻¹` column by column from the lower Cholesky factor of `M`;
/// `scratch` is an n-vector of workspace.
pub fn inverse_from_cholesky(
    chol: &DMatrix<f64>,
    scratch: &mut DVector<f64>,
    out: &mut DMatrix<f64>,
) {
    for k in 0..chol.nrows() {
        scratch.fill(0.0);
        scratch[k] = 1.0;
        cholesky_solve_in_place(chol, scratch.as_mut_slice());
        out.set_column(k, scratch);
    }
}

/// Why OSC could not run this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum OscError {
    /// `Λ⁻¹` was not finite, or its eigen-decomposition did not converge
    /// within the iteration cap.
    #[error("the task-space inertia could not be decomposed")]
    Decomposition,
}

/// Singularity-robust inverse of a symmetric positive semi-definite 6×6
/// matrix with eigenvalues σ: `V diag(φ(σ)) Vᵀ` with `φ(σ) = 1/σ` for
/// `σ ≥ ε` and `φ(σ) = σ/ε²` below. This is damped least squares with the
/// variable damping `λ² = ε² − σ²` (zero away from singularities, so Λ is
/// exact there and the null space stays dynamically consistent); φ is
/// continuous, bounded by `1/ε`, and goes to zero at a singularity, so no
/// force is commanded along a direction the arm cannot move in.
/// Returns the inverse and the smallest eigenvalue.
///
/// `max_iter` (≥ 1) caps the QR sweeps of the eigen-decomposition:
/// `SymmetricEigen::new` has no cap and can loop forever (nalgebra issue
/// 1025), and `try_new` with 0 means no cap either. `None` when `m` is not
/// finite (nalgebra's 2×2 step unwraps a NaN square root), when the cap is
/// reached, or when the result is not finite.
pub fn robust_inverse(m: &Matrix6<f64>, eps: f64, max_iter: usize) -> Option<(Matrix6<f64>, f64)> {
    if max_iter == 0 || !m.iter().all(|x| x.is_finite()) {
        return None;
    }
    let eig = SymmetricEigen::try_new(*m, f64::EPSILON, max_iter)?;
    let mut min_sigma = f64::INFINITY;
    let mut out = Matrix6::zeros();
    for k in 0..6 {
        let s = eig.eigenvalues[k];
        min_sigma = min_sigma.min(s);
        // Negative eigenvalues are rounding of a PSD matrix: treat as 0.
        let s = s.max(0.0);
        let w = if s >= eps { 1.0 / s } else { s / (eps * eps) };
        let col = eig.eigenvectors.column(k);
        out += w * col * col.transpose();
    }
    (out.iter().all(|x| x.is_finite()) && min_sigma.is_finite()).then_some((out, min_sigma))
}

/// The constants of one OSC evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OscParams {
    /// Singularity threshold ε, see [`robust_inverse`].
    pub singular_eps: f64,
    /// Cap on the eigen-decomposition's QR sweeps, see [`robust_inverse`].
    pub eigen_max_iter: usize,
    /// Posture stiffness of the null-space term, 1/s².
    pub null_kp: f64,
    /// Posture damping of the null-space term, 1/s.
    pub null_kv: f64,
}

/// Computes `τ_osc` and the quantities the QP filter needs. On an error the
/// results are stale and must not be used.
pub fn compute(d: &mut OscData, inp: &OscInputs<'_>, p: &OscParams) -> Result<(), OscError> {
    let nv = inp.q.len();
    inverse_from_cholesky(inp.chol, &mut d.scratch, &mut d.minv);
    mul_into(inp.jac, &d.minv, &mut d.j_minv);
    d.j_minv.transpose_to(&mut d.minv_jt);
    mul_into(inp.jac, &d.minv_jt, &mut d.lambda_inv);
    // Symmetrise: rounding leaves the two triangles a few ulps apart.
    d.lambda_inv = 0.5 * (d.lambda_inv + d.lambda_inv.transpose());
    let (lambda, min_sigma) = robust_inverse(&d.lambda_inv, p.singular_eps, p.eigen_max_iter)
        .ok_or(OscError::Decomposition)?;
    d.lambda = lambda;
    d.min_sigma = min_sigma;
    mul_into(&d.minv_jt, &d.lambda, &mut d.jbar);
    mul_into(&d.jbar, inp.jac, &mut d.jbar_j);
    for c in 0..nv {
        for r in 0..nv {
            let id = if r == c { 1.0 } else { 0.0 };
            d.null_t[(r, c)] = id - d.jbar_j[(c, r)];
        }
    }
    // Posture torque τ₀ = M (k_p (q_rest − q) − k_v v), then Nᵀ τ₀.
    for i in 0..nv {
        d.scratch[i] = p.null_kp * (inp.rest_q[i] - inp.q[i]) - p.null_kv * inp.v[i];
    }
    mul_into(inp.mass, &d.scratch, &mut d.tau0);
    mul_into(&d.null_t, &d.tau0, &mut d.tau_null);
    d.force = d.lambda * (inp.a_u - inp.jdot_v);
    tr_mul_into(inp.jac, &d.force, &mut d.tau);
    d.tau += &d.tau_null;
    d.tau += inp.h;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_inverse_is_exact_when_well_conditioned_and_bounded_when_singular() {
        let a = Matrix6::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 * 0.1);
        let spd = a * a.transpose() + 0.05 * Matrix6::identity();
        let (inv, min_s) = robust_inverse(&spd, 0.02, 180).unwrap();
        assert!(min_s >= 0.05 - 1e-12);
        let err = (inv * spd - Matrix6::identity()).norm();
        assert!(err < 1e-10, "exact above the threshold: {err}");
        // Rank-deficient: bounded by 1/ε, zero along the lost direction.
        let v = Vector6::new(1.0, 2.0, 0.0, 0.0, 1.0, 0.0);
        let rank1 = v * v.transpose() * 1e-3;
        let (inv, min_s) = robust_inverse(&rank1, 0.02, 180).unwrap();
        assert!(min_s.abs() < 1e-12);
        let e = SymmetricEigen::new(inv).eigenvalues;
        assert!(e.amax() <= 1.0 / 0.02 + 1e-9, "{e}");
        let lost = Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0);
        assert!((inv * lost).norm() < 1e-9);
        // Continuous at the threshold.
        let below = robust_inverse(&(Matrix6::identity() * (0.02 - 1e-12)), 0.02, 180)
            .unwrap()
            .0;
        let above = robust_inverse(&(Matrix6::identity() * (0.02 + 1e-12)), 0.02, 180)
            .unwrap()
            .0;
        assert!((below - above).norm() < 1e-6);
    }

    #[test]
    fn robust_inverse_gives_up_at_its_iteration_cap_and_on_non_finite_input() {
        // A dense matrix needs several QR sweeps; one is not enough.
        let a = Matrix6::from_fn(|i, j| ((i * 5 + j * 3) % 7) as f64 * 0.3 - 0.8);
        let m = a * a.transpose() + 0.1 * Matrix6::identity();
        assert!(robust_inverse(&m, 0.02, 1).is_none());
        assert!(robust_inverse(&m, 0.02, 0).is_none(), "0 would be no cap");
        assert!(robust_inverse(&m, 0.02, 180).is_some());
        let mut bad = m;
        bad[(2, 3)] = f64::NAN;
        bad[(3, 2)] = f64::NAN;
        assert!(robust_inverse(&bad, 0.02, 180).is_none());
        bad[(2, 3)] = f64::INFINITY;
        bad[(3, 2)] = f64::INFINITY;
        assert!(robust_inverse(&bad, 0.02, 180).is_none());
    }
}
