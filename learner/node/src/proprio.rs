//! Proprioception as the paper's encoder takes it ("Modality encoders"): the
//! end-effector's position (3), roll (1), linear velocity (3) and roll rate
//! (1). One function, [`Proprio::from_frame`], builds it wherever an
//! observation is made: dataset labelling, the live node and the fast path.
//!
//! **Roll** is the rotation of the tool about the base's vertical axis: the
//! heading of the tool's x axis in the base x-y plane, which is the
//! controller's roll coordinate `r_z` (fixed-axis XYZ angles,
//! [`rt_controller::trajectory::fixed_xyz_angles`]) and the one the policy's
//! Δroll moves. The tool points down, so this is its turn about its own axis.
//! It is measured relative to the roll at the episode's first sensor frame
//! (the start pose, held until the first action) and wrapped into (−π, π].
//! That reference puts the wrap where the task never goes: the controller
//! centres its roll range on the same start roll and clamps targets to
//! ±`trajectory.roll_range_rad` (π by default) about it, and hw-sim draws the
//! box's yaw within ±`task.box_yaw_range_rad` (0.26 rad) of the yaw that
//! fits the peg at the start; so the roll the task needs lies near 0 and a
//! reading reaches ±π only at the controller's roll limit. Unlike the
//! quaternion, whose sign is free (q and −q are one rotation, and with the
//! tool pointing down w ≈ 0, so the sign a conversion picks can flip between
//! near-identical poses), the wrapped angle of near-identical poses is
//! near-identical. The hole's orientation is not a usable reference: it is
//! the task's ground truth, which a real robot's proprioception lacks.
//!
//! **Roll rate** is the exact time derivative of that heading given the
//! base-frame angular velocity ω: with x the tool's x axis, ẋ = ω × x and
//! d/dt atan2(x_y, x_x) = (x_x ẋ_y − x_y ẋ_x) / (x_x² + x_y²) (ω_z when the
//! tool points straight down).

use nalgebra::{UnitQuaternion, Vector3};
use shared_mem_schema::SensorFrame;

/// Proprioception values: position (3), roll (1), linear velocity (3), roll
/// rate (1), in that order.
pub const PROPRIO: usize = 8;

/// The paper's proprioception of one sensor frame, base frame, SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proprio {
    /// End-effector (peg tip) position, m.
    pub pos_m: [f64; 3],
    /// Roll relative to the episode's start, rad, in (−π, π].
    pub roll_rad: f64,
    /// End-effector linear velocity, m/s.
    pub vel_m_s: [f64; 3],
    /// Roll rate, rad/s.
    pub roll_rate_rad_s: f64,
}

/// The tool's absolute roll (heading of its x axis about the base's
/// vertical), rad, in (−π, π]: the reference an episode's rolls are taken
/// from when given its first sensor frame's orientation.
pub fn tool_roll_rad(rot: &UnitQuaternion<f64>) -> f64 {
    let (_, _, rz) = rt_controller::trajectory::fixed_xyz_angles(rot.to_rotation_matrix().matrix());
    rt_controller::trajectory::wrap_angle(rz)
}

/// The time derivative of [`tool_roll_rad`] at orientation `rot` turning at
/// base-frame angular velocity `omega`, rad/s.
pub fn tool_roll_rate_rad_s(rot: &UnitQuaternion<f64>, omega: &Vector3<f64>) -> f64 {
    let x = rot * Vector3::x();
    let dx = omega.cross(&x);
    let h = x.x * x.x + x.y * x.y;
    if h < 1e-12 {
        // The tool's x axis is vertical: its heading is undefined.
        return omega.z;
    }
    (x.x * dx.y - x.y * dx.x) / h
}

/// The orientation a sensor frame carries.
fn frame_rotation(f: &SensorFrame) -> UnitQuaternion<f64> {
    hw_sim::convert::unit_quaternion(f.ee_quat_xyzw)
}

/// The roll reference of an episode: the absolute roll of its first sensor
/// frame.
pub fn roll_reference(first: &SensorFrame) -> f64 {
    tool_roll_rad(&frame_rotation(first))
}

impl Proprio {
    /// From a pose, the twist (linear, angular; base frame) and the
    /// episode's roll reference ([`roll_reference`]).
    pub fn new(
        pos: &Vector3<f64>,
        rot: &UnitQuaternion<f64>,
        twist: &[f64; 6],
        roll_ref_rad: f64,
    ) -> Self {
        let omega = Vector3::new(twist[3], twist[4], twist[5]);
        Self {
            pos_m: [pos.x, pos.y, pos.z],
            roll_rad: rt_controller::trajectory::wrap_angle(tool_roll_rad(rot) - roll_ref_rad),
            vel_m_s: [twist[0], twist[1], twist[2]],
            roll_rate_rad_s: tool_roll_rate_rad_s(rot, &omega),
        }
    }

    /// From a controller sensor frame, with the episode's roll reference.
    pub fn from_frame(f: &SensorFrame, roll_ref_rad: f64) -> Self {
        Self::new(
            &Vector3::from(f.ee_pos_m),
            &frame_rotation(f),
            &f.ee_twist,
            roll_ref_rad,
        )
    }

