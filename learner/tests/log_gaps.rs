//! Gaps in a log's 1 kHz channels are reported by `learner log info` and
//! `learner log check`, with where the sensor frames went: never published
//! by the controller, or published and not recorded.

use learner_node::log::{self, LogOptions, LogReader, LogWriter, topics};
use shared_mem_schema::rates::CONTROL_PERIOD_NS;
use shared_mem_schema::{Header, Message, SensorFrame};
use std::path::Path;
use std::process::Command;

fn frame(step: u64, seq: u64) -> SensorFrame {
    let mut f = *SensorFrame::boxed_zeroed();
    f.header = Header::new(seq, 1_000 + step, step * CONTROL_PERIOD_NS, 1);
    f.step = step;
    f.n_joints = 7;
    f.ee_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
    f
}

/// 2 s of frames with three known gaps: steps 500..=509 never published
/// (the controller's sequence numbers run on), steps 1000..=1002 published
/// and lost before the log (their sequence numbers are missing), and at
/// step 1500 one step of each.
fn write_gappy_log(path: &Path) -> u64 {
    let mut w = LogWriter::create_with(path, LogOptions::default()).unwrap();
    let mut seq = 0;
    let mut written = 0;
    for step in 0..2000u64 {
        let unpublished = (500..510).contains(&step) || step == 1500;
        let unrecorded = (1000..1003).contains(&step) || step == 1501;
        if unpublished {
            continue;
        }
        seq += 1;
        if unrecorded {
            continue;
        }
        w.sensor(&frame(step, seq)).unwrap();
        written += 1;
    }
    w.finish().unwrap();
    written
}

fn learner(args: &[&str], file: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(args)
        .arg(file)
        .output()
        .expect("running learner");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn gaps_in_1khz_channels_are_reported_by_info_and_check() {
    let dir = test_support::scratch_dir("log-gaps");
    let path = dir.join("gappy.mcap");
    let written = write_gappy_log(&path);
    assert_eq!(written, 2000 - 11 - 4);

    // The library's count.
    let r = LogReader::open(&path).unwrap();
    let gaps = log::log_gaps(&r).unwrap();
    let sensor = &gaps[0];
    assert_eq!(sensor.topic, topics::SENSOR);
    assert_eq!(
        (sensor.messages, sensor.gaps, sensor.missing, sensor.longest),
        (written, 3, 15, 10)
    );
    let loss = sensor.sensor.unwrap();
    assert_eq!((loss.not_published, loss.not_recorded), (11, 4));
    // The views written from the same frames (1 kHz by default) have the
    // same gaps, found by log time.
    for view in [topics::VIEW_TF, topics::VIEW_EE_POSE, topics::VIEW_WRENCH] {
        let g = gaps.iter().find(|g| g.topic == view).expect(view);
        assert_eq!((g.gaps, g.missing, g.longest), (3, 15, 10), "{view}");
    }
    assert_eq!(gaps.len(), 4, "{gaps:?}");

    // What users see.
    let expect = format!(
        "1 kHz {}: 3 gaps, 15 messages missing (0.75 % of 2000), the longest 10 missing",
        topics::SENSOR
    );
    for cmd in [["log", "info"], ["log", "check"]] {
        let (ok, text) = learner(&cmd, &path);
        assert!(ok, "{cmd:?}: {text}");
        assert!(
            text.contains(&expect),
            "{cmd:?} does not report the gaps:\n{text}"
        );
        assert!(
            text.contains(
                "11 hardware steps without a controller frame, 4 frames published but not recorded"
            ),
            "{cmd:?}: {text}"
        );
        assert!(
            text.contains("1 kHz /ft/wrench: 3 gaps, 15 messages missing"),
            "{cmd:?}: {text}"
        );
    }
}

#[test]
fn a_log_without_gaps_says_so() {
    let dir = test_support::scratch_dir("log-no-gaps");
    let path = dir.join("whole.mcap");
    let mut w = LogWriter::create_with(&path, LogOptions::default()).unwrap();
    for step in 0..300 {
        w.sensor(&frame(step, step + 1)).unwrap();
    }
    w.finish().unwrap();
    let (ok, text) = learner(&["log", "check"], &path);
    assert!(ok, "{text}");
    assert!(
        text.contains("1 kHz /controller/sensor: no gaps in 300 messages"),
        "{text}"
    );
}
