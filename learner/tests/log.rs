//! MCAP logs: round trip, Foxglove views, indexed time-range reads, wrong
//! schema versions, and damaged files (truncated anywhere, bytes flipped
//! anywhere): an error naming the offset, never a panic, and a recovered copy
//! that holds every intact message.

use learner_node::log::events::{EpisodeEnd, Event, Reset};
use learner_node::log::{
    self, LogOptions, LogReader, LogWriter, ReadError, RunConfig, RunMode, topics,
};
use learner_node::mix::EpisodePolicy;
use shared_mem_schema::{CameraFrame, Header, Message, PolicyAction, SensorFrame};
use std::path::Path;

fn sensor(i: u64) -> SensorFrame {
    let mut f = *SensorFrame::boxed_zeroed();
    f.header = Header::new(i, 1_000 + i, i * 1_000_000, 1);
    f.step = i;
    f.n_joints = 7;
    f.q[0] = 0.001 * i as f64;
    f.ee_pos_m = [0.5, 0.01 * (i % 7) as f64, 0.2];
    f.ee_quat_xyzw = [1.0, 0.0, 0.0, 0.0];
    f.wrench = [0.1 * i as f64, -1.0, 2.0, 0.0, 0.01, 0.0];
    f
}

fn camera(i: u64, w: u32, h: u32) -> Box<CameraFrame> {
    let mut c = CameraFrame::boxed_zeroed();
    c.header = Header::new(i, 5, i * 50_000_000, 1);
    c.index = i;
    c.calibration.width = w;
    c.calibration.height = h;
    c.calibration.focal_px = 154.5;
    c.calibration.principal_px = [w as f64 / 2.0, h as f64 / 2.0];
    c.calibration.pose_pos_m = [1.45, -0.75, 0.85];
    c.calibration.pose_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
    for k in 0..(w * h) as usize {
        c.rgb[3 * k] = (k % 251) as u8;
        c.rgb[3 * k + 1] = i as u8;
        c.depth_m[k] = 0.5 + k as f32 * 1e-4;
    }
    c
}

/// The configuration record of the test episodes.
fn run_config() -> RunConfig {
    let mut c = RunConfig::new(
        RunMode::Live,
        hw_sim::WorldConfig::default(),
        EpisodePolicy::Heuristic,
        1,
        3,
    );
    c.lockstep = Some(true);
    c.namespace = Some("test".into());
    c
}

/// 3 s of a small episode: 3000 sensor frames, 60 actions and camera frames.
fn write_log(path: &Path, opts: LogOptions) -> Vec<SensorFrame> {
    let mut w = LogWriter::create_with(path, opts).unwrap();
    w.config(0, &run_config()).unwrap();
    w.event(
        0,
        &Event::Reset(Box::new(Reset {
            episode: 1,
            seed: 3,
            peg: hw_sim::PegShape::Square,
            policy: EpisodePolicy::Heuristic,
            lockstep: None,
            world: None,
            hole_pos_m: [0.6, 0.0, 0.1],
            hole_quat_xyzw: [0.0, 0.0, 0.0, 1.0],
            hole_depth_m: 0.04,
        })),
    )
    .unwrap();
    let mut frames = Vec::new();
    for i in 0..3000 {
        let f = sensor(i);
        w.sensor(&f).unwrap();
        frames.push(f);
        if i % 50 == 0 {
            w.camera(&camera(i / 50, 32, 24)).unwrap();
            let mut a = PolicyAction::new(i / 50, 7, [0.001, 0.0, -0.002, 0.01]);
            a.header.t_hw_ns = i * 1_000_000;
            a.apply_at_step = i + 1;
            w.action(&a).unwrap();
        }
    }
    w.event(
        2_999_000_000,
        &Event::Outcome(EpisodeEnd {
            stage: hw_sim::Stage::Touched,
            duration_s: Some(2.9),
            actions: Some(59),
            states: None,
            interrupted: None,
        }),
    )
    .unwrap();
    w.finish().unwrap();
    frames
}

