//! Trajectory generator: 20 Hz policy steps (Δx, Δy, Δz, Δroll) become a
//! 1 kHz Cartesian reference with continuous pose, velocity and acceleration.
//!
//! As in the paper, the controlled coordinates are the position and the roll
//! `r_z` (rotation about the base z axis); the other two Euler angles are held
//! at their values when the generator is reset. With fixed-axis XYZ angles,
//! `R = Rz(r_z)·Ry(r_y)·Rx(r_x)`, so a change of `r_z` is a rotation about the
//! base z axis and the reference angular velocity is simply `ṙ_z·ẑ`.
//!
//! Each new target starts a quintic segment from the reference's current
//! position, velocity and acceleration to the target at rest, so a new action
//! arriving mid-segment leaves the reference C² continuous.

use crate::config::{TrajectoryConfig, TrajectoryTarget};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// A quintic `p(t)` on `[0, T]` with given end conditions; constant after.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Quintic {
    c: [f64; 6],
    duration: f64,
}

impl Quintic {
    /// Rest at `p` forever.
    pub fn hold(p: f64) -> Self {
        Self {
            c: [p, 0.0, 0.0, 0.0, 0.0, 0.0],
            duration: 0.0,
        }
    }

    /// From `(p0, v0, a0)` to `(pf, 0, 0)` in `duration` seconds.
    pub fn to_rest(p0: f64, v0: f64, a0: f64, pf: f64, duration: f64) -> Self {
        let t = duration;
        let h = pf - p0;
        let (t2, t3) = (t * t, t * t * t);
        Self {
            c: [
                p0,
                v0,
                0.5 * a0,
                (20.0 * h - 12.0 * v0 * t - 3.0 * a0 * t2) / (2.0 * t3),
                (-30.0 * h + 16.0 * v0 * t + 3.0 * a0 * t2) / (2.0 * t3 * t),
                (12.0 * h - 6.0 * v0 * t - a0 * t2) / (2.0 * t3 * t2),
            ],
            duration,
        }
    }

    /// Position, velocity and acceleration at `t` seconds into the segment
    /// (clamped to `[0, T]`; after `T` it rests at the end point).
    pub fn eval(&self, t: f64) -> (f64, f64, f64) {
        let t = t.clamp(0.0, self.duration);
        let c = &self.c;
        let p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
        let v = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])));
        let a = 2.0 * c[2] + t * (6.0 * c[3] + t * (12.0 * c[4] + t * 20.0 * c[5]));
        if t >= self.duration {
            // Exactly at rest at the end, whatever rounding left behind.
            (self.end(), 0.0, 0.0)
        } else {
            (p, v, a)
        }
    }

    /// The end point.
    pub fn end(&self) -> f64 {
        let t = self.duration;
        let c = &self.c;
        c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
    }
}

/// The Cartesian reference at one instant: position, roll, and their first
/// two derivatives, plus the rotation they describe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// Desired position in the base frame, m.
    pub pos: Vector3<f64>,
    /// Desired velocity, m/s.
    pub vel: Vector3<f64>,
    /// Desired acceleration, m/s².
    pub acc: Vector3<f64>,
    /// Desired orientation in the base frame.
    pub rot: Matrix3<f64>,
    /// Desired angular velocity (base axes), rad/s.
    pub ang_vel: Vector3<f64>,
    /// Desired angular acceleration (base axes), rad/s².
    pub ang_acc: Vector3<f64>,
    /// Desired roll `r_z`, rad.
    pub roll: f64,
}

/// What became of one action.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActionEffect {
    /// Applied as given.
    Applied,
    /// Applied after clamping its size, the workspace box, the roll range
    /// or the anti-windup lead.
    Clamped,
}

/// Extracts the fixed-axis XYZ angles `(r_x, r_y, r_z)` with
/// `R = Rz(r_z)·Ry(r_y)·Rx(r_x)`.
pub fn fixed_xyz_angles(r: &Matrix3<f64>) -> (f64, f64, f64) {
    let (rx, ry, rz) = Rotation3::from_matrix_unchecked(*r).euler_angles();
    (rx, ry, rz)
}

/// Wraps an angle into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

/// The generator's state. Plain data, no allocation.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryGenerator {
    axes: [Quintic; 4],
    segment_start: f64,
    target: [f64; 4],
    roll_center: f64,
    held_rx: f64,
    held_ry: f64,
}

impl Default for TrajectoryGenerator {
    fn default() -> Self {
        Self {
            axes: [Quintic::hold(0.0); 4],
            segment_start: 0.0,
            target: [0.0; 4],
            roll_center: 0.0,
            held_rx: 0.0,
            held_ry: 0.0,
        }
    }
}

