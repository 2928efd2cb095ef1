//! The representation's inference on the robot PC: a trained model's z
//! means (paper, "Policy Learning": the policy takes the mean of the learned
//! representation) from plain arrays, without burn.
//!
//! - [`inputs`]: observations → normalised input arrays.
//! - [`fast`]: the encoders' and fusion's arithmetic on the CPU
//!   ([`EncoderWeights`], [`FastEncoder`]).
//! - [`weights`]: the encoder's weights file ([`EncoderFile`]), which the
//!   training crate writes from its network.
//! - [`observer`]: the z means as a policy's observation
//!   ([`Representation`]).

pub mod fast;
pub mod inputs;
pub mod observer;
pub mod weights;

pub use fast::{EncoderWeights, FastEncoder, WeightsError};
pub use inputs::{InputArrays, InputError, Normaliser, ObservationRef};
pub use observer::{Representation, ZEncoder};
pub use weights::EncoderFile;

use serde::{Deserialize, Serialize};
use shared_mem_schema::CameraCalibration;
use std::path::Path;

/// Which sensors a model sees. A modality left out contributes no expert to
/// the product (no input to the concatenation of the deterministic model);
/// the same switch masks a sensor of a trained model at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Modalities {
    /// RGB camera image.
    pub rgb: bool,
    /// Depth image.
    pub depth: bool,
    /// The wrist F/T sensor's window (the paper's haptics).
    pub haptics: bool,
    /// End-effector pose and velocity.
    pub proprio: bool,
}

impl Default for Modalities {
    fn default() -> Self {
        Self::ALL
    }
}

impl Modalities {
    /// Every sensor.
    pub const ALL: Self = Self {
        rgb: true,
        depth: true,
        haptics: true,
        proprio: true,
    };

    /// Those of `self` that `other` also has.
    pub fn and(self, other: Self) -> Self {
        Self {
            rgb: self.rgb && other.rgb,
            depth: self.depth && other.depth,
            haptics: self.haptics && other.haptics,
            proprio: self.proprio && other.proprio,
        }
    }

    /// Whether none is on.
    pub fn none(self) -> bool {
        !(self.rgb || self.depth || self.haptics || self.proprio)
    }

    /// Names of those on, for messages.
    pub fn names(self) -> String {
        let mut v = Vec::new();
        for (on, name) in [
            (self.rgb, "rgb"),
            (self.depth, "depth"),
            (self.haptics, "haptics"),
            (self.proprio, "proprio"),
        ] {
            if on {
                v.push(name);
            }
        }
        if v.is_empty() {
            "none".into()
        } else {
            v.join("+")
        }
    }
}

/// A deployed representation: its weights file loaded, encoding on the CPU.
#[derive(Debug)]
pub struct DeployedEncoder {
    fast: FastEncoder,
    modalities: Modalities,
    normaliser: Normaliser,
    camera: Option<CameraCalibration>,
}

impl DeployedEncoder {
    /// From a weights file's contents.
    pub fn new(file: EncoderFile) -> Result<Self, WeightsError> {
        Ok(Self {
            fast: FastEncoder::new(file.weights)?,
            modalities: file.modalities,
            normaliser: file.normaliser,
            camera: file.camera,
        })
    }

    /// Reads the weights file `path` ([`weights`]).
    pub fn load(path: &Path) -> Result<Self, weights::FileError> {
        let file = EncoderFile::read(path)?;
        Self::new(file).map_err(|e| weights::FileError {
            path: path.to_path_buf(),
            kind: e.into(),
        })
    }

    /// Splits batches over at most `n` threads (the default: every core).
    pub fn with_threads(mut self, n: usize) -> Self {
        self.fast = self.fast.with_threads(n);
        self
    }
}

impl ZEncoder for DeployedEncoder {
    fn dim(&self) -> usize {
        self.fast.weights().latent_dim
    }

    fn camera(&self) -> Option<CameraCalibration> {
        self.camera
    }

    fn encode(&self, obs: &[ObservationRef<'_>]) -> Result<Vec<f32>, InputError> {
        if obs.is_empty() {
            return Ok(Vec::new());
        }
        let a = self
            .normaliser
            .inputs(obs, self.fast.weights().image_side)?;
        Ok(self.fast.encode(&a, self.modalities))
    }
}
