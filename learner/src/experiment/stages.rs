//! The stages before the evaluation: the dataset, each variant's
//! representation and its policy (trained or distilled), and the log of
//! their wall times.

use super::{DataStage, ExperimentConfig, RunOptions, Variant};
use crate::collect::{self, CollectConfig};
use crate::dataset::{self, BuildConfig, Dataset};
use crate::rl::distill::{self, DistillConfig};
use crate::rl::observe::ObservationKind;
use crate::rl::run as policy_run;
use crate::train::{self, TrainOptions};
use anyhow::{Context, Result, bail, ensure};
use hw_sim::PegShape;
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How the variants' policies learn.
pub(super) enum Route {
    /// `learner policy train` from this base configuration.
    Train(Box<policy_run::TrainConfig>),
    /// `learner policy distill` from this base configuration, then, when
    /// given, `learner policy train` from its student.
    Distill(Box<DistillConfig>, Option<Box<policy_run::TrainConfig>>),
}

/// Trains (or resumes, or finds finished) a variant's policy by TRPO/PPO
/// on `observation`; returns its checkpoint.
#[allow(clippy::too_many_arguments)] // the stage's whole context
fn train_policy(
    cfg: &ExperimentConfig,
    base: &policy_run::TrainConfig,
    v: &Variant,
    observation: ObservationKind,
    seed: Option<u64>,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let mut pcfg = base.clone();
    if let Some(s) = seed {
        pcfg.seed = s;
    }
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
    let what = format!(
        "{}: policy ({} steps{})",
        v.name,
        pcfg.env_steps,
        seed_note(seed)
    );
    train_stage(v, pcfg, what, dir, log, stop)
}

/// A `learner policy train` stage of `p`, finished at its `env_steps`.
fn train_stage(
    v: &Variant,
    p: policy_run::TrainConfig,
    what: String,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let target = p.env_steps;
    policy_stage(
        v,
        dir,
        what,
        target,
        |c| c.state.env_steps,
        log,
        || policy_run::train(p, dir, true, stop),
    )
}

/// Distils (or resumes, or finds finished) a variant's policy: DAgger from
/// the configuration's checkpoint teacher, or from the touch search told by
/// a probe of the variant's representation (the truth with the configured
/// error for the ground truth); returns its checkpoint.
fn distill_policy(
    base: &DistillConfig,
    v: &Variant,
    observation: ObservationKind,
    seed: Option<u64>,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let mut d = base.clone();
    if let Some(s) = seed {
        d.student.seed = s;
    }
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
        "{}: policy (DAgger, {} rounds of {} steps{})",
        v.name,
        d.dagger.rounds,
        d.dagger.steps_per_round,
        seed_note(seed)
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

/// Fine-tunes (or resumes, or finds finished) a variant's distilled
/// student (`student`, its checkpoint `distilled`) by `base` (PPO) on the
/// variant's `observation`; returns the fine-tune's checkpoint.
#[allow(clippy::too_many_arguments)] // the stage's whole context
fn finetune_policy(
    base: &policy_run::TrainConfig,
    v: &Variant,
    observation: ObservationKind,
    seed: Option<u64>,
    student: &Path,
    distilled: &policy_run::Checkpoint,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<policy_run::Checkpoint> {
    let mut p = base.clone();
    if let Some(s) = seed {
        p.seed = s;
    }
    p.observation = observation;
    p.init_from = Some(student.to_path_buf());
    // The student it started from (its round and its policy's
    // fingerprint), so that a student distilled further, or distilled
    // again into another policy, is not silently followed by the old
    // fine-tune.
    let mark = dir.join("student-rounds.json");
    let now = StudentMark {
        rounds: distilled.state.iteration,
        policy: fingerprint(&distilled.state.policy),
    };
    match std::fs::read_to_string(&mark) {
        Ok(text) => {
            // Marks written before the fingerprint hold the round alone.
            let then: StudentMark = match serde_json::from_str::<u64>(&text) {
                Ok(rounds) => StudentMark {
                    rounds,
                    policy: now.policy.clone(),
                },
                Err(_) => serde_json::from_str(&text)
                    .with_context(|| format!("reading {}", mark.display()))?,
            };
            ensure!(
                then.rounds == now.rounds,
                "{}: this fine-tune started from the student's round {}, and the student in {} \
                 now has {}; delete {} to fine-tune it again",
                v.name,
                then.rounds,
                student.display(),
                now.rounds,
                dir.display()
            );
            ensure!(
                then.policy == now.policy,
                "{}: this fine-tune started from another student than the one in {} (policy \
                 {} then, {} now, both at round {}); delete {} to fine-tune it again",
                v.name,
                student.display(),
                then.policy,
                now.policy,
                now.rounds,
                dir.display()
            );
        }
        Err(_) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let text = serde_json::to_string(&now).expect("a mark serialises");
            std::fs::write(&mark, text).with_context(|| format!("writing {}", mark.display()))?;
        }
    }
    let what = format!(
        "{}: fine-tune of the student ({} steps{})",
        v.name,
        p.env_steps,
        seed_note(seed)
    );
    train_stage(v, p, what, dir, log, stop)
}

/// What a fine-tune records of the student it started from.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct StudentMark {
    /// The student's DAgger rounds.
    rounds: u64,
    /// [`fingerprint`] of its policy.
    policy: String,
}