impl TrajectoryGenerator {
    /// Rests the reference at a measured pose; the pitch and yaw seen now are
    /// held from here on, and the roll range is centred on the roll seen now.
    pub fn reset(&mut self, pos: &Vector3<f64>, rot: &Matrix3<f64>, now: f64) {
        let (rx, ry, rz) = fixed_xyz_angles(rot);
        self.held_rx = rx;
        self.held_ry = ry;
        self.roll_center = rz;
        self.target = [pos.x, pos.y, pos.z, rz];
        self.axes = self.target.map(Quintic::hold);
        self.segment_start = now;
    }

    /// The current target (x, y, z, roll) the reference moves towards.
    pub fn target(&self) -> [f64; 4] {
        self.target
    }

    /// Starts a segment towards `base + (Δx, Δroll)` after clamping the step
    /// to its maximum, the target to the workspace box and roll range, and the
    /// lead over the measured pose (`meas_pos`, `meas_roll`) to the
    /// anti-windup bound. `base` is the previous target or the measured pose,
    /// as `cfg.target` says. `delta` must be finite (the supervisor checks).
    pub fn apply_action(
        &mut self,
        cfg: &TrajectoryConfig,
        delta: [f64; 4],
        meas_pos: &Vector3<f64>,
        meas_roll: f64,
        now: f64,
    ) -> ActionEffect {
        let mut clamped = false;
        let mut clamp = |x: f64, lo: f64, hi: f64| {
            // Not `f64::clamp`, which panics on a NaN bound or `lo > hi`
            // (here a NaN bound is ignored and an empty box gives `hi`).
            let y = x.max(lo).min(hi);
            // `!=` would call −0.0 vs 0.0 equal anyway; NaN never reaches here.
            if y != x {
                clamped = true;
            }
            y
        };
        let mut target = self.target;
        if cfg.target == TrajectoryTarget::Measured {
            target[..3].copy_from_slice(meas_pos.as_slice());
            // The measured roll on the previous target's branch, so that
            // the roll range is not crossed at the ±π wrap.
            target[3] += wrap_angle(meas_roll - target[3]);
        }
        for i in 0..3 {
            let d = clamp(delta[i], -cfg.max_step_m, cfg.max_step_m);
            let mut x = target[i] + d;
            x = clamp(
                x,
                meas_pos[i] - cfg.max_lead_m,
                meas_pos[i] + cfg.max_lead_m,
            );
            x = clamp(x, cfg.workspace_min_m[i], cfg.workspace_max_m[i]);
            target[i] = x;
        }
        let d = clamp(delta[3], -cfg.max_step_rad, cfg.max_step_rad);
        let mut roll = target[3] + d;
        // The measured roll is wrapped; compare it near the target's branch.
        let meas = target[3] + wrap_angle(meas_roll - target[3]);
        roll = clamp(roll, meas - cfg.max_lead_rad, meas + cfg.max_lead_rad);
        roll = clamp(
            roll,
            self.roll_center - cfg.roll_range_rad,
            self.roll_center + cfg.roll_range_rad,
        );
        target[3] = roll;
        self.start_segment(target, cfg.interpolation_s, now);
        if clamped {
            ActionEffect::Clamped
        } else {
            ActionEffect::Applied
        }
    }

    /// Starts a C²-continuous segment from the reference at `now` to rest at
    /// `target` in `duration` seconds.
    pub fn start_segment(&mut self, target: [f64; 4], duration: f64, now: f64) {
        let t = now - self.segment_start;
        for (axis, &goal) in self.axes.iter_mut().zip(target.iter()) {
            let (p, v, a) = axis.eval(t);
            *axis = Quintic::to_rest(p, v, a, goal, duration);
        }
        self.target = target;
        self.segment_start = now;
    }

