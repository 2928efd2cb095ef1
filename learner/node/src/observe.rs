//! What the policy sees: an [`Observer`] turns the state of a batch of
//! environments (the RL environment's, or the live node's one) into one
//! observation vector each.
//!
//! Two sources: [`GroundTruth`] (the tip relative to the hole, velocities
//! and a wrench summary: privileged, the simulator's report, as the
//! heuristic policy uses) and the frozen representation
//! ([`crate::repr::Representation`]: a trained model's z means over the
//! camera, the wrench window and proprioception, encoded in batches), which
//! asks for camera frames through [`Observer::needs_camera`].

use crate::policy::{Observation, WrenchHistory};
use hw_sim::{Stage, TaskState};
use nalgebra::{Isometry3, Vector3};
use shared_mem_schema::EpisodeReport;

/// One environment's state at a policy step, as an observer reads it.
pub struct ObsView<'a> {
    /// The sensor frame's end-effector (peg tip) pose and twist.
    pub obs: &'a Observation,
    /// The wrist wrench readings of the last cycles (newest last).
    pub wrench: &'a WrenchHistory,
    /// The wrench read in free space at the start of the episode (the
    /// sensor's bias and the peg's weight), sensor frame.
    pub free_wrench: &'a [f64; 6],
    /// The simulator's task state (privileged).
    pub task: &'a TaskState,
    /// The hole frame in the base frame (privileged).
    pub hole_pose: &'a Isometry3<f64>,
    /// The peg's rotational symmetry order.
    pub symmetry: u32,
    /// The camera frame of this step, rendered only when the observer
    /// asks for it.
    pub camera: Option<&'a shared_mem_schema::CameraFrame>,
}

/// Turns environment states into observation vectors, a batch at a time
/// (a learned encoder is run on a batch).
pub trait Observer: Send + Sync {
    /// Length of one observation.
    fn dim(&self) -> usize;
    /// Whether [`ObsView::camera`] must be rendered (it costs a ray-cast
    /// frame per step).
    fn needs_camera(&self) -> bool {
        false
    }
    /// Writes `views.len()` observations, one after the other, into `out`
    /// (`views.len() * dim()` values).
    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]);
    /// Batches it could not observe and wrote as zeros (a learned
    /// encoder's refusals; 0 for an observer that never refuses).
    fn rejected(&self) -> u64 {
        0
    }
    /// The camera it must see through (a learned encoder's training
    /// camera); `None`: any camera, or none.
    fn camera(&self) -> Option<shared_mem_schema::CameraCalibration> {
        None
    }
}

/// Ground-truth state, 18 values, each scaled to about unit size:
/// the tip's position in the hole frame (/ 0.1 m, 3), its roll relative to
/// the hole wrapped by the peg's symmetry (/ (π/k), 1), the tip's linear
/// velocity in the hole frame (/ 0.1 m/s, 3), its roll rate (rad/s, 1), the
/// mean wrench of the newest 8 readings less the free-space reading
/// (force / 10 N, 3; moment / 1 N·m, 3), sensor frame, and the position and
/// roll again at the scale of the clearance (`tanh(s / 5 mm)`, 3;
/// `tanh(s_ψ / 0.05 rad)`, 1).
///
/// Why the second, fine copy: at the coarse scale the 2 mm clearance is an
/// input change of 0.02, which a freshly initialised MLP maps to an action
/// change of about as little (0.1 mm), so the policy cannot resolve the
/// opening; a policy trained without it hovered 1 mm above the opening
/// with 3 mm lateral steps.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruth;

/// Readings averaged for [`GroundTruth`]'s wrench (8 ms).
const WRENCH_MEAN_READINGS: usize = 8;

/// Length of a [`GroundTruth`] observation.
pub const GROUND_TRUTH_DIM: usize = 18;

/// Position scale of [`GroundTruth`]'s fine channels, m.
const FINE_POSITION_M: f64 = 0.005;

/// Roll scale of [`GroundTruth`]'s fine channel, rad.
const FINE_ROLL_RAD: f64 = 0.05;

impl GroundTruth {
    /// One view's observation into `out` ([`GROUND_TRUTH_DIM`] values).
    pub fn one(v: &ObsView<'_>, out: &mut [f64]) {
        let s = v.task.s_m;
        let inv = v.hole_pose.rotation.inverse();
        let lin = inv * Vector3::new(v.obs.ee_twist[0], v.obs.ee_twist[1], v.obs.ee_twist[2]);
        let ang = inv * Vector3::new(v.obs.ee_twist[3], v.obs.ee_twist[4], v.obs.ee_twist[5]);
        let k = v.symmetry.max(1) as f64;
        let mut w = [0.0; 6];
        let n = WRENCH_MEAN_READINGS.min(v.wrench.len()).max(1);
        for r in v.wrench.ordered().skip(v.wrench.len().saturating_sub(n)) {
            for (a, b) in w.iter_mut().zip(r) {
                *a += b / n as f64;
            }
        }
        let vals = [
            s.x / 0.1,
            s.y / 0.1,
            s.z / 0.1,
            v.task.s_psi_rad / (std::f64::consts::PI / k),
            lin.x / 0.1,
            lin.y / 0.1,
            lin.z / 0.1,
            ang.z,
            (w[0] - v.free_wrench[0]) / 10.0,
            (w[1] - v.free_wrench[1]) / 10.0,
            (w[2] - v.free_wrench[2]) / 10.0,
            w[3] - v.free_wrench[3],
            w[4] - v.free_wrench[4],
            w[5] - v.free_wrench[5],
            (s.x / FINE_POSITION_M).tanh(),
            (s.y / FINE_POSITION_M).tanh(),
            (s.z / FINE_POSITION_M).tanh(),
            (v.task.s_psi_rad / FINE_ROLL_RAD).tanh(),
        ];
        out.copy_from_slice(&vals);
    }
}

