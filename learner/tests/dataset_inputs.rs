//! The dataset builder and reader trust none of their inputs: a log naming
//! a file as its robot, frames with a wrong joint count or images of
//! another size are skipped and reported while the rest builds; a tampered
//! meta.json (episodes that do not tile the samples included) is refused
//! with the field named, as is a split that trains on a test episode; a
//! damaged block fails its checksum.

mod one_episode;

use learner::dataset::{self, BuildConfig, Dataset, DatasetError, Loader, LoaderConfig};
use learner_node::log::{LogOptions, LogReader, LogWriter, topics};
use shared_mem_schema::{CameraFrame, Message, PolicyAction, SensorFrame};
use std::path::Path;

/// How a copy of a log is altered.
#[derive(Default)]
struct Edit {
    robot: Option<String>,
    n_joints: Option<u32>,
    /// Keep only the top-left `(w, h)` of every image.
    crop: Option<(u32, u32)>,
}

/// Writes a copy of the log `src` to `dst` with `edit` applied.
fn rewrite(src: &Path, dst: &Path, edit: &Edit) {
    let r = LogReader::open(src).unwrap();
    let mut w = LogWriter::create_with(
        dst,
        LogOptions {
            foxglove: false,
            ..LogOptions::default()
        },
    )
    .unwrap();
    for (t, mut c) in r.read_config(None).unwrap() {
        if let Some(robot) = &edit.robot {
            c.robot = robot.clone();
            c.world.robot = robot.clone();
        }
        w.config(t, &c).unwrap();
    }
    for mut f in r.read_raw::<SensorFrame>(topics::SENSOR, None).unwrap() {
        if let Some(n) = edit.n_joints {
            f.n_joints = n;
        }
        w.sensor(&f).unwrap();
    }
    for a in r.read_raw::<PolicyAction>(topics::ACTION, None).unwrap() {
        w.action(&a).unwrap();
    }
    let mut m = CameraFrame::boxed_zeroed();
    for c in r.read_camera(None).unwrap() {
        let (w0, h0) = (c.calibration.width as usize, c.calibration.height as usize);
        let (cw, ch) = edit
            .crop
            .map_or((w0, h0), |(a, b)| (a as usize, b as usize));
        m.header = c.header;
        m.index = c.index;
        m.calibration = c.calibration;
        m.calibration.width = cw as u32;
        m.calibration.height = ch as u32;
        if edit.crop.is_some() {
            m.calibration.principal_px = [cw as f64 / 2.0, ch as f64 / 2.0];
        }
        for y in 0..ch {
            for x in 0..cw {
                let (i, o) = (y * w0 + x, y * cw + x);
                m.rgb[3 * o..3 * o + 3].copy_from_slice(&c.rgb[3 * i..3 * i + 3]);
                m.depth_m[o] = c.depth_m[i];
            }
        }
        w.camera(&m).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn bad_logs_are_skipped_and_named_and_damaged_datasets_refused() {
    let scratch = test_support::scratch_dir("ds-inputs");
    let root = scratch.path();
    let good = one_episode::collect_one(&root.join("collect"), hw_sim::WorldConfig::default(), 5);
    let logs = root.join("logs");
    std::fs::create_dir_all(&logs).unwrap();
    // Names sort the good log first: it sets the dataset's image size.
    std::fs::copy(&good, logs.join("a-good.mcap")).unwrap();
    let cases = [
        (
            "b-robot-path.mcap",
            Edit {
                robot: Some("/etc/passwd".into()),
                ..Edit::default()
            },
            "no robot directory is configured",
        ),
        (
            "c-nine-joints.mcap",
            Edit {
                n_joints: Some(9),
                ..Edit::default()
            },
            "reports 9 joints, robot iiwa14 has 7",
        ),
        (
            "d-six-joints.mcap",
            Edit {
                n_joints: Some(6),
                ..Edit::default()
            },
            "reports 6 joints",
        ),
        (
            "e-small-images.mcap",
            Edit {
                crop: Some((64, 48)),
                ..Edit::default()
            },
            "images of 64×48",
        ),
    ];
    for (name, edit, _) in &cases {
        rewrite(&good, &logs.join(name), edit);
    }
    let out = root.join("ds");
    let files = dataset::find_logs(std::slice::from_ref(&logs)).unwrap();
    let mut reported = Vec::new();
    let cfg = BuildConfig {
        block_samples: 4,
        ..BuildConfig::default()
    };
    let meta = dataset::build(&files, &out, &cfg, 2, |p, r| {
        if let Err(e) = r {
            reported.push((p.file_name().unwrap().to_string_lossy().to_string(), e));
        }
    })
    .expect("bad logs must not abort the build");
    assert_eq!(meta.episodes.len(), 1, "the good log builds");
    assert!(meta.samples > 10, "{} samples", meta.samples);
    assert_eq!(reported.len(), cases.len(), "{reported:?}");
    assert_eq!(meta.skipped.len(), cases.len());
    for ((name, _, why), (got, text)) in cases.iter().zip(&reported) {
        assert_eq!(name, got);
        assert!(text.contains(why), "{name}: {text}");
    }

    // The dataset as built opens and reads.
    let ds = Dataset::open(&out).unwrap();
    for (s, k) in ds.blocks() {
        ds.read_block(s, k).unwrap();
    }
    let meta_path = out.join("meta.json");
    let pristine = std::fs::read_to_string(&meta_path).unwrap();
    let wrench = std::fs::read(out.join("wrench.bin")).unwrap();
    let tamper = |f: &dyn Fn(&mut serde_json::Value)| -> String {
        let mut v: serde_json::Value = serde_json::from_str(&pristine).unwrap();
        f(&mut v);
        std::fs::write(&meta_path, serde_json::to_string(&v).unwrap()).unwrap();
        let r = Dataset::open(&out);
        std::fs::write(&meta_path, &pristine).unwrap();
        match r {
            Err(e @ DatasetError::BadMeta { .. }) => e.to_string(),
            Err(e) => panic!("wrong error: {e}"),
            Ok(_) => panic!("a tampered meta.json was accepted"),
        }
    };
    let e = tamper(&|v| v["episodes"][0]["samples"] = 1_000_000.into());
    assert!(e.contains("episodes[0]"), "{e}");
    let e = tamper(&|v| v["episodes"][0]["episode"] = 5.into());
    assert!(e.contains("episodes[0].episode"), "{e}");
    let e = tamper(&|v| v["shards"][0][0] = "../../../etc/passwd".into());
    assert!(e.contains("not a file name"), "{e}");
    let e = tamper(&|v| v["shards"][0][1][0]["length"] = (1u64 << 50).into());
    assert!(e.contains("outside the"), "{e}");
    let e = tamper(&|v| v["shards"][0][1][0]["samples"] = 4_000_000_000u64.into());
    assert!(e.contains("block 0"), "{e}");
    let e = tamper(&|v| v["width"] = 100_000.into());
    assert!(e.contains("image size"), "{e}");
    let e = tamper(&|v| v["build"]["block_samples"] = 0.into());
    assert!(e.contains("block_samples"), "{e}");
    // Episodes that do not tile the samples: the rest would count as
    // episode 0, and with no episodes at all the loader had none to index.
    let n = ds.meta.samples;
    let e = tamper(&|v| v["episodes"][0]["samples"] = (n - 1).into());
    assert!(
        e.contains(&format!("the episodes hold {} of the {n}", n - 1)),
        "{e}"
    );
    let e = tamper(&|v| v["episodes"] = serde_json::json!([]));
    assert!(
        e.contains(&format!("the episodes hold 0 of the {n}")),
        "{e}"
    );
    let e = tamper(&|v| {
        v["episodes"][0]["first_id"] = 1.into();
        v["episodes"][0]["samples"] = (n - 1).into();
    });
    assert!(e.contains("episodes[0]") && e.contains("tile"), "{e}");
    // A run's split that holds an episode out and trains on it too.
    let split = out.join("split.json");
    std::fs::write(&split, r#"{"train": [0], "test": [0]}"#).unwrap();
    let e = learner::train::Split::read(&split, &ds.meta)
        .expect_err("refused")
        .to_string();
    assert!(e.contains("episode 0 is in both train and test"), "{e}");
    // A list out of order or with a repeat: the sample counts bisect it.
    std::fs::write(&split, r#"{"train": [], "test": [0, 0]}"#).unwrap();
    let e = learner::train::Split::read(&split, &ds.meta)
        .expect_err("refused")
        .to_string();
    assert!(e.contains("test must list its episodes ascending"), "{e}");
    // A wrench window that matches a shortened table still disagrees with
    // the samples (the loader would copy windows of the wrong length).
    std::fs::write(out.join("wrench.bin"), &wrench[..wrench.len() / 2]).unwrap();
    let e = tamper(&|v| v["wrench_window"] = 16.into());
    assert!(e.contains("wrench_window"), "{e}");
    std::fs::write(out.join("wrench.bin"), &wrench).unwrap();

    // One flipped bit inside a block: its checksum names it.
    let ds = Dataset::open(&out).unwrap();
    let b = ds.meta.shards[0].1[1].clone();
    let shard = out.join(&ds.meta.shards[0].0);
    let mut bytes = std::fs::read(&shard).unwrap();
    bytes[(b.offset + b.length / 2) as usize] ^= 0x10;
    std::fs::write(&shard, &bytes).unwrap();
    let e = ds.read_block(0, 1).unwrap_err();
    assert!(matches!(e, DatasetError::BlockChecksum { .. }), "{e}");
    let text = e.to_string();
    assert!(text.contains("checksum") && text.contains(&format!("byte offset {}", b.offset)));
    // The loader reports it too, instead of training on damaged samples.
    let errors = Loader::new(
        &ds,
        LoaderConfig {
            batch: 4,
            ..LoaderConfig::default()
        },
    )
    .filter(|b| b.is_err())
    .count();
    assert_eq!(errors, 1);
}
