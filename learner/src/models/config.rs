//! What a representation model is: its kind, latent size, the modalities it
//! sees and the weights of its losses. One TOML file per model under
//! `configs/repr/`; every field has a default, so a file names only what
//! differs from the paper's Full Model.

pub use learner_node::repr::Modalities;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::{FieldError, ensure, non_negative, within};

/// The paper's representation models (sections "Multi-Modal Representation
/// Model" and "Baseline Representation Models").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// Variational encoders fused by a product of experts, action-conditional
    /// self-supervised decoders, KL to the prior.
    #[default]
    Full,
    /// Deterministic encoders, concatenation and a two-layer MLP, the same
    /// decoders, no KL.
    Deterministic,
    /// A product-of-experts VAE reconstructing RGB, the last wrench reading
    /// and proprioception.
    Reconstruction,
}

/// What the end-effector head predicts from the action-conditioned feature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EeTarget {
    /// The paper's text ("the future end-effector position"), as the
    /// displacement to it: next position minus current, normalised by the
    /// dataset's displacement statistics (3 values). The default, and what
    /// every model exported before the choice existed predicts.
    #[default]
    Displacement,
    /// The authors' public code (`ee_yaw_next`, the next step's first
    /// `action_dim` = 4 proprioception values): the next position and roll
    /// themselves, normalised with the proprioception's statistics (4
    /// values). A displacement can be predicted without knowing where the
    /// arm is; the pose cannot, so this target asks z to keep the position
    /// and the roll.
    Pose,
}

impl EeTarget {
    /// Values the head predicts.
    pub fn dim(self) -> usize {
        match self {
            Self::Displacement => 3,
            Self::Pose => 4,
        }
    }
}

/// Loss weights. The paper does not give them; the defaults are those of the
/// authors' public code (stanford-iprl-lab/multimodal_representation,
/// `configs/training_default.yaml`): flow ×10, mask ×1, KL ×0.05, contact ×1,
/// pairing ×0.5, end-effector ×1. The reconstruction model's three terms
/// (ours) default to 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LossWeights {
    /// Flow endpoint error, px.
    pub flow: f64,
    /// Flow mask cross-entropy.
    pub mask: f64,
    /// Contact-at-next-step cross-entropy.
    pub contact: f64,
    /// Time-alignment cross-entropy (0: the No Pairing ablation).
    pub pairing: f64,
    /// Next end-effector position, mean squared error of the normalised
    /// displacement.
    pub ee: f64,
    /// KL divergence of the fused posterior from the standard normal prior
    /// (ignored by the deterministic model).
    pub kl: f64,
    /// Reconstruction: RGB mean squared error (0..1 intensities).
    pub recon_rgb: f64,
    /// Reconstruction: last wrench reading, normalised.
    pub recon_wrench: f64,
    /// Reconstruction: proprioception, normalised.
    pub recon_proprio: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            flow: 10.0,
            mask: 1.0,
            contact: 1.0,
            pairing: 0.5,
            ee: 1.0,
            kl: 0.05,
            recon_rgb: 1.0,
            recon_wrench: 1.0,
            recon_proprio: 1.0,
        }
    }
}

/// The architecture of a representation model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelConfig {
    /// Which model.
    pub kind: ModelKind,
    /// Latent size d (the paper: 128; its ablation: 16, 64, 256).
    pub latent_dim: usize,
    /// Sensors the model is trained with.
    pub modalities: Modalities,
    /// Image side, px (a multiple of 64: six stride-2 layers reach a map of
    /// side/64). The dataset's images must have it.
    pub image_size: usize,
    /// 3×3 convolutions per stage of the VGG-like depth encoder (six stages;
    /// 3 gives the paper's eighteen layers).
    pub depth_convs_per_stage: usize,
    /// The end-effector head's target (dataset format 5 for
    /// [`EeTarget::Pose`]).
    pub ee_target: EeTarget,
}

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            kind: ModelKind::Full,
            latent_dim: 128,
            modalities: Modalities::ALL,
            image_size: 128,
            depth_convs_per_stage: 3,
            ee_target: EeTarget::Displacement,
        }
    }
}

impl ModelConfig {
    /// Checks the fields, naming the one at fault.
    pub fn validate(&self) -> Result<(), FieldError> {
        within("model.latent_dim", self.latent_dim, 1..=4096)?;
        let s = self.image_size;
        ensure(
            s > 0 && s.is_multiple_of(64) && s <= 1024,
            "model.image_size",
            s,
            "must be a positive multiple of 64, at most 1024",
        )?;
        within(
            "model.depth_convs_per_stage",
            self.depth_convs_per_stage,
            1..=8,
        )?;
        ensure(
            !self.modalities.none(),
            "model.modalities",
            self.modalities.names(),
            "at least one modality must be on",
        )
    }
}

impl LossWeights {
    /// Checks the fields, naming the one at fault.
    pub fn validate(&self) -> Result<(), FieldError> {
        for (name, w) in [
            ("flow", self.flow),
            ("mask", self.mask),
            ("contact", self.contact),
            ("pairing", self.pairing),
            ("ee", self.ee),
            ("kl", self.kl),
            ("recon_rgb", self.recon_rgb),
            ("recon_wrench", self.recon_wrench),
            ("recon_proprio", self.recon_proprio),
        ] {
            non_negative(&format!("loss.{name}"), w)?;
        }
        Ok(())
    }
}
