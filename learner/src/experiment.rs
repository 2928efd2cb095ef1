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

use crate::collect::{self, CollectConfig};
use crate::dataset::{self, BuildConfig, Dataset};
use crate::plot::{Chart, Series};
use crate::rl::distill::{self, DistillConfig};
use crate::rl::observe::ObservationKind;
use crate::rl::reward::Outcome;
use crate::rl::run::{self as policy_run, EvalReport};
use crate::train::{self, DeviceKind, TrainOptions};
use anyhow::{Context, Result, bail, ensure};
use hw_sim::PegShape;
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An experiment (TOML; see configs/experiments/).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// The dataset every representation trains on.
    pub data: DataStage,
    /// The representation stage.
    #[serde(default)]
    pub representation: ReprStage,
    /// The policy stage.
    #[serde(default)]
    pub policy: PolicyStage,
    /// The evaluation.
    #[serde(default)]
    pub eval: EvalStage,
    /// The variants compared.
    pub variant: Vec<Variant>,
}

/// Where the dataset is, and how to make it when it is not there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataStage {
    /// The built dataset (used as it is when it opens).
    pub dataset: PathBuf,
    /// When it is absent: collect this many 20 Hz states on the fast path
    /// (`collect_pegs`, the default heuristic/random mix, in the policy
    /// configuration's world and controller) and build it. 0: a missing
    /// dataset is an error.
    #[serde(default)]
    pub collect_states: u64,
    /// Seed of the collection's first episode.
    #[serde(default = "one")]
    pub collect_seed: u64,
    /// The pegs collected, taken in turn (empty: all four). One peg gives
    /// the paper's transfer experiments a representation that has never
    /// seen the others.
    #[serde(default)]
    pub collect_pegs: Vec<PegShape>,
    /// A hw-sim world file to collect in instead of the policy
    /// configuration's world, whose camera it must share (a dataset of the
    /// box turned for a policy trained with it square, or of noisy
    /// sensors). Relative to the working directory.
    #[serde(default)]
    pub collect_world: Option<PathBuf>,
}

fn one() -> u64 {
    1
}

/// Representation training, shared by the variants.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReprStage {
    /// Epochs (overrides each variant's configuration; the paper: 20).
    pub epochs: Option<u32>,
    /// Batch size (overrides each variant's configuration).
    pub batch: Option<usize>,
    /// Where the representations train: `"cpu"` (the default), or a GPU
    /// through `"vulkan"` or `"cuda"` (a learner built with that feature).
    pub device: DeviceKind,
}

/// Policy training, shared by the variants.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyStage {
    /// The base training configuration (`learner policy train`'s; absent:
    /// its defaults, the paper's TRPO). Its observation is replaced by the
    /// variant's.
    pub config: Option<PathBuf>,
    /// Environment steps (overrides the base; the paper: 1M).
    pub env_steps: Option<u64>,
    /// In place of `config`: a `learner policy distill` configuration. The
    /// student observes the variant's z means, and the search teacher's
    /// probe (`[search_teacher.probe]`) reads the same representation, so
    /// each variant's teacher knows the opening only as well as its z tells
    /// it. For the ground-truth variant the probe is dropped: the search is
    /// told the hole with the configuration's `hole_error_m`. The policy
    /// evaluated is the last round's (DAgger has no best-logged update).
    pub distill: Option<PathBuf>,
}

/// The evaluation of every policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalStage {
    /// Episodes per policy and peg (the paper: 50).
    pub episodes: usize,
    /// Seed of the first evaluation episode (training seeds start at the
    /// run's seed; these are far from them).
    pub seed: u64,
    /// Pegs evaluated on (absent: the one the policy trained on). Another
    /// peg than the training one is the paper's transfer.
    pub pegs: Vec<PegShape>,
}

impl Default for EvalStage {
    fn default() -> Self {
        Self {
            episodes: 50,
            seed: 1_000_000,
            pegs: Vec::new(),
        }
    }
}

/// One compared model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    /// Its name in tables and charts (also its directory).
    pub name: String,
    /// The representation's training configuration; absent: the policy
    /// observes the privileged ground truth (a reference, not in the paper).
    pub representation: Option<PathBuf>,
    /// A representation already trained with `representation`'s
    /// configuration on `data.dataset` (its exported model directory): used
    /// as it is instead of training the variant's own. Its `model.json`'s
    /// epochs, architecture and dataset must be the variant's (checked), for
    /// the comparison to be fair.
    #[serde(default)]
    pub model: Option<PathBuf>,
    /// The paper's completed-insertion share for it, where the paper's text
    /// gives one (0..1).
    pub paper_completed: Option<f64>,
}

