//! `learner dataset`: build the self-supervised dataset from logs,
//! inspect one.

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// `learner dataset`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum DatasetCmd {
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
    /// Imports the authors' published HDF5 episodes (one file per
    /// episode, their multimodal_representation layout) into a dataset,
    /// labelled as their loader labels them (docs/data.md, "Importing the
    /// authors' data").
    Import {
        /// HDF5 files (.h5, .hdf5) or directories of them.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Output directory.
        #[arg(long, default_value = "data/dataset-imported")]
        out: PathBuf,
        /// The peg of every episode (their real-robot data: the triangle).
        #[arg(long, value_enum, default_value_t = hw_sim::PegShape::Triangle)]
        peg: hw_sim::PegShape,
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

/// Runs one `learner dataset` subcommand.
pub fn run(cmd: DatasetCmd) -> Result<()> {
    use crate::dataset::{self, BuildConfig, Dataset};
    match cmd {
        DatasetCmd::Import { inputs, out, peg } => {
            let files = dataset::find_hdf5(&inputs)?;
            anyhow::ensure!(!files.is_empty(), "no .h5 or .hdf5 files in {inputs:?}");
            let progress = learner_node::progress::Progress::new(files.len() as u64, "files");
            let mut done = 0;
            let t = std::time::Instant::now();
            let meta = dataset::import(&files, &out, peg, &BuildConfig::default(), |_, _| {
                done += 1;
                progress.update(done, String::new());
            })?;
            progress.finish();
            println!(
                "imported {} samples from {} files in {:.1} s into {}",
                meta.samples,
                meta.episodes.len(),
                t.elapsed().as_secs_f64(),
                out.display()
            );
            Ok(())
        }
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
            let workers = workers.unwrap_or_else(crate::rl::vec::all_cores);
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
