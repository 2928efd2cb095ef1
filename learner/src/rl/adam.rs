//! Adam (Kingma & Ba 2015) over a flat parameter vector: the optimiser of
//! PPO, the value network and the MLP regressions. Its own module so that
//! the network code does not import an algorithm for it.

use serde::{Deserialize, Serialize};

/// Adam's moments over a flat parameter vector (Kingma & Ba 2015; β₁ 0.9,
/// β₂ 0.999, ε 10⁻⁸, their defaults). Part of a checkpoint, so that a
/// resumed PPO run continues the same optimiser.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Adam {
    /// First moments.
    pub m: Vec<f64>,
    /// Second moments.
    pub v: Vec<f64>,
    /// Steps taken.
    pub t: u64,
}

impl Adam {
    const BETA1: f64 = 0.9;
    const BETA2: f64 = 0.999;
    const EPS: f64 = 1e-8;

    /// One ascent step of `params` along `grad` (a fresh optimiser sizes
    /// itself on the first step).
    pub fn ascend(&mut self, params: &mut [f64], grad: &[f64], lr: f64) {
        if self.m.len() != params.len() {
            self.m = vec![0.0; params.len()];
            self.v = vec![0.0; params.len()];
            self.t = 0;
        }
        self.t += 1;
        let b1t = 1.0 - Self::BETA1.powi(self.t.min(i32::MAX as u64) as i32);
        let b2t = 1.0 - Self::BETA2.powi(self.t.min(i32::MAX as u64) as i32);
        for (((p, g), m), v) in params
            .iter_mut()
            .zip(grad)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            *m = Self::BETA1 * *m + (1.0 - Self::BETA1) * g;
            *v = Self::BETA2 * *v + (1.0 - Self::BETA2) * g * g;
            *p += lr * (*m / b1t) / ((*v / b2t).sqrt() + Self::EPS);
        }
    }
}
