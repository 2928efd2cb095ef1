//! meta.json (block index, episodes) and stats.json (normalisation
//! constants, label ratios).

use super::*;
use hw_sim::PegShape;
use learner_node::mix::EpisodePolicy;
use serde::{Deserialize, Serialize};

/// Where a block is in its shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockIndex {
    /// Byte offset.
    pub offset: u64,
    /// Compressed length.
    pub length: u64,
    /// Samples in it.
    pub samples: u32,
    /// Dataset-wide id of its first sample.
    pub first_id: u64,
    /// CRC-32 of its compressed bytes as stored (zstd frames carry no
    /// checksum of their own here, and a flipped bit in a literal would
    /// decode silently).
    pub crc32: u32,
}

/// An episode's samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Dataset-wide number.
    pub episode: u32,
    /// The log it came from.
    pub source: String,
    /// Peg.
    pub peg: PegShape,
    /// Policy that collected it.
    pub policy: EpisodePolicy,
    /// Id of its first sample (its samples are consecutive).
    pub first_id: u64,
    /// Samples.
    pub samples: u64,
}

/// meta.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Wrench readings per sample.
    pub wrench_window: usize,
    /// Samples.
    pub samples: u64,
    /// Shard files and their blocks.
    pub shards: Vec<(String, Vec<BlockIndex>)>,
    /// Episodes.
    pub episodes: Vec<EpisodeInfo>,
    /// Logs skipped, with the reason.
    pub skipped: Vec<(String, String)>,
    /// How the labels were made.
    pub build: BuildConfig,
    /// The camera every episode was recorded with (absent from datasets
    /// built before it was kept). A model trained on these images is only
    /// valid for this camera.
    #[serde(default)]
    pub camera: Option<shared_mem_schema::CameraCalibration>,
}

/// Running mean and variance (Welford), per component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Moments {
    /// Count.
    pub n: u64,
    /// Mean.
    pub mean: Vec<f64>,
    m2: Vec<f64>,
    /// Standard deviation (filled by [`Moments::finish`]).
    pub std: Vec<f64>,
}

impl Moments {
    pub(super) fn new(dim: usize) -> Self {
        Self {
            n: 0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
            std: vec![0.0; dim],
        }
    }

    pub(super) fn add(&mut self, x: &[f32]) {
        self.n += 1;
        for (k, &v) in x.iter().enumerate() {
            let d = v as f64 - self.mean[k];
            self.mean[k] += d / self.n as f64;
            self.m2[k] += d * (v as f64 - self.mean[k]);
        }
    }

    pub(super) fn finish(&mut self) {
        let n = self.n.max(2) as f64 - 1.0;
        self.std = self.m2.iter().map(|m| (m / n).sqrt().max(1e-6)).collect();
    }
}

/// stats.json: normalisation constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Wrench components (fx, fy, fz, tx, ty, tz).
    pub wrench: Moments,
    /// Proprioception.
    pub proprio: Moments,
    /// Actions.
    pub action: Moments,
    /// Depth of pixels with a return, m.
    pub depth: Moments,
    /// RGB channels, 0..255.
    pub rgb: Moments,
    /// Next position minus current position, m.
    pub ee_delta: Moments,
    /// Share of samples in contact at the next step.
    pub contact_next_ratio: f64,
    /// Share of flow-mask pixels.
    pub mask_ratio: f64,
    /// Samples by policy, stage reached, contact and motion (absent from
    /// datasets built before it existed: all zero).
    #[serde(default)]
    pub balance: super::Balance,
}

pub(super) fn stats_new() -> Stats {
    Stats {
        wrench: Moments::new(6),
        proprio: Moments::new(PROPRIO),
        action: Moments::new(4),
        depth: Moments::new(1),
        rgb: Moments::new(3),
        ee_delta: Moments::new(3),
        contact_next_ratio: 0.0,
        mask_ratio: 0.0,
        balance: Default::default(),
    }
}
