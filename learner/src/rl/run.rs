//! `learner policy train` and `learner policy eval`: a training run over
//! the vectorised fast path with checkpoints, learning curves (CSV and PNG)
//! and a progress bar; the evaluation of a checkpoint over N episodes.

use super::curve::{CurveError, write_validation_csv};
pub use super::curve::{CurvePoint, ValidationPoint, write_curves};
use super::env::{RlEnv, RlEnvError};
use super::gaussian::GaussianPolicy;
use super::reward::{Outcome, normalised_return};
pub use super::run_config::{TrainConfig, ValidationConfig};
use super::run_config::{hole_error_share, outcome_scalars, training_observer};
use super::train::{Trainer, TrainerState};
use super::value::Baseline;
use super::vec::{VecEnv, all_cores, par_map};
use learner_node::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The best validated policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidatedPolicy {
    /// Its validation.
    pub validation: ValidationPoint,
    /// The policy.
    pub policy: GaussianPolicy,
}

/// What a checkpoint file holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The run's configuration.
    pub config: TrainConfig,
    /// Policy, baseline and counters.
    pub state: TrainerState,
    /// Every update's statistics so far (the learning curves).
    pub history: Vec<CurvePoint>,
    /// The best policy logged so far: the paper evaluates "the best
    /// performing checkpoint that was logged during training based on the
    /// training results" (absent in checkpoints older than this field).
    #[serde(default)]
    pub best: Option<BestPolicy>,
    /// Every validation so far (none when validation is off).
    #[serde(default)]
    pub validations: Vec<ValidationPoint>,
    /// The best validated policy, which is evaluated when there is one.
    #[serde(default)]
    pub best_validated: Option<ValidatedPolicy>,
}

/// The policy of the checkpoint with the highest training reward.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BestPolicy {
    /// The update it was saved at.
    pub iteration: u64,
    /// Environment steps then.
    pub env_steps: u64,
    /// The mean normalised reward of the episodes that ended since the
    /// checkpoint before it (its training result).
    pub mean_normalised: f64,
    /// The policy.
    pub policy: GaussianPolicy,
}

/// The policy a checkpoint offers for evaluation or deployment.
#[derive(Debug, Clone, Copy)]
pub struct Chosen<'a> {
    /// The policy.
    pub policy: &'a GaussianPolicy,
    /// The update it was saved at.
    pub iteration: u64,
    /// Environment steps then.
    pub env_steps: u64,
    /// Why it was chosen.
    pub why: ChosenBy,
}

/// How a checkpoint's policy was chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChosenBy {
    /// The last policy.
    Last,
    /// The highest training reward over a checkpoint interval (the paper).
    TrainingReward(f64),
    /// The best validation: its completed share and normalised reward.
    Validation {
        /// Completed insertions in its validation episodes.
        completed: f64,
        /// Their mean normalised reward.
        reward: f64,
    },
}

impl std::fmt::Display for Chosen<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.why {
            ChosenBy::TrainingReward(r) => write!(
                f,
                "the best logged policy (update {}, {} steps, training reward {r:.3})",
                self.iteration, self.env_steps
            ),
            ChosenBy::Validation { completed, reward } => write!(
                f,
                "the best validated policy (update {}, {} steps, validation: {:.0} % completed, \
                 reward {reward:.3})",
                self.iteration,
                self.env_steps,
                100.0 * completed
            ),
            ChosenBy::Last => write!(
                f,
                "the last policy (update {}, {} steps)",
                self.iteration, self.env_steps
            ),
        }
    }
}

impl Checkpoint {
    /// The policy to evaluate or deploy unless `last` (or when nothing
    /// else exists yet): the best validated one when the run validated,
    /// otherwise the best logged one (the paper's choice).
    pub fn chosen_policy(&self, last: bool) -> Chosen<'_> {
        match (&self.best_validated, &self.best, last) {
            (Some(v), _, false) => Chosen {
                policy: &v.policy,
                iteration: v.validation.iteration,
                env_steps: v.validation.env_steps,
                why: ChosenBy::Validation {
                    completed: v.validation.outcomes[Outcome::CompletedInsertion.index()],
                    reward: v.validation.mean_normalised,
                },
            },
            (None, Some(b), false) => Chosen {
                policy: &b.policy,
                iteration: b.iteration,
                env_steps: b.env_steps,
                why: ChosenBy::TrainingReward(b.mean_normalised),
            },
            _ => Chosen {
                policy: &self.state.policy,
                iteration: self.state.iteration,
                env_steps: self.state.env_steps,
                why: ChosenBy::Last,
            },
        }
    }
}