    /// The reference at time `now`.
    pub fn eval(&self, now: f64) -> Reference {
        let t = now - self.segment_start;
        let [x, y, z, r] = self.axes.map(|q| q.eval(t));
        let rot = Rotation3::from_euler_angles(self.held_rx, self.held_ry, r.0).into_inner();
        Reference {
            pos: Vector3::new(x.0, y.0, z.0),
            vel: Vector3::new(x.1, y.1, z.1),
            acc: Vector3::new(x.2, y.2, z.2),
            rot,
            ang_vel: Vector3::new(0.0, 0.0, r.1),
            ang_acc: Vector3::new(0.0, 0.0, r.2),
            roll: r.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> TrajectoryConfig {
        TrajectoryConfig {
            workspace_min_m: [-1.0; 3],
            workspace_max_m: [1.0; 3],
            ..TrajectoryConfig::default()
        }
    }

    #[test]
    fn quintic_meets_its_end_conditions() {
        let q = Quintic::to_rest(0.2, -0.3, 4.0, 1.0, 0.05);
        let (p, v, a) = q.eval(0.0);
        assert!((p - 0.2).abs() < 1e-15 && (v + 0.3).abs() < 1e-15 && (a - 4.0).abs() < 1e-12);
        // Just before the end, by continuity.
        let (p, v, a) = q.eval(0.05 - 1e-9);
        assert!((p - 1.0).abs() < 1e-9, "p {p}");
        assert!(v.abs() < 1e-6, "v {v}");
        assert!(a.abs() < 1e-3, "a {a}");
        assert_eq!(q.eval(1.0), (q.end(), 0.0, 0.0));
        assert!((q.end() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn quintic_derivatives_match_finite_differences() {
        let q = Quintic::to_rest(-0.1, 0.5, -2.0, 0.3, 0.05);
        let h = 1e-6;
        for k in 1..50 {
            let t = k as f64 * 0.001;
            let (p0, v0, _) = q.eval(t - h);
            let (p1, v1, _) = q.eval(t + h);
            let (_, v, a) = q.eval(t);
            assert!(((p1 - p0) / (2.0 * h) - v).abs() < 1e-6);
            assert!(((v1 - v0) / (2.0 * h) - a).abs() < 1e-4);
        }
    }

    #[test]
    fn fixed_xyz_angles_round_trip() {
        let r = Rotation3::from_euler_angles(3.0, 0.2, -1.2).into_inner();
        let (x, y, z) = fixed_xyz_angles(&r);
        let back = Rotation3::from_euler_angles(x, y, z).into_inner();
        assert!((back - r).norm() < 1e-12);
        // Fixed-axis XYZ: R = Rz·Ry·Rx.
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), -1.2);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.2);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), 3.0);
        assert!(((rz * ry * rx).into_inner() - r).norm() < 1e-12);
    }

    #[test]
    fn reference_is_c2_continuous_when_actions_arrive_mid_segment() {
        let c = cfg();
        let mut g = TrajectoryGenerator::default();
        let rot = Rotation3::from_euler_angles(std::f64::consts::PI, 0.0, 0.3).into_inner();
        let start = Vector3::new(0.5, 0.0, 0.3);
        g.reset(&start, &rot, 0.0);
        let dt = 0.001;
        let mut switches = 0;
        for k in 1..=400 {
            let now = k as f64 * dt;
            // Actions every 37 ms: never aligned with segment ends.
            if k % 37 == 0 {
                let before = g.eval(now);
                g.apply_action(
                    &c,
                    [0.008, -0.006, 0.004, 0.03],
                    &before.pos,
                    before.roll,
                    now,
                );
                let after = g.eval(now);
                // A new segment starts from the reference's own state.
                assert!((after.pos - before.pos).norm() < 1e-12);
                assert!((after.vel - before.vel).norm() < 1e-12);
                assert!((after.acc - before.acc).norm() < 1e-9);
                assert!((after.ang_vel - before.ang_vel).norm() < 1e-12);
                assert!((after.ang_acc - before.ang_acc).norm() < 1e-9);
                assert!(
                    switches == 0 || before.vel.norm() > 0.01,
                    "switch while moving"
                );
                switches += 1;
            }
        }
        assert_eq!(switches, 10);
        // And the segment reaches its target at rest.
        let end = g.eval(10.0);
        let t = g.target();
        assert!((end.pos - Vector3::new(t[0], t[1], t[2])).norm() < 1e-12);
        assert_eq!(end.vel, Vector3::zeros());
        assert_eq!(end.acc, Vector3::zeros());
    }

