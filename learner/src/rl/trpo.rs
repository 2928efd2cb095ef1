//! TRPO (Schulman et al. 2015) for a diagonal Gaussian policy: the
//! policy, generalised advantage estimation, conjugate gradient on
//! Fisher-vector products, the backtracking line search on the KL bound and
//! the surrogate, and a least-squares value baseline.
//!
//! The Fisher-vector product is analytic: for a Gaussian with mean μ(s; θ)
//! and state-independent log σ, the Fisher matrix (the Hessian of the mean
//! KL at the old policy) is `(1/N) Σᵢ Jᵢᵀ diag(1/σ²) Jᵢ` for the network's
//! parameters (Jᵢ the Jacobian of μ(sᵢ)) and `2·I` for log σ, with no
//! cross terms. `F v` is then one forward-mode pass (J v), a scaling and one
//! reverse-mode pass (Jᵀ ·) of [`Mlp`].

use super::mlp::{Cache, Mlp};
use faer::Mat;
use faer::prelude::*;
use hw_sim::rng::{self, SimRng};
use serde::{Deserialize, Serialize};

/// TRPO's settings; defaults are the paper's appendix (simulation column)
/// and, where it is silent, pytorch-trpo's, which the paper's
/// implementation was based on (docs/rl.md, "TRPO").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrpoConfig {
    /// Environment steps per policy update (paper: 2000).
    pub batch_steps: usize,
    /// Discount γ (paper: 0.995).
    pub gamma: f64,
    /// GAE λ (paper: 0.97).
    pub gae_lambda: f64,
    /// KL bound per update (paper: 0.01).
    pub max_kl: f64,
    /// Damping added to the Fisher matrix (paper: 0.1).
    pub damping: f64,
    /// Conjugate-gradient iterations (pytorch-trpo: 10).
    pub cg_iters: usize,
    /// Conjugate gradient stops below this squared residual (1e-10).
    pub cg_residual_tol: f64,
    /// Halvings of the step the line search tries (pytorch-trpo: 10).
    pub max_backtracks: usize,
    /// Least ratio of actual to expected improvement accepted (0.1).
    pub accept_ratio: f64,
    /// Hidden layer widths of the policy's MLP (pytorch-trpo: 64, 64).
    pub hidden: Vec<usize>,
    /// Initial log σ of every action component (pytorch-trpo: 0).
    pub init_log_std: f64,
    /// Ridge regularisation of the baseline's least squares (grown ×10
    /// while the normal equations are not positive definite).
    pub baseline_ridge: f64,
}

impl Default for TrpoConfig {
    fn default() -> Self {
        Self {
            batch_steps: 2000,
            gamma: 0.995,
            gae_lambda: 0.97,
            max_kl: 0.01,
            damping: 0.1,
            cg_iters: 10,
            cg_residual_tol: 1e-10,
            max_backtracks: 10,
            accept_ratio: 0.1,
            hidden: vec![64, 64],
            init_log_std: 0.0,
            baseline_ridge: 1e-5,
        }
    }
}

impl TrpoConfig {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), hw_sim::FieldError> {
        use hw_sim::FieldError;
        let unit = [
            ("trpo.gamma", self.gamma),
            ("trpo.gae_lambda", self.gae_lambda),
        ];
        for (name, v) in unit {
            if !(0.0..=1.0).contains(&v) {
                return Err(FieldError::new(name, v, "must be within [0, 1]"));
            }
        }
        let positive = [
            ("trpo.max_kl", self.max_kl),
            ("trpo.baseline_ridge", self.baseline_ridge),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(FieldError::new(name, v, "must be positive and finite"));
            }
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(FieldError::new("trpo.damping", self.damping, "must be ≥ 0"));
        }
        if !self.init_log_std.is_finite() {
            return Err(FieldError::new(
                "trpo.init_log_std",
                self.init_log_std,
                "must be finite",
            ));
        }
        if self.batch_steps == 0 || self.cg_iters == 0 {
            return Err(FieldError::new(
                "trpo.batch_steps / trpo.cg_iters",
                format!("{} / {}", self.batch_steps, self.cg_iters),
                "must be at least 1",
            ));
        }
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(FieldError::new(
                "trpo.hidden",
                format!("{:?}", self.hidden),
                "at least one layer, each at least 1 wide",
            ));
        }
        Ok(())
    }
}

