//! What every policy-gradient update here shares: the diagonal Gaussian
//! policy, its log-density and KL, on-policy batches, generalised
//! advantage estimation and the linear value baseline (faer). TRPO
//! ([`super::trpo`]) and PPO ([`super::ppo`]) take their steps on these.

use super::mlp::{Cache, Mlp};
use super::obs_norm::ObsNorm;
use faer::Mat;
use faer::prelude::*;
use serde::{Deserialize, Serialize};
use stack_common::rng::{self, SimRng};

/// A diagonal Gaussian policy: an MLP's output is the mean, log σ is a
/// free parameter per action component. With `obs_norm` the observations
/// are normalised before the network ([`ObsNorm`]); the network's inputs
/// are then those, not the observations ([`GaussianPolicy::inputs`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaussianPolicy {
    /// Layer sizes of the mean's MLP (observation, hidden…, action).
    pub sizes: Vec<usize>,
    /// The MLP's parameters (see [`Mlp`]'s layout).
    pub net: Vec<f64>,
    /// log σ per action component.
    pub log_std: Vec<f64>,
    /// The observation normalisation the network was trained under (None:
    /// the network sees the observations as they are, as every policy
    /// trained before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_norm: Option<ObsNorm>,
}

impl GaussianPolicy {
    /// A fresh policy: hidden tanh layers, output weights scaled by 0.1.
    pub fn new(
        obs_dim: usize,
        hidden: &[usize],
        act_dim: usize,
        init_log_std: f64,
        rng: &mut SimRng,
    ) -> Self {
        let mut sizes = vec![obs_dim];
        sizes.extend_from_slice(hidden);
        sizes.push(act_dim);
        let mlp = Mlp::new(&sizes);
        Self {
            net: mlp.init(rng, 0.1),
            sizes,
            log_std: vec![init_log_std; act_dim],
            obs_norm: None,
        }
    }

    /// The network's inputs for a batch of observations: normalised when
    /// the policy has an [`ObsNorm`], the observations otherwise.
    pub fn inputs(&self, obs: &[f64]) -> Vec<f64> {
        match &self.obs_norm {
            Some(n) => n.apply(obs),
            None => obs.to_vec(),
        }
    }

    /// The mean's network.
    pub fn mlp(&self) -> Mlp {
        Mlp::new(&self.sizes)
    }

    /// Parameters in all (network and log σ).
    pub fn num_params(&self) -> usize {
        self.net.len() + self.log_std.len()
    }

    /// All parameters, flat: the network's, then log σ.
    pub fn flat(&self) -> Vec<f64> {
        let mut v = self.net.clone();
        v.extend_from_slice(&self.log_std);
        v
    }

    /// Sets all parameters from [`GaussianPolicy::flat`]'s layout.
    pub fn set_flat(&mut self, v: &[f64]) {
        let n = self.net.len();
        self.net.copy_from_slice(&v[..n]);
        self.log_std.copy_from_slice(&v[n..]);
    }

    /// Action components.
    pub fn act_dim(&self) -> usize {
        self.log_std.len()
    }

    /// Means for a batch of observations (batch × action).
    pub fn means(&self, obs: &[f64]) -> Vec<f64> {
        self.net_means(&self.inputs(obs))
    }

    /// Means for a batch of the network's inputs (what
    /// [`GaussianPolicy::inputs`] gives; what an update's [`RolloutBatch`] holds).
    pub fn net_means(&self, inputs: &[f64]) -> Vec<f64> {
        let mut c = Cache::default();
        self.mlp().forward(&self.net, inputs, &mut c);
        c.output().to_vec()
    }

    /// Draws actions for a batch of observations: mean + σ·ε.
    pub fn sample(&self, obs: &[f64], rng: &mut SimRng) -> Vec<f64> {
        let mut a = self.means(obs);
        let d = self.act_dim();
        for (k, x) in a.iter_mut().enumerate() {
            *x += self.log_std[k % d].exp() * rng::normal(rng);
        }
        a
    }
}

