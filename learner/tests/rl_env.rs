//! The RL environment over the fast path: the heuristic completes every
//! peg through it and earns most of the attainable reward, doing nothing
//! fails, a peg pushed down beside the box earns no insertion reward, and
//! the vectorised environment gives the same results on any number of
//! threads.

use hw_sim::PegShape;
use learner::rl::reward::{Outcome, RewardStage, normalised_return};
use learner::rl::{BatchEnv, GroundTruth, RlEnv, RlEnvConfig, VecEnv};
use learner_node::policy::{HeuristicConfig, HeuristicPolicy};
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

/// The ground truth told with a hole error: the tip's horizontal position
/// relative to the hole (coarse and fine channels) is off by one error per
/// episode, of about the asked deviation over many episodes; nothing else
/// changes, and a zero deviation is the ground truth itself.
#[test]
fn the_hole_error_is_one_offset_per_episode() {
    use learner::rl::ObservationKind;
    use learner::rl::observe::{GROUND_TRUTH_DIM as D, HoleError};
    let cfg = config(PegShape::Square, 30);
    let n = 4;
    let seeds: Vec<(usize, u64)> = (0..n).map(|i| (i, 40 + i as u64)).collect();
    let observe = |kind: ObservationKind| {
        let mut v = VecEnv::new(&cfg, n, kind.observer().unwrap(), 1).unwrap();
        v.reset(&seeds).unwrap();
        let mut trace = vec![v.observations().to_vec()];
        for _ in 0..5 {
            v.step(&[0.3, -0.2, -1.0, 0.1].repeat(n)).unwrap();
            trace.push(v.observations().to_vec());
        }
        trace
    };
    let exact = observe(ObservationKind::GroundTruth);
    assert_eq!(observe(ObservationKind::GroundTruthHoleError(0.0)), exact);
    let told = observe(ObservationKind::GroundTruthHoleError(0.003));
    let mut offsets = Vec::new();
    for (t, e) in told.iter().zip(&exact) {
        for i in 0..n {
            let (t, e) = (&t[i * D..(i + 1) * D], &e[i * D..(i + 1) * D]);
            // Coarse x, y are s / 0.1 m: the offset in metres.
            let off = [(t[0] - e[0]) * 0.1, (t[1] - e[1]) * 0.1];
            offsets.push((i, off));
            assert!(off[0] != 0.0 && off[1] != 0.0);
            // Height, roll, velocities and wrench are untouched.
            assert_eq!(t[2..14], e[2..14]);
            assert_eq!(t[16..], e[16..]);
            // The fine channels carry the same offset.
            let fine = (e[14].atanh() * 0.005 + off[0]) / 0.005;
            assert!((t[14] - fine.tanh()).abs() < 1e-9);
        }
    }
    // One offset per episode, another in each.
    for &(i, off) in &offsets {
        let first = offsets.iter().find(|(j, _)| *j == i).unwrap().1;
        assert!((off[0] - first[0]).abs() < 1e-12 && (off[1] - first[1]).abs() < 1e-12);
    }
    let firsts: Vec<[f64; 2]> = (0..n).map(|i| offsets[i].1).collect();
    for a in 0..n {
        for b in a + 1..n {
            assert_ne!(firsts[a], firsts[b]);
        }
    }
    // Its deviation over many hole poses is the one asked for.
    let h = HoleError { std_m: 0.003 };
    let draws: Vec<f64> = (0..4000)
        .flat_map(|k| {
            let pose = nalgebra::Isometry3::translation(0.5 + k as f64 * 1e-5, 0.01, 0.1);
            h.error(&pose)
        })
        .collect();
    let sd = (draws.iter().map(|x| x * x).sum::<f64>() / draws.len() as f64).sqrt();
    assert!((sd - 0.003).abs() < 0.0002, "{sd}");
    // A policy trained on one takes the other's inputs (init_from), not a
    // representation's.
    let (g, e) = (
        ObservationKind::GroundTruth,
        ObservationKind::GroundTruthHoleError(0.002),
    );
    assert!(g.same_inputs(&e) && e.same_inputs(&g) && e.same_inputs(&e));
    assert!(!e.same_inputs(&ObservationKind::Representation("m".into())));
    // A negative deviation is refused, naming the field.
    let e = ObservationKind::GroundTruthHoleError(-1.0)
        .observer()
        .err()
        .unwrap();
    assert!(e.to_string().contains("ground_truth_hole_error"), "{e}");
}

