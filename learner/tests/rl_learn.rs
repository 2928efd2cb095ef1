//! TRPO and PPO learn: on a one-dimensional reach (a point that must move
//! to a goal drawn per episode), with the seed fixed, the success rate
//! rises from chance to at least 80% within 30 updates of 400 steps.
//!
//! The task is small so that the learning test takes seconds; the same
//! trainer drives the fast path's `VecEnv` (`learner policy train`).

use learner::rl::env::{RlEnvError, StepOutcome};
use learner::rl::reward::{Outcome, RewardStage};
use learner::rl::train::CriticInput;
use learner::rl::{Algorithm, BaselineKind, BatchEnv, PolicyConfig, Trainer};

/// A point on a line: observation (x, goal), action a clipped to [−1, 1]
/// moves x by 0.1·a; reward −|x − goal| per step; 20 steps.
struct Reach {
    x: Vec<f64>,
    goal: Vec<f64>,
    t: Vec<u32>,
    sum: Vec<f64>,
    obs: Vec<f64>,
    out: Vec<StepOutcome>,
    /// What the observation is multiplied by (the learned representation's
    /// z means vary by a few hundredths).
    scale: f64,
    /// The privileged state an asymmetric critic sees (x − goal, goal, and
    /// a marker no observation holds), when it has one.
    critic: Option<Vec<f64>>,
}

/// What the critic's third value holds: the actor must never see it.
const CRITIC_MARKER: f64 = 1234.5;

const STEPS: u32 = 20;

impl Reach {
    fn new(n: usize) -> Self {
        Self {
            x: vec![0.0; n],
            goal: vec![0.0; n],
            t: vec![0; n],
            sum: vec![0.0; n],
            obs: vec![0.0; 2 * n],
            out: Vec::new(),
            scale: 1.0,
            critic: None,
        }
    }

    fn with_critic(n: usize) -> Self {
        Self {
            critic: Some(vec![0.0; 3 * n]),
            ..Self::new(n)
        }
    }

    fn scaled(n: usize, scale: f64) -> Self {
        Self {
            scale,
            ..Self::new(n)
        }
    }

    fn observe(&mut self) {
        for i in 0..self.x.len() {
            self.obs[2 * i] = self.scale * self.x[i];
            self.obs[2 * i + 1] = self.scale * self.goal[i];
            if let Some(c) = &mut self.critic {
                c[3 * i] = self.x[i] - self.goal[i];
                c[3 * i + 1] = self.goal[i];
                c[3 * i + 2] = CRITIC_MARKER;
            }
        }
    }

    fn success(&self, i: usize) -> bool {
        (self.x[i] - self.goal[i]).abs() < 0.05
    }
}

impl BatchEnv for Reach {
    fn num_envs(&self) -> usize {
        self.x.len()
    }
    fn obs_dim(&self) -> usize {
        2
    }
    fn act_dim(&self) -> usize {
        1
    }
    fn max_steps(&self) -> u32 {
        STEPS
    }
    fn reset(&mut self, which: &[(usize, u64)]) -> Result<(), RlEnvError> {
        for &(i, seed) in which {
            let mut rng = stack_common::rng::seeded(seed, 0);
            self.goal[i] = stack_common::rng::uniform(&mut rng, -1.0, 1.0);
            self.x[i] = 0.0;
            self.t[i] = 0;
            self.sum[i] = 0.0;
        }
        self.observe();
        Ok(())
    }
    fn step(&mut self, actions: &[f64]) -> Result<&[StepOutcome], RlEnvError> {
        self.out.clear();
        for (i, a) in actions.iter().enumerate() {
            self.x[i] += 0.1 * a.clamp(-1.0, 1.0);
            self.t[i] += 1;
            let r = -(self.x[i] - self.goal[i]).abs();
            self.sum[i] += r;
            let done = self.t[i] >= STEPS;
            self.out.push(StepOutcome {
                reward: r,
                stage: RewardStage::Reaching,
                terminated: false,
                truncated: done,
                outcome: if done && self.success(i) {
                    Outcome::CompletedInsertion
                } else {
                    Outcome::Failed
                },
                steps: self.t[i],
                episode_reward: self.sum[i],
            });
        }
        self.observe();
        Ok(&self.out)
    }
    fn observations(&self) -> &[f64] {
        &self.obs
    }
    fn critic_dim(&self) -> usize {
        self.critic.as_ref().map_or(0, |_| 3)
    }
    fn critic_observations(&self) -> &[f64] {
        self.critic.as_deref().unwrap_or(&[])
    }
}

