//! PPO (Schulman et al. 2017, "Proximal Policy Optimization Algorithms")
//! for the diagonal Gaussian policy of [`super::gaussian`]: several epochs
//! of minibatch Adam ascent on the clipped surrogate
//! `L = (1/N) Σ min(r·A, clip(r, 1−ε, 1+ε)·A)`, r = π_θ(a|s)/π_old(a|s).
//!
//! The gradient is written out: a sample whose clipped term is the smaller
//! one (r above 1+ε with A > 0, or below 1−ε with A < 0) contributes
//! nothing; any other contributes `A·r·∇log π`, whose parts are
//! `(a−μ)/σ²` for the mean (back-propagated through [`super::mlp::Mlp`])
//! and `(a−μ)²/σ² − 1` for log σ.

/// The optimiser PPO steps with (its own module: the value network and
/// the MLP regression use it too).
pub use super::adam::Adam;
use super::gaussian::{
    GaussianPolicy, RolloutBatch, UpdateStats, kl_gaussian, log_prob, normalise,
};
use super::mlp::Cache;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;
use stack_common::rng::SimRng;

/// PPO's own settings (`[policy.ppo]`). Defaults are the PPO paper's for
/// its continuous-control (MuJoCo) benchmark: ε 0.2, 10 epochs, minibatches
/// of 64, Adam at 3·10⁻⁴; the gradient-norm cap of 0.5 is OpenAI
/// Baselines' `ppo2`. The batch, γ and λ are shared with TRPO
/// ([`super::train::PolicyConfig`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PpoConfig {
    /// Clip range ε of the probability ratio.
    pub clip: f64,
    /// Passes over each batch.
    pub epochs: usize,
    /// Samples per gradient step.
    pub minibatch: usize,
    /// Adam's step size.
    pub learning_rate: f64,
    /// The gradient is scaled down to at most this Euclidean norm (0: no
    /// cap).
    pub max_grad_norm: f64,
    /// The update stops early, before a minibatch's step, once the mean KL
    /// divergence of the current policy from the old over that minibatch's
    /// states exceeds 1.5 × this (0: never; Stable
    /// Baselines3's `target_kl`). The clip alone does not bound the step:
    /// a policy of small σ moved ~1 σ per update (KL 0.1–0.5) in the
    /// fine-tune of docs/rl.md.
    pub target_kl: f64,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            clip: 0.2,
            epochs: 10,
            minibatch: 64,
            learning_rate: 3e-4,
            max_grad_norm: 0.5,
            target_kl: 0.0,
        }
    }
}

