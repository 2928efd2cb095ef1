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
//! every round's samples so far. The observation normalisation is refitted
//! to the same samples. After every round the student's mean runs the
//! validation episodes; the checkpoint is `learner policy train`'s, so
//! `policy eval`, `rl_probe` and `init_from` take it as they are.

use super::gaussian::GaussianPolicy;
use super::mlp::MseFit;
use super::obs_norm::ObsNorm;
use super::observe::{ObsView, Observer};
use super::probe::LinearProbe;
use super::run::{
    Checkpoint, RunError, TrainConfig, ValidatedPolicy, ValidationPoint, checkpoint_path, evaluate,
    read_checkpoint, read_json, read_toml, write_json,
};
use super::search::{
    BeliefProbeConfig, BeliefProbes, ProbedSearchView, SearchView, TouchSearch, TouchSearchConfig,
    fit_belief_probe,
};
use super::train::TrainerState;
use super::value::Baseline;
use super::vec::{BatchEnv, VecEnv};
use super::{RlEnvConfig, RlEnvError};
use crate::plot::{Chart, Series};
use hw_sim::FieldError;
use hw_sim::rng;
use learner_node::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

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
    /// ([`super::search::TouchSearch`]), told the hole with a per-episode
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
        }
    }
}

impl DaggerConfig {
    fn validate(&self) -> Result<(), FieldError> {
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

/// Two observers side by side: each observation is the first's values,
/// then the second's.
pub struct Pair {
    first: Arc<dyn Observer>,
    second: Arc<dyn Observer>,
}

impl Pair {
    /// `first`'s observation followed by `second`'s.
    pub fn new(first: Arc<dyn Observer>, second: Arc<dyn Observer>) -> Self {
        Self { first, second }
    }
}

impl Observer for Pair {
    fn dim(&self) -> usize {
        self.first.dim() + self.second.dim()
    }

    fn needs_camera(&self) -> bool {
        self.first.needs_camera() || self.second.needs_camera()
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let (a, b) = (self.first.dim(), self.second.dim());
        let mut fa = vec![0.0; views.len() * a];
        let mut fb = vec![0.0; views.len() * b];
        self.first.observe(views, &mut fa);
        self.second.observe(views, &mut fb);
        for (i, o) in out.chunks_exact_mut(a + b).enumerate() {
            o[..a].copy_from_slice(&fa[i * a..(i + 1) * a]);
            o[a..].copy_from_slice(&fb[i * b..(i + 1) * b]);
        }
    }

    fn rejected(&self) -> u64 {
        self.first.rejected() + self.second.rejected()
    }

    /// The second's (the student's) camera, else the first's. `distill`
    /// checks each of the two against the world before it builds one.
    fn camera(&self) -> Option<shared_mem_schema::CameraCalibration> {
        self.second.camera().or_else(|| self.first.camera())
    }
}

/// One round's samples: the student's observations (as observed, not
/// normalised) and the teacher's clipped mean actions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Samples {
    /// Observation size.
    pub obs_dim: usize,
    /// Action size.
    pub act_dim: usize,
    /// Observations, samples × `obs_dim`.
    pub obs: Vec<f32>,
    /// Target actions, samples × `act_dim`.
    pub actions: Vec<f32>,
}

const MAGIC: &[u8; 8] = b"DAGGER01";

impl Samples {
    /// Samples held.
    pub fn len(&self) -> usize {
        self.actions.len() / self.act_dim.max(1)
    }

    /// True when none are held.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Writes the samples (a header, then little-endian f32s), atomically.
    pub fn write(&self, path: &Path) -> Result<(), RunError> {
        let mut b = Vec::with_capacity(32 + 4 * (self.obs.len() + self.actions.len()));
        b.extend_from_slice(MAGIC);
        for v in [self.obs_dim, self.act_dim, self.len()] {
            b.extend_from_slice(&(v as u64).to_le_bytes());
        }
        for v in self.obs.iter().chain(&self.actions) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        crate::write_atomic(path, &b).map_err(|source| RunError::Io {
            path: path.into(),
            source,
        })
    }

