//! The value baseline of a run: rllab's linear features
//! ([`LinearBaseline`]) or pytorch-trpo's value network ([`ValueNet`]),
//! chosen by `policy.baseline`.
//!
//! Why the network: the linear baseline fits `[o, o², t, t², t³, 1]`, 2d + 4
//! weights, to one batch (2000 states of four episodes): 40 for the 18
//! ground-truth values, 260 for a representation's 128 z means. On those it
//! explained most of the next batch's returns but now and then less than
//! their mean (docs/rl.md, "Baselines"); the network shares its hidden
//! layers across inputs and is fitted with an L2 penalty, as pytorch-trpo
//! fits its value MLP.

use super::adam::Adam;
use super::gaussian::LinearBaseline;
use super::mlp::{Cache, Mlp};
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;
use stack_common::rng::SimRng;

/// Which baseline (`policy.baseline`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BaselineKind {
    /// Linear in fixed features (rllab's `LinearFeatureBaseline`).
    #[default]
    Linear,
    /// An MLP over the policy's inputs and the time (pytorch-trpo's).
    Network,
}

/// The value network's fitting (`[policy.value]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValueConfig {
    /// Hidden layer widths (pytorch-trpo: 64, 64).
    pub hidden: Vec<usize>,
    /// Passes over each batch.
    pub epochs: usize,
    /// Samples per Adam step.
    pub minibatch: usize,
    /// Adam's step size.
    pub learning_rate: f64,
    /// L2 penalty on the weights (pytorch-trpo: 10⁻³).
    pub l2: f64,
}

impl Default for ValueConfig {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            epochs: 10,
            minibatch: 64,
            learning_rate: 1e-3,
            l2: 1e-3,
        }
    }
}

impl ValueConfig {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(FieldError::new(
                "policy.value.hidden",
                format!("{:?}", self.hidden),
                "at least one layer, each at least 1 wide",
            ));
        }
        if self.epochs == 0 || self.minibatch == 0 {
            return Err(FieldError::new(
                "policy.value.epochs/minibatch",
                format!("{}/{}", self.epochs, self.minibatch),
                "must be at least 1",
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(FieldError::new(
                "policy.value.learning_rate",
                self.learning_rate,
                "must be positive and finite",
            ));
        }
        if !(self.l2.is_finite() && self.l2 >= 0.0) {
            return Err(FieldError::new(
                "policy.value.l2",
                self.l2,
                "must be finite and not negative",
            ));
        }
        Ok(())
    }
}

/// A value network: an MLP (tanh hidden layers) over the policy's inputs
/// and the step over the episode length, its output times `scale`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValueNet {
    /// Layer sizes (input + 1, hidden…, 1).
    pub sizes: Vec<usize>,
    /// The MLP's parameters.
    pub net: Vec<f64>,
    /// Returns are fitted divided by this: the first batch's target spread,
    /// at least 1 (0: not fitted yet), fixed from then on so that the
    /// network's function does not move under it. The mean is not taken
    /// out: returns that grow tenfold in training are fitted at about ten
    /// times unit size.
    pub scale: f64,
    /// The optimiser's moments (kept across updates).
    pub adam: Adam,
}

impl ValueNet {
    /// A fresh network for `input` values per state.
    pub fn new(input: usize, hidden: &[usize], rng: &mut SimRng) -> Self {
        let mut sizes = vec![input + 1];
        sizes.extend_from_slice(hidden);
        sizes.push(1);
        Self {
            net: Mlp::new(&sizes).init(rng, 0.1),
            sizes,
            scale: 0.0,
            adam: Adam::default(),
        }
    }

    fn rows(obs: &[f64], times: &[f64]) -> Vec<f64> {
        let d = obs.len() / times.len().max(1);
        let mut x = Vec::with_capacity(times.len() * (d + 1));
        for (o, &t) in obs.chunks_exact(d.max(1)).zip(times) {
            x.extend_from_slice(o);
            x.push(t);
        }
        x
    }

    /// The value of a batch of states.
    pub fn predict(&self, obs: &[f64], times: &[f64]) -> Vec<f64> {
        if self.scale == 0.0 || times.is_empty() {
            return vec![0.0; times.len()];
        }
        let mut c = Cache::default();
        Mlp::new(&self.sizes).forward(&self.net, &Self::rows(obs, times), &mut c);
        c.output().iter().map(|v| v * self.scale).collect()
    }

    /// Fits to `targets`: `cfg.epochs` passes over a permutation drawn from
    /// `rng`, one Adam step on the mean squared error plus the L2 penalty
    /// per minibatch.
    pub fn fit(
        &mut self,
        obs: &[f64],
        times: &[f64],
        targets: &[f64],
        cfg: &ValueConfig,
        rng: &mut SimRng,
    ) {
        let n = times.len();
        if n == 0 {
            return;
        }
        if self.scale == 0.0 {
            let mean = targets.iter().sum::<f64>() / n as f64;
            let var = targets.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / n as f64;
            self.scale = var.sqrt().max(1.0);
        }
        let x = Self::rows(obs, times);
        let y: Vec<f64> = targets.iter().map(|t| t / self.scale).collect();
        let fit = super::mlp::MseFit {
            epochs: cfg.epochs,
            minibatch: cfg.minibatch,
            learning_rate: cfg.learning_rate,
            l2: cfg.l2,
        };
        fit.run(
            &Mlp::new(&self.sizes),
            &mut self.net,
            &mut self.adam,
            &x,
            &y,
            rng,
        );
    }
}

