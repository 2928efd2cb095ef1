//! The self-supervised dataset: built from MCAP logs, stored as chunked
//! shards, read back by a shuffling, streaming loader. Format: docs/data.md.
//!
//! One sample per 20 Hz step that has an action: the camera frame, the last
//! 32 wrench readings, proprioception and the next action; labels: the flow
//! that action causes and its mask, contact at the next step, the next
//! end-effector position. Pairing negatives (the paper's time-shifted
//! haptics with the opposite contact state) are drawn by the loader from a
//! table of every sample's wrench window kept beside the shards.
//!
//! Files: `sample` (the sample and its encoding), `label` (log → samples),
//! `import` (the authors' HDF5 episodes → samples),
//! `meta` (meta.json, stats.json), `build` (the writer and the parallel
//! build), `reader` (an opened dataset), `loader` (shuffled batches with
//! pairing negatives), `sheet` (the contact sheet), `balance` (how the
//! samples split by stage, contact and motion), `error` (what can fail).

mod balance;
mod build;
mod episode;
mod error;
mod import;
mod loader;
mod meta;
mod reader;
mod sample;
mod sheet;

pub use balance::{Balance, MOVING_M, SampleTags, StageCounts};
pub use build::{build, find_logs};
pub use episode::{BuildConfig, EpisodeSamples, Models, episode_samples};
pub use error::{DatasetError, Result};
pub use import::{find_hdf5, import, import_file};
pub use loader::{Batch, Loader, LoaderConfig};
pub use meta::{BlockIndex, EpisodeInfo, Meta, Moments, Stats};
pub use reader::Dataset;
pub use sample::Sample;
pub use sheet::contact_sheet;

use meta::stats_new;
use reader::read_block;
use sample::sample_bytes;

/// Shard file magic (start and end).
pub const SHARD_MAGIC: &[u8; 8] = b"VTDSHRD5";
/// Dataset format version (meta.json). 2: blocks carry a CRC-32. 3:
/// proprioception is the paper's 8 values ([`learner_node::proprio`]) instead of 13
/// with a quaternion; the flow mask is the robot in motion. 4: each sample
/// carries the stage its episode had reached (a byte of the head's padding).
/// 5: the end-effector label carries the next roll beside the next position
/// (the authors' code predicts both).
pub const FORMAT_VERSION: u32 = 5;
/// Proprioception values per sample: position (3), roll (1), linear
/// velocity (3), roll rate (1) ([`learner_node::proprio::Proprio`]).
pub use learner_node::proprio::PROPRIO;
