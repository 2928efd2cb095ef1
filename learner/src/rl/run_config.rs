//! A policy training run's configuration ([`TrainConfig`], the TOML file
//! of `learner policy train`) and the observer its training environments
//! see.

use super::env::{RlEnvConfig, RlEnvError};
use super::observe::ObservationKind;
use super::train::PolicyConfig;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A training run's configuration (TOML; every field defaulted).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Seed of the run (policy initialisation, episode seeds, noise).
    pub seed: u64,
    /// Environments stepped together.
    pub num_envs: usize,
    /// Threads (0: all cores).
    pub threads: usize,
    /// Environment steps to train for (the paper: 2000 episodes of 500).
    pub env_steps: u64,
    /// A checkpoint every this many updates (and at the end).
    pub checkpoint_every: u64,
    /// What the policy observes.
    pub observation: ObservationKind,
    /// The environment.
    pub env: RlEnvConfig,
    /// The policy and its learning algorithm.
    pub policy: PolicyConfig,
    /// Validation episodes during training, which choose the policy to
    /// evaluate.
    pub validation: ValidationConfig,
    /// Start from another run's last policy and baseline (its
    /// `checkpoint.json`) instead of fresh weights: a new run under this
    /// configuration, its counters from zero. Its observation must be this
    /// run's.
    pub init_from: Option<PathBuf>,
}

/// Validation: every `every` updates the current policy's mean runs
/// `episodes` episodes on seeds of their own, and the best validated policy
/// is the one evaluated and deployed. Off by default (the paper evaluates
/// the best policy logged in training, by its training episodes' reward).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValidationConfig {
    /// Validate every this many updates (0: never).
    pub every: u64,
    /// Episodes per validation.
    pub episodes: usize,
    /// Seed of the first validation episode: apart from the training
    /// episodes' seeds and from evaluation's (1 000 000 on).
    pub seed: u64,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        Self {
            every: 0,
            episodes: 10,
            seed: 2_000_000,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            num_envs: 4,
            threads: 0,
            env_steps: 1_000_000,
            checkpoint_every: 10,
            observation: ObservationKind::GroundTruth,
            env: RlEnvConfig::default(),
            policy: PolicyConfig::default(),
            validation: ValidationConfig::default(),
            init_from: None,
        }
    }
}

/// The training environments' observer: the configuration's, or with a
/// hole error and `training.hole_error_ramp_steps` its ramped version,
/// returned beside it for the loop to advance.
pub(super) type TrainingObserver = (
    std::sync::Arc<dyn super::observe::Observer>,
    Option<std::sync::Arc<super::observe::RampedHoleError>>,
);

/// See [`TrainingObserver`].
pub(super) fn training_observer(cfg: &TrainConfig) -> Result<TrainingObserver, RlEnvError> {
    // The configuration's own observer checks its settings (σ) first.
    let observer = cfg.observation.observer_on(cfg.threads)?;
    let steps = cfg.env.training.hole_error_ramp_steps;
    if steps == 0 {
        return Ok((observer, None));
    }
    let refuse = |why: &str| {
        Err(RlEnvError::Config(
            shared_mem_schema::config::FieldError::new(
                "env.training.hole_error_ramp_steps",
                steps,
                why,
            ),
        ))
    };
    let ObservationKind::GroundTruthHoleError(std_m) = cfg.observation else {
        return refuse("ramps a hole error: needs observation = { ground_truth_hole_error = σ }");
    };
    // During the ramp the training reward is earned at a smaller error
    // than the one evaluated: only validation can choose the policy.
    if cfg.validation.every == 0 {
        return refuse("a ramped hole error needs [validation] (every > 0) to choose the policy");
    }
    let r = std::sync::Arc::new(super::observe::RampedHoleError::new(std_m));
    let observer: std::sync::Arc<dyn super::observe::Observer> = r.clone();
    Ok((observer, Some(r)))
}

