//! The six losses of the paper's Full Model ("Loss Functions and Training
//! Details") and the reconstruction model's three, weighted and summed.
//!
//! The action-conditional losses (flow, mask, contact, end-effector) are
//! taken over the time-aligned samples only: a pairing negative carries
//! another moment's haptics, so its labels do not belong to its inputs. The
//! pairing loss is over every sample; the KL over every posterior.

use super::config::LossWeights;
use super::inputs::LabelArrays;
use super::net::{Outputs, tensor};
use burn::prelude::*;

/// Keeps the endpoint error's square root differentiable at zero flow.
const EPE_EPS: f32 = 1e-8;

/// A batch's labels as tensors.
#[derive(Debug, Clone)]
pub struct LabelTensors {
    /// `[B, 4]`, normalised.
    pub action: Tensor<2>,
    /// `[B, 2, S, S]`, px.
    pub flow: Tensor<4>,
    /// `[B, 1, S, S]`.
    pub mask: Tensor<4>,
    /// `[B]`.
    pub contact_next: Tensor<1>,
    /// `[B]`.
    pub paired: Tensor<1>,
    /// Time-aligned samples in the batch (the sum of `paired`, counted on
    /// the host: no device round trip per step).
    pub n_paired: f64,
    /// `[B, k]`, normalised: the end-effector target
    /// ([`super::EeTarget`]).
    pub ee: Tensor<2>,
    /// `[B, 3, S, S]`, 0..1 (`None` when the arrays carry none).
    pub rgb01: Option<Tensor<4>>,
    /// `[B, 6]`, normalised.
    pub last_wrench: Tensor<2>,
}

impl LabelTensors {
    /// Uploads `a` (images of side `side`) to `device`.
    pub fn new(a: &LabelArrays, side: usize, device: &Device) -> Self {
        let b = a.paired.len();
        Self {
            action: tensor(a.action.clone(), [b, 4], device),
            flow: tensor(a.flow.clone(), [b, 2, side, side], device),
            mask: tensor(a.mask.clone(), [b, 1, side, side], device),
            contact_next: tensor(a.contact_next.clone(), [b], device),
            paired: tensor(a.paired.clone(), [b], device),
            n_paired: a.paired.iter().map(|&p| p as f64).sum(),
            ee: {
                assert_eq!(
                    a.ee.len(),
                    b * a.ee_dim,
                    "end-effector labels: {} values for {b} samples of {}",
                    a.ee.len(),
                    a.ee_dim
                );
                tensor(a.ee.clone(), [b, a.ee_dim], device)
            },
            rgb01: (!a.rgb01.is_empty())
                .then(|| tensor(a.rgb01.clone(), [b, 3, side, side], device)),
            last_wrench: tensor(a.last_wrench.clone(), [b, 6], device),
        }
    }
}

/// Binary cross-entropy of `logits` against 0/1 `targets`, elementwise,
/// in the stable form max(x, 0) − x·y + ln(1 + e^−|x|):
/// [`learner_kernels::bce_with_logits`], one operation with its own
/// backward pass; the targets get no gradient.
pub fn bce_with_logits<const D: usize>(logits: Tensor<D>, targets: Tensor<D>) -> Tensor<D> {
    learner_kernels::bce_with_logits(logits, targets)
}

/// Per-sample average endpoint error of `pred` against `target`, both
/// `[B, 2, S, S]`: the mean over pixels of the flow vectors' distance, `[B]`.
/// [`learner_kernels::endpoint_error`], one operation with its own
/// backward pass.
pub fn endpoint_error(pred: Tensor<4>, target: Tensor<4>) -> Tensor<1> {
    learner_kernels::endpoint_error(pred, target, EPE_EPS)
}

fn per_sample_mean<const D: usize>(t: Tensor<D>) -> Tensor<1> {
    let b = t.dims()[0];
    t.reshape([b as i32, -1]).mean_dim(1).squeeze_dim(1)
}

/// The mean of `per_sample` `[B]` weighted by `w` `[B]` (0/1), over the
/// samples with weight (zero when none has).
fn weighted_mean(per_sample: Tensor<1>, w: &Tensor<1>, n: f64) -> Tensor<1> {
    (per_sample * w.clone()).sum().div_scalar(n.max(1.0))
}

