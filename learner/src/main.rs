//! `learner`: the training toolkit's command line, and the node's `run` and
//! `stack` (learner-node's, with training checkpoints converted). It parses
//! and dispatches; each command lives in [`learner::cli`].

use anyhow::Result;
use clap::{Parser, Subcommand};
use learner::cli;
use learner_node::cli::{RunArgs, StackArgs};
use shared_mem_schema::process::install_termination_handler;

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
    Collect(cli::collect::CollectArgs),
    /// MCAP log tools: summary, integrity check, crash recovery.
    #[command(subcommand)]
    Log(cli::log::LogCmd),
    /// The self-supervised dataset: build from logs, inspect.
    #[command(subcommand)]
    Dataset(cli::dataset::DatasetCmd),
    /// Reinforcement learning on the fast path: train a policy with TRPO
    /// or PPO, distil one by DAgger, evaluate or export a checkpoint
    /// (docs/rl.md).
    #[command(subcommand)]
    Policy(cli::policy::PolicyCmd),
    /// The multimodal representation: train a model from a dataset,
    /// evaluate it on its test split (docs/representation.md).
    #[command(subcommand)]
    Repr(cli::repr::ReprCmd),
    /// The paper's ablations end to end: dataset → representation →
    /// policy → evaluation per variant, a results table and charts next to
    /// the paper's numbers (docs/experiments.md). Resumes where it stopped.
    Experiment(cli::ExperimentArgs),
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

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Cmd::Run(a) => cli::run_node(a),
        Cmd::Stack(a) => cli::stack(a),
        Cmd::Collect(a) => cli::collect::run(a),
        Cmd::Log(c) => cli::log::run(c),
        Cmd::Dataset(c) => cli::dataset::run(c),
        Cmd::Policy(c) => cli::policy::run(c),
        Cmd::Repr(c) => cli::repr::run(c),
        Cmd::Experiment(a) => cli::experiment(a),
    }
}
