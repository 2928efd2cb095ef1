//! The lockstep stack equals the in-process fast path bit for bit.

use hw_sim::WorldConfig;
use learner::fast_env::FastEnv;
use learner_node::live::{PolicyNode, task_geometry};
use learner_node::policy::{HeuristicConfig, HeuristicPolicy, Observation, WrenchHistory};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::transport;
use std::time::{Duration, Instant};

#[test]
fn lockstep_stack_and_fast_path_give_the_same_trajectory() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("lockstep");
    let dir = test_support::scratch_dir("lockstep");
    let _sim = tests::start(
        "hw-sim",
        &["--namespace", &ns, "--mode", "lockstep", "--no-camera"],
        &dir,
    );
    let _ctl = tests::start(
        "rt-controller",
        &[
            "--namespace",
            &ns,
            "--no-realtime",
            "--clock",
            "hardware",
            "--lockstep-actions",
        ],
        &dir,
    );
    let mut world = WorldConfig::default();
    world.task.peg = hw_sim::PegShape::Hexagon;
    let seed = 42;
    let actions = 60;

    // Through the processes, this test acting as the policy node.
    let mut node = PolicyNode::open(&ns).unwrap();
    let report = node
        .reset(seed, &toml::to_string(&world).unwrap(), true)
        .expect("reset through the stack");
    let episode = report.header.episode;
    // What hw-sim reports passes the check the live node makes.
    assert_eq!(report.task_problem(), None);
    let task = task_geometry(&report, &world);
    let mut policy = HeuristicPolicy::new(HeuristicConfig::default());
    let mut wrench = WrenchHistory::default();
    let mut stack_obs = Vec::new();
    // The roll reference and the step of the first frame this test
    // received of the episode.
    let mut roll_ref = None;
    let start = Instant::now();
    // The frames the reset drained while it waited for its answer come
    // first: the episode's first frames, up to its first action request.
    let mut early = node.take_early_frames();
    while stack_obs.len() < actions {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "lockstep stalled"
        );
        let mut frames: Vec<_> = std::mem::take(&mut early)
            .into_iter()
            .filter(|f| f.header.episode == episode)
            .collect();
        transport::drain(&node.sensor, |f| {
            if f.header.episode == episode {
                frames.push(*f)
            }
        })
        .unwrap();
        for f in frames {
            roll_ref.get_or_insert_with(|| (learner_node::proprio::roll_reference(&f), f.step));
            wrench.push(f.wrench);
            if (f.step + 1).is_multiple_of(ACTION_PERIOD_STEPS) {
                let obs = Observation::from_frame(&f, roll_ref.expect("first frame").0);
                let a = policy.act(&obs, &wrench, &task);
                node.send_action(episode, f.header.t_hw_ns, f.step + 1, a)
                    .unwrap();
                stack_obs.push((f.step, obs.ee_pos, obs.proprio, a));
            }
        }
        std::thread::yield_now();
    }

    // In one process. The fast path's roll reference is its first cycle's
    // frame; this test's is the first frame of the episode it received,
    // which, with the reset's early frames, is the episode's first.
    // (2026-11-26: without them, on a busy machine, the roll was 1e-13 rad
    // off at action 0, every other value equal; had the reset drained the
    // first action request too, it answered it with zeros itself.) Both
    // sides' observations take this test's reference, so that a failure
    // here is one of the frames themselves.
    let (roll_ref, first_step) = roll_ref.expect("a frame");
    assert_eq!(first_step, 0, "the episode's first frame was not received");
    let mut env = FastEnv::new(world.clone(), rt_controller::ControllerConfig::default()).unwrap();
    env.reset(seed).unwrap();
    let mut policy = HeuristicPolicy::new(HeuristicConfig::default());
    let own = env.step(None).unwrap();
    let mut obs = Observation::from_frame(env.sensor_frame(), roll_ref);
    assert_eq!(own.proprio, obs.proprio, "the fast path's roll reference");
    for (k, (step, ee, proprio, a_stack)) in stack_obs.iter().enumerate() {
        assert_eq!(
            obs.step, *step,
            "the test's first frame was step {first_step}"
        );
        assert_eq!(
            obs.ee_pos,
            *ee,
            "action {k} (step {step}): the end-effector differs by {:e} m",
            (obs.ee_pos - ee).norm()
        );
        // Proprioception (the roll from the same reference) too.
        assert_eq!(
            obs.proprio, *proprio,
            "action {k}: proprioception differs (the test's first frame was step {first_step})"
        );
        let a = policy.act(&obs, &env.wrench, &task);
        assert_eq!(&a, a_stack, "action {k} differs");
        env.step(Some(&a)).unwrap();
        obs = Observation::from_frame(env.sensor_frame(), roll_ref);
    }
}
