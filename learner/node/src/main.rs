//! `policy-node`: the live policy node (`run`) and the whole stack with it
//! (`stack`), built without the training stack. Deployed policies only; the
//! `learner` CLI takes the same arguments and also converts a training
//! checkpoint.

use anyhow::Result;
use clap::{Parser, Subcommand};
use learner_node::cli::{self, RunArgs, StackArgs};
use shared_mem_schema::process::install_termination_handler;

/// The robot PC's policy node.
#[derive(Debug, Parser)]
#[command(name = "policy-node", version)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// The live policy node: heuristic (or --policy) insertion episodes
    /// against a running hw-sim and rt-controller, logged to MCAP. With
    /// --hole-pos, against a running rt-controller alone (a robot,
    /// franky-sim): the task from the calibration, no resets.
    Run(RunArgs),
    /// The whole stack: starts hw-sim (or franky-sim), rt-controller and
    /// this node as separate processes, runs the episodes, stops everything.
    Stack(StackArgs),
}

fn run(c: Cli) -> Result<()> {
    match c.command {
        Cmd::Run(a) => {
            let policy = cli::deployed_policy(&a.episodes)?;
            cli::run(a, policy)
        }
        Cmd::Stack(a) => cli::stack(a),
    }
}

fn main() {
    install_termination_handler();
    shared_mem_schema::transport::quiet_logs();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("policy-node: error: {e:#}");
        std::process::exit(1);
    }
}
