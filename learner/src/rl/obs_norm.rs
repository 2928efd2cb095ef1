//! Observation normalisation of the policy's input: a running mean and
//! standard deviation per component over every observation trained on,
//! shifted, scaled and clipped before the policy's network (pytorch-trpo's
//! `ZFilter`, which the paper's TRPO implementation was based on, clips at
//! ±5).
//!
//! Why: the learned representation's z means vary by a few hundredths per
//! component across the states of a task (docs/experiments.md, full-v2), so
//! a fresh network maps every state to nearly one action and the policy
//! gradient has nothing to tell states apart with. Scaled to unit spread,
//! the same inputs give the network something to work with.
//!
//! The statistics belong to the policy ([`super::GaussianPolicy`]): the
//! network is only meaningful with the scaling it was trained under, so
//! evaluation, validation and deployment apply the one the checkpoint holds.

use serde::{Deserialize, Serialize};

/// Running mean and spread of observations (Chan et al.'s parallel update
/// of Welford's sums, so that a batch merges in one pass).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObsNorm {
    /// Observations seen.
    pub count: u64,
    /// Their mean per component.
    pub mean: Vec<f64>,
    /// Sum of squared deviations from the mean per component.
    pub m2: Vec<f64>,
    /// Normalised components are clipped to ±clip.
    pub clip: f64,
}

/// Added to the standard deviation before dividing, so a constant component
/// maps to 0 rather than to a division by zero (pytorch-trpo's 1e-8).
const EPS: f64 = 1e-8;

impl ObsNorm {
    /// No observations seen yet: the identity until two are.
    pub fn new(dim: usize, clip: f64) -> Self {
        Self {
            count: 0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
            clip,
        }
    }

    /// Components per observation.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Adds a batch of observations (batch × [`ObsNorm::dim`]).
    pub fn update(&mut self, obs: &[f64]) {
        let d = self.dim();
        if d == 0 || obs.is_empty() {
            return;
        }
        assert_eq!(obs.len() % d, 0, "observations of {d} components");
        let nb = (obs.len() / d) as f64;
        let mut bmean = vec![0.0; d];
        for o in obs.chunks_exact(d) {
            for (m, x) in bmean.iter_mut().zip(o) {
                *m += x / nb;
            }
        }
        let mut bm2 = vec![0.0; d];
        for o in obs.chunks_exact(d) {
            for ((s, x), m) in bm2.iter_mut().zip(o).zip(&bmean) {
                *s += (x - m) * (x - m);
            }
        }
        let na = self.count as f64;
        let n = na + nb;
        for k in 0..d {
            let delta = bmean[k] - self.mean[k];
            self.mean[k] += delta * nb / n;
            self.m2[k] += bm2[k] + delta * delta * na * nb / n;
        }
        self.count += obs.len() as u64 / d as u64;
    }

    /// The sample standard deviation per component (0 before two
    /// observations).
    pub fn std(&self) -> Vec<f64> {
        if self.count < 2 {
            return vec![0.0; self.dim()];
        }
        let n1 = (self.count - 1) as f64;
        self.m2.iter().map(|s| (s / n1).sqrt()).collect()
    }

    /// The shift and scale [`ObsNorm::apply`] uses, before its clip:
    /// component i maps to (o − shift[i]) · scale[i]; the identity (0, 1)
    /// before two observations have been seen.
    pub fn affine(&self) -> (Vec<f64>, Vec<f64>) {
        if self.count < 2 {
            return (vec![0.0; self.dim()], vec![1.0; self.dim()]);
        }
        let scale = self.std().iter().map(|s| 1.0 / (s + EPS)).collect();
        (self.mean.clone(), scale)
    }

    /// The normalised batch: (o − mean) / (std + ε), clipped to ±clip; the
    /// observations unchanged before two have been seen.
    pub fn apply(&self, obs: &[f64]) -> Vec<f64> {
        if self.count < 2 {
            return obs.to_vec();
        }
        let d = self.dim();
        let (_, scale) = self.affine();
        let mut out = obs.to_vec();
        for o in out.chunks_exact_mut(d) {
            for ((x, m), s) in o.iter_mut().zip(&self.mean).zip(&scale) {
                *x = ((*x - m) * s).clamp(-self.clip, self.clip);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batched_updates_give_the_statistics_of_all_observations() {
        // Two components, five observations in batches of 2 and 3.
        let all = [1.0, 10.0, 2.0, 20.0, 4.0, 10.0, 7.0, 30.0, 1.0, 0.0];
        let mut n = ObsNorm::new(2, 5.0);
        n.update(&all[..4]);
        n.update(&all[4..]);
        assert_eq!(n.count, 5);
        // Means 3 and 14; sample variances 26/4 and 520/4 (hand-computed).
        assert!((n.mean[0] - 3.0).abs() < 1e-12 && (n.mean[1] - 14.0).abs() < 1e-12);
        let s = n.std();
        assert!((s[0] - 6.5f64.sqrt()).abs() < 1e-12, "{s:?}");
        assert!((s[1] - 130f64.sqrt()).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn apply_scales_shifts_and_clips() {
        let mut n = ObsNorm::new(2, 1.5);
        assert_eq!(n.apply(&[3.0, 4.0]), vec![3.0, 4.0], "identity at first");
        // Component 0: mean 1, sd √2; component 1 constant.
        n.update(&[0.0, 5.0, 2.0, 5.0]);
        let out = n.apply(&[1.5, 5.0, 9.0, 6.0]);
        assert!((out[0] - 0.5 / 2f64.sqrt()).abs() < 1e-6, "{out:?}");
        assert_eq!(out[1], 0.0);
        assert_eq!(out[2], 1.5, "clipped");
        assert_eq!(out[3], 1.5, "clipped, not divided into infinity");
    }
}