#[test]
fn round_trip_with_views_and_time_ranges() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("round-trip.mcap");
    let frames = write_log(&path, LogOptions::default());
    let r = LogReader::open(&path).unwrap();
    let back: Vec<SensorFrame> = r.read_raw(topics::SENSOR, None).unwrap();
    assert_eq!(back.len(), frames.len());
    assert!(
        back.iter()
            .zip(&frames)
            .all(|(a, b)| a.as_bytes() == b.as_bytes())
    );

    let cams = r.read_camera(None).unwrap();
    assert_eq!(cams.len(), 60);
    let want = camera(17, 32, 24);
    let c = &cams[17];
    assert_eq!(c.index, 17);
    assert_eq!(c.calibration, want.calibration);
    assert_eq!(c.rgb, want.rgb[..32 * 24 * 3]);
    assert_eq!(c.depth_m, want.depth_m[..32 * 24]);

    let actions: Vec<PolicyAction> = r.read_raw(topics::ACTION, None).unwrap();
    assert_eq!(actions.len(), 60);
    assert_eq!(actions[3].delta_pos_m, [0.001, 0.0, -0.002]);
    let events = r.read_events(None).unwrap();
    assert_eq!(events.len(), 2);
    assert!(matches!(&events[0].1, Event::Reset(r) if r.seed == 3));
    assert!(matches!(&events[1].1, Event::Outcome(o) if o.stage == hw_sim::Stage::Touched));
    let configs = r.read_config(None).unwrap();
    assert_eq!(configs.len(), 1);
    // Compared by field: serde_json's default float parsing need not give
    // back every world value bit for bit.
    let (t, c) = &configs[0];
    assert_eq!(*t, 0);
    assert_eq!(
        (c.mode, c.policy),
        (RunMode::Live, EpisodePolicy::Heuristic)
    );
    assert_eq!((c.episode, c.seed, c.lockstep), (1, 3, Some(true)));
    assert_eq!(c.namespace.as_deref(), Some("test"));
    assert_eq!(c.robot, c.world.robot);
    assert_eq!(c.world.task.peg, hw_sim::PegShape::Square);
    assert!(c.controller.is_none());
    // The JSON keeps the names older readers index by.
    let json = &r.read_json(topics::CONFIG, None).unwrap()[0].1;
    assert_eq!(json["world"]["task"]["peg"], "square");
    assert_eq!(json["policy"], "heuristic");
    assert_eq!(json["mode"], "live");

    // A time range reads exactly its messages.
    let window: Vec<SensorFrame> = r
        .read_raw(topics::SENSOR, Some((1_000_000_000, 1_250_000_000)))
        .unwrap();
    assert_eq!(window.len(), 250);
    assert_eq!(window[0].step, 1000);
    assert_eq!(window.last().unwrap().step, 1249);

    // The Foxglove views carry the well-known schemas.
    let infos = r.topics();
    let schema = |t: &str| infos.iter().find(|i| i.topic == t).unwrap().schema.clone();
    assert_eq!(schema(topics::VIEW_RGB), "foxglove.RawImage");
    assert_eq!(schema(topics::VIEW_DEPTH), "foxglove.RawImage");
    assert_eq!(
        schema(topics::VIEW_CALIBRATION),
        "foxglove.CameraCalibration"
    );
    assert_eq!(schema(topics::VIEW_TF), "foxglove.FrameTransforms");
    assert_eq!(schema(topics::VIEW_EE_POSE), "foxglove.PoseInFrame");
    let rgb = r.read_json(topics::VIEW_RGB, None).unwrap();
    assert_eq!(rgb.len(), 60);
    assert_eq!(rgb[0].1["encoding"], "rgb8");
    assert_eq!(rgb[0].1["step"], 96);
    let wrench = r.read_json(topics::VIEW_WRENCH, None).unwrap();
    assert_eq!(wrench.len(), 3000);
    assert_eq!(wrench[10].1["force"]["x"], 1.0);
    let tf = r.read_json(topics::VIEW_TF, None).unwrap();
    assert!(
        tf.iter()
            .any(|(_, v)| v["transforms"][0]["child_frame_id"] == "camera")
    );
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn views_can_be_thinned_or_left_out() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("thin.mcap");
    write_log(
        &path,
        LogOptions {
            view_rate_hz: 100.0,
            ..LogOptions::default()
        },
    );
    let r = LogReader::open(&path).unwrap();
    assert_eq!(r.read(&[topics::VIEW_WRENCH], None).unwrap().len(), 300);
    assert_eq!(r.read(&[topics::SENSOR], None).unwrap().len(), 3000);
    write_log(
        &path,
        LogOptions {
            foxglove: false,
            ..LogOptions::default()
        },
    );
    let r = LogReader::open(&path).unwrap();
    assert!(r.topics().iter().all(|t| t.topic != topics::VIEW_RGB));
    assert_eq!(r.read_camera(None).unwrap().len(), 60);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn another_schema_version_is_refused_by_name() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("version.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    let mut f = sensor(1);
    let foreign = shared_mem_schema::SCHEMA_VERSION + 1;
    f.header.schema_version = foreign;
    w.sensor(&f).unwrap();
    w.finish().unwrap();
    let r = LogReader::open(&path).unwrap();
    let e = r.read_raw::<SensorFrame>(topics::SENSOR, None).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains(&format!("schema version {foreign}"))
            && text.contains(&format!(
                "versions {} to {}",
                shared_mem_schema::OLDEST_RECORDED_VERSION,
                shared_mem_schema::SCHEMA_VERSION
            )),
        "{text}"
    );
    assert!(text.contains("/controller/sensor"), "{text}");
    std::fs::remove_file(&path).unwrap();
    // Reading a channel as the wrong struct is a size error, not garbage.
    let mut w = LogWriter::create(&path).unwrap();
    w.sensor(&sensor(1)).unwrap();
    w.finish().unwrap();
    let r = LogReader::open(&path).unwrap();
    let e = r
        .read_raw::<PolicyAction>(topics::SENSOR, None)
        .unwrap_err();
    assert!(e.to_string().contains("bytes"), "{e}");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn missing_and_foreign_files_are_named() {
    let e = LogReader::open(Path::new("/nonexistent/x.mcap"))
        .err()
        .unwrap();
    assert!(e.to_string().contains("/nonexistent/x.mcap"), "{e}");
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("foreign.mcap");
    std::fs::write(&path, b"PK\x03\x04 not a log at all").unwrap();
    let e = LogReader::open(&path).err().unwrap();
    assert!(matches!(e, ReadError::NotMcap { .. }), "{e}");
    assert!(e.to_string().contains("offset 0"), "{e}");
}

