//! Spatial algebra: rigid transforms, 6-D motion and force vectors and rigid
//! body inertias, with the operations the recursive algorithms need.
//!
//! Conventions (as Pinocchio): 6-D vectors are ordered linear part first,
//! then angular part. A motion vector `(v, ω)` of a body, expressed in a frame
//! `A`, gives the velocity `v` of the body-fixed point that coincides with the
//! origin of `A`, and its angular velocity `ω`, both in `A`'s coordinates. A
//! force `(f, n)` expressed in `A` is the resultant force and the moment about
//! `A`'s origin.
//!
//! Rotations are stored as matrices rather than quaternions: composing and
//! applying them is what the hot loops do, and matrices are cheaper for both.

use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A rigid transform `a_M_b`: maps coordinates in frame `b` to frame `a`
/// (`p_a = rot * p_b + trans`). `trans` is the position of `b`'s origin in `a`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Se3 {
    /// Rotation matrix, columns are `b`'s axes in `a`.
    pub rot: Matrix3<f64>,
    /// Position of `b`'s origin in `a`, metres.
    pub trans: Vector3<f64>,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Se3 {
    /// The identity transform.
    pub const IDENTITY: Se3 = Se3 {
        rot: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        trans: Vector3::new(0.0, 0.0, 0.0),
    };

    /// A transform from its rotation matrix and translation.
    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Self { rot, trans }
    }

    /// A transform from URDF `xyz` and `rpy` (fixed-axis roll, pitch, yaw:
    /// `R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        let rot = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        Self {
            rot: *rot.matrix(),
            trans: Vector3::from(xyz),
        }
    }

    /// Converts from an isometry (quaternion rotation).
    pub fn from_isometry(iso: &Isometry3<f64>) -> Self {
        Self {
            rot: *iso.rotation.to_rotation_matrix().matrix(),
            trans: iso.translation.vector,
        }
    }

    /// Converts to an isometry, the pose type of the public API.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        let rot = Rotation3::from_matrix_unchecked(self.rot);
        Isometry3::from_parts(
            Translation3::from(self.trans),
            UnitQuaternion::from_rotation_matrix(&rot),
        )
    }

    /// Composition `self * other` (`a_M_b * b_M_c = a_M_c`).
    #[inline]
    pub fn mul(&self, other: &Se3) -> Se3 {
        Se3 {
            rot: self.rot * other.rot,
            trans: self.rot * other.trans + self.trans,
        }
    }

    /// The inverse transform `b_M_a`.
    #[inline]
    pub fn inverse(&self) -> Se3 {
        let rt = self.rot.transpose();
        Se3 {
            rot: rt,
            trans: -(rt * self.trans),
        }
    }

    /// Maps a point from `b` to `a`.
    #[inline]
    pub fn act_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }

    /// Expresses in `a` a motion vector given in `b`.
    #[inline]
    pub fn act_motion(&self, m: &Motion) -> Motion {
        let ang = self.rot * m.ang;
        Motion {
            lin: self.rot * m.lin + self.trans.cross(&ang),
            ang,
        }
    }

    /// Expresses in `b` a motion vector given in `a`.
    #[inline]
    pub fn act_inv_motion(&self, m: &Motion) -> Motion {
        let rt = self.rot.transpose();
        Motion {
            lin: rt * (m.lin - self.trans.cross(&m.ang)),
            ang: rt * m.ang,
        }
    }

    /// Expresses in `a` a force given in `b`.
    #[inline]
    pub fn act_force(&self, f: &Force) -> Force {
        let lin = self.rot * f.lin;
        Force {
            lin,
            ang: self.rot * f.ang + self.trans.cross(&lin),
        }
    }

    /// Expresses in `b` a force given in `a`.
    #[inline]
    pub fn act_inv_force(&self, f: &Force) -> Force {
        let rt = self.rot.transpose();
        Force {
            lin: rt * f.lin,
            ang: rt * (f.ang - self.trans.cross(&f.lin)),
        }
    }

    /// Expresses in `a` a rigid-body inertia given in `b`.
    // Forced for the same reason as `joint_placement`: 16% of CRBA when called.
    #[inline(always)]
    pub fn act_inertia(&self, y: &Inertia) -> Inertia {
        let rh = self.rot * y.h;
        let p = &self.trans;
        // About the new origin: R I Rᵀ − ([Rh]ₓ[p]ₓ + [p]ₓ[Rh]ₓ) − m[p]ₓ², written
        // with [a]ₓ[b]ₓ = b aᵀ − (a·b) 1.
        let cross_terms = p * rh.transpose() + rh * p.transpose();
        let rot_i = self.rot * y.rot_inertia * self.rot.transpose() - cross_terms
            + Matrix3::from_diagonal_element(2.0 * p.dot(&rh))
            + y.mass * (Matrix3::from_diagonal_element(p.dot(p)) - p * p.transpose());
        Inertia {
            mass: y.mass,
            h: rh + y.mass * p,
            rot_inertia: rot_i,
        }
    }
}

