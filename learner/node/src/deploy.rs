//! A trained policy outside its training run: loaded from a checkpoint
//! with the observer it was trained with (ground truth, or the frozen
//! representation it names) and its action scale, it turns one state into
//! the controller's action: the Gaussian's mean, clipped and scaled as the
//! environment did. The live policy node (`learner run --policy`) acts
//! through it.

use super::env::ActionScale;
use super::gaussian::GaussianPolicy;
use super::observe::{ObsView, Observer};
use super::run::{RunError, read_checkpoint};
use crate::policy::Action4;
use hw_sim::{PegShape, Stage, TaskState};
use nalgebra::Vector3;
use shared_mem_schema::EpisodeReport;
use std::path::Path;
use std::sync::Arc;

/// A policy and what it needs to act.
pub struct TrainedPolicy {
    policy: GaussianPolicy,
    observer: Arc<dyn Observer>,
    scale: ActionScale,
    peg: PegShape,
}

impl std::fmt::Debug for TrainedPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrainedPolicy")
            .field("sizes", &self.policy.sizes)
            .field("observation_dim", &self.observer.dim())
            .field("scale", &self.scale)
            .field("peg", &self.peg)
            .finish()
    }
}

impl TrainedPolicy {
    /// Loads `checkpoint` (a run's checkpoint.json): its best validated or
    /// best logged policy unless `last`
    /// ([`super::run::Checkpoint::chosen_policy`]), and its
    /// observer (a representation's model is loaded from the directory the
    /// run was configured with). Returns the line saying which policy.
    pub fn load(checkpoint: &Path, last: bool) -> Result<(Self, String), RunError> {
        let c = read_checkpoint(checkpoint)?;
        let observer = c.config.observation.observer()?;
        let chosen = c.chosen_policy(last);
        let which = chosen.to_string();
        Self::new(
            chosen.policy.clone(),
            observer,
            c.config.env.action,
            c.config.env.world.task.peg,
        )
        .map(|p| (p, which))
        .map_err(|detail| RunError::Parse {
            path: checkpoint.to_path_buf(),
            detail,
        })
    }

    /// From its parts; refused when the policy's input is not the
    /// observer's output.
    pub fn new(
        policy: GaussianPolicy,
        observer: Arc<dyn Observer>,
        scale: ActionScale,
        peg: PegShape,
    ) -> Result<Self, String> {
        let input = policy.sizes.first().copied().unwrap_or(0);
        if input != observer.dim() || policy.act_dim() != 4 {
            return Err(format!(
                "the policy takes {input} inputs and gives {} actions; its observer gives {} \
                 values and the controller takes 4",
                policy.act_dim(),
                observer.dim()
            ));
        }
        if let Some(n) = &policy.obs_norm
            && n.dim() != input
        {
            return Err(format!(
                "the policy's observation normalisation has {} components, its network {input} \
                 inputs",
                n.dim()
            ));
        }
        Ok(Self {
            policy,
            observer,
            scale,
            peg,
        })
    }

    /// Refuses a world whose camera is not the one the policy's
    /// representation was trained with (its z would describe another
    /// scene).
    pub fn check_world(&self, world: &hw_sim::WorldConfig) -> Result<(), super::env::RlEnvError> {
        super::observe::check_camera(&world.camera, self.observer.as_ref())
    }

    /// Whether the observer reads the camera.
    pub fn needs_camera(&self) -> bool {
        self.observer.needs_camera()
    }

    /// Observations the observer could not make and gave as zeros so far
    /// (a camera frame missing or of another size, a value not finite).
    pub fn rejected(&self) -> u64 {
        self.observer.rejected()
    }

    /// The peg it was trained on.
    pub fn trained_peg(&self) -> PegShape {
        self.peg
    }

    /// The action for one state: the mean, clipped to [−1, 1] and scaled.
    pub fn act(&self, view: &ObsView<'_>) -> Action4 {
        let mut obs = vec![0.0; self.observer.dim()];
        self.observer.observe(std::slice::from_ref(view), &mut obs);
        self.scale.to_delta(&self.policy.means(&obs))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rl::observe::GroundTruth;
    use crate::rl::{ObsNorm, RlEnv};

    #[test]
    fn a_deployed_policy_acts_on_its_normalised_observation() {
        let mut env = RlEnv::new(&Default::default()).unwrap();
        env.reset(5, false).unwrap();
        env.step(&[0.3, -0.2, -0.5, 0.1], false).unwrap();
        let view = env.view().unwrap();
        let mut obs = vec![0.0; GroundTruth.dim()];
        GroundTruth.observe(std::slice::from_ref(&view), &mut obs);
        let mut rng = hw_sim::rng::seeded(1, 0);
        let mut policy = GaussianPolicy::new(obs.len(), &[8], 4, 0.0, &mut rng);
        // Statistics far from the identity: every component shifted and
        // spread around values unlike this observation's.
        let mut norm = ObsNorm::new(obs.len(), 5.0);
        let seen: Vec<f64> = (0..4 * obs.len())
            .map(|k| 0.3 * (k % 7) as f64 - 0.8)
            .collect();
        norm.update(&seen);
        policy.obs_norm = Some(norm.clone());
        let scale = ActionScale::default();
        let p = TrainedPolicy::new(
            policy.clone(),
            Arc::new(GroundTruth),
            scale.clone(),
            PegShape::Square,
        )
        .unwrap();
        let acted = p.act(&view);
        assert_eq!(acted, scale.to_delta(&policy.net_means(&norm.apply(&obs))));
        assert_ne!(acted, scale.to_delta(&policy.net_means(&obs)));
        // A normaliser of another size than the network's input is refused.
        policy.obs_norm = Some(ObsNorm::new(3, 5.0));
        let e = TrainedPolicy::new(policy, Arc::new(GroundTruth), scale, PegShape::Square);
        assert!(e.err().unwrap().contains("normalisation"));
    }
}