    #[test]
    fn pitch_and_yaw_are_held_and_roll_rotates_about_base_z() {
        let c = cfg();
        let mut g = TrajectoryGenerator::default();
        let rot0 = Rotation3::from_euler_angles(2.9, 0.1, 0.3).into_inner();
        g.reset(&Vector3::new(0.5, 0.0, 0.3), &rot0, 0.0);
        g.apply_action(
            &c,
            [0.0, 0.0, 0.0, 0.04],
            &Vector3::new(0.5, 0.0, 0.3),
            0.3,
            0.0,
        );
        let r = g.eval(1.0);
        let (rx, ry, rz) = fixed_xyz_angles(&r.rot);
        assert!((rx - 2.9).abs() < 1e-12 && (ry - 0.1).abs() < 1e-12);
        assert!((rz - 0.34).abs() < 1e-12);
        let expected = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.04).into_inner() * rot0;
        assert!((r.rot - expected).norm() < 1e-12);
    }

    #[test]
    fn steps_workspace_roll_range_and_lead_are_clamped() {
        let mut c = cfg();
        c.workspace_max_m = [1.0, 1.0, 0.305];
        c.roll_range_rad = 0.1;
        let mut g = TrajectoryGenerator::default();
        let p = Vector3::new(0.5, 0.0, 0.3);
        g.reset(&p, &Matrix3::identity(), 0.0);
        let e = g.apply_action(&c, [0.004, 0.0, 0.0, 0.0], &p, 0.0, 0.0);
        assert_eq!(e, ActionEffect::Applied);
        let e = g.apply_action(&c, [0.05, -0.05, 0.008, 0.5], &p, 0.0, 0.05);
        assert_eq!(e, ActionEffect::Clamped);
        let t = g.target();
        assert!((t[0] - 0.514).abs() < 1e-12, "step clamped to 1 cm: {t:?}");
        assert!((t[1] + 0.01).abs() < 1e-12);
        assert!((t[2] - 0.305).abs() < 1e-12, "workspace box: {t:?}");
        assert!((t[3] - 0.05).abs() < 1e-12, "roll step clamped: {t:?}");
        for k in 0..10 {
            g.apply_action(&c, [0.0, 0.0, 0.0, 0.05], &p, 0.0, 0.1 + k as f64 * 0.05);
        }
        assert!((g.target()[3] - 0.1).abs() < 1e-12, "roll range");
        // The measured pose is stuck (in contact): the target leads it by at
        // most max_lead however many steps push.
        for k in 0..20 {
            g.apply_action(&c, [0.01, 0.0, 0.0, 0.0], &p, 0.0, 1.0 + k as f64 * 0.05);
        }
        assert!((g.target()[0] - (0.5 + c.max_lead_m)).abs() < 1e-12);
    }

    #[test]
    fn roll_lead_works_across_the_pi_wrap() {
        let c = cfg();
        let mut g = TrajectoryGenerator::default();
        let rot = Rotation3::from_euler_angles(0.0, 0.0, 3.1).into_inner();
        let p = Vector3::new(0.5, 0.0, 0.3);
        g.reset(&p, &rot, 0.0);
        for k in 0..4 {
            let meas = wrap_angle(3.1 + 0.05 * k as f64);
            g.apply_action(&c, [0.0, 0.0, 0.0, 0.05], &p, meas, k as f64 * 0.05);
        }
        // Measured roll follows across +π (wrapping to −π): no lead clamp.
        assert!((g.target()[3] - 3.3).abs() < 1e-12, "{:?}", g.target());
    }

    #[test]
    fn measured_target_adds_the_step_to_the_measured_pose() {
        let c = TrajectoryConfig {
            target: TrajectoryTarget::Measured,
            ..cfg()
        };
        let mut g = TrajectoryGenerator::default();
        let rot = Rotation3::from_euler_angles(0.0, 0.0, 3.1).into_inner();
        let p = Vector3::new(0.5, 0.0, 0.3);
        g.reset(&p, &rot, 0.0);
        // The pose is stuck (in contact): the target leads it by one step,
        // however many steps push, where accumulation would wind up to
        // max_lead.
        for k in 0..20 {
            let e = g.apply_action(&c, [0.004, 0.0, -0.002, 0.0], &p, 3.1, k as f64 * 0.05);
            assert_eq!(e, ActionEffect::Applied);
        }
        let t = g.target();
        assert!(
            (t[0] - 0.504).abs() < 1e-12 && (t[2] - 0.298).abs() < 1e-12,
            "{t:?}"
        );
        // The measured pose moved on: the next target starts from it.
        let q = Vector3::new(0.52, 0.01, 0.25);
        g.apply_action(&c, [0.001, 0.0, 0.0, 0.0], &q, 3.1, 1.0);
        let t = g.target();
        assert!((t[0] - 0.521).abs() < 1e-12 && (t[1] - 0.01).abs() < 1e-12);
        assert!((t[2] - 0.25).abs() < 1e-12);
        // Roll: measured across the ±π wrap, taken on the target's branch.
        g.apply_action(&c, [0.0, 0.0, 0.0, 0.05], &q, wrap_angle(3.2), 1.05);
        assert!((g.target()[3] - 3.25).abs() < 1e-12, "{:?}", g.target());
    }
}