/// A spatial motion vector (twist or spatial acceleration): linear part
/// first, then angular part.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    /// Linear part (m/s or m/s²).
    pub lin: Vector3<f64>,
    /// Angular part (rad/s or rad/s²).
    pub ang: Vector3<f64>,
}

impl Motion {
    /// The zero motion.
    pub const ZERO: Motion = Motion {
        lin: Vector3::new(0.0, 0.0, 0.0),
        ang: Vector3::new(0.0, 0.0, 0.0),
    };

    /// A motion from its linear and angular parts.
    pub fn new(lin: Vector3<f64>, ang: Vector3<f64>) -> Self {
        Self { lin, ang }
    }

    /// Motion cross product `self × m` (derivative of `m` moving with `self`).
    #[inline]
    pub fn cross(&self, m: &Motion) -> Motion {
        Motion {
            lin: self.ang.cross(&m.lin) + self.lin.cross(&m.ang),
            ang: self.ang.cross(&m.ang),
        }
    }

    /// Dual cross product `self ×* f` acting on a force.
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            lin: self.ang.cross(&f.lin),
            ang: self.ang.cross(&f.ang) + self.lin.cross(&f.lin),
        }
    }

    /// Power pairing `selfᵀ f`.
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        self.lin.dot(&f.lin) + self.ang.dot(&f.ang)
    }

    /// The 6×6 matrix of `self ×` (motion cross product).
    pub fn cross_matrix(&self) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        let w = self.ang.cross_matrix();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
        m.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&self.lin.cross_matrix());
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&w);
        m
    }

    /// As a 6-vector `[lin; ang]`.
    pub fn to_vector(&self) -> nalgebra::Vector6<f64> {
        nalgebra::Vector6::new(
            self.lin.x, self.lin.y, self.lin.z, self.ang.x, self.ang.y, self.ang.z,
        )
    }

    /// From a 6-vector `[lin; ang]`.
    pub fn from_vector(v: &nalgebra::Vector6<f64>) -> Self {
        Self {
            lin: Vector3::new(v[0], v[1], v[2]),
            ang: Vector3::new(v[3], v[4], v[5]),
        }
    }
}

impl std::ops::Add for Motion {
    type Output = Motion;
    #[inline]
    fn add(self, o: Motion) -> Motion {
        Motion {
            lin: self.lin + o.lin,
            ang: self.ang + o.ang,
        }
    }
}

impl std::ops::Sub for Motion {
    type Output = Motion;
    #[inline]
    fn sub(self, o: Motion) -> Motion {
        Motion {
            lin: self.lin - o.lin,
            ang: self.ang - o.ang,
        }
    }
}

impl std::ops::Mul<f64> for Motion {
    type Output = Motion;
    #[inline]
    fn mul(self, s: f64) -> Motion {
        Motion {
            lin: self.lin * s,
            ang: self.ang * s,
        }
    }
}

/// A spatial force (wrench): force first, then moment about the frame origin.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Force {
    /// Resultant force, N.
    pub lin: Vector3<f64>,
    /// Moment about the frame's origin, N·m.
    pub ang: Vector3<f64>,
}

impl Force {
    /// The zero force.
    pub const ZERO: Force = Force {
        lin: Vector3::new(0.0, 0.0, 0.0),
        ang: Vector3::new(0.0, 0.0, 0.0),
    };

    /// A force from its linear and angular parts.
    pub fn new(lin: Vector3<f64>, ang: Vector3<f64>) -> Self {
        Self { lin, ang }
    }
}

impl std::ops::Add for Force {
    type Output = Force;
    #[inline]
    fn add(self, o: Force) -> Force {
        Force {
            lin: self.lin + o.lin,
            ang: self.ang + o.ang,
        }
    }
}

impl std::ops::AddAssign for Force {
    #[inline]
    fn add_assign(&mut self, o: Force) {
        self.lin += o.lin;
        self.ang += o.ang;
    }
}

