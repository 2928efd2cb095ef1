//! Trained policies (ground truth and representation) drive the stack live.

use shared_mem_schema::PolicyAction;
use std::process::Command;

/// Writes a policy checkpoint of `policy` observing `observation` (the
/// rest of the run's configuration at its defaults) as `dir/name`.
fn policy_checkpoint(
    dir: &std::path::Path,
    name: &str,
    policy: learner::rl::GaussianPolicy,
    observation: learner::rl::observe::ObservationKind,
) -> std::path::PathBuf {
    use learner::rl::run::{Checkpoint, TrainConfig};
    use learner::rl::{Baseline, TrainerState};
    let mut config = TrainConfig {
        observation,
        ..TrainConfig::default()
    };
    // Steps of up to 5 mm (the default is 1.5 mm): the hand-made centring
    // policy then crosses its 4.6 cm within the short lockstep episode.
    config.env.action.max_step_m = 0.005;
    let c = Checkpoint {
        config,
        state: TrainerState::fresh(policy, Baseline::default(), 1),
        history: Vec::new(),
        best: None,
        validations: Vec::new(),
        best_validated: None,
    };
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
    path
}

/// Runs one lockstep episode of `seed` and `seconds` (none: the
/// checkpoint's episode length) through the stack with the policy
/// `checkpoint`; returns the episode's log.
fn policy_episode(
    dir: &std::path::Path,
    checkpoint: &std::path::Path,
    seed: u64,
    seconds: Option<u32>,
) -> learner_node::log::LogReader {
    let mut cmd = Command::new(tests::stack_bins().join("learner"));
    cmd.args(["stack", "--lockstep", "--episodes", "1", "--seed"])
        .arg(seed.to_string());
    if let Some(s) = seconds {
        cmd.arg("--episode-timeout-s").arg(s.to_string());
    }
    let out = cmd
        .arg("--namespace")
        .arg(tests::unique_namespace("policy"))
        .arg("--policy")
        .arg(checkpoint)
        .arg("--log-dir")
        .arg(dir)
        .output()
        .expect("running learner stack");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let log = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("the episode's log");
    learner_node::log::LogReader::open(&log).unwrap()
}

/// A policy checkpoint that centres the tip over the hole of episode
/// `seed` from the ground truth: hidden unit k = tanh(4·obs[k]) for the
/// tip's x and y in the hole frame (obs = s/0.1 m), the base-frame step
/// −R·h (R the hole frame's rotation, from the fast path's world of the same
/// seed; ×5 mm), no descent and no roll. It acts only through the
/// observation the live node rebuilds.
fn centring_policy(dir: &std::path::Path, seed: u64) -> std::path::PathBuf {
    let (obs, hidden, act) = (learner::rl::observe::GROUND_TRUTH_DIM, 2, 4);
    let mut net = vec![0.0; hidden * obs + hidden + act * hidden + act];
    net[0] = 4.0; // w1[0][0]: s_x
    net[obs + 1] = 4.0; // w1[1][1]: s_y
    let mut env = learner::rl::RlEnv::new(&Default::default()).unwrap();
    env.reset(seed, false).unwrap();
    let r = env.task_geometry().hole_pose.rotation.to_rotation_matrix();
    let w2 = hidden * obs + hidden;
    for i in 0..2 {
        for j in 0..2 {
            net[w2 + i * hidden + j] = -r[(i, j)]; // w2[i][j]
        }
    }
    let policy = learner::rl::GaussianPolicy {
        sizes: vec![obs, hidden, act],
        net,
        log_std: vec![0.0; act],
        obs_norm: None,
    };
    let path = policy_checkpoint(
        dir,
        "centring.json",
        policy,
        learner::rl::observe::ObservationKind::GroundTruth,
    );
    // A training world, controller and episode length unlike the stack's
    // defaults, which a run without --world, --controller-config or
    // --episode-timeout-s takes from the checkpoint: another camera (the
    // ground-truth policy does not look), ten times stiffer tilts, 3 s.
    let mut c = learner::rl::run::read_checkpoint(&path).unwrap();
    c.config.env.world.camera.eye_m = [0.901, -0.241, 0.773];
    c.config.env.controller.impedance.kp[3] = 3000.0;
    c.config.env.controller.impedance.kp[4] = 3000.0;
    c.config.env.max_steps = 60;
    std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
    path
}

