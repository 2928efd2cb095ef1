//! End-to-end tests that start the real processes: hw-sim, rt-controller
//! and the policy node, over real shared memory. The test process plays the
//! learner (or a misbehaving peer) where a test needs to see inside.

use hw_sim::WorldConfig;
use learner::env::FastEnv;
use learner_node::live::{PolicyNode, task_geometry};
use learner_node::policy::{HeuristicConfig, HeuristicPolicy, Observation, WrenchHistory};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::transport::{self, Channel, TransportError};
use shared_mem_schema::{
    ControllerMode, ControllerStatus, HardwareState, PolicyAction, SCHEMA_VERSION, SensorFrame,
    TorqueCommand,
};
use std::process::Command;
use std::time::{Duration, Instant};
use test_support::{RngExt, Uniform};
use tests::wait_for;

#[test]
fn heuristic_policy_completes_insertion_through_the_stack() {
    let _g = tests::exclusive();
    tests::stack_bins();
    for (mode, peg) in [("realtime", "square"), ("lockstep", "triangle")] {
        let dir = test_support::scratch_dir(&format!("stack-{mode}"));
        let mut cmd = Command::new(tests::stack_bins().join("learner"));
        cmd.args(["stack", "--episodes", "1", "--peg", peg, "--namespace"])
            .arg(tests::unique_namespace(mode))
            .arg("--log-dir")
            .arg(dir.path());
        if mode == "lockstep" {
            cmd.arg("--lockstep");
        }
        let out = cmd.output().expect("running learner stack");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{mode}: {}\n{stdout}\n{stderr}",
            out.status
        );
        assert!(
            stdout.contains(": completed after"),
            "{mode} {peg}: not completed:\n{stdout}\n{stderr}"
        );
        // The user's episodes count from 1 (hw-sim's idle start is not one).
        let numbers: Vec<&str> = stdout
            .lines()
            .filter_map(|l| l.strip_prefix("episode "))
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        assert_eq!(numbers, ["1"], "{mode}: episodes printed:\n{stdout}");
        let logs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "mcap"))
            .collect();
        assert_eq!(logs.len(), 1, "{mode}: one MCAP log per episode");
        assert!(
            logs[0]
                .file_name()
                .to_string_lossy()
                .starts_with("episode-0001-"),
            "{mode}: log {:?}",
            logs[0].file_name()
        );
        assert!(logs[0].metadata().unwrap().len() > 10_000);
        check_sensor_frames_accounted(mode, &stdout, &logs[0].path());
        let ctl = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap();
        assert!(
            !ctl.contains("mode fault"),
            "{mode}: controller faulted:\n{ctl}"
        );
    }
}

/// The counts in `learner run`'s episode line (`sensor frames: N logged, M
/// missing in G gaps (A hardware steps without a controller frame, B
/// published but not recorded)`).
fn episode_frame_counts(stdout: &str) -> [u64; 5] {
    let line = stdout
        .lines()
        .find(|l| l.starts_with("episode "))
        .unwrap_or_else(|| panic!("no episode line:\n{stdout}"));
    let (_, rest) = line
        .split_once("sensor frames: ")
        .unwrap_or_else(|| panic!("no sensor frame counts: {line}"));
    let numbers: Vec<u64> = rest
        .split(|c: char| !c.is_ascii_digit())
        .filter(|w| !w.is_empty())
        .take(5)
        .map(|w| w.parse().unwrap())
        .collect();
    numbers
        .try_into()
        .unwrap_or_else(|_| panic!("counts: {line}"))
}

