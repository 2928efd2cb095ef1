//! Faults across restarts, through the real processes: with a fault record
//! a latched fault, and a daemon killed while it held the arm, refuse
//! every later start (exit status 3, no torques) until `rt-controller
//! reset`, which clears the record and counts the reset; a clean stop
//! leaves no record; a second daemon on the same record is refused as a
//! bad configuration (exit status 2); exit statuses follow
//! docs/operation.md.

use shared_mem_schema::transport;
use shared_mem_schema::{ControllerMode, ControllerStatus, TorqueCommand};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;
use tests::wait_for;

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The daemon's arguments: its namespace, no real-time set-up, the record.
fn args<'a>(ns: &'a str, record: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "--namespace",
        ns,
        "--no-realtime",
        "--fault-record",
        record.to_str().unwrap(),
    ];
    a.extend_from_slice(extra);
    a
}

/// Runs `rt-controller` to its end (a refused start ends at once; one
/// that runs is stopped after 20 s and fails the test): its exit status and
/// its output.
fn run_to_end(ns: &str, record: &Path, extra: &[&str], log_dir: &Path) -> (Option<i32>, String) {
    let mut p = tests::start("rt-controller", &args(ns, record, extra), log_dir);
    let Some(status) = p.wait_timeout(Duration::from_secs(20)) else {
        p.stop(Duration::from_secs(5));
        panic!("rt-controller {extra:?} did not end by itself");
    };
    let log = std::fs::read_to_string(log_dir.join("rt-controller.log")).unwrap();
    (status.code(), log)
}

/// Waits until the record's file says `what`.
fn wait_for_record(record: &Path, what: &str) {
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !std::fs::read_to_string(record).is_ok_and(|t| t.contains(what)) {
        assert!(std::time::Instant::now() < deadline, "no {what} on record");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_fault_survives_a_kill_and_restart_until_the_operator_resets_it() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("fault-record");
    let dir = test_support::scratch_dir("fault-record");
    let record = dir.join("rt-controller.fault");
    // A force limit the peg's own weight exceeds: the daemon faults as soon
    // as the hardware streams.
    let faulting = dir.join("faulting.toml");
    std::fs::write(&faulting, "[controller.safety]\nmax_force_n = 0.001\n").unwrap();
    let faulting = faulting.to_str().unwrap();
    let _sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], &dir);
    let node = transport::create_node("e2e-fault-record").unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();

    let mut ctl = tests::start(
        "rt-controller",
        &args(&ns, &record, &["--config", faulting]),
        &dir.join("first"),
    );
    wait_for(&status, Duration::from_secs(20), |s| {
        s.mode == ControllerMode::Fault as u32
    })
    .expect("the controller did not fault");
    // The monitor writes the record within its 50 ms period.
    wait_for_record(&record, "fault");
    // A reset command to the running daemon: counted in the history (it
    // faults again at once, and the record says so).
    let (code, log) = run_to_end(
        &ns,
        &record,
        &["reset", "--timeout-s", "10"],
        &dir.join("cmd"),
    );
    assert_eq!(code, Some(0), "{log}");
    let history = dir.join("rt-controller.fault.history");
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !std::fs::read_to_string(&history)
        .is_ok_and(|h| h.matches("fault 4").count() >= 2 && h.contains("reset by a reset command"))
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the second fault is not in the history"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let h = std::fs::read_to_string(&history).unwrap();
    assert!(h.contains("reset by a reset command"), "{h}");
    wait_for_record(&record, "fault");
    // A second daemon on the same record: a configuration error.
    let (code, log) = run_to_end(&ns, &record, &[], &dir.join("beside"));
    assert_eq!(code, Some(2), "{log}");
    assert!(log.contains("holds the fault record"), "{log}");
    // Killed as the watchdog kills it: no clean stop.
    ctl.signal(libc::SIGKILL);
    ctl.wait_timeout(Duration::from_secs(5)).expect("killed");

    // A fresh daemon (systemd's restart) with a configuration that would
    // not fault: refused, exit status 3, and no torques.
    transport::drain(&torques, |_| {}).unwrap();
    let (code, log) = run_to_end(&ns, &record, &[], &dir.join("refused"));
    assert_eq!(code, Some(3), "{log}");
    assert!(
        log.contains("start refused") && log.contains("force overload"),
        "{log}"
    );
    let sent = transport::drain(&torques, |_| {}).unwrap();
    assert_eq!(sent, 0, "{sent} torque commands from a refused start");

    // The operator's reset with no daemon running clears the record,
    // counted in its history.
    let (code, log) = run_to_end(&ns, &record, &["reset"], &dir.join("reset"));
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("cleared the fault record"), "{log}");
    assert!(!record.exists());
    let history = std::fs::read_to_string(dir.join("rt-controller.fault.history")).unwrap();
    assert!(history.contains("fault 4") && history.contains("reset by `rt-controller reset`"));

    // Now a daemon starts and sends torques; a clean stop (SIGTERM) leaves
    // no record and exits 0.
    transport::drain(&torques, |_| {}).unwrap();
    let mut ctl = tests::start(
        "rt-controller",
        &args(&ns, &record, &[]),
        &dir.join("second"),
    );
    assert!(
        wait_for(&torques, Duration::from_secs(20), |_| true).is_some(),
        "no torques after the reset"
    );
    assert!(
        std::fs::read_to_string(&record)
            .unwrap()
            .contains("running")
    );
    // What an operator reads: the status on shared memory and the record.
    let out = Command::new(tests::stack_bins().join("rt-controller"))
        .args(args(
            &ns,
            &record,
            &["status", "--json", "--timeout-s", "10"],
        ))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let status: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(status["fault_code"], 0, "{status}");
    assert_eq!(status["mode"], "idle", "{status}");
    assert!(
        status["fault_record"]
            .as_str()
            .is_some_and(|r| r.starts_with("running")),
        "{status}"
    );
    let end = ctl.stop(Duration::from_secs(5)).expect("stopped");
    assert_eq!(end.code(), Some(0), "a clean stop");
    assert!(!record.exists(), "a clean stop leaves no record");

    // Killed while it held the arm without a fault: the next start is
    // refused as an unclean end, until a reset.
    let mut ctl = tests::start(
        "rt-controller",
        &args(&ns, &record, &[]),
        &dir.join("third"),
    );
    wait_for_record(&record, "running");
    transport::drain(&torques, |_| {}).unwrap();
    assert!(wait_for(&torques, Duration::from_secs(20), |_| true).is_some());
    ctl.signal(libc::SIGKILL);
    ctl.wait_timeout(Duration::from_secs(5)).expect("killed");
    let (code, log) = run_to_end(&ns, &record, &[], &dir.join("refused-again"));
    assert_eq!(code, Some(3), "{log}");
    assert!(log.contains("without a clean stop"), "{log}");
    let (code, log) = run_to_end(&ns, &record, &["reset"], &dir.join("reset-again"));
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("3 resets on record"), "{log}");
}