/// Small chunks so that damage can land in many places.
fn small_chunks() -> LogOptions {
    LogOptions {
        chunk_bytes: 16 << 10,
        ..LogOptions::default()
    }
}

#[test]
fn truncated_files_name_the_offset_and_recover_to_a_prefix() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("full.mcap");
    write_log(&path, small_chunks());
    let full = std::fs::read(&path).unwrap();
    let all = LogReader::open(&path).unwrap().read(&[], None).unwrap();
    let cut_path_dir = test_support::scratch_dir("log");
    let cut_path = cut_path_dir.path().join("cut.mcap");
    let out_path_dir = test_support::scratch_dir("log");
    let out_path = out_path_dir.path().join("cut-recovered.mcap");
    let mut last_count = 0;
    for k in 1..40 {
        let cut = full.len() * k / 40;
        std::fs::write(&cut_path, &full[..cut]).unwrap();
        let e = LogReader::open(&cut_path)
            .err()
            .expect("a truncated file is refused");
        match &e {
            ReadError::Incomplete {
                offset, readable, ..
            } => {
                assert!(*offset <= cut as u64 && *readable <= *offset, "{e}");
                assert!(e.to_string().contains("learner log recover"), "{e}");
            }
            other => panic!("cut at {cut}: {other}"),
        }
        let rep = log::recover(&cut_path, &out_path).unwrap();
        let back = LogReader::open(&out_path).unwrap().read(&[], None).unwrap();
        assert_eq!(back.len() as u64, rep.messages);
        // What comes back is exactly the start of the original, message
        // for message (per channel order is kept; sort both the same way).
        let key = |m: &log::LogMessage| (m.topic.clone(), m.sequence);
        let mut want: Vec<_> = all.iter().map(key).collect();
        want.sort();
        for m in &back {
            assert!(want.binary_search(&key(m)).is_ok());
            let orig = all.iter().find(|o| key(o) == key(m)).unwrap();
            assert_eq!(orig, m);
        }
        assert!(back.len() >= last_count, "longer prefixes recover no less");
        last_count = back.len();
    }
    // Nearly the whole file (only the summary lost) recovers nearly all.
    assert!(
        last_count * 10 >= all.len() * 9,
        "{last_count} of {}",
        all.len()
    );
    std::fs::remove_file(&path).unwrap();
}

