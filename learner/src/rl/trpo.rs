//! TRPO (Schulman et al. 2015) for the diagonal Gaussian policy of
//! [`super::gaussian`]: conjugate gradient on Fisher-vector products and the
//! backtracking line search on the KL bound and the surrogate.
//!
//! The Fisher-vector product is analytic: for a Gaussian with mean μ(s; θ)
//! and state-independent log σ, the Fisher matrix (the Hessian of the mean
//! KL at the old policy) is `(1/N) Σᵢ Jᵢᵀ diag(1/σ²) Jᵢ` for the network's
//! parameters (Jᵢ the Jacobian of μ(sᵢ)) and `2·I` for log σ, with no
//! cross terms. `F v` is then one forward-mode pass (J v), a scaling and one
//! reverse-mode pass (Jᵀ ·) of [`Mlp`].

use super::gaussian::{
    GaussianPolicy, RolloutBatch, UpdateStats, dot, kl_gaussian, log_prob, normalise,
};
use super::mlp::{Cache, Mlp};
use serde::{Deserialize, Serialize};

/// TRPO's own settings (`[policy.trpo]`); defaults are the paper's appendix
/// (simulation column) and, where it is silent, pytorch-trpo's, which the
/// paper's implementation was based on (docs/rl.md, "TRPO").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrpoConfig {
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
}

impl Default for TrpoConfig {
    fn default() -> Self {
        Self {
            max_kl: 0.01,
            damping: 0.1,
            cg_iters: 10,
            cg_residual_tol: 1e-10,
            max_backtracks: 10,
            accept_ratio: 0.1,
        }
    }
}

impl TrpoConfig {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), shared_mem_schema::config::FieldError> {
        use shared_mem_schema::config::FieldError;
        if !(self.max_kl.is_finite() && self.max_kl > 0.0) {
            return Err(FieldError::new(
                "policy.trpo.max_kl",
                self.max_kl,
                "must be positive and finite",
            ));
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(FieldError::new(
                "policy.trpo.damping",
                self.damping,
                "must be ≥ 0",
            ));
        }
        if !(self.cg_residual_tol.is_finite() && self.cg_residual_tol >= 0.0) {
            return Err(FieldError::new(
                "policy.trpo.cg_residual_tol",
                self.cg_residual_tol,
                "must be ≥ 0",
            ));
        }
        if !(self.accept_ratio.is_finite() && self.accept_ratio >= 0.0) {
            return Err(FieldError::new(
                "policy.trpo.accept_ratio",
                self.accept_ratio,
                "must be ≥ 0",
            ));
        }
        if self.cg_iters == 0 {
            return Err(FieldError::new(
                "policy.trpo.cg_iters",
                0,
                "must be at least 1",
            ));
        }
        Ok(())
    }
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

/// The policy at fixed old parameters over a batch: what the surrogate, the
/// KL and the Fisher products are taken against.
pub struct Linearisation<'a> {
    policy: &'a GaussianPolicy,
    mlp: Mlp,
    cache: Cache,
    batch: &'a RolloutBatch,
    old_log_prob: Vec<f64>,
}

impl<'a> Linearisation<'a> {
    /// The old policy's pass over `batch`.
    pub fn new(policy: &'a GaussianPolicy, batch: &'a RolloutBatch) -> Self {
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

/// One TRPO update of `policy` on `batch` (advantages normalised here):
/// s = F⁻¹g by conjugate gradient on damped Fisher-vector products, the
/// full step scaled to the KL bound (½ sᵀFs = max_kl), then halved until
/// the mean KL is within `max_kl` and the surrogate improves by at least
/// `accept_ratio` of the linear expectation.
pub fn trpo_step(
    policy: &mut GaussianPolicy,
    batch: &mut RolloutBatch,
    cfg: &TrpoConfig,
) -> UpdateStats {
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
            clip_fraction: 0.0,
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
                            clip_fraction: 0.0,
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

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use faer::prelude::*;

    /// A tiny policy and batch: 3 observations in, one hidden layer of 4,
    /// 2 actions; 5 samples.
    fn tiny() -> (GaussianPolicy, RolloutBatch) {
        let mut rng = stack_common::rng::seeded(3, 0);
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
            RolloutBatch {
                obs,
                actions,
                advantages,
            },
        )
    }

    fn explicit_fisher(p: &GaussianPolicy, batch: &RolloutBatch) -> Mat<f64> {
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
            let (m0, m1) = (old.net_means(&batch.obs), p.net_means(&batch.obs));
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
    fn bad_settings_are_named() {
        let c = TrpoConfig {
            max_kl: -1.0,
            ..Default::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("policy.trpo.max_kl"), "{e}");
        TrpoConfig::default().validate().unwrap();
    }
}
