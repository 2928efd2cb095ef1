//! Training and evaluation of the representation over the dataset loader
//! (`learner repr train|eval`): the configuration file, the split by
//! episode, the loop with checkpoints that resume, per-epoch metrics with
//! their CSV and curves, and the exported model.
//!
//! Files: `config` (the TOML file), `split` (episodes → train/test),
//! `metrics` (the appendix table's rows, CSV, curves), `checkpoint`
//! (save/resume), `run` (the loop), `eval` (`learner repr eval`).

pub mod checkpoint;
pub mod config;
pub mod eval;
pub mod metrics;
pub mod run;
pub mod split;

pub use config::{DeviceKind, ReprTrainConfig, TrainSettings};
pub use run::{TrainOptions, TrainSummary, train};
pub use split::Split;

/// What can go wrong in training or evaluation.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The dataset.
    #[error(transparent)]
    Dataset(#[from] crate::dataset::DatasetError),
    /// A file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A configuration or state file that does not parse or holds a bad
    /// value.
    #[error("{path}: {what}")]
    BadFile {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        what: String,
    },
    /// A configuration file that cannot be read or parsed.
    #[error(transparent)]
    ConfigFile(#[from] shared_mem_schema::config::ConfigFileError),
    /// The dataset does not fit the model.
    #[error("{0}")]
    Mismatch(String),
    /// A model or optimizer file burn could not read or write.
    #[error("{path}: {what}")]
    Record {
        /// The file.
        path: std::path::PathBuf,
        /// burn's message.
        what: String,
    },
    /// A chart.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// A loss that is not finite: training stops rather than write a
    /// poisoned checkpoint over the last good one.
    #[error("epoch {epoch}, batch {batch}: the loss is {value}; stopping without a checkpoint")]
    NotFinite {
        /// Epoch (1-based).
        epoch: u32,
        /// Batch within it.
        batch: u64,
        /// The loss.
        value: f64,
    },
    /// Inputs that do not fit the model.
    #[error(transparent)]
    Input(#[from] crate::models::inputs::InputError),
}

/// Result of training and evaluation.
pub type Result<T> = std::result::Result<T, TrainError>;

pub(crate) fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    }
}
