//! Self-supervised labels computed offline from what a log records, so that
//! a log of the real robot gets them as well as a simulator log:
//!
//! - optical flow of the robot and peg caused by an action, and its mask,
//!   from robot-model forward kinematics of the joint positions at the two
//!   frames, the robot's and the peg's geometry, and the camera's recorded
//!   calibration; a pixel counts when the recorded depth shows that the
//!   robot is what the camera saw there (the box and anything else in front
//!   hide it); the mask is the robot in motion (as hw-sim's, moved at least
//!   [`hw_sim::camera::FLOW_MASK_MIN_PX`]);
//! - contact, from the wrist wrench against the free-space reading.

use hw_sim::SimError;
use hw_sim::camera::{BodyPoses, Camera, CameraFrame, Class, Primitive};
use hw_sim::config::TaskConfig;
use nalgebra::{Isometry3, Vector3};
use robot_model::Model;
use shared_mem_schema::CameraCalibration;

/// Why a labeler could not be made.
#[derive(Debug, thiserror::Error)]
pub enum LabelError {
    /// The recorded camera calibration has no usable size or focal length.
    #[error("camera calibration {calibration:?} is not usable")]
    Calibration {
        /// The calibration at fault.
        calibration: CameraCalibration,
    },
    /// The task's peg cannot be attached to the robot.
    #[error(transparent)]
    Peg(#[from] SimError),
}

/// Flow labels from kinematics and geometry.
pub struct FlowLabeler {
    model: Model,
    data: robot_model::Data,
    camera: Camera,
    a: CameraFrame,
    b: CameraFrame,
    links: Vec<Isometry3<f64>>,
    /// Flow on the first frame's grid, px (u right, v down), wherever the
    /// first frame saw the robot or the peg, moving or not.
    pub flow_px: Vec<[f32; 2]>,
    /// 1 where the first frame saw the robot or the peg and it moved (the
    /// robot in motion).
    pub mask: Vec<u8>,
    /// Flow from which a pixel counts as moving, px; hw-sim's
    /// [`hw_sim::camera::FLOW_MASK_MIN_PX`] unless set (0: every robot
    /// pixel, the mask of dataset format version 1).
    pub mask_min_px: f32,
}

impl FlowLabeler {
    /// A labeler for `model` carrying the peg of `task` (none when the task
    /// is disabled), seen by a camera of calibration `cal`.
    pub fn new(
        model: Model,
        task: &TaskConfig,
        cal: &CameraCalibration,
    ) -> Result<Self, LabelError> {
        let usable =
            cal.width > 0 && cal.height > 0 && cal.focal_px.is_finite() && cal.focal_px > 0.0;
        if !usable {
            return Err(LabelError::Calibration { calibration: *cal });
        }
        let mut prims: Vec<Primitive> = hw_sim::camera::robot_primitives(&model);
        if task.enabled {
            let peg = hw_sim::world::peg_info(&model, task)?;
            prims.push(peg.primitive());
        }
        let camera = Camera::calibrated(cal, 100.0, prims, 0);
        let n = (cal.width * cal.height) as usize;
        Ok(Self {
            data: model.create_data(),
            links: vec![Isometry3::identity(); model.nv() + 1],
            model,
            camera,
            a: CameraFrame::default(),
            b: CameraFrame::default(),
            flow_px: vec![[0.0; 2]; n],
            mask: vec![0; n],
            mask_min_px: hw_sim::camera::FLOW_MASK_MIN_PX,
        })
    }

    fn poses(&mut self, q: &[f64]) {
        robot_model::forward_kinematics(&self.model, &mut self.data, q);
        for (j, l) in self.links.iter_mut().enumerate() {
            *l = self.data.o_m_i[j].to_isometry();
        }
    }

