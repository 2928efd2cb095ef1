//! `learner`: the training toolkit's command line, and the node's `run` and
//! `stack` (learner-node's, with training checkpoints converted).

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use hw_sim::{PegShape, WorldConfig};
use learner_node::cli::{RunArgs, StackArgs};
use shared_mem_schema::process::install_termination_handler;
use std::path::PathBuf;

/// Vision-and-touch learner: live policy node and tools.
#[derive(Debug, Parser)]
#[command(name = "learner", version)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// The live policy node: heuristic insertion episodes against a running
    /// hw-sim and rt-controller, logged to MCAP. With --hole-pos, against a
    /// running rt-controller alone (a robot, franky-sim): the task from the
    /// calibration, no resets. --policy takes a deployed policy or a
    /// training checkpoint (converted).
    Run(RunArgs),
    /// The whole stack: starts hw-sim (or franky-sim), rt-controller and
    /// `learner run` as separate processes, runs the episodes, stops
    /// everything.
    Stack(StackArgs),
    /// Collects episodes for the self-supervised dataset (random and
    /// heuristic policies), one MCAP shard per episode.
    Collect(CollectArgs),
    /// MCAP log tools: summary, integrity check, crash recovery.
    #[command(subcommand)]
    Log(LogCmd),
    /// The self-supervised dataset: build from logs, inspect.
    #[command(subcommand)]
    Dataset(DatasetCmd),
    /// Reinforcement learning on the fast path: train a policy with TRPO,
    /// evaluate a checkpoint (docs/rl.md).
    #[command(subcommand)]
    Policy(PolicyCmd),
    /// The multimodal representation: train a model from a dataset,
    /// evaluate it on its test split (docs/representation.md).
    #[command(subcommand)]
    Repr(ReprCmd),
    /// The paper's ablations end to end: dataset → representation →
    /// policy → evaluation per variant, a results table and charts next to
    /// the paper's numbers (docs/experiments.md). Resumes where it stopped.
    Experiment {
        /// The experiment (TOML; see configs/experiments/).
        #[arg(long)]
        config: PathBuf,
        /// Its directory (default: runs/experiments/<config's file stem>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run only this variant (repeatable).
        #[arg(long)]
        only: Vec<String>,
    },
}