/// Success rate of the policy's mean over 100 fresh goals.
fn evaluate(trainer: &Trainer<Reach>) -> f64 {
    let mut env = Reach::scaled(100, trainer.env().scale);
    // The actor's inputs are the observation's two values, whatever the
    // critic sees.
    assert_eq!(trainer.state.policy.sizes[0], 2);
    let which: Vec<_> = (0..100).map(|i| (i, 1_000_000 + i as u64)).collect();
    env.reset(&which).unwrap();
    for _ in 0..STEPS {
        let a = trainer.state.policy.means(env.observations());
        env.step(&a).unwrap();
    }
    (0..100).filter(|&i| env.success(i)).count() as f64 / 100.0
}

/// Success rate of `algorithm`'s policy after 30 updates of 400 steps on
/// the reach with its observations multiplied by `scale`.
fn reach_after_training(algorithm: Algorithm, scale: f64, normalise: bool) -> f64 {
    let cfg = PolicyConfig {
        algorithm,
        batch_steps: 400,
        normalise_observations: normalise,
        ..Default::default()
    };
    let mut trainer = Trainer::new(Reach::scaled(10, scale), cfg, 7).unwrap();
    for _ in 0..30 {
        trainer.iterate().unwrap();
    }
    evaluate(&trainer)
}

#[test]
fn observation_normalisation_lets_a_policy_tell_nearby_observations_apart() {
    // Observations that vary by hundredths, as the z means do: the raw
    // network maps them to nearly one action; normalised, it learns.
    let raw = reach_after_training(Algorithm::Trpo, 0.02, false);
    let normalised = reach_after_training(Algorithm::Trpo, 0.02, true);
    println!("success after 30 updates: raw {raw:.2}, normalised {normalised:.2}");
    assert!(normalised >= 0.8, "{normalised}");
    assert!(raw < 0.5, "{raw}");
}

/// Trains 30 updates of 400 steps and checks the success rate before and
/// after.
fn learns_a_reach(algorithm: Algorithm) {
    learns_a_reach_with(PolicyConfig {
        algorithm,
        batch_steps: 400,
        ..Default::default()
    });
}

#[test]
fn trpo_learns_a_reach_with_the_value_network() {
    learns_a_reach_with(PolicyConfig {
        batch_steps: 400,
        baseline: BaselineKind::Network,
        ..Default::default()
    });
}

fn learns_a_reach_with(cfg: PolicyConfig) {
    let algorithm = cfg.algorithm;
    let mut trainer = Trainer::new(Reach::new(10), cfg, 7).unwrap();
    let before = evaluate(&trainer);
    let mut returns = Vec::new();
    for _ in 0..30 {
        let s = trainer.iterate().unwrap();
        if algorithm == Algorithm::Trpo {
            assert!(s.update.kl <= 0.01 * (1.0 + 1e-9), "{:?}", s.update);
        }
        println!(
            "update {}: return {:.2} kl {:.4} step {} clipped {:.2} std {:.3}",
            s.iteration,
            s.mean_return().unwrap(),
            s.update.kl,
            s.update.step_fraction,
            s.update.clip_fraction,
            s.mean_std
        );
        returns.push(s.mean_return().unwrap());
    }
    let after = evaluate(&trainer);
    println!(
        "{algorithm:?}: success {before:.2} → {after:.2}; mean return {:.2} → {:.2}",
        returns[0],
        returns.last().unwrap()
    );
    assert!(before < 0.3, "{before}");
    assert!(after >= 0.8, "{after}");
    assert!(returns.last().unwrap() > &(returns[0] * 0.5), "{returns:?}");
    assert_eq!(trainer.state.env_steps, 30 * 400);
    assert_eq!(trainer.state.episodes_started, 30 * 400 / 20);
}