/// Every frame the controller published is in the episode's log, or counted
/// as lost: the counts the policy node printed are the gaps the log shows.
/// In lockstep no hardware step goes without a frame, and the log begins at
/// the episode's first step.
fn check_sensor_frames_accounted(mode: &str, stdout: &str, log: &std::path::Path) {
    let [logged, missing, gaps, not_published, not_recorded] = episode_frame_counts(stdout);
    let reader = learner_node::log::LogReader::open(log).unwrap();
    let all = learner_node::log::log_gaps(&reader).unwrap();
    let g = &all[0];
    assert_eq!(g.topic, learner_node::log::topics::SENSOR, "{all:?}");
    let loss = g.sensor.unwrap();
    assert_eq!(
        [
            g.messages,
            g.missing,
            g.gaps,
            loss.not_published,
            loss.not_recorded
        ],
        [logged, missing, gaps, not_published, not_recorded],
        "{mode}: the printed counts differ from the log's gaps"
    );
    assert_eq!(missing, not_published + not_recorded, "{mode}");
    if mode == "lockstep" {
        assert_eq!(missing, 0, "{mode}: {all:?}");
        let frames = reader
            .read_raw::<SensorFrame>(learner_node::log::topics::SENSOR, None)
            .unwrap();
        assert_eq!(
            frames[0].step, 0,
            "{mode}: the log misses the episode's first frames"
        );
    }
}

fn start_sim_and_controller(
    ns: &str,
    dir: &std::path::Path,
) -> (learner_node::stack::Managed, learner_node::stack::Managed) {
    let sim = tests::start("hw-sim", &["--namespace", ns, "--no-camera"], dir);
    let ctl = tests::start("rt-controller", &["--namespace", ns, "--no-realtime"], dir);
    (sim, ctl)
}

/// An action answering `frame` (its episode and hardware time), as a
/// policy node stamps it: the daemon drops actions answering no frame of
/// the current episode, or one older than two policy periods.
fn action(seq: u64, dx: f64, version: u32, frame: &SensorFrame) -> PolicyAction {
    let mut a = PolicyAction::new(seq, mono_now_ns(), [dx, 0.0, 0.0, 0.0]);
    a.header.schema_version = version;
    a.header.episode = frame.header.episode;
    a.header.t_hw_ns = frame.header.t_hw_ns;
    a
}

/// The newest sensor frame, waiting up to 5 s for one.
fn latest(frames: &transport::Sub<SensorFrame>) -> SensorFrame {
    let mut newest = wait_for(frames, Duration::from_secs(5), |_| true).expect("sensor frames");
    transport::drain(frames, |f| newest = *f).unwrap();
    newest
}