/// A diagonal Gaussian policy: an MLP's output is the mean, log σ is a
/// free parameter per action component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaussianPolicy {
    /// Layer sizes of the mean's MLP (observation, hidden…, action).
    pub sizes: Vec<usize>,
    /// The MLP's parameters (see [`Mlp`]'s layout).
    pub net: Vec<f64>,
    /// log σ per action component.
    pub log_std: Vec<f64>,
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
        let mut c = Cache::default();
        self.mlp().forward(&self.net, obs, &mut c);
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

/// Solves `A x = b` for a symmetric positive definite `A` given as its
/// product with a vector, by conjugate gradient from x = 0: at most `iters`
/// iterations, stopping once the squared residual is below `tol`.
pub fn conjugate_gradient(
    mut a: impl FnMut(&[f64]) -> Vec<f64>,
    b: &[f64],
    iters: usize,
    tol: f64,
) -> Vec<f64> {
    let mut x = vec![0.0; b.len()];
    let mut r = b.to_vec();
    let mut p = b.to_vec();
    let mut rr = dot(&r, &r);
    for _ in 0..iters {
        if rr < tol {
            break;
        }
        let ap = a(&p);
        let alpha = rr / dot(&p, &ap);
        for k in 0..x.len() {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        let rr_new = dot(&r, &r);
        let beta = rr_new / rr;
        for k in 0..p.len() {
            p[k] = r[k] + beta * p[k];
        }
        rr = rr_new;
    }
    x
}

/// ⟨a, b⟩.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// One batch of on-policy samples for an update.
#[derive(Debug, Clone, Default)]
pub struct Batch {
    /// Observations, batch × observation size.
    pub obs: Vec<f64>,
    /// The actions drawn (before the environment's clipping), batch ×
    /// action size.
    pub actions: Vec<f64>,
    /// Advantages (normalised to zero mean and unit spread by
    /// [`trpo_step`]).
    pub advantages: Vec<f64>,
}

/// The policy at fixed old parameters over a batch: what the surrogate, the
/// KL and the Fisher products are taken against.
pub struct Linearisation<'a> {
    policy: &'a GaussianPolicy,
    mlp: Mlp,
    cache: Cache,
    batch: &'a Batch,
    old_log_prob: Vec<f64>,
}

impl<'a> Linearisation<'a> {
    /// The old policy's pass over `batch`.
    pub fn new(policy: &'a GaussianPolicy, batch: &'a Batch) -> Self {
        let mlp = policy.mlp();
        let mut cache = Cache::default();
        mlp.forward(&policy.net, &batch.obs, &mut cache);
        let d = policy.act_dim();
        let old_log_prob = batch
            .actions
            .chunks_exact(d)
            .zip(cache.output().chunks_exact(d))
            .map(|(a, m)| log_prob(a, m, &policy.log_std))
            .collect();
        Self {
            policy,
            mlp,
            cache,
            batch,
            old_log_prob,
        }
    }

    fn n(&self) -> usize {
        self.cache.len()
    }

    /// The Fisher matrix (without damping) times `v`, v in
    /// [`GaussianPolicy::flat`]'s layout.
    pub fn fisher_vector_product(&self, v: &[f64]) -> Vec<f64> {
        let p = self.policy;
        let nn = p.net.len();
        let d = p.act_dim();
        let n = self.n().max(1) as f64;
        let mut jv = self.mlp.jvp(&p.net, &self.cache, &v[..nn]);
        for (k, x) in jv.iter_mut().enumerate() {
            *x *= (-2.0 * p.log_std[k % d]).exp() / n;
        }
        let mut out = vec![0.0; v.len()];
        self.mlp.backward(&p.net, &self.cache, &jv, &mut out[..nn]);
        for k in 0..d {
            out[nn + k] = 2.0 * v[nn + k];
        }
        out
    }