/// The episode-weighted mean normalised reward of `points` (None: no
/// episode ended in them).
fn window_mean(points: &[CurvePoint]) -> Option<f64> {
    let (sum, n) = points
        .iter()
        .fold((0.0, 0usize), |(s, n), p| match p.mean_normalised {
            Some(m) => (s + m * p.episodes as f64, n + p.episodes),
            None => (s, n),
        });
    (n > 0).then(|| sum / n as f64)
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The environment or the trainer.
    #[error(transparent)]
    Env(#[from] RlEnvError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file's content is not what it should be.
    #[error("{path}: {detail}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        detail: String,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The learning curves could not be written.
    #[error(transparent)]
    Curve(#[from] CurveError),
    /// Stopped (Ctrl-C) before it was done.
    #[error("stopped before the evaluation was done")]
    Stopped,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads a training configuration (TOML).
pub fn read_config(path: &Path) -> Result<TrainConfig, RunError> {
    read_toml(path)
}

/// Reads a checkpoint; a relative representation path is taken beside the
/// checkpoint when the model is there (a package's, [`super::package`]).
pub fn read_checkpoint(path: &Path) -> Result<Checkpoint, RunError> {
    let mut c = read_json(path)?;
    super::package::resolve_beside(path, &mut c);
    Ok(c)
}

/// A TOML file's value; the error names the file.
pub(crate) fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, RunError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    toml::from_str(&text).map_err(|e| RunError::Parse {
        path: path.into(),
        detail: e.to_string(),
    })
}

/// A JSON file's value; the error names the file.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, RunError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|e| RunError::Parse {
        path: path.into(),
        detail: e.to_string(),
    })
}

/// Writes `v` as JSON, atomically.
pub(crate) fn write_json<T: Serialize + ?Sized>(path: &Path, v: &T) -> Result<(), RunError> {
    let bytes = serde_json::to_vec(v).map_err(|e| RunError::Parse {
        path: path.into(),
        detail: e.to_string(),
    })?;
    write_atomic(path, &bytes)
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RunError> {
    crate::write_atomic(path, bytes).map_err(io(path))
}

/// The checkpoint file of a run directory.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join("checkpoint.json")
}

