//! The self-supervised multimodal representation (paper, "Multi-Modal
//! Representation Model" and "Baseline Representation Models"), written
//! with burn: the same code runs on the CPU (`flex`) and, built with the
//! `vulkan` (or `cuda`) feature, on a GPU.
//!
//! - [`config`]: what a model is (kind, latent size, modalities, loss
//!   weights); one TOML file per model under `configs/repr/`.
//! - [`inputs`]: samples → normalised arrays (no tensors).
//! - [`encoders`], [`fusion`], [`decoders`], [`net`]: the network.
//! - [`init`]: initial weights from our own seeded generator.
//! - [`losses`]: the losses.
//! - [`encoder`]: the inference API the live node and the RL environment
//!   use (a trained model's z means for a batch of observations); on the
//!   CPU it runs [`fast`], a copy of the encoders' arithmetic outside burn.
//!
//! The training operations whose burn compositions were slow on the CPU
//! (the convolutions, the leaky ReLU, the losses' elementwise parts, the
//! upsampling, the channel concatenation) are the crate `learner_kernels`'
//! (`learner/kernels`): the network's code calls its operations.
//!
//! Training loops, checkpoints and evaluation live in [`crate::train`];
//! nothing here reads files except the exported model's loader.

pub mod config;
pub mod decoders;
pub mod encoders;
pub mod fast;
pub mod fusion;
pub mod inference;
pub mod init;
pub mod inputs;
pub mod losses;
pub mod named;
pub mod net;

pub use config::{EeTarget, LossWeights, Modalities, ModelConfig, ModelKind};
pub use inference::Encoder;
pub use inputs::{InputArrays, LabelArrays, Normaliser, ObservationRef};
pub use net::{InputTensors, Outputs, ReprNet};
