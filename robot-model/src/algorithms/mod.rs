//! The algorithms, as free functions over `(model, data, q, v, a)`.
//!
//! Every function writes its results into [`crate::Data`] (or into an output
//! the caller made) and never allocates. Input slices must have
//! [`crate::Model::nv`] entries; a wrong length is a programming error and
//! panics with the sizes involved.

pub mod dynamics;
pub mod kinematics;

use crate::model::{Joint, JointKind};
use crate::spatial::{Motion, Se3};
use nalgebra::{Matrix3, Vector3};

/// Rotation by `angle` about the unit vector `k` (Rodrigues).
#[inline]
pub(crate) fn axis_rotation(k: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    let (x, y, z) = (k.x, k.y, k.z);
    Matrix3::new(
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    )
}

/// The joint's frame in its parent joint's frame at coordinate `q`.
#[inline]
pub(crate) fn joint_placement(j: &Joint, q: f64) -> Se3 {
    match j.kind {
        JointKind::Revolute | JointKind::Continuous => Se3 {
            rot: j.placement.rot * axis_rotation(&j.axis, q),
            trans: j.placement.trans,
        },
        JointKind::Prismatic => Se3 {
            rot: j.placement.rot,
            trans: j.placement.trans + j.placement.rot * (j.axis * q),
        },
        JointKind::Root => Se3::IDENTITY,
    }
}

/// The joint's motion subspace (a unit twist) in its own frame.
#[inline]
pub(crate) fn subspace(j: &Joint) -> Motion {
    match j.kind {
        JointKind::Prismatic => Motion {
            lin: j.axis,
            ang: Vector3::zeros(),
        },
        _ => Motion {
            lin: Vector3::zeros(),
            ang: j.axis,
        },
    }
}

#[inline]
pub(crate) fn check_len(what: &str, got: usize, nv: usize) {
    assert!(
        got == nv,
        "{what} has {got} entries, the model has {nv} degrees of freedom"
    );
}