/// Each loss of a batch (`None`: the model has no such term) and their
/// weighted sum.
#[derive(Debug, Clone)]
pub struct Losses {
    /// The weighted sum, to minimise, `[1]`.
    pub total: Tensor<1>,
    /// Flow endpoint error, px.
    pub flow: Option<Tensor<1>>,
    /// Flow-mask cross-entropy.
    pub mask: Option<Tensor<1>>,
    /// Contact cross-entropy.
    pub contact: Option<Tensor<1>>,
    /// Pairing cross-entropy.
    pub pairing: Option<Tensor<1>>,
    /// End-effector mean squared error (normalised units).
    pub ee: Option<Tensor<1>>,
    /// KL to the prior (nats, summed over d, mean over samples).
    pub kl: Option<Tensor<1>>,
    /// Reconstruction mean squared errors: RGB, last wrench, proprio.
    pub recon: Option<[Tensor<1>; 3]>,
}

/// The losses of `out` against `y`, with the normalised proprioception
/// `proprio` (the reconstruction target) and weights `w`.
pub fn losses(out: &Outputs, y: &LabelTensors, proprio: &Tensor<2>, w: &LossWeights) -> Losses {
    let paired = &y.paired;
    let n_paired = y.n_paired;
    let mut l = Losses {
        total: Tensor::zeros([1], &paired.device()),
        flow: None,
        mask: None,
        contact: None,
        pairing: None,
        ee: None,
        kl: None,
        recon: None,
    };
    let mut terms: Vec<(Tensor<1>, f64)> = Vec::new();
    if let Some(f) = &out.flow {
        let epe = weighted_mean(
            endpoint_error(f.flow.clone(), y.flow.clone()),
            paired,
            n_paired,
        );
        let mask = weighted_mean(
            per_sample_mean(bce_with_logits(f.mask_logits.clone(), y.mask.clone())),
            paired,
            n_paired,
        );
        terms.push((epe.clone(), w.flow));
        terms.push((mask.clone(), w.mask));
        l.flow = Some(epe);
        l.mask = Some(mask);
    }
    if let Some(c) = &out.contact_logits {
        let t = weighted_mean(
            bce_with_logits(c.clone(), y.contact_next.clone()),
            paired,
            n_paired,
        );
        terms.push((t.clone(), w.contact));
        l.contact = Some(t);
    }
    if let Some(e) = &out.ee {
        let t = weighted_mean(
            per_sample_mean((e.clone() - y.ee.clone()).powf_scalar(2.0)),
            paired,
            n_paired,
        );
        terms.push((t.clone(), w.ee));
        l.ee = Some(t);
    }
    if let Some(p) = &out.pairing_logits
        && w.pairing > 0.0
    {
        let t = bce_with_logits(p.clone(), paired.clone()).mean();
        terms.push((t.clone(), w.pairing));
        l.pairing = Some(t);
    }
    if let Some(var) = &out.latent.var {
        let g = super::fusion::Gaussian {
            mean: out.latent.mean.clone(),
            var: var.clone(),
        };
        let t = super::fusion::kl_to_prior(&g).mean();
        terms.push((t.clone(), w.kl));
        l.kl = Some(t);
    }
    if let Some(r) = &out.recon {
        let mse = |a: Tensor<2>, b: Tensor<2>| (a - b).powf_scalar(2.0).mean();
        let target = y
            .rgb01
            .clone()
            .expect("the reconstruction model's labels carry rgb01");
        let rgb = (r.rgb.clone() - target).powf_scalar(2.0).mean();
        let wr = mse(r.wrench.clone(), y.last_wrench.clone());
        let pr = mse(r.proprio.clone(), proprio.clone());
        terms.push((rgb.clone(), w.recon_rgb));
        terms.push((wr.clone(), w.recon_wrench));
        terms.push((pr.clone(), w.recon_proprio));
        l.recon = Some([rgb, wr, pr]);
    }
    for (t, weight) in terms {
        if weight != 0.0 {
            l.total = l.total + t.mul_scalar(weight);
        }
    }
    l
}
