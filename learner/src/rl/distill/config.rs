//! The distillation's configuration: the teacher, the student's run and
//! DAgger's settings.

use crate::rl::run::{RunError, TrainConfig, read_toml};
use crate::rl::search::TouchSearchConfig;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;
use std::path::{Path, PathBuf};

/// A distillation's configuration (TOML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistillConfig {
    /// The teacher: a `learner policy train` checkpoint, whose chosen policy
    /// (the best validated, else the best logged) acts. Either this or
    /// `[search_teacher]`.
    #[serde(default)]
    pub teacher: Option<PathBuf>,
    /// A scripted teacher in place of a checkpoint: the touch search
    /// ([`crate::rl::search::TouchSearch`]), told the hole with a per-episode
    /// error, which slides over the top face until the peg drops in. It
    /// acts in `[student.env]`.
    #[serde(default)]
    pub search_teacher: Option<TouchSearchConfig>,
    /// The student's run: its observation, policy layers, environments,
    /// threads, seed and validation. With a checkpoint teacher its
    /// environment is the teacher's (the teacher's actions mean nothing
    /// elsewhere): an `[student.env]` that differs from it is refused.
    pub student: TrainConfig,
    /// DAgger's settings.
    #[serde(default)]
    pub dagger: DaggerConfig,
    /// The camera the student sees through, in place of the teacher
    /// environment's (`[camera]`, hw-sim's camera fields): a student on a
    /// representation trained with another camera than the teacher's world
    /// has. The camera changes what is seen, not what happens, so a
    /// ground-truth teacher's actions still hold; a teacher that observes
    /// the camera itself keeps its own, and this is refused. The section
    /// replaces the whole camera: fields left out take hw-sim's defaults,
    /// not the teacher's.
    #[serde(default)]
    pub camera: Option<hw_sim::config::CameraConfig>,
}

/// DAgger's settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaggerConfig {
    /// Rounds of collection and refit.
    pub rounds: u64,
    /// Environment steps collected per round (over all environments; a
    /// round steps every environment alike, so it rounds this up to a
    /// multiple of `student.num_envs`).
    pub steps_per_round: usize,
    /// β of round r is this to the power r: round 0 acts with the teacher
    /// alone.
    pub teacher_share_decay: f64,
    /// The refit after each round.
    pub epochs: usize,
    /// Samples per Adam step.
    pub minibatch: usize,
    /// Adam's step size.
    pub learning_rate: f64,
    /// Seed of the first collected episode (the run's episode seeds go up
    /// from it; apart from evaluation's, from 1 000 000, and validation's).
    pub episode_seed: u64,
    /// Environments whose samples each round holds out of the refit (the
    /// last ones: whole episodes, never a state of one on each side). The
    /// refit scores itself on them after every epoch and keeps the
    /// network of the best epoch, the round's incoming weights (under the
    /// refitted normalisation) included: early stopping. 0 (the default):
    /// every sample is fitted for `epochs`.
    /// Why: a student with many inputs (raw pixels) fits its labels to
    /// within a hundredth while its error on other episodes grows.
    pub holdout_envs: usize,
}

impl Default for DaggerConfig {
    fn default() -> Self {
        Self {
            rounds: 10,
            steps_per_round: 8000,
            teacher_share_decay: 0.5,
            epochs: 10,
            minibatch: 256,
            learning_rate: 1e-3,
            episode_seed: 5_000_000,
            holdout_envs: 0,
        }
    }
}

impl DaggerConfig {
    pub(super) fn validate(&self) -> Result<(), FieldError> {
        if self.rounds == 0 {
            return Err(FieldError::new("dagger.rounds", 0, "must be at least 1"));
        }
        if self.steps_per_round == 0 {
            return Err(FieldError::new(
                "dagger.steps_per_round",
                0,
                "must be at least 1",
            ));
        }
        if !(0.0..=1.0).contains(&self.teacher_share_decay) {
            return Err(FieldError::new(
                "dagger.teacher_share_decay",
                self.teacher_share_decay,
                "must lie in [0, 1]",
            ));
        }
        if self.epochs == 0 || self.minibatch == 0 {
            return Err(FieldError::new(
                "dagger.epochs / dagger.minibatch",
                0,
                "must be at least 1",
            ));
        }
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            return Err(FieldError::new(
                "dagger.learning_rate",
                self.learning_rate,
                "must be positive",
            ));
        }
        Ok(())
    }
}

/// Reads a distillation configuration.
pub fn read_config(path: &Path) -> Result<DistillConfig, RunError> {
    read_toml(path)
}