#[test]
fn trpo_learns_a_reach_within_30_updates() {
    learns_a_reach(Algorithm::Trpo);
}

#[test]
fn ppo_learns_a_reach_within_30_updates() {
    learns_a_reach(Algorithm::Ppo);
}

#[test]
fn a_resumed_run_continues_where_the_checkpoint_left() {
    for (algorithm, baseline) in [
        (Algorithm::Trpo, BaselineKind::Linear),
        (Algorithm::Ppo, BaselineKind::Linear),
        (Algorithm::Trpo, BaselineKind::Network),
    ] {
        resumes_exactly(algorithm, baseline);
    }
}

fn resumes_exactly(algorithm: Algorithm, baseline: BaselineKind) {
    let cfg = PolicyConfig {
        algorithm,
        batch_steps: 200,
        baseline,
        ..Default::default()
    };
    let mut a = Trainer::new(Reach::new(10), cfg.clone(), 3).unwrap();
    for _ in 0..2 {
        a.iterate().unwrap();
    }
    let json = serde_json::to_string(&a.state).unwrap();
    let state = serde_json::from_str(&json).unwrap();
    let mut b = Trainer::resume(Reach::new(10), cfg, state).unwrap();
    assert_eq!(b.state, a.state);
    // Episodes are 20 steps and batches 200: none is cut, so the resumed
    // run is exactly the uninterrupted one.
    let (sa, sb) = (a.iterate().unwrap(), b.iterate().unwrap());
    assert_eq!(sa, sb);
    assert_eq!(a.state, b.state);
}

#[test]
fn a_policy_cannot_gain_or_lose_its_normalisation_by_a_setting() {
    let on = PolicyConfig {
        batch_steps: 200,
        ..Default::default()
    };
    let off = PolicyConfig {
        normalise_observations: false,
        ..on.clone()
    };
    let trained_on = Trainer::new(Reach::new(2), on.clone(), 3).unwrap().state;
    let trained_off = Trainer::new(Reach::new(2), off.clone(), 3).unwrap().state;
    assert!(trained_on.policy.obs_norm.is_some() && trained_off.policy.obs_norm.is_none());
    for (cfg, state) in [(off, trained_on), (on, trained_off)] {
        let e = Trainer::resume(Reach::new(2), cfg, state).err().unwrap();
        assert!(
            e.to_string().contains("policy.normalise_observations"),
            "{e}"
        );
    }
}

#[test]
fn a_state_with_another_baseline_than_the_configurations_is_refused() {
    let linear = PolicyConfig {
        batch_steps: 200,
        ..Default::default()
    };
    let network = PolicyConfig {
        baseline: BaselineKind::Network,
        ..linear.clone()
    };
    let state = Trainer::new(Reach::new(2), linear, 3).unwrap().state;
    let e = Trainer::resume(Reach::new(2), network, state)
        .err()
        .unwrap();
    assert!(e.to_string().contains("policy.baseline"), "{e}");
}

/// During `value_warmup_updates` the policy and its observation statistics
/// stay as they were while the value network learns; the first update after
/// it moves the policy.
#[test]
fn the_value_warm_up_trains_the_baseline_alone() {
    for algorithm in [Algorithm::Trpo, Algorithm::Ppo] {
        let cfg = PolicyConfig {
            algorithm,
            batch_steps: 200,
            baseline: BaselineKind::Network,
            value_warmup_updates: 3,
            ..Default::default()
        };
        let mut trainer = Trainer::new(Reach::new(10), cfg, 5).unwrap();
        let policy = trainer.state.policy.clone();
        let baseline = serde_json::to_string(&trainer.state.baseline).unwrap();
        let mut explained = Vec::new();
        for _ in 0..3 {
            let s = trainer.iterate().unwrap();
            assert_eq!(s.update.kl, 0.0, "{algorithm:?}");
            explained.push(s.baseline_explained);
        }
        assert_eq!(
            trainer.state.policy, policy,
            "{algorithm:?}: the policy moved"
        );
        assert_ne!(
            serde_json::to_string(&trainer.state.baseline).unwrap(),
            baseline,
            "{algorithm:?}: the baseline did not learn"
        );
        trainer.iterate().unwrap();
        assert_ne!(
            trainer.state.policy.net, policy.net,
            "{algorithm:?}: no policy step after the warm-up"
        );
    }
}