#[test]
fn losing_the_policy_holds_within_100ms_and_its_return_resumes() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("policy-loss");
    let dir = test_support::scratch_dir("policy-loss");
    let (_sim, _ctl) = start_sim_and_controller(&ns, &dir);
    let node = transport::create_node("e2e-observer").unwrap();
    let frames = transport::subscriber::<SensorFrame>(&node, &ns).unwrap();
    let mut policy = tests::start(
        "learner",
        &[
            "run",
            "--episodes",
            "1",
            "--episode-timeout-s",
            "60",
            "--namespace",
            &ns,
            "--log-dir",
            dir.to_str().unwrap(),
        ],
        &dir,
    );
    // The hardware time at which the applied action last changed, followed
    // in every frame from the start: the first frame after the kill may
    // come up to 50 ms after the last action was applied.
    // Also the hardware time of the last frame still Running.
    let mut last_action = (0u64, 0u64);
    let mut last_running = 0u64;
    let mut follow = |f: &SensorFrame| {
        if f.action_seq != last_action.0 {
            last_action = (f.action_seq, f.header.t_hw_ns);
        }
        if f.mode == ControllerMode::Running as u32 {
            last_running = f.header.t_hw_ns;
        }
    };
    let running = wait_for(&frames, Duration::from_secs(30), |f| {
        follow(f);
        f.mode == ControllerMode::Running as u32 && f.action_seq > 10
    });
    assert!(running.is_some(), "the policy never drove the controller");
    policy.signal(libc::SIGKILL);
    policy.wait_timeout(Duration::from_secs(5)).expect("killed");
    // The last action applied, then the first frame in Holding.
    let holding = wait_for(&frames, Duration::from_secs(5), |f| {
        follow(f);
        f.mode == ControllerMode::Holding as u32
    })
    .expect("the controller never held");
    // The controller held at its first cycle past the timeout: it still
    // ran at most 0.1 s after the last action. (The first Holding frame may
    // come later than 0.1 s + 1 ms when a loaded hw-sim's states were
    // skipped; the hardware clock jumps over them.)
    let ran_s = (last_running - last_action.1) as f64 * 1e-9;
    let gap_s = (holding.header.t_hw_ns - last_action.1) as f64 * 1e-9;
    assert!(
        ran_s <= 0.1 + 1e-6,
        "still running {ran_s:.4} s after the last action (timeout 0.1 s)"
    );
    // The supervisor compares times in f64 seconds: at some absolute times
    // 100 ms after the action already counts as past 0.1 s, so the hold may
    // come exactly 100 ms after it (seen once on a loaded machine).
    assert!(
        gap_s > 0.1 - 1e-6 && gap_s < 0.2,
        "held {gap_s:.4} s after the last action (timeout 0.1 s)"
    );
    // The policy comes back: actions resume the run.
    let back = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    let mut seq = 1_000_000;
    let resumed = {
        let start = Instant::now();
        let mut hit = None;
        while hit.is_none() && start.elapsed() < Duration::from_secs(5) {
            seq += 1;
            let a = action(seq, 0.0, SCHEMA_VERSION, &latest(&frames));
            transport::send(&back, &a).unwrap();
            hit = wait_for(&frames, Duration::from_millis(50), |f| {
                f.mode == ControllerMode::Running as u32
            });
        }
        hit
    };
    assert!(resumed.is_some(), "actions did not resume the run");
    // A frozen policy: the same message again and again at 20 Hz. It was
    // applied once; its repetitions are replays (and soon too old): the
    // controller holds.
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let frozen = action(2_000_000, 0.0, SCHEMA_VERSION, &latest(&frames));
    let held = {
        let start = Instant::now();
        let mut hit = None;
        let mut applied = false;
        while hit.is_none() && start.elapsed() < Duration::from_secs(10) {
            transport::send(&back, &frozen).unwrap();
            hit = wait_for(&frames, Duration::from_millis(50), |f| {
                applied |= f.action_seq == frozen.header.seq;
                applied && f.mode == ControllerMode::Holding as u32
            });
        }
        hit
    };
    assert!(
        held.is_some(),
        "a frozen policy kept the controller running"
    );
    // A status published after the hold counts the replays (one published
    // between the first replay and the hold still says Running).
    wait_for(&status, Duration::from_secs(2), |s| {
        s.actions_replayed > 0 && s.mode == ControllerMode::Holding as u32
    })
    .expect("no status in Holding counts the replays");
}

#[test]
fn silent_hardware_is_a_fault_with_no_further_torques() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("hw-loss");
    let dir = test_support::scratch_dir("hw-loss");
    let (mut sim, _ctl) = start_sim_and_controller(&ns, &dir);
    let node = transport::create_node("e2e-observer").unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    assert!(
        wait_for(&torques, Duration::from_secs(20), |_| true).is_some(),
        "no torque commands at all"
    );
    sim.signal(libc::SIGKILL);
    sim.wait_timeout(Duration::from_secs(5)).expect("killed");
    let lost = wait_for(&status, Duration::from_secs(2), |s| {
        s.mode == ControllerMode::HardwareLost as u32
    })
    .expect("the controller never reported the hardware lost");
    assert_eq!(
        lost.fault_code,
        rt_controller::daemon::FAULT_HARDWARE_SILENT
    );
    // Whatever was in flight is gone; nothing new may come.
    std::thread::sleep(Duration::from_millis(20));
    transport::drain(&torques, |_| {}).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let late = transport::drain(&torques, |_| {}).unwrap();
    assert_eq!(
        late, 0,
        "{late} torque commands after the hardware went silent"
    );
}

/// The lines of `log` longer than `max` characters, or iceoryx2's
/// config-file warning.
fn noisy_lines(log: &str, max: usize) -> Vec<String> {
    log.lines()
        .filter(|l| l.chars().count() > max || l.contains("No config file"))
        .map(|l| l.chars().take(400).collect())
        .collect()
}

