//! The results: each evaluation on file, the rows of a variant on a peg,
//! and the table, CSV, JSON and charts they make.

use super::{ExperimentConfig, RunOptions};
use crate::plot::{Chart, Series};
use crate::rl::reward::Outcome;
use crate::rl::run::EvalReport;
use anyhow::{Context, Result};
use hw_sim::PegShape;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// An evaluation on file, with what it evaluated: it is reused only for
/// the same policy (the same update of the same run), seed and length.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct StoredEval {
    /// The update of the policy evaluated.
    pub(super) policy_iteration: u64,
    /// The run's environment steps when it was evaluated.
    pub(super) run_env_steps: u64,
    /// Seed of the first episode.
    pub(super) seed: u64,
    /// The evaluation.
    pub(super) report: EvalReport,
}

/// One row of the results: a variant on one peg.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResultRow {
    /// The variant.
    pub variant: String,
    /// The evaluation peg.
    pub peg: PegShape,
    /// The evaluation.
    pub report: EvalReport,
    /// The paper's completed-insertion share (on the training peg only:
    /// the paper's ablation numbers are not transfer numbers).
    pub paper_completed: Option<f64>,
    /// With several training seeds (`policy.seeds`): each one's count;
    /// `report` pools them.
    #[serde(default)]
    pub per_seed: Vec<SeedRow>,
    /// How the policy learned, as docs/results.md names routes.
    #[serde(default)]
    pub route: String,
}

/// One training seed's completed insertions in a pooled row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedRow {
    /// The training seed.
    pub seed: u64,
    /// Completed insertions.
    pub completed: usize,
    /// Of this many episodes.
    pub episodes: usize,
}

/// `rows` of this invocation, and for a partial one (`--only`) the other
/// variants' rows on file, in the configuration's order.
pub(super) fn with_others(
    cfg: &ExperimentConfig,
    opts: &RunOptions,
    out: &Path,
    rows: &[ResultRow],
) -> Vec<ResultRow> {
    if opts.only.is_empty() {
        return rows.to_vec();
    }
    let path = out.join("results.json");
    // A missing file is a first run; an unreadable one is said aloud, since
    // the table written next would silently lack the other variants.
    let old: Vec<ResultRow> = match std::fs::read(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        read => read
            .map_err(anyhow::Error::from)
            .and_then(|text| Ok(serde_json::from_slice(&text)?))
            .unwrap_or_else(|e| {
                eprintln!(
                    "experiment: {} unreadable ({e}); the results keep only this run's variants",
                    path.display()
                );
                Vec::new()
            }),
    };
    let mut merged = Vec::new();
    for v in &cfg.variant {
        let from = if opts.only.contains(&v.name) {
            rows
        } else {
            &old[..]
        };
        merged.extend(from.iter().filter(|r| r.variant == v.name).cloned());
    }
    merged
}

/// The evaluation on file at `path`, if any (one that does not parse is
/// done again, with a warning).
pub(super) fn read_eval(path: &Path) -> Result<Option<StoredEval>> {
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    match serde_json::from_slice(&text) {
        Ok(e) => Ok(Some(e)),
        Err(e) => {
            eprintln!("experiment: {}: {e}; evaluating again", path.display());
            Ok(None)
        }
    }
}

/// Writes `results.md`, `results.csv`, `results.json` and
/// `completed-<peg>.png`.
pub fn write_results(out: &Path, rows: &[ResultRow]) -> Result<()> {
    let pct = |x: f64| format!("{:.0}%", 100.0 * x);
    let mut md = String::from(
        "| variant | route | peg | episodes | completed insertion (95 % interval) | per training seed | inserted into hole | touched the box | failed | normalised reward | paper: completed |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut csv = String::from(
        "variant,peg,episodes,completed_insertion,inserted_into_hole,touched_the_box,failed,normalised_reward,paper_completed,completed_interval_low,completed_interval_high,route\n",
    );
    for r in rows {
        let o = r.report.outcomes;
        let c = |x: Outcome| o[x.index()];
        let k = super::evaluate::completed(&r.report);
        let (lo, hi) = super::evaluate::wilson(k, r.report.episodes);
        let seeds = r
            .per_seed
            .iter()
            .map(|s| format!("s{}: {} of {}", s.seed, s.completed, s.episodes))
            .collect::<Vec<_>>()
            .join(", ");
        md += &format!(
            "| {} | {} | {} | {} | {k} of {} ({:.0} %, {:.0}–{:.0}) | {} | {} | {} | {} | {:.3} | {} |\n",
            r.variant,
            r.route,
            r.peg.name(),
            r.report.episodes,
            r.report.episodes,
            100.0 * c(Outcome::CompletedInsertion),
            100.0 * lo,
            100.0 * hi,
            if seeds.is_empty() {
                "–".into()
            } else {
                seeds
            },
            pct(c(Outcome::InsertedIntoHole)),
            pct(c(Outcome::TouchedBox)),
            pct(c(Outcome::Failed)),
            r.report.mean_normalised,
            r.paper_completed.map_or("–".into(), pct)
        );
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{lo},{hi},{}\n",
            r.variant,
            r.peg.name(),
            r.report.episodes,
            c(Outcome::CompletedInsertion),
            c(Outcome::InsertedIntoHole),
            c(Outcome::TouchedBox),
            c(Outcome::Failed),
            r.report.mean_normalised,
            r.paper_completed.map_or(String::new(), |p| p.to_string()),
            r.route
        );
    }
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    write("results.md", &md)?;
    write("results.csv", &csv)?;
    write("results.json", &serde_json::to_string_pretty(rows)?)?;
    let mut pegs: Vec<PegShape> = Vec::new();
    for r in rows {
        if !pegs.contains(&r.peg) {
            pegs.push(r.peg);
        }
    }
    for peg in pegs {
        let here: Vec<&ResultRow> = rows.iter().filter(|r| r.peg == peg).collect();
        let names: Vec<String> = here.iter().map(|r| r.variant.clone()).collect();
        let ours: Vec<f64> = here
            .iter()
            .map(|r| 100.0 * r.report.outcomes[Outcome::CompletedInsertion.index()])
            .collect();
        let paper: Vec<f64> = here
            .iter()
            .map(|r| r.paper_completed.map_or(f64::NAN, |p| 100.0 * p))
            .collect();
        Chart::new(
            &format!("Completed insertions, {} peg", peg.name()),
            "representation the policy observes",
            "completed insertion (% of evaluation episodes)",
        )
        .with_categories(names)
        .with(Series::bars("ours", &ours, -0.4, 0.4))
        .with(Series::bars(
            "paper (where its text gives it)",
            &paper,
            0.0,
            0.4,
        ))
        .write_png(out.join(format!("completed-{}.png", peg.name())))?;
    }
    Ok(())
}
