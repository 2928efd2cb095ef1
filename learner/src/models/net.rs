//! One network type for every representation model: the encoders its
//! modalities need, the fusion of its kind, and its decoders. A
//! configuration ([`ModelConfig`]) says which parts exist; the forward pass
//! takes the modalities to use, so a trained model can be queried with a
//! sensor masked and an ablation needs no code of its own.

use super::config::{Modalities, ModelConfig, ModelKind};
use super::decoders::{
    ActionFusion, FlowDecoder, FlowPrediction, ReconDecoders, Reconstruction, zero_maps,
};
use super::encoders::{DepthEncoder, LeakyMlp, ProprioEncoder, RgbEncoder, WrenchEncoder};
use super::fusion::{self, Gaussian};
use super::inputs::InputArrays;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use learner_node::policy::WRENCH_WINDOW;
use learner_node::proprio::PROPRIO;

/// A batch of inputs as tensors.
#[derive(Debug, Clone)]
pub struct InputTensors {
    /// `[B, 3, S, S]`, normalised.
    pub rgb: Tensor<4>,
    /// `[B, 1, S, S]`, normalised.
    pub depth: Tensor<4>,
    /// `[B, 6, 32]`, normalised.
    pub wrench: Tensor<3>,
    /// `[B, 8]`, normalised.
    pub proprio: Tensor<2>,
}

impl InputTensors {
    /// Uploads `a` to `device`.
    pub fn new(a: &InputArrays, device: &Device) -> Self {
        let (b, s) = (a.batch, a.side);
        Self {
            rgb: tensor(a.rgb.clone(), [b, 3, s, s], device),
            depth: tensor(a.depth.clone(), [b, 1, s, s], device),
            wrench: tensor(a.wrench.clone(), [b, 6, WRENCH_WINDOW], device),
            proprio: tensor(a.proprio.clone(), [b, PROPRIO], device),
        }
    }

    /// Samples in the batch.
    pub fn batch(&self) -> usize {
        self.proprio.dims()[0]
    }
}

/// A float tensor of shape `shape` from row-major `values`.
pub fn tensor<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// The fused representation of a batch.
#[derive(Debug, Clone)]
pub struct Latent {
    /// The posterior's mean (the deterministic model's z), `[B, d]`.
    pub mean: Tensor<2>,
    /// The posterior's variance (`None` for the deterministic model).
    pub var: Option<Tensor<2>>,
    /// The RGB encoder's feature maps, finest first (zeros when RGB is
    /// masked), for the flow decoder.
    pub maps: Vec<Tensor<4>>,
}

/// Everything a forward pass predicts; a part the model lacks is `None`.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// The fused representation.
    pub latent: Latent,
    /// The z the decoders saw (a sample in training, the mean otherwise).
    pub z: Tensor<2>,
    /// Contact at the next step, logits `[B]`.
    pub contact_logits: Option<Tensor<1>>,
    /// Time alignment of the inputs, logits `[B]`.
    pub pairing_logits: Option<Tensor<1>>,
    /// The end-effector target ([`super::EeTarget`]), normalised, `[B, k]`.
    pub ee: Option<Tensor<2>>,
    /// Flow and mask.
    pub flow: Option<FlowPrediction>,
    /// The reconstruction model's outputs.
    pub recon: Option<Reconstruction>,
}

/// The network of a representation model.
#[derive(Module, Debug)]
pub struct ReprNet {
    pub(crate) rgb: Option<RgbEncoder>,
    pub(crate) depth: Option<DepthEncoder>,
    pub(crate) haptics: Option<WrenchEncoder>,
    pub(crate) proprio: Option<ProprioEncoder>,
    /// Deterministic model: the concatenated features (4 × 2d) → d.
    pub(crate) concat_fusion: Option<LeakyMlp>,
    pub(crate) action: Option<ActionFusion>,
    pub(crate) flow: Option<FlowDecoder>,
    pub(crate) contact: Option<Linear>,
    pub(crate) pairing: Option<Linear>,
    pub(crate) ee: Option<LeakyMlp>,
    pub(crate) recon: Option<ReconDecoders>,
}