/// log N(a; μ, σ²) of one sample, summed over components.
pub fn log_prob(a: &[f64], mean: &[f64], log_std: &[f64]) -> f64 {
    let half_log_2pi = 0.5 * (std::f64::consts::TAU).ln();
    a.iter()
        .zip(mean)
        .zip(log_std)
        .map(|((a, m), ls)| {
            let z = (a - m) / ls.exp();
            -0.5 * z * z - ls - half_log_2pi
        })
        .sum()
}

/// KL(old ‖ new) of two diagonal Gaussians, summed over components.
pub fn kl_gaussian(m0: &[f64], ls0: &[f64], m1: &[f64], ls1: &[f64]) -> f64 {
    m0.iter()
        .zip(ls0)
        .zip(m1.iter().zip(ls1))
        .map(|((m0, l0), (m1, l1))| {
            let (v0, v1) = ((2.0 * l0).exp(), (2.0 * l1).exp());
            l1 - l0 + (v0 + (m0 - m1).powi(2)) / (2.0 * v1) - 0.5
        })
        .sum()
}

/// Generalised advantage estimates of one trajectory segment: `values[t]`
/// is V(s_t), `last_value` V of the state after the last step (0 when the
/// episode terminated there). Aᵗ = Σ_k (γλ)ᵏ δ_{t+k}, δ_t = r_t + γV(s_{t+1})
/// − V(s_t).
pub fn gae(rewards: &[f64], values: &[f64], last_value: f64, gamma: f64, lambda: f64) -> Vec<f64> {
    assert_eq!(rewards.len(), values.len());
    let mut adv = vec![0.0; rewards.len()];
    let mut next_value = last_value;
    let mut acc = 0.0;
    for t in (0..rewards.len()).rev() {
        let delta = rewards[t] + gamma * next_value - values[t];
        acc = delta + gamma * lambda * acc;
        adv[t] = acc;
        next_value = values[t];
    }
    adv
}

/// ⟨a, b⟩.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// One batch of on-policy samples for an update.
#[derive(Debug, Clone, Default)]
pub struct RolloutBatch {
    /// The network's inputs (the observations, normalised where the policy
    /// normalises them: [`GaussianPolicy::inputs`]), batch × observation
    /// size.
    pub obs: Vec<f64>,
    /// The actions drawn (before the environment's clipping), batch ×
    /// action size.
    pub actions: Vec<f64>,
    /// Advantages (normalised to zero mean and unit spread by the update,
    /// TRPO's or PPO's).
    pub advantages: Vec<f64>,
}

/// Shifts and scales to zero mean and unit standard deviation.
pub fn normalise(x: &mut [f64]) {
    if x.is_empty() {
        return;
    }
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let sd = var.sqrt().max(1e-8);
    for v in x.iter_mut() {
        *v = (*v - mean) / sd;
    }
}

/// A linear value baseline over fixed features of the observation and the
/// time step (rllab's `LinearFeatureBaseline`): `[o, o², t, t², t³, 1]` with
/// o clipped to ±10 and t the step over the episode length, fitted by
/// ridge-regularised least squares (faer's Cholesky).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
// No unknown fields, and no defaults: the untagged `value::Baseline` tells
// this from a value network by its fields.
#[serde(deny_unknown_fields)]
pub struct LinearBaseline {
    /// Fitted weights (empty: predicts 0).
    pub weights: Vec<f64>,
}

impl LinearBaseline {
    /// Features of one state.
    pub fn features(obs: &[f64], t: f64, out: &mut Vec<f64>) {
        out.clear();
        out.extend(obs.iter().map(|o| o.clamp(-10.0, 10.0)));
        out.extend(obs.iter().map(|o| o.clamp(-10.0, 10.0).powi(2)));
        out.extend([t, t * t, t * t * t, 1.0]);
    }

    /// The value of a batch of states (observations and their times).
    pub fn predict(&self, obs: &[f64], times: &[f64]) -> Vec<f64> {
        if self.weights.is_empty() || times.is_empty() {
            return vec![0.0; times.len()];
        }
        let d = obs.len() / times.len();
        let mut f = Vec::new();
        obs.chunks_exact(d)
            .zip(times)
            .map(|(o, &t)| {
                Self::features(o, t, &mut f);
                dot(&f, &self.weights)
            })
            .collect()
    }