#[test]
fn a_killed_peer_costs_the_others_no_long_log_lines() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("quiet");
    let dir = test_support::scratch_dir("quiet");
    let (_sim, mut ctl) = start_sim_and_controller(&ns, &dir.join("first"));
    let node = transport::create_node("e2e-observer").unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    assert!(
        wait_for(&torques, Duration::from_secs(20), |_| true).is_some(),
        "no torque commands at all"
    );
    // A controller killed: its node is dead, its ports stay behind; the
    // next one removes them at its start, while hw-sim keeps serving.
    ctl.signal(libc::SIGKILL);
    ctl.wait_timeout(Duration::from_secs(5)).expect("killed");
    std::thread::sleep(Duration::from_millis(300));
    let mut ctl = tests::start(
        "rt-controller",
        &["--namespace", &ns, "--no-realtime"],
        &dir.join("second"),
    );
    transport::drain(&torques, |_| {}).unwrap();
    assert!(
        wait_for(&torques, Duration::from_secs(20), |_| true).is_some(),
        "the second controller sent no torques"
    );
    std::thread::sleep(Duration::from_millis(300));
    ctl.stop(Duration::from_secs(5));
    for log in [
        "first/hw-sim.log",
        "first/rt-controller.log",
        "second/rt-controller.log",
    ] {
        let text = std::fs::read_to_string(dir.join(log)).unwrap();
        let noisy = noisy_lines(&text, 300);
        assert!(noisy.is_empty(), "{log}: {noisy:#?}");
    }
}

#[test]
fn processes_of_another_schema_version_are_refused() {
    let _g = tests::exclusive();
    // A peer built with another version owns the hardware service: the
    // daemon must refuse to start, saying why.
    let ns = tests::unique_namespace("schema");
    let dir = test_support::scratch_dir("schema");
    let node = transport::create_node("e2e-other-version").unwrap();
    let _other = Channel::<HardwareState>::open_as_version(&node, &ns, SCHEMA_VERSION + 1).unwrap();
    let mut ctl = tests::start(
        "rt-controller",
        &["--namespace", &ns, "--no-realtime"],
        &dir,
    );
    let status = ctl
        .wait_timeout(Duration::from_secs(20))
        .expect("the daemon kept running against another schema version");
    assert!(!status.success());
    let log = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap();
    assert!(
        log.contains(&format!("schema version {}", SCHEMA_VERSION + 1))
            && log.contains(&format!("schema version {SCHEMA_VERSION}")),
        "the error does not name both versions:\n{log}"
    );
    // And the other way round: our services refuse a peer of another version.
    let ns2 = tests::unique_namespace("schema2");
    let _sim = tests::start("hw-sim", &["--namespace", &ns2, "--no-camera"], &dir);
    let ours = transport::create_node("e2e-ours").unwrap();
    assert!(
        wait_for(
            &transport::subscriber::<HardwareState>(&ours, &ns2).unwrap(),
            Duration::from_secs(20),
            |_| true
        )
        .is_some()
    );
    match Channel::<HardwareState>::open_as_version(&node, &ns2, SCHEMA_VERSION + 1) {
        Err(TransportError::SchemaMismatch { ours, theirs, .. }) => {
            assert_eq!(ours, SCHEMA_VERSION + 1);
            assert_eq!(theirs, SCHEMA_VERSION.to_string());
        }
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a peer of another schema version was let in"),
    }
}

