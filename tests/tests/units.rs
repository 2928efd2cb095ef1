//! The shipped systemd units: `systemd-analyze verify` accepts them (with
//! ExecStart pointed at this build's binaries), and rt-controller's unit
//! never restarts after a bad configuration (exit status 2) or a fault (3)
//! while a crash (any other failure) may be restarted, for the fault record
//! to refuse (docs/operation.md, "Faults across restarts").

use std::process::Command;

fn unit(name: &str) -> String {
    std::fs::read_to_string(tests::workspace_root().join("deploy").join(name)).unwrap()
}

/// `key=value` lines of a unit (the last of each key wins, as systemd reads them).
fn setting<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines()
        .filter_map(|l| l.strip_prefix(key)?.strip_prefix('='))
        .next_back()
}

#[test]
fn the_controller_unit_never_restarts_after_a_fault_or_a_bad_configuration() {
    let text = unit("rt-controller.service");
    assert_eq!(setting(&text, "Restart"), Some("on-failure"));
    let prevent: Vec<&str> = setting(&text, "RestartPreventExitStatus")
        .expect("RestartPreventExitStatus")
        .split_whitespace()
        .collect();
    for code in [
        rt_controller_daemon::exit::CONFIG,
        rt_controller_daemon::exit::FAULT,
    ] {
        assert!(prevent.contains(&code.to_string().as_str()), "{prevent:?}");
    }
    // An error that left no fault (no hardware at start-up) is restarted.
    let error = rt_controller_daemon::exit::ERROR.to_string();
    assert!(!prevent.contains(&error.as_str()), "{prevent:?}");
    // The record lives in the unit's state directory, where the shipped
    // configuration points.
    assert_eq!(setting(&text, "StateDirectory"), Some("vision-touch"));
    let cfg = rt_controller_daemon::config::DaemonConfig::from_file(
        &tests::workspace_root().join("deploy/rt-controller.toml"),
    )
    .unwrap();
    assert_eq!(
        cfg.fault_record.as_deref(),
        Some(std::path::Path::new(
            "/var/lib/vision-touch/rt-controller.fault"
        ))
    );
}

#[test]
fn every_unit_keeps_iceoryx2_in_one_private_runtime_directory() {
    for name in ["rt-controller.service", "hw-sim.service"] {
        let text = unit(name);
        assert_eq!(
            setting(&text, "RuntimeDirectory"),
            Some("vision-touch"),
            "{name}"
        );
        assert_eq!(
            setting(&text, "RuntimeDirectoryMode"),
            Some("0700"),
            "{name}"
        );
        // Shared by both units: one stopping must not remove the other's.
        assert_eq!(
            setting(&text, "RuntimeDirectoryPreserve"),
            Some("yes"),
            "{name}"
        );
        let env = format!(
            "{}=/run/vision-touch/iceoryx2",
            shared_mem_schema::transport::IPC_ROOT_ENV
        );
        assert!(
            text.lines()
                .any(|l| l.strip_prefix("Environment=") == Some(env.as_str())),
            "{name}: no {env}"
        );
        let writable = setting(&text, "ReadWritePaths").unwrap_or("");
        assert!(
            !writable.split_whitespace().any(|p| p == "/tmp"),
            "{name}: {writable}"
        );
        assert_eq!(setting(&text, "PrivateTmp"), Some("yes"), "{name}");
    }
}

#[test]
fn systemd_analyze_verifies_the_shipped_units() {
    let bins = tests::stack_bins();
    let dir = test_support::scratch_dir("units");
    for name in ["rt-controller.service", "hw-sim.service"] {
        let text = unit(name).replace("/opt/vision-touch/bin", bins.to_str().unwrap());
        std::fs::write(dir.join(name), text).unwrap();
    }
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .arg(dir.join("rt-controller.service"))
        .arg(dir.join("hw-sim.service"))
        .output()
        .expect("systemd-analyze (systemd) is needed for this test");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success() && text.trim().is_empty(), "{text}");
}
