//! `learner dataset import` on files in the authors' HDF5 layout, written by
//! h5py (tests/data/write_authors_h5.py) both uncompressed and
//! gzip-chunked: every field of every imported sample is checked against
//! the formulas the files were written from, and files that differ from
//! the layout are refused naming the file, the key, expected and found.
//!
//! The interpreter is `$INTEROP_PYTHON`, else the repository's
//! `.venv-interop` (scripts/interop-venv.sh, which installs h5py). Without
//! h5py the test is skipped with a message, unless `$INTEROP_REQUIRED=1`
//! or `$CI` is set: then it fails.

use learner::dataset::{self, BuildConfig, Dataset, DatasetError, Sample};
use shared_mem_schema::Stage;
use std::path::{Path, PathBuf};
use std::process::Command;

const T: usize = 50;
const H: usize = 128;
const W: usize = 128;

mod interop_venv;

fn h5py() -> Option<PathBuf> {
    interop_venv::python("h5py", "h5py is")
}

fn write(py: &Path, out: &Path, episode: usize, storage: &str, fault: Option<&str>) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/write_authors_h5.py");
    let mut cmd = Command::new(py);
    cmd.arg(script)
        .arg(out)
        .arg(episode.to_string())
        .arg(storage);
    if let Some(f) = fault {
        cmd.arg(f);
    }
    interop_venv::run_ok(&mut cmd);
}

/// Sample `s` of episode `e` as the writer's formulas give it (numpy's
/// float64 arithmetic in the same order, then f32).
fn expected(e: usize, s: usize) -> Sample {
    let (ef, sf) = (e as f64, s as f64);
    let mut rgb = Vec::with_capacity(H * W * 3);
    let mut depth = Vec::with_capacity(H * W);
    let mut flow = Vec::with_capacity(H * W * 2);
    let mut mask = Vec::with_capacity(H * W);
    for y in 0..H {
        for x in 0..W {
            for c in 0..3 {
                rgb.push(((s * 7 + y * 3 + x * 5 + c + e) % 256) as u8);
            }
            depth.push((0.5 + 0.001 * (s + y + x + e) as f64) as f32);
            let fx = (((s + y + x) % 5) as f64 - 2.0) * 0.25;
            let fy = (((2 * s + x) % 3) as f64 - 1.0) * 0.5;
            flow.extend([fx as f32, fy as f32]);
            mask.push(u8::from(fx as f32 + fy as f32 != 0.0));
        }
    }
    let mut wrench = Vec::new();
    for r in 18..50 {
        for j in 0..6 {
            wrench.push((sf + 0.01 * r as f64 + 0.1 * j as f64 + ef) as f32);
        }
    }
    let proprio =
        |t: usize| -> [f32; 8] { std::array::from_fn(|i| (t as f64 * 0.1 + i as f64 + ef) as f32) };
    // In contact from step 20 + e to 39; the stage stays touched after.
    let contact = |t: usize| (20 + e..40).contains(&t);
    Sample {
        episode: e as u32,
        index: s as u32,
        step: s as u64,
        contact: contact(s),
        contact_next: contact(s + 1),
        stage: if s >= 20 + e {
            Stage::Touched
        } else {
            Stage::Failed
        },
        rgb,
        depth,
        wrench,
        proprio: proprio(s),
        action: std::array::from_fn(|i| {
            ((s + 1) as f64 * 0.01 + i as f64 * 0.001 - ef * 0.002) as f32
        }),
        flow,
        mask,
        ee_next: proprio(s + 1)[..4].try_into().unwrap(),
    }
}

#[test]
fn the_authors_layout_imports_field_by_field_plain_and_gzip() {
    let Some(py) = h5py() else { return };
    let dir = test_support::scratch_dir("import");
    let src = dir.path().join("h5");
    std::fs::create_dir_all(&src).unwrap();
    write(&py, &src.join("episode-0.h5"), 0, "plain", None);
    write(&py, &src.join("episode-1.h5"), 1, "gzip", None);
    let out = dir.path().join("dataset");
    let files = dataset::find_hdf5(std::slice::from_ref(&src)).unwrap();
    assert_eq!(files.len(), 2);
    let meta = dataset::import(
        &files,
        &out,
        hw_sim::PegShape::Triangle,
        &BuildConfig::default(),
        |_, n| assert_eq!(n, T - 1),
    )
    .unwrap();
    assert_eq!(meta.samples, 2 * (T as u64 - 1));
    assert_eq!((meta.width, meta.height), (W, H));
    assert!(meta.episodes.iter().all(|e| e.policy.name() == "imported"));
    let ds = Dataset::open(&out).unwrap();
    let mut samples = Vec::new();
    for (shard, block) in ds.blocks() {
        samples.extend(ds.read_block(shard, block).unwrap());
    }
    assert_eq!(samples.len(), 2 * (T - 1));
    for got in &samples {
        let want = expected(got.episode as usize, got.index as usize);
        assert_eq!(got.rgb, want.rgb, "rgb of {}/{}", got.episode, got.index);
        assert_eq!(got.depth, want.depth, "depth");
        assert_eq!(got.flow, want.flow, "flow");
        assert_eq!(got.mask, want.mask, "mask");
        assert_eq!(got.wrench, want.wrench, "wrench");
        assert_eq!(
            (got.proprio, got.action, got.ee_next),
            (want.proprio, want.action, want.ee_next)
        );
        assert_eq!(
            (got.contact, got.contact_next, got.stage, got.step),
            (want.contact, want.contact_next, want.stage, want.step),
            "labels of {}/{}",
            got.episode,
            got.index
        );
    }
    // Contact turns on within both episodes, so the pairing table has
    // negatives of both states.
    assert!(samples.iter().any(|s| s.contact) && samples.iter().any(|s| !s.contact));
}

#[test]
fn a_file_that_differs_from_the_layout_is_named_with_its_key() {
    let Some(py) = h5py() else { return };
    let dir = test_support::scratch_dir("import-bad");
    for (fault, key, expected, found) in [
        ("missing-contact", "contact", "the key present", "NotFound"),
        ("proprio-7", "proprio", "shape [50, 8]", "shape [50, 7]"),
        ("image-float", "image", "uint8", "float32"),
        ("forces-nan", "ee_forces_continuous", "finite values", "NaN"),
    ] {
        let file = dir.path().join(format!("{fault}.h5"));
        write(&py, &file, 0, "gzip", Some(fault));
        let err = dataset::import_file(&file, hw_sim::PegShape::Triangle)
            .err()
            .expect("a bad file must be refused");
        match &err {
            DatasetError::Import {
                file: f, key: k, ..
            } => {
                assert_eq!((f.as_path(), k.as_str()), (file.as_path(), key));
            }
            e => panic!("{fault}: wrong error {e}"),
        }
        let text = err.to_string();
        for part in [
            file.display().to_string(),
            key.into(),
            expected.into(),
            found.into(),
        ] {
            assert!(text.contains(&part), "{fault}: `{text}` lacks `{part}`");
        }
    }
    // Nothing else than HDF5 is taken for it.
    let not_h5 = dir.path().join("text.h5");
    std::fs::write(&not_h5, "not hdf5").unwrap();
    let err = dataset::import_file(&not_h5, hw_sim::PegShape::Triangle)
        .err()
        .unwrap();
    assert!(err.to_string().contains("an HDF5 file"), "{err}");
}