#[test]
fn garbage_actions_never_produce_torques_beyond_limits() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("garbage");
    let dir = test_support::scratch_dir("garbage");
    let (_sim, _ctl) = start_sim_and_controller(&ns, &dir);
    let model = robot_model::descriptions::builtin("iiwa14").unwrap();
    let limits = model.effort_limits();
    let cfg = rt_controller::ControllerConfig::default();
    let max_rate_step = cfg.qp.torque_rate_limit_nm_s * cfg.period_s;
    let node = transport::create_node("e2e-garbage").unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    let frames = transport::subscriber::<SensorFrame>(&node, &ns).unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let publisher = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    assert!(wait_for(&torques, Duration::from_secs(20), |_| true).is_some());
    let specials = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        f64::MIN_POSITIVE / 4.0,
        -f64::MIN_POSITIVE / 3.0,
        1e300,
        -1e300,
        f64::MAX,
        0.5,
        -0.2,
    ];
    let mut rng = test_support::rng(7);
    let mut checked = 0usize;
    let mut bad = Vec::new();
    let mut rate_bad = Vec::new();
    let mut prev: Option<TorqueCommand> = None;
    let mut check = |c: &TorqueCommand| {
        for (i, &t) in c.tau[..7].iter().enumerate() {
            if !(t.is_finite() && t.abs() <= limits[i] + 1e-9) {
                bad.push((c.state_step, i, t));
            }
        }
        // Commands of consecutive steps of one episode: the rate limit.
        if let Some(p) = prev
            .filter(|p| p.header.episode == c.header.episode && p.state_step + 1 == c.state_step)
        {
            for i in 0..7 {
                let d = (c.tau[i] - p.tau[i]).abs();
                if d.is_nan() || d > max_rate_step + 1e-9 {
                    rate_bad.push((c.state_step, i, d));
                }
            }
        }
        prev = Some(*c);
        checked += 1;
    };
    const N: u64 = 4000;
    let (mut bad_schema, mut bad_value) = (0u64, 0u64);
    let mut newest = latest(&frames);
    for k in 0..N {
        let mut a = action(k + 1, 0.0, SCHEMA_VERSION, &newest);
        let pick = |rng: &mut test_support::Rng| match rng.random_range(0..3) {
            0 => specials[rng.random_range(0..specials.len())],
            1 => rng.uniform(-0.01, 0.01), // plausible steps
            _ => rng.uniform(-1e3, 1e3),   // far out of range
        };
        a.delta_pos_m = [pick(&mut rng), pick(&mut rng), pick(&mut rng)];
        a.delta_roll_rad = pick(&mut rng);
        if rng.random_range(0..50) == 0 {
            a.header.schema_version = SCHEMA_VERSION + rng.random_range(1..6);
            bad_schema += 1;
        } else if rt_controller::supervisor::Supervisor::check_action(&cfg.safety, &a.delta())
            .is_err()
        {
            bad_value += 1;
        }
        transport::send(&publisher, &a).unwrap();
        // One action in flight: wait for the second sensor frame published
        // after the send. Its cycle began after the first one's publication,
        // so it drained and applied this action; neither the daemon's
        // subscriber buffer nor its queue can overflow, however the
        // scheduler treats the processes.
        let sent = mono_now_ns();
        let mut after = 0;
        let deadline = Instant::now() + Duration::from_secs(10);
        while after < 2 {
            assert!(
                Instant::now() < deadline,
                "no sensor frames after action {k}"
            );
            transport::drain(&frames, |f| {
                after += (f.header.t_mono_ns > sent) as u32;
                newest = *f;
            })
            .unwrap();
            transport::drain(&torques, &mut check).unwrap();
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    transport::drain(&torques, &mut check).unwrap();
    assert!(checked > 1000, "only {checked} torque commands seen");
    assert!(
        bad.is_empty(),
        "torques beyond limits: {:?}",
        &bad[..bad.len().min(5)]
    );
    assert!(
        rate_bad.is_empty(),
        "torque steps beyond the rate limit ({max_rate_step} N·m): {:?}",
        &rate_bad[..rate_bad.len().min(5)]
    );
    let s = wait_for(&status, Duration::from_secs(10), |s| {
        s.actions_received >= N
    })
    .expect("the status never counted the actions");
    assert_eq!(s.actions_received, N);
    // One action in flight: the queue never overflows, so every rejection
    // below is the validation's, not a flood's.
    assert_eq!(s.actions_overflow, 0, "{s:?}");
    // Every action received is accounted for exactly once. Each answers a
    // frame published a moment before: stale only if the machine stalled
    // for two policy periods (then counted as such).
    let stale =
        s.actions_too_old + s.actions_from_future + s.actions_other_episode + s.actions_replayed;
    assert_eq!(
        s.actions_accepted + s.actions_rejected + s.actions_ignored + s.actions_overflow + stale,
        N,
        "{s:?}"
    );
    assert_eq!(
        s.actions_from_future + s.actions_other_episode + s.actions_replayed,
        0,
        "{s:?}"
    );
    assert!(
        bad_schema > 0 && bad_value > N / 2,
        "{bad_schema} {bad_value}"
    );
    if s.faults == 0 {
        // Another schema is refused on arrival; a bad value only when not
        // dropped as stale before the control law sees it.
        assert!(s.actions_rejected <= bad_schema + bad_value, "{s:?}");
        assert!(
            s.actions_rejected + stale >= bad_schema + bad_value,
            "{s:?}"
        );
        assert_eq!(s.actions_ignored, 0);
    } else {
        // In Fault valid and invalid actions alike are ignored.
        assert!(s.actions_rejected >= bad_schema, "{s:?}");
        assert!(s.actions_rejected + s.actions_ignored >= bad_schema + bad_value);
    }
}

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

#[test]
fn systemd_notifications_and_sigterm_hold_then_clean_exit() {
    use std::os::unix::net::UnixDatagram;
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("systemd");
    let dir = test_support::scratch_dir("systemd");
    let sock_path = dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let _sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], &dir);
    let mut cmd = Command::new(tests::stack_bins().join("rt-controller"));
    cmd.args(["--namespace", &ns, "--no-realtime"])
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", "1000000");
    let mut ctl = learner_node::stack::Managed::spawn(
        "rt-controller",
        cmd,
        Some(&dir.join("rt-controller.log")),
    )
    .unwrap();
    let node = transport::create_node("e2e-systemd").unwrap();
    let frames = transport::subscriber::<SensorFrame>(&node, &ns).unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(20)
        && !(got.iter().any(|m: &String| m.contains("READY=1"))
            && got.iter().any(|m| m == "WATCHDOG=1"))
    {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    assert!(
        got.iter().any(|m| m.contains("READY=1")),
        "no READY: {got:?}"
    );
    assert!(
        got.iter().any(|m| m == "WATCHDOG=1"),
        "no WATCHDOG: {got:?}"
    );
    assert!(wait_for(&frames, Duration::from_secs(5), |_| true).is_some());
    ctl.signal(libc::SIGTERM);
    let held = wait_for(&frames, Duration::from_secs(2), |f| {
        f.mode == ControllerMode::Holding as u32
    });
    assert!(
        held.is_some(),
        "SIGTERM did not bring the controller to a hold"
    );
    let status = ctl.wait_timeout(Duration::from_secs(5)).expect("exits");
    assert!(status.success(), "exit status {status}");
    let mut stopping = false;
    while let Ok(n) = sock.recv(&mut buf) {
        stopping |= String::from_utf8_lossy(&buf[..n]).contains("STOPPING=1");
    }
    assert!(stopping, "no STOPPING notification");
}

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
        state: TrainerState {
            policy,
            baseline: Baseline::default(),
            iteration: 0,
            env_steps: 0,
            episodes_started: 0,
            seed: 1,
            adam: Default::default(),
        },
        history: Vec::new(),
        best: None,
        validations: Vec::new(),
        best_validated: None,
    };
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
    path
}

