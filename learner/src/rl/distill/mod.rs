//! `learner policy distill`: DAgger (Ross, Gordon & Bagnell, AISTATS 2011)
//! from a teacher policy that observes one thing (the privileged ground
//! truth) to a student that observes another (the frozen representation's z
//! means).
//!
//! Not the paper's training, which is TRPO on z alone: this measures what a
//! policy on z can do when it is shown the right action in every state it
//! reaches, and gives TRPO a starting point (`init_from`). Each round runs
//! the environments for `steps_per_round` steps acting with the teacher's
//! mean with probability β = `teacher_share_decay`ʳ (round r from 0, drawn
//! per step and environment) and the student's mean otherwise, records the
//! student's observation with the teacher's mean action (clipped to the
//! action range, where the environment clips it), and refits the student to
//! every round's samples so far (with `dagger.holdout_envs`, all but the
//! held-out environments', on which it stops early). The observation
//! normalisation is refitted to the same samples. After every round the student's mean runs the
//! validation episodes; the checkpoint is `learner policy train`'s, so
//! `policy eval`, `rl_probe` and `init_from` take it as they are.

mod config;
mod record;
mod samples;
mod teacher;

pub use config::{DaggerConfig, DistillConfig, read_config};
pub use record::{HoldoutFit, RoundPoint};
pub use samples::{Pair, Samples, round_path, teacher_round_path};
pub use teacher::search_teacher_of;

use super::gaussian::GaussianPolicy;
use super::mlp::MseFit;
use super::obs_norm::ObsNorm;
use super::observe::Observer;
use super::run::{
    Checkpoint, RunError, ValidatedPolicy, ValidationPoint, checkpoint_path, evaluate,
    read_checkpoint, read_json, write_json,
};
use super::search::{SearchView, TouchSearch};
use super::train::TrainerState;
use super::value::Baseline;
use super::vec::{BatchEnv, VecEnv};
use super::{RlEnvConfig, RlEnvError};
use learner_node::progress::Progress;
use record::{read_rounds, save};
use shared_mem_schema::config::FieldError;
use stack_common::rng;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use teacher::{Teacher, collect, probed_view};

/// Why the student's configuration cannot be distilled into.
fn refuse(detail: String, path: &Path) -> RunError {
    RunError::Parse {
        path: path.into(),
        detail,
    }
}

