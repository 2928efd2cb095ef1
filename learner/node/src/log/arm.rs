//! The arm's links for Foxglove's 3D panel: every URDF link's pose in the
//! base frame at the measured joint angles, as `foxglove.FrameTransforms`
//! entries named after the links, so that the panel's URDF layer (the
//! shipped layout, deploy/foxglove/) draws the arm as it moved. The robot
//! is the one the log's `/config` names ([`super::LogWriter::config`]).

use super::foxglove::{BASE_FRAME, Transform, parts};
use robot_model::algorithms::kinematics::{forward_kinematics, frame_placement};
use robot_model::{Data, FrameKind, Model};

/// A robot's link frames and the buffers their poses are computed in.
pub struct ArmFrames {
    /// The robot description it was loaded from (name or path).
    pub robot: String,
    model: Model,
    data: Data,
    /// Frame index and link name of every link.
    links: Vec<(usize, String)>,
    q: Vec<f64>,
}

impl ArmFrames {
    /// Loads `robot` (a built-in name or a URDF path, as the world's
    /// `robot` field).
    pub fn load(robot: &str) -> Result<Self, robot_model::ModelError> {
        let model = robot_model::descriptions::load(robot)?;
        let links = model
            .frames
            .iter()
            .enumerate()
            .filter(|(_, f)| f.kind == FrameKind::Link)
            .map(|(i, f)| (i, f.name.clone()))
            .collect();
        Ok(Self {
            robot: robot.to_string(),
            data: model.create_data(),
            q: vec![0.0; model.nq()],
            model,
            links,
        })
    }

    /// The robot's model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The wrist sensor's origin in the peg tip's frame (the peg runs
    /// between them), when the model has both frames.
    pub fn tip_to_sensor(&self) -> Option<nalgebra::Vector3<f64>> {
        let tip = self.model.frame_id("peg_tip").ok()?;
        let sensor = self.model.frame_id("ft_sensor").ok()?;
        let mut data = self.model.create_data();
        forward_kinematics(&self.model, &mut data, &vec![0.0; self.model.nq()]);
        let t = frame_placement(&self.model, &data, tip);
        let s = frame_placement(&self.model, &data, sensor);
        Some(
            t.inverse_transform_point(&s.translation.vector.into())
                .coords,
        )
    }

    /// The base → link transform of every link at joint positions `q`
    /// (`None` when `q` is not one finite value per joint of the model: a
    /// frame of another robot draws no arm rather than a wrong one).
    pub fn transforms(&mut self, q: &[f64]) -> Option<Vec<Transform<'_>>> {
        if q.len() != self.q.len() || q.iter().any(|x| !x.is_finite()) {
            return None;
        }
        self.q.copy_from_slice(q);
        forward_kinematics(&self.model, &mut self.data, &self.q);
        Some(
            self.links
                .iter()
                .map(|(i, name)| {
                    let (translation, rotation_xyzw) =
                        parts(&frame_placement(&self.model, &self.data, *i));
                    Transform {
                        parent: BASE_FRAME,
                        child: name,
                        translation,
                        rotation_xyzw,
                    }
                })
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_link_of_the_panda_is_placed_and_the_tip_is_where_the_model_puts_it() {
        let mut arm = ArmFrames::load("panda").unwrap();
        let q = [0.0, -0.3, 0.0, -2.0, 0.0, 1.6, 0.8];
        let tfs = arm.transforms(&q).unwrap();
        let names: Vec<&str> = tfs.iter().map(|t| t.child).collect();
        assert!(
            names.contains(&"panda_link0") && names.contains(&"panda_link7"),
            "{names:?}"
        );
        assert!(names.contains(&"peg_tip"), "{names:?}");
        // The tip by the model directly.
        let model = robot_model::descriptions::load("panda").unwrap();
        let mut data = model.create_data();
        forward_kinematics(&model, &mut data, &q);
        let want = frame_placement(&model, &data, model.frame_id("peg_tip").unwrap());
        let tip = tfs.iter().find(|t| t.child == "peg_tip").unwrap();
        for k in 0..3 {
            assert!((tip.translation[k] - want.translation.vector[k]).abs() < 1e-12);
        }
        // Too few or too many angles, or a NaN, give nothing rather than a
        // wrong arm.
        assert!(arm.transforms(&q[..6]).is_none());
        assert!(arm.transforms(&[0.0; 8]).is_none());
        assert!(arm.transforms(&[f64::NAN; 7]).is_none());
    }
}