/// The messages of `topic` in `msgs`, in the order they were written.
fn of_topic<'a>(msgs: &'a [log::LogMessage], topic: &str) -> Vec<&'a log::LogMessage> {
    let mut v: Vec<_> = msgs.iter().filter(|m| &*m.topic == topic).collect();
    v.sort_by_key(|m| m.sequence);
    v
}

#[test]
fn flipped_bytes_are_caught_or_harmless_and_recover_to_a_prefix() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("flip.mcap");
    write_log(&path, small_chunks());
    let full = std::fs::read(&path).unwrap();
    let all = LogReader::open(&path).unwrap().read(&[], None).unwrap();
    let topics: std::collections::BTreeSet<String> =
        all.iter().map(|m| m.topic.to_string()).collect();
    let flipped = path_dir.path().join("flipped.mcap");
    let out = path_dir.path().join("flipped-recovered.mcap");
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut rand = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut caught = 0;
    for case in 0..300 {
        let mut buf = full.clone();
        for _ in 0..1 + rand() % 4 {
            let at = (rand() % buf.len() as u64) as usize;
            buf[at] ^= 1 << (rand() % 8);
        }
        // Detected (an error naming the file or the offset) or harmless
        // (every message reads back exactly as written); a panic fails.
        match LogReader::from_bytes(&path, buf.clone()) {
            Err(e) => {
                caught += 1;
                assert!(e.to_string().contains("flip.mcap"), "{e}");
            }
            Ok(r) => {
                match r.read(&[], None) {
                    Err(e) => {
                        caught += 1;
                        assert!(e.to_string().contains("offset"), "{e}");
                    }
                    Ok(got) => assert!(
                        got == all,
                        "case {case}: an undetected corruption changed what is read"
                    ),
                }
                let _ = r.read_camera(None);
                let _ = r.read_raw::<SensorFrame>(topics::SENSOR, None);
                let _ = r.read_events(None);
            }
        }
        // Recovery of the damaged file: no panic, and per channel exactly
        // the first messages written.
        std::fs::write(&flipped, &buf).unwrap();
        match log::recover(&flipped, &out) {
            Err(e) => assert!(e.to_string().contains("flipped.mcap"), "{e}"),
            Ok(rep) => {
                let back = LogReader::open(&out).unwrap().read(&[], None).unwrap();
                assert_eq!(back.len() as u64, rep.messages);
                for t in &topics {
                    let (want, got) = (of_topic(&all, t), of_topic(&back, t));
                    assert!(
                        got.len() <= want.len() && got[..] == want[..got.len()],
                        "case {case}: recovered {t} is not a prefix of what was written"
                    );
                }
                assert!(
                    back.iter().all(|m| topics.contains(&*m.topic)),
                    "case {case}: a recovered message is on a channel never written"
                );
            }
        }
    }
    // Most of the file is compressed chunks under a CRC.
    assert!(caught >= 200, "only {caught} of 300 corruptions caught");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn an_oversized_camera_frame_is_refused_and_the_channel_stays_readable() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("big-camera.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    for i in 0..3 {
        w.camera(&camera(i, 32, 24)).unwrap();
    }
    let mut big = camera(3, 32, 24);
    big.calibration.width = shared_mem_schema::MAX_IMAGE_WIDTH as u32 + 1;
    let e = w.camera(&big).unwrap_err().to_string();
    assert!(
        e.contains("larger than") && e.contains("big-camera.mcap"),
        "{e}"
    );
    w.camera(&camera(4, 32, 24)).unwrap();
    w.finish().unwrap();
    let back = LogReader::open(&path).unwrap().read_camera(None).unwrap();
    assert_eq!(
        back.iter().map(|c| c.index).collect::<Vec<_>>(),
        [0, 1, 2, 4]
    );
}