/// An evaluation on file, with what it evaluated: it is reused only for
/// the same policy (the same update of the same run), seed and length.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct StoredEval {
    /// The update of the policy evaluated.
    policy_iteration: u64,
    /// The run's environment steps when it was evaluated.
    run_env_steps: u64,
    /// Seed of the first episode.
    seed: u64,
    /// The evaluation.
    report: EvalReport,
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
}

impl ExperimentConfig {
    /// Reads and checks a configuration file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let cfg: Self = shared_mem_schema::config::read_toml(path)?;
        cfg.validate()
            .with_context(|| format!("{}", path.display()))?;
        Ok(cfg)
    }

    /// Checks the values, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        ensure!(!self.variant.is_empty(), "variant: at least one is needed");
        ensure!(self.eval.episodes > 0, "eval.episodes: must be at least 1");
        if self.policy.distill.is_some() {
            ensure!(
                self.policy.config.is_none() && self.policy.env_steps.is_none(),
                "policy.distill: give either a distillation (distill = …, its length its \
                 dagger.rounds) or a training configuration (config, env_steps), not both"
            );
        }
        for (i, v) in self.variant.iter().enumerate() {
            ensure!(
                !v.name.is_empty()
                    && !v.name.starts_with('.')
                    && v.name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_.=".contains(c)),
                "variant[{i}].name `{}`: letters, digits and - _ . = only, not starting with a \
                 dot (it names a directory)",
                v.name
            );
            if v.model.is_some() && v.representation.is_none() {
                bail!(
                    "variant[{i}].model: needs the representation configuration it was trained \
                     with (representation = …)"
                );
            }
            if let Some(p) = v.paper_completed {
                ensure!(
                    (0.0..=1.0).contains(&p),
                    "variant[{i}].paper_completed {p}: must be within 0..1"
                );
            }
            ensure!(
                !self.variant[..i].iter().any(|w| w.name == v.name),
                "variant[{i}].name `{}`: used twice",
                v.name
            );
        }
        Ok(())
    }
}

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