    /// The surrogate `(1/N) Σ exp(log π_θ − log π_old)·A` and the mean KL
    /// from the old policy, at parameters `flat`.
    pub fn surrogate_and_kl(&self, flat: &[f64]) -> (f64, f64) {
        let p = self.policy;
        let nn = p.net.len();
        let d = p.act_dim();
        let (net, log_std) = flat.split_at(nn);
        let mut c = Cache::default();
        self.mlp.forward(net, &self.batch.obs, &mut c);
        let n = self.n().max(1) as f64;
        let mut surr = 0.0;
        let mut kl = 0.0;
        for (s, (m1, m0)) in c
            .output()
            .chunks_exact(d)
            .zip(self.cache.output().chunks_exact(d))
            .enumerate()
        {
            let a = &self.batch.actions[s * d..(s + 1) * d];
            let ratio = (log_prob(a, m1, log_std) - self.old_log_prob[s]).exp();
            surr += ratio * self.batch.advantages[s];
            kl += kl_gaussian(m0, &p.log_std, m1, log_std);
        }
        (surr / n, kl / n)
    }

    /// The surrogate's gradient at the old parameters (where every ratio
    /// is 1): `(1/N) Σ A ∇ log π`.
    pub fn surrogate_gradient(&self) -> Vec<f64> {
        let p = self.policy;
        let nn = p.net.len();
        let d = p.act_dim();
        let n = self.n().max(1) as f64;
        let inv_var: Vec<f64> = p.log_std.iter().map(|l| (-2.0 * l).exp()).collect();
        let mut dmean = vec![0.0; self.batch.actions.len()];
        let mut g = vec![0.0; p.num_params()];
        for (s, m) in self.cache.output().chunks_exact(d).enumerate() {
            let adv = self.batch.advantages[s] / n;
            for k in 0..d {
                let diff = self.batch.actions[s * d + k] - m[k];
                dmean[s * d + k] = adv * diff * inv_var[k];
                g[nn + k] += adv * (diff * diff * inv_var[k] - 1.0);
            }
        }
        self.mlp.backward(&p.net, &self.cache, &dmean, &mut g[..nn]);
        g
    }
}

/// What one TRPO update did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UpdateStats {
    /// Mean KL from the old policy after the update (0 when rejected).
    pub kl: f64,
    /// Surrogate improvement achieved.
    pub improvement: f64,
    /// Improvement the linear model expected of the full step.
    pub expected: f64,
    /// Fraction of the full step taken (0: every candidate rejected).
    pub step_fraction: f64,
}

