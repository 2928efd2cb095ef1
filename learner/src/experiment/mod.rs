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
mod evaluate;
mod results;
mod stages;

pub use config::{DataStage, EvalStage, ExperimentConfig, PolicyStage, ReprStage, Variant};
pub use evaluate::wilson;
pub use results::{ResultRow, SeedRow, write_results};

use crate::rl::distill;
use crate::rl::observe::ObservationKind;
use crate::rl::run as policy_run;
use crate::rl::run::EvalReport;
use anyhow::{Context, Result, bail, ensure};
use evaluate::{evaluate_policy, pool};
use hw_sim::PegShape;
use results::with_others;
use stages::{Route, StageLog, ensure_dataset, representation, train_route};
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
                    matches!(
                        c.config.observation,
                        ObservationKind::GroundTruth | ObservationKind::GroundTruthHoleError(_)
                    ),
                    "policy.distill {}: its teacher {} observes {:?}, not the ground truth that \
                     the learned route's teacher observes (a representation would be its own, \
                     not the variant's)",
                    p.display(),
                    t.display(),
                    c.config.observation
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
                Some(f) => {
                    let ft = policy_run::read_config(f)?;
                    // It goes on in the students' world (its training aids
                    // are its own).
                    ensure!(
                        ft.env.world == env.world
                            && ft.env.action == env.action
                            && ft.env.controller.impedance == env.controller.impedance,
                        "policy.finetune {}: its [env.world], [env.action] or \
                         [env.controller.impedance] is not the students' (the teacher's, with the \
                         distillation's camera)",
                        f.display()
                    );
                    Some(Box::new(ft))
                }
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
        let seeds: Vec<Option<u64>> = if cfg.policy.seeds.is_empty() {
            vec![None]
        } else {
            cfg.policy.seeds.iter().map(|&s| Some(s)).collect()
        };
        // Each peg's evaluations, one per training seed.
        let mut by_peg: Vec<(PegShape, Vec<(u64, EvalReport)>)> = Vec::new();
        let mut trained_peg = None;
        for seed in seeds {
            let (ckpt, last) = train_route(
                &route,
                cfg,
                v,
                observation.clone(),
                seed,
                &dir,
                &mut log,
                stop,
            )?;
            trained_peg = Some(ckpt.config.env.world.task.peg);
            let tag = seed.map_or(String::new(), |s| format!("-s{s}"));
            let evals = evaluate_policy(cfg, v, &ckpt, last, &dir, &tag, &mut log, stop)?;
            for (peg, report) in evals {
                let s = seed.unwrap_or(ckpt.config.seed);
                match by_peg.iter_mut().find(|(p, _)| *p == peg) {
                    Some((_, reports)) => reports.push((s, report)),
                    None => by_peg.push((peg, vec![(s, report)])),
                }
            }
        }
        for (peg, reports) in by_peg {
            let (report, per_seed) = if cfg.policy.seeds.is_empty() {
                (reports[0].1.clone(), Vec::new())
            } else {
                pool(&reports)
            };
            rows.push(ResultRow {
                variant: v.name.clone(),
                peg,
                report,
                paper_completed: v.paper_completed.filter(|_| Some(peg) == trained_peg),
                per_seed,
                route: route.name(),
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
