//! Misbehaving or lost peers: a silent policy, a silent hardware, a killed
//! process, another schema version.

use crate::{action, latest, start_sim_and_controller};
use shared_mem_schema::transport::{self, Channel, TransportError};
use shared_mem_schema::{
    ControllerMode, ControllerStatus, HardwareState, PolicyAction, SCHEMA_VERSION, SensorFrame,
    TorqueCommand,
};
use std::time::{Duration, Instant};
use tests::wait_for;

#[test]
fn losing_the_policy_holds_within_100ms_and_its_return_resumes() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("policy-loss");
    let dir = test_support::scratch_dir("policy-loss");
    let (_sim, _ctl) = start_sim_and_controller(&ns, &dir, &[]);
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
    // The policy comes back, numbering on from its last action (a jump of
    // more than 1000 would be refused as forged): actions resume the run.
    let back = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    let mut seq = last_action.0;
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
    let frozen = action(seq + 1, 0.0, SCHEMA_VERSION, &latest(&frames));
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
    let (mut sim, _ctl) = start_sim_and_controller(&ns, &dir, &[]);
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
    assert_eq!(lost.fault_code, rt_controller_daemon::FAULT_HARDWARE_SILENT);
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
    let (_sim, mut ctl) = start_sim_and_controller(&ns, &dir.join("first"), &[]);
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