/// `rows` of this invocation, and for a partial one (`--only`) the other
/// variants' rows on file, in the configuration's order.
fn with_others(
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

/// How the variants' policies learn.
enum Route {
    /// `learner policy train` from this base configuration.
    Train(Box<policy_run::TrainConfig>),
    /// `learner policy distill` from this base configuration.
    Distill(Box<DistillConfig>),
}

/// Trains (or resumes, or finds finished) a variant's policy by TRPO/PPO
/// on `observation`; returns its checkpoint.
fn train_policy(
    cfg: &ExperimentConfig,
    base: &policy_run::TrainConfig,
    v: &Variant,
    observation: ObservationKind,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let mut pcfg = base.clone();
    // The ground truth's channels are scaled by hand, and normalised
    // its free-space wrench noise is as loud as the position (docs/rl.md,
    // "Observation normalisation"): the reference runs without it.
    if observation == ObservationKind::GroundTruth {
        pcfg.policy.normalise_observations = false;
    }
    pcfg.observation = observation;
    if let Some(n) = cfg.policy.env_steps {
        pcfg.env_steps = n;
    }
    let what = format!("{}: policy ({} steps)", v.name, pcfg.env_steps);
    let target = pcfg.env_steps;
    policy_stage(
        v,
        dir,
        what,
        target,
        |c| c.state.env_steps,
        log,
        || policy_run::train(pcfg, dir, true, stop),
    )
}

/// Distils (or resumes, or finds finished) a variant's policy: DAgger from
/// the touch search told by a probe of the variant's representation (the
/// truth with the configured error for the ground truth); returns its
/// checkpoint.
fn distill_policy(
    base: &DistillConfig,
    v: &Variant,
    observation: ObservationKind,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let mut d = base.clone();
    if let Some(search) = d.search_teacher.as_mut() {
        match &observation {
            ObservationKind::Representation(model) => {
                if let Some(p) = search.probe.as_mut() {
                    p.representation = model.clone();
                }
            }
            _ => search.probe = None,
        }
    }
    d.student.observation = observation;
    let what = format!(
        "{}: policy (DAgger, {} rounds of {} steps)",
        v.name, d.dagger.rounds, d.dagger.steps_per_round
    );
    let rounds = d.dagger.rounds;
    let resume = policy_run::checkpoint_path(dir).exists();
    policy_stage(
        v,
        dir,
        what,
        rounds,
        |c| c.state.iteration,
        log,
        || distill::distill(d, dir, resume, stop),
    )
}

/// A variant's policy stage, either route: the checkpoint in `dir` as it is
/// when its `progress` has reached `target`; otherwise `what` is logged and
/// `run` trains (or resumes) it, and a run stopped short of `target` is
/// reported as stopped.
fn policy_stage(
    v: &Variant,
    dir: &Path,
    what: String,
    target: u64,
    progress: impl Fn(&policy_run::Checkpoint) -> u64,
    log: &mut StageLog,
    run: impl FnOnce() -> std::result::Result<policy_run::Checkpoint, policy_run::RunError>,
) -> Result<policy_run::Checkpoint> {
    let trained = policy_run::checkpoint_path(dir);
    if trained.exists() {
        let c = policy_run::read_checkpoint(&trained)?;
        if progress(&c) >= target {
            return Ok(c);
        }
    }
    log.start(&what);
    let c = run()?;
    if progress(&c) < target {
        bail!(
            "stopped during the policy of {}; run the same command again to resume",
            v.name
        );
    }
    log.end()?;
    Ok(policy_run::read_checkpoint(&trained)?)
}

/// Refuses `field`'s file at `path` when its camera (`other`; none: no
/// check) is not the policy's world's `camera`, naming both and `advice`.
fn policy_camera(
    camera: &hw_sim::config::CameraConfig,
    other: Option<shared_mem_schema::CameraCalibration>,
    field: &str,
    path: &Path,
    advice: &str,
) -> Result<()> {
    match crate::rl::observe::check_calibration(camera, other) {
        Ok(()) => Ok(()),
        Err(crate::rl::RlEnvError::Camera { world, model }) => bail!(
            "{field} {}: its camera ({model}) is not the policy's world's ({world}); {advice}",
            path.display()
        ),
        Err(e) => Err(e.into()),
    }
}

/// The dataset: opened where it is, or collected and built there in the
/// policy's environment `env` (its world, camera included, and its
/// controller; `collect_world` in place of the world, with the same camera),
/// so that the representation learns the scene the policy will see.
fn ensure_dataset(
    d: &DataStage,
    env: &crate::rl::RlEnvConfig,
    uses_representation: bool,
    out: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<PathBuf> {
    if d.dataset.join("meta.json").exists() {
        let ds = Dataset::open(&d.dataset)
            .with_context(|| format!("opening the dataset {}", d.dataset.display()))?;
        // Before hours of training: a representation of another camera's
        // images would be refused by the policy's environment. (Only a
        // variant with a representation uses the dataset.)
        env.world.camera.validate()?;
        if uses_representation {
            policy_camera(
                &env.world.camera,
                ds.meta.camera,
                "data.dataset",
                &d.dataset,
                "give data.dataset a new path to collect one through the policy's camera, or set \
                 the policy configuration's [env.world.camera] to the dataset's",
            )?;
        }
        return Ok(d.dataset.clone());
    }
    ensure!(
        d.collect_states > 0,
        "data.dataset {}: no dataset there, and data.collect_states is 0",
        d.dataset.display()
    );
    let world = match &d.collect_world {
        None => env.world.clone(),
        Some(p) => {
            let w = hw_sim::WorldConfig::from_file(p)
                .with_context(|| format!("data.collect_world {}", p.display()))?;
            policy_camera(
                &env.world.camera,
                Some(w.camera.calibration()),
                "data.collect_world",
                p,
                "a representation of its images would be refused by the policy",
            )?;
            w
        }
    };
    let logs = out.join("collect");
    log.start(&format!("dataset: collecting {} states", d.collect_states));
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ccfg = CollectConfig {
        out_dir: logs.clone(),
        states: d.collect_states,
        episodes: None,
        episode_actions: 100,
        pegs: if d.collect_pegs.is_empty() {
            PegShape::ALL.to_vec()
        } else {
            d.collect_pegs.clone()
        },
        seed: d.collect_seed,
        workers,
        world,
        controller: env.controller.clone(),
        mix: Mix::default(),
        log: LogOptions {
            foxglove: false,
            ..Default::default()
        },
        // An interrupted collection continues where it stopped.
        resume: true,
    };
    let (_, stopped) = collect::collect_fast_until(&ccfg, stop)?;
    if stopped {
        bail!(
            "stopped during the collection into {}; run the same command again to continue it",
            logs.display()
        );
    }
    let files = dataset::find_logs(std::slice::from_ref(&logs))?;
    let mut skipped = Vec::new();
    dataset::build(
        &files,
        &d.dataset,
        &BuildConfig::default(),
        workers,
        |p, r| {
            if let Err(e) = r {
                skipped.push(format!("{}: {e}", p.display()));
            }
        },
    )?;
    for s in &skipped {
        eprintln!("experiment: skipped {s}");
    }
    log.end()?;
    Ok(d.dataset.clone())
}

/// Trains (or resumes) a variant's representation; returns its exported
/// model's directory.
#[allow(clippy::too_many_arguments)]
fn representation(
    cfg: &ExperimentConfig,
    v: &Variant,
    repr_cfg: &Path,
    data: &Path,
    dir: &Path,
    opts: &RunOptions,
    stop: &(dyn Fn() -> bool + Sync),
    log: &mut StageLog,
) -> Result<PathBuf> {
    if let Some(m) = &v.model {
        let meta_path = m.join("model.json");
        ensure!(
            meta_path.exists(),
            "variant {}: model {}: no model.json there (an exported model directory, a run's \
             model/)",
            v.name,
            m.display()
        );
        let meta = train::checkpoint::read_meta(m)
            .with_context(|| format!("variant {}: {}", v.name, meta_path.display()))?;
        // The comparison is fair only for a model trained as the variant's
        // own would be.
        let tcfg = train::TrainConfig::from_file(repr_cfg)
            .with_context(|| format!("variant {}", v.name))?;
        let epochs = cfg.representation.epochs.unwrap_or(tcfg.train.epochs);
        ensure!(
            meta.epochs == epochs,
            "variant {}: model {}: trained {} epochs, the experiment's representations {epochs}",
            v.name,
            m.display(),
            meta.epochs
        );
        ensure!(
            meta.model == tcfg.model,
            "variant {}: model {}: its model configuration is not {}'s",
            v.name,
            m.display(),
            repr_cfg.display()
        );
        let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => a == b,
        };
        ensure!(
            same(Path::new(&meta.dataset), data),
            "variant {}: model {}: trained on {}, the experiment's dataset is {}",
            v.name,
            m.display(),
            meta.dataset,
            data.display()
        );
        return Ok(m.clone());
    }
    let out = dir.join("repr");
    let model = out.join(train::run::files::MODEL_DIR);
    if model.join("model.json").exists() {
        return Ok(model);
    }
    let mut tcfg =
        train::TrainConfig::from_file(repr_cfg).with_context(|| format!("variant {}", v.name))?;
    if let Some(e) = cfg.representation.epochs {
        tcfg.train.epochs = e;
    }
    if let Some(b) = cfg.representation.batch {
        tcfg.train.batch = b;
    }
    log.start(&format!(
        "{}: representation ({} epochs)",
        v.name, tcfg.train.epochs
    ));
    let resume = train::checkpoint::dir(&out).exists();
    let t = train::train(
        &tcfg,
        data,
        &out,
        &TrainOptions {
            resume,
            device: cfg.representation.device,
            progress: opts.progress,
            ..Default::default()
        },
        stop,
    )?;
    if !t.finished {
        bail!(
            "stopped during the representation of {}; run the same command again to resume",
            v.name
        );
    }
    log.end()?;
    Ok(t.model_dir)
}

/// The evaluation on file at `path`, if any (one that does not parse is
/// done again, with a warning).
fn read_eval(path: &Path) -> Result<Option<StoredEval>> {
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
        "| variant | peg | episodes | completed insertion | inserted into hole | touched the box | failed | normalised reward | paper: completed |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut csv = String::from(
        "variant,peg,episodes,completed_insertion,inserted_into_hole,touched_the_box,failed,normalised_reward,paper_completed\n",
    );
    for r in rows {
        let o = r.report.outcomes;
        let c = |x: Outcome| o[x.index()];
        md += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.3} | {} |\n",
            r.variant,
            r.peg.name(),
            r.report.episodes,
            pct(c(Outcome::CompletedInsertion)),
            pct(c(Outcome::InsertedIntoHole)),
            pct(c(Outcome::TouchedBox)),
            pct(c(Outcome::Failed)),
            r.report.mean_normalised,
            r.paper_completed.map_or("–".into(), pct)
        );
        csv += &format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.variant,
            r.peg.name(),
            r.report.episodes,
            c(Outcome::CompletedInsertion),
            c(Outcome::InsertedIntoHole),
            c(Outcome::TouchedBox),
            c(Outcome::Failed),
            r.report.mean_normalised,
            r.paper_completed.map_or(String::new(), |p| p.to_string())
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

