//! The frozen representation of a `learner repr train` export as an RL
//! observation: the node's [`Representation`] observer around the training
//! crate's [`Encoder`] (burn's model, encoding on the CPU's fast path).

use crate::models::{Encoder, ObservationRef};
pub use learner_node::repr::Representation;
use learner_node::repr::{InputError, ZEncoder};
use shared_mem_schema::CameraCalibration;
use std::path::Path;

impl ZEncoder for Encoder {
    fn dim(&self) -> usize {
        Encoder::dim(self)
    }

    fn camera(&self) -> Option<CameraCalibration> {
        Encoder::camera(self).copied()
    }

    fn encode(&self, obs: &[ObservationRef<'_>]) -> Result<Vec<f32>, InputError> {
        Encoder::encode(self, obs)
    }
}

/// Loads the model `learner repr train` exported into `dir`, for the CPU.
pub fn load(dir: &Path) -> crate::train::Result<Representation> {
    load_on(dir, 0)
}

/// The same, encoding batches on at most `threads` cores (0: all).
pub fn load_on(dir: &Path, threads: usize) -> crate::train::Result<Representation> {
    let mut encoder = Encoder::load(dir, &burn::prelude::Device::flex())?;
    if threads > 0 {
        encoder = encoder.with_threads(threads);
    }
    Ok(Representation::new(Box::new(encoder)))
}