/// The baseline of a run (a checkpoint's; one written before the network
/// existed holds the linear one).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Baseline {
    /// rllab's linear features.
    Linear(LinearBaseline),
    /// A value network.
    Network(ValueNet),
}

impl Default for Baseline {
    fn default() -> Self {
        Self::Linear(LinearBaseline::default())
    }
}

impl Baseline {
    /// A fresh baseline of `kind` for `input` values per state.
    pub fn new(kind: BaselineKind, input: usize, cfg: &ValueConfig, rng: &mut SimRng) -> Self {
        match kind {
            BaselineKind::Linear => Self::default(),
            BaselineKind::Network => Self::Network(ValueNet::new(input, &cfg.hidden, rng)),
        }
    }

    /// Whether it is what `kind` and `cfg` describe for `input` values per
    /// state (a value network of those hidden layers).
    pub fn fits(&self, kind: BaselineKind, input: usize, cfg: &ValueConfig) -> bool {
        match self {
            Self::Linear(_) => kind == BaselineKind::Linear,
            Self::Network(v) => {
                kind == BaselineKind::Network
                    && v.sizes.first() == Some(&(input + 1))
                    && v.sizes.get(1..v.sizes.len().saturating_sub(1)) == Some(&cfg.hidden[..])
            }
        }
    }

    /// Its kind.
    pub fn kind(&self) -> BaselineKind {
        match self {
            Self::Linear(_) => BaselineKind::Linear,
            Self::Network(_) => BaselineKind::Network,
        }
    }

    /// The value of a batch of states (inputs and their times).
    pub fn predict(&self, obs: &[f64], times: &[f64]) -> Vec<f64> {
        match self {
            Self::Linear(b) => b.predict(obs, times),
            Self::Network(b) => b.predict(obs, times),
        }
    }

    /// Fits to a batch's targets (the linear one with ridge `ridge`).
    pub fn fit(
        &mut self,
        obs: &[f64],
        times: &[f64],
        targets: &[f64],
        ridge: f64,
        cfg: &ValueConfig,
        rng: &mut SimRng,
    ) {
        match self {
            Self::Linear(b) => b.fit(obs, times, targets, ridge),
            Self::Network(b) => b.fit(obs, times, targets, cfg, rng),
        }
    }
}

/// The share of the targets' variance the predictions explain:
/// 1 − Var(y − v) / Var(y) (1: exact, 0: no better than their mean,
/// negative: worse).
pub fn explained_variance(values: &[f64], targets: &[f64]) -> f64 {
    let n = targets.len();
    if n == 0 {
        return 0.0;
    }
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / n as f64;
        v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64
    };
    let residuals: Vec<f64> = targets.iter().zip(values).map(|(y, v)| y - v).collect();
    let (vy, vr) = (var(targets), var(&residuals));
    if vy == 0.0 { 0.0 } else { 1.0 - vr / vy }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_value_network_fits_a_nonlinear_value_the_linear_baseline_cannot() {
        // V = 100·sin(3·o₀)·o₁ + 50·t over 2 inputs: far from
        // [o, o², t, …]'s span.
        let mut rng = stack_common::rng::seeded(4, 0);
        let n = 2000;
        let (mut obs, mut times, mut y) = (vec![], vec![], vec![]);
        for k in 0..n {
            let (a, b) = (
                stack_common::rng::uniform(&mut rng, -1.0, 1.0),
                stack_common::rng::uniform(&mut rng, -1.0, 1.0),
            );
            let t = (k % 100) as f64 / 100.0;
            obs.extend([a, b]);
            times.push(t);
            y.push(100.0 * (3.0 * a).sin() * b + 50.0 * t);
        }
        let cfg = ValueConfig {
            epochs: 60,
            ..Default::default()
        };
        let mut net = Baseline::new(BaselineKind::Network, 2, &cfg, &mut rng);
        let mut lin = Baseline::default();
        assert_eq!(net.predict(&obs, &times), vec![0.0; n], "0 before a fit");
        net.fit(&obs, &times, &y, 1e-5, &cfg, &mut rng);
        lin.fit(&obs, &times, &y, 1e-5, &cfg, &mut rng);
        let ev_net = explained_variance(&net.predict(&obs, &times), &y);
        let ev_lin = explained_variance(&lin.predict(&obs, &times), &y);
        assert!(ev_net > 0.9, "{ev_net}");
        assert!(ev_lin < 0.5, "{ev_lin}");
        // The checkpoint's JSON tells the two apart, and an old linear one
        // still reads.
        for b in [net, lin] {
            let back: Baseline = serde_json::from_str(&serde_json::to_string(&b).unwrap()).unwrap();
            assert_eq!(back, b);
        }
        let old: Baseline = serde_json::from_str(r#"{"weights":[1.0,2.0]}"#).unwrap();
        assert_eq!(old.kind(), BaselineKind::Linear);
    }

    #[test]
    fn explained_variance_on_known_cases() {
        let y = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(explained_variance(&y, &y), 1.0);
        assert_eq!(explained_variance(&[2.5; 4], &y), 0.0);
        // Residuals 1, −1, 1, −1 (variance 1) on targets of variance 1.25.
        let v = [0.0, 3.0, 2.0, 5.0];
        assert!((explained_variance(&v, &y) - (1.0 - 1.0 / 1.25)).abs() < 1e-12);
    }
}