impl ReprNet {
    /// A freshly initialised network for `cfg` (already validated).
    pub fn new(cfg: &ModelConfig, device: &Device) -> Self {
        let d = cfg.latent_dim;
        let s = cfg.image_size;
        let m = cfg.modalities;
        let predictive = cfg.kind != ModelKind::Reconstruction;
        Self {
            rgb: m.rgb.then(|| RgbEncoder::new(d, s, device)),
            depth: m
                .depth
                .then(|| DepthEncoder::new(d, s, cfg.depth_convs_per_stage, device)),
            haptics: m.haptics.then(|| WrenchEncoder::new(d, device)),
            proprio: m.proprio.then(|| ProprioEncoder::new(d, device)),
            concat_fusion: (cfg.kind == ModelKind::Deterministic)
                .then(|| LeakyMlp::new(&[8 * d, 2 * d, d], device)),
            action: predictive.then(|| ActionFusion::new(d, device)),
            flow: predictive.then(|| FlowDecoder::new(d, device)),
            contact: predictive.then(|| LinearConfig::new(d, 1).init(device)),
            pairing: predictive.then(|| LinearConfig::new(d, 1).init(device)),
            ee: predictive.then(|| LeakyMlp::new(&[d, 128, 64, 32, cfg.ee_target.dim()], device)),
            recon: (!predictive).then(|| ReconDecoders::new(d, s, device)),
        }
    }

    /// Encodes `x` with the modalities `active` (those the model lacks are
    /// left out whatever `active` says; at least one must remain).
    pub fn encode(&self, cfg: &ModelConfig, x: &InputTensors, active: Modalities) -> Latent {
        let b = x.batch();
        let d = cfg.latent_dim;
        let device = x.proprio.device();
        let on = cfg.modalities.and(active);
        let (rgb, maps) = match (&self.rgb, on.rgb) {
            (Some(e), true) => {
                let (p, maps) = e.forward(x.rgb.clone());
                (Some(p), maps)
            }
            // Only the flow decoder reads the maps.
            _ if self.flow.is_some() => (None, zero_maps(b, d, cfg.image_size, &device)),
            _ => (None, Vec::new()),
        };
        let feats = [
            rgb,
            self.depth
                .as_ref()
                .filter(|_| on.depth)
                .map(|e| e.forward(x.depth.clone())),
            self.haptics
                .as_ref()
                .filter(|_| on.haptics)
                .map(|e| e.forward(x.wrench.clone())),
            self.proprio
                .as_ref()
                .filter(|_| on.proprio)
                .map(|e| e.forward(x.proprio.clone())),
        ];
        match &self.concat_fusion {
            Some(fuse) => {
                // A masked modality's features are zeros: the MLP's input
                // keeps its size.
                let parts = feats
                    .into_iter()
                    .map(|f| f.unwrap_or_else(|| Tensor::zeros([b, 2 * d], &device)))
                    .collect();
                Latent {
                    mean: fuse.forward(Tensor::cat(parts, 1)),
                    var: None,
                    maps,
                }
            }
            None => {
                let experts: Vec<Gaussian> =
                    feats.into_iter().flatten().map(fusion::gaussian).collect();
                let g = if experts.is_empty() {
                    Gaussian {
                        mean: Tensor::zeros([b, d], &device),
                        var: Tensor::ones([b, d], &device),
                    }
                } else {
                    fusion::product_of_experts(&experts)
                };
                Latent {
                    mean: g.mean,
                    var: Some(g.var),
                    maps,
                }
            }
        }
    }

    /// The whole forward pass: encode, take z (the sample μ + σ·`eps` when
    /// `eps` is given and the model is variational, else the mean), decode.
    /// `action` `[B, 4]` (normalised) conditions the predictive decoders.
    pub fn forward(
        &self,
        cfg: &ModelConfig,
        x: &InputTensors,
        action: Tensor<2>,
        eps: Option<Tensor<2>>,
        active: Modalities,
    ) -> Outputs {
        let latent = self.encode(cfg, x, active);
        let z = match (&latent.var, eps) {
            (Some(var), Some(eps)) => fusion::sample(
                &Gaussian {
                    mean: latent.mean.clone(),
                    var: var.clone(),
                },
                eps,
            ),
            _ => latent.mean.clone(),
        };
        let h = self.action.as_ref().map(|a| a.forward(z.clone(), action));
        let squeeze = |t: Tensor<2>| t.squeeze_dim::<1>(1);
        Outputs {
            contact_logits: h
                .as_ref()
                .zip(self.contact.as_ref())
                .map(|(h, l)| squeeze(l.forward(h.clone()))),
            pairing_logits: self.pairing.as_ref().map(|l| squeeze(l.forward(z.clone()))),
            ee: h
                .as_ref()
                .zip(self.ee.as_ref())
                .map(|(h, m)| m.forward(h.clone())),
            flow: h
                .as_ref()
                .zip(self.flow.as_ref())
                .map(|(h, f)| f.forward(h.clone(), &latent.maps)),
            recon: self
                .recon
                .as_ref()
                .map(|r| r.forward(z.clone(), cfg.image_size)),
            latent,
            z,
        }
    }
}
