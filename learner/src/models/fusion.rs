//! Fusion of the modality posteriors by a product of Gaussian experts with
//! the standard-normal prior as one more expert (paper, "Multimodal
//! Fusion"; Wu and Goodman's multimodal VAE), the KL divergence to the
//! prior, and the reparameterised sample.
//!
//! The product of Gaussians has precision Σᵢ 1/σᵢ² and mean
//! (Σᵢ μᵢ/σᵢ²)/(Σᵢ 1/σᵢ²). The paper prints σ² = (Σᵢ σᵢ²)⁻¹, a typo for
//! the sum of precisions (docs/paper.md).

use burn::prelude::*;
use burn::tensor::activation::softplus;

/// Added to every expert's variance so that no precision is unbounded.
pub const MIN_VARIANCE: f64 = 1e-4;

/// A diagonal Gaussian over the latent space, `[B, d]` each.
#[derive(Debug, Clone)]
pub struct Gaussian {
    /// Mean.
    pub mean: Tensor<2>,
    /// Variance.
    pub var: Tensor<2>,
}

/// Splits an encoder's `[B, 2d]` output into a Gaussian: the first d values
/// are the mean, the softplus of the last d (plus [`MIN_VARIANCE`]) the
/// variance.
pub fn gaussian(params: Tensor<2>) -> Gaussian {
    let [b, two_d] = params.dims();
    let d = two_d / 2;
    let mean = params.clone().slice([0..b, 0..d]);
    let raw = params.slice([0..b, d..two_d]);
    Gaussian {
        mean,
        var: softplus(raw, 1.0).add_scalar(MIN_VARIANCE),
    }
}

/// The product of `experts` and the standard-normal prior.
pub fn product_of_experts(experts: &[Gaussian]) -> Gaussian {
    let mut precision: Option<Tensor<2>> = None;
    let mut weighted: Option<Tensor<2>> = None;
    for e in experts {
        let p = e.var.clone().recip();
        let m = e.mean.clone() * p.clone();
        precision = Some(match precision {
            Some(t) => t + p,
            None => p,
        });
        weighted = Some(match weighted {
            Some(t) => t + m,
            None => m,
        });
    }
    let precision = precision.expect("product_of_experts needs one expert or more");
    let weighted = weighted.expect("same count");
    // The prior: mean 0, precision 1.
    let var = precision.add_scalar(1.0).recip();
    Gaussian {
        mean: weighted * var.clone(),
        var,
    }
}

/// KL(N(μ, σ²) ‖ N(0, I)) = ½ Σⱼ (σⱼ² + μⱼ² − 1 − ln σⱼ²), per sample: `[B]`.
pub fn kl_to_prior(g: &Gaussian) -> Tensor<1> {
    let t = g.var.clone() + g.mean.clone().powf_scalar(2.0) - g.var.clone().log();
    t.add_scalar(-1.0).sum_dim(1).mul_scalar(0.5).squeeze_dim(1)
}

/// The reparameterised sample μ + σ·ε with the given standard-normal noise
/// `eps` (drawn by the caller, so a run is reproducible on any backend).
pub fn sample(g: &Gaussian, eps: Tensor<2>) -> Tensor<2> {
    g.mean.clone() + g.var.clone().sqrt() * eps
}
