//! Inverse dynamics (RNEA), the mass matrix (CRBA), gravity, nonlinear
//! effects, the Coriolis matrix, energies and forward dynamics.

use super::{check_len, joint_placement, subspace, subspace_dot};
use crate::data::Data;
use crate::error::DynamicsError;
use crate::model::Model;
use crate::spatial::{Inertia, Motion, force_cross_bar_matrix};
use nalgebra::{DMatrix, DVector};

/// RNEA into `data.tau`, with optional velocity and acceleration (absent is
/// zero) and optional gravity.
fn rnea_impl(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: Option<&[f64]>,
    a: Option<&[f64]>,
    with_gravity: bool,
) {
    data.v[0] = Motion::ZERO;
    data.a_gf[0] = if with_gravity {
        // Accelerating the base upwards stands in for gravity.
        Motion::new(-model.gravity, nalgebra::Vector3::zeros())
    } else {
        Motion::ZERO
    };
    for i in 1..model.njoints() {
        let j = &model.joints[i];
        let p = j.parent;
        let k = j.idx_v;
        let m = joint_placement(j, q[k]);
        data.li_m_i[i] = m;
        let s = subspace(j);
        let y = &model.inertias[i];
        let mut ai = m.act_inv_motion(&data.a_gf[p]);
        if let Some(a) = a {
            ai = ai + s * a[k];
        }
        if let Some(v) = v {
            let vj = s * v[k];
            let vi = m.act_inv_motion(&data.v[p]) + vj;
            ai = ai + vi.cross(&vj);
            data.v[i] = vi;
            data.f[i] = y.mul_motion(&ai) + vi.cross_force(&y.mul_motion(&vi));
        } else {
            data.v[i] = Motion::ZERO;
            data.f[i] = y.mul_motion(&ai);
        }
        data.a_gf[i] = ai;
    }
    for i in (1..model.njoints()).rev() {
        let j = &model.joints[i];
        data.tau[j.idx_v] = subspace_dot(j, &data.f[i]);
        if j.parent > 0 {
            let fp = data.li_m_i[i].act_force(&data.f[i]);
            data.f[j.parent] += fp;
        }
    }
}

/// Inverse dynamics: `τ = M(q) a + C(q, v) v + g(q)`, into `data.tau`.
pub fn rnea<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &[f64],
    v: &[f64],
    a: &[f64],
) -> &'a DVector<f64> {
    let nv = model.nv();
    check_len("q", q.len(), nv);
    check_len("v", v.len(), nv);
    check_len("a", a.len(), nv);
    rnea_impl(model, data, q, Some(v), Some(a), true);
    &data.tau
}

/// Generalised gravity `g(q)` (the torques that hold the robot still), into
/// `data.g`.
pub fn gravity<'a>(model: &Model, data: &'a mut Data, q: &[f64]) -> &'a DVector<f64> {
    check_len("q", q.len(), model.nv());
    rnea_impl(model, data, q, None, None, true);
    data.g.copy_from(&data.tau);
    &data.g
}

/// Nonlinear effects `h = C(q, v) v + g(q)`, into `data.nle`.
pub fn nonlinear_effects<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &[f64],
    v: &[f64],
) -> &'a DVector<f64> {
    let nv = model.nv();
    check_len("q", q.len(), nv);
    check_len("v", v.len(), nv);
    rnea_impl(model, data, q, Some(v), None, true);
    data.nle.copy_from(&data.tau);
    &data.nle
}

/// Joint-space mass matrix `M(q)` by the composite-rigid-body algorithm,
/// into `data.mass` (both triangles filled).
pub fn crba<'a>(model: &Model, data: &'a mut Data, q: &[f64]) -> &'a DMatrix<f64> {
    check_len("q", q.len(), model.nv());
    let nj = model.njoints();
    for i in 1..nj {
        let j = &model.joints[i];
        data.li_m_i[i] = joint_placement(j, q[j.idx_v]);
        data.ic[i] = model.inertias[i];
    }
    for i in (1..nj).rev() {
        let ji = &model.joints[i];
        let col = ji.idx_v;
        // Force needed to accelerate joint i's subtree at unit rate, carried
        // down the chain to every ancestor.
        let mut f = data.ic[i].mul_motion(&subspace(ji));
        data.mass[(col, col)] = subspace_dot(ji, &f);
        let mut k = i;
        while model.joints[k].parent > 0 {
            f = data.li_m_i[k].act_force(&f);
            k = model.joints[k].parent;
            let jk = &model.joints[k];
            let val = subspace_dot(jk, &f);
            data.mass[(jk.idx_v, col)] = val;
            data.mass[(col, jk.idx_v)] = val;
        }
        if ji.parent > 0 {
            let y = data.li_m_i[i].act_inertia(&data.ic[i]);
            data.ic[ji.parent] += y;
        }
    }
    &data.mass
}

