//! Forward kinematics, frame placements, Jacobians and J̇v.

use super::{check_len, joint_placement, subspace};
use crate::data::Data;
use crate::model::{FrameId, Model};
use crate::spatial::{Motion, Se3};
use nalgebra::{Isometry3, Matrix6xX, Vector3};

/// In which coordinates a frame quantity (Jacobian, velocity, acceleration)
/// is expressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reference {
    /// The classical geometric Jacobian: linear velocity of the frame's
    /// origin and angular velocity, both in base-frame axes (Pinocchio's
    /// `LOCAL_WORLD_ALIGNED`). Accelerations are classical (`p̈`, `ω̇`).
    Base,
    /// The frame's body twist in the frame's own axes (Pinocchio's `LOCAL`).
    /// Accelerations are spatial (the time derivative of the body twist).
    Local,
}

/// Placements of every joint: fills `data.li_m_i` and `data.o_m_i`.
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    check_len("q", q.len(), model.nv());
    for i in 1..model.njoints() {
        let j = &model.joints[i];
        let m = joint_placement(j, q[j.idx_v]);
        data.li_m_i[i] = m;
        data.o_m_i[i] = data.o_m_i[j.parent].mul(&m);
    }
}

/// Placements, body velocities (`data.v`) and body accelerations (`data.a`,
/// without gravity) of every joint. `a = None` means zero joint acceleration,
/// which is what J̇v needs.
pub fn forward_kinematics_second_order(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    a: Option<&[f64]>,
) {
    let nv = model.nv();
    check_len("q", q.len(), nv);
    check_len("v", v.len(), nv);
    if let Some(a) = a {
        check_len("a", a.len(), nv);
    }
    data.v[0] = Motion::ZERO;
    data.a[0] = Motion::ZERO;
    for i in 1..model.njoints() {
        let j = &model.joints[i];
        let p = j.parent;
        let k = j.idx_v;
        let m = joint_placement(j, q[k]);
        data.li_m_i[i] = m;
        data.o_m_i[i] = data.o_m_i[p].mul(&m);
        let s = subspace(j);
        let vj = s * v[k];
        let vi = m.act_inv_motion(&data.v[p]) + vj;
        let mut ai = m.act_inv_motion(&data.a[p]) + vi.cross(&vj);
        if let Some(a) = a {
            ai = ai + s * a[k];
        }
        data.v[i] = vi;
        data.a[i] = ai;
    }
}

/// Pose of a frame in the base frame, as the internal transform type.
/// Needs [`forward_kinematics`] (or the second-order pass) first.
#[inline]
pub fn frame_se3(model: &Model, data: &Data, frame: FrameId) -> Se3 {
    let f = &model.frames[frame];
    data.o_m_i[f.parent_joint].mul(&f.placement)
}

/// Pose of a frame in the base frame. Needs [`forward_kinematics`] first.
pub fn frame_placement(model: &Model, data: &Data, frame: FrameId) -> Isometry3<f64> {
    frame_se3(model, data, frame).to_isometry()
}

/// The 6×nv Jacobian of a frame (rows: linear, then angular), written into
/// `out`; columns of joints that do not move the frame are zero. Needs
/// [`forward_kinematics`] at the configuration of interest.
pub fn frame_jacobian(
    model: &Model,
    data: &Data,
    frame: FrameId,
    reference: Reference,
    out: &mut Matrix6xX<f64>,
) {
    check_len("Jacobian output columns", out.ncols(), model.nv());
    out.fill(0.0);
    let o_m_f = frame_se3(model, data, frame);
    let p = o_m_f.trans;
    let mut i = model.frames[frame].parent_joint;
    while i > 0 {
        let j = &model.joints[i];
        // The joint's unit twist in base coordinates, about the base origin.
        let c = data.o_m_i[i].act_motion(&subspace(j));
        // Velocity of the point at the frame's origin: v_O + ω × p.
        let lin = c.lin + c.ang.cross(&p);
        let (lin, ang) = match reference {
            Reference::Base => (lin, c.ang),
            Reference::Local => (o_m_f.rot.tr_mul(&lin), o_m_f.rot.tr_mul(&c.ang)),
        };
        let mut col = out.column_mut(j.idx_v);
        col[0] = lin.x;
        col[1] = lin.y;
        col[2] = lin.z;
        col[3] = ang.x;
        col[4] = ang.y;
        col[5] = ang.z;
        i = j.parent;
    }
}

/// The frame's body twist in its own axes, from `data.v`.
#[inline]
fn frame_local_velocity(model: &Model, data: &Data, frame: FrameId) -> Motion {
    let f = &model.frames[frame];
    f.placement.act_inv_motion(&data.v[f.parent_joint])
}

/// Velocity of a frame (`J v`). Needs [`forward_kinematics_second_order`].
pub fn frame_velocity(model: &Model, data: &Data, frame: FrameId, reference: Reference) -> Motion {
    let v = frame_local_velocity(model, data, frame);
    match reference {
        Reference::Local => v,
        Reference::Base => {
            let r = frame_se3(model, data, frame).rot;
            Motion::new(r * v.lin, r * v.ang)
        }
    }
}

/// Acceleration of a frame (`J a + J̇ v`): the spatial acceleration in the
/// frame's axes for [`Reference::Local`], the classical acceleration of its
/// origin (`p̈`, `ω̇`) in base axes for [`Reference::Base`]. Needs
/// [`forward_kinematics_second_order`].
pub fn frame_acceleration(
    model: &Model,
    data: &Data,
    frame: FrameId,
    reference: Reference,
) -> Motion {
    let f = &model.frames[frame];
    let a = f.placement.act_inv_motion(&data.a[f.parent_joint]);
    match reference {
        Reference::Local => a,
        Reference::Base => {
            let v = frame_local_velocity(model, data, frame);
            let r = frame_se3(model, data, frame).rot;
            // ṗ = R v_lin ⇒ p̈ = R (a_lin + ω × v_lin).
            Motion::new(r * (a.lin + v.ang.cross(&v.lin)), r * a.ang)
        }
    }
}

/// `J̇(q, v) v` of a frame in the given reference (the acceleration the frame
/// has when the joints do not accelerate), as operational-space control
/// needs. Runs its own kinematics pass, so `data` then holds `q` and `v`.
pub fn frame_jdot_v(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    frame: FrameId,
    reference: Reference,
) -> Motion {
    forward_kinematics_second_order(model, data, q, v, None);
    frame_acceleration(model, data, frame, reference)
}

/// Centre of mass of the moving bodies in the base frame (the origin when
/// nothing moves has mass). Needs [`forward_kinematics`].
pub fn center_of_mass(model: &Model, data: &Data) -> Vector3<f64> {
    let mut m = 0.0;
    let mut h = Vector3::zeros();
    for i in 1..model.njoints() {
        let y = &model.inertias[i];
        let o = &data.o_m_i[i];
        m += y.mass;
        h += o.rot * y.h + y.mass * o.trans;
    }
    if m > 0.0 { h / m } else { Vector3::zeros() }
}