fn critic_config(algorithm: Algorithm) -> PolicyConfig {
    PolicyConfig {
        algorithm,
        batch_steps: 400,
        baseline: BaselineKind::Network,
        critic: CriticInput::GroundTruth,
        ..Default::default()
    }
}

/// With an asymmetric critic the value network sees the environment's
/// privileged state (under its own statistics), the policy only its
/// observation, and the reach is still learned.
#[test]
fn an_asymmetric_critic_sees_the_privileged_state_and_the_policy_learns() {
    for algorithm in [Algorithm::Ppo, Algorithm::Trpo] {
        // Batches of 250 steps cut episodes of 20 (10 environments): the
        // cut segments' critic states bootstrap and carry on.
        let cfg = PolicyConfig {
            batch_steps: 250,
            ..critic_config(algorithm)
        };
        let mut trainer = Trainer::new(Reach::with_critic(10), cfg, 7).unwrap();
        let value_inputs = match &trainer.state.baseline {
            learner::rl::Baseline::Network(v) => v.sizes[0],
            other => panic!("{other:?}"),
        };
        // The critic's three values and the episode's time.
        assert_eq!(value_inputs, 3 + 1, "{algorithm:?}");
        for _ in 0..48 {
            trainer.iterate().unwrap();
        }
        let norm = trainer
            .state
            .critic_norm
            .as_ref()
            .expect("critic statistics");
        assert_eq!(norm.count, 48 * 250, "{algorithm:?}");
        // The marker reached the critic's statistics and nothing of the
        // actor's: its normalisation holds the observation's two values.
        assert!(
            (norm.mean[2] - CRITIC_MARKER).abs() < 1e-6,
            "{:?}",
            norm.mean
        );
        let actor = trainer.state.policy.obs_norm.as_ref().unwrap();
        assert_eq!(actor.dim(), 2);
        assert!(
            actor.mean.iter().all(|m| m.abs() < 10.0),
            "{:?}",
            actor.mean
        );
        let after = evaluate(&trainer);
        assert!(after >= 0.8, "{algorithm:?}: {after}");
    }
    // It survives a checkpoint: the resumed run is the uninterrupted one.
    let cfg = PolicyConfig {
        batch_steps: 200,
        ..critic_config(Algorithm::Ppo)
    };
    let mut a = Trainer::new(Reach::with_critic(10), cfg.clone(), 3).unwrap();
    a.iterate().unwrap();
    let state = serde_json::from_str(&serde_json::to_string(&a.state).unwrap()).unwrap();
    let mut b = Trainer::resume(Reach::with_critic(10), cfg, state).unwrap();
    assert_eq!(a.iterate().unwrap(), b.iterate().unwrap());
    assert_eq!(a.state, b.state);
}

#[test]
fn an_asymmetric_critic_without_a_privileged_state_is_refused() {
    let e = Trainer::new(Reach::new(2), critic_config(Algorithm::Ppo), 3)
        .err()
        .unwrap();
    assert!(e.to_string().contains("policy.critic"), "{e}");
}

/// `freeze_obs_norm` keeps the observation statistics as they were while
/// the policy learns; without it they take in every batch.
#[test]
fn frozen_observation_statistics_stay_put() {
    for freeze in [true, false] {
        let cfg = PolicyConfig {
            algorithm: Algorithm::Ppo,
            batch_steps: 200,
            freeze_obs_norm: freeze,
            ..Default::default()
        };
        let mut trainer = Trainer::new(Reach::new(10), cfg, 3).unwrap();
        trainer.iterate().unwrap();
        let norm = trainer.state.policy.obs_norm.clone();
        let net = trainer.state.policy.net.clone();
        trainer.iterate().unwrap();
        assert_ne!(
            trainer.state.policy.net, net,
            "the policy learns either way"
        );
        assert_eq!(
            trainer.state.policy.obs_norm == norm,
            freeze,
            "freeze {freeze}"
        );
    }
}