    /// Fits the weights to `targets` by least squares with ridge `ridge`
    /// (×10 while the normal equations do not factor, at most 5 times).
    pub fn fit(&mut self, obs: &[f64], times: &[f64], targets: &[f64], ridge: f64) {
        let n = times.len();
        if n == 0 {
            return;
        }
        let d = obs.len() / n;
        let mut f = Vec::new();
        Self::features(&obs[..d], times[0], &mut f);
        let k = f.len();
        let mut phi = Mat::<f64>::zeros(n, k);
        for (i, (o, &t)) in obs.chunks_exact(d).zip(times).enumerate() {
            Self::features(o, t, &mut f);
            for (j, v) in f.iter().enumerate() {
                phi[(i, j)] = *v;
            }
        }
        let y = Mat::<f64>::from_fn(n, 1, |i, _| targets[i]);
        let ata = phi.transpose() * &phi;
        let aty = phi.transpose() * &y;
        let mut reg = ridge;
        for _ in 0..5 {
            let m = Mat::<f64>::from_fn(k, k, |i, j| ata[(i, j)] + if i == j { reg } else { 0.0 });
            if let Ok(llt) = m.llt(faer::Side::Lower) {
                let w = llt.solve(&aty);
                let w: Vec<f64> = (0..k).map(|i| w[(i, 0)]).collect();
                if w.iter().all(|x| x.is_finite()) {
                    self.weights = w;
                    return;
                }
            }
            reg *= 10.0;
        }
    }
}

/// What one policy update did (TRPO or PPO).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UpdateStats {
    /// Mean KL from the old policy after the update (0 when rejected).
    pub kl: f64,
    /// Surrogate improvement achieved (PPO: of the unclipped surrogate).
    pub improvement: f64,
    /// TRPO: improvement the linear model expected of the full step (PPO: 0).
    pub expected: f64,
    /// TRPO: fraction of the full step taken, 0 when every candidate was
    /// rejected (PPO: 1).
    pub step_fraction: f64,
    /// PPO: share of the last epoch's samples whose ratio was clipped
    /// (TRPO: 0).
    #[serde(default)]
    pub clip_fraction: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gae_by_hand() {
        // γ = 0.9, λ = 0.8: δ = (1.4, −1.0, 4.7);
        // A₂ = 4.7, A₁ = −1 + 0.72·4.7 = 2.384, A₀ = 1.4 + 0.72·2.384.
        let a = gae(&[1.0, 0.0, 2.0], &[0.5, 1.0, 0.0], 3.0, 0.9, 0.8);
        let want = [3.116_48, 2.384, 4.7];
        for (g, w) in a.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{a:?}");
        }
        // A terminal state (no bootstrap) and λ = 1: the discounted return
        // minus the value.
        let a = gae(&[1.0, 1.0], &[0.0, 0.0], 0.0, 0.5, 1.0);
        assert_eq!(a, vec![1.5, 1.0]);
    }

    #[test]
    fn the_baseline_fits_a_function_of_its_features() {
        let obs: Vec<f64> = (0..40).map(|k| (k as f64 * 0.3).sin()).collect();
        let times: Vec<f64> = (0..20).map(|k| k as f64 / 20.0).collect();
        let y: Vec<f64> = obs
            .chunks(2)
            .zip(&times)
            .map(|(o, t)| 1.0 + 2.0 * o[0] - o[1] * o[1] + 0.5 * t)
            .collect();
        let mut b = LinearBaseline::default();
        assert_eq!(b.predict(&obs, &times), vec![0.0; 20]);
        b.fit(&obs, &times, &y, 1e-9);
        for (p, w) in b.predict(&obs, &times).iter().zip(&y) {
            assert!((p - w).abs() < 1e-4, "{p} vs {w}");
        }
    }
}
