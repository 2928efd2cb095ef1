//! # learner
//!
//! Owns everything at the policy's rate and slower. Today: MCAP logging and
//! reading ([`log`]), data collection ([`collect`]), the self-supervised
//! dataset and its labels ([`dataset`], [`labels`]), the scripted and random
//! policies ([`policy`]), the fast-path environment ([`env`]), the live
//! 20 Hz inference node ([`live`]), the process orchestrator ([`stack`]),
//! charts for people ([`plot`]), the RL environment with TRPO and PPO and
//! the trained policy's deployment ([`rl`]), the multimodal representation
//! with its baselines and ablations ([`models`]) and its training and
//! evaluation ([`train`]), the paper's experiments end to end
//! ([`experiment`]), and the command-line interface; see
//! docs/architecture.md.
//!
//! It must never sit in the 1 kHz path: the controller takes its latest
//! action without waiting for it.

pub mod calibrated;
pub mod collect;
pub mod dataset;
pub mod env;
pub mod experiment;
pub mod labels;
pub mod live;
pub mod log;
pub mod models;
pub mod plot;
pub mod policy;
pub mod progress;
pub mod proprio;
pub mod rl;
pub mod settings;
pub mod stack;
pub mod train;

/// Writes `bytes` to `path` through a sibling `<name>.tmp` and a rename, so
/// that a crash leaves the old file or the new one, never half of one.
pub(crate) fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}