    /// Reads what [`Samples::write`] wrote; a file of another format or a
    /// truncated one is an error naming it.
    pub fn read(path: &Path) -> Result<Self, RunError> {
        let bad = |detail: String| RunError::Parse {
            path: path.into(),
            detail,
        };
        let bytes = std::fs::read(path).map_err(|source| RunError::Io {
            path: path.into(),
            source,
        })?;
        if bytes.len() < 32 || &bytes[..8] != MAGIC {
            return Err(bad("not a DAgger samples file (no DAGGER01 header)".into()));
        }
        let u = |k: usize| u64::from_le_bytes(bytes[8 + 8 * k..16 + 8 * k].try_into().unwrap());
        let (od, ad, n) = (u(0) as usize, u(1) as usize, u(2) as usize);
        let expected = od
            .checked_add(ad)
            .and_then(|per| n.checked_mul(per))
            .and_then(|v| v.checked_mul(4))
            .and_then(|b| b.checked_add(32));
        let Some(expected) = expected else {
            return Err(bad(format!(
                "a header of {n} samples of {od} + {ad} values (corrupt)"
            )));
        };
        if expected != bytes.len() {
            return Err(bad(format!(
                "{} bytes, expected {expected} for {n} samples of {od} + {ad} values (truncated?)",
                bytes.len()
            )));
        }
        let values = (expected - 32) / 4;
        let f: Vec<f32> = bytes[32..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        debug_assert_eq!(f.len(), values);
        Ok(Self {
            obs_dim: od,
            act_dim: ad,
            actions: f[n * od..].to_vec(),
            obs: f[..n * od].to_vec(),
        })
    }
}

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
    /// The refitted student's error on every round's samples so far.
    pub error_after: f64,
    /// `error_after` per action component (empty in runs recorded before
    /// it was).
    #[serde(default)]
    pub error_after_parts: Vec<f64>,
    /// The refitted student's validation.
    pub validation: ValidationPoint,
}

/// Why the student's configuration cannot be distilled into.
fn refuse(detail: String, path: &Path) -> RunError {
    RunError::Parse {
        path: path.into(),
        detail,
    }
}

/// Where round `round`'s samples are kept.
pub fn round_path(out: &Path, round: u64) -> PathBuf {
    out.join("rounds").join(format!("round-{round:03}.bin"))
}

/// Where round `round`'s teacher observations are kept: the same samples
/// as [`round_path`]'s, each with what the teacher observed in place of
/// what the student did (for diagnosis; a resume does not read them).
pub fn teacher_round_path(out: &Path, round: u64) -> PathBuf {
    out.join("rounds")
        .join(format!("round-{round:03}.teacher.bin"))
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

        // Refit the normalisation and the network to everything so far.
        let obs: Vec<f64> = data.obs.iter().map(|&v| v as f64).collect();
        let targets: Vec<f64> = data.actions.iter().map(|&v| v as f64).collect();
        let mut norm = ObsNorm::new(sd, student_cfg.policy.observation_clip);
        norm.update(&obs);
        state.policy.obs_norm = Some(norm);
        let inputs = state.policy.inputs(&obs);
        let fit = MseFit {
            epochs: d.epochs,
            minibatch: d.minibatch,
            learning_rate: d.learning_rate,
            l2: 0.0,
        };
        let mut frng = rng::seeded(student_cfg.seed, (4 << 32) + r);
        let mlp = state.policy.mlp();
        fit.run(
            &mlp,
            &mut state.policy.net,
            &mut state.adam,
            &inputs,
            &targets,
            &mut frng,
        );
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
            validation: validation.clone(),
        };
        progress.update(
            state.iteration * d.steps_per_round as u64,
            format!(
                "round {r} | β {beta:.3} | {} samples | error {error_before:.3} → {error_after:.3} | \
                 validation {:.0} % completed, reward {:.3}",
                data.len(),
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
        rounds.push(point);
        save(out, &student_cfg, &state, &rounds, &best)?;
    }
    progress.finish();
    if rounds.is_empty() && state.iteration == 0 {
        return Err(RunError::Stopped);
    }
    save(out, &student_cfg, &state, &rounds, &best)
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

/// Where the probe of a representation-told search teacher is kept.
fn probe_path(out: &Path) -> PathBuf {
    out.join("search-probe.json")
}

/// Where the search teacher's approach probe (`approach`) is kept.
fn approach_probe_path(out: &Path) -> PathBuf {
    out.join("search-approach-probe.json")
}

/// Seed of the first episode a search teacher's probe is fitted on: apart
/// from DAgger's (from `dagger.episode_seed`, 5 000 000 by default),
/// validation's and evaluation's (from 1 000 000) episodes.
const PROBE_FIT_SEED: u64 = 7_000_000;

/// The touch-search teacher of the distillation run in `out` as it
/// labelled the run's rounds: its search and its view, through the run's
/// saved probes when a representation tells it. For comparing a student
/// with its teacher on the same episodes (`distill_fit shadow`).
pub fn search_teacher_of(out: &Path) -> Result<(TouchSearch, Arc<dyn Observer>), RunError> {
    let cfg_path = out.join("distill-config.json");
    let cfg: DistillConfig = read_json(&cfg_path)?;
    let search = cfg
        .search_teacher
        .as_ref()
        .ok_or_else(|| refuse("not a distillation from the touch search".into(), &cfg_path))?;
    let view: Arc<dyn Observer> = match &search.probe {
        Some(p) => probed_view(search, p, &cfg.student, out, false)?,
        None => Arc::new(SearchView {
            std_m: search.hole_error_m,
        }),
    };
    let teacher = TouchSearch {
        cfg: search.clone(),
        scale: cfg.student.env.action.clone(),
    };
    Ok((teacher, view))
}

/// The representation-told search teacher's view through its probes: fitted
/// in the student's environment (a fresh run) or read back (a resumed one).
fn probed_view(
    search: &TouchSearchConfig,
    p: &BeliefProbeConfig,
    student_cfg: &TrainConfig,
    out: &Path,
    fresh: bool,
) -> Result<Arc<dyn Observer>, RunError> {
    let path = probe_path(out);
    let approach_path = approach_probe_path(out);
    // A resumed run's rounds were labelled through its probes: refit ones
    // could label the next rounds differently.
    for (needed, path) in [(true, &path), (p.approach, &approach_path)] {
        if needed && !fresh && !path.exists() {
            return Err(refuse(
                "resuming: a probe of the search teacher is missing; its rounds were labelled \
                 through it (start afresh without --resume)"
                    .into(),
                path,
            ));
        }
    }
    let repr = super::ObservationKind::Representation(p.representation.clone())
        .observer_on(student_cfg.threads)?;
    let probes = if !fresh {
        let read = |path: &Path| -> Result<LinearProbe, RunError> {
            let probe: LinearProbe = read_json(path)?;
            probe.check().map_err(|e| refuse(e.to_string(), path))?;
            Ok(probe)
        };
        BeliefProbes {
            near: read(&path)?,
            approach: if p.approach {
                Some(read(&approach_path)?)
            } else {
                None
            },
        }
    } else {
        eprintln!(
            "learner: fitting the search teacher's probe{} of {} on {} episodes per round, {} \
             round(s)",
            if p.approach {
                "s (near and approach)"
            } else {
                ""
            },
            p.representation.display(),
            p.fit_episodes,
            p.fit_rounds
        );
        let progress = Progress::new(
            p.fit_episodes.saturating_mul(u64::from(p.fit_rounds)),
            "episodes",
        );
        let probes = fit_belief_probe(
            &student_cfg.env,
            repr.as_ref(),
            search,
            p,
            PROBE_FIT_SEED,
            &mut |ep, rows| progress.update(ep, format!("{rows} states")),
        )?;
        progress.finish();
        write_json(&path, &probes.near)?;
        if let Some(a) = &probes.approach {
            write_json(&approach_path, a)?;
        }
        probes
    };
    for (probe, path, targets) in [
        (Some(&probes.near), &path, 3),
        (probes.approach.as_ref(), &approach_path, 2),
    ] {
        if let Some(probe) = probe
            && (probe.features() != repr.dim() || probe.targets != targets)
        {
            return Err(refuse(
                format!(
                    "a probe of {} features to {} targets; the representation gives {} and the \
                     search needs {targets}",
                    probe.features(),
                    probe.targets,
                    repr.dim()
                ),
                path,
            ));
        }
    }
    Ok(Arc::new(ProbedSearchView {
        repr,
        probes,
        below_m: p.below_m,
    }))
}

/// Who labels the student's states.
enum Teacher {
    /// A trained policy's mean.
    Policy(GaussianPolicy),
    /// The scripted touch search.
    Search(TouchSearch),
}

impl Teacher {
    fn means(&self, obs: &[f64]) -> Vec<f64> {
        match self {
            Teacher::Policy(p) => p.means(obs),
            Teacher::Search(s) => s.means(obs),
        }
    }
}

/// One round's collection: `steps` steps over all environments, each acting
/// with the teacher's mean with probability `beta`, the student's
/// otherwise; with the number of steps the student acted. None when
/// stopped.
#[allow(clippy::too_many_arguments)]
fn collect(
    env: &mut VecEnv,
    teacher: &Teacher,
    student: &GaussianPolicy,
    td: usize,
    beta: f64,
    cfg: &DistillConfig,
    state: &mut TrainerState,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Option<(Samples, Samples, usize)>, RunError> {
    let n = env.num_envs();
    let (od, ad) = (env.obs_dim(), env.act_dim());
    let sd = od - td;
    let mut pick = rng::seeded(cfg.student.seed, (5 << 32) + state.iteration);
    let mut s = Samples {
        obs_dim: sd,
        act_dim: ad,
        ..Default::default()
    };
    let mut seen_by_teacher = Samples {
        obs_dim: td,
        act_dim: ad,
        ..Default::default()
    };
    let next_seed = |state: &mut TrainerState| {
        let seed = cfg.dagger.episode_seed + state.episodes_started;
        state.episodes_started += 1;
        seed
    };
    // Every round starts fresh episodes: a resumed round collects what the
    // uninterrupted one would have.
    let which: Vec<(usize, u64)> = (0..n).map(|i| (i, next_seed(state))).collect();
    env.reset(&which)?;
    let (mut tobs, mut sobs) = (Vec::new(), Vec::new());
    let (mut collected, mut by_student) = (0, 0);
    while collected < cfg.dagger.steps_per_round {
        if stop() {
            return Ok(None);
        }
        tobs.clear();
        sobs.clear();
        for o in env.observations().chunks_exact(od) {
            tobs.extend_from_slice(&o[..td]);
            sobs.extend_from_slice(&o[td..]);
        }
        let mut target = teacher.means(&tobs);
        for a in target.iter_mut() {
            *a = if a.is_nan() { 0.0 } else { a.clamp(-1.0, 1.0) };
        }
        let mut act = student.means(&sobs);
        for i in 0..n {
            if rng::unit(&mut pick) < beta {
                act[i * ad..(i + 1) * ad].copy_from_slice(&target[i * ad..(i + 1) * ad]);
            } else {
                by_student += 1;
            }
        }
        s.obs.extend(sobs.iter().map(|&v| v as f32));
        s.actions.extend(target.iter().map(|&v| v as f32));
        seen_by_teacher.obs.extend(tobs.iter().map(|&v| v as f32));
        seen_by_teacher
            .actions
            .extend(target.iter().map(|&v| v as f32));
        let outcomes = env.step(&act)?.to_vec();
        collected += n;
        state.env_steps += n as u64;
        let which: Vec<(usize, u64)> = outcomes
            .iter()
            .enumerate()
            .filter(|(_, o)| o.done())
            .map(|(i, _)| (i, next_seed(state)))
            .collect();
        if !which.is_empty() {
            env.reset(&which)?;
        }
    }
    Ok(Some((s, seen_by_teacher, by_student)))
}

/// The rounds recorded in `out`'s `distill.json` (none when it is absent).
fn read_rounds(out: &Path) -> Result<Vec<RoundPoint>, RunError> {
    let path = out.join("distill.json");
    if path.exists() {
        read_json(&path)
    } else {
        Ok(Vec::new())
    }
}

fn save(
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
         touched_the_box,failed,mean_normalised\n",
    );
    for p in rounds {
        let o = p.validation.outcomes;
        let part = |k: usize| p.error_after_parts.get(k).copied().unwrap_or(f64::NAN);
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
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
            p.validation.mean_normalised
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
            x(&|p| p.validation.outcomes[super::Outcome::CompletedInsertion.index()]),
        ))
        .with(Series::line(
            "mean normalised reward",
            x(&|p| p.validation.mean_normalised),
        ))
        .write_png(out.join("distill.png"))?;
        Chart::new(
            "DAgger: the student's action error",
            "round",
            "mean squared action error (4 components summed)",
        )
        .with(Series::line(
            "on the round's new states, before the refit",
            x(&|p| p.error_before),
        ))
        .with(Series::line(
            "on all samples so far, after the refit",
            x(&|p| p.error_after),
        ))
        .write_png(out.join("distill-error.png"))?;
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `value` `dim` times per view.
    struct Constant {
        dim: usize,
        value: f64,
    }

    impl Observer for Constant {
        fn dim(&self) -> usize {
            self.dim
        }
        fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
            assert_eq!(out.len(), views.len() * self.dim);
            out.fill(self.value);
        }
    }

    /// The teacher's values first, then the student's, per environment:
    /// what `collect` splits at the teacher's size.
    #[test]
    fn a_pair_puts_the_first_observers_values_first() {
        let mut env = super::super::RlEnv::new(&RlEnvConfig::default()).unwrap();
        env.reset(1, false).unwrap();
        let pair = Pair::new(
            Arc::new(Constant { dim: 2, value: 1.0 }),
            Arc::new(Constant { dim: 3, value: 2.0 }),
        );
        assert_eq!(pair.dim(), 5);
        assert!(!pair.needs_camera());
        let view = env.view().unwrap();
        let mut out = vec![0.0; 10];
        pair.observe(&[env.view().unwrap(), view], &mut out);
        assert_eq!(out, [1.0, 1.0, 2.0, 2.0, 2.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
    }
}
