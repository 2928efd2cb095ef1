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
