//! What the learner writes for other tools and later readers, read by
//! those tools' own code: a training run's TensorBoard event file, read by
//! TensorBoard's reader (`event_accumulator`), holds the same rows as its
//! CSV files; `run.json` records the commit, the host, the start time, the
//! command line and the resolved configuration, one entry per start (a
//! resumed run adds one); an exported policy's safetensors, loaded by
//! `safetensors.numpy` and run in NumPy as its spec says, acts as ours.

use std::process::{Command, Stdio};

/// The readers' interpreter: `$INTEROP_PYTHON`, else the repository's
/// `.venv-interop` (scripts/interop-venv.sh). None (the test then skips)
/// when it cannot import them and `$INTEROP_REQUIRED` is not 1
/// (scripts/test.sh sets it) and `$CI` is unset.
fn interop_python() -> Option<std::path::PathBuf> {
    let py = std::env::var_os("INTEROP_PYTHON")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv-interop/bin/python")
        });
    let ok = Command::new(&py)
        .args(["-c", "import tensorboard, safetensors.numpy"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let required =
        std::env::var("INTEROP_REQUIRED").is_ok_and(|v| v == "1") || std::env::var("CI").is_ok();
    assert!(
        ok || !required,
        "tensorboard and safetensors are required here but `{} -c 'import tensorboard, \
         safetensors.numpy'` fails; run scripts/interop-venv.sh",
        py.display()
    );
    if !ok {
        eprintln!(
            "\n*** SKIPPED: tensorboard is not importable by {} ***\n",
            py.display()
        );
    }
    ok.then_some(py)
}

const READ: &str = r#"
import json, sys
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
acc = EventAccumulator(sys.argv[1], size_guidance={"scalars": 0})
acc.Reload()
print(json.dumps({t: [[e.step, e.value] for e in acc.Scalars(t)] for t in acc.Tags()["scalars"]}))
"#;

/// Column `name` of a CSV file, as (env_steps, value) rows.
fn column(path: &std::path::Path, name: &str) -> Vec<(u64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let steps = header.iter().position(|&h| h == "env_steps").unwrap();
    let col = header.iter().position(|&h| h == name).unwrap();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[steps].parse().unwrap(), f[col].parse().unwrap())
        })
        .collect()
}

#[test]
fn a_policy_run_writes_tensorboard_scalars_and_its_provenance() {
    let dir = test_support::scratch_dir("runlog");
    let out = dir.path().join("run");
    let text = "num_envs = 1\nenv_steps = 40\n[policy]\nbatch_steps = 20\n\
                [env]\nmax_steps = 20\n[validation]\nevery = 1\nepisodes = 1\n";
    let mut run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    learner::rl::run::train(run.clone(), &out, false, &|| false).unwrap();
    run.env_steps = 60;
    learner::rl::run::train(run, &out, true, &|| false).unwrap();

    let starts: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(starts.len(), 2, "one entry per start");
    for s in &starts {
        assert!(s["host"].as_str().is_some_and(|h| !h.is_empty()), "{s}");
        assert!(
            s["started"].as_str().is_some_and(|t| t.ends_with('Z')),
            "{s}"
        );
        assert!(s["argv"].as_array().is_some_and(|a| !a.is_empty()), "{s}");
        // The repository the test runs in is a git checkout.
        assert_eq!(s["commit"].as_str().map(str::len), Some(40), "{s}");
        assert!(s["dirty"].is_boolean(), "{s}");
    }
    assert_eq!(
        starts[1]["config"]["env_steps"], 60,
        "the resolved configuration"
    );

    let events: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| {
            let n = e.unwrap().file_name().into_string().unwrap();
            n.starts_with("events.out.tfevents.").then_some(n)
        })
        .collect();
    assert_eq!(events.len(), 2, "one event file per start: {events:?}");
    let Some(py) = interop_python() else {
        return;
    };
    let read = Command::new(py)
        .args(["-c", READ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let scalars: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    for (csv, tag, col) in [
        ("curve.csv", "train/mean_normalised", "mean_normalised"),
        ("curve.csv", "train/kl", "kl"),
        (
            "validation.csv",
            "validation/completed_insertion",
            "completed_insertion",
        ),
        (
            "validation.csv",
            "validation/mean_normalised",
            "mean_normalised",
        ),
    ] {
        let want = column(&out.join(csv), col);
        let got: Vec<(u64, f64)> = scalars[tag]
            .as_array()
            .unwrap_or_else(|| panic!("no {tag} in {scalars}"))
            .iter()
            .map(|p| (p[0].as_u64().unwrap(), p[1].as_f64().unwrap()))
            .collect();
        assert_eq!(got.len(), want.len(), "{tag}: {got:?} vs {want:?}");
        for ((gs, gv), (ws, wv)) in got.iter().zip(&want) {
            assert_eq!(gs, ws, "{tag}");
            assert!(
                (gv - wv).abs() <= 1e-6 * wv.abs().max(1.0),
                "{tag}: {gv} vs {wv}"
            );
        }
    }
}

const ACT: &str = r#"
import json, sys
import numpy as np
from safetensors.numpy import load_file
t = load_file(sys.argv[1] + "/policy.safetensors")
spec = json.load(open(sys.argv[1] + "/policy-spec.json"))
out = []
for o in json.loads(sys.argv[2]):
    x = np.array(o)
    if spec["obs_norm_clip"] is not None:
        c = spec["obs_norm_clip"]
        x = np.clip((x - t["obs_norm.shift"]) * t["obs_norm.scale"], -c, c)
    for i in range(spec["layers"]):
        x = t[f"layers.{i}.weight"] @ x + t[f"layers.{i}.bias"]
        if i + 1 < spec["layers"]:
            x = np.tanh(x)
    out.append(x.tolist())
print(json.dumps(out))
"#;

#[test]
fn an_exported_policy_acts_in_numpy_as_it_does_here() {
    let dir = test_support::scratch_dir("interop-policy");
    let out = dir.path().join("run");
    let text = "num_envs = 1\nenv_steps = 40\n[policy]\nbatch_steps = 20\n\
                normalise_observations = true\n[env]\nmax_steps = 20\n";
    let run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    let c = learner::rl::run::train(run, &out, false, &|| false).unwrap();
    let policy = &c.state.policy;
    assert!(
        policy.obs_norm.is_some(),
        "the normalisation is exported too"
    );
    let d = learner::rl::export::from_checkpoint(&out.join("checkpoint.json"), true).unwrap();
    let export = dir.path().join("export");
    std::fs::create_dir_all(&export).unwrap();
    learner::rl::export::write_safetensors(&d.policy, &export).unwrap();
    // Observations unlike one another, some far outside the statistics.
    let dim = policy.sizes[0];
    let obs: Vec<Vec<f64>> = (0..5)
        .map(|k| {
            (0..dim)
                .map(|i| ((k * 7 + i * 3) % 11) as f64 * 0.3 - 1.5)
                .collect()
        })
        .collect();
    let Some(py) = interop_python() else {
        return;
    };
    let run = Command::new(py)
        .args(["-c", ACT])
        .arg(&export)
        .arg(serde_json::to_string(&obs).unwrap())
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let theirs: Vec<Vec<f64>> = serde_json::from_slice(&run.stdout).unwrap();
    for (o, t) in obs.iter().zip(&theirs) {
        let ours = policy.means(o);
        assert_eq!(ours.len(), t.len());
        for (a, b) in ours.iter().zip(t) {
            assert!((a - b).abs() < 1e-9, "ours {ours:?}, NumPy's {t:?}");
        }
    }
}