/// Trains (or, with `resume`, continues the run in `out`) until the
/// configured number of environment steps, writing `checkpoint.json`,
/// `curve.csv`, `return.png` and `outcomes.png` into `out`. When `stop`
/// turns true (Ctrl-C) the update in progress finishes, a checkpoint is
/// written and the run returns early: its `state.env_steps` is then below
/// `config.env_steps`.
pub fn train(
    cfg: TrainConfig,
    out: &Path,
    resume: bool,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Checkpoint, RunError> {
    std::fs::create_dir_all(out).map_err(io(out))?;
    let ckpt_path = checkpoint_path(out);
    let (cfg, state, mut history, mut best, mut validations, mut best_validated) =
        if resume && ckpt_path.exists() {
            let c = read_checkpoint(&ckpt_path)?;
            // The file's configuration rules, except the length of the run: a
            // run is one experiment, and its curves one configuration's.
            let mut kept = c.config;
            kept.env_steps = cfg.env_steps;
            // A checkpoint written before the setting existed reads it as
            // its default; its policy says how it was trained.
            let normalised = c.state.policy.obs_norm.is_some();
            kept.policy.normalise_observations = normalised;
            if cfg.policy.normalise_observations != normalised {
                eprintln!(
                    "learner: resuming {}: its policy was trained {} observation \
                     normalisation, and goes on so",
                    ckpt_path.display(),
                    if normalised { "with" } else { "without" }
                );
            }
            let mut given = cfg.clone();
            given.policy.normalise_observations = normalised;
            // An overload ramp that starts after the steps already taken
            // does not change the run so far: the given one is adopted.
            let pending = |r: [u64; 2]| r[1] == 0 || r[0] >= c.state.env_steps;
            let ramp = given.env.training.overload_ramp_steps;
            if ramp != kept.env.training.overload_ramp_steps
                && pending(ramp)
                && pending(kept.env.training.overload_ramp_steps)
            {
                eprintln!(
                    "learner: resuming {} at {} environment steps with \
                     env.training.overload_ramp_steps = {ramp:?}, which starts after them",
                    ckpt_path.display(),
                    c.state.env_steps
                );
                kept.env.training.overload_ramp_steps = ramp;
            }
            if kept != given {
                eprintln!(
                    "learner: resuming {} with the configuration it started with; the one given \
                     differs in more than env_steps and is not used",
                    ckpt_path.display()
                );
            }
            (
                kept,
                Some(c.state),
                c.history,
                c.best,
                c.validations,
                c.best_validated,
            )
        } else {
            (cfg, None, Vec::new(), None, Vec::new(), None)
        };
    if cfg.validation.every > 0 && cfg.validation.episodes == 0 {
        return Err(
            RlEnvError::Config(shared_mem_schema::config::FieldError::new(
                "validation.episodes",
                0,
                "must be at least 1 when validation.every is set",
            ))
            .into(),
        );
    }
    if cfg.init_from.is_none()
        && let Some(l) = cfg.policy.init_from_log_std
    {
        return Err(
            RlEnvError::Config(shared_mem_schema::config::FieldError::new(
                "policy.init_from_log_std",
                l,
                "applies to a run started from init_from; set init_log_std for a fresh one",
            ))
            .into(),
        );
    }
    let (observer, ramp) = training_observer(&cfg)?;
    let mut env = VecEnv::new(&cfg.env, cfg.num_envs, observer, cfg.threads)?;
    if cfg.policy.critic == super::train::CriticInput::GroundTruth {
        env = env.with_critic(std::sync::Arc::new(super::observe::GroundTruth));
    }
    let critic_dim = cfg.policy.critic_dim(&env);
    let state = match (state, &cfg.init_from) {
        (Some(s), _) => Some(s),
        (None, Some(from)) => {
            let c = read_checkpoint(from)?;
            if !c.config.observation.same_inputs(&cfg.observation) {
                return Err(RunError::Parse {
                    path: from.clone(),
                    detail: format!(
                        "init_from: its policy observes {:?}, this run {:?}",
                        c.config.observation, cfg.observation
                    ),
                });
            }
            // The network only means something under the scaling it was
            // trained with, which it keeps (statistics and clip).
            let norm = &c.state.policy.obs_norm;
            if norm.is_some() != cfg.policy.normalise_observations
                || norm
                    .as_ref()
                    .is_some_and(|n| n.clip != cfg.policy.observation_clip)
            {
                return Err(RunError::Parse {
                    path: from.clone(),
                    detail: match norm {
                        Some(n) => format!(
                            "init_from: its policy was trained with its observations normalised \
                             and clipped to ±{}: set policy.normalise_observations = true and \
                             policy.observation_clip = {}",
                            n.clip, n.clip
                        ),
                        None => "init_from: its policy was trained without observation \
                                 normalisation: set policy.normalise_observations = false"
                            .into(),
                    },
                });
            }
            // The policy keeps its own layers: this run's `policy.hidden`
            // must describe them (the initial σ is the source's learned one).
            let hidden = &c.state.policy.sizes[1..c.state.policy.sizes.len().saturating_sub(1)];
            if hidden != cfg.policy.hidden.as_slice() {
                return Err(RunError::Parse {
                    path: from.clone(),
                    detail: format!(
                        "init_from: its policy's hidden layers are {hidden:?}, this run's \
                         policy.hidden {:?}",
                        cfg.policy.hidden
                    ),
                });
            }
            // The baseline does not change what the policy does: one that
            // is not this configuration's (its kind, shape, or what it
            // observes) is replaced by a fresh one; one that is keeps its
            // critic's statistics.
            let mut baseline = c.state.baseline;
            let mut critic_norm = c.state.critic_norm;
            if c.config.policy.critic != cfg.policy.critic
                || !baseline.fits(cfg.policy.baseline, critic_dim, &cfg.policy.value)
            {
                critic_norm = None;
                eprintln!(
                    "learner: init_from {}: its value baseline is not this run's \
                     (policy.baseline, policy.value.hidden, policy.critic); a fresh one is fitted",
                    from.display()
                );
                let mut rng = stack_common::rng::seeded(cfg.seed, 901);
                baseline =
                    Baseline::new(cfg.policy.baseline, critic_dim, &cfg.policy.value, &mut rng);
            }
            let mut policy = c.state.policy;
            if let Some(l) = cfg.policy.init_from_log_std {
                policy.log_std.iter_mut().for_each(|x| *x = l);
            }
            Some(TrainerState {
                critic_norm,
                ..TrainerState::fresh(policy, baseline, cfg.seed)
            })
        }
        (None, None) => None,
    };
    let mut trainer = match state {
        Some(s) => Trainer::resume(env, cfg.policy.clone(), s)?,
        None => Trainer::new(env, cfg.policy.clone(), cfg.seed)?,
    };
    crate::interop::record_start(out, &cfg).map_err(io(out))?;
    let mut tb = crate::interop::ScalarLog::create(out).map_err(io(out))?;
    let progress = Progress::new(cfg.env_steps, "steps");
    progress.resume_at(trainer.state.env_steps);
    let started = std::time::Instant::now();
    let mut episodes = 0usize;
    // Updates already covered by the best-policy bookkeeping.
    let mut judged = history.len();
    let mut save = |trainer: &Trainer<VecEnv>,
                    history: &[CurvePoint],
                    validations: &[ValidationPoint],
                    best_validated: &Option<ValidatedPolicy>|
     -> Result<Checkpoint, RunError> {
        if let Some(m) = window_mean(&history[judged.min(history.len())..])
            && best.as_ref().is_none_or(|b| m > b.mean_normalised)
        {
            best = Some(BestPolicy {
                iteration: trainer.state.iteration,
                env_steps: trainer.state.env_steps,
                mean_normalised: m,
                policy: trainer.state.policy.clone(),
            });
        }
        judged = history.len();
        let c = Checkpoint {
            config: cfg.clone(),
            state: trainer.state.clone(),
            history: history.to_vec(),
            best: best.clone(),
            validations: validations.to_vec(),
            best_validated: best_validated.clone(),
        };
        write_json(&ckpt_path, &c)?;
        write_curves(out, history, cfg.policy.algorithm)?;
        Ok(c)
    };
    while trainer.state.env_steps < cfg.env_steps {
        if stop() {
            progress.finish();
            eprintln!(
                "learner: stopped at {} environment steps; --resume continues",
                trainer.state.env_steps
            );
            break;
        }
        if let Some(r) = &ramp {
            r.set_share(hole_error_share(
                &cfg.env.training,
                trainer.state.env_steps,
                &history,
            ));
        }
        let share = cfg.env.training.overload_share(trainer.state.env_steps);
        trainer.env().overload_share().set(share);
        let s = trainer.iterate()?;
        episodes += s.episodes.len();
        let mut p = CurvePoint::from_stats(&s);
        p.hole_error_std_m = ramp.as_ref().map_or(0.0, |r| r.current_std_m());
        let rate = episodes as f64 / started.elapsed().as_secs_f64().max(1e-9);
        progress.update(
            s.env_steps.min(cfg.env_steps),
            format!(
                "update {} | {:.2} episodes/s | mean return {:.1} (normalised {:.3}) | completed {:.0}% | baseline explained {:.2}",
                s.iteration,
                rate,
                p.mean_return.unwrap_or(f64::NAN),
                p.mean_normalised.unwrap_or(f64::NAN),
                100.0 * p.outcomes[Outcome::CompletedInsertion.index()],
                p.baseline_explained
            ),
        );
        let extra = [
            ("mean_return", p.mean_return.unwrap_or(f64::NAN)),
            ("kl", p.kl),
            ("mean_std", p.mean_std),
            ("baseline_explained", p.baseline_explained),
            ("hole_error_std_mm", 1e3 * p.hole_error_std_m),
        ];
        let m = p.mean_normalised.unwrap_or(f64::NAN);
        tb.scalars(
            p.env_steps,
            &outcome_scalars("train", m, &p.outcomes, &extra),
        )
        .map_err(io(out))?;
        history.push(p);
        let v = &cfg.validation;
        if v.every > 0 && s.iteration.is_multiple_of(v.every) {
            let policy = trainer.state.policy.clone();
            let r = match evaluate(&policy, &cfg, v.episodes, v.seed, stop) {
                Ok(r) => r,
                // Ctrl-C during a validation: the loop's check saves.
                Err(RunError::Stopped) => continue,
                Err(e) => return Err(e),
            };
            let point = ValidationPoint {
                iteration: s.iteration,
                env_steps: s.env_steps,
                outcomes: r.outcomes,
                mean_normalised: r.mean_normalised,
            };
            if best_validated
                .as_ref()
                .is_none_or(|b| point.beats(&b.validation))
            {
                best_validated = Some(ValidatedPolicy {
                    validation: point.clone(),
                    policy,
                });
            }
            let rows = outcome_scalars("validation", point.mean_normalised, &point.outcomes, &[]);
            tb.scalars(point.env_steps, &rows).map_err(io(out))?;
            validations.push(point);
            write_validation_csv(out, &validations)?;
        }
        if s.iteration.is_multiple_of(cfg.checkpoint_every.max(1)) {
            save(&trainer, &history, &validations, &best_validated)?;
        }
    }
    progress.finish();
    save(&trainer, &history, &validations, &best_validated)
}

/// The result of an evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// Episodes run.
    pub episodes: usize,
    /// Share in each outcome category ([`Outcome::ALL`] order).
    pub outcomes: [f64; 4],
    /// Mean normalised episode reward.
    pub mean_normalised: f64,
    /// Normalised reward of each episode, in seed order.
    pub normalised: Vec<f64>,
    /// Whether the actions were drawn from the policy's Gaussian
    /// ([`Act::Sample`]) rather than its mean.
    #[serde(default)]
    pub sampled: bool,
    /// The controller's fault code at each episode's end, in seed order (0:
    /// none; rt-controller's `fault_code`: 4 force, 5 moment overload).
    #[serde(default)]
    pub fault_codes: Vec<u32>,
}