impl Observer for GroundTruth {
    fn dim(&self) -> usize {
        GROUND_TRUTH_DIM
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        for (v, o) in views.iter().zip(out.chunks_exact_mut(GROUND_TRUTH_DIM)) {
            Self::one(v, o);
        }
    }
}

/// [`GroundTruth`] as a sensor that misplaces the hole: each episode the
/// tip's position relative to the hole (coarse and fine channels) is off
/// by an error drawn once, Gaussian with `std_m` per horizontal axis of the
/// hole frame. Everything else (height, roll, velocities, wrench) is exact.
///
/// What it answers: how precisely must an observation say where the
/// opening is for a policy to insert (a ground-truth policy evaluated
/// under it), and can a policy learn to find the opening by touch when it
/// is told only roughly (one trained under it). The error is drawn from a
/// generator seeded by the hole's pose, which each episode's seed draws:
/// fixed within an episode, the same on a rerun, no state kept. A world
/// whose box is not randomised (`box_xy_range_m` and `box_yaw_range_rad`
/// zero) has one hole pose, so every episode gets the same error there: a
/// bias, not a spread.
#[derive(Debug, Clone, Copy)]
pub struct HoleError {
    /// Standard deviation per horizontal axis, m.
    pub std_m: f64,
}

impl HoleError {
    /// The episode's error (hole-frame x, y), m.
    pub fn error(&self, hole_pose: &Isometry3<f64>) -> [f64; 2] {
        // Any change of the pose gives another seed: the fold mixes the
        // bits of every coordinate (a multiply-rotate hash).
        let t = hole_pose.translation.vector;
        let q = hole_pose.rotation.coords;
        let seed =
            [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
                .iter()
                .fold(0x9e37_79b9_7f4a_7c15u64, |h, v| {
                    (h ^ v.to_bits())
                        .rotate_left(23)
                        .wrapping_mul(0xff51_afd7_ed55_8ccd)
                });
        let mut rng = stack_common::rng::seeded(seed, 0x401e);
        [
            self.std_m * stack_common::rng::normal(&mut rng),
            self.std_m * stack_common::rng::normal(&mut rng),
        ]
    }
}

impl Observer for HoleError {
    fn dim(&self) -> usize {
        GROUND_TRUTH_DIM
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        for (v, o) in views.iter().zip(out.chunks_exact_mut(GROUND_TRUTH_DIM)) {
            let [ex, ey] = self.error(v.hole_pose);
            let mut task = *v.task;
            task.s_m.x += ex;
            task.s_m.y += ey;
            GroundTruth::one(&ObsView { task: &task, ..*v }, o);
        }
    }
}

/// Why a world's camera cannot feed an observer.
#[derive(Debug, thiserror::Error)]
pub enum CameraMismatch {
    /// The world's camera settings are invalid.
    #[error(transparent)]
    Invalid(#[from] shared_mem_schema::config::FieldError),
    /// The world's camera is not the one the observer was trained through.
    #[error(
        "the world's camera ({world}) is not the camera the representation was trained with \
         ({model}); give the world (its [camera]) the training data's camera"
    )]
    Other {
        /// The world's camera.
        world: Box<shared_mem_schema::CameraCalibration>,
        /// The trained one.
        model: Box<shared_mem_schema::CameraCalibration>,
    },
}

/// Refuses a world camera (`camera`, the world's `[camera]`) that is not
/// `trained` (the camera a representation, or the dataset it learns from,
/// was made through; `None`: any camera).
pub fn check_calibration(
    camera: &hw_sim::config::CameraConfig,
    trained: Option<shared_mem_schema::CameraCalibration>,
) -> Result<(), CameraMismatch> {
    let Some(model) = trained else {
        return Ok(());
    };
    // An invalid camera is named by its field, not reported as another one.
    camera.validate()?;
    let world = camera.calibration();
    if world.same_camera(&model) {
        Ok(())
    } else {
        Err(CameraMismatch::Other {
            world: Box::new(world),
            model: Box::new(model),
        })
    }
}

/// The simulator's task state as an episode report carries it (the live
/// node's view of what the fast path reads from the world directly).
pub fn task_state(r: &EpisodeReport) -> TaskState {
    let stage_now = r.stage_now();
    TaskState {
        s_m: Vector3::from(r.s_m),
        s_psi_rad: r.s_psi_rad,
        in_contact: r.in_contact != 0,
        in_hole: stage_now >= Stage::Inserted,
        stage_now,
        best_stage: r.best_stage(),
    }
}