impl PpoConfig {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), FieldError> {
        if !(self.clip.is_finite() && self.clip > 0.0 && self.clip < 1.0) {
            return Err(FieldError::new(
                "policy.ppo.clip",
                self.clip,
                "must be within (0, 1)",
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(FieldError::new(
                "policy.ppo.learning_rate",
                self.learning_rate,
                "must be positive and finite",
            ));
        }
        if !(self.target_kl.is_finite() && self.target_kl >= 0.0) {
            return Err(FieldError::new(
                "policy.ppo.target_kl",
                self.target_kl,
                "must be ≥ 0 and finite (0: off)",
            ));
        }
        if !(self.max_grad_norm.is_finite() && self.max_grad_norm >= 0.0) {
            return Err(FieldError::new(
                "policy.ppo.max_grad_norm",
                self.max_grad_norm,
                "must be ≥ 0 and finite",
            ));
        }
        for (name, v) in [
            ("policy.ppo.epochs", self.epochs),
            ("policy.ppo.minibatch", self.minibatch),
        ] {
            if v == 0 {
                return Err(FieldError::new(name, v, "must be at least 1"));
            }
        }
        Ok(())
    }
}

/// The clipped surrogate over samples `idx` of a batch, at the policy's
/// current parameters, with its gradient in [`GaussianPolicy::flat`]'s
/// layout and the share of samples whose ratio lies outside [1−ε, 1+ε].
#[derive(Debug, Clone, PartialEq)]
pub struct Clipped {
    /// `(1/N) Σ min(r·A, clip(r)·A)`.
    pub objective: f64,
    /// Its gradient.
    pub grad: Vec<f64>,
    /// Share of samples clipped.
    pub clip_fraction: f64,
}

/// Evaluates the clipped surrogate of `policy` on the samples `idx` of
/// `batch`, whose log-probabilities under the old policy are `old_log_prob`
/// (one per sample of the batch).
pub fn clipped_surrogate(
    policy: &GaussianPolicy,
    batch: &RolloutBatch,
    old_log_prob: &[f64],
    idx: &[usize],
    clip: f64,
) -> Clipped {
    let mlp = policy.mlp();
    let (od, d) = (policy.sizes[0], policy.act_dim());
    let nn = policy.net.len();
    let mut obs = Vec::with_capacity(idx.len() * od);
    for &i in idx {
        obs.extend_from_slice(&batch.obs[i * od..(i + 1) * od]);
    }
    let mut cache = Cache::default();
    mlp.forward(&policy.net, &obs, &mut cache);
    let n = idx.len().max(1) as f64;
    let inv_var: Vec<f64> = policy.log_std.iter().map(|l| (-2.0 * l).exp()).collect();
    let mut grad = vec![0.0; policy.num_params()];
    let mut dmean = vec![0.0; idx.len() * d];
    let (mut objective, mut clipped) = (0.0, 0usize);
    for (s, (&i, m)) in idx.iter().zip(cache.output().chunks_exact(d)).enumerate() {
        let a = &batch.actions[i * d..(i + 1) * d];
        let adv = batch.advantages[i];
        let ratio = (log_prob(a, m, &policy.log_std) - old_log_prob[i]).exp();
        let bounded = ratio.clamp(1.0 - clip, 1.0 + clip);
        if bounded != ratio {
            clipped += 1;
        }
        objective += (ratio * adv).min(bounded * adv) / n;
        // The clipped term is the minimum (and constant in θ) exactly when
        // the ratio has left the range in the advantage's direction.
        let flat = (adv > 0.0 && ratio > 1.0 + clip) || (adv < 0.0 && ratio < 1.0 - clip);
        if flat {
            continue;
        }
        let w = adv * ratio / n;
        for k in 0..d {
            let diff = a[k] - m[k];
            dmean[s * d + k] = w * diff * inv_var[k];
            grad[nn + k] += w * (diff * diff * inv_var[k] - 1.0);
        }
    }
    mlp.backward(&policy.net, &cache, &dmean, &mut grad[..nn]);
    Clipped {
        objective,
        grad,
        clip_fraction: clipped as f64 / n,
    }
}

/// One PPO update of `policy` on `batch` (advantages normalised here):
/// `epochs` passes, each over a fresh permutation (drawn from `rng`) cut
/// into minibatches, one Adam step per minibatch along the clipped
/// surrogate's gradient (its norm capped at `max_grad_norm`).
pub fn ppo_update(
    policy: &mut GaussianPolicy,
    batch: &mut RolloutBatch,
    cfg: &PpoConfig,
    adam: &mut Adam,
    rng: &mut SimRng,
) -> UpdateStats {
    normalise(&mut batch.advantages);
    let d = policy.act_dim();
    let old = policy.clone();
    let old_means = old.net_means(&batch.obs);
    let old_log_prob: Vec<f64> = batch
        .actions
        .chunks_exact(d)
        .zip(old_means.chunks_exact(d))
        .map(|(a, m)| log_prob(a, m, &old.log_std))
        .collect();
    let n = old_log_prob.len();
    let all: Vec<usize> = (0..n).collect();
    let before = clipped_surrogate(policy, batch, &old_log_prob, &all, f64::INFINITY).objective;
    let mut order = all.clone();
    let mut params = policy.flat();
    let mut clip_fraction = 0.0;
    // The minibatch KL of the new policy from the old, past the limit.
    let od = batch.obs.len() / n.max(1);
    let too_far = |policy: &GaussianPolicy, idx: &[usize]| {
        if cfg.target_kl <= 0.0 {
            return false;
        }
        let obs: Vec<f64> = idx
            .iter()
            .flat_map(|&i| &batch.obs[i * od..(i + 1) * od])
            .copied()
            .collect();
        let new = policy.net_means(&obs);
        let kl = idx
            .iter()
            .zip(new.chunks_exact(d))
            .map(|(&i, m1)| {
                kl_gaussian(
                    &old_means[i * d..(i + 1) * d],
                    &old.log_std,
                    m1,
                    &policy.log_std,
                )
            })
            .sum::<f64>()
            / idx.len().max(1) as f64;
        kl > 1.5 * cfg.target_kl
    };
    let mut stopped = false;
    for _ in 0..cfg.epochs {
        if stopped {
            break;
        }
        order.shuffle(rng);
        let (mut clipped, mut seen) = (0.0, 0usize);
        for idx in order.chunks(cfg.minibatch) {
            if too_far(policy, idx) {
                stopped = true;
                break;
            }
            let mut c = clipped_surrogate(policy, batch, &old_log_prob, idx, cfg.clip);
            let norm = c.grad.iter().map(|g| g * g).sum::<f64>().sqrt();
            if !norm.is_finite() {
                continue;
            }
            if cfg.max_grad_norm > 0.0 && norm > cfg.max_grad_norm {
                let s = cfg.max_grad_norm / norm;
                c.grad.iter_mut().for_each(|g| *g *= s);
            }
            adam.ascend(&mut params, &c.grad, cfg.learning_rate);
            policy.set_flat(&params);
            clipped += c.clip_fraction * idx.len() as f64;
            seen += idx.len();
        }
        // An epoch stopped before its first step keeps the last one's.
        if seen > 0 {
            clip_fraction = clipped / seen as f64;
        }
    }
    let after = clipped_surrogate(policy, batch, &old_log_prob, &all, f64::INFINITY).objective;
    let new_means = policy.net_means(&batch.obs);
    let kl = old_means
        .chunks_exact(d)
        .zip(new_means.chunks_exact(d))
        .map(|(m0, m1)| kl_gaussian(m0, &old.log_std, m1, &policy.log_std))
        .sum::<f64>()
        / n.max(1) as f64;
    UpdateStats {
        kl,
        improvement: after - before,
        expected: 0.0,
        step_fraction: 1.0,
        clip_fraction,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One observation, a policy with no hidden layer to speak of: the
    /// objective by hand.
    #[test]
    fn the_clipped_objective_on_known_inputs() {
        let mut rng = stack_common::rng::seeded(1, 0);
        let p = GaussianPolicy::new(1, &[2], 1, 0.0, &mut rng);
        let m = p.means(&[0.0; 4]);
        // Four samples at the same state; the old log-probabilities are
        // chosen so that the ratios are 1.5, 0.5, 1.1, 0.7 exactly.
        let actions = vec![m[0] + 0.3, m[0] - 0.2, m[0], m[0] + 1.0];
        let lp: Vec<f64> = actions
            .iter()
            .map(|a| log_prob(&[*a], &[m[0]], &p.log_std))
            .collect();
        let ratios = [1.5f64, 0.5, 1.1, 0.7];
        let old: Vec<f64> = lp.iter().zip(ratios).map(|(l, r)| l - r.ln()).collect();
        let batch = RolloutBatch {
            obs: vec![0.0; 4],
            actions,
            advantages: vec![2.0, -1.0, 3.0, 1.0],
        };
        let c = clipped_surrogate(&p, &batch, &old, &[0, 1, 2, 3], 0.2);
        // min(1.5·2, 1.2·2) = 2.4; min(0.5·−1, 0.8·−1) = −0.8;
        // min(1.1·3, 1.1·3) = 3.3; min(0.7·1, 0.8·1) = 0.7.
        let want = (2.4 - 0.8 + 3.3 + 0.7) / 4.0;
        assert!((c.objective - want).abs() < 1e-12, "{}", c.objective);
        assert!((c.clip_fraction - 0.75).abs() < 1e-12);
        // Samples 0 and 1 sit on the flat (clipped) side: the gradient is
        // that of samples 2 and 3 alone.
        let alone = clipped_surrogate(&p, &batch, &old, &[2, 3], 0.2);
        for (a, b) in c.grad.iter().zip(&alone.grad) {
            assert!((a - b * 0.5).abs() < 1e-12, "{a} vs {b}/2");
        }
        assert!(alone.grad.iter().any(|g| g.abs() > 1e-6));
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        let mut rng = stack_common::rng::seeded(4, 0);
        let mut p = GaussianPolicy::new(3, &[5], 2, -0.2, &mut rng);
        for w in &mut p.net {
            *w *= 3.0;
        }
        let obs: Vec<f64> = (0..18).map(|k| (k as f64 * 0.7).cos()).collect();
        let actions = p.sample(&obs, &mut rng);
        let means = p.means(&obs);
        // Old log-probabilities a little off the current ones: ratios near
        // 1, inside the clip range, so the objective is smooth here.
        let old: Vec<f64> = actions
            .chunks(2)
            .zip(means.chunks(2))
            .enumerate()
            .map(|(i, (a, m))| log_prob(a, m, &p.log_std) + 0.03 * (i as f64 - 2.5))
            .collect();
        let batch = RolloutBatch {
            obs,
            actions,
            advantages: (0..6).map(|k| (k as f64 * 1.9).sin()).collect(),
        };
        let idx: Vec<usize> = (0..6).collect();
        let c = clipped_surrogate(&p, &batch, &old, &idx, 0.2);
        assert_eq!(c.clip_fraction, 0.0);
        let flat = p.flat();
        let h = 1e-6;
        for j in 0..flat.len() {
            let mut q = p.clone();
            let mut f = flat.clone();
            f[j] += h;
            q.set_flat(&f);
            let up = clipped_surrogate(&q, &batch, &old, &idx, 0.2).objective;
            f[j] -= 2.0 * h;
            q.set_flat(&f);
            let down = clipped_surrogate(&q, &batch, &old, &idx, 0.2).objective;
            let fd = (up - down) / (2.0 * h);
            assert!(
                (fd - c.grad[j]).abs() < 1e-6,
                "param {j}: {fd} vs {}",
                c.grad[j]
            );
        }
    }

    /// A policy of initial log σ `log_std` on 200 two-value observations,
    /// its sampled actions rewarded above the mean where the first
    /// observation is positive (a direction the policy can follow), and
    /// the random stream after the sampling.
    fn followable(log_std: f64) -> (GaussianPolicy, RolloutBatch, SimRng) {
        let mut rng = stack_common::rng::seeded(5, 0);
        let p = GaussianPolicy::new(2, &[8], 1, log_std, &mut rng);
        let obs: Vec<f64> = (0..400).map(|k| (k as f64 * 0.37).sin()).collect();
        let actions = p.sample(&obs, &mut rng);
        let means = p.means(&obs);
        let advantages = obs
            .chunks(2)
            .zip(actions.iter().zip(&means))
            .map(|(o, (a, m))| (a - m) * o[0].signum())
            .collect();
        let batch = RolloutBatch {
            obs,
            actions,
            advantages,
        };
        (p, batch, rng)
    }

    #[test]
    fn an_update_improves_the_surrogate_and_stays_near_the_old_policy() {
        let (mut p, mut batch, mut rng) = followable(0.0);
        let mut adam = Adam::default();
        let cfg = PpoConfig::default();
        let s = ppo_update(&mut p, &mut batch, &cfg, &mut adam, &mut rng);
        assert!(s.improvement > 0.0, "{s:?}");
        assert!(s.kl > 0.0 && s.kl < 0.1, "{s:?}");
        assert_eq!(adam.t, 10 * 4, "10 epochs of 4 minibatches of ≤ 64");
    }

    /// With `target_kl` the update stops once a minibatch's KL passes 1.5×
    /// it: fewer steps, and a KL near the target where the unbounded update
    /// goes far past it (a small σ makes every step large in KL).
    #[test]
    fn target_kl_stops_the_update_early() {
        let run = |target_kl: f64| {
            let (mut p, mut batch, mut rng) = followable(-2.0);
            let mut adam = Adam::default();
            let cfg = PpoConfig {
                target_kl,
                learning_rate: 3e-3,
                ..Default::default()
            };
            let s = ppo_update(&mut p, &mut batch, &cfg, &mut adam, &mut rng);
            (s.kl, adam.t)
        };
        let (free_kl, free_steps) = run(0.0);
        let (kl, steps) = run(0.002);
        assert_eq!(free_steps, 40);
        assert!(steps < free_steps, "{steps}");
        assert!(free_kl > 0.02, "{free_kl}");
        assert!(kl < 0.01, "{kl} (unbounded: {free_kl})");
    }

    #[test]
    fn bad_settings_are_named() {
        for (c, field) in [
            (
                PpoConfig {
                    clip: 1.5,
                    ..Default::default()
                },
                "policy.ppo.clip",
            ),
            (
                PpoConfig {
                    minibatch: 0,
                    ..Default::default()
                },
                "policy.ppo.minibatch",
            ),
            (
                PpoConfig {
                    target_kl: -1.0,
                    ..Default::default()
                },
                "policy.ppo.target_kl",
            ),
        ] {
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
        }
        PpoConfig::default().validate().unwrap();
    }
}
