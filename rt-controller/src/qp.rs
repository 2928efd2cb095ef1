//! QP torque-limit filter. With `δ = τ − τ_osc` it solves
//!
//! ```text
//! min ½ δᵀ P δ + ½ ρ ‖s‖²,   P = J̄ W J̄ᵀ + w_N N M⁻¹ Nᵀ + ε M⁻¹
//!                             W = G + κ P⊥ G P⊥,  G = D Λ⁻¹ D,  P⊥ = I − u uᵀ
//! s.t. τ_lo − τ_osc ≤ δ ≤ τ_hi − τ_osc                 torque and torque-rate box (hard)
//!      a_lo − a_osc − s ≤ M⁻¹ δ ≤ a_hi − a_osc + s     joint position/velocity limits (soft)
//! ```
//!
//! The joint-limit rows are soft (slack `s`, heavy penalty ρ) because with a
//! torque-rate limit the robot cannot always brake as fast as they ask; a
//! hard version then has no solution at all exactly when it matters.
//!
//! `‖J̄ᵀ δ‖_W` is the error of the task force the torques produce
//! (`f = J̄ᵀ(τ − h)`), so when OSC asks for more than the robot can give the
//! filter gives up magnitude before direction, which per-joint clipping does
//! not. The part of the force error across the demanded force `u = f/‖f‖`
//! costs `1 + κ` times the shortfall along it: the plain closest point in a
//! box far from the demand is a vertex whose direction can be tens of
//! degrees off (measured: mean 13°, p95 27° with κ = 0), while giving up
//! magnitude first keeps the direction. The force error is measured in the kinetic-energy metric `Λ⁻¹` and
//! the null-space and plain errors in `M⁻¹`: an error then costs by the
//! acceleration it causes. With plain Euclidean norms a moment error on the
//! light wrist is almost free, and while the torque-rate limit binds the
//! filter used the wrist and the self-motion to make up force on the big
//! joints, which drove the wrist into oscillation (measured; see
//! docs/rt-controller.md). When `δ = 0` is feasible it is the optimum (P is positive definite,
//! there is no linear term) and the solve is skipped.
//!
//! The clarabel solver is built once with the problem's fixed sparsity
//! (P: dense upper triangle for δ, diagonal for s; A = [I 0; −I 0; M⁻¹ −I;
//! −M⁻¹ −I]) and only its values are updated each cycle, which needs presolve
//! off and structural zeros kept.

use crate::config::QpConfig;
use crate::linalg::{mul_into, tr_mul_into};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};
use nalgebra::{DMatrix, DVector, Dyn, Matrix6, Matrix6xX, OMatrix, U6, Vector6};

/// Acceleration bounds beyond this (rad/s²) are treated as absent: the
/// solver wants finite data and no joint can get near it.
const ACC_BOUND_CAP: f64 = 1e6;

/// What the filter did in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpOutcome {
    /// The OSC torques satisfied every constraint and were passed through.
    Skipped,
    /// The QP was solved.
    Solved {
        /// Interior-point iterations used.
        iterations: u32,
    },
    /// The solver failed; the OSC torques were clipped to the box instead.
    Fallback(SolverStatus),
}

/// The data of one filter problem.
pub struct QpProblem<'a> {
    /// Dynamically consistent inverse `J̄` (n×6).
    pub jbar: &'a OMatrix<f64, Dyn, U6>,
    /// The task force OSC demands, `f = Λ(a_u − J̇v)`: its direction is the
    /// one the filter protects.
    pub task_force: &'a Vector6<f64>,
    /// Inverse task-space inertia `Λ⁻¹`: the metric of the force error.
    pub lambda_inv: &'a Matrix6<f64>,
    /// Null-space projector transpose `Nᵀ` (n×n).
    pub null_t: &'a DMatrix<f64>,
    /// Inverse mass matrix.
    pub minv: &'a DMatrix<f64>,
    /// The OSC torques.
    pub tau_osc: &'a DVector<f64>,
    /// Joint accelerations the OSC torques produce, `M⁻¹(τ_osc − h)`.
    pub a_osc: &'a DVector<f64>,
    /// Lower torque bound per joint (torque and rate limits intersected).
    pub tau_lo: &'a DVector<f64>,
    /// Upper torque bound per joint.
    pub tau_hi: &'a DVector<f64>,
    /// Lower joint acceleration bound.
    pub acc_lo: &'a DVector<f64>,
    /// Upper joint acceleration bound.
    pub acc_hi: &'a DVector<f64>,
}

