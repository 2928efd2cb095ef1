//! The RL environment over the fast path: the heuristic completes every
//! peg through it and earns most of the attainable reward, doing nothing
//! fails, a peg pushed down beside the box earns no insertion reward, and
//! the vectorised environment gives the same results on any number of
//! threads.

use hw_sim::PegShape;
use learner::policy::{HeuristicConfig, HeuristicPolicy};
use learner::rl::reward::{Outcome, RewardStage, normalised_return};
use learner::rl::{BatchEnv, GroundTruth, RlEnv, RlEnvConfig, VecEnv};
use nalgebra::Vector3;
use std::sync::Arc;

fn config(peg: PegShape, max_steps: u32) -> RlEnvConfig {
    let mut cfg = RlEnvConfig {
        max_steps,
        ..Default::default()
    };
    cfg.world.task.peg = peg;
    cfg
}

#[test]
fn the_heuristic_completes_every_peg_with_near_maximal_reward() {
    for (i, peg) in PegShape::ALL.into_iter().enumerate() {
        let mut cfg = config(peg, 500);
        // The heuristic's own steps (up to 8 mm), within the controller's
        // 1 cm clamp, not the policy's 1.5 mm scale.
        cfg.action.max_step_m = 0.01;
        let mut env = RlEnv::new(&cfg).unwrap();
        let seed = 21 + i as u64;
        env.reset(seed, false).unwrap();
        let task = env.task_geometry();
        let mut policy = HeuristicPolicy::new(HeuristicConfig::default());
        let mut stages = Vec::new();
        let last = loop {
            let obs = env.observation().unwrap().clone();
            let delta = policy.act(&obs, &env.fast().wrench, &task);
            let a = env.action_scale().from_delta(&delta);
            let out = env.step(&a, false).unwrap();
            stages.push(out.stage);
            if out.done() {
                break out;
            }
        };
        let norm = normalised_return(last.episode_reward, 500);
        println!(
            "{} (seed {seed}): {} after {} steps, normalised reward {norm:.3}, first completion at step {:?}",
            peg.name(),
            last.outcome.name(),
            last.steps,
            stages.iter().position(|s| *s == RewardStage::Completion)
        );
        assert!(last.truncated && !last.terminated, "{last:?}");
        assert_eq!(last.steps, 500);
        assert_eq!(last.outcome, Outcome::CompletedInsertion, "{}", peg.name());
        // It reaches the bottom within about 3 s (60 steps) and stays: at
        // least 0.85 of the maximum.
        assert!(norm > 0.85, "{}: {norm}", peg.name());
        // The stages come in order: never back out of the hole.
        let first_in = stages
            .iter()
            .position(|s| *s >= RewardStage::Insertion)
            .unwrap();
        assert!(
            stages[first_in..]
                .iter()
                .all(|s| *s >= RewardStage::Insertion)
        );
    }
}

#[test]
fn doing_nothing_fails() {
    let mut env = RlEnv::new(&config(PegShape::Square, 60)).unwrap();
    env.reset(5, false).unwrap();
    let last = loop {
        let out = env.step(&[0.0; 4], false).unwrap();
        assert_eq!(out.stage, RewardStage::Reaching);
        if out.done() {
            break out;
        }
    };
    assert_eq!(last.outcome, Outcome::Failed);
    assert!(last.truncated && last.steps == 60);
    assert!(normalised_return(last.episode_reward, 60) < 0.2);
}

#[test]
fn a_peg_pushed_down_beside_the_box_earns_no_insertion_reward() {
    let mut env = RlEnv::new(&config(PegShape::Square, 400)).unwrap();
    env.reset(9, false).unwrap();
    let task = env.task_geometry();
    let box_half = env.fast().world().config().task.box_side_m / 2.0;
    // Beside the box: 3 cm outside its side along the hole frame's x, then
    // down to 4 cm below the top face (as deep as the hole).
    let goal = Vector3::new(box_half + 0.03, 0.0, -0.04);
    let mut stages = Vec::new();
    let mut lowest = f64::INFINITY;
    for _ in 0..400 {
        let s = env.task().s_m;
        lowest = lowest.min(s.z);
        let mut d = goal - s;
        // Over the box: stay 2 cm above its top until clear of its side.
        if s.x < box_half + 0.02 {
            d.z = 0.02 - s.z;
        }
        let delta = task.hole_pose.rotation * (d * 0.5);
        let a = env
            .action_scale()
            .from_delta(&[delta.x, delta.y, delta.z, 0.0]);
        let out = env.step(&a, false).unwrap();
        stages.push(out.stage);
        if out.done() {
            break;
        }
    }
    assert!(lowest < -0.03, "the tip went only to {lowest} m");
    assert!(
        stages.iter().all(|s| *s == RewardStage::Reaching),
        "{stages:?}"
    );
    let outcome = Outcome::from_stage(env.task().best_stage);
    assert!(outcome < Outcome::InsertedIntoHole, "{outcome:?}");
    assert!(!env.task().in_hole);
}

#[test]
fn the_vectorised_env_gives_the_same_results_on_any_number_of_threads() {
    let cfg = config(PegShape::Triangle, 30);
    let run = |threads: usize| {
        let mut v = VecEnv::new(&cfg, 3, Arc::new(GroundTruth), threads).unwrap();
        assert_eq!(v.threads(), threads);
        v.reset(&[(0, 1), (1, 2), (2, 3)]).unwrap();
        let mut trace = v.observations().to_vec();
        for k in 0..12 {
            let actions: Vec<f64> = (0..12)
                .map(|j| ((k * 12 + j) as f64 * 0.7).sin() * 1.5)
                .collect();
            let out = v.step(&actions).unwrap().to_vec();
            trace.extend(out.iter().map(|o| o.reward));
            trace.extend_from_slice(v.observations());
        }
        trace
    };
    let one = run(1);
    let d = learner::rl::observe::GROUND_TRUTH_DIM;
    assert_eq!(one.len(), 3 * d + 12 * (3 + 3 * d));
    assert!(one.iter().all(|x| x.is_finite()));
    assert_eq!(one, run(3));
    // Different seeds: different boxes, different observations.
    assert_ne!(one[..d], one[d..2 * d]);
}

#[test]
fn the_vectorised_env_checks_its_arguments() {
    let cfg = config(PegShape::Square, 5);
    let mut v = VecEnv::new(&cfg, 2, Arc::new(GroundTruth), 1).unwrap();
    let e = v.reset(&[(2, 1)]).unwrap_err().to_string();
    assert!(e.contains("environment index"), "{e}");
    v.reset(&[(0, 1)]).unwrap();
    let e = v.step(&[0.0; 8]).unwrap_err().to_string();
    assert!(e.contains("environment 1 has no running episode"), "{e}");
    let e = v.step(&[0.0; 3]).unwrap_err().to_string();
    assert!(e.contains("actions: 3 values, expected 8"), "{e}");
    let mut bad = cfg.clone();
    bad.reward.eps2_m = 0.0;
    let e = VecEnv::new(&bad, 1, Arc::new(GroundTruth), 1)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("reward.eps2_m"), "{e}");
}
