//! The run's record: each round's [`RoundPoint`], the checkpoint, the CSV
//! and the charts.

use crate::plot::{Chart, Series};
use crate::rl::run::{
    Checkpoint, RunError, TrainConfig, ValidatedPolicy, ValidationPoint, checkpoint_path,
    read_json, write_json,
};
use crate::rl::train::TrainerState;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One round's record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundPoint {
    /// Round (from 0).
    pub round: u64,
    /// Its teacher share β.
    pub beta: f64,
    /// Samples after it, all rounds.
    pub samples: usize,
    /// Environment steps of the round that took the student's action (the
    /// others took the teacher's; absent in runs recorded before it was).
    #[serde(default)]
    pub student_steps: usize,
    /// The previous student's mean squared error (summed over the action's
    /// components) on this round's samples before the refit: its error on
    /// the states it led to.
    pub error_before: f64,
    /// `error_before` per action component (Δx, Δy, Δz, Δroll; empty in
    /// runs recorded before it was).
    #[serde(default)]
    pub error_before_parts: Vec<f64>,
    /// The refitted student's error on every round's samples so far (the
    /// fitted ones: without the held-out environments').
    pub error_after: f64,
    /// `error_after` per action component (empty in runs recorded before
    /// it was).
    #[serde(default)]
    pub error_after_parts: Vec<f64>,
    /// With `dagger.holdout_envs`: the kept network's error on the
    /// held-out episodes and its epoch (absent otherwise, and in runs
    /// recorded before it was). `error_after` is then on the fitted
    /// samples alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<HoldoutFit>,
    /// The refitted student's validation.
    pub validation: ValidationPoint,
}

/// The network a refit kept by its error on held-out episodes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HoldoutFit {
    /// Mean squared error on the held-out samples, summed over the
    /// action's components.
    pub error: f64,
    /// The epoch it came from (0: the network the round started with).
    pub epoch: usize,
}

/// The rounds recorded in `out`'s `distill.json` (none when it is absent).
pub(super) fn read_rounds(out: &Path) -> Result<Vec<RoundPoint>, RunError> {
    let path = out.join("distill.json");
    if path.exists() {
        read_json(&path)
    } else {
        Ok(Vec::new())
    }
}

/// Writes the run's record, the checkpoint, `distill.csv` and the charts,
/// and returns the checkpoint.
pub(super) fn save(
    out: &Path,
    cfg: &TrainConfig,
    state: &TrainerState,
    rounds: &[RoundPoint],
    best: &Option<ValidatedPolicy>,
) -> Result<Checkpoint, RunError> {
    let c = Checkpoint {
        config: cfg.clone(),
        state: state.clone(),
        history: Vec::new(),
        best: None,
        validations: rounds.iter().map(|r| r.validation.clone()).collect(),
        best_validated: best.clone(),
    };
    // The record first: a checkpoint never counts a round it lacks.
    write_json(&out.join("distill.json"), &rounds)?;
    write_json(&checkpoint_path(out), &c)?;
    let mut csv = String::from(
        "round,beta,samples,student_steps,error_before,error_after,error_after_dx,error_after_dy,\
         error_after_dz,error_after_droll,env_steps,completed_insertion,inserted_into_hole,\
         touched_the_box,failed,mean_normalised,holdout_error,holdout_epoch\n",
    );
    for p in rounds {
        let o = p.validation.outcomes;
        let part = |k: usize| p.error_after_parts.get(k).copied().unwrap_or(f64::NAN);
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            p.round,
            p.beta,
            p.samples,
            p.student_steps,
            p.error_before,
            p.error_after,
            part(0),
            part(1),
            part(2),
            part(3),
            p.validation.env_steps,
            o[3],
            o[2],
            o[1],
            o[0],
            p.validation.mean_normalised,
            p.holdout.map_or(String::new(), |h| h.error.to_string()),
            p.holdout.map_or(String::new(), |h| h.epoch.to_string()),
        );
    }
    let path = out.join("distill.csv");
    crate::write_atomic(&path, csv.as_bytes()).map_err(|source| RunError::Io { path, source })?;
    if !rounds.is_empty() {
        let x = |f: &dyn Fn(&RoundPoint) -> f64| {
            rounds
                .iter()
                .map(|p| (p.round as f64, f(p)))
                .collect::<Vec<_>>()
        };
        Chart::new(
            "DAgger: the student's validation after each round",
            "round",
            "share of validation episodes / normalised reward",
        )
        .with(Series::line(
            "completed insertion",
            x(&|p| p.validation.outcomes[crate::rl::Outcome::CompletedInsertion.index()]),
        ))
        .with(Series::line(
            "mean normalised reward",
            x(&|p| p.validation.mean_normalised),
        ))
        .write_png(out.join("distill.png"))?;
        let chart = Chart::new(
            "DAgger: the student's action error",
            "round",
            "mean squared action error (4 components summed)",
        )
        .with(Series::line(
            "on the round's new states, before the refit",
            x(&|p| p.error_before),
        ))
        .with(Series::line(
            "on the fitted samples so far, after the refit",
            x(&|p| p.error_after),
        ));
        let held = rounds.iter().any(|p| p.holdout.is_some());
        let chart = if held {
            chart.with(Series::line(
                "on the held-out episodes so far, the kept epoch",
                x(&|p| p.holdout.map_or(f64::NAN, |h| h.error)),
            ))
        } else {
            chart
        };
        chart.write_png(out.join("distill-error.png"))?;
    }
    Ok(c)
}