/// Appends each stage's wall time to `stages.log` (the scale of a run is
/// only half its story without them).
struct StageLog {
    path: PathBuf,
    current: Option<(String, Instant)>,
}

impl StageLog {
    fn open(out: &Path) -> Self {
        Self {
            path: out.join("stages.log"),
            current: None,
        }
    }

    fn start(&mut self, what: &str) {
        eprintln!("experiment: {what}");
        self.current = Some((what.to_string(), Instant::now()));
    }

    fn end(&mut self) -> Result<()> {
        use std::io::Write;
        if let Some((what, t)) = self.current.take() {
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)
                .with_context(|| format!("writing {}", self.path.display()))?;
            writeln!(f, "{what}: {:.1} s", t.elapsed().as_secs_f64())
                .with_context(|| format!("writing {}", self.path.display()))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every shipped experiment loads; the paper-scale one trains its
    /// representations on the GPU through Vulkan, the others on the CPU;
    /// the old `cuda = true` is refused, naming the field.
    #[test]
    fn the_shipped_experiments_load_and_name_their_device() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let dir = root.join("configs/experiments");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_none_or(|x| x != "toml") {
                continue;
            }
            let cfg = ExperimentConfig::from_file(&p)
                .unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            // The paper-scale experiments are for a GPU machine.
            let paper_scale = p
                .file_stem()
                .is_some_and(|s| s.to_string_lossy().ends_with("_paper"));
            let expected = if paper_scale {
                DeviceKind::Vulkan
            } else {
                DeviceKind::Cpu
            };
            assert_eq!(cfg.representation.device, expected, "{}", p.display());
            // The files it names load too: a typo there would otherwise
            // surface hours into a run. (Paths are the repository root's.)
            let at = |f: &Path| format!("{}: {}", p.display(), f.display());
            if let Some(f) = &cfg.policy.distill {
                distill::read_config(&root.join(f)).unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            if let Some(f) = &cfg.policy.config {
                policy_run::read_config(&root.join(f)).unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            if let Some(f) = &cfg.data.collect_world {
                hw_sim::WorldConfig::from_file(&root.join(f))
                    .unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            for v in &cfg.variant {
                if let Some(f) = &v.representation {
                    train::TrainConfig::from_file(&root.join(f))
                        .unwrap_or_else(|e| panic!("{}: {e}", at(f)));
                }
            }
            n += 1;
        }
        assert!(n >= 3, "{n} experiments in {}", dir.display());
        // The shipped distillations load too, those no experiment names
        // among them (docs/results.md runs them by themselves).
        let dir = root.join("configs/distill");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                distill::read_config(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                n += 1;
            }
        }
        assert!(n >= 4, "{n} distillations in {}", dir.display());
        let e = toml::from_str::<ReprStage>("cuda = true").unwrap_err();
        assert!(e.to_string().contains("cuda"), "{e}");
        let r: ReprStage = toml::from_str("device = \"vulkan\"").unwrap();
        assert_eq!(r.device, DeviceKind::Vulkan);
    }

    /// A distillation beside a training configuration, and a trained model
    /// without the configuration it was trained with, are refused by name.
    #[test]
    fn contradictory_policy_and_model_settings_are_refused() {
        let base = "[data]\ndataset = \"d\"\n\n[[variant]]\nname = \"Full\"\n";
        for (extra, field) in [
            (
                "[policy]\ndistill = \"a.toml\"\nconfig = \"b.toml\"\n",
                "policy.distill",
            ),
            (
                "[policy]\ndistill = \"a.toml\"\nenv_steps = 5\n",
                "policy.distill",
            ),
            ("", "variant[0].model"),
        ] {
            let mut text = format!("{extra}{base}");
            if extra.is_empty() {
                text += "model = \"m\"\n";
            }
            let cfg: ExperimentConfig = toml::from_str(&text).unwrap();
            let e = cfg.validate().unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
        let ok: ExperimentConfig =
            toml::from_str(&format!("[policy]\ndistill = \"a.toml\"\n{base}")).unwrap();
        ok.validate().unwrap();
    }
}
