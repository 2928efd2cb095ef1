//! The learner's file readers fuzzed as the control cycle is (proptest):
//! random damage to a deployed policy file, a dataset's meta.json and its
//! shards. Each input either loads, and then what it loads works, or is
//! refused with an error naming the file; never a panic. (The MCAP reader's
//! fuzz is tests/log.rs's bit flips and truncations, and tests/log_bounds.rs
//! for the claims a file makes about its sizes.)

mod one_episode;

use learner::dataset::{self, BuildConfig, Dataset, Loader, LoaderConfig};
use learner_node::deploy::{
    ActionScale, DeployedPolicy, Deployment, LayerSpec, ObservationSpec, PolicyFile,
};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A small ground-truth policy file's text.
fn policy_text() -> String {
    let layer = |inputs: usize, outputs: usize| LayerSpec {
        inputs,
        outputs,
        weight: (0..inputs * outputs)
            .map(|k| 0.01 * (k % 13) as f64 - 0.06)
            .collect(),
        bias: vec![0.1; outputs],
    };
    let p = PolicyFile {
        format: learner_node::deploy::FORMAT.into(),
        version: learner_node::deploy::VERSION,
        source: "fuzz".into(),
        observation: ObservationSpec::GroundTruth,
        obs_norm: None,
        layers: vec![layer(18, 6), layer(6, 4)],
        action_scale: ActionScale::default(),
        peg: hw_sim::PegShape::Square,
    };
    serde_json::to_string_pretty(&p).unwrap()
}

/// One damage to a text or a byte string.
#[derive(Debug, Clone)]
enum Damage {
    /// XOR the byte at this fraction of the length.
    Flip(f64, u8),
    /// Cut the input at this fraction.
    Cut(f64),
    /// Replace the number nearest this fraction with this text.
    Number(f64, &'static str),
    /// Parse the JSON and set its numeric leaf at this fraction (of the
    /// leaves, in document order) to this value: the text stays JSON, so
    /// the damage reaches the reader's own checks.
    Leaf(f64, f64),
}

fn damage() -> impl Strategy<Value = Damage> {
    let edge = prop::sample::select(vec![
        "0",
        "-1",
        "1e308",
        "-1e308",
        "1e999",
        "18446744073709551615",
        "18446744073709551616",
        "4294967296",
        "0.5",
        "NaN",
        "[]",
        "null",
    ]);
    prop_oneof![
        (0.0..1.0f64, 1u8..=255).prop_map(|(at, x)| Damage::Flip(at, x)),
        (0.0..1.0f64).prop_map(Damage::Cut),
        (0.0..1.0f64, edge).prop_map(|(at, v)| Damage::Number(at, v)),
        (0.0..1.0f64, leaf_value()).prop_map(|(at, v)| Damage::Leaf(at, v)),
        (0.0..1.0f64, leaf_value()).prop_map(|(at, v)| Damage::Leaf(at, v)),
    ]
}

fn leaf_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::sample::select(vec![
            0.0,
            1.0,
            -1.0,
            2.0,
            1e9,
            4294967296.0,
            1.8e19,
            -1e300,
            0.5
        ]),
        -100.0..100_000.0f64,
    ]
}

/// The numeric leaves of `v`, in document order.
fn leaves(v: &mut serde_json::Value) -> Vec<&mut serde_json::Value> {
    match v {
        serde_json::Value::Number(_) => vec![v],
        serde_json::Value::Array(a) => a.iter_mut().flat_map(leaves).collect(),
        serde_json::Value::Object(o) => o.values_mut().flat_map(leaves).collect(),
        _ => Vec::new(),
    }
}

fn apply(bytes: &[u8], d: &Damage) -> Vec<u8> {
    let at = |f: f64| ((f * bytes.len() as f64) as usize).min(bytes.len().saturating_sub(1));
    let mut out = bytes.to_vec();
    if out.is_empty() {
        return out;
    }
    match *d {
        Damage::Flip(f, x) => out[at(f)] ^= x,
        Damage::Cut(f) => out.truncate(at(f)),
        Damage::Number(f, v) => {
            // The first run of digits at or after the point.
            let start = (at(f)..bytes.len()).find(|&i| bytes[i].is_ascii_digit());
            if let Some(s) = start {
                let end = (s..bytes.len())
                    .find(|&i| !bytes[i].is_ascii_digit())
                    .unwrap_or(bytes.len());
                out.splice(s..end, v.bytes());
            }
        }
        Damage::Leaf(f, x) => {
            if let Ok(mut v) = serde_json::from_slice::<serde_json::Value>(bytes) {
                let mut all = leaves(&mut v);
                if !all.is_empty() {
                    let k = ((f * all.len() as f64) as usize).min(all.len() - 1);
                    // Integers where the value is one, so that integer
                    // fields take it.
                    *all[k] = if x.fract() == 0.0 && (0.0..1.8e19).contains(&x) {
                        (x as u64).into()
                    } else if x.fract() == 0.0 && x > -9e18 && x < 0.0 {
                        (x as i64).into()
                    } else {
                        x.into()
                    };
                    out = serde_json::to_vec(&v).unwrap();
                }
            }
        }
    }
    out
}

