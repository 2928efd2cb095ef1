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

/// `p * R(axis, angle)`. Rotations about a coordinate axis (every joint of
/// the shipped arms) only mix two columns of `p`, a fraction of the cost of
/// a general 3×3 product.
#[inline(always)]
fn rotate_about(
    p: &Matrix3<f64>,
    axis: &Vector3<f64>,
    aligned: Option<usize>,
    angle: f64,
) -> Matrix3<f64> {
    let Some(k) = aligned else {
        return p * axis_rotation(axis, angle);
    };
    // Columns (a, b) span the plane of rotation, right-handed about +axis.
    let (a, b) = ((k + 1) % 3, (k + 2) % 3);
    let (s, c) = angle.sin_cos();
    let s = if axis[k] > 0.0 { s } else { -s };
    let mut out = *p;
    let (pa, pb) = (p.column(a).into_owned(), p.column(b).into_owned());
    out.set_column(a, &(pa * c + pb * s));
    out.set_column(b, &(pb * c - pa * s));
    out
}

/// The joint's frame in its parent joint's frame at coordinate `q`.
// Forced: left out of line it returns its Se3 through memory, 14% of CRBA
// (docs/performance.md).
#[inline(always)]
pub(crate) fn joint_placement(j: &Joint, q: f64) -> Se3 {
    match j.kind {
        JointKind::Revolute | JointKind::Continuous => Se3 {
            rot: rotate_about(&j.placement.rot, &j.axis, j.aligned_axis(), q),
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

/// `Sᵀ f`: the joint's share of a spatial force (torque or axial force).
#[inline]
pub(crate) fn subspace_dot(j: &Joint, f: &crate::spatial::Force) -> f64 {
    match j.kind {
        JointKind::Prismatic => j.axis.dot(&f.lin),
        _ => j.axis.dot(&f.ang),
    }
}

#[inline]
pub(crate) fn check_len(what: &str, got: usize, nv: usize) {
    assert!(
        got == nv,
        "{what} has {got} entries, the model has {nv} degrees of freedom"
    );
}
