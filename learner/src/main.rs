//! `learner`: the policy node and the stack's command-line interface.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use hw_sim::{PegShape, WorldConfig};
use learner::live::{self, LiveConfig};
use learner::stack::{self, StackConfig};
use shared_mem_schema::process::install_termination_handler;
use std::path::PathBuf;

/// Vision-and-touch learner: live policy node and tools.
#[derive(Debug, Parser)]
#[command(name = "learner", version)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, clap::Args)]
struct EpisodeArgs {
    /// Episodes to run.
    #[arg(long, default_value_t = 3)]
    episodes: u32,
    /// Peg: square, triangle, semicircle or hexagon.
    #[arg(long, default_value = "square")]
    peg: String,
    /// Seed of the first episode.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// World configuration (TOML) sent with every reset; `--peg` overrides
    /// its peg.
    #[arg(long)]
    world: Option<PathBuf>,
    /// Episode time limit, s.
    #[arg(long, default_value_t = 20.0)]
    episode_timeout_s: f64,
    /// Where logs go.
    #[arg(long, default_value = "logs")]
    log_dir: PathBuf,
    /// Service namespace.
    #[arg(long, default_value = shared_mem_schema::DEFAULT_NAMESPACE)]
    namespace: String,
    /// Deterministic lockstep run.
    #[arg(long)]
    lockstep: bool,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// The live policy node: heuristic insertion episodes against a running
    /// hw-sim and rt-controller, logged to MCAP.
    Run(EpisodeArgs),
    /// The whole stack: starts hw-sim, rt-controller and `learner run` as
    /// separate processes, runs the episodes, stops everything.
    Stack {
        #[command(flatten)]
        episodes: EpisodeArgs,
        /// rt-controller configuration (TOML).
        #[arg(long)]
        controller_config: Option<PathBuf>,
    },
    /// MCAP log tools: summary, integrity check, crash recovery.
    #[command(subcommand)]
    Log(LogCmd),
}

#[derive(Debug, Subcommand)]
enum LogCmd {
    /// Channels, message counts and time span of a complete log.
    Info {
        /// The log.
        file: PathBuf,
    },
    /// Reads every record and chunk; reports the first damage by byte offset.
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

fn parse_peg(name: &str) -> Result<PegShape> {
    PegShape::ALL
        .into_iter()
        .find(|p| p.name() == name)
        .with_context(|| {
            format!("--peg {name:?}: expected one of square, triangle, semicircle, hexagon")
        })
}

fn world_config(a: &EpisodeArgs) -> Result<WorldConfig> {
    let mut w = match &a.world {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the world configuration {}", p.display()))?;
            WorldConfig::from_toml(&text).with_context(|| format!("in {}", p.display()))?
        }
        None => WorldConfig::default(),
    };
    w.task.enabled = true;
    w.task.peg = parse_peg(&a.peg)?;
    Ok(w)
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
    use learner::log;
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
            Ok(())
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
            Ok(())
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
            Ok(())
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Cmd::Log(cmd) => run_log(cmd),
        Cmd::Run(a) => {
            let cfg = LiveConfig {
                namespace: a.namespace.clone(),
                episodes: a.episodes,
                seed: a.seed,
                world: world_config(&a)?,
                episode_timeout_s: a.episode_timeout_s,
                log_dir: a.log_dir.clone(),
                lockstep: a.lockstep,
                settle_s: 0.3,
            };
            let outcomes = live::run(&cfg, |o| {
                println!(
                    "episode {} (seed {}): {}{} after {:.2} s, {} actions; log {}",
                    o.episode,
                    o.seed,
                    o.stage,
                    if o.interrupted { " (interrupted)" } else { "" },
                    o.duration_s,
                    o.actions,
                    o.log.display()
                );
            })?;
            let done = outcomes.iter().filter(|o| o.stage == "completed").count();
            println!(
                "{done} of {} episodes completed the insertion",
                outcomes.len()
            );
            Ok(())
        }
        Cmd::Stack {
            episodes: a,
            controller_config,
        } => {
            world_config(&a)?; // fail early on a bad peg or file
            let mut run_args = vec![
                "--episodes".to_string(),
                a.episodes.to_string(),
                "--peg".into(),
                a.peg.clone(),
                "--seed".into(),
                a.seed.to_string(),
                "--episode-timeout-s".into(),
                a.episode_timeout_s.to_string(),
            ];
            if let Some(w) = &a.world {
                run_args.push("--world".into());
                run_args.push(w.display().to_string());
            }
            let status = stack::run(&StackConfig {
                namespace: a.namespace.clone(),
                lockstep: a.lockstep,
                run_args,
                log_dir: a.log_dir.clone(),
                controller_config,
            })?;
            println!("stack stopped; process logs in {}", a.log_dir.display());
            if !status.success() {
                anyhow::bail!("the policy node failed ({status})");
            }
            Ok(())
        }
    }
}