#[derive(Debug, Subcommand)]
enum PolicyCmd {
    /// Writes a checkpoint's policy in the node's deployed format: DIR/policy.json
    /// and, for a representation policy, DIR/encoder.bin (the robot PC's
    /// `policy-node run --policy DIR/policy.json` reads them without the
    /// training stack).
    Export {
        /// The training run's checkpoint.json.
        #[arg(long)]
        checkpoint: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// The checkpoint's last policy instead of its best validated or
        /// best logged one.
        #[arg(long)]
        last: bool,
    },
    /// Trains with TRPO or PPO (`policy.algorithm`); writes
    /// checkpoint.json, curve.csv, return.png and outcomes.png into `--out`.
    Train {
        /// Training configuration (TOML; every field defaulted, see
        /// learner::rl::run::TrainConfig).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Overrides one field of the configuration by its dotted path,
        /// e.g. `--set seed=2 --set env.world.task.box_yaw_range_rad=0.26`
        /// (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Run directory.
        #[arg(long, default_value = "runs/policy")]
        out: PathBuf,
        /// Continue the run in `--out` from its checkpoint.
        #[arg(long)]
        resume: bool,
        /// Environment steps to train for (overrides the configuration).
        #[arg(long)]
        env_steps: Option<u64>,
        /// Peg (overrides the configuration's).
        #[arg(long, value_enum)]
        peg: Option<PegShape>,
        /// Update rule (overrides the configuration's `policy.algorithm`).
        #[arg(long, value_enum)]
        algorithm: Option<AlgorithmArg>,
    },
    /// DAgger: a student policy on one observation (the representation)
    /// learns the actions of a trained teacher on another (the ground
    /// truth); writes a checkpoint that `policy eval` and `init_from` take
    /// (docs/rl.md, "Distillation").
    Distill {
        /// Distillation configuration (TOML, see configs/policy/).
        #[arg(long)]
        config: PathBuf,
        /// Run directory.
        #[arg(long, default_value = "runs/distill")]
        out: PathBuf,
        /// Continue the run in `--out` from its last finished round.
        #[arg(long)]
        resume: bool,
    },
    /// Runs a checkpoint's policy (its mean action) for N episodes: the
    /// four outcome categories and the normalised episode reward.
    Eval {
        /// The checkpoint (a run's checkpoint.json).
        #[arg(long)]
        checkpoint: PathBuf,
        /// Episodes.
        #[arg(long, default_value_t = 50)]
        episodes: usize,
        /// Seed of the first episode (training uses the run's seed upward).
        #[arg(long, default_value_t = 1_000_000)]
        seed: u64,
        /// Peg (default: the one it was trained on). Another peg than the
        /// training one is the paper's policy transfer.
        #[arg(long, value_enum)]
        peg: Option<PegShape>,
        /// Random pushes on the last link per episode (sets hw-sim's
        /// `perturbations.random_pushes`: 5–20 N for 0.2 s each, starting
        /// within 1–20 s).
        #[arg(long, default_value_t = 0)]
        pushes: u32,
        /// Random camera occlusions per episode (32-px squares for 1 s).
        #[arg(long, default_value_t = 0)]
        occlusions: u32,
        /// F/T force noise, N (standard deviation per reading).
        #[arg(long)]
        force_noise_n: Option<f64>,
        /// F/T moment noise, N·m (standard deviation per reading).
        #[arg(long)]
        torque_noise_nm: Option<f64>,
        /// Depth noise, m (standard deviation per pixel).
        #[arg(long)]
        depth_noise_m: Option<f64>,
        /// RGB noise, 8-bit levels (standard deviation per channel).
        #[arg(long)]
        rgb_noise: Option<f64>,
        /// A fixed factor on every noise deviation, for every episode (sets
        /// hw-sim's `noise.episode_scale` to `[X, X]`): evaluates a policy
        /// trained across noise levels at one of them.
        #[arg(long)]
        noise_scale: Option<f64>,
        /// A ground-truth policy told the hole's position with a
        /// per-episode error of this standard deviation per horizontal
        /// axis, mm (the observation `ground_truth_hole_error`): how
        /// precisely the policy needs to know where the opening is.
        #[arg(long)]
        hole_error_mm: Option<f64>,
        /// Half-range of the box's yaw, rad (hw-sim's
        /// `task.box_yaw_range_rad`; default: the run's, 0.26). 0
        /// randomises the box's position alone, the paper's literal wording
        /// ("we randomize the configuration of the box position"; it names
        /// no yaw), so the peg starts square to the hole.
        #[arg(long)]
        box_yaw_range_rad: Option<f64>,
        /// Overrides one field of the checkpoint's training configuration
        /// by its dotted path before evaluating, e.g. `--set
        /// env.world.task.box_yaw_range_rad=0.26` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Also write the report as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Evaluate the last policy instead of the best validated one (a
        /// run with `[validation]`) or the best one logged in training (the
        /// paper's choice).
        #[arg(long)]
        last: bool,
    },
}

/// `--algorithm`'s values.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum AlgorithmArg {
    Trpo,
    Ppo,
}

#[derive(Debug, Subcommand)]
enum ReprCmd {
    /// Trains a representation model (docs/representation.md): progress
    /// bar, per-epoch metrics.csv and curves, checkpoints, and the exported
    /// model in `--out/model`.
    Train {
        /// Model and training configuration (TOML; configs/repr/ has the
        /// paper's models).
        #[arg(long)]
        config: PathBuf,
        /// The dataset (`learner dataset build`'s output).
        #[arg(long)]
        data: PathBuf,
        /// Run directory.
        #[arg(long, default_value = "runs/repr")]
        out: PathBuf,
        /// Continue the run in `--out` from its checkpoint.
        #[arg(long)]
        resume: bool,
        /// Epochs (overrides the configuration).
        #[arg(long)]
        epochs: Option<u32>,
        /// Where the tensors live.
        #[arg(long, value_enum, default_value_t = learner::train::DeviceKind::Cpu)]
        device: learner::train::DeviceKind,
    },
    /// Evaluates a trained run on its test split: the appendix table with
    /// baselines, flow for candidate actions, PCA of z.
    Eval {
        /// The training run's directory.
        #[arg(long)]
        run: PathBuf,
        /// The dataset it was trained on.
        #[arg(long)]
        data: PathBuf,
        /// Where the table and pictures go (default: `<run>/eval`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Where the tensors live.
        #[arg(long, value_enum, default_value_t = learner::train::DeviceKind::Cpu)]
        device: learner::train::DeviceKind,
        /// Samples in the PCA picture.
        #[arg(long, default_value_t = 1500)]
        pca_samples: usize,
        /// Images in the flow picture.
        #[arg(long, default_value_t = 4)]
        flow_images: usize,
    },
}