/// The filter: a reused clarabel solver and its value buffers.
pub struct QpFilter {
    nv: usize,
    solver: DefaultSolver<f64>,
    p_vals: Vec<f64>,
    a_vals: Vec<f64>,
    b: Vec<f64>,
    q: Vec<f64>,
    sqrt_w: [f64; 6],
    direction_weight: f64,
    null_weight: f64,
    regularization: f64,
    w_mat: Matrix6<f64>,
    jbar_w: OMatrix<f64, Dyn, U6>,
    w_jbar_t: Matrix6xX<f64>,
    p_full: DMatrix<f64>,
    minv_nt: DMatrix<f64>,
    p_null: DMatrix<f64>,
}

/// P's pattern in CSC order: dense upper triangle for the n torque columns,
/// the diagonal for the n slack columns.
fn hessian_pattern(n: usize) -> (Vec<usize>, Vec<usize>) {
    let mut colptr = Vec::with_capacity(2 * n + 1);
    let mut rowval = Vec::new();
    colptr.push(0);
    for j in 0..n {
        rowval.extend(0..=j);
        colptr.push(rowval.len());
    }
    for j in n..2 * n {
        rowval.push(j);
        colptr.push(rowval.len());
    }
    (colptr, rowval)
}

/// A's pattern: `[I 0; −I 0; D −I; −D −I]` with a dense D, 4n rows.
fn constraint_pattern(n: usize) -> (Vec<usize>, Vec<usize>) {
    let mut colptr = Vec::with_capacity(2 * n + 1);
    let mut rowval = Vec::new();
    colptr.push(0);
    for j in 0..n {
        rowval.push(j);
        rowval.push(n + j);
        rowval.extend((0..n).map(|i| 2 * n + i));
        rowval.extend((0..n).map(|i| 3 * n + i));
        colptr.push(rowval.len());
    }
    for j in 0..n {
        rowval.push(2 * n + j);
        rowval.push(3 * n + j);
        colptr.push(rowval.len());
    }
    (colptr, rowval)
}

impl QpFilter {
    /// Builds the solver for `nv` joints. The problem is set up once with
    /// representative values (`minv`, typically `M⁻¹` at the rest pose) that
    /// fix clarabel's equilibration scaling.
    pub fn new(nv: usize, cfg: &QpConfig, minv: &DMatrix<f64>) -> Self {
        let (pc, pr) = hessian_pattern(nv);
        let (ac, ar) = constraint_pattern(nv);
        let mut p_vals = vec![0.0; pr.len()];
        let mut k = 0;
        for j in 0..nv {
            for i in 0..=j {
                p_vals[k] = if i == j { 1.0 } else { 0.0 };
                k += 1;
            }
        }
        for v in &mut p_vals[k..] {
            *v = cfg.limit_slack_weight;
        }
        let mut a_vals = vec![0.0; ar.len()];
        Self::fill_a(nv, minv, &mut a_vals);
        let p = CscMatrix::new(2 * nv, 2 * nv, pc, pr, p_vals.clone());
        let a = CscMatrix::new(4 * nv, 2 * nv, ac, ar, a_vals.clone());
        let q = vec![0.0; 2 * nv];
        let b = vec![1.0; 4 * nv];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(cfg.max_iter)
            .time_limit(cfg.time_limit_s.unwrap_or(f64::INFINITY))
            .build()
            .expect("clarabel settings are valid");
        let cones = [NonnegativeConeT(4 * nv)];
        let solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
            .expect("the filter's QP data are well formed by construction");
        Self {
            nv,
            solver,
            p_vals,
            a_vals,
            b,
            q,
            sqrt_w: cfg.task_weight.map(f64::sqrt),
            direction_weight: cfg.direction_weight,
            null_weight: cfg.null_weight,
            regularization: cfg.regularization,
            w_mat: Matrix6::zeros(),
            jbar_w: OMatrix::<f64, Dyn, U6>::zeros(nv),
            w_jbar_t: Matrix6xX::zeros(nv),
            p_full: DMatrix::zeros(nv, nv),
            minv_nt: DMatrix::zeros(nv, nv),
            p_null: DMatrix::zeros(nv, nv),
        }
    }

    fn fill_a(nv: usize, minv: &DMatrix<f64>, a_vals: &mut [f64]) {
        let mut k = 0;
        for j in 0..nv {
            a_vals[k] = 1.0;
            a_vals[k + 1] = -1.0;
            k += 2;
            for i in 0..nv {
                a_vals[k + i] = minv[(i, j)];
                a_vals[k + nv + i] = -minv[(i, j)];
            }
            k += 2 * nv;
        }
        for _ in 0..nv {
            a_vals[k] = -1.0;
            a_vals[k + 1] = -1.0;
            k += 2;
        }
    }