/// One TRPO update of `policy` on `batch` (advantages normalised here):
/// s = F⁻¹g by conjugate gradient on damped Fisher-vector products, the
/// full step scaled to the KL bound (½ sᵀFs = max_kl), then halved until
/// the mean KL is within `max_kl` and the surrogate improves by at least
/// `accept_ratio` of the linear expectation.
pub fn trpo_step(policy: &mut GaussianPolicy, batch: &mut Batch, cfg: &TrpoConfig) -> UpdateStats {
    normalise(&mut batch.advantages);
    let old = policy.flat();
    let (best, stats) = {
        let lin = Linearisation::new(policy, batch);
        let g = lin.surrogate_gradient();
        let fvp = |v: &[f64]| {
            let mut f = lin.fisher_vector_product(v);
            for (a, b) in f.iter_mut().zip(v) {
                *a += cfg.damping * b;
            }
            f
        };
        let s = conjugate_gradient(fvp, &g, cfg.cg_iters, cfg.cg_residual_tol);
        let shs = 0.5 * dot(&s, &fvp(&s));
        let rejected = UpdateStats {
            kl: 0.0,
            improvement: 0.0,
            expected: 0.0,
            step_fraction: 0.0,
        };
        if !(shs.is_finite() && shs > 0.0) {
            (None, rejected)
        } else {
            let scale = (cfg.max_kl / shs).sqrt();
            let full: Vec<f64> = s.iter().map(|x| x * scale).collect();
            let expected = dot(&g, &full);
            let (surr0, _) = lin.surrogate_and_kl(&old);
            let mut found = (
                None,
                UpdateStats {
                    expected,
                    ..rejected
                },
            );
            for k in 0..cfg.max_backtracks {
                let frac = 0.5f64.powi(k as i32);
                let cand: Vec<f64> = old.iter().zip(&full).map(|(a, b)| a + frac * b).collect();
                let (surr, kl) = lin.surrogate_and_kl(&cand);
                let improvement = surr - surr0;
                if kl.is_finite()
                    && kl <= cfg.max_kl
                    && improvement > 0.0
                    && improvement / (expected * frac) > cfg.accept_ratio
                {
                    found = (
                        Some(cand),
                        UpdateStats {
                            kl,
                            improvement,
                            expected,
                            step_fraction: frac,
                        },
                    );
                    break;
                }
            }
            found
        }
    };
    if let Some(p) = best {
        policy.set_flat(&p);
    }
    stats
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny policy and batch: 3 observations in, one hidden layer of 4,
    /// 2 actions; 5 samples.
    fn tiny() -> (GaussianPolicy, Batch) {
        let mut rng = hw_sim::rng::seeded(3, 0);
        let mut p = GaussianPolicy::new(3, &[4], 2, 0.0, &mut rng);
        // Larger output weights than the 0.1-scaled start: a Fisher with
        // clear structure.
        for w in &mut p.net {
            *w *= 3.0;
        }
        p.log_std = vec![-0.3, 0.2];
        let obs: Vec<f64> = (0..15).map(|k| (k as f64 * 0.61).sin()).collect();
        let actions = p.sample(&obs, &mut rng);
        let advantages = (0..5).map(|k| (k as f64 * 1.3).cos()).collect();
        (
            p,
            Batch {
                obs,
                actions,
                advantages,
            },
        )
    }

    fn explicit_fisher(p: &GaussianPolicy, batch: &Batch) -> Mat<f64> {
        let mlp = p.mlp();
        let mut c = Cache::default();
        mlp.forward(&p.net, &batch.obs, &mut c);
        let (nn, d, n) = (p.net.len(), p.act_dim(), c.len());
        // Per-sample Jacobians of the mean, column by column (J e_j).
        let mut jac = vec![Mat::<f64>::zeros(d, nn); n];
        for j in 0..nn {
            let mut e = vec![0.0; nn];
            e[j] = 1.0;
            let col = mlp.jvp(&p.net, &c, &e);
            for (i, jm) in jac.iter_mut().enumerate() {
                for k in 0..d {
                    jm[(k, j)] = col[i * d + k];
                }
            }
        }
        let np = p.num_params();
        let mut f = Mat::<f64>::zeros(np, np);
        let w = Mat::<f64>::from_fn(d, d, |a, b| {
            if a == b {
                (-2.0 * p.log_std[a]).exp() / n as f64
            } else {
                0.0
            }
        });
        for jm in &jac {
            let block = jm.transpose() * &w * jm;
            for a in 0..nn {
                for b in 0..nn {
                    f[(a, b)] += block[(a, b)];
                }
            }
        }
        for k in 0..d {
            f[(nn + k, nn + k)] = 2.0;
        }
        f
    }

    #[test]
    fn fisher_vector_product_equals_the_explicit_fisher_times_v() {
        let (p, batch) = tiny();
        let f = explicit_fisher(&p, &batch);
        let lin = Linearisation::new(&p, &batch);
        let np = p.num_params();
        let v: Vec<f64> = (0..np).map(|k| (k as f64 * 0.9).sin()).collect();
        let fv = &f * Mat::<f64>::from_fn(np, 1, |i, _| v[i]);
        let got = lin.fisher_vector_product(&v);
        for i in 0..np {
            assert!(
                (got[i] - fv[(i, 0)]).abs() < 1e-12,
                "{i}: {} vs {}",
                got[i],
                fv[(i, 0)]
            );
        }
    }

    #[test]
    fn fisher_is_the_hessian_of_the_kl() {
        // KL(θ ‖ θ + h v) = ½ h² vᵀ F v + O(h³): checks the analytic Fisher
        // against the KL itself, not against its own formula.
        let (p, batch) = tiny();
        let lin = Linearisation::new(&p, &batch);
        let np = p.num_params();
        let v: Vec<f64> = (0..np).map(|k| (k as f64 * 0.4).cos()).collect();
        let vfv = dot(&v, &lin.fisher_vector_product(&v));
        let h = 1e-4;
        let theta: Vec<f64> = p.flat().iter().zip(&v).map(|(a, b)| a + h * b).collect();
        let (_, kl) = lin.surrogate_and_kl(&theta);
        let numeric = 2.0 * kl / (h * h);
        assert!((numeric - vfv).abs() < 1e-3 * vfv, "{numeric} vs {vfv}");
    }

    #[test]
    fn surrogate_gradient_matches_finite_differences() {
        let (p, batch) = tiny();
        let lin = Linearisation::new(&p, &batch);
        let g = lin.surrogate_gradient();
        let theta = p.flat();
        let h = 1e-6;
        for j in [0, 7, theta.len() - 3, theta.len() - 1] {
            let mut a = theta.clone();
            let mut b = theta.clone();
            a[j] += h;
            b[j] -= h;
            let num = (lin.surrogate_and_kl(&a).0 - lin.surrogate_and_kl(&b).0) / (2.0 * h);
            assert!((num - g[j]).abs() < 1e-7, "{j}: {num} vs {}", g[j]);
        }
    }

    #[test]
    fn conjugate_gradient_solves_a_known_spd_system() {
        let a = Mat::<f64>::from_fn(4, 4, |i, j| {
            [
                [4.0, 1.0, 0.5, 0.0],
                [1.0, 3.0, 0.2, 0.1],
                [0.5, 0.2, 2.0, 0.3],
                [0.0, 0.1, 0.3, 1.5],
            ][i][j]
        });
        let b = [1.0, -2.0, 0.5, 3.0];
        let x = conjugate_gradient(
            |v| {
                let r = &a * Mat::<f64>::from_fn(4, 1, |i, _| v[i]);
                (0..4).map(|i| r[(i, 0)]).collect()
            },
            &b,
            10,
            1e-24,
        );
        let want = a
            .llt(faer::Side::Lower)
            .unwrap()
            .solve(Mat::<f64>::from_fn(4, 1, |i, _| b[i]));
        for i in 0..4 {
            assert!((x[i] - want[(i, 0)]).abs() < 1e-12, "{x:?}");
        }
    }

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
    fn a_trpo_step_respects_the_kl_bound_and_improves_the_surrogate() {
        for max_kl in [0.01, 1e-4] {
            let (mut p, mut batch) = tiny();
            let old = p.clone();
            let cfg = TrpoConfig {
                max_kl,
                ..Default::default()
            };
            let stats = trpo_step(&mut p, &mut batch, &cfg);
            assert!(stats.step_fraction > 0.0, "{stats:?}");
            assert!(stats.improvement > 0.0);
            // The KL recomputed from the two policies.
            let (m0, m1) = (old.means(&batch.obs), p.means(&batch.obs));
            let kl: f64 = m0
                .chunks(2)
                .zip(m1.chunks(2))
                .map(|(a, b)| kl_gaussian(a, &old.log_std, b, &p.log_std))
                .sum::<f64>()
                / 5.0;
            assert!(kl <= max_kl * (1.0 + 1e-9), "{kl} > {max_kl}");
            assert!((kl - stats.kl).abs() < 1e-12);
            // A full step scaled to the bound lands near it (the quadratic
            // model of the KL is close at this size).
            if stats.step_fraction == 1.0 {
                assert!(kl > 0.3 * max_kl, "{kl}");
            }
        }
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

    #[test]
    fn bad_settings_are_named() {
        let c = TrpoConfig {
            gamma: 1.5,
            ..Default::default()
        };
        assert!(c.validate().unwrap_err().to_string().contains("trpo.gamma"));
        TrpoConfig::default().validate().unwrap();
    }
}
