//! Configurations that would remove a protection on a robot are refused by
//! the field's name: the Franka's torque-rate limit off, no wrench (no
//! force supervision), unbounded Net F/T time-outs, no fault record.

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
