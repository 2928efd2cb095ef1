//! # learner
//!
//! The training toolkit, on the training machine: data collection
//! ([`collect`]), the self-supervised dataset and its labels ([`dataset`],
//! [`labels`]), the fast-path environment ([`fast_env`]), charts for people
//! ([`plot`]), the RL environment with TRPO and PPO, distillation and the
//! conversion of a trained policy into the node's deployed format ([`rl`]),
//! the multimodal representation with its baselines and ablations
//! ([`models`]) and its training and evaluation ([`train`]), the paper's
//! experiments end to end ([`experiment`]), what a run writes for other
//! tools and later readers ([`interop`]: TensorBoard, provenance), and the
//! `learner` command line;
//! see docs/architecture.md.
//!
//! What the robot PC runs (observations, the scripted and deployed
//! policies, the representation's inference, MCAP logging, the live node,
//! the stack's orchestrator) is the `learner-node` crate, which this one
//! builds on; nothing there may depend on this crate.

pub mod cli;
pub mod collect;
pub mod dataset;
pub mod experiment;
pub mod fast_env;
pub mod interop;
pub mod labels;
pub mod models;
pub mod plot;
pub mod rl;
pub mod settings;
pub mod train;

/// Writes `bytes` to `path` through a sibling `<name>.tmp` and a rename, so
/// that a crash leaves the old file or the new one, never half of one.
pub(crate) fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}
