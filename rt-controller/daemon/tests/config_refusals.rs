//! Configurations that would remove a protection on a robot are refused by
//! the field's name: the Franka's torque-rate limit off, no wrench (no
//! force supervision), unbounded Net F/T time-outs, no fault record, a
//! speed fault above the robot's own limits.

use rt_controller_daemon::config::DaemonConfig;

fn franka(extra: &str) -> String {
    format!(
        "fault_record = \"/tmp/rt.fault\"\n[backend]\nkind = \"franka\"\n[timing]\n\
         clock = \"hardware\"\n{extra}"
    )
}

#[test]
fn a_robot_configuration_that_removes_a_protection_is_refused() {
    DaemonConfig::from_toml(&franka(""), "test").expect("the plain Franka configuration");
    for (extra, field) in [
        (
            "[backend.franka]\nrate_limit = false\n",
            "backend.franka.rate_limit",
        ),
        (
            "[backend.franka]\nwrench = \"none\"\n",
            "backend.franka.wrench",
        ),
        (
            "[backend.franka]\nwrench = \"net_ft\"\n[backend.franka.net_ft]\ntimeout_ms = 1e300\n",
            "backend.franka.net_ft.timeout_ms",
        ),
        (
            "[backend.franka]\nwrench = \"net_ft\"\n[backend.franka.net_ft]\nstart_timeout_s = 1e300\n",
            "backend.franka.net_ft.start_timeout_s",
        ),
        (
            "[backend.franka]\nwrench = \"net_ft\"\n[backend.franka.net_ft]\ntare_ms = -1.0\n",
            "backend.franka.net_ft.tare_ms",
        ),
    ] {
        let err = DaemonConfig::from_toml(&franka(extra), "test")
            .err()
            .unwrap_or_else(|| panic!("{extra} was accepted"));
        assert!(err.to_string().contains(field), "{extra}: {err}");
    }
    // The record is required once the command line's overrides are in.
    let text = "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n";
    let cfg = DaemonConfig::from_toml(text, "test").unwrap();
    let err = cfg.validate_for_start().unwrap_err();
    assert!(err.to_string().contains("fault_record"), "{err}");
}

#[test]
fn a_franka_supervisor_that_would_fault_after_the_robot_is_refused() {
    let speeds = "[controller]\njoint_speed_limits = \"fr3\"\n";
    let scale = "[controller.safety]\nvelocity_fault_scale = 0.95\n";
    let start = |text: &str| DaemonConfig::from_toml(&franka(text), "test")?.validate_for_motion();
    start(&format!("{speeds}{scale}")).expect("the FR3's limits, faulting at them");
    for (extra, field) in [
        (scale.to_string(), "controller.joint_speed_limits"),
        (speeds.to_string(), "controller.safety.velocity_fault_scale"),
        (
            format!("{speeds}[controller.safety]\nvelocity_fault_scale = 1.0\n"),
            "controller.safety.velocity_fault_scale",
        ),
    ] {
        let err = start(&extra).expect_err(&extra).to_string();
        assert!(err.contains(field), "{extra}: {err}");
    }
    // A Panda (FER) keeps the URDF's constant limits, but not above them.
    let fer = "[backend.franka]\ngeneration = \"panda\"\n";
    start(&format!("{scale}{fer}")).expect("the Panda's constant limits");
}