fn run_repr(cmd: ReprCmd) -> Result<()> {
    use learner::train::{self, TrainConfig, TrainOptions};
    match cmd {
        ReprCmd::Train {
            config,
            data,
            out,
            resume,
            epochs,
            device,
        } => {
            let mut cfg = TrainConfig::from_file(&config)?;
            if let Some(e) = epochs {
                cfg.train.epochs = e;
            }
            let opts = TrainOptions {
                resume,
                device,
                progress: true,
                ..Default::default()
            };
            let s = train::train(
                &cfg,
                &data,
                &out,
                &opts,
                &shared_mem_schema::process::termination_requested,
            )?;
            for r in &s.rows {
                println!("{}", r.csv());
            }
            if s.finished {
                println!(
                    "{} steps, {:.1} samples/s; model in {}",
                    s.steps,
                    s.samples_per_s,
                    s.model_dir.display()
                );
            } else {
                println!(
                    "stopped after {} steps; `--resume` continues from the checkpoint in {}",
                    s.steps,
                    out.display()
                );
            }
        }
        ReprCmd::Eval {
            run,
            data,
            out,
            device,
            pca_samples,
            flow_images,
        } => {
            let out = out.unwrap_or_else(|| run.join("eval"));
            let r = train::eval::eval(&train::eval::EvalOptions {
                run,
                data,
                out: out.clone(),
                device,
                pca_samples,
                flow_images,
            })?;
            println!("{}", r.markdown);
            println!("written to {}", out.display());
        }
    }
    Ok(())
}