    /// The encoder's input vector, in [`PROPRIO`] order.
    pub fn to_array(&self) -> [f32; PROPRIO] {
        let [x, y, z] = self.pos_m.map(|v| v as f32);
        let [vx, vy, vz] = self.vel_m_s.map(|v| v as f32);
        [
            x,
            y,
            z,
            self.roll_rad as f32,
            vx,
            vy,
            vz,
            self.roll_rate_rad_s as f32,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_mem_schema::Message;
    use std::f64::consts::PI;

    /// The tool pointing down (a half turn about base x), turned by `roll`
    /// about the vertical, tilted slightly by `tilt` about base y.
    fn down(roll: f64, tilt: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI)
    }

    fn frame(rot: &UnitQuaternion<f64>, twist: [f64; 6]) -> SensorFrame {
        let mut f = *SensorFrame::boxed_zeroed();
        f.ee_pos_m = [0.5, 0.1, 0.3];
        let q = rot.coords;
        f.ee_quat_xyzw = [q.x, q.y, q.z, q.w];
        f.ee_twist = twist;
        f
    }

    #[test]
    fn near_identical_poses_across_the_quaternion_sign_flip_give_near_identical_proprio() {
        // Two poses 1e-4 rad apart whose quaternions, as recorded, carry
        // opposite signs (both are valid: q and −q are one rotation).
        let a = down(0.3, 0.0);
        let b = down(0.3 + 1e-4, 1e-4);
        let fa = frame(&a, [0.0; 6]);
        let mut fb = frame(&b, [0.0; 6]);
        fb.ee_quat_xyzw = fb.ee_quat_xyzw.map(|c| -c);
        let far = (0..4)
            .map(|k| (fa.ee_quat_xyzw[k] - fb.ee_quat_xyzw[k]).abs())
            .fold(0.0, f64::max);
        assert!(far > 1.0, "the recorded quaternions differ by {far}");
        let r = roll_reference(&fa);
        let (pa, pb) = (
            Proprio::from_frame(&fa, r).to_array(),
            Proprio::from_frame(&fb, r).to_array(),
        );
        for k in 0..PROPRIO {
            assert!((pa[k] - pb[k]).abs() < 1e-3, "value {k}: {pa:?} vs {pb:?}");
        }
    }

    #[test]
    fn roll_and_roll_rate_follow_a_scripted_rotation() {
        // Start at an absolute roll of 3 rad (near the ±π wrap of an
        // absolute angle) and turn at 0.8 rad/s about the vertical for 2 s,
        // with a slight tilt: roll relative to the start is the turn, the
        // wrap of the absolute heading never shows, and the rate is 0.8.
        let (start, rate, tilt) = (3.0, 0.8, 0.05);
        let first = frame(&down(start, tilt), [0.0; 6]);
        let r = roll_reference(&first);
        assert!((r - start).abs() < 1e-9, "{r}");
        let omega = Vector3::new(0.0, 0.0, rate);
        let mut prev: Option<(f64, f64)> = None;
        for k in 0..=200 {
            let t = k as f64 * 0.01;
            let rot = down(start + rate * t, tilt);
            let f = frame(&rot, [0.01, 0.0, -0.02, omega.x, omega.y, omega.z]);
            let p = Proprio::from_frame(&f, r);
            assert!(
                (p.roll_rad - rate * t).abs() < 1e-9,
                "t {t}: {}",
                p.roll_rad
            );
            assert!(
                (p.roll_rate_rad_s - rate).abs() < 1e-9,
                "t {t}: {}",
                p.roll_rate_rad_s
            );
            assert_eq!(p.vel_m_s, [0.01, 0.0, -0.02]);
            // The rate is the roll's derivative (finite differences).
            if let Some((t0, r0)) = prev {
                let fd = (p.roll_rad - r0) / (t - t0);
                assert!((fd - p.roll_rate_rad_s).abs() < 1e-6, "t {t}: {fd}");
            }
            prev = Some((t, p.roll_rad));
        }
        // Past half a turn the relative roll wraps to −π.. (the controller's
        // roll limit, which the task never reaches).
        let p = Proprio::from_frame(&frame(&down(start + PI + 0.1, tilt), [0.0; 6]), r);
        assert!((p.roll_rad - (-PI + 0.1)).abs() < 1e-9, "{}", p.roll_rad);
    }

    #[test]
    fn roll_rate_about_a_tilted_axis_is_the_heading_derivative() {
        // A turn about base x (the tool's own tilt) changes no heading when
        // the tool points straight down; a general ω against finite
        // differences of the heading.
        let rot = down(0.4, 0.0);
        assert!(tool_roll_rate_rad_s(&rot, &Vector3::new(0.7, 0.0, 0.0)).abs() < 1e-12);
        let rot = down(0.4, 0.2);
        let omega = Vector3::new(0.3, -0.5, 0.9);
        let dt = 1e-6;
        let later = UnitQuaternion::from_scaled_axis(omega * dt) * rot;
        let fd =
            rt_controller::trajectory::wrap_angle(tool_roll_rad(&later) - tool_roll_rad(&rot)) / dt;
        let rate = tool_roll_rate_rad_s(&rot, &omega);
        assert!((fd - rate).abs() < 1e-5, "{fd} vs {rate}");
    }
}