/// The hole error's curriculum: at share 0 the ramped observer is the
/// exact ground truth, at share 1 the full error, in between the same
/// per-episode offset scaled; a ramp without a hole error is refused.
#[test]
fn the_ramped_hole_error_grows_from_the_truth_to_the_full_error() {
    use learner::rl::ObservationKind;
    use learner::rl::observe::{GROUND_TRUTH_DIM as D, RampedHoleError};
    let cfg = config(PegShape::Square, 30);
    let n = 2;
    let seeds: Vec<(usize, u64)> = (0..n).map(|i| (i, 70 + i as u64)).collect();
    let first = |observer: Arc<dyn learner::rl::Observer>| {
        let mut v = VecEnv::new(&cfg, n, observer, 1).unwrap();
        v.reset(&seeds).unwrap();
        v.observations().to_vec()
    };
    let exact = first(ObservationKind::GroundTruth.observer().unwrap());
    let full = first(
        ObservationKind::GroundTruthHoleError(0.004)
            .observer()
            .unwrap(),
    );
    let ramp = Arc::new(RampedHoleError::new(0.004));
    assert_eq!(first(ramp.clone()), exact, "starts at no error");
    ramp.set_share(1.0);
    assert_eq!(first(ramp.clone()), full, "ends at the full error");
    ramp.set_share(0.25);
    let quarter = first(ramp.clone());
    for i in 0..n {
        // Coarse x, y are s / 0.1 m: a quarter of the full offset.
        for k in 0..2 {
            let (q, f, e) = (quarter[i * D + k], full[i * D + k], exact[i * D + k]);
            assert!(f != e);
            assert!(((q - e) - 0.25 * (f - e)).abs() < 1e-12, "{q} {f} {e}");
        }
    }
    ramp.set_share(7.0);
    assert_eq!(ramp.current_std_m(), 0.004, "clamped to the full error");
    // The training aid needs a hole error to ramp.
    let dir = test_support::scratch_dir("rl-env-ramp");
    let text = "num_envs = 1\nenv_steps = 10\n[policy]\nbatch_steps = 10\n\
                [env.training]\nhole_error_ramp_steps = 100\n";
    let run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    let Err(err) = learner::rl::run::train(run, &dir.path().join("run"), false, &|| false) else {
        panic!("a ramp without a hole error was not refused");
    };
    assert!(err.to_string().contains("hole_error_ramp_steps"), "{err}");
    // With a hole error but no validation to choose the policy, likewise.
    let text = "num_envs = 1\nenv_steps = 10\n\
                observation = { ground_truth_hole_error = 0.004 }\n[policy]\nbatch_steps = 10\n\
                [env.training]\nhole_error_ramp_steps = 100\n";
    let run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    let Err(err) = learner::rl::run::train(run, &dir.path().join("run2"), false, &|| false) else {
        panic!("a ramp without validation was not refused");
    };
    assert!(err.to_string().contains("[validation]"), "{err}");
}

/// Straight down at 5 mm per step (10 cm/s) from the start onto the box:
/// the impact overloads the 100 N supervisor where it is not raised.
fn press_down(mut env: RlEnv) -> (bool, Vec<f64>) {
    env.reset(5, false).unwrap();
    let mut rewards = Vec::new();
    loop {
        let out = env.step(&[0.0, 0.0, -1.0, 0.0], false).unwrap();
        rewards.push(out.reward);
        if out.done() {
            return (out.terminated, rewards);
        }
    }
}