fn run_policy(cmd: PolicyCmd) -> Result<()> {
    use learner::rl::reward::Outcome;
    use learner::rl::run;
    match cmd {
        PolicyCmd::Train {
            config,
            sets,
            out,
            resume,
            env_steps,
            peg,
            algorithm,
        } => {
            let mut cfg: run::TrainConfig =
                learner::settings::read_with_overrides(config.as_deref(), &sets)?;
            if let Some(n) = env_steps {
                cfg.env_steps = n;
            }
            if let Some(p) = peg {
                cfg.env.world.task.peg = p;
            }
            if let Some(a) = algorithm {
                cfg.policy.algorithm = match a {
                    AlgorithmArg::Trpo => learner::rl::Algorithm::Trpo,
                    AlgorithmArg::Ppo => learner::rl::Algorithm::Ppo,
                };
            }
            let c = run::train(
                cfg,
                &out,
                resume,
                &shared_mem_schema::process::termination_requested,
            )?;
            println!(
                "{} updates, {} environment steps; checkpoint {}",
                c.state.iteration,
                c.state.env_steps,
                run::checkpoint_path(&out).display()
            );
        }
        PolicyCmd::Distill {
            config,
            out,
            resume,
        } => {
            let cfg = learner::rl::distill::read_config(&config)?;
            let c = learner::rl::distill::distill(
                cfg,
                &out,
                resume,
                &shared_mem_schema::process::termination_requested,
            )?;
            println!(
                "{} rounds, {} environment steps; checkpoint {}",
                c.state.iteration,
                c.state.env_steps,
                run::checkpoint_path(&out).display()
            );
        }
        PolicyCmd::Export {
            checkpoint,
            out,
            last,
        } => {
            let d = learner::rl::export::from_checkpoint(&checkpoint, last)?;
            let path = d.write(&out)?;
            println!("{} written ({})", path.display(), d.policy.source);
        }
        PolicyCmd::Eval {
            checkpoint,
            episodes,
            seed,
            peg,
            pushes,
            occlusions,
            force_noise_n,
            torque_noise_nm,
            depth_noise_m,
            rgb_noise,
            noise_scale,
            hole_error_mm,
            box_yaw_range_rad,
            sets,
            json,
            last,
        } => {
            anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
            let c = run::read_checkpoint(&checkpoint)?;
            let trained_on = c.config.env.world.task.peg;
            let mut cfg = learner::settings::with_overrides(&c.config, &sets)?;
            if let Some(mm) = hole_error_mm {
                use learner::rl::ObservationKind as O;
                anyhow::ensure!(
                    mm.is_finite() && mm >= 0.0,
                    "--hole-error-mm {mm}: must be a standard deviation in mm, 0 or more"
                );
                anyhow::ensure!(
                    matches!(cfg.observation, O::GroundTruth | O::GroundTruthHoleError(_)),
                    "--hole-error-mm is for a ground-truth policy; this one observes {:?}",
                    cfg.observation
                );
                cfg.observation = O::GroundTruthHoleError(mm * 1e-3);
            }
            let world = &mut cfg.env.world;
            if let Some(p) = peg {
                world.task.peg = p;
            }
            if pushes > 0 {
                world.perturbations.random_pushes = pushes;
            }
            if occlusions > 0 {
                world.perturbations.random_occlusions = occlusions;
            }
            if let Some(r) = box_yaw_range_rad {
                anyhow::ensure!(
                    r.is_finite() && r >= 0.0,
                    "--box-yaw-range-rad {r}: must be a half-range in rad, 0 or more"
                );
                world.task.box_yaw_range_rad = r;
            }
            for (v, field) in [
                (force_noise_n, &mut world.noise.force_std_n),
                (torque_noise_nm, &mut world.noise.torque_std_nm),
                (depth_noise_m, &mut world.noise.depth_std_m),
                (rgb_noise, &mut world.noise.rgb_std),
            ] {
                if let Some(v) = v {
                    *field = v;
                }
            }
            if let Some(k) = noise_scale {
                anyhow::ensure!(
                    k.is_finite() && k >= 0.0,
                    "--noise-scale {k}: must be a factor on the noise, 0 or more"
                );
                world.noise.episode_scale = [k, k];
            }
            let chosen = c.chosen_policy(last);
            println!("evaluating {chosen}");
            let r = run::evaluate(
                chosen.policy,
                &cfg,
                episodes,
                seed,
                &shared_mem_schema::process::termination_requested,
            )?;
            println!(
                "{} episodes ({} peg, trained on {}): normalised reward {:.3}",
                r.episodes,
                cfg.env.world.task.peg.name(),
                trained_on.name(),
                r.mean_normalised
            );
            for o in Outcome::ALL.into_iter().rev() {
                println!("  {:<20} {:5.1}%", o.name(), 100.0 * r.outcomes[o.index()]);
            }
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&r)?;
                std::fs::write(&path, text)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
struct CollectArgs {
    /// 20 Hz states to collect: in fast mode the first episodes whose
    /// states reach this many, the same whatever the worker count.
    #[arg(long, default_value_t = 1000)]
    states: u64,
    /// Stop after this many episodes even if fewer states were written
    /// (fast mode).
    #[arg(long)]
    episodes: Option<u64>,
    /// Output directory.
    #[arg(long, default_value = "data/collect")]
    out: PathBuf,
    /// Actions per episode (20 per second).
    #[arg(long, default_value_t = 100)]
    episode_actions: u32,
    /// Pegs, comma-separated, taken in turn (default: all four).
    #[arg(long, value_enum, value_delimiter = ',')]
    pegs: Vec<PegShape>,
    /// Seed of the first episode.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Share of episodes run by the heuristic; the rest are random.
    #[arg(long, default_value_t = 0.5)]
    heuristic_fraction: f64,
    /// Run episodes that completed the insertion to their length (by
    /// default they end 10 actions after completion, so that a peg resting
    /// at the bottom does not dominate the data).
    #[arg(long)]
    full_episodes: bool,
    /// Continue an interrupted collection in `--out` (fast mode): the
    /// episodes its manifest lists are kept and not run again. Without it a
    /// directory that already holds a collection is refused.
    #[arg(long)]
    resume: bool,
    /// Worker threads (fast mode); default: all cores.
    #[arg(long)]
    workers: Option<usize>,
    /// World configuration (TOML); its peg is replaced per episode.
    #[arg(long)]
    world: Option<PathBuf>,
    /// rt-controller configuration (TOML; its `[controller]` is used).
    #[arg(long)]
    controller_config: Option<PathBuf>,
    /// Leave out the Foxglove view channels (smaller shards).
    #[arg(long)]
    no_foxglove: bool,
    /// Rate of the 1 kHz view channels (pose, wrench), Hz.
    #[arg(long, default_value_t = 100.0)]
    view_rate_hz: f64,
    /// Through the real-time stack (hw-sim, rt-controller, learner run as
    /// processes) instead of in-process lockstep.
    #[arg(long)]
    live: bool,
}

fn load_world(path: Option<&PathBuf>) -> Result<WorldConfig> {
    Ok(match path {
        Some(p) => WorldConfig::from_file(p)?,
        None => WorldConfig::default(),
    })
}

fn run_collect(a: CollectArgs) -> Result<()> {
    use learner::collect::{self, CollectConfig};
    use learner_node::mix::Mix;
    anyhow::ensure!(
        (0.0..=1.0).contains(&a.heuristic_fraction),
        "--heuristic-fraction {} must be within 0..1",
        a.heuristic_fraction
    );
    let pegs = if a.pegs.is_empty() {
        PegShape::ALL.to_vec()
    } else {
        a.pegs.clone()
    };
    let world = load_world(a.world.as_ref())?;
    let log = learner_node::log::LogOptions {
        foxglove: !a.no_foxglove,
        view_rate_hz: a.view_rate_hz,
        ..Default::default()
    };
    let mut mix = Mix {
        heuristic_fraction: a.heuristic_fraction,
        ..Mix::default()
    };
    if a.full_episodes {
        mix.end_after_completion = None;
    }
    if a.live {
        anyhow::ensure!(
            !a.resume,
            "--resume continues a fast-mode collection; a live collection cannot be resumed"
        );
        return Ok(learner_node::stack::collect_live(
            &learner_node::stack::LiveCollect {
                out_dir: a.out.clone(),
                states: a.states,
                episode_actions: a.episode_actions,
                pegs,
                seed: a.seed,
                world,
                mix,
                log,
                controller_config: a.controller_config.clone(),
            },
        )?);
    }
    let controller = match &a.controller_config {
        Some(p) => rt_controller_daemon::config::DaemonConfig::from_file(p)?.controller,
        None => rt_controller::ControllerConfig::default(),
    };
    let workers = a
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let cfg = CollectConfig {
        out_dir: a.out.clone(),
        states: a.states,
        episodes: a.episodes,
        episode_actions: a.episode_actions,
        pegs,
        seed: a.seed,
        workers,
        world,
        controller,
        mix,
        log,
        resume: a.resume,
    };
    // Ctrl-C: the workers finish their episodes' files and stop.
    let (summary, _) =
        collect::collect_fast_until(&cfg, &shared_mem_schema::process::termination_requested)?;
    let bytes: u64 = summary
        .shards
        .iter()
        .filter_map(|s| std::fs::metadata(&s.file).ok())
        .map(|m| m.len())
        .sum();
    println!(
        "collected {} states in {} episodes with {workers} workers in {:.1} s ({:.0} states/s, \
         {:.2} GB); shards and manifest.jsonl in {}",
        summary.states,
        summary.shards.len(),
        summary.wall_s,
        summary.states as f64 / summary.wall_s.max(1e-9),
        bytes as f64 * 1e-9,
        a.out.display()
    );
    println!(
        "controller faults by where the peg was (count, median force, median tip speed in the \
         10 ms before):\n{}",
        collect::fault_table(&summary.shards)
    );
    Ok(())
}

#[derive(Debug, Subcommand)]
enum DatasetCmd {
    /// Builds training shards with labels from MCAP logs (files or
    /// directories).
    Build {
        /// Logs or directories of logs.
        #[arg(required = true)]
        logs: Vec<PathBuf>,
        /// Output directory.
        #[arg(long, default_value = "data/dataset")]
        out: PathBuf,
        /// Contact: force change against free space above this, N.
        #[arg(long, default_value_t = 3.0)]
        contact_threshold_n: f64,
        /// Flow mask: image motion from which a robot pixel counts as
        /// moving, px (0: every robot pixel).
        #[arg(long, default_value_t = hw_sim::camera::FLOW_MASK_MIN_PX as f64)]
        flow_mask_min_px: f64,
        /// Worker threads; default: all cores.
        #[arg(long)]
        workers: Option<usize>,
        /// Directory of the URDF files logs may name as their robot;
        /// without it, only the built-in robots.
        #[arg(long)]
        robot_dir: Option<PathBuf>,
    },
    /// Counts, label balance and a PNG contact sheet.
    Inspect {
        /// Dataset directory.
        dir: PathBuf,
        /// Contact sheet (RGB, depth, flow, mask per row); default:
        /// contact-sheet.png in the dataset's directory.
        #[arg(long)]
        sheet: Option<PathBuf>,
        /// Rows in the sheet.
        #[arg(long, default_value_t = 8)]
        rows: usize,
    },
}

fn run_dataset(cmd: DatasetCmd) -> Result<()> {
    use learner::dataset::{self, BuildConfig, Dataset};
    match cmd {
        DatasetCmd::Build {
            logs,
            out,
            contact_threshold_n,
            flow_mask_min_px,
            workers,
            robot_dir,
        } => {
            let files = dataset::find_logs(&logs)?;
            anyhow::ensure!(!files.is_empty(), "no .mcap logs in {logs:?}");
            let cfg = BuildConfig {
                contact_threshold_n,
                robot_dir,
                flow_mask_min_px,
                ..Default::default()
            };
            let workers = workers
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            let progress = learner_node::progress::Progress::new(files.len() as u64, "logs");
            let (mut done, mut skipped) = (0, 0);
            let t = std::time::Instant::now();
            let meta = dataset::build(&files, &out, &cfg, workers, |path, r| {
                done += 1;
                if let Err(e) = r {
                    skipped += 1;
                    progress.suspend(|| eprintln!("skipped {}: {e}", path.display()));
                }
                progress.update(done, format!("{skipped} skipped"));
            })?;
            progress.finish();
            println!(
                "built {} samples from {} episodes ({} logs skipped) in {:.1} s into {}",
                meta.samples,
                meta.episodes.len(),
                meta.skipped.len(),
                t.elapsed().as_secs_f64(),
                out.display()
            );
            Ok(())
        }
        DatasetCmd::Inspect { dir, sheet, rows } => {
            let ds = Dataset::open(&dir)?;
            let m = &ds.meta;
            println!(
                "{}: {} samples, {} episodes, {} shards, images {}×{}",
                dir.display(),
                m.samples,
                m.episodes.len(),
                m.shards.len(),
                m.width,
                m.height
            );
            let mut by: std::collections::BTreeMap<(&str, &str), u64> = Default::default();
            for e in &m.episodes {
                *by.entry((e.peg.name(), e.policy.name())).or_default() += e.samples;
            }
            for ((peg, policy), n) in by {
                println!("  {peg:<11} {policy:<10} {n:>8} samples");
            }
            println!(
                "contact now {:.1} %, contact at the next step {:.1} %, pairing (a negative \
                 exists) {:.1} %, flow mask {:.2} % of pixels",
                100.0 * ds.contact_ratio(),
                100.0 * ds.stats.contact_next_ratio,
                100.0 * ds.pairing_ratio(),
                100.0 * ds.stats.mask_ratio
            );
            let b = &ds.stats.balance;
            if b.total().samples == m.samples {
                println!(
                    "balance (stage: the best reached by the sample's frame; moving: the tip \
                     moves more than {} mm until the next frame):\n{}",
                    1e3 * dataset::MOVING_M,
                    b.table()
                );
            } else {
                println!("balance: not recorded (built before it was; rebuild to see it)");
            }
            if !m.skipped.is_empty() {
                println!("{} logs skipped:", m.skipped.len());
                for (f, why) in &m.skipped {
                    println!("  {f}: {why}");
                }
            }
            let sheet = sheet.unwrap_or_else(|| dir.join("contact-sheet.png"));
            dataset::contact_sheet(&ds, rows, &sheet)?;
            println!("contact sheet: {}", sheet.display());
            Ok(())
        }
    }
}

#[derive(Debug, Subcommand)]
enum LogCmd {
    /// Channels, message counts and time span of a complete log, and the
    /// gaps in its 1 kHz channels.
    Info {
        /// The log.
        file: PathBuf,
    },
    /// Reads every record and chunk; reports the first damage by byte offset
    /// (exit status 1), then the gaps in the 1 kHz channels.
    Check {
        /// The log.
        file: PathBuf,
    },
    /// Writes a valid copy of everything intact in a truncated or damaged
    /// log (the input is left as it is).
    Recover {
        /// The damaged log.
        file: PathBuf,
        /// Where the copy goes (default: FILE with `.recovered.mcap`).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

fn main() {
    tracing_subscriber::fmt().with_target(false).init();
    install_termination_handler();
    shared_mem_schema::transport::quiet_logs();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("learner: error: {e:#}");
        std::process::exit(1);
    }
}

fn run_log(cmd: LogCmd) -> Result<()> {
    use learner_node::log;
    match cmd {
        LogCmd::Info { file } => {
            let r = log::LogReader::open(&file)?;
            println!("{}: {} bytes", file.display(), r.len_bytes());
            if let Some((a, b)) = r.time_span() {
                println!(
                    "log time {:.3} s to {:.3} s ({:.3} s)",
                    a as f64 * 1e-9,
                    b as f64 * 1e-9,
                    (b - a) as f64 * 1e-9
                );
            }
            println!(
                "{:<24} {:>9}  {:<28} encoding",
                "topic", "messages", "schema"
            );
            for t in r.topics() {
                println!(
                    "{:<24} {:>9}  {:<28} {}",
                    t.topic, t.messages, t.schema, t.encoding
                );
            }
            print_gaps(&r)
        }
        LogCmd::Check { file } => {
            let rep = log::scan(&file)?;
            println!(
                "{}: {} chunks, {} messages, {} bytes intact{}",
                file.display(),
                rep.chunks,
                rep.messages,
                rep.readable_bytes,
                if rep.complete { ", complete" } else { "" }
            );
            if let Some((offset, what)) = rep.problem {
                anyhow::bail!(
                    "{}: damaged at byte offset {offset}: {what}; `learner log recover {}` keeps \
                     everything before it",
                    file.display(),
                    file.display()
                );
            }
            print_gaps(&log::LogReader::open(&file)?)
        }
        LogCmd::Recover { file, output } => {
            let out = output.unwrap_or_else(|| file.with_extension("recovered.mcap"));
            let rep = log::recover(&file, &out)?;
            match &rep.damage {
                Some((offset, what)) => println!(
                    "{}: damage at byte offset {offset} ({what}); kept the {} bytes before it",
                    file.display(),
                    rep.readable_bytes
                ),
                None => println!("{}: no damage found", file.display()),
            }
            println!(
                "wrote {}: {} messages on {} channels",
                out.display(),
                rep.messages,
                rep.channels
            );
            if rep.channels_without_schema > 0 {
                println!(
                    "  {} channels lost their schema record; kept without a schema",
                    rep.channels_without_schema
                );
            }
            Ok(())
        }
    }
}

/// Prints the gaps of every 1 kHz channel of a log (lost messages are
/// reported, not an error: the file itself is intact).
fn print_gaps(r: &learner_node::log::LogReader) -> Result<()> {
    let gaps = learner_node::log::log_gaps(r)?;
    if gaps.is_empty() {
        println!("1 kHz channels: none");
    }
    for line in learner_node::log::gaps::describe(&gaps) {
        println!("1 kHz {line}");
    }
    Ok(())
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Cmd::Log(cmd) => run_log(cmd),
        Cmd::Collect(a) => run_collect(a),
        Cmd::Dataset(c) => run_dataset(c),
        Cmd::Policy(c) => run_policy(c),
        Cmd::Repr(c) => run_repr(c),
        Cmd::Experiment { config, out, only } => {
            use learner::experiment::{ExperimentConfig, RunOptions, run};
            let cfg = ExperimentConfig::from_file(&config)?;
            let out = out.unwrap_or_else(|| {
                let stem = config
                    .file_stem()
                    .map_or("experiment".into(), |s| s.to_string_lossy().into_owned());
                PathBuf::from("runs/experiments").join(stem)
            });
            let rows = run(
                &cfg,
                &out,
                &RunOptions {
                    only,
                    progress: true,
                },
                &shared_mem_schema::process::termination_requested,
            )?;
            print!(
                "{}",
                std::fs::read_to_string(out.join("results.md")).unwrap_or_default()
            );
            println!("{} results in {}", rows.len(), out.display());
            Ok(())
        }
        Cmd::Run(a) => {
            let policy = match &a.episodes.policy {
                Some(p) => Some(learner::rl::export::load_for_node(p, a.episodes.last)?),
                None => None,
            };
            learner_node::cli::run(a, policy)
        }
        Cmd::Stack(mut a) => {
            // The node the stack starts reads deployed policies only: a
            // training checkpoint is converted into the run's log directory
            // first (a record of what ran).
            if let Some(p) = a.episodes.policy.take() {
                let dir = a.episodes.log_dir.join("policy");
                let file = learner::rl::export::file_for_node(&p, a.episodes.last, &dir)?;
                if file != p {
                    eprintln!("learner: {} converted into {}", p.display(), file.display());
                }
                a.episodes.policy = Some(file);
                a.episodes.last = false;
            }
            learner_node::cli::stack(a)
        }
    }
}
