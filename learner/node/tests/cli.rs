//! `policy-node` reads deployed policies only, and says so before any
//! process starts.

use std::process::Command;

fn node() -> Command {
    Command::new(env!("CARGO_BIN_EXE_policy-node"))
}

#[test]
fn a_training_checkpoint_is_refused_before_the_stack_starts() {
    let dir = test_support::scratch_dir("node-cli-checkpoint");
    let ckpt = dir.path().join("checkpoint.json");
    std::fs::write(&ckpt, r#"{"config": {}, "state": {}}"#).unwrap();
    let out = node()
        .args([
            "stack",
            "--episodes",
            "1",
            "--namespace",
            "node-cli-refused",
        ])
        .arg("--log-dir")
        .arg(dir.path().join("logs"))
        .arg("--policy")
        .arg(&ckpt)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("checkpoint.json"), "{err}");
    assert!(err.contains("not a deployed policy"), "{err}");
    assert!(err.contains("learner policy export"), "{err}");
    // Nothing was started: no process logs.
    assert!(!dir.path().join("logs").join("hw-sim.log").exists());
}

#[test]
fn last_is_refused_with_a_deployed_policy() {
    let dir = test_support::scratch_dir("node-cli-last");
    let policy = dir.path().join("policy.json");
    std::fs::write(&policy, "{}").unwrap();
    let out = node()
        .args(["run", "--episodes", "1", "--namespace", "node-cli-last"])
        .arg("--policy")
        .arg(&policy)
        .arg("--last")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--last picks among a training checkpoint's policies"),
        "{err}"
    );
}
