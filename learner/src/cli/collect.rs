//! `learner collect`: episodes for the self-supervised dataset.

use anyhow::Result;
use hw_sim::{PegShape, WorldConfig};
use std::path::PathBuf;

/// `learner collect`'s arguments.
#[derive(Debug, clap::Args)]
pub struct CollectArgs {
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

/// The world file, or the default world.
fn load_world(path: Option<&PathBuf>) -> Result<WorldConfig> {
    Ok(match path {
        Some(p) => WorldConfig::from_file(p)?,
        None => WorldConfig::default(),
    })
}

/// Runs `learner collect`.
pub fn run(a: CollectArgs) -> Result<()> {
    use crate::collect::{self, CollectConfig};
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
    let workers = a.workers.unwrap_or_else(crate::rl::vec::all_cores);
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