impl std::ops::Sub for Force {
    type Output = Force;
    #[inline]
    fn sub(self, o: Force) -> Force {
        Force {
            lin: self.lin - o.lin,
            ang: self.ang - o.ang,
        }
    }
}

/// A rigid-body inertia expressed about a frame's origin, stored in the form
/// that is linear in the body's mass distribution: mass `m`, first moment
/// `h = m c` and rotational inertia about the origin. Sums of inertias (the
/// composite bodies of CRBA) are then plain sums, massless bodies included.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertia {
    /// Mass, kg.
    pub mass: f64,
    /// First moment of mass `m c`, kg·m.
    pub h: Vector3<f64>,
    /// Rotational inertia about the frame's origin (not the centre of mass), kg·m².
    pub rot_inertia: Matrix3<f64>,
}

impl Default for Inertia {
    fn default() -> Self {
        Self::ZERO
    }
}

impl Inertia {
    /// A massless body.
    pub const ZERO: Inertia = Inertia {
        mass: 0.0,
        h: Vector3::new(0.0, 0.0, 0.0),
        rot_inertia: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// From mass, centre of mass and the inertia tensor about the centre of
    /// mass (parallel-axis theorem).
    pub fn from_com(mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) -> Self {
        let shift = mass * (Matrix3::from_diagonal_element(com.dot(&com)) - com * com.transpose());
        Self {
            mass,
            h: mass * com,
            rot_inertia: inertia_com + shift,
        }
    }

    /// Centre of mass (the origin for a massless body).
    pub fn com(&self) -> Vector3<f64> {
        if self.mass > 0.0 {
            self.h / self.mass
        } else {
            Vector3::zeros()
        }
    }

    /// Inertia tensor about the centre of mass.
    pub fn inertia_about_com(&self) -> Matrix3<f64> {
        let c = self.com();
        self.rot_inertia
            - self.mass * (Matrix3::from_diagonal_element(c.dot(&c)) - c * c.transpose())
    }

    /// Momentum `I v` of the body moving with `v`.
    #[inline]
    pub fn mul_motion(&self, v: &Motion) -> Force {
        Force {
            lin: self.mass * v.lin + v.ang.cross(&self.h),
            ang: self.h.cross(&v.lin) + self.rot_inertia * v.ang,
        }
    }

    /// Kinetic energy `½ vᵀ I v`.
    #[inline]
    pub fn kinetic_energy(&self, v: &Motion) -> f64 {
        0.5 * v.dot(&self.mul_motion(v))
    }

    /// The 6×6 spatial inertia matrix `[[m 1, −[h]ₓ], [[h]ₓ, I]]`.
    pub fn to_matrix(&self) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        let hx = self.h.cross_matrix();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::from_diagonal_element(self.mass));
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-hx));
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx);
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.rot_inertia);
        m
    }
}

impl std::ops::Add for Inertia {
    type Output = Inertia;
    #[inline]
    fn add(self, o: Inertia) -> Inertia {
        Inertia {
            mass: self.mass + o.mass,
            h: self.h + o.h,
            rot_inertia: self.rot_inertia + o.rot_inertia,
        }
    }
}

impl std::ops::AddAssign for Inertia {
    #[inline]
    fn add_assign(&mut self, o: Inertia) {
        self.mass += o.mass;
        self.h += o.h;
        self.rot_inertia += o.rot_inertia;
    }
}

/// The matrix of `m ↦ m ×* f`: skew-symmetric, used to build the Coriolis
/// matrix so that `Ṁ − 2C` is skew-symmetric.
pub(crate) fn force_cross_bar_matrix(f: &Force) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    let fx = f.lin.cross_matrix();
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-fx));
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-fx));
    m.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-f.ang.cross_matrix()));
    m
}

