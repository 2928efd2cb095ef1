//! A learning test on the fast path itself (hw-sim's world and the control
//! cycle at 1 kHz, the policy at 20 Hz): TRPO on the ground-truth state,
//! with the staged reward, learns to bring the peg to the hole of a box
//! placed at random per episode (the tip starts about 25 cm above it). Seed fixed; the success rate of the
//! policy's mean over held-out box poses must rise from under 20% to at
//! least 80% within a fixed number of updates.
//!
//! The episode is shortened to 40 steps (2 s) and the action's scale raised
//! to the controller's 1 cm clamp so that the reach fits in an episode and
//! the test in seconds; everything else is what `learner policy train` runs.

use learner::rl::observe::{GroundTruth, Observer};
use learner::rl::{ActionScale, PolicyConfig, RlEnv, RlEnvConfig, Trainer, VecEnv};
use std::sync::Arc;

const STEPS: u32 = 40;

fn env_config() -> RlEnvConfig {
    RlEnvConfig {
        max_steps: STEPS,
        action: ActionScale {
            max_step_m: 0.01,
            max_roll_rad: 0.05,
        },
        ..Default::default()
    }
}

/// At the hole: the tip within 1 cm of the hole's axis and at most 4 cm
/// above the opening (over it, or in it: the reward leads on into the hole,
/// and TRPO's policy goes in).
fn at_the_hole(s: &nalgebra::Vector3<f64>) -> bool {
    s.xy().norm() < 0.01 && s.z < 0.04
}

/// Share of `n` held-out episodes (seeds far from the training seeds) whose
/// last state is at the hole, acting with the policy's mean. An episode the
/// controller faults is a failure.
fn success_rate(policy: &learner::rl::GaussianPolicy, n: usize) -> f64 {
    let mut env = RlEnv::new(&env_config()).unwrap();
    let mut obs = vec![0.0; GroundTruth.dim()];
    let ok = (0..n)
        .filter(|&i| {
            env.reset(1_000_000 + i as u64, false).unwrap();
            loop {
                GroundTruth.observe(&[env.view().unwrap()], &mut obs);
                let o = env.step(&policy.means(&obs), false).unwrap();
                if o.terminated {
                    return false;
                }
                if o.done() {
                    return at_the_hole(&env.task().s_m);
                }
            }
        })
        .count();
    ok as f64 / n as f64
}

#[test]
fn trpo_learns_to_reach_the_hole_on_the_fast_path() {
    learns(learner::rl::Algorithm::Trpo);
}

#[test]
fn ppo_learns_to_reach_the_hole_on_the_fast_path() {
    learns(learner::rl::Algorithm::Ppo);
}

fn learns(algorithm: learner::rl::Algorithm) {
    let env = VecEnv::new(&env_config(), 10, Arc::new(GroundTruth), 0).unwrap();
    let cfg = PolicyConfig {
        algorithm,
        batch_steps: 400,
        // The ground truth's channels are scaled by hand; normalised, its
        // free-space wrench noise becomes as loud as the position, and this
        // test's policy did not learn (0 % at the hole after 30 updates).
        normalise_observations: false,
        ..Default::default()
    };
    let mut trainer = Trainer::new(env, cfg, 3).unwrap();
    let before = success_rate(&trainer.state.policy, 20);
    for _ in 0..UPDATES {
        let s = trainer.iterate().unwrap();
        println!(
            "update {}: return {:.2} kl {:.4} std {:.3}",
            s.iteration,
            s.mean_return().unwrap_or(f64::NAN),
            s.update.kl,
            s.mean_std
        );
    }
    let after = success_rate(&trainer.state.policy, 20);
    println!("success {before:.2} → {after:.2}");
    assert!(before < 0.2, "{before}");
    assert!(after >= 0.8, "{after}");
}

const UPDATES: usize = 30;