/// Runs one lockstep episode of `seed` and `seconds` through the stack
/// with the policy `checkpoint`; returns the episode's log.
fn policy_episode(
    dir: &std::path::Path,
    checkpoint: &std::path::Path,
    seed: u64,
    seconds: u32,
) -> learner_node::log::LogReader {
    let out = Command::new(tests::stack_bins().join("learner"))
        .args(["stack", "--lockstep", "--episodes", "1", "--seed"])
        .arg(seed.to_string())
        .arg("--episode-timeout-s")
        .arg(seconds.to_string())
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
    policy_checkpoint(
        dir,
        "centring.json",
        policy,
        learner::rl::observe::ObservationKind::GroundTruth,
    )
}

#[test]
fn a_trained_policy_drives_the_stack_live() {
    use shared_mem_schema::EpisodeReport;
    let _g = tests::exclusive();
    let dir = test_support::scratch_dir("stack-policy");
    let policy = centring_policy(dir.path(), 4);
    let reader = policy_episode(dir.path(), &policy, 4, 3);
    let config = reader.read_config(None).unwrap();
    assert_eq!(
        config[0].1.policy,
        learner_node::mix::EpisodePolicy::Learned,
        "the log names the policy"
    );
    let actions = reader
        .read_raw::<PolicyAction>(learner_node::log::topics::ACTION, None)
        .unwrap();
    // 3 s at 20 Hz, the first action after one policy period.
    assert!(actions.len() >= 55, "{} actions", actions.len());
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
    let mut rng = hw_sim::rng::seeded(9, 0);
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
    let reader = policy_episode(dir.path(), &ckpt, 2, 2);
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
