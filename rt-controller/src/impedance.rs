//! Cartesian impedance: `a_u = a_d + Kp·e − Kv·(v − v_d)` in the base frame,
//! 6-D (linear first). The orientation error is the rotation vector of
//! `R_d·Rᵀ` (taken on SO(3), so it is right for large errors and free of
//! Euler-angle singularities); for small errors it is `≈ θ_d − θ`.

use crate::trajectory::Reference;
use nalgebra::{Matrix3, Vector3, Vector6};
use robot_model::spatial::log3;

/// The measured end-effector state the law needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EeState {
    /// Position in the base frame, m.
    pub pos: Vector3<f64>,
    /// Orientation in the base frame.
    pub rot: Matrix3<f64>,
    /// Twist `J·v` in the base frame: linear velocity of the origin, then
    /// angular velocity.
    pub twist: Vector6<f64>,
}

/// Pose error `(x_d − x, log(R_d·Rᵀ))`, base frame.
pub fn pose_error(reference: &Reference, ee: &EeState) -> Vector6<f64> {
    let ep = reference.pos - ee.pos;
    let eo = log3(&(reference.rot * ee.rot.transpose()));
    Vector6::new(ep.x, ep.y, ep.z, eo.x, eo.y, eo.z)
}

/// The commanded task acceleration `a_u`.
pub fn task_acceleration(
    reference: &Reference,
    ee: &EeState,
    kp: &[f64; 6],
    kv: &[f64; 6],
) -> Vector6<f64> {
    let e = pose_error(reference, ee);
    let v_d = Vector6::new(
        reference.vel.x,
        reference.vel.y,
        reference.vel.z,
        reference.ang_vel.x,
        reference.ang_vel.y,
        reference.ang_vel.z,
    );
    let a_d = Vector6::new(
        reference.acc.x,
        reference.acc.y,
        reference.acc.z,
        reference.ang_acc.x,
        reference.ang_acc.y,
        reference.ang_acc.z,
    );
    let ev = v_d - ee.twist;
    Vector6::from_fn(|i, _| a_d[i] + kp[i] * e[i] + kv[i] * ev[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn reference(pos: Vector3<f64>, rot: Matrix3<f64>) -> Reference {
        Reference {
            pos,
            vel: Vector3::zeros(),
            acc: Vector3::zeros(),
            rot,
            ang_vel: Vector3::zeros(),
            ang_acc: Vector3::zeros(),
            roll: 0.0,
        }
    }

    #[test]
    fn orientation_error_is_the_rotation_taking_current_to_desired() {
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.0).into_inner();
        let axis = Vector3::new(1.0, 2.0, -0.5).normalize();
        let d = Rotation3::from_scaled_axis(axis * 2.5).into_inner() * r;
        let ee = EeState {
            pos: Vector3::zeros(),
            rot: r,
            twist: Vector6::zeros(),
        };
        let e = pose_error(&reference(Vector3::zeros(), d), &ee);
        let eo = Vector3::new(e[3], e[4], e[5]);
        assert!(
            (eo - axis * 2.5).norm() < 1e-12,
            "large angle, no Euler artefacts"
        );
    }

    #[test]
    fn law_combines_feedforward_stiffness_and_damping_per_axis() {
        let mut rf = reference(Vector3::new(0.1, 0.0, 0.0), Matrix3::identity());
        rf.acc = Vector3::new(1.0, 0.0, 0.0);
        rf.vel = Vector3::new(0.0, 0.5, 0.0);
        let ee = EeState {
            pos: Vector3::zeros(),
            rot: Matrix3::identity(),
            twist: Vector6::new(0.0, 0.0, 0.2, 0.0, 0.0, 0.0),
        };
        let kp = [100.0, 200.0, 300.0, 1.0, 1.0, 1.0];
        let kv = [20.0, 30.0, 40.0, 1.0, 1.0, 1.0];
        let a = task_acceleration(&rf, &ee, &kp, &kv);
        assert!((a[0] - (1.0 + 100.0 * 0.1)).abs() < 1e-12);
        assert!((a[1] - 30.0 * 0.5).abs() < 1e-12);
        assert!((a[2] + 40.0 * 0.2).abs() < 1e-12);
        assert_eq!(a[3], 0.0);
    }
}