#[test]
fn a_trained_policy_drives_the_stack_live() {
    use shared_mem_schema::EpisodeReport;
    let _g = tests::exclusive();
    let dir = test_support::scratch_dir("stack-policy");
    let policy = centring_policy(dir.path(), 4);
    let reader = policy_episode(dir.path(), &policy, 4, None);
    let config = reader.read_config(None).unwrap();
    assert_eq!(
        config[0].1.policy,
        learner_node::mix::EpisodePolicy::Learned,
        "the log names the policy"
    );
    // The run took the checkpoint's world, controller and episode length.
    let trained = learner::rl::run::read_checkpoint(&policy)
        .unwrap()
        .config
        .env;
    assert_eq!(config[0].1.world.camera, trained.world.camera, "the world");
    // The daemon's own account of what it ran with: the configuration it
    // prints at start, before its first timestamped log line.
    let log = std::fs::read_to_string(dir.path().join("rt-controller.log")).unwrap();
    let (_, after) = log
        .split_once("# rt-controller effective configuration\n")
        .expect("the daemon printed its configuration");
    let printed: Vec<&str> = after
        .lines()
        .take_while(|l| !l.starts_with(|c: char| c.is_ascii_digit()))
        .collect();
    let ran: rt_controller_daemon::config::DaemonConfig =
        toml::from_str(&printed.join("\n")).unwrap();
    assert_eq!(ran.controller, trained.controller, "the controller");
    let actions = reader
        .read_raw::<PolicyAction>(learner_node::log::topics::ACTION, None)
        .unwrap();
    // 3 s (60 steps) at 20 Hz, the first action after one policy period.
    assert!(
        (55..=61).contains(&actions.len()),
        "{} actions",
        actions.len()
    );
    for a in &actions {
        assert_eq!(a.delta_pos_m[2], 0.0, "no descent");
        assert_eq!(a.delta_roll_rad, 0.0, "no roll");
        assert!(a.delta_pos_m[0].abs() <= 0.005 && a.delta_pos_m[1].abs() <= 0.005);
    }
    let reports = reader
        .read_raw::<EpisodeReport>(learner_node::log::topics::EPISODE, None)
        .unwrap();
    let horizontal = |r: &EpisodeReport| r.s_m[0].hypot(r.s_m[1]);
    let (first, last) = (horizontal(&reports[0]), horizontal(reports.last().unwrap()));
    println!("horizontal distance to the hole: {first:.4} m → {last:.4} m");
    assert!(first > 0.02, "the episode starts off the hole: {first}");
    assert!(
        last < 0.003 && last < 0.2 * first,
        "the policy centred the tip over the hole: {first} → {last}"
    );
    // `--last` takes the checkpoint's last policy over its best: here a
    // zero policy (every action 0) after the centring one as the best.
    let mut c = learner::rl::run::read_checkpoint(&policy).unwrap();
    let centring = c.state.policy.clone();
    c.best = Some(learner::rl::run::BestPolicy {
        iteration: 1,
        env_steps: 0,
        mean_normalised: 1.0,
        policy: centring,
    });
    c.state.policy.net.iter_mut().for_each(|w| *w = 0.0);
    let both = dir.path().join("best-and-last.json");
    std::fs::write(&both, serde_json::to_vec(&c).unwrap()).unwrap();
    let out = Command::new(tests::stack_bins().join("learner"))
        .args(["stack", "--lockstep", "--episodes", "1", "--seed", "4"])
        .args(["--episode-timeout-s", "1", "--namespace"])
        .arg(tests::unique_namespace("policy-last"))
        .arg("--log-dir")
        .arg(dir.path().join("last-logs"))
        .arg("--policy")
        .arg(&both)
        .arg("--last")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr) + String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}");
    assert!(said.contains("acting with the last policy"), "{said}");
    let log = std::fs::read_dir(dir.path().join("last-logs"))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("the episode's log");
    let actions = learner_node::log::LogReader::open(&log)
        .unwrap()
        .read_raw::<PolicyAction>(learner_node::log::topics::ACTION, None)
        .unwrap();
    assert!(actions.len() >= 15, "{} actions", actions.len());
    assert!(
        actions.iter().all(|a| a.delta_pos_m == [0.0; 3]),
        "the last (zero) policy acted: {:?}",
        actions[0].delta_pos_m
    );
}