#[test]
fn training_aids_apply_to_training_environments_only() {
    let mut cfg = config(PegShape::Square, 150);
    cfg.action.max_step_m = 0.005;
    // Default aids change nothing: a training environment is the evaluated one.
    let plain = press_down(RlEnv::new(&cfg).unwrap());
    assert_eq!(press_down(RlEnv::for_training(&cfg).unwrap()), plain);
    assert!(
        plain.0,
        "the impact overloads the supervisor: {:?}",
        plain.1
    );

    cfg.training.max_force_n = Some(1.0e4);
    cfg.training.max_moment_nm = Some(1.0e3);
    cfg.training.force_penalty_per_n = 0.1;
    // Evaluation keeps the real fault and the paper's reward.
    assert_eq!(press_down(RlEnv::new(&cfg).unwrap()), plain);
    // Training runs on through the impact and pays for the force.
    let (terminated, rewards) = press_down(RlEnv::for_training(&cfg).unwrap());
    assert!(!terminated, "no fault in training at the raised limit");
    assert_eq!(rewards.len(), 150);
    assert!(
        rewards.iter().any(|&r| r < -1.0),
        "the pressing steps are penalised: {rewards:?}"
    );

    // The overload penalty: what the evaluated supervisor would have
    // faulted on costs that much more per step.
    cfg.training.overload_penalty = 50.0;
    let (_, with_overload) = press_down(RlEnv::for_training(&cfg).unwrap());
    let extra: Vec<f64> = rewards
        .iter()
        .zip(&with_overload)
        .map(|(a, b)| a - b)
        .collect();
    assert!(
        extra.iter().all(|&d| d == 0.0 || (d - 50.0).abs() < 1e-9),
        "{extra:?}"
    );
    assert!(
        extra.iter().any(|&d| (d - 50.0).abs() < 1e-9),
        "some step is over 100 N: {extra:?}"
    );

    cfg.training.force_penalty_per_n = -1.0;
    let err = RlEnv::for_training(&cfg)
        .err()
        .expect("a negative penalty is refused");
    assert!(
        err.to_string().contains("training.force_penalty_per_n"),
        "{err}"
    );
}

/// Steps along the base's x (`dir` ±1) at the action's full scale: the
/// training reward with lateral shaping minus the evaluated reward, per
/// step, and the tip's true horizontal distance from the hole's axis, mm,
/// before each step and after the last.
fn shaping_of_a_sideways_walk(cfg: &RlEnvConfig, dir: f64) -> (Vec<f64>, Vec<f64>) {
    let mut train = RlEnv::for_training(cfg).unwrap();
    let mut eval = RlEnv::new(cfg).unwrap();
    train.reset(7, false).unwrap();
    eval.reset(7, false).unwrap();
    let (mut extra, mut dist) = (Vec::new(), Vec::new());
    for _ in 0..40 {
        let s = train.task().s_m;
        dist.push(s.x.hypot(s.y) * 1e3);
        let a = [dir, 0.0, 0.0, 0.0];
        extra.push(train.step(&a, false).unwrap().reward - eval.step(&a, false).unwrap().reward);
    }
    let s = train.task().s_m;
    dist.push(s.x.hypot(s.y) * 1e3);
    (extra, dist)
}

#[test]
fn lateral_shaping_pays_each_millimetre_towards_the_axis_and_telescopes() {
    let mut cfg = config(PegShape::Square, 150);
    cfg.training.lateral_shaping_per_mm = 0.25;
    for dir in [1.0, -1.0] {
        let (extra, dist) = shaping_of_a_sideways_walk(&cfg, dir);
        for (i, e) in extra.iter().enumerate() {
            let want = 0.25 * (dist[i] - dist[i + 1]);
            assert!((e - want).abs() < 1e-9, "step {i}: {e} against {want}");
        }
        // It telescopes: the episode's sum is the potential's change alone.
        let sum: f64 = extra.iter().sum();
        let change = 0.25 * (dist[0] - dist[dist.len() - 1]);
        assert!((sum - change).abs() < 1e-9, "{sum} against {change}");
        let paid: f64 = extra.iter().map(|e| e.abs()).sum();
        assert!(paid > 1.0, "the walk moved the tip: {dist:?}");
    }
    // Evaluation never sees it: without shaping the two agree exactly.
    cfg.training.lateral_shaping_per_mm = 0.0;
    assert!(
        shaping_of_a_sideways_walk(&cfg, 1.0)
            .0
            .iter()
            .all(|&e| e == 0.0)
    );
    cfg.training.lateral_shaping_per_mm = f64::NAN;
    let err = RlEnv::for_training(&cfg).err().expect("NaN is refused");
    assert!(
        err.to_string().contains("training.lateral_shaping_per_mm"),
        "{err}"
    );
}