#[test]
fn recovery_keeps_a_channel_whose_schema_record_is_lost() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("no-schema.mcap");
    let out = path_dir.path().join("no-schema-recovered.mcap");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .use_chunks(false)
        .compression(None)
        .create(file)
        .unwrap();
    let schema = w.add_schema("Lost", "text", b"lost").unwrap();
    let channel = w
        .add_channel(schema, "/kept", "raw", &Default::default())
        .unwrap();
    for k in 0..10u32 {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: k,
            log_time: k as u64,
            publish_time: k as u64,
        };
        w.write_to_known_channel(&header, &k.to_le_bytes()).unwrap();
    }
    w.finish().unwrap();
    // Point the channel at a schema that is not in the file: its id sits
    // just before the topic's length prefix, in the data section and again
    // in the summary.
    let mut bytes = std::fs::read(&path).unwrap();
    let topic = b"\x05\x00\x00\x00/kept";
    let mut patched = 0;
    for at in 0..bytes.len() - topic.len() {
        if &bytes[at..at + topic.len()] == topic {
            bytes[at - 2..at].copy_from_slice(&77u16.to_le_bytes());
            patched += 1;
        }
    }
    assert!(patched >= 1);
    std::fs::write(&path, &bytes).unwrap();
    let rep = log::recover(&path, &out).unwrap();
    assert_eq!((rep.messages, rep.channels), (10, 1));
    assert_eq!(rep.channels_without_schema, 1);
    let back = LogReader::open(&out)
        .unwrap()
        .read(&["/kept"], None)
        .unwrap();
    assert_eq!(back.len(), 10);
    assert_eq!(back[3].data, 3u32.to_le_bytes());
}

#[test]
fn recovery_refuses_to_overwrite_its_input() {
    let path_dir = test_support::scratch_dir("log");
    let path = path_dir.path().join("self.mcap");
    write_log(&path, small_chunks());
    let before = std::fs::read(&path).unwrap();
    assert!(log::recover(&path, &path).is_err());
    assert_eq!(std::fs::read(&path).unwrap(), before);
}