impl EvalReport {
    /// Episodes that ended by a controller fault.
    pub fn faulted(&self) -> usize {
        self.fault_codes.iter().filter(|&&c| c != 0).count()
    }
}

/// How an evaluated policy acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Act {
    /// Its mean action (the paper's and this project's default).
    #[default]
    Mean,
    /// An action drawn from its Gaussian, as in training, from a generator
    /// seeded by the episode's seed (repeatable): a memoryless policy's
    /// noise is part of how it searches.
    Sample,
}

/// Runs `episodes` episodes (seeds `seed`, `seed + 1`, …) of `policy`'s
/// mean action, spread over `cfg.num_envs` environments on parallel threads
/// (each runs whole episodes, observing one state at a time).
pub fn evaluate(
    policy: &GaussianPolicy,
    cfg: &TrainConfig,
    episodes: usize,
    seed: u64,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<EvalReport, RunError> {
    evaluate_acting(policy, cfg, episodes, seed, Act::Mean, stop)
}

/// [`evaluate`], the policy acting as `act` says.
pub fn evaluate_acting(
    policy: &GaussianPolicy,
    cfg: &TrainConfig,
    episodes: usize,
    seed: u64,
    act: Act,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<EvalReport, RunError> {
    let n = cfg.num_envs.clamp(1, episodes.max(1));
    let observer = cfg.observation.observer_on(cfg.threads)?;
    let mut envs = (0..n)
        .map(|_| RlEnv::new(&cfg.env))
        .collect::<Result<Vec<_>, _>>()?;
    super::observe::check_camera(&cfg.env.world.camera, observer.as_ref())?;
    let threads = if cfg.threads == 0 {
        all_cores()
    } else {
        cfg.threads
    };
    let camera = observer.needs_camera();
    let dim = observer.dim();
    let results = par_map(&mut envs, threads, |i, env| {
        let mut done = Vec::new();
        let mut obs = vec![0.0; dim];
        for k in (i..episodes).step_by(n) {
            if stop() {
                break;
            }
            env.reset(seed + k as u64, camera)?;
            let mut rng = stack_common::rng::seeded(seed + k as u64, 0xe7a1);
            loop {
                observer.observe(&[env.view().expect("reset")], &mut obs);
                let a = match act {
                    Act::Mean => policy.means(&obs),
                    Act::Sample => policy.sample(&obs, &mut rng),
                };
                let o = env.step(&a, camera)?;
                if o.done() {
                    done.push((k, o, env.fast().sensor_frame().fault_code));
                    break;
                }
            }
        }
        Ok::<_, RlEnvError>(done)
    });
    let mut norm = vec![0.0; episodes];
    let mut fault_codes = vec![0; episodes];
    let mut outcomes = [0.0; 4];
    let mut done = 0;
    for r in results {
        for (k, o, code) in r? {
            done += 1;
            fault_codes[k] = code;
            norm[k] = normalised_return(o.episode_reward, cfg.env.max_steps);
            outcomes[o.outcome.index()] += 1.0 / episodes as f64;
        }
    }
    if done < episodes {
        return Err(RunError::Stopped);
    }
    Ok(EvalReport {
        episodes,
        mean_normalised: norm.iter().sum::<f64>() / episodes.max(1) as f64,
        normalised: norm,
        outcomes,
        sampled: act == Act::Sample,
        fault_codes,
    })
}