/// The Coriolis matrix `C(q, v)`, factorised so that `C v` is the velocity
/// part of the nonlinear effects and `Ṁ − 2C` is skew-symmetric, into
/// `data.coriolis`.
///
/// With world-frame body inertias `Iᵢ`, twists `vᵢ` and joint columns `Sⱼ`,
/// `C = Σᵢ Jᵢᵀ (Iᵢ J̇ᵢ + Bᵢ Jᵢ)` where
/// `Bᵢ = ½ (vᵢ×* Iᵢ − Iᵢ vᵢ× + (Iᵢ vᵢ)×̄)` and `f×̄` is the skew matrix of
/// `m ↦ m ×* f`; the sums over bodies become composite sums over subtrees.
pub fn coriolis_matrix<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &[f64],
    v: &[f64],
) -> &'a DMatrix<f64> {
    super::kinematics::forward_kinematics_second_order(model, data, q, v, None);
    let nj = model.njoints();
    for i in 1..nj {
        let o = data.o_m_i[i];
        let s_w = o.act_motion(&subspace(&model.joints[i]));
        let v_w = o.act_motion(&data.v[i]);
        data.c_s[i] = s_w.to_vector();
        data.c_sdot[i] = v_w.cross(&s_w).to_vector();
        let y_w = o.act_inertia(&model.inertias[i]);
        let ym = y_w.to_matrix();
        let vx = v_w.cross_matrix();
        let h = y_w.mul_motion(&v_w);
        data.c_ic[i] = ym;
        data.c_bc[i] = 0.5 * (-(vx.transpose() * ym) - ym * vx + force_cross_bar_matrix(&h));
    }
    for i in (2..nj).rev() {
        let p = model.joints[i].parent;
        if p > 0 {
            let (ic, bc) = (data.c_ic[i], data.c_bc[i]);
            data.c_ic[p] += ic;
            data.c_bc[p] += bc;
        }
    }
    data.coriolis.fill(0.0);
    for k in 1..nj {
        // Pairs (j, k) with j an ancestor of k (or k itself): the deepest is k.
        let w = data.c_ic[k] * data.c_sdot[k] + data.c_bc[k] * data.c_s[k];
        let ck = model.joints[k].idx_v;
        let mut j = k;
        while j > 0 {
            data.coriolis[(model.joints[j].idx_v, ck)] = data.c_s[j].dot(&w);
            j = model.joints[j].parent;
        }
        // Pairs (k, j) with j a strict ancestor of k: the deepest is k.
        let mut j = model.joints[k].parent;
        while j > 0 {
            let w = data.c_ic[k] * data.c_sdot[j] + data.c_bc[k] * data.c_s[j];
            data.coriolis[(ck, model.joints[j].idx_v)] = data.c_s[k].dot(&w);
            j = model.joints[j].parent;
        }
    }
    &data.coriolis
}

/// Kinetic energy `½ vᵀ M(q) v`, J. Leaves the kinematics of (q, v) in `data`.
pub fn kinetic_energy(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> f64 {
    super::kinematics::forward_kinematics_second_order(model, data, q, v, None);
    (1..model.njoints())
        .map(|i| model.inertias[i].kinetic_energy(&data.v[i]))
        .sum()
}

/// Gravitational potential energy of the moving bodies relative to the base
/// origin, J. Leaves the placements of q in `data`.
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> f64 {
    super::kinematics::forward_kinematics(model, data, q);
    (1..model.njoints())
        .map(|i| {
            let y: &Inertia = &model.inertias[i];
            let o = &data.o_m_i[i];
            -model.gravity.dot(&(o.rot * y.h + y.mass * o.trans))
        })
        .sum()
}

/// Forward dynamics `a = M(q)⁻¹ (τ − h(q, v))` by CRBA, RNEA and a Cholesky
/// solve, into `data.ddq` (the factor stays in `data.chol`).
pub fn forward_dynamics<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
) -> Result<&'a DVector<f64>, DynamicsError> {
    check_len("tau", tau.len(), model.nv());
    nonlinear_effects(model, data, q, v);
    crba(model, data, q);
    cholesky_factor(&data.mass, &mut data.chol)?;
    for ((d, t), h) in data.ddq.iter_mut().zip(tau).zip(data.nle.iter()) {
        *d = t - h;
    }
    cholesky_solve_in_place(&data.chol, data.ddq.as_mut_slice());
    Ok(&data.ddq)
}

/// Lower Cholesky factor `L` of a symmetric positive-definite `a` (`a = L Lᵀ`),
/// written into `l` (same size; its upper triangle is zeroed). Reads only
/// the lower triangle of `a`.
pub fn cholesky_factor(a: &DMatrix<f64>, l: &mut DMatrix<f64>) -> Result<(), DynamicsError> {
    let n = a.nrows();
    assert!(
        a.ncols() == n && l.nrows() == n && l.ncols() == n,
        "cholesky_factor: size mismatch"
    );
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        // Also catches NaN.
        if d.is_nan() || d <= 0.0 {
            return Err(DynamicsError::SingularMassMatrix { pivot: j, value: d });
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in (j + 1)..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / ljj;
        }
        for i in 0..j {
            l[(i, j)] = 0.0;
        }
    }
    Ok(())
}

/// Solves `L Lᵀ x = b` in place (`b` becomes `x`), `L` from [`cholesky_factor`].
pub fn cholesky_solve_in_place(l: &DMatrix<f64>, b: &mut [f64]) {
    let n = l.nrows();
    assert!(b.len() == n, "cholesky_solve_in_place: size mismatch");
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[(i, k)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in (i + 1)..n {
            s -= l[(k, i)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
}