/// The most compressible log our writer can be given: the arm at rest
/// (frames that differ only in their header) and a blank camera (a capped
/// lens: black, no depth). Its chunks must stay within the reader's bound
/// on a chunk's compression ratio, or the reader would refuse a log it
/// wrote itself. Measured (docs/data.md): 187–241× at worst, against
/// the bound of 1 000×.
#[test]
fn a_blank_camera_and_an_arm_at_rest_read_back() {
    let dir = test_support::scratch_dir("log");
    for opts in [
        LogOptions::default(),
        LogOptions {
            foxglove: false,
            ..LogOptions::default()
        },
        LogOptions {
            chunk_bytes: 64 << 20,
            flush_period_s: 60.0,
            ..LogOptions::default()
        },
    ] {
        let path = dir.path().join("blank.mcap");
        let mut w = LogWriter::create_with(&path, opts.clone()).unwrap();
        let n = 10_000u64;
        for i in 0..n {
            let mut f = *SensorFrame::boxed_zeroed();
            f.header = Header::new(i, 1_000, i * 1_000_000, 1);
            f.step = i;
            f.n_joints = 7;
            f.ee_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
            w.sensor(&f).unwrap();
            if i % 50 == 0 {
                let mut c = CameraFrame::boxed_zeroed();
                c.header = Header::new(i / 50, 5, i * 1_000_000, 1);
                c.index = i / 50;
                c.calibration.width = 128;
                c.calibration.height = 128;
                c.calibration.focal_px = 154.5;
                c.calibration.principal_px = [64.0, 64.0];
                c.calibration.pose_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
                w.camera(&c).unwrap();
            }
        }
        w.finish().unwrap();
        let r = LogReader::open(&path).unwrap_or_else(|e| panic!("{opts:?}: {e}"));
        let back: Vec<SensorFrame> = r
            .read_raw(topics::SENSOR, None)
            .unwrap_or_else(|e| panic!("{opts:?}: {e}"));
        assert_eq!(back.len() as u64, n, "{opts:?}");
        let cams = r.read_camera(None).unwrap();
        assert_eq!(cams.len() as u64, n / 50, "{opts:?}");
        std::fs::remove_file(&path).unwrap();
    }
}

/// A frame with a NaN pose, wrench or calibration (a faulty peer) is kept
/// in its raw channel, and no view message holds a `null` (Foxglove's
/// schemas want numbers): its views are left out for that frame only.
#[test]
fn non_finite_values_stay_raw_and_out_of_the_views() {
    let dir = test_support::scratch_dir("log-nan");
    let path = dir.path().join("nan.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    w.config(0, &run_config()).unwrap();
    for i in 0..4 {
        let mut f = sensor(i);
        if i == 1 {
            f.ee_pos_m[2] = f64::NAN;
        }
        if i == 2 {
            f.wrench[0] = f64::INFINITY;
        }
        if i == 3 {
            f.q[2] = f64::NAN;
        }
        w.sensor(&f).unwrap();
    }
    let mut c = camera(1, 8, 8);
    c.calibration.focal_px = f64::NAN;
    w.camera(&c).unwrap();
    w.finish().unwrap();
    let r = LogReader::open(&path).unwrap();
    assert_eq!(r.read(&[topics::SENSOR], None).unwrap().len(), 4);
    assert_eq!(r.read_camera(None).unwrap().len(), 1);
    // Frames 1 and 2 have no pose, wrench or transforms; frame 3 (a NaN
    // joint angle) keeps its pose and the end effector's transform.
    let times = |topic| -> Vec<u64> {
        r.read_json(topic, None)
            .unwrap()
            .into_iter()
            .map(|(t, _)| t)
            .collect()
    };
    let ms = |i: u64| i * 1_000_000;
    assert_eq!(times(topics::VIEW_EE_POSE), [ms(0), ms(3)]);
    assert_eq!(times(topics::VIEW_WRENCH), [ms(0), ms(3)]);
    assert_eq!(times(topics::VIEW_TF), [ms(0), ms(3)]);
    // The image is there; its calibration and camera transform are not.
    assert_eq!(times(topics::VIEW_RGB).len(), 1);
    assert!(times(topics::VIEW_CALIBRATION).is_empty());
    fn has_null(v: &serde_json::Value) -> bool {
        match v {
            serde_json::Value::Null => true,
            serde_json::Value::Array(a) => a.iter().any(has_null),
            serde_json::Value::Object(o) => o.values().any(has_null),
            _ => false,
        }
    }
    for topic in [
        topics::VIEW_EE_POSE,
        topics::VIEW_WRENCH,
        topics::VIEW_TF,
        topics::VIEW_RGB,
        topics::VIEW_SCENE,
    ] {
        for (_, v) in r.read_json(topic, None).unwrap() {
            assert!(!has_null(&v), "{topic}: {v}");
        }
    }
}