/// A representation policy live: an untrained Full Model (d = 16, the
/// camera's 128 px) exported as `learner repr train` exports one, and a
/// random policy on its z means. The run must act every policy step, and
/// its actions must change as the scene does: without camera frames the
/// representation gives zeros, and the actions would all be the same.
#[test]
fn a_representation_policy_drives_the_stack_live() {
    use learner::models::{ModelConfig, Normaliser, ReprNet, init};
    use learner::rl::GaussianPolicy;
    use learner::rl::observe::ObservationKind;
    let _g = tests::exclusive();
    let dir = test_support::scratch_dir("stack-repr-policy");
    let model_dir = dir.join("model");
    let model = ModelConfig {
        latent_dim: 16,
        depth_convs_per_stage: 1,
        ..ModelConfig::default()
    };
    let dev = burn::prelude::Device::flex();
    let net = init::seeded(ReprNet::new(&model, &dev), 5);
    // Trained, as it were, through the default world's camera, which the
    // stack's hw-sim has.
    let export = |dir: &std::path::Path, camera: hw_sim::config::CameraConfig| {
        learner::train::checkpoint::export(
            dir,
            &net,
            &learner::train::checkpoint::ExportMeta {
                model: model.clone(),
                normaliser: Normaliser::identity(),
                dataset: "none (untrained)".into(),
                epochs: 0,
                camera: Some(camera.calibration()),
            },
        )
        .unwrap()
    };
    export(&model_dir, hw_sim::config::CameraConfig::default());
    let mut rng = stack_common::rng::seeded(9, 0);
    let mut policy = GaussianPolicy::new(16, &[8], 4, 0.0, &mut rng);
    // Larger output weights than a fresh policy's: actions that follow z.
    for w in &mut policy.net {
        *w *= 10.0;
    }
    let ckpt = policy_checkpoint(
        dir.path(),
        "policy.json",
        policy,
        ObservationKind::Representation(model_dir.clone()),
    );
    // The same model as if trained through another camera is refused
    // before any process starts, the camera named.
    let moved_dir = dir.join("moved-model");
    let mut moved = hw_sim::config::CameraConfig::default();
    moved.eye_m[2] += 0.1;
    export(&moved_dir, moved);
    let mut p = learner::rl::run::read_checkpoint(&ckpt).unwrap();
    p.config.observation = ObservationKind::Representation(moved_dir);
    let moved_ckpt = dir.join("moved-policy.json");
    std::fs::write(&moved_ckpt, serde_json::to_vec(&p).unwrap()).unwrap();
    // The arguments of a real episode, so that a check that stopped
    // refusing would run one short episode in its own namespace, not hang.
    let out = Command::new(tests::stack_bins().join("learner"))
        .args([
            "stack",
            "--lockstep",
            "--episodes",
            "1",
            "--episode-timeout-s",
            "1",
        ])
        .arg("--namespace")
        .arg(tests::unique_namespace("policy-moved"))
        .arg("--log-dir")
        .arg(dir.join("moved-logs"))
        .arg("--policy")
        .arg(&moved_ckpt)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("is not the camera the representation was trained with"),
        "{stderr}"
    );
    let reader = policy_episode(dir.path(), &ckpt, 2, Some(2));
    let actions = reader
        .read_raw::<PolicyAction>(learner_node::log::topics::ACTION, None)
        .unwrap();
    assert!(actions.len() >= 35, "{} actions", actions.len());
    let distinct = |k: usize| {
        let mut v: Vec<f64> = actions[1..].iter().map(|a| a.delta_pos_m[k]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v.len()
    };
    assert!(
        distinct(0) > 5 && distinct(1) > 5,
        "the actions do not follow the scene: {:?}",
        &actions[..5]
            .iter()
            .map(|a| a.delta_pos_m)
            .collect::<Vec<_>>()
    );
}
