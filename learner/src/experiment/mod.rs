//! `learner experiment`: the paper's ablations end to end. For each
//! variant (a representation configuration, or the ground truth): the
//! dataset (collected and built once, shared), the representation trained
//! on it, a policy trained on its frozen z means, and the evaluation of that
//! policy on each evaluation peg; then one results table and bar charts of
//! the completed-insertion share next to the paper's numbers.
//!
//! The policy learns one of three ways: by `learner policy train` (TRPO or
//! PPO on z, the paper's); by `learner policy distill` from the touch
//! search whose belief of the opening is a linear probe of the same z; or
//! the learned route: DAgger from a trained teacher on the ground truth,
//! then optionally PPO on z from the student (docs/results.md). Each takes
//! the variant's representation in place of its configuration's.
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
use stages::{
    Route, StageLog, distill_policy, ensure_dataset, finetune_policy, representation, train_policy,
};
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
    // Everything the route reads is checked now rather than when a
    // variant's turn comes, hours in.
    let (route, env) = match &cfg.policy.distill {
        Some(p) => {
            let mut d = distill::read_config(p)?;
            if let Some(r) = cfg.policy.dagger_rounds {
                d.dagger.rounds = r;
            }
            // The world the students act in: the teacher's for a checkpoint
            // teacher (with the distillation's camera), else their own.
            let mut env = d.student.env.clone();
            if let Some(t) = &d.teacher {
                let c = policy_run::read_checkpoint(t)
                    .with_context(|| format!("policy.distill {}: its teacher", p.display()))?;
                ensure!(
                    !matches!(c.config.observation, ObservationKind::Representation(_)),
                    "policy.distill {}: its teacher {} observes a representation, its own and \
                     not the variant's; the learned route's teacher observes the ground truth",
                    p.display(),
                    t.display()
                );
                env = c.config.env;
                if let Some(camera) = &d.camera {
                    env.world.camera = camera.clone();
                }
            } else {
                let probe = d.search_teacher.as_ref().and_then(|t| t.probe.as_ref());
                ensure!(
                    probe.is_some() || cfg.variant.iter().all(|v| v.representation.is_none()),
                    "policy.distill {}: no [search_teacher.probe]: every variant's teacher would \
                     be told the hole by the truth rather than by its own z",
                    p.display()
                );
            }
            let finetune = match &cfg.policy.finetune {
                Some(f) => Some(Box::new(policy_run::read_config(f)?)),
                None => None,
            };
            (Route::Distill(Box::new(d), finetune), env)
        }
        None => {
            let t = match &cfg.policy.config {
                Some(p) => policy_run::read_config(p)?,
                None => policy_run::TrainConfig::default(),
            };
            let env = t.env.clone();
            (Route::Train(Box::new(t)), env)
        }
    };
    let uses_representation = cfg.variant.iter().any(|v| v.representation.is_some());
    let data = ensure_dataset(&cfg.data, &env, uses_representation, out, &mut log, stop)?;
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
            Route::Distill(base, None) => (
                distill_policy(base, v, observation, &policy_dir, &mut log, stop)?,
                true,
            ),
            Route::Distill(base, Some(ft)) => {
                distill_policy(base, v, observation.clone(), &policy_dir, &mut log, stop)?;
                let student = policy_run::checkpoint_path(&policy_dir);
                let dir = dir.join("finetune");
                let c = finetune_policy(ft, v, observation, &student, &dir, &mut log, stop)?;
                (c, false)
            }
        };
        let trained_peg = ckpt.config.env.world.task.peg;
        // TRPO/PPO (a fine-tune too): the best validated policy when the
        // policy configuration validates, otherwise the best logged in
        // training (the paper's protocol). DAgger: the last round's.
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
