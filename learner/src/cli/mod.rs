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
}

/// Runs `learner experiment`: every variant that is not done yet, then
/// prints the results table.
pub fn experiment(a: ExperimentArgs) -> Result<()> {
    use crate::experiment::{ExperimentConfig, RunOptions, run};
    let cfg = ExperimentConfig::from_file(&a.config)?;
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

/// `learner run`: the node's, taking a training checkpoint as well as a
/// deployed policy.
pub fn run_node(a: RunArgs) -> Result<()> {
    let policy = match &a.episodes.policy {
        Some(p) => Some(crate::rl::export::load_for_node(p, a.episodes.last)?),
        None => None,
    };
    learner_node::cli::run(a, policy)
}

/// `learner stack`: the node's, a training checkpoint converted into the
/// run's log directory first (the node the stack starts reads deployed
/// policies only; the converted file is a record of what ran).
pub fn stack(mut a: StackArgs) -> Result<()> {
    if let Some(p) = a.episodes.policy.take() {
        let dir = a.episodes.log_dir.join("policy");
        let file = crate::rl::export::file_for_node(&p, a.episodes.last, &dir)?;
        if file != p {
            eprintln!("learner: {} converted into {}", p.display(), file.display());
        }
        a.episodes.policy = Some(file);
        a.episodes.last = false;
    }
    learner_node::cli::stack(a)
}