#[test]
fn a_bad_configuration_exits_2_and_a_stop_with_a_fault_latched_exits_3() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("exit-codes");
    let dir = test_support::scratch_dir("exit-codes");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[controller.safety]\nmax_force_n = -1.0\n").unwrap();
    let out = Command::new(tests::stack_bins().join("rt-controller"))
        .args(["--namespace", &ns, "--config", bad.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    // A Franka without a fault record is a bad configuration.
    let franka = dir.join("franka.toml");
    std::fs::write(
        &franka,
        "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n",
    )
    .unwrap();
    let out = Command::new(tests::stack_bins().join("rt-controller"))
        .args(["--config", franka.to_str().unwrap(), "--print-config"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("fault_record"), "{}", text(&out));

    // No hardware at start-up: exit 1 (a restart may cure it), nothing on
    // record.
    let quick = dir.join("quick.toml");
    std::fs::write(&quick, "[timing]\nstartup_timeout_s = 0.5\n").unwrap();
    let record = dir.join("rt.fault");
    let out = Command::new(tests::stack_bins().join("rt-controller"))
        .args(["--namespace", &format!("{ns}-nobody"), "--no-realtime"])
        .args(["--config", quick.to_str().unwrap()])
        .args(["--fault-record", record.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        !record.exists(),
        "no record after a start that never held the arm"
    );

    // Without a record a fault still sets the exit status.
    let faulting = dir.join("faulting.toml");
    std::fs::write(&faulting, "[controller.safety]\nmax_force_n = 0.001\n").unwrap();
    let _sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], &dir);
    let node = transport::create_node("e2e-exit-codes").unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let mut ctl = tests::start(
        "rt-controller",
        &[
            "--namespace",
            &ns,
            "--no-realtime",
            "--config",
            faulting.to_str().unwrap(),
        ],
        &dir,
    );
    wait_for(&status, Duration::from_secs(20), |s| {
        s.mode == ControllerMode::Fault as u32
    })
    .expect("the controller did not fault");
    let end = ctl.stop(Duration::from_secs(5)).expect("stopped");
    assert_eq!(end.code(), Some(3), "stopped with a fault latched");
    let log = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap();
    assert!(!log.contains('\u{1b}'), "no colour codes in a log file");
}
