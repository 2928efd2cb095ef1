//! The whole stack on franky-sim (docs/franka.md, "The whole stack on
//! franky-sim"): `learner stack --robot franky-sim` starts franky-sim, the
//! daemon with the Franka backend and the policy node with the heuristic on
//! a calibrated hole; two short episodes, then everything stops.
//!
//! franky-sim's interpreter is `$FRANKY_SIM_PYTHON`, else the repository's
//! `.venv-franky-sim` (scripts/franky-sim-venv.sh). When franky-sim cannot
//! be imported the test is skipped with a message, unless
//! `$FRANKY_SIM_REQUIRED=1` or `$CI` is set: then it fails (scripts/test.sh
//! sets it), as rt-controller/tests/franka.rs does.

use std::process::Command;
use test_support::franky_sim;

/// The numbers of an episode line: (moved towards the goal, ended from it),
/// mm.
fn approach(line: &str) -> (f64, f64) {
    let num = |after: &str| -> f64 {
        let (_, rest) = line
            .split_once(after)
            .unwrap_or_else(|| panic!("no {after:?} in {line}"));
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    (num("moved "), num("ended "))
}

#[test]
fn the_heuristic_drives_franky_sim_through_the_stack() {
    if !franky_sim::available_for("the_heuristic_drives_franky_sim_through_the_stack") {
        return;
    }
    let _g = tests::exclusive();
    let dir = test_support::scratch_dir("franky-stack");
    // An address of this test's own (franky-sim serves one client at a
    // time); the Franka backend's test uses 127.19.0.0/16.
    let addr = franky_sim::loopback_address(21);
    let out = Command::new(tests::stack_bins().join("learner"))
        .args(["stack", "--robot", "franky-sim", "--episodes", "2"])
        // 5 cm in front of and 10 cm below the FR3's start pose.
        .args(["--hole-pos", "0.60,0.0,0.42", "--hole-depth-m", "0.03"])
        // Generous: an episode takes about 2.7 s of the robot's time.
        .args(["--episode-timeout-s", "30"])
        .args(["--franky-sim-address", &addr, "--namespace"])
        .arg(tests::unique_namespace("franky"))
        .arg("--log-dir")
        .arg(dir.path())
        .arg("--franky-sim-python")
        .arg(franky_sim::python())
        .output()
        .expect("running learner stack");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let ctl = std::fs::read_to_string(dir.join("rt-controller.log")).unwrap_or_default();
    assert!(
        out.status.success(),
        "{}\n{stdout}\n{stderr}\nrt-controller.log:\n{ctl}",
        out.status
    );
    eprintln!("{stdout}");
    let episodes: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("episode "))
        .collect();
    assert_eq!(episodes.len(), 2, "{stdout}");
    for line in &episodes {
        assert!(
            line.contains("reached the hole's bottom level"),
            "{line}\n{stderr}"
        );
        // The tip starts 137 mm from the hole's bottom centre (the goal);
        // franky-sim's joint friction leaves millimetres (1.5 measured).
        let (moved, ended) = approach(line);
        assert!(
            moved > 120.0 && ended < 10.0,
            "moved {moved} mm towards the goal, ended {ended} mm from it: {line}"
        );
    }
    for n in [1, 2] {
        let log = dir.join(format!("episode-000{n}.mcap"));
        let reader = learner_node::log::LogReader::open(&log).unwrap();
        let gaps = learner_node::log::log_gaps(&reader).unwrap();
        assert!(
            gaps[0].topic == learner_node::log::topics::SENSOR && gaps[0].messages > 1000,
            "{}: {gaps:?}",
            log.display()
        );
    }
    assert!(
        stdout.contains("no insertion outcome"),
        "no statement of what the run shows:\n{stdout}"
    );
    assert!(stdout.contains("controller: "), "{stdout}");
    // Clean stop: the daemon exits 0 on SIGTERM after its final hold, and
    // its control loop never reached the heap.
    assert!(
        stdout.contains("rt-controller exit status: 0 after SIGTERM"),
        "{stdout}"
    );
    assert!(ctl.contains("stopped (signal 15)"), "{ctl}");
    assert!(ctl.contains(", 0 from the heap;"), "{ctl}");
    assert!(!ctl.contains("mode fault"), "{ctl}");
    // franky-sim is gone: nothing serves its address any more.
    assert!(
        std::net::TcpStream::connect((addr.as_str(), 1337)).is_err(),
        "franky-sim still serves {addr}:1337"
    );
}
