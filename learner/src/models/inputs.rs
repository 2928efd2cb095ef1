//! From samples to the model's label arrays, and the input normaliser of a
//! dataset's statistics. The input arrays themselves (what inference needs
//! too) are the node's: [`learner_node::repr::inputs`].

use super::EeTarget;
use crate::dataset::{Sample, Stats};
pub use learner_node::repr::inputs::{InputArrays, InputError, Normaliser, ObservationRef};

fn arr<const N: usize>(v: &[f64]) -> [f32; N] {
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(v) {
        *o = *x as f32;
    }
    out
}

/// The normaliser of a dataset's statistics (already validated by
/// `Dataset::open`).
pub fn normaliser_from_stats(s: &Stats) -> Normaliser {
    Normaliser {
        rgb_mean: arr(&s.rgb.mean),
        rgb_std: arr(&s.rgb.std),
        depth_mean: s.depth.mean.first().copied().unwrap_or(0.0) as f32,
        depth_std: s.depth.std.first().copied().unwrap_or(1.0) as f32,
        wrench_mean: arr(&s.wrench.mean),
        wrench_std: arr(&s.wrench.std),
        proprio_mean: arr(&s.proprio.mean),
        proprio_std: arr(&s.proprio.std),
        action_mean: arr(&s.action.mean),
        action_std: arr(&s.action.std),
        ee_delta_mean: arr(&s.ee_delta.mean),
        ee_delta_std: arr(&s.ee_delta.std),
    }
}

impl<'a> From<&'a Sample> for ObservationRef<'a> {
    fn from(s: &'a Sample) -> Self {
        Self {
            rgb: &s.rgb,
            depth: &s.depth,
            wrench: &s.wrench,
            proprio: &s.proprio,
        }
    }
}

/// A batch's labels and the action it is conditioned on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabelArrays {
    /// B×4, normalised.
    pub action: Vec<f32>,
    /// B×2×S×S, px.
    pub flow: Vec<f32>,
    /// B×1×S×S, 0 or 1.
    pub mask: Vec<f32>,
    /// B: contact at the next step, 0 or 1.
    pub contact_next: Vec<f32>,
    /// B: 1 time-aligned, 0 haptics from another time.
    pub paired: Vec<f32>,
    /// B×k: the end-effector target ([`EeTarget`]), normalised.
    pub ee: Vec<f32>,
    /// k, the values per sample in `ee` (kept, since an empty batch cannot
    /// tell it).
    pub ee_dim: usize,
    /// Reconstruction targets: B×3×S×S RGB in 0..1 (empty unless asked
    /// for: only the reconstruction model reads it).
    pub rgb01: Vec<f32>,
    /// Reconstruction targets: B×6, the newest wrench reading, normalised.
    pub last_wrench: Vec<f32>,
}

/// The labels of `samples` (`paired[i]`: whether sample i keeps its own
/// haptics) with the end-effector target `ee`, normalised by `norm`; the
/// RGB reconstruction target only `with_rgb01`.
pub fn labels(
    norm: &Normaliser,
    samples: &[Sample],
    paired: &[u8],
    side: usize,
    ee: EeTarget,
    with_rgb01: bool,
) -> LabelArrays {
    let n = side * side;
    let b = samples.len();
    let mut out = LabelArrays {
        action: Vec::with_capacity(b * 4),
        flow: Vec::with_capacity(b * 2 * n),
        mask: Vec::with_capacity(b * n),
        contact_next: Vec::with_capacity(b),
        paired: paired.iter().map(|&p| p as f32).collect(),
        ee: Vec::with_capacity(b * ee.dim()),
        ee_dim: ee.dim(),
        rgb01: Vec::with_capacity(if with_rgb01 { b * 3 * n } else { 0 }),
        last_wrench: Vec::with_capacity(b * 6),
    };
    for s in samples {
        out.action.extend(
            s.action
                .iter()
                .zip(norm.action_mean.iter().zip(&norm.action_std))
                .map(|(&v, (m, sd))| (v - m) / sd),
        );
        for c in 0..2 {
            out.flow.extend(s.flow[c..].iter().step_by(2));
        }
        out.mask
            .extend(s.mask.iter().map(|&m| (m != 0) as u8 as f32));
        out.contact_next.push(s.contact_next as u8 as f32);
        match ee {
            EeTarget::Displacement => {
                for k in 0..3 {
                    let d = s.ee_next[k] - s.proprio[k];
                    out.ee
                        .push((d - norm.ee_delta_mean[k]) / norm.ee_delta_std[k]);
                }
            }
            // The next pose is distributed as the proprioception's
            // position and roll are, so their statistics normalise it.
            EeTarget::Pose => {
                for k in 0..4 {
                    out.ee
                        .push((s.ee_next[k] - norm.proprio_mean[k]) / norm.proprio_std[k]);
                }
            }
        }
        for c in (0..3).filter(|_| with_rgb01) {
            out.rgb01
                .extend(s.rgb[c..].iter().step_by(3).map(|&v| v as f32 / 255.0));
        }
        let last = &s.wrench[s.wrench.len() - 6..];
        out.last_wrench.extend(
            last.iter()
                .zip(norm.wrench_mean.iter().zip(&norm.wrench_std))
                .map(|(&v, (m, sd))| (v - m) / sd),
        );
    }
    out
}
