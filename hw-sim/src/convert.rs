//! The one place where nalgebra (our API) meets glam (rapier's API), and
//! where rotations sent as quaternion arrays become nalgebra rotations.

use nalgebra::{Isometry3, Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rapier3d_f64::math::{Matrix, Pose, Rotation, Vector};

/// nalgebra → glam vector.
#[inline]
pub fn to_glam(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

/// glam → nalgebra vector.
#[inline]
pub fn from_glam(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// nalgebra → glam rotation.
#[inline]
pub fn rot_to_glam(r: &UnitQuaternion<f64>) -> Rotation {
    Rotation::from_xyzw(r.i, r.j, r.k, r.w)
}

/// glam → nalgebra rotation.
#[inline]
pub fn rot_from_glam(r: Rotation) -> UnitQuaternion<f64> {
    UnitQuaternion::new_unchecked(Quaternion::new(r.w, r.x, r.y, r.z))
}

/// nalgebra isometry → rapier pose.
#[inline]
pub fn pose_to_glam(iso: &Isometry3<f64>) -> Pose {
    Pose::from_parts(to_glam(&iso.translation.vector), rot_to_glam(&iso.rotation))
}

/// rapier pose → nalgebra isometry.
#[inline]
pub fn pose_from_glam(p: &Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(from_glam(p.translation)),
        rot_from_glam(p.rotation),
    )
}

/// nalgebra → glam 3×3 matrix.
#[inline]
pub fn mat_to_glam(m: &Matrix3<f64>) -> Matrix {
    Matrix::from_cols(
        Vector::new(m[(0, 0)], m[(1, 0)], m[(2, 0)]),
        Vector::new(m[(0, 1)], m[(1, 1)], m[(2, 1)]),
        Vector::new(m[(0, 2)], m[(1, 2)], m[(2, 2)]),
    )
}

/// A rotation sent as a unit quaternion `[x, y, z, w]` (messages, logs,
/// calibrations), taken as is when it is unit to within 1e-12:
/// renormalising it would move it by an ulp, and lockstep runs would no
/// longer match the fast path bit for bit.
pub fn unit_quaternion(xyzw: [f64; 4]) -> UnitQuaternion<f64> {
    let [x, y, z, w] = xyzw;
    let q = Quaternion::new(w, x, y, z);
    if (q.norm() - 1.0).abs() < 1e-12 {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::from_quaternion(q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_are_exact_and_act_alike() {
        let iso = Isometry3::new(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.4, -0.5, 0.6));
        let pose = pose_to_glam(&iso);
        let back = pose_from_glam(&pose);
        assert!((back.to_homogeneous() - iso.to_homogeneous()).amax() < 1e-15);
        let p = Vector3::new(0.7, 0.8, -0.9);
        let a = iso * nalgebra::Point3::from(p);
        let b = pose.transform_point(to_glam(&p));
        assert!((from_glam(b) - a.coords).amax() < 1e-15);
        let m = iso.rotation.to_rotation_matrix().into_inner();
        let gm = mat_to_glam(&m);
        assert!((from_glam(gm * to_glam(&p)) - m * p).amax() < 1e-15);
    }
}