/// Runs (or, with `resume`, continues in `out`) a distillation, writing
/// `checkpoint.json`, `rounds/round-NNN.bin` (each round's samples),
/// `rounds/round-NNN.teacher.bin` (their teacher observations, see
/// [`teacher_round_path`]), `distill.csv` and `distill.png` into `out`. Ctrl-C (`stop`) drops the
/// round in progress; the finished ones are kept.
pub fn distill(
    cfg: DistillConfig,
    out: &Path,
    resume: bool,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Checkpoint, RunError> {
    cfg.dagger.validate().map_err(RlEnvError::from)?;
    let mut student_cfg = cfg.student.clone();
    let field = |name: &str, value: &dyn std::fmt::Display, why: &str| -> RunError {
        RlEnvError::from(FieldError::new(name, value, why)).into()
    };
    if cfg.dagger.holdout_envs >= cfg.student.num_envs {
        return Err(field(
            "dagger.holdout_envs",
            &cfg.dagger.holdout_envs,
            &format!(
                "must be below student.num_envs ({}): some episodes must be fitted",
                cfg.student.num_envs
            ),
        ));
    }
    // Where the teacher's actions and observations come from, and its
    // exploration noise (the student's starting σ).
    let (teacher, mut t_obs, teacher_path, log_std) = match (&cfg.teacher, &cfg.search_teacher) {
        (Some(path), None) => {
            let ckpt = read_checkpoint(path)?;
            let chosen = ckpt.chosen_policy(false);
            eprintln!("learner: teacher: {} of {}", chosen, path.display());
            let policy = chosen.policy.clone();
            if student_cfg.env != RlEnvConfig::default() && student_cfg.env != ckpt.config.env {
                return Err(field(
                    "student.env",
                    &"(set)",
                    "the student acts in the teacher's environment (its checkpoint's); leave \
                     [student.env] out",
                ));
            }
            student_cfg.env = ckpt.config.env.clone();
            let t_obs = ckpt.config.observation.observer_on(student_cfg.threads)?;
            if policy.sizes[0] != t_obs.dim() {
                return Err(refuse(
                    format!(
                        "the teacher's policy takes {} values, its observer gives {}",
                        policy.sizes[0],
                        t_obs.dim()
                    ),
                    path,
                ));
            }
            let log_std = policy.log_std.clone();
            (Teacher::Policy(policy), t_obs, path.clone(), Some(log_std))
        }
        (None, Some(search)) => {
            search.validate().map_err(RlEnvError::from)?;
            // A step the action scale would clip per component would turn
            // the spiral, not just shorten it.
            let max = student_cfg.env.action.max_step_m;
            for (name, v) in [
                ("slide_m", search.slide_m),
                ("step_m", search.step_m),
                ("descent_m", search.descent_m.unwrap_or(0.0)),
            ] {
                if v > max {
                    return Err(field(
                        &format!("search_teacher.{name}"),
                        &v,
                        &format!("must not exceed the action scale's step, {max} m"),
                    ));
                }
            }
            eprintln!("learner: teacher: the touch search, {search:?}");
            let t_obs: Arc<dyn Observer> = Arc::new(SearchView {
                std_m: search.hole_error_m,
            });
            let teacher = Teacher::Search(TouchSearch {
                cfg: search.clone(),
                scale: student_cfg.env.action.clone(),
            });
            (teacher, t_obs, PathBuf::from("[search_teacher]"), None)
        }
        (Some(path), Some(_)) => {
            return Err(field(
                "teacher",
                &path.display(),
                "give exactly one teacher: a checkpoint (teacher = \"…\") or \
                 [search_teacher], not both",
            ));
        }
        (None, None) => {
            return Err(field(
                "teacher",
                &"(none)",
                "give exactly one teacher: a checkpoint (teacher = \"…\") or [search_teacher]",
            ));
        }
    };
    if let Some(p) = &student_cfg.init_from {
        return Err(field(
            "student.init_from",
            &p.display(),
            "a distilled student starts from fresh weights",
        ));
    }
    if student_cfg.validation.episodes == 0 {
        return Err(field(
            "student.validation.episodes",
            &0,
            "must be at least 1 (every round is validated)",
        ));
    }
    let probe_cfg = cfg.search_teacher.as_ref().and_then(|s| s.probe.as_ref());
    if let Some(camera) = &cfg.camera {
        if probe_cfg.is_some() {
            return Err(field(
                "camera",
                &"(set)",
                "the search teacher reads a representation through the environment's \
                 camera; set [student.env.world.camera] instead",
            ));
        }
        if t_obs.needs_camera() {
            return Err(field(
                "camera",
                &"(set)",
                "the teacher observes through its environment's camera; leave [camera] out",
            ));
        }
        student_cfg.env.world.camera = camera.clone();
    }
    // The checkpoint's config says what the student observes; TRPO from
    // it (`init_from`) needs normalisation on, as the student has it.
    student_cfg.policy.normalise_observations = true;
    student_cfg.policy.validate().map_err(RlEnvError::from)?;
    let ckpt_path = checkpoint_path(out);
    let fresh = !(resume && ckpt_path.exists());
    if fresh {
        // A fresh run's rounds are its own: older files would be read by
        // `distill_fit` and by a later resume.
        let _ = std::fs::remove_dir_all(out.join("rounds"));
    }
    std::fs::create_dir_all(out.join("rounds")).map_err(|source| RunError::Io {
        path: out.into(),
        source,
    })?;
    // Everything but the number of rounds must stay as the run started, or
    // a resumed run would not be the one its files describe.
    let cfg_path = out.join("distill-config.json");
    let mut recorded = cfg.clone();
    recorded.dagger.rounds = 0;
    if !fresh && cfg_path.exists() {
        let was: DistillConfig = read_json(&cfg_path)?;
        if was != recorded {
            return Err(refuse(
                "resuming: the configuration differs from the one the run started with in \
                 more than dagger.rounds"
                    .into(),
                &cfg_path,
            ));
        }
    }
    write_json(&cfg_path, &recorded)?;
    let io = |source| RunError::Io {
        path: out.into(),
        source,
    };
    crate::interop::record_start(out, &cfg).map_err(io)?;
    let mut tb = crate::interop::ScalarLog::create(out).map_err(io)?;
    if let (Some(search), Some(p)) = (&cfg.search_teacher, probe_cfg) {
        t_obs = probed_view(search, p, &student_cfg, out, fresh)?;
    }
    let s_obs = student_cfg.observation.observer_on(student_cfg.threads)?;
    // Each against the world they share, named: the teacher keeps its
    // environment's camera, the student's comes from `[camera]`.
    let camera = &student_cfg.env.world.camera;
    super::observe::check_camera(camera, t_obs.as_ref()).map_err(|e| {
        refuse(
            format!("the teacher: {e} (a teacher that observes the camera keeps its own)"),
            &teacher_path,
        )
    })?;
    super::observe::check_camera(camera, s_obs.as_ref()).map_err(|e| {
        field(
            "camera",
            &"(the student's)",
            &format!("{e}; set [camera] to the student's representation's training camera"),
        )
    })?;
    let (td, sd) = (t_obs.dim(), s_obs.dim());
    let mut env = VecEnv::new(
        &student_cfg.env,
        student_cfg.num_envs,
        Arc::new(Pair::new(t_obs, s_obs)),
        student_cfg.threads,
    )?;
    // A training overload ramp is over by the time there is a policy to
    // distil: DAgger collects under the limits it ends at.
    let ramp_end = student_cfg.env.training.overload_share(u64::MAX);
    env.overload_share().set(ramp_end);
    let ad = env.act_dim();

    let (mut state, mut rounds, mut best) = if !fresh {
        let c = read_checkpoint(&ckpt_path)?;
        if c.config.observation != student_cfg.observation {
            return Err(refuse(
                format!(
                    "resuming: it observes {:?}, the configuration {:?}",
                    c.config.observation, student_cfg.observation
                ),
                &ckpt_path,
            ));
        }
        let rounds = read_rounds(out)?;
        (c.state, rounds, c.best_validated)
    } else {
        let mut r = rng::seeded(student_cfg.seed, 900);
        let mut policy = GaussianPolicy::new(
            sd,
            &student_cfg.policy.hidden,
            ad,
            student_cfg.policy.init_log_std,
            &mut r,
        );
        // TRPO from here explores as the teacher did at the end (a
        // scripted teacher has no σ: the configured one).
        if let Some(l) = &log_std {
            policy.log_std = l.clone();
        }
        policy.obs_norm = Some(ObsNorm::new(sd, student_cfg.policy.observation_clip));
        let mut r = rng::seeded(student_cfg.seed, 901);
        let baseline = Baseline::new(
            student_cfg.policy.baseline,
            sd,
            &student_cfg.policy.value,
            &mut r,
        );
        let state = TrainerState::fresh(policy, baseline, student_cfg.seed);
        (state, Vec::new(), None)
    };
    let mut data = Samples {
        obs_dim: sd,
        act_dim: ad,
        ..Default::default()
    };
    for r in 0..state.iteration {
        let s = Samples::read(&round_path(out, r))?;
        if (s.obs_dim, s.act_dim) != (sd, ad) {
            return Err(refuse(
                format!(
                    "samples of {} + {} values; this run's are {sd} + {ad}",
                    s.obs_dim, s.act_dim
                ),
                &round_path(out, r),
            ));
        }
        data.obs.extend_from_slice(&s.obs);
        data.actions.extend_from_slice(&s.actions);
    }
    if rounds.len() < state.iteration as usize {
        return Err(refuse(
            format!(
                "{} rounds recorded, the checkpoint has {}",
                rounds.len(),
                state.iteration
            ),
            &out.join("distill.json"),
        ));
    }
    rounds.truncate(state.iteration as usize);

    let d = &cfg.dagger;
    let progress = Progress::new(d.rounds * d.steps_per_round as u64, "steps");
    progress.resume_at(state.iteration * d.steps_per_round as u64);
    while state.iteration < d.rounds {
        let r = state.iteration;
        // A stop drops the round: its counters go back to its start.
        let before = state.clone();
        let student = state.policy.clone();
        let beta = d.teacher_share_decay.powi(r as i32);
        let Some((new, seen_by_teacher, student_steps)) = collect(
            &mut env, &teacher, &student, td, beta, &cfg, &mut state, stop,
        )?
        else {
            state = before;
            eprintln!("learner: stopped in round {r}; --resume collects it again");
            break;
        };
        // The teacher's file first: a round file without it is a round
        // recorded before this file existed, never one half written.
        seen_by_teacher.write(&teacher_round_path(out, r))?;
        new.write(&round_path(out, r))?;
        let error_before_parts = action_error(&student, &new);
        data.obs.extend_from_slice(&new.obs);
        data.actions.extend_from_slice(&new.actions);

        // Refit the normalisation and the network to everything so far
        // (the held-out episodes apart).
        // Without held-out episodes everything is fitted, read in place:
        // a copy of a raw run's samples would be hundreds of MB a round.
        drop(new);
        let split =
            (d.holdout_envs > 0).then(|| data.split_envs(student_cfg.num_envs, d.holdout_envs));
        let (fitted, held) = match &split {
            Some((f, h)) => (f, h.as_ref()),
            None => (&data, None),
        };
        let obs: Vec<f64> = fitted.obs.iter().map(|&v| v as f64).collect();
        let targets: Vec<f64> = fitted.actions.iter().map(|&v| v as f64).collect();
        let mut norm = ObsNorm::new(sd, student_cfg.policy.observation_clip);
        norm.update(&obs);
        state.policy.obs_norm = Some(norm);
        let inputs = state.policy.inputs(&obs);
        drop(obs);
        let mut frng = rng::seeded(student_cfg.seed, (4 << 32) + r);
        let holdout = refit(d, &mut state, &inputs, &targets, held, &mut frng);
        let error_after_parts = input_error(&state.policy, &inputs, &targets);
        let (error_before, error_after) = (
            error_before_parts.iter().sum::<f64>(),
            error_after_parts.iter().sum::<f64>(),
        );
        state.iteration += 1;

        let v = &student_cfg.validation;
        let report = evaluate(&state.policy, &student_cfg, v.episodes, v.seed, stop);
        let report = match report {
            Ok(x) => x,
            Err(RunError::Stopped) => {
                state = before;
                eprintln!("learner: stopped in round {r}'s validation; --resume collects it again");
                break;
            }
            Err(e) => return Err(e),
        };
        let validation = ValidationPoint {
            iteration: state.iteration,
            env_steps: state.env_steps,
            outcomes: report.outcomes,
            mean_normalised: report.mean_normalised,
        };
        let point = RoundPoint {
            round: r,
            beta,
            samples: data.len(),
            student_steps,
            error_before,
            error_before_parts,
            error_after,
            error_after_parts,
            holdout,
            validation: validation.clone(),
        };
        progress.update(
            state.iteration * d.steps_per_round as u64,
            format!(
                "round {r} | β {beta:.3} | {} samples | error {error_before:.3} → {error_after:.3}{} | \
                 validation {:.0} % completed, reward {:.3}",
                data.len(),
                point.holdout.as_ref().map_or(String::new(), |h| format!(
                    ", held out {:.3} (epoch {})",
                    h.error, h.epoch
                )),
                100.0 * validation.outcomes[super::Outcome::CompletedInsertion.index()],
                validation.mean_normalised
            ),
        );
        if best
            .as_ref()
            .is_none_or(|b: &ValidatedPolicy| validation.beats(&b.validation))
        {
            best = Some(ValidatedPolicy {
                validation: validation.clone(),
                policy: state.policy.clone(),
            });
        }
        let mut extra = vec![
            ("beta", point.beta),
            ("samples", point.samples as f64),
            ("error_before", point.error_before),
            ("error_after", point.error_after),
        ];
        if let Some(h) = &point.holdout {
            extra.push(("holdout_error", h.error));
            extra.push(("holdout_epoch", h.epoch as f64));
        }
        let v = &point.validation;
        let rows =
            super::run_config::outcome_scalars("distill", v.mean_normalised, &v.outcomes, &extra);
        tb.scalars(point.round, &rows).map_err(io)?;
        rounds.push(point);
        save(out, &student_cfg, &state, &rounds, &best)?;
    }
    progress.finish();
    if rounds.is_empty() && state.iteration == 0 {
        return Err(RunError::Stopped);
    }
    save(out, &student_cfg, &state, &rounds, &best)
}

/// The refit of one round: `d.epochs` epochs of Adam on `inputs` →
/// `targets`; with held-out samples, scored on them after each epoch, the
/// best epoch's network and Adam state kept (epoch 0: the incoming weights
/// under the refitted normalisation) and returned with its error.
fn refit(
    d: &DaggerConfig,
    state: &mut TrainerState,
    inputs: &[f64],
    targets: &[f64],
    held: Option<&Samples>,
    rng: &mut stack_common::rng::SimRng,
) -> Option<HoldoutFit> {
    let fit = |epochs| MseFit {
        epochs,
        minibatch: d.minibatch,
        learning_rate: d.learning_rate,
        l2: 0.0,
    };
    let mlp = state.policy.mlp();
    let Some(held) = held else {
        let net = &mut state.policy.net;
        fit(d.epochs).run(&mlp, net, &mut state.adam, inputs, targets, rng);
        return None;
    };
    let obs: Vec<f64> = held.obs.iter().map(|&v| v as f64).collect();
    let h_inputs = state.policy.inputs(&obs);
    drop(obs);
    let h_targets: Vec<f64> = held.actions.iter().map(|&v| v as f64).collect();
    let score = |p: &GaussianPolicy| input_error(p, &h_inputs, &h_targets).iter().sum::<f64>();
    let mut best = HoldoutFit {
        error: score(&state.policy),
        epoch: 0,
    };
    // Adam's moments go with the network they were at: the next round
    // goes on from the kept epoch, not from a discarded one.
    let mut kept = (state.policy.net.clone(), state.adam.clone());
    for epoch in 1..=d.epochs {
        let net = &mut state.policy.net;
        fit(1).run(&mlp, net, &mut state.adam, inputs, targets, rng);
        let error = score(&state.policy);
        if error < best.error {
            best = HoldoutFit { error, epoch };
            kept = (state.policy.net.clone(), state.adam.clone());
        }
    }
    (state.policy.net, state.adam) = kept;
    Some(best)
}

/// The student's mean squared error against the teacher's actions of `s`,
/// per action component (NaN for no samples).
fn action_error(policy: &GaussianPolicy, s: &Samples) -> Vec<f64> {
    let obs: Vec<f64> = s.obs.iter().map(|&v| v as f64).collect();
    let targets: Vec<f64> = s.actions.iter().map(|&v| v as f64).collect();
    input_error(policy, &policy.inputs(&obs), &targets)
}

/// The same from the network's inputs ([`GaussianPolicy::inputs`]) and the
/// targets, in chunks: the activations of a whole run's samples at once
/// would take hundreds of MB.
fn input_error(policy: &GaussianPolicy, inputs: &[f64], targets: &[f64]) -> Vec<f64> {
    let (d, k) = (policy.sizes[0], policy.act_dim());
    let mut e = vec![0.0; k];
    for (x, t) in inputs.chunks(4096 * d).zip(targets.chunks(4096 * k)) {
        for (i, (a, t)) in policy.net_means(x).iter().zip(t).enumerate() {
            e[i % k] += (a - t).powi(2);
        }
    }
    let n = (targets.len() / k.max(1)) as f64;
    e.iter().map(|v| v / n).collect()
}