/// A dataset of one short heuristic episode, built once per test binary.
fn dataset_dir() -> &'static Path {
    static DIR: OnceLock<(test_support::ScratchDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let root = test_support::scratch_dir("fuzz-readers");
        let mut world = hw_sim::WorldConfig::default();
        world.camera.width = 32;
        world.camera.height = 32;
        let log = one_episode::collect_one(&root.join("logs"), world, 9);
        let out = root.join("ds");
        let b = BuildConfig {
            block_samples: 4,
            ..BuildConfig::default()
        };
        dataset::build(&[log], &out, &b, 1, |p, r| {
            if let Err(e) = r {
                panic!("{}: {e}", p.display());
            }
        })
        .unwrap();
        (root, out)
    })
    .1
}

/// The dataset's shard and its samples as built, read once.
fn pristine() -> &'static (String, Vec<Vec<dataset::Sample>>) {
    static PRISTINE: OnceLock<(String, Vec<Vec<dataset::Sample>>)> = OnceLock::new();
    PRISTINE.get_or_init(|| {
        let ds = Dataset::open(dataset_dir()).unwrap();
        (
            ds.meta.shards[0].0.clone(),
            read_all(dataset_dir()).unwrap(),
        )
    })
}

/// A damaged copy of the dataset: `file` replaced by `bytes`.
fn damaged_copy(file: &str, bytes: &[u8]) -> test_support::ScratchDir {
    let dir = test_support::scratch_dir("fuzz-ds");
    for e in std::fs::read_dir(dataset_dir()).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    std::fs::write(dir.path().join(file), bytes).unwrap();
    dir
}

/// Opens and reads everything of a dataset; an error must name its folder.
fn read_all(dir: &Path) -> Result<Vec<Vec<dataset::Sample>>, String> {
    let named = |e: dataset::DatasetError| {
        let text = e.to_string();
        assert!(text.contains(&*dir.to_string_lossy()), "{text}");
        text
    };
    let ds = Dataset::open(dir).map_err(named)?;
    let mut blocks = Vec::new();
    for (s, k) in ds.blocks() {
        blocks.push(ds.read_block(s, k).map_err(named)?);
    }
    // The loader over what opened: batches or errors, no panic.
    let cfg = LoaderConfig {
        batch: 3,
        ..LoaderConfig::default()
    };
    for b in Loader::new(&ds, cfg) {
        b.map_err(named)?;
    }
    Ok(blocks)
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 96,
        ..ProptestConfig::default()
    })]

    #[test]
    fn a_damaged_policy_file_loads_and_acts_finitely_or_is_refused(
        d in prop::collection::vec(damage(), 1..4)
    ) {
        let mut bytes = policy_text().into_bytes();
        for one in &d {
            bytes = apply(&bytes, one);
        }
        let dir = test_support::scratch_dir("fuzz-policy");
        let path = dir.path().join("policy.json");
        std::fs::write(&path, &bytes).unwrap();
        let loaded = DeployedPolicy::load(&path);
        // The same text through the in-memory path (a checkpoint's
        // conversion) is accepted or refused alike.
        let parsed = std::str::from_utf8(&bytes)
            .map_err(|e| e.to_string())
            .and_then(PolicyFile::parse);
        if let Ok(policy) = &parsed {
            let d = Deployment { policy: policy.clone(), encoder: None };
            prop_assert_eq!(DeployedPolicy::new(d, &path).is_ok(), loaded.is_ok());
        }
        match loaded {
            Err(e) => prop_assert!(e.to_string().contains("policy.json"), "{}", e),
            Ok(p) => {
                // What the node sends: within the file's own step limits.
                let scale = &parsed.as_ref().expect("a loaded file parses").action_scale;
                for x in [0.0, 0.5, -3.0, 1e6] {
                    let means = p.means(&[x; 18]);
                    prop_assert_eq!(means.len(), 4);
                    let d = scale.to_delta(&means);
                    prop_assert!(
                        d[..3].iter().all(|v| v.abs() <= scale.max_step_m)
                            && d[3].abs() <= scale.max_roll_rad,
                        "{:?}",
                        d
                    );
                }
            }
        }
    }

    #[test]
    fn a_damaged_meta_json_opens_and_reads_or_is_refused(
        d in prop::collection::vec(damage(), 1..3)
    ) {
        let pristine = std::fs::read(dataset_dir().join("meta.json")).unwrap();
        let mut bytes = pristine.clone();
        for one in &d {
            bytes = apply(&bytes, one);
        }
        let dir = damaged_copy("meta.json", &bytes);
        let _ = read_all(dir.path());
    }

    #[test]
    fn a_damaged_shard_reads_back_unchanged_or_is_refused(
        flips in prop::collection::vec((0.0..1.0f64, 1u8..=255), 1..5)
    ) {
        let (shard, pristine) = pristine();
        let mut bytes = std::fs::read(dataset_dir().join(shard)).unwrap();
        for (f, x) in &flips {
            let at = ((f * bytes.len() as f64) as usize).min(bytes.len() - 1);
            bytes[at] ^= x;
        }
        let dir = damaged_copy(shard, &bytes);
        if let Ok(got) = read_all(dir.path()) {
            // Undetected damage must not change a sample.
            prop_assert!(&got == pristine, "damage changed the samples unnoticed");
        }
    }
}
