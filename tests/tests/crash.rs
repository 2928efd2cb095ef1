//! A collector killed mid-run (SIGKILL, no chance to finish its files)
//! leaves logs readable up to their last complete chunk; `learner log
//! recover` turns each into a valid file, and the dataset builder skips the
//! damaged ones, naming them, while building the rest.

use learner_node::log::{LogReader, ReadError, topics};
use std::process::Command;
use std::time::{Duration, Instant};
use test_support::scratch_dir;
use tests::{exclusive, stack_bins, start};

#[test]
fn a_killed_collector_leaves_recoverable_logs() {
    let _one = exclusive();
    let dir = scratch_dir("crash");
    let out = dir.join("shards");
    let out_s = out.display().to_string();
    let mut p = start(
        "learner",
        &[
            "collect",
            "--states",
            "100000",
            "--out",
            &out_s,
            "--workers",
            "1",
            "--episode-actions",
            "400",
            "--pegs",
            "square",
        ],
        &dir,
    );
    // Wait for the episode file to hold a few chunks (1 MiB or 1 s each).
    let file = out.join("episode-000000.mcap");
    let t0 = Instant::now();
    while std::fs::metadata(&file).map_or(0, |m| m.len()) < 4 << 20 {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the collector wrote nothing"
        );
        assert!(p.try_wait().is_none(), "the collector exited early");
        std::thread::sleep(Duration::from_millis(20));
    }
    p.signal(libc::SIGKILL);
    p.wait_timeout(Duration::from_secs(5)).expect("killed");

    let e = LogReader::open(&file)
        .err()
        .expect("an unfinished log is refused");
    let ReadError::Incomplete {
        offset, readable, ..
    } = &e
    else {
        panic!("{e}");
    };
    let len = std::fs::metadata(&file).unwrap().len();
    assert!(*readable > 1 << 20 && *offset <= len, "{e}");

    let learner = stack_bins().join("learner");
    let fixed = dir.join("fixed.mcap");
    let o = Command::new(&learner)
        .args(["log", "recover"])
        .arg(&file)
        .arg("-o")
        .arg(&fixed)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("byte offset"), "{text}");
    let r = LogReader::open(&fixed).unwrap();
    let frames: Vec<shared_mem_schema::SensorFrame> = r.read_raw(topics::SENSOR, None).unwrap();
    assert!(frames.len() > 500, "{} frames recovered", frames.len());
    // Consecutive steps from the start: nothing in the middle is lost.
    assert!(frames.windows(2).all(|w| w[1].step == w[0].step + 1));
    assert!(!r.read_camera(None).unwrap().is_empty());
    // The damaged input is left as it was.
    assert_eq!(std::fs::metadata(&file).unwrap().len(), len);
}
