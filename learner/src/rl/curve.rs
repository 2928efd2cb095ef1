//! A training run's record: the learning-curve points and validations it
//! keeps in its checkpoint, and the `curve.csv`, `validation.csv` and
//! charts written from them. Owns no training logic; `run` fills it.

use super::reward::Outcome;
use super::train::{Algorithm, IterationStats};
use crate::plot::{Chart, Series};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Why a run's record could not be written.
#[derive(Debug, thiserror::Error)]
pub enum CurveError {
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CurveError + '_ {
    move |source| CurveError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// One validation's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationPoint {
    /// The update validated.
    pub iteration: u64,
    /// Environment steps then.
    pub env_steps: u64,
    /// Share in each outcome category ([`Outcome::ALL`] order).
    pub outcomes: [f64; 4],
    /// Mean normalised episode reward.
    pub mean_normalised: f64,
}

impl ValidationPoint {
    /// Whether it beats `other`: more completed insertions, then a higher
    /// reward.
    pub(crate) fn beats(&self, other: &ValidationPoint) -> bool {
        let c = Outcome::CompletedInsertion.index();
        (self.outcomes[c], self.mean_normalised) > (other.outcomes[c], other.mean_normalised)
    }
}

/// One point of the learning curves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Update number.
    pub iteration: u64,
    /// Environment steps so far.
    pub env_steps: u64,
    /// Episodes finished in the update's batch.
    pub episodes: usize,
    /// Their mean reward (None: none finished; JSON has no NaN, so a NaN
    /// here made the checkpoint unreadable).
    pub mean_return: Option<f64>,
    /// Their mean normalised reward.
    pub mean_normalised: Option<f64>,
    /// Share in each outcome category ([`Outcome::ALL`] order).
    pub outcomes: [f64; 4],
    /// KL of the update.
    pub kl: f64,
    /// Mean σ of the policy.
    pub mean_std: f64,
    /// The share of the batch's λ-returns the baseline explained before
    /// its fit (absent from runs before it was recorded: 0).
    #[serde(default)]
    pub baseline_explained: f64,
    /// The hole error's standard deviation the update's training episodes
    /// observed, m (0 without one; absent from runs before it was
    /// recorded: 0).
    #[serde(default)]
    pub hole_error_std_m: f64,
}

impl CurvePoint {
    /// The point of one update, before the hole error is noted.
    pub(super) fn from_stats(s: &IterationStats) -> Self {
        Self {
            iteration: s.iteration,
            env_steps: s.env_steps,
            episodes: s.episodes.len(),
            mean_return: s.mean_return(),
            mean_normalised: s.mean_normalised(),
            outcomes: s.outcome_shares(),
            kl: s.update.kl,
            mean_std: s.mean_std,
            baseline_explained: s.baseline_explained,
            hole_error_std_m: 0.0,
        }
    }
}

/// Writes `validation.csv`: one row per validation.
pub(super) fn write_validation_csv(
    out: &Path,
    points: &[ValidationPoint],
) -> Result<(), CurveError> {
    let mut text = String::from(
        "iteration,env_steps,mean_normalised,completed_insertion,inserted_into_hole,\
         touched_the_box,failed\n",
    );
    for p in points {
        let o = |x: Outcome| p.outcomes[x.index()];
        text.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            p.iteration,
            p.env_steps,
            p.mean_normalised,
            o(Outcome::CompletedInsertion),
            o(Outcome::InsertedIntoHole),
            o(Outcome::TouchedBox),
            o(Outcome::Failed)
        ));
    }
    let path = out.join("validation.csv");
    crate::write_atomic(&path, text.as_bytes()).map_err(io(&path))
}

/// Writes `curve.csv` and the two charts of a run.
pub fn write_curves(
    out: &Path,
    history: &[CurvePoint],
    algorithm: Algorithm,
) -> Result<(), CurveError> {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    let path = out.join("curve.csv");
    let mut f = std::fs::File::create(&path).map_err(io(&path))?;
    let mut text = String::from(
        "iteration,env_steps,episodes,mean_return,mean_normalised,completed_insertion,inserted_into_hole,touched_the_box,failed,kl,mean_std,baseline_explained,hole_error_std_m\n",
    );
    for p in history {
        let o = p.outcomes;
        text += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            p.iteration,
            p.env_steps,
            p.episodes,
            opt(p.mean_return),
            opt(p.mean_normalised),
            o[3],
            o[2],
            o[1],
            o[0],
            p.kl,
            p.mean_std,
            p.baseline_explained,
            p.hole_error_std_m
        );
    }
    f.write_all(text.as_bytes()).map_err(io(&path))?;
    let finished: Vec<&CurvePoint> = history.iter().filter(|p| p.episodes > 0).collect();
    if finished.is_empty() {
        return Ok(());
    }
    // Episode-weighted means over the last SMOOTH updates: an update ends
    // only a few episodes (the paper's four), too few for a share.
    const SMOOTH: usize = 20;
    let pts = |f: &dyn Fn(&CurvePoint) -> f64| {
        (0..finished.len())
            .map(|i| {
                let w = &finished[i.saturating_sub(SMOOTH - 1)..=i];
                let n: usize = w.iter().map(|p| p.episodes).sum();
                let m = w.iter().map(|p| f(p) * p.episodes as f64).sum::<f64>() / n as f64;
                (finished[i].env_steps as f64, m)
            })
            .collect::<Vec<_>>()
    };
    let name = match algorithm {
        Algorithm::Trpo => "TRPO",
        Algorithm::Ppo => "PPO",
    };
    Chart::new(
        &format!("{name}: episode reward"),
        "environment steps (20 Hz policy steps)",
        "mean normalised episode reward (last 20 updates)",
    )
    .with(Series::line(
        "mean normalised reward",
        pts(&|p| p.mean_normalised.unwrap_or(f64::NAN)),
    ))
    .write_png(out.join("return.png"))?;
    let mut chart = Chart::new(
        &format!("{name}: outcome of the episodes"),
        "environment steps (20 Hz policy steps)",
        "share of the episodes of the last 20 updates",
    );
    for o in Outcome::ALL.into_iter().rev() {
        chart = chart.with(Series::line(o.name(), pts(&|p| p.outcomes[o.index()])));
    }
    chart.write_png(out.join("outcomes.png"))?;
    Ok(())
}
