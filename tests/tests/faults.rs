//! The fault policy through the real processes: a restarted hw-sim leaves
//! rt-controller down (no torques) until an operator's `rt-controller
//! reset`, which is refused while the hardware is silent; the learner's
//! episode driver resets a latched fault where a new episode starts, and the
//! daemon counts and logs every reset.

use shared_mem_schema::transport;
use shared_mem_schema::{ControllerMode, ControllerStatus, HardwareState, TorqueCommand};
use std::process::{Command, Output};
use std::time::Duration;
use tests::wait_for;

/// `rt-controller --namespace <ns> reset`, the operator's command.
fn reset_cli(ns: &str) -> Output {
    Command::new(tests::stack_bins().join("rt-controller"))
        .args(["--namespace", ns, "reset", "--timeout-s", "10"])
        .output()
        .expect("running rt-controller reset")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn a_restarted_simulator_leaves_the_controller_down_until_a_reset() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("hw-restart");
    let dir = test_support::scratch_dir("hw-restart");
    let mut sim = tests::start(
        "hw-sim",
        &["--namespace", &ns, "--no-camera"],
        &dir.join("first"),
    );
    let mut ctl = tests::start(
        "rt-controller",
        &["--namespace", &ns, "--no-realtime"],
        &dir,
    );
    let node = transport::create_node("e2e-restart").unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    let states = transport::subscriber::<HardwareState>(&node, &ns).unwrap();
    assert!(
        wait_for(&torques, Duration::from_secs(20), |_| true).is_some(),
        "no torque commands at all"
    );
    sim.signal(libc::SIGKILL);
    sim.wait_timeout(Duration::from_secs(5)).expect("killed");
    wait_for(&status, Duration::from_secs(5), |s| {
        s.mode == ControllerMode::HardwareLost as u32
    })
    .expect("the controller never reported the hardware lost");
    // The operator's reset is refused while the hardware is silent.
    let refused = reset_cli(&ns);
    assert!(!refused.status.success(), "{}", text(&refused));
    assert!(text(&refused).contains("silent"), "{}", text(&refused));

    // hw-sim comes back (systemd restarts it): a fresh stream from step 0.
    let _sim = tests::start(
        "hw-sim",
        &["--namespace", &ns, "--no-camera"],
        &dir.join("second"),
    );
    transport::drain(&states, |_| {}).unwrap();
    wait_for(&states, Duration::from_secs(20), |_| true).expect("the new hw-sim streams");
    // The controller stays down: no torques, still hardware-lost in a
    // status published after the new stream came.
    transport::drain(&torques, |_| {}).unwrap();
    let streaming = shared_mem_schema::process::mono_now_ns();
    let s = wait_for(&status, Duration::from_secs(5), |s| {
        s.header.t_mono_ns > streaming
    })
    .expect("status");
    assert_eq!(s.mode, ControllerMode::HardwareLost as u32, "{s:?}");
    std::thread::sleep(Duration::from_millis(300));
    let late = transport::drain(&torques, |_| {}).unwrap();
    assert_eq!(
        late, 0,
        "{late} torque commands to the restarted hw-sim before a reset"
    );
    // The subscriber keeps only the newest few states: judge the stream by
    // the step it reached (a fresh hw-sim counts from 0).
    let mut newest = 0;
    transport::drain(&states, |m| newest = newest.max(m.step)).unwrap();
    assert!(
        newest > 100,
        "the new hw-sim stopped streaming (newest step {newest})"
    );

    // The operator's reset clears it: torques again, from Idle, counted.
    let cleared = reset_cli(&ns);
    assert!(cleared.status.success(), "{}", text(&cleared));
    assert!(text(&cleared).contains("cleared"), "{}", text(&cleared));
    assert!(
        wait_for(&torques, Duration::from_secs(5), |_| true).is_some(),
        "no torques after the reset"
    );
    let s = wait_for(&status, Duration::from_secs(5), |s| s.resets == 1)
        .expect("the reset was not counted");
    assert_eq!(s.mode, ControllerMode::Idle as u32, "{s:?}");
    ctl.stop(Duration::from_secs(5));
    let log = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap();
    assert!(
        log.contains("refused: the hardware is silent") && log.contains("fault cleared"),
        "the resets are not logged:\n{log}"
    );
}

#[test]
fn the_learner_resets_a_latched_fault_where_an_episode_starts() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("learner-reset");
    let dir = test_support::scratch_dir("learner-reset");
    // A force limit the peg's own weight exceeds: the controller faults at
    // once, and again after every reset.
    let cfg = dir.join("rt-controller.toml");
    std::fs::write(&cfg, "[controller.safety]\nmax_force_n = 0.001\n").unwrap();
    let _sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], &dir);
    let mut ctl = tests::start(
        "rt-controller",
        &[
            "--namespace",
            &ns,
            "--no-realtime",
            "--config",
            cfg.to_str().unwrap(),
        ],
        &dir,
    );
    let node = transport::create_node("e2e-learner-reset").unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    wait_for(&status, Duration::from_secs(20), |s| {
        s.mode == ControllerMode::Fault as u32
    })
    .expect("the controller did not fault");
    let out = Command::new(tests::stack_bins().join("learner"))
        .args(["run", "--episodes", "2", "--episode-timeout-s", "0.5"])
        .args(["--namespace", &ns, "--log-dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    for e in 1..=2 {
        assert!(
            text(&out).contains(&format!("reset for episode {e}")),
            "episode {e}: no reset\n{}",
            text(&out)
        );
    }
    let s = wait_for(&status, Duration::from_secs(5), |s| s.resets >= 2)
        .expect("the resets were not counted");
    assert_eq!(s.resets, 2, "{s:?}");
    ctl.stop(Duration::from_secs(5));
    let log = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap();
    assert_eq!(log.matches("fault cleared").count(), 2, "{log}");
}