/// Logarithm of a rotation matrix as a rotation vector (axis × angle),
/// accurate for small angles (where acos-based formulas lose half the
/// digits) and well defined up to π.
pub fn log3(rot: &Matrix3<f64>) -> Vector3<f64> {
    // vee(R − Rᵀ)/2 = sin θ · axis; (tr R − 1)/2 = cos θ.
    let w = 0.5
        * Vector3::new(
            rot[(2, 1)] - rot[(1, 2)],
            rot[(0, 2)] - rot[(2, 0)],
            rot[(1, 0)] - rot[(0, 1)],
        );
    let s = w.norm();
    let c = 0.5 * (rot.trace() - 1.0);
    let theta = s.atan2(c);
    if theta < 1e-8 {
        // θ/sin θ = 1 to machine precision.
        return w;
    }
    if theta < std::f64::consts::PI - 1e-6 {
        return w * (theta / s);
    }
    // Near π the skew part vanishes; the axis comes from the symmetric part.
    Rotation3::from_matrix_unchecked(*rot).scaled_axis()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_se3() -> Se3 {
        Se3::from_xyz_rpy([0.3, -0.2, 0.5], [0.4, -1.1, 2.0])
    }

    #[test]
    fn log3_inverts_exp_at_all_angles() {
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        for angle in [
            0.0,
            1e-12,
            1e-7,
            1e-3,
            0.5,
            2.0,
            3.0,
            std::f64::consts::PI - 1e-7,
        ] {
            let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
            let w = log3(r.matrix());
            assert!(
                (w - axis * angle).norm() < 1e-9 * angle.max(1e-3),
                "angle {angle}: {w}"
            );
        }
    }

    #[test]
    fn motion_action_matches_matrix_form() {
        let x = sample_se3();
        let m = Motion::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(-0.5, 0.2, 0.9));
        let back = x.act_inv_motion(&x.act_motion(&m));
        assert!((back.lin - m.lin).norm() < 1e-12);
        assert!((back.ang - m.ang).norm() < 1e-12);
    }

    #[test]
    fn power_is_frame_invariant() {
        let x = sample_se3();
        let m = Motion::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(-0.5, 0.2, 0.9));
        let f = Force::new(Vector3::new(0.1, -4.0, 2.0), Vector3::new(3.0, 0.7, -1.0));
        let p_b = m.dot(&f);
        let p_a = x.act_motion(&m).dot(&x.act_force(&f));
        assert!((p_a - p_b).abs() < 1e-12);
        let back = x.act_inv_force(&x.act_force(&f));
        assert!((back.lin - f.lin).norm() < 1e-12 && (back.ang - f.ang).norm() < 1e-12);
    }

    #[test]
    fn inertia_transform_preserves_momentum_relation() {
        // (X I) (X v) must equal X (I v).
        let x = sample_se3();
        let y = Inertia::from_com(
            2.5,
            Vector3::new(0.1, -0.05, 0.2),
            Matrix3::new(0.03, 0.001, -0.002, 0.001, 0.02, 0.003, -0.002, 0.003, 0.04),
        );
        let v = Motion::new(Vector3::new(0.3, -1.0, 0.4), Vector3::new(1.2, 0.1, -0.7));
        let lhs = x.act_inertia(&y).mul_motion(&x.act_motion(&v));
        let rhs = x.act_force(&y.mul_motion(&v));
        assert!((lhs.lin - rhs.lin).norm() < 1e-12);
        assert!((lhs.ang - rhs.ang).norm() < 1e-12);
        let com_a = x.act_point(&y.com());
        assert!((x.act_inertia(&y).com() - com_a).norm() < 1e-12);
    }

    #[test]
    fn matrices_match_operators() {
        let y = Inertia::from_com(
            1.5,
            Vector3::new(0.1, 0.2, -0.3),
            Matrix3::identity() * 0.01,
        );
        let v = Motion::new(Vector3::new(0.3, -1.0, 0.4), Vector3::new(1.2, 0.1, -0.7));
        let m = Motion::new(Vector3::new(-0.2, 0.5, 0.8), Vector3::new(0.4, -0.3, 0.2));
        let f = y.mul_motion(&v);
        let f_mat = y.to_matrix() * v.to_vector();
        assert!((Motion::from_vector(&f_mat).lin - f.lin).norm() < 1e-12);
        let c = v.cross(&m);
        let c_mat = v.cross_matrix() * m.to_vector();
        assert!((c.to_vector() - c_mat).norm() < 1e-12);
        // ×* is −(×)ᵀ.
        let cf = v.cross_force(&f);
        let cf_mat = -v.cross_matrix().transpose()
            * Motion {
                lin: f.lin,
                ang: f.ang,
            }
            .to_vector();
        assert!(
            (Motion {
                lin: cf.lin,
                ang: cf.ang
            }
            .to_vector()
                - cf_mat)
                .norm()
                < 1e-12
        );
        let xb = force_cross_bar_matrix(&f);
        assert!((xb + xb.transpose()).norm() < 1e-15);
        let lhs = xb * m.to_vector();
        let rhs = m.cross_force(&f);
        assert!(
            (lhs - Motion {
                lin: rhs.lin,
                ang: rhs.ang
            }
            .to_vector())
            .norm()
                < 1e-12
        );
    }
}
