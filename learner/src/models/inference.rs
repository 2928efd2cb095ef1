//! The inference API: a trained, exported model that turns a batch of
//! observations into z means, as the live node and the RL environment need
//! them. Inference never samples: z is the fused posterior's mean (paper,
//! "Multimodal Input Experiments": the mean is the policy's input).

use super::config::{Modalities, ModelConfig};
use super::inputs::{InputError, Normaliser, ObservationRef};
use super::net::{InputTensors, ReprNet};
use burn::prelude::*;
use learner_node::repr::{EncoderFile, FastEncoder};
use shared_mem_schema::CameraCalibration;
use std::path::Path;

/// A trained representation, ready to encode.
pub struct Encoder {
    net: ReprNet,
    config: ModelConfig,
    normaliser: Normaliser,
    device: Device,
    active: Modalities,
    /// The CPU path (on the `flex` device only).
    fast: Option<FastEncoder>,
    /// The camera of its training images, when the export kept it.
    camera: Option<CameraCalibration>,
}

impl Encoder {
    /// Loads the model exported by `learner repr train` (its `model/`
    /// directory) onto `device` (a plain device: no gradients are kept).
    pub fn load(dir: &Path, device: &Device) -> crate::train::Result<Self> {
        let (net, meta) = crate::train::checkpoint::import(dir, device)?;
        let mut e = Self::new(net.valid(), meta.model, meta.normaliser, device);
        e.camera = meta.camera;
        Ok(e)
    }

    /// The model's configuration, as exported.
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// From parts in memory.
    pub fn new(net: ReprNet, config: ModelConfig, normaliser: Normaliser, device: &Device) -> Self {
        Self {
            fast: (*device == Device::flex()).then(|| super::fast::fast_encoder(&net, &config)),
            active: config.modalities,
            net,
            config,
            normaliser,
            device: device.clone(),
            camera: None,
        }
    }

    /// The camera its training images came from (`None`: not known, as in
    /// a model exported before it was kept); set by [`Encoder::load`].
    pub fn camera(&self) -> Option<&CameraCalibration> {
        self.camera.as_ref()
    }

    /// With the sensors `m` only (a lost sensor's expert is left out of the
    /// product).
    pub fn with_modalities(mut self, m: Modalities) -> Self {
        self.active = self.config.modalities.and(m);
        self
    }

    /// Whether encoding on the CPU takes the fast path (the default) or
    /// burn's `flex` backend (the reference the fast path is tested against).
    pub fn with_fast_path(mut self, on: bool) -> Self {
        if !on {
            self.fast = None;
        } else if self.fast.is_none() && self.device == Device::flex() {
            self.fast = Some(super::fast::fast_encoder(&self.net, &self.config));
        }
        self
    }

    /// Splits the CPU path's batches over at most `n` threads (the default:
    /// every core). burn's own path takes rayon's pool (RAYON_NUM_THREADS).
    pub fn with_threads(mut self, n: usize) -> Self {
        self.fast = self.fast.map(|f| f.with_threads(n));
        self
    }

    /// What the node's weights file holds for it: its layers as plain
    /// arrays, the sensors it encodes with, its normaliser and camera.
    pub fn to_file(&self) -> EncoderFile {
        EncoderFile {
            weights: super::fast::encoder_weights(&self.net, &self.config),
            modalities: self.active,
            normaliser: self.normaliser.clone(),
            camera: self.camera,
        }
    }

    /// Latent size d.
    pub fn dim(&self) -> usize {
        self.config.latent_dim
    }

    /// Image side the model takes, px.
    pub fn image_size(&self) -> usize {
        self.config.image_size
    }

    /// The z means of `obs`, `obs.len()` × d values, row after row.
    pub fn encode(&self, obs: &[ObservationRef<'_>]) -> Result<Vec<f32>, InputError> {
        if obs.is_empty() {
            return Ok(Vec::new());
        }
        let a = self.normaliser.inputs(obs, self.config.image_size)?;
        if let Some(f) = &self.fast {
            return Ok(f.encode(&a, self.active));
        }
        let x = InputTensors::new(&a, &self.device);
        let latent = self.net.encode(&self.config, &x, self.active);
        Ok(latent.mean.try_into_vec_as::<f32>().expect("an f32 tensor"))
    }
}