/// A fingerprint of `p`'s parameters (FNV-1a over the bits of its sizes,
/// weights, log σ and observation statistics), hex: equal policies give
/// equal fingerprints on every machine.
fn fingerprint(p: &crate::rl::GaussianPolicy) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |x: u64| {
        for b in x.to_le_bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    };
    p.sizes.iter().for_each(|&n| eat(n as u64));
    p.net
        .iter()
        .chain(&p.log_std)
        .for_each(|x| eat(x.to_bits()));
    if let Some(n) = &p.obs_norm {
        eat(n.count);
        n.mean.iter().chain(&n.m2).for_each(|x| eat(x.to_bits()));
    }
    format!("{h:016x}")
}

impl Route {
    /// The route as docs/results.md names it, for the results table.
    pub(super) fn name(&self) -> String {
        use crate::rl::train::Algorithm;
        let rl = |a: Algorithm| match a {
            Algorithm::Trpo => "TRPO",
            Algorithm::Ppo => "PPO",
        };
        match self {
            Route::Train(t) => match &t.init_from {
                Some(_) => format!("{} from a start", rl(t.policy.algorithm)),
                None => format!("{} from scratch", rl(t.policy.algorithm)),
            },
            Route::Distill(d, ft) => {
                let teacher = if d.teacher.is_some() {
                    "DAgger ← learned teacher"
                } else if d.search_teacher.as_ref().is_some_and(|t| t.probe.is_some()) {
                    "DAgger ← search(probe)"
                } else {
                    "DAgger ← search(truth)"
                };
                match ft {
                    Some(f) => format!("{teacher} → {} on z", rl(f.policy.algorithm)),
                    None => teacher.to_string(),
                }
            }
        }
    }
}

/// `, seed N` for a stage of one of several training seeds.
fn seed_note(seed: Option<u64>) -> String {
    seed.map_or(String::new(), |s| format!(", seed {s}"))
}

/// Trains (or resumes, or finds finished) a variant's policy by `route` on
/// `observation`, with training seed `seed` (None: the configuration's),
/// under `dir` (`policy<tag>/`, and `finetune<tag>/` after a
/// distillation); returns its checkpoint and whether its last policy is
/// the one to evaluate (DAgger's).
#[allow(clippy::too_many_arguments)] // the stage's whole context
pub(super) fn train_route(
    route: &Route,
    cfg: &ExperimentConfig,
    v: &Variant,
    observation: ObservationKind,
    seed: Option<u64>,
    dir: &Path,
    log: &mut StageLog,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<(policy_run::Checkpoint, bool)> {
    let tag = seed.map_or(String::new(), |s| format!("-s{s}"));
    let policy_dir = dir.join(format!("policy{tag}"));
    Ok(match route {
        Route::Train(base) => (
            train_policy(cfg, base, v, observation, seed, &policy_dir, log, stop)?,
            false,
        ),
        Route::Distill(base, None) => (
            distill_policy(base, v, observation, seed, &policy_dir, log, stop)?,
            true,
        ),
        Route::Distill(base, Some(ft)) => {
            let s = distill_policy(base, v, observation.clone(), seed, &policy_dir, log, stop)?;
            let student = policy_run::checkpoint_path(&policy_dir);
            let ft_dir = dir.join(format!("finetune{tag}"));
            let c = finetune_policy(ft, v, observation, seed, &student, &s, &ft_dir, log, stop)?;
            (c, false)
        }
    })
}

/// A variant's policy stage, any route: the checkpoint in `dir` as it is
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
pub(super) fn ensure_dataset(
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
    let workers = crate::rl::vec::all_cores();
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
pub(super) fn representation(
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
        let tcfg = train::ReprTrainConfig::from_file(repr_cfg)
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
    let mut tcfg = train::ReprTrainConfig::from_file(repr_cfg)
        .with_context(|| format!("variant {}", v.name))?;
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

/// Appends each stage's wall time to `stages.log` (the scale of a run is
/// only half its story without them).
pub(super) struct StageLog {
    path: PathBuf,
    current: Option<(String, Instant)>,
}

impl StageLog {
    pub(super) fn open(out: &Path) -> Self {
        Self {
            path: out.join("stages.log"),
            current: None,
        }
    }

    pub(super) fn start(&mut self, what: &str) {
        eprintln!("experiment: {what}");
        self.current = Some((what.to_string(), Instant::now()));
    }

    pub(super) fn end(&mut self) -> Result<()> {
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
