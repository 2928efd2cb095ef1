//! The evaluation stage: a trained policy on each evaluation peg (reusing
//! an evaluation on file of the same policy), and the pooling of several
//! training seeds' evaluations into one row.

use super::ExperimentConfig;
use super::Variant;
use super::results::{SeedRow, StoredEval, read_eval};
use super::stages::StageLog;
use crate::rl::reward::Outcome;
use crate::rl::run::{self as policy_run, Checkpoint, EvalReport};
use anyhow::{Context, Result};
use hw_sim::PegShape;
use std::path::Path;

/// Evaluates `ckpt`'s chosen policy (its last with `last`) on each of the
/// experiment's evaluation pegs (its training peg when none is named),
/// into `dir/eval-<peg><tag>.json`; returns each peg's report.
#[allow(clippy::too_many_arguments)] // the stage's whole context
pub(super) fn evaluate_policy(
    cfg: &ExperimentConfig,
    v: &Variant,
    ckpt: &Checkpoint,
    last: bool,
    dir: &Path,
    tag: &str,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Vec<(PegShape, EvalReport)>> {
    // TRPO/PPO (a fine-tune too): the best validated policy when the
    // policy configuration validates, otherwise the best logged in
    // training (the paper's protocol). DAgger: the last round's.
    let chosen = ckpt.chosen_policy(last);
    let pegs = if cfg.eval.pegs.is_empty() {
        vec![ckpt.config.env.world.task.peg]
    } else {
        cfg.eval.pegs.clone()
    };
    let mut out = Vec::new();
    for peg in pegs {
        let path = dir.join(format!("eval-{}{tag}.json", peg.name()));
        let wanted = |e: &StoredEval| {
            e.policy_iteration == chosen.iteration
                && e.run_env_steps == ckpt.state.env_steps
                && e.seed == cfg.eval.seed
                && e.report.episodes == cfg.eval.episodes
        };
        let report = match read_eval(&path)?.filter(wanted) {
            Some(e) => e.report,
            None => {
                log.start(&format!(
                    "{}: evaluation of {chosen} on the {} peg ({} episodes{})",
                    v.name,
                    peg.name(),
                    cfg.eval.episodes,
                    tag.strip_prefix("-s")
                        .map_or(String::new(), |s| format!(", seed {s}"))
                ));
                let mut ecfg = ckpt.config.clone();
                ecfg.env.world.task.peg = peg;
                let report = policy_run::evaluate(
                    chosen.policy,
                    &ecfg,
                    cfg.eval.episodes,
                    cfg.eval.seed,
                    stop,
                )?;
                let e = StoredEval {
                    policy_iteration: chosen.iteration,
                    run_env_steps: ckpt.state.env_steps,
                    seed: cfg.eval.seed,
                    report,
                };
                std::fs::write(&path, serde_json::to_vec_pretty(&e)?)
                    .with_context(|| format!("writing {}", path.display()))?;
                log.end()?;
                e.report
            }
        };
        out.push((peg, report));
    }
    Ok(out)
}

/// Completed insertions of a report, as a count.
pub(super) fn completed(r: &EvalReport) -> usize {
    (r.outcomes[Outcome::CompletedInsertion.index()] * r.episodes as f64).round() as usize
}

/// Several training seeds' evaluations (of the same episodes) as one: the
/// episodes of all, each outcome's share of them all, and each seed's own
/// count.
pub(super) fn pool(reports: &[(u64, EvalReport)]) -> (EvalReport, Vec<SeedRow>) {
    let episodes: usize = reports.iter().map(|(_, r)| r.episodes).sum();
    let mut outcomes = [0.0; 4];
    let mut normalised = Vec::with_capacity(episodes);
    let mut fault_codes = Vec::new();
    for (_, r) in reports {
        for (o, share) in outcomes.iter_mut().zip(r.outcomes) {
            *o += share * r.episodes as f64 / episodes.max(1) as f64;
        }
        normalised.extend_from_slice(&r.normalised);
        fault_codes.extend_from_slice(&r.fault_codes);
    }
    let mean_normalised = normalised.iter().sum::<f64>() / normalised.len().max(1) as f64;
    let pooled = EvalReport {
        episodes,
        outcomes,
        mean_normalised,
        normalised,
        sampled: reports.iter().any(|(_, r)| r.sampled),
        fault_codes,
    };
    let seeds = reports
        .iter()
        .map(|(seed, r)| SeedRow {
            seed: *seed,
            completed: completed(r),
            episodes: r.episodes,
        })
        .collect();
    (pooled, seeds)
}

/// Wilson's score interval of `k` successes in `n` trials at 95 %, as
/// shares (docs/results.md's rates).
pub fn wilson(k: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (k, n) = (k as f64, n as f64);
    let z = 1.96_f64;
    let p = k / n;
    let d = 1.0 + z * z / n;
    let c = (p + z * z / 2.0 / n) / d;
    let h = z * (p * (1.0 - p) / n + z * z / 4.0 / n / n).sqrt() / d;
    ((c - h).max(0.0), (c + h).min(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interval of docs/results.md's one-liner, and its edges.
    #[test]
    fn wilson_matches_the_documented_intervals() {
        let pct = |(a, b): (f64, f64)| ((100.0 * a).round(), (100.0 * b).round());
        assert_eq!(pct(wilson(118, 150)), (71.0, 84.0));
        assert_eq!(pct(wilson(30, 50)), (46.0, 72.0));
        assert_eq!(pct(wilson(0, 96)), (0.0, 4.0));
        let (lo, hi) = wilson(50, 50);
        assert!(lo > 0.9 && hi == 1.0);
    }

    /// Pooling keeps every episode and each seed's count.
    #[test]
    fn pooled_seeds_count_every_episode() {
        let r = |completed: f64, n: usize, faults: Vec<u32>| EvalReport {
            episodes: n,
            outcomes: [1.0 - completed, 0.0, 0.0, completed],
            mean_normalised: completed,
            normalised: vec![completed; n],
            sampled: false,
            fault_codes: faults,
        };
        let (p, seeds) = pool(&[(1, r(0.5, 4, vec![0; 4])), (2, r(1.0, 6, vec![4; 6]))]);
        assert_eq!(p.episodes, 10);
        assert_eq!(completed(&p), 8);
        assert!((p.outcomes.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((p.mean_normalised - 0.8).abs() < 1e-12);
        assert_eq!(p.faulted(), 6);
        assert_eq!(
            seeds,
            [
                SeedRow {
                    seed: 1,
                    completed: 2,
                    episodes: 4
                },
                SeedRow {
                    seed: 2,
                    completed: 6,
                    episodes: 6
                }
            ]
        );
    }
}
