//! `learner policy`: train, distil, export and evaluate policies
//! (docs/rl.md).

use anyhow::{Context, Result};
use clap::Subcommand;
use std::path::PathBuf;

/// `learner policy`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum PolicyCmd {
    /// Writes a checkpoint's policy in the node's deployed format: DIR/policy.json
    /// and, for a representation policy, DIR/encoder.bin (the robot PC's
    /// `policy-node run --policy DIR/policy.json` reads them without the
    /// training stack); and, for other tools, DIR/policy.safetensors with
    /// DIR/policy-spec.json (docs/rl.md, "The policy for other tools"), and
    /// for a representation policy DIR/representation.safetensors with its
    /// spec (`learner repr export`'s).
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
    /// Copies a checkpoint and the representation it observes through into
    /// DIR (DIR/checkpoint.json naming DIR/model/, and the run's run.json),
    /// a directory that works wherever it is put: how `artifacts/` is made
    /// (docs/rl.md, "Packaging a policy"). DIR must be absent or empty.
    Package {
        /// The training run's checkpoint.json.
        #[arg(long)]
        checkpoint: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Trains with TRPO or PPO (`policy.algorithm`); writes
    /// checkpoint.json, curve.csv, return.png and outcomes.png into `--out`.
    Train {
        /// Training configuration (TOML; every field defaulted, see
        /// learner::rl::run::TrainConfig).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Overrides one field of the configuration by its dotted path,
        /// e.g. `--set seed=2 --set env.world.task.peg=triangle`
        /// (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Run directory.
        #[arg(long, default_value = "runs/policy")]
        out: PathBuf,
        /// Continue the run in `--out` from its checkpoint.
        #[arg(long)]
        resume: bool,
    },
    /// DAgger: a student policy on one observation (the representation)
    /// learns the actions of a trained teacher on another (the ground
    /// truth); writes a checkpoint that `policy eval` and `init_from` take
    /// (docs/rl.md, "Distillation").
    Distill {
        /// Distillation configuration (TOML, see configs/distill/).
        #[arg(long)]
        config: PathBuf,
        /// Changes one setting of the configuration by its dotted path,
        /// e.g. `--set student.seed=2` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Run directory.
        #[arg(long, default_value = "runs/distill")]
        out: PathBuf,
        /// Continue the run in `--out` from its last finished round.
        #[arg(long)]
        resume: bool,
    },
    /// Runs a checkpoint's policy (its mean action, or with --sample an
    /// action drawn from its Gaussian) for N episodes: the
    /// four outcome categories and the normalised episode reward. The
    /// world is the checkpoint's training world; `--set` changes any of it
    /// (another peg, pushes, noise, the box's yaw, a hole error: docs/rl.md,
    /// "Evaluation").
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
        /// Overrides one field of the checkpoint's training configuration
        /// by its dotted path before evaluating, e.g. `--set
        /// env.world.task.peg=triangle`, `--set
        /// env.world.perturbations.random_pushes=1` (repeatable).
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
        /// Draw each action from the policy's Gaussian, as in training
        /// (seeded by the episode), instead of taking its mean.
        #[arg(long)]
        sample: bool,
    },
}

/// Runs one `learner policy` subcommand.
pub fn run(cmd: PolicyCmd) -> Result<()> {
    use crate::rl::reward::Outcome;
    use crate::rl::run;
    let stop = &shared_mem_schema::process::termination_requested;
    match cmd {
        PolicyCmd::Train {
            config,
            sets,
            out,
            resume,
        } => {
            let cfg: run::TrainConfig =
                crate::settings::read_with_overrides(config.as_deref(), &sets)?;
            let c = run::train(cfg, &out, resume, stop)?;
            println!(
                "{} updates, {} environment steps; checkpoint {}",
                c.state.iteration,
                c.state.env_steps,
                run::checkpoint_path(&out).display()
            );
        }
        PolicyCmd::Distill {
            config,
            sets,
            out,
            resume,
        } => {
            let cfg: crate::rl::distill::DistillConfig =
                crate::settings::read_with_overrides(Some(&config), &sets)?;
            let c = crate::rl::distill::distill(cfg, &out, resume, stop)?;
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
            let d = crate::rl::export::from_checkpoint(&checkpoint, last)?;
            let path = d.write(&out)?;
            println!("{} written ({})", path.display(), d.policy.source);
            let [st, spec] =
                crate::rl::export::write_safetensors(&d.policy, &out).with_context(|| {
                    format!("writing the safetensors export into {}", out.display())
                })?;
            println!("{} and {} written", st.display(), spec.display());
            // A representation policy's encoder, for other tools as well.
            if let crate::rl::ObservationKind::Representation(model) =
                run::read_checkpoint(&checkpoint)?.config.observation
            {
                let [st, spec] = crate::interop::repr_export::export_model_dir(&model, &out)?;
                println!("{} and {} written", st.display(), spec.display());
            }
        }
        PolicyCmd::Package { checkpoint, out } => {
            let path = crate::rl::package::package(&checkpoint, &out)?;
            println!("{} written", path.display());
        }
        PolicyCmd::Eval {
            checkpoint,
            episodes,
            seed,
            sets,
            json,
            last,
            sample,
        } => {
            anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
            let c = run::read_checkpoint(&checkpoint)?;
            let trained_on = c.config.env.world.task.peg;
            let cfg = crate::settings::with_overrides(&c.config, &sets)?;
            anyhow::ensure!(
                c.config.observation.same_inputs(&cfg.observation),
                "--set observation: the policy was trained on {:?}, which does not take {:?}'s \
                 inputs",
                c.config.observation,
                cfg.observation
            );
            let chosen = c.chosen_policy(last);
            println!("evaluating {chosen}");
            let act = if sample {
                run::Act::Sample
            } else {
                run::Act::Mean
            };
            let r = run::evaluate_acting(chosen.policy, &cfg, episodes, seed, act, stop)?;
            println!(
                "{} episodes ({} peg, trained on {}, {} action): normalised reward {:.3}",
                r.episodes,
                cfg.env.world.task.peg.name(),
                trained_on.name(),
                if sample { "sampled" } else { "mean" },
                r.mean_normalised
            );
            for o in Outcome::ALL.into_iter().rev() {
                println!("  {:<20} {:5.1}%", o.name(), 100.0 * r.outcomes[o.index()]);
            }
            let count = |c: u32| r.fault_codes.iter().filter(|&&x| x == c).count();
            println!(
                "  ended by a controller fault: {} of {} (force overload {}, moment overload {})",
                r.faulted(),
                r.episodes,
                count(4),
                count(5)
            );
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&r)?;
                std::fs::write(&path, text)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
    }
    Ok(())
}
