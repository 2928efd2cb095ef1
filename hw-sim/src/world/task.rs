//! The task: the peg mounted on the sensor, its contact with the box, and
//! the stages of the paper's evaluation.

use super::*;
use crate::camera::{BodyRef, Class, Primitive};
use crate::config::TaskConfig;
use crate::shapes::ConvexPrism;
use nalgebra::Matrix3;
use shared_mem_schema::Stage;

/// The task state at the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskState {
    /// The peg tip's position relative to the hole frame (centre of the
    /// opening, z up): the paper's s. The goal is (0, 0, −depth).
    pub s_m: Vector3<f64>,
    /// The peg's roll about the hole's z axis relative to the hole, wrapped
    /// into (−π/k, π/k] for a peg with k-fold symmetry: the paper's s_ψ.
    pub s_psi_rad: f64,
    /// The peg touches the box at this step (the ground does not count).
    pub in_contact: bool,
    /// The tip is in the hole: below the box's top face and at least
    /// `task.in_hole_margin_m` inside the hole's outline. Inserted and
    /// completed require it; the tip's height alone would also count a peg
    /// pushed down beside the box.
    pub in_hole: bool,
    /// The stage reached at this step.
    pub stage_now: Stage,
    /// The best stage reached in the episode so far.
    pub best_stage: Stage,
}

/// The peg, as mounted on the sensor.
#[derive(Clone, Debug)]
pub struct PegInfo {
    /// Its prism in the sensor frame (z along the peg, from the sensor face).
    pub prism: ConvexPrism,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the sensor frame.
    pub com_sensor: Vector3<f64>,
    /// Inertia about the centre of mass, in the sensor frame.
    pub inertia_sensor: Matrix3<f64>,
    /// The sensor frame in the frame of the link that carries it.
    pub sensor_in_link: Isometry3<f64>,
    /// Joint index (robot-model numbering) of the link that carries it.
    pub link: usize,
}

impl PegInfo {
    /// The peg as a camera primitive.
    pub fn primitive(&self) -> Primitive {
        Primitive {
            body: BodyRef::Link(self.link),
            local: self.sensor_in_link,
            geometry: crate::camera::prism_geometry(&self.prism),
            class: Class::Peg,
            color: [0.85, 0.22, 0.15],
        }
    }
}

/// The joint index whose body carries the F/T sensor (and the peg).
pub fn peg_link(model: &Model) -> usize {
    for name in ["ft_sensor", "flange"] {
        if let Ok(f) = model.frame_id(name) {
            return model.frames[f].parent_joint;
        }
    }
    model.nv()
}

/// The peg a task configuration describes, on `model`'s sensor link.
pub fn peg_info(model: &Model, task: &TaskConfig) -> Result<PegInfo, SimError> {
    let link = peg_link(model);
    let t = task;
    let sensor_in_link = ["ft_sensor", "flange"]
        .iter()
        .find_map(|n| model.frame_id(n).ok())
        .map(|f| model.frames[f].placement.to_isometry())
        .unwrap_or_else(Isometry3::identity);
    let length = if t.peg_length_m > 0.0 {
        t.peg_length_m
    } else if let Ok(tip) = model.frame_id("peg_tip") {
        let tip = model.frames[tip].placement.to_isometry();
        (sensor_in_link.inverse() * tip).translation.vector.norm()
    } else {
        0.08
    };
    if length <= 0.0 {
        return Err(FieldError::new(
            "task.peg_length_m",
            t.peg_length_m,
            "the peg_tip frame coincides with the sensor; set a length",
        )
        .into());
    }
    let prism = ConvexPrism {
        polygon: t.peg.outline(t.peg_width_m),
        z0: 0.0,
        z1: length,
    };
    let mass_kg = prism.volume() * t.peg_density_kg_m3;
    // Inertia of the prism from its hull (rapier's own computation, so
    // the sensor model and the physics agree on it).
    let mp = build::hull_collider(&prism)
        .density(t.peg_density_kg_m3)
        .build()
        .mass_properties();
    let frame = crate::convert::rot_from_glam(mp.principal_inertia_local_frame)
        .to_rotation_matrix()
        .into_inner();
    let principal = Matrix3::from_diagonal(&from_glam(mp.principal_inertia()));
    Ok(PegInfo {
        prism,
        mass_kg,
        com_sensor: from_glam(mp.local_com),
        inertia_sensor: frame * principal * frame.transpose(),
        sensor_in_link,
        link,
    })
}

impl World {
    pub(super) fn peg_box_contact(&self) -> bool {
        let (Some(peg), Some(b)) = (self.peg.as_ref(), self.box_state.as_ref()) else {
            return false;
        };
        peg.colliders.iter().any(|&h| {
            self.physics.narrow_phase.contact_pairs_with(h).any(|pair| {
                let other = if pair.collider1 == h {
                    pair.collider2
                } else {
                    pair.collider1
                };
                b.colliders.contains(&other) && pair.has_any_active_contact()
            })
        })
    }

    pub(super) fn update_task(&mut self, contact: bool) {
        let (Some(b), Some(_)) = (self.box_state.as_ref(), self.peg.as_ref()) else {
            self.task = None;
            return;
        };
        let tip = self.peg_tip_pose();
        let rel = b.hole_pose.inverse() * tip;
        let s = rel.translation.vector;
        // Roll: the angle of the peg's x axis about the hole's z axis.
        let x = rel.rotation * Vector3::x();
        let raw = x.y.atan2(x.x);
        let k = self.config.task.peg.symmetry_order() as f64;
        let period = std::f64::consts::TAU / k;
        let mut psi = raw.rem_euclid(period);
        if psi > 0.5 * period {
            psi -= period;
        }
        let t = &self.config.task;
        let in_hole = s.z < 0.0 && b.geometry.hole_inset([s.x, s.y]) >= t.in_hole_margin_m;
        let stage_now = if in_hole && s.z <= -(b.geometry.depth - t.completed_tolerance_m) {
            Stage::Completed
        } else if in_hole && s.z <= -t.inserted_depth_m {
            Stage::Inserted
        } else if contact {
            Stage::Touched
        } else {
            Stage::Failed
        };
        let best = self
            .task
            .map(|t| t.best_stage)
            .unwrap_or(Stage::Failed)
            .max(stage_now);
        self.task = Some(TaskState {
            s_m: s,
            s_psi_rad: psi,
            in_contact: contact,
            in_hole,
            stage_now,
            best_stage: best,
        });
    }
}
