//! The training configuration file: `[model]` ([`ModelConfig`]), `[loss]`
//! ([`LossWeights`]) and `[train]` ([`TrainSettings`]). Every field has a
//! default; the files under `configs/repr/` name what differs from the Full
//! Model.

use super::{Result, TrainError};
use crate::models::{LossWeights, ModelConfig, ModelKind};
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::{FieldError, at_least, check, positive, read_toml, within};
use std::path::Path;

/// Optimiser, data and schedule settings. Adam's defaults are the paper's
/// (appendix, "Hyperparameters for Representation Learning"): learning rate
/// 1e-4, β₁ 0.5, β₂ 0.999, batch 64, and 20 epochs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainSettings {
    /// Adam's learning rate.
    pub lr: f64,
    /// Adam's β₁.
    pub beta1: f64,
    /// Adam's β₂.
    pub beta2: f64,
    /// Samples per batch.
    pub batch: usize,
    /// Passes over the training split.
    pub epochs: u32,
    /// Seed of the initial weights, the split, the shuffles and the noise.
    pub seed: u64,
    /// Share of each peg's episodes held out for testing.
    pub test_fraction: f64,
    /// Share of samples given another moment's haptics (the pairing
    /// negatives); 0 for models without the pairing loss.
    pub negative_fraction: f64,
    /// Blocks of 32 samples the loader shuffles among.
    pub shuffle_blocks: usize,
    /// A checkpoint every this many batches (and at every epoch's end).
    pub checkpoint_every: u64,
    /// At most this many training batches per epoch (0: all): a shorter
    /// run on a large dataset.
    pub max_batches_per_epoch: u64,
    /// At most this many test batches per evaluation (0: all).
    pub max_test_batches: u64,
}

impl Default for TrainSettings {
    fn default() -> Self {
        Self {
            lr: 1e-4,
            beta1: 0.5,
            beta2: 0.999,
            batch: 64,
            epochs: 20,
            seed: 0,
            test_fraction: 0.2,
            negative_fraction: 0.5,
            shuffle_blocks: 16,
            checkpoint_every: 100,
            max_batches_per_epoch: 0,
            max_test_batches: 0,
        }
    }
}

/// A whole training configuration file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReprTrainConfig {
    /// The model.
    pub model: ModelConfig,
    /// Loss weights.
    pub loss: LossWeights,
    /// Optimiser and schedule.
    pub train: TrainSettings,
}

/// Where the tensors live.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    /// burn's `flex` CPU backend.
    #[default]
    Cpu,
    /// burn's CUDA backend, GPU 0 (a build with the `cuda` feature).
    Cuda,
    /// burn's Vulkan backend (wgpu, SPIR-V kernels) on wgpu's default
    /// adapter, a high-power GPU first (`CUBECL_WGPU_DEFAULT_DEVICE`
    /// overrides); a build with the `vulkan` feature.
    Vulkan,
}

impl DeviceKind {
    /// The burn device, with automatic differentiation when `autodiff`.
    pub fn device(self, autodiff: bool) -> std::result::Result<burn::prelude::Device, String> {
        let d = match self {
            DeviceKind::Cpu => burn::prelude::Device::flex(),
            #[cfg(feature = "cuda")]
            DeviceKind::Cuda => burn::prelude::Device::cuda(0),
            #[cfg(not(feature = "cuda"))]
            DeviceKind::Cuda => {
                return Err(
                    "this learner was built without CUDA: rebuild with `--features cuda`".into(),
                );
            }
            #[cfg(feature = "vulkan")]
            DeviceKind::Vulkan => {
                burn::prelude::Device::vulkan(burn::tensor::DeviceKind::DefaultDevice)
            }
            #[cfg(not(feature = "vulkan"))]
            DeviceKind::Vulkan => {
                return Err(
                    "this learner was built without Vulkan: rebuild with `--features vulkan`"
                        .into(),
                );
            }
        };
        Ok(if autodiff { d.autodiff() } else { d })
    }
}

impl ReprTrainConfig {
    /// Reads and validates a configuration file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let cfg: Self = read_toml(path)?;
        cfg.validate().map_err(|e| TrainError::BadFile {
            path: path.to_path_buf(),
            what: e.to_string(),
        })?;
        Ok(cfg)
    }

    /// Checks every field, naming the one at fault.
    pub fn validate(&self) -> std::result::Result<(), FieldError> {
        self.model.validate()?;
        self.loss.validate()?;
        let t = &self.train;
        positive("train.lr", t.lr)?;
        for (name, b) in [("train.beta1", t.beta1), ("train.beta2", t.beta2)] {
            check(name, b, b > 0.0 && b < 1.0, "must be in (0, 1)")?;
        }
        within("train.batch", t.batch, 1..=4096)?;
        within("train.epochs", t.epochs, 1..=10_000)?;
        let f = t.test_fraction;
        check(
            "train.test_fraction",
            f,
            (0.0..1.0).contains(&f),
            "must be in [0, 1)",
        )?;
        let f = t.negative_fraction;
        check(
            "train.negative_fraction",
            f,
            (0.0..=1.0).contains(&f),
            "must be in [0, 1]",
        )?;
        within("train.shuffle_blocks", t.shuffle_blocks, 1..=1024)?;
        at_least("train.checkpoint_every", t.checkpoint_every, 1)
    }

    /// Whether the model learns time alignment: it needs the pairing loss,
    /// the haptics (a negative is another moment's wrench window, which a
    /// model without haptics cannot see) and a predictive kind.
    pub fn learns_pairing(&self) -> bool {
        self.model.kind != ModelKind::Reconstruction
            && self.model.modalities.haptics
            && self.loss.pairing > 0.0
            && self.train.negative_fraction > 0.0
    }

    /// The share of pairing negatives the loader draws: none for a model
    /// that does not learn pairing (they would only corrupt its inputs).
    pub fn negatives(&self) -> f64 {
        if self.learns_pairing() {
            self.train.negative_fraction
        } else {
            0.0
        }
    }

    /// The loss weights as trained: no pairing term where
    /// [`Self::learns_pairing`] is false.
    pub fn loss_weights(&self) -> LossWeights {
        let mut w = self.loss;
        if !self.learns_pairing() {
            w.pairing = 0.0;
        }
        w
    }
}
