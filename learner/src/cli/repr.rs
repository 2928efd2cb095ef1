//! `learner repr`: train and evaluate the multimodal representation
//! (docs/representation.md).

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// `learner repr`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum ReprCmd {
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
        #[arg(long, value_enum, default_value_t = crate::train::DeviceKind::Cpu)]
        device: crate::train::DeviceKind,
    },
    /// Writes a trained representation for other tools:
    /// OUT/representation.safetensors (the PyTorch twin's parameter names)
    /// and OUT/representation-spec.json (architecture, input
    /// normalisation; docs/representation.md, "Loading it in PyTorch").
    Export {
        /// The exported model (a training run's `model/`).
        #[arg(long)]
        model: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
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
        #[arg(long, value_enum, default_value_t = crate::train::DeviceKind::Cpu)]
        device: crate::train::DeviceKind,
        /// Samples in the PCA picture.
        #[arg(long, default_value_t = 1500)]
        pca_samples: usize,
        /// Images in the flow picture.
        #[arg(long, default_value_t = 4)]
        flow_images: usize,
    },
}

/// Runs one `learner repr` subcommand.
pub fn run(cmd: ReprCmd) -> Result<()> {
    use crate::train::{self, ReprTrainConfig, TrainOptions};
    match cmd {
        ReprCmd::Train {
            config,
            data,
            out,
            resume,
            epochs,
            device,
        } => {
            let mut cfg = ReprTrainConfig::from_file(&config)?;
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
        ReprCmd::Export { model, out } => {
            let [st, spec] = crate::interop::repr_export::export_model_dir(&model, &out)?;
            println!("{} and {} written", st.display(), spec.display());
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