    /// The flow from the frame at joint positions `q0` (whose recorded
    /// depth is `depth0`, m, 0 for no return) to the frame at `q1`. A pixel
    /// gets flow when the robot or peg rendered there lies within
    /// `depth_tol_m` of the recorded depth, and is in the mask when it also
    /// moved at least `mask_min_px` (as hw-sim's mask).
    pub fn label(&mut self, q0: &[f64], q1: &[f64], depth0: &[f32], depth_tol_m: f64) {
        self.camera.reset();
        self.poses(q0);
        let none = [];
        let poses = BodyPoses {
            links: &self.links,
            box_pose: None,
        };
        self.camera
            .render(&poses, 0.0, &none, (0.0, 0.0), &mut self.a);
        self.poses(q1);
        let poses = BodyPoses {
            links: &self.links,
            box_pose: None,
        };
        self.camera.render(
            &poses,
            shared_mem_schema::rates::ACTION_PERIOD_S,
            &none,
            (0.0, 0.0),
            &mut self.b,
        );
        for i in 0..self.flow_px.len() {
            let seen = depth0.get(i).copied().unwrap_or(0.0);
            let robot =
                self.a.class[i] == Class::Robot as u8 || self.a.class[i] == Class::Peg as u8;
            let visible = robot
                && seen > 0.0
                && (self.a.depth_m[i] as f64 - seen as f64).abs() <= depth_tol_m;
            let f = self.b.flow_px[i];
            let moved = f[0] * f[0] + f[1] * f[1] >= self.mask_min_px * self.mask_min_px;
            self.mask[i] = (visible && moved) as u8;
            self.flow_px[i] = if visible { self.b.flow_px[i] } else { [0.0; 2] };
        }
    }
}

/// Contact from the wrist force: the mean of the newest `window` force
/// readings differs from the free-space reading `free` by more than
/// `threshold_n`.
pub fn in_contact(forces: &[[f64; 3]], free: &[f64; 3], threshold_n: f64) -> bool {
    if forces.is_empty() {
        return false;
    }
    let mut m = [0.0; 3];
    for f in forces {
        for k in 0..3 {
            m[k] += f[k] / forces.len() as f64;
        }
    }
    let d = Vector3::new(m[0] - free[0], m[1] - free[1], m[2] - free[2]);
    d.norm() > threshold_n
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    #[test]
    fn contact_threshold_on_the_mean_change() {
        let free = [0.0, 0.0, -1.0];
        assert!(!in_contact(&[[0.0, 0.0, -1.0]; 4], &free, 3.0));
        assert!(in_contact(&[[0.0, 0.0, -5.0]; 4], &free, 3.0));
        // One spike among four does not make the mean cross.
        let f = [
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -9.0],
        ];
        assert!(!in_contact(&f, &free, 3.0));
        assert!(!in_contact(&[], &free, 3.0));
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // pixel index drives several arrays
    fn turning_joint_one_moves_each_seen_point_about_the_base_axis() {
        // No joint motion: zero flow wherever the robot is seen.
        let model = robot_model::descriptions::builtin("iiwa14").unwrap();
        let world = hw_sim::WorldConfig::default();
        let cam = Camera::new(&world.camera, vec![], 0);
        let cal = cam.calibration();
        let mut l = FlowLabeler::new(model.clone(), &world.task, &cal).unwrap();
        let q = hw_sim::world::default_initial_q(&model);
        // Depth of the robot itself: everything it covers is visible.
        l.label(&q, &q, &[0.0; 0], 0.01);
        assert!(
            l.mask.iter().all(|&m| m == 0),
            "no recorded depth: nothing labelled"
        );
        let depth = l.a.depth_m.clone();
        l.label(&q, &q, &depth, 0.01);
        let robot = |c: u8| c == Class::Robot as u8 || c == Class::Peg as u8;
        let seen = l.a.class.iter().filter(|&&c| robot(c)).count();
        assert!(seen > 200, "the robot covers {seen} pixels");
        assert!(l.mask.iter().all(|&m| m == 0), "a still arm: empty mask");
        assert!(
            l.flow_px
                .iter()
                .all(|f| f[0].abs() < 1e-4 && f[1].abs() < 1e-4)
        );
        // Joint 1 turns about the vertical: the labelled flow is that of
        // points rotated about the base z axis, projected.
        let mut q1 = q.clone();
        q1[0] += 0.02;
        l.label(&q, &q1, &depth, 0.01);
        let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.02);
        let (cx, cy, f) = (cal.principal_px[0], cal.principal_px[1], cal.focal_px);
        let pose = cam.pose;
        let mut checked = 0;
        for i in 0..l.mask.len() {
            if !robot(l.a.class[i]) {
                assert_eq!(l.mask[i], 0, "pixel {i} is not the robot");
                continue;
            }
            let (u, v) = ((i % 128) as f64 + 0.5, (i / 128) as f64 + 0.5);
            let d = depth[i] as f64;
            let pc = Vector3::new((u - cx) / f * d, (v - cy) / f * d, d);
            let pw = pose * nalgebra::Point3::from(pc);
            let moved = pose.inverse() * (rot * pw);
            let (u1, v1) = (cx + f * moved.x / moved.z, cy + f * moved.y / moved.z);
            let fl = l.flow_px[i];
            let turned =
                (fl[0] as f64 - (u1 - u)).abs() < 1e-3 && (fl[1] as f64 - (v1 - v)).abs() < 1e-3;
            // The base (below joint 1) stays put.
            let still = fl[0].abs() < 1e-4 && fl[1].abs() < 1e-4;
            assert!(
                turned || still,
                "pixel {i}: {fl:?} vs {:?}",
                (u1 - u, v1 - v)
            );
            // The mask is the robot in motion: the base is left out.
            let moving = fl[0].hypot(fl[1]) >= hw_sim::camera::FLOW_MASK_MIN_PX;
            assert_eq!(l.mask[i] == 1, moving, "pixel {i}: {fl:?}");
            checked += (turned && moving) as usize;
        }
        assert!(checked > 150, "{checked} of {seen} pixels turned");
    }
}
