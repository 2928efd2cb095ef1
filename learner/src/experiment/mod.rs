//! `learner experiment`: the paper's ablations end to end. For each
//! variant (a representation configuration, or the ground truth): the
//! dataset (collected and built once, shared), the representation trained
//! on it, a policy trained on its frozen z means, and the evaluation of that
//! policy on each evaluation peg; then one results table and bar charts of
//! the completed-insertion share next to the paper's numbers.
//!
//! The policy learns one of two ways: by `learner policy train` (TRPO or
//! PPO on z, the paper's), or by `learner policy distill` (DAgger from the
//! touch search whose belief of the opening is a linear probe of the same
//! z, the route that completes insertions here; docs/results.md). Both
//! take the variant's representation in place of their configuration's.
//!
//! Every stage leaves its output in the experiment's directory and is
//! skipped when that output is complete, so an interrupted experiment
//! resumes where it stopped (the representation and the policy also resume
//! mid-run from their own checkpoints). The scale — states, epochs,
//! environment steps, episodes — is the configuration's: one file for this
//! machine, one for a GPU machine at the paper's scale.

mod config;
mod results;
mod stages;

pub use config::{DataStage, EvalStage, ExperimentConfig, PolicyStage, ReprStage, Variant};
pub use results::{ResultRow, write_results};

use crate::rl::distill;
use crate::rl::observe::ObservationKind;
use crate::rl::run as policy_run;
use anyhow::{Context, Result, bail, ensure};
use results::{StoredEval, read_eval, with_others};
use stages::{Route, StageLog, distill_policy, ensure_dataset, representation, train_policy};
use std::path::Path;

/// Options of one invocation.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Run only the variants of these names (empty: all).
    pub only: Vec<String>,
    /// Show progress bars.
    pub progress: bool,
}

/// Runs (or resumes) the experiment into `out`; returns its rows, also
/// written to `results.md`, `results.csv`, `results.json` and a chart per
/// evaluation peg.
pub fn run(
    cfg: &ExperimentConfig,
    out: &Path,
    opts: &RunOptions,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Vec<ResultRow>> {
    cfg.validate()?;
    for name in &opts.only {
        ensure!(
            cfg.variant.iter().any(|v| &v.name == name),
            "--only {name}: no such variant"
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut log = StageLog::open(out);
    let route = match &cfg.policy.distill {
        Some(p) => {
            let d = distill::read_config(p)?;
            ensure!(
                d.search_teacher.is_some() && d.teacher.is_none(),
                "policy.distill {}: the experiment distils from the touch search \
                 ([search_teacher]); a checkpoint teacher observes its own representation, not the \
                 variant's",
                p.display()
            );
            // Refused now rather than when the variant's turn comes, hours in.
            let probe = d.search_teacher.as_ref().and_then(|t| t.probe.as_ref());
            ensure!(
                probe.is_some() || cfg.variant.iter().all(|v| v.representation.is_none()),
                "policy.distill {}: no [search_teacher.probe]: every variant's teacher would be \
                 told the hole by the truth rather than by its own z",
                p.display()
            );
            Route::Distill(Box::new(d))
        }
        None => Route::Train(Box::new(match &cfg.policy.config {
            Some(p) => policy_run::read_config(p)?,
            None => policy_run::TrainConfig::default(),
        })),
    };
    let env = match &route {
        Route::Train(t) => &t.env,
        Route::Distill(d) => &d.student.env,
    };
    let uses_representation = cfg.variant.iter().any(|v| v.representation.is_some());
    let data = ensure_dataset(&cfg.data, env, uses_representation, out, &mut log, stop)?;
    let mut rows = Vec::new();
    for v in &cfg.variant {
        if !opts.only.is_empty() && !opts.only.contains(&v.name) {
            continue;
        }
        let dir = out.join(&v.name);
        let observation = match &v.representation {
            None => ObservationKind::GroundTruth,
            Some(repr_cfg) => {
                let model = representation(cfg, v, repr_cfg, &data, &dir, opts, stop, &mut log)?;
                ObservationKind::Representation(model)
            }
        };
        if stop() {
            bail!("stopped; run the same command again to resume");
        }
        let policy_dir = dir.join("policy");
        let (ckpt, last) = match &route {
            Route::Train(base) => (
                train_policy(cfg, base, v, observation, &policy_dir, &mut log, stop)?,
                false,
            ),
            Route::Distill(base) => (
                distill_policy(base, v, observation, &policy_dir, &mut log, stop)?,
                true,
            ),
        };
        let trained_peg = ckpt.config.env.world.task.peg;
        // TRPO/PPO: the best validated policy when the policy configuration
        // validates, otherwise the best logged in training (the paper's
        // protocol). DAgger: the last round's.
        let chosen = ckpt.chosen_policy(last);
        let pegs = if cfg.eval.pegs.is_empty() {
            vec![trained_peg]
        } else {
            cfg.eval.pegs.clone()
        };
        for peg in pegs {
            let path = dir.join(format!("eval-{}.json", peg.name()));
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
                        "{}: evaluation of {chosen} on the {} peg ({} episodes)",
                        v.name,
                        peg.name(),
                        cfg.eval.episodes
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
            rows.push(ResultRow {
                variant: v.name.clone(),
                peg,
                report,
                paper_completed: v.paper_completed.filter(|_| peg == trained_peg),
            });
        }
        // The table so far after each variant: a run of many hours shows
        // each row as it comes.
        write_results(out, &with_others(cfg, opts, out, &rows))?;
    }
    let rows = with_others(cfg, opts, out, &rows);
    write_results(out, &rows)?;
    Ok(rows)
}
