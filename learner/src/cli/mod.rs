//! The `learner` command line's commands: their arguments (clap) and what
//! each does. The binary (`src/main.rs`) only parses and dispatches; the
//! node's own commands (`run`, `stack`) are learner-node's
//! ([`learner_node::cli`]), here with training checkpoints converted into
//! the deployed format first.

pub mod collect;
pub mod dataset;
pub mod log;
pub mod policy;
pub mod repr;

use anyhow::Result;
use learner_node::cli::{RunArgs, StackArgs};
use std::path::PathBuf;

/// `learner experiment`'s arguments.
#[derive(Debug, clap::Args)]
pub struct ExperimentArgs {
    /// The experiment (TOML; see configs/experiments/).
    #[arg(long)]
    pub config: PathBuf,
    /// Its directory (default: runs/experiments/<config's file stem>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run only this variant (repeatable).
    #[arg(long)]
    pub only: Vec<String>,
    /// Changes one setting of the experiment's file by its dotted path,
    /// e.g. `--set policy.dagger_rounds=4 --set eval.episodes=10`
    /// (repeatable). The stages' own resume checks still hold: a
    /// distillation resumed under other settings is refused.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

/// Runs `learner experiment`: every variant that is not done yet, then
/// prints the results table.
pub fn experiment(a: ExperimentArgs) -> Result<()> {
    use crate::experiment::{ExperimentConfig, RunOptions, run};
    let cfg = ExperimentConfig::from_file_with(&a.config, &a.set)?;
    let out = a.out.unwrap_or_else(|| {
        let stem = a
            .config
            .file_stem()
            .map_or("experiment".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("runs/experiments").join(stem)
    });
    let rows = run(
        &cfg,
        &out,
        &RunOptions {
            only: a.only,
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

/// What a training checkpoint gives a live run that did not say otherwise:
/// the world it was trained in (`--world`, written as `dir/world.toml`:
/// its box ranges, camera, noise and perturbations, and its peg unless
/// `--peg`), its episode length (`--episode-timeout-s`) and, for the stack,
/// its controller (`--controller-config`, written as
/// `dir/rt-controller.toml`; `learner run` acts through whichever daemon
/// is running). A policy run in another world than its own meets a task
/// it never saw; a representation's camera would even be refused.
fn training_settings(
    checkpoint: &std::path::Path,
    a: &mut learner_node::cli::EpisodeArgs,
    controller: Option<&mut Option<PathBuf>>,
    dir: &std::path::Path,
) -> Result<()> {
    use anyhow::Context;
    let c = crate::rl::run::read_checkpoint(checkpoint)?;
    let env = &c.config.env;
    let mut taken = Vec::new();
    let mut flags = vec!["--world", "--peg", "--episode-timeout-s"];
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    if a.world.is_none() {
        let path = dir.join("world.toml");
        let text = toml::to_string(&env.world).context("printing the checkpoint's world")?;
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        taken.push(format!("its world ({})", path.display()));
        a.world = Some(path);
    }
    if a.episode_timeout_s.is_none() {
        // From whole nanoseconds: 500 steps print as 25 s, not 25.000000000000004.
        let ns = u64::from(env.max_steps) * shared_mem_schema::rates::ACTION_PERIOD_NS;
        let s = ns as f64 / 1e9;
        taken.push(format!("its episode length ({s} s)"));
        a.episode_timeout_s = Some(s);
    }
    if let Some(slot) = controller {
        flags.push("--controller-config");
        if slot.is_none() {
            let daemon = rt_controller_daemon_config(&env.world.robot, &env.controller)?;
            let path = dir.join("rt-controller.toml");
            std::fs::write(&path, daemon).with_context(|| format!("writing {}", path.display()))?;
            taken.push(format!("its controller ({})", path.display()));
            *slot = Some(path);
        }
    }
    if !taken.is_empty() {
        eprintln!(
            "learner: from the training run of {}: {} (give {} to run it otherwise)",
            checkpoint.display(),
            taken.join(", "),
            flags.join(", ")
        );
    }
    Ok(())
}

/// The rt-controller daemon's configuration (TOML) with `robot` and the
/// control law `controller`, every other setting the daemon's default (what
/// the stack runs without `--controller-config`).
fn rt_controller_daemon_config(
    robot: &str,
    controller: &rt_controller::ControllerConfig,
) -> Result<String> {
    let daemon = rt_controller_daemon::config::DaemonConfig {
        robot: robot.to_string(),
        controller: controller.clone(),
        ..Default::default()
    };
    Ok(toml::to_string(&daemon)?)
}

/// `learner run`: the node's, taking a training checkpoint as well as a
/// deployed policy (a checkpoint's world and episode length unless given).
pub fn run_node(mut a: RunArgs) -> Result<()> {
    // Loaded first: a checkpoint the node cannot act with is refused
    // before anything is written.
    let policy = match &a.episodes.policy {
        Some(p) => Some(crate::rl::export::load_for_node(p, a.episodes.last)?),
        None => None,
    };
    if let Some(p) = a.episodes.policy.clone()
        && a.calibration.hole_pos.is_none()
        && !crate::rl::export::is_deployed(&p)?
    {
        let dir = a.episodes.log_dir.join("policy");
        training_settings(&p, &mut a.episodes, None, &dir)?;
    }
    learner_node::cli::run(a, policy)
}

/// `learner stack`: the node's, a training checkpoint converted into the
/// run's log directory first (the node the stack starts reads deployed
/// policies only; the converted file is a record of what ran), with the
/// checkpoint's world, episode length and controller unless given.
pub fn stack(mut a: StackArgs) -> Result<()> {
    if let Some(p) = a.episodes.policy.take() {
        let dir = a.episodes.log_dir.join("policy");
        // Converted first: a checkpoint the node cannot act with is
        // refused before the settings are written.
        let file = crate::rl::export::file_for_node(&p, a.episodes.last, &dir)?;
        if file != p {
            eprintln!("learner: {} converted into {}", p.display(), file.display());
            if a.robot == learner_node::cli::RobotArg::Sim && a.calibration.hole_pos.is_none() {
                training_settings(&p, &mut a.episodes, Some(&mut a.controller_config), &dir)?;
            }
        }
        a.episodes.policy = Some(file);
        a.episodes.last = false;
    }
    learner_node::cli::stack(a)
}