#[test]
fn the_overload_ramp_brings_the_training_limits_to_the_evaluated_fault() {
    let mut cfg = config(PegShape::Square, 150);
    cfg.action.max_step_m = 0.005;
    cfg.training.max_force_n = Some(1.0e4);
    cfg.training.max_moment_nm = Some(1.0e3);
    cfg.training.overload_ramp_steps = [100, 300];
    let t = &cfg.training;
    assert_eq!(t.overload_share(0), 0.0);
    assert_eq!(t.overload_share(100), 0.0);
    assert_eq!(t.overload_share(200), 0.5);
    assert_eq!(t.overload_share(10_000), 1.0);

    let (plain_terminated, plain) = press_down(RlEnv::new(&cfg).unwrap());
    assert!(plain_terminated);
    // Before the ramp a training episode runs on through the impact.
    let shared = Arc::new(learner::rl::env::Share::default());
    let mut env = RlEnv::for_training(&cfg).unwrap();
    env.share_overload_ramp(shared.clone());
    assert_eq!(env.overload_limits(), Some((1.0e4, 1.0e3)));
    let (terminated, rewards) = press_down(env);
    assert!(!terminated);
    assert_eq!(rewards.len(), 150);
    // Half-way the limits are half-way to the controller's (100 N, 15 N·m).
    shared.set(0.5);
    let mut env = RlEnv::for_training(&cfg).unwrap();
    env.share_overload_ramp(shared.clone());
    let (f, m) = env.overload_limits().unwrap();
    assert!(
        (f - 5050.0).abs() < 1e-9 && (m - 507.5).abs() < 1e-9,
        "{f} {m}"
    );
    // At the end a training episode ends on the step the fault ends the
    // evaluated one.
    shared.set(1.0);
    env.share_overload_ramp(shared.clone());
    let (terminated, rewards) = press_down(env);
    assert!(terminated, "the ramped limit ends the episode");
    assert_eq!(rewards.len(), plain.len(), "{rewards:?} vs {plain:?}");
    // An evaluated environment has no training limits to ramp.
    assert_eq!(RlEnv::new(&cfg).unwrap().overload_limits(), None);

    // Bad ramps are refused by name.
    for (ramp, aids) in [([300, 100], true), ([100, 100], true), ([0, 100], false)] {
        let mut bad = cfg.clone();
        bad.training.overload_ramp_steps = ramp;
        if !aids {
            bad.training.max_force_n = None;
            bad.training.max_moment_nm = None;
        }
        let err = RlEnv::for_training(&bad).err().expect("refused");
        assert!(
            err.to_string().contains("training.overload_ramp_steps"),
            "{ramp:?}: {err}"
        );
    }
}

#[test]
fn a_resumed_run_adopts_an_overload_ramp_only_if_it_starts_after_the_steps_taken() {
    let dir = test_support::scratch_dir("rl-env-overload-resume");
    let out = dir.path().join("run");
    let text = "num_envs = 1\nenv_steps = 20\n[policy]\nbatch_steps = 20\n\
                [env]\nmax_steps = 20\n[env.training]\nmax_force_n = 400.0\n";
    let mut run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    let first = learner::rl::run::train(run.clone(), &out, false, &|| false).unwrap();
    assert_eq!(first.state.env_steps, 20);
    // A ramp that would have acted on the steps taken is not adopted.
    run.env_steps = 40;
    run.env.training.overload_ramp_steps = [10, 100];
    let c = learner::rl::run::train(run.clone(), &out, true, &|| false).unwrap();
    assert_eq!(c.config.env.training.overload_ramp_steps, [0, 0]);
    // One that starts after them is.
    run.env_steps = 60;
    run.env.training.overload_ramp_steps = [c.state.env_steps, 100];
    let c = learner::rl::run::train(run.clone(), &out, true, &|| false).unwrap();
    assert_eq!(c.config.env.training.overload_ramp_steps, [40, 100]);
    assert_eq!(c.state.env_steps, 60);
}