    /// Whether the OSC torques already satisfy every constraint.
    pub fn is_feasible(pb: &QpProblem<'_>) -> bool {
        let n = pb.tau_osc.len();
        (0..n).all(|i| {
            let t = pb.tau_osc[i];
            let a = pb.a_osc[i];
            t >= pb.tau_lo[i] && t <= pb.tau_hi[i] && a >= pb.acc_lo[i] && a <= pb.acc_hi[i]
        })
    }

    /// Filters `pb.tau_osc` into `out`. `out` always ends inside the torque
    /// box `[tau_lo, tau_hi]`, whatever the solver does (and finite when the
    /// box is: a NaN torque becomes the box's point nearest 0, a box with a
    /// NaN bound or `lo > hi` gives 0). The caller keeps NaN out of `pb`.
    pub fn filter(&mut self, pb: &QpProblem<'_>, out: &mut DVector<f64>) -> QpOutcome {
        let n = self.nv;
        if Self::is_feasible(pb) {
            out.copy_from(pb.tau_osc);
            return QpOutcome::Skipped;
        }
        // P = J̄ W J̄ᵀ + w_N N M⁻¹ Nᵀ + ε M⁻¹ with W = G + κ P⊥ G P⊥,
        // G = D Λ⁻¹ D, D = diag(√w), P⊥ = I − u uᵀ across the demanded force u.
        let g = Matrix6::from_fn(|r, c| self.sqrt_w[r] * pb.lambda_inv[(r, c)] * self.sqrt_w[c]);
        let norm = pb.task_force.norm();
        self.w_mat = if self.direction_weight > 0.0 && norm > 1e-9 {
            let u = pb.task_force / norm;
            let p_perp = Matrix6::identity() - u * u.transpose();
            g + self.direction_weight * (p_perp * g * p_perp)
        } else {
            g
        };
        mul_into(pb.jbar, &self.w_mat, &mut self.jbar_w);
        self.jbar_w.transpose_to(&mut self.w_jbar_t);
        mul_into(pb.jbar, &self.w_jbar_t, &mut self.p_full);
        mul_into(pb.minv, pb.null_t, &mut self.minv_nt);
        tr_mul_into(pb.null_t, &self.minv_nt, &mut self.p_null);
        let mut k = 0;
        for j in 0..n {
            for i in 0..=j {
                self.p_vals[k] = self.p_full[(i, j)]
                    + self.null_weight * self.p_null[(i, j)]
                    + self.regularization * pb.minv[(i, j)];
                k += 1;
            }
        }
        // The slack block (the penalty ρ) never changes.
        Self::fill_a(n, pb.minv, &mut self.a_vals);
        for i in 0..n {
            let t = pb.tau_osc[i];
            let a = pb.a_osc[i];
            let acc_hi = pb.acc_hi[i].min(ACC_BOUND_CAP);
            let acc_lo = pb.acc_lo[i].max(-ACC_BOUND_CAP);
            self.b[i] = pb.tau_hi[i] - t;
            self.b[n + i] = t - pb.tau_lo[i];
            self.b[2 * n + i] = acc_hi - a;
            self.b[3 * n + i] = a - acc_lo;
        }
        let updated = self
            .solver
            .update_P(&self.p_vals)
            .and_then(|_| self.solver.update_A(&self.a_vals))
            .and_then(|_| self.solver.update_q(&self.q))
            .and_then(|_| self.solver.update_b(&self.b));
        let status = if updated.is_ok() {
            self.solver.solve();
            self.solver.solution.status
        } else {
            SolverStatus::NumericalError
        };
        let x = &self.solver.solution.x;
        let ok = matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved)
            && x.iter().all(|v| v.is_finite());
        for i in 0..n {
            let t = if ok {
                pb.tau_osc[i] + x[i]
            } else {
                pb.tau_osc[i]
            };
            // The interior-point answer is feasible to tolerance; the box is
            // made exact here because torque limits are hard (and without
            // `f64::clamp`, which panics on a NaN bound).
            out[i] = crate::clamp_torque(t, pb.tau_lo[i], pb.tau_hi[i]);
        }
        if ok {
            QpOutcome::Solved {
                iterations: self.solver.solution.iterations,
            }
        } else {
            QpOutcome::Fallback(status)
        }
    }
}
