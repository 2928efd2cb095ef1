//! The heuristic policy completes an insertion through the three processes,
//! and every sensor frame is accounted for in its log.

use shared_mem_schema::SensorFrame;
use std::process::Command;

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