/// The share of the hole error's ramp done after `history` (the updates
/// so far, `env_steps` steps): the steps over `training.hole_error_ramp_steps`,
/// or with `training.hole_error_gate` only the steps of updates whose
/// training episodes completed the insertion at least that often. Derived
/// from the history alone, so a resumed run goes on where it stopped.
pub(super) fn hole_error_share(
    aids: &super::env::TrainingAids,
    env_steps: u64,
    history: &[super::curve::CurvePoint],
) -> f64 {
    let len = aids.hole_error_ramp_steps.max(1) as f64;
    if aids.hole_error_gate <= 0.0 {
        return (env_steps as f64 / len).min(1.0);
    }
    let c = super::reward::Outcome::CompletedInsertion.index();
    let mut before = 0;
    let mut counted = 0;
    for p in history {
        if p.episodes > 0 && p.outcomes[c] >= aids.hole_error_gate {
            counted += p.env_steps.saturating_sub(before);
        }
        before = p.env_steps;
    }
    (counted as f64 / len).min(1.0)
}

/// The scalars a run logs to TensorBoard for one row of its curve or
/// validation CSV: `extra`, then `{prefix}/mean_normalised` and the share
/// of each outcome (`{prefix}/completed_insertion`, …).
pub(super) fn outcome_scalars(
    prefix: &str,
    mean_normalised: f64,
    outcomes: &[f64; 4],
    extra: &[(&str, f64)],
) -> Vec<(String, f64)> {
    use super::reward::Outcome;
    let mut v: Vec<(String, f64)> = extra
        .iter()
        .map(|&(t, x)| (format!("{prefix}/{t}"), x))
        .collect();
    v.push((format!("{prefix}/mean_normalised"), mean_normalised));
    for o in Outcome::ALL {
        let name = o.name().replace(' ', "_");
        v.push((format!("{prefix}/{name}"), outcomes[o.index()]));
    }
    v
}

#[cfg(test)]
mod tests {
    use super::super::curve::CurvePoint;
    use super::super::env::TrainingAids;
    use super::hole_error_share;

    fn point(env_steps: u64, completed: f64) -> CurvePoint {
        CurvePoint {
            iteration: env_steps / 1000,
            env_steps,
            episodes: 4,
            mean_return: Some(0.0),
            mean_normalised: Some(0.0),
            outcomes: [1.0 - completed, 0.0, 0.0, completed],
            kl: 0.0,
            mean_std: 1.0,
            baseline_explained: 0.0,
            hole_error_std_m: 0.0,
        }
    }

    #[test]
    fn the_gated_ramp_counts_only_the_updates_that_completed_often_enough() {
        let mut aids = TrainingAids {
            hole_error_ramp_steps: 4000,
            ..TrainingAids::default()
        };
        let history = [
            point(1000, 0.0),
            point(2000, 0.5),
            point(3000, 0.2),
            point(4000, 0.25),
        ];
        // Without a gate the share follows the steps.
        assert_eq!(hole_error_share(&aids, 2000, &history[..2]), 0.5);
        assert_eq!(hole_error_share(&aids, 8000, &history), 1.0);
        aids.hole_error_gate = 0.25;
        assert_eq!(hole_error_share(&aids, 0, &[]), 0.0);
        assert_eq!(hole_error_share(&aids, 1000, &history[..1]), 0.0);
        // Updates 2 and 4 reached the gate: 2000 of 4000 steps.
        assert_eq!(hole_error_share(&aids, 4000, &history), 0.5);
        // An update that ended no episode does not advance it.
        let mut idle = point(5000, 1.0);
        idle.episodes = 0;
        let mut h = history.to_vec();
        h.push(idle);
        assert_eq!(hole_error_share(&aids, 5000, &h), 0.5);
    }

    #[test]
    fn a_gate_needs_a_ramp_and_a_share() {
        let gated = |gate, steps| TrainingAids {
            hole_error_gate: gate,
            hole_error_ramp_steps: steps,
            ..TrainingAids::default()
        };
        assert!(gated(0.25, 1000).validate().is_ok());
        let e = gated(0.25, 0).validate().unwrap_err().to_string();
        assert!(e.contains("training.hole_error_gate"), "{e}");
        for bad in [-0.1, 1.5, f64::NAN] {
            let e = gated(bad, 1000).validate().unwrap_err().to_string();
            assert!(e.contains("training.hole_error_gate"), "{e}");
        }
    }
}
