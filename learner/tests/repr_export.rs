//! `learner repr export`'s safetensors load into the PyTorch twin of the
//! Full Model (bench-anchors/torch-repr/bench.py) by its own
//! `load_state_dict(strict=True)`, and the twin computes what we do on the
//! same inputs: the z means our encoder gives the policy (the CPU fast
//! path) within 1e-4, and the variance and every decoder's output within
//! 1e-4 of their magnitude. The shipped policy's export, likewise, acts in
//! PyTorch as it does here. Needs scripts/torch-venv.sh's environment
//! (scripts/test.sh installs it and requires it).

use burn::prelude::*;
use learner::interop::repr_export::write_representation;
use learner::interop::safetensors::{Tensor as St, write};
use learner::models::init;
use learner::models::{
    Encoder, InputTensors, Modalities, ModelConfig, Normaliser, ObservationRef, ReprNet,
};
use std::collections::BTreeMap;
use std::path::PathBuf;

mod interop_venv;

/// A small deterministic stream of values in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.try_into_vec_as::<f32>().unwrap()
}

#[derive(serde::Deserialize, Debug)]
struct Diff {
    max_abs_diff: f64,
    max_abs: f64,
}

/// The Full Model the shipped policies observe through (full-near, d = 128,
/// 128 px, committed): z means within 1e-4, as the issue asks.
#[test]
fn the_exported_full_model_computes_in_the_pytorch_twin_what_it_does_here() {
    let Some(py) = interop_venv::torch_python("torch, safetensors.torch", "PyTorch is") else {
        return;
    };
    let dir =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../lab/results/full-near-repro/model");
    let (net, meta) = learner::train::checkpoint::import(&dir, &Device::flex()).unwrap();
    let z = agree_in_the_twin(&py, &net, &meta.model, &meta.normaliser);
    assert!(z.max_abs_diff < 1e-4, "z means: {z:?}");
}

/// A freshly initialised, small Full Model (d = 16, 64 px, one 3×3
/// convolution per depth stage), whose untrained z means are large: they
/// agree to 1e-4 of their magnitude.
#[test]
fn a_small_untrained_full_model_computes_in_the_twin_what_it_does_here() {
    let Some(py) = interop_venv::torch_python("torch, safetensors.torch", "PyTorch is") else {
        return;
    };
    let cfg = ModelConfig {
        latent_dim: 16,
        image_size: 64,
        depth_convs_per_stage: 1,
        ..Default::default()
    };
    let net = init::seeded(ReprNet::new(&cfg, &Device::flex()), 11);
    let normaliser = Normaliser {
        rgb_mean: [120.0, 110.0, 100.0],
        rgb_std: [60.0, 55.0, 50.0],
        depth_mean: 0.7,
        depth_std: 0.2,
        wrench_mean: [0.5, -0.2, 3.0, 0.01, 0.0, -0.02],
        wrench_std: [4.0, 4.0, 8.0, 0.3, 0.3, 0.1],
        ..Normaliser::identity()
    };
    agree_in_the_twin(&py, &net, &cfg, &normaliser);
}

/// Exports `net` (built for `cfg`), runs the twin on three random
/// observations normalised by `normaliser`, and checks that every output
/// agrees with ours to 1e-4 of its magnitude (at least 1); returns the z
/// means' difference.
fn agree_in_the_twin(
    py: &std::path::Path,
    net: &ReprNet,
    cfg: &ModelConfig,
    normaliser: &Normaliser,
) -> Diff {
    let dev = Device::flex();
    // Three observations: random pixels, depths with holes (no return),
    // wrench windows and proprioception.
    let (b, s) = (3, cfg.image_size);
    let mut r = Lcg(7);
    let rgb: Vec<Vec<u8>> = (0..b)
        .map(|_| (0..s * s * 3).map(|_| (r.next() * 255.0) as u8).collect())
        .collect();
    let depth: Vec<Vec<f32>> = (0..b)
        .map(|_| {
            (0..s * s)
                .map(|_| {
                    let v = r.next();
                    if v < 0.1 { 0.0 } else { 0.4 + 0.6 * v }
                })
                .collect()
        })
        .collect();
    let wrench: Vec<Vec<f32>> = (0..b)
        .map(|_| (0..32 * 6).map(|_| 10.0 * (r.next() - 0.5)).collect())
        .collect();
    let proprio: Vec<[f32; 8]> = (0..b)
        .map(|_| std::array::from_fn(|_| r.next() - 0.5))
        .collect();
    let obs: Vec<ObservationRef<'_>> = (0..b)
        .map(|i| ObservationRef {
            rgb: &rgb[i],
            depth: &depth[i],
            wrench: &wrench[i],
            proprio: &proprio[i],
        })
        .collect();
    let a = normaliser.inputs(&obs, s).unwrap();
    let action: Vec<f32> = (0..b * 4).map(|_| 2.0 * r.next() - 1.0).collect();

    // Ours: the z means the policy gets (the fast path), and burn's
    // forward pass with z at its mean for the rest.
    let z = Encoder::new(net.clone(), cfg.clone(), normaliser.clone(), &dev)
        .encode(&obs)
        .unwrap();
    let x = InputTensors::new(&a, &dev);
    let act = Tensor::<2>::from_data(TensorData::new(action.clone(), [b, 4]), &dev);
    let out = net.forward(cfg, &x, act, None, Modalities::ALL);
    let flow = out.flow.unwrap();
    let d = cfg.latent_dim;
    let case = vec![
        St::f32("rgb", &[b, 3, s, s], a.rgb.clone()),
        St::f32("depth", &[b, 1, s, s], a.depth.clone()),
        St::f32("wrench", &[b, 6, 32], a.wrench.clone()),
        St::f32("proprio", &[b, 8], a.proprio.clone()),
        St::f32("action", &[b, 4], action),
        St::f32("z_mean", &[b, d], z),
        St::f32("z_var", &[b, d], values(out.latent.var.unwrap())),
        St::f32("contact", &[b], values(out.contact_logits.unwrap())),
        St::f32("pairing", &[b], values(out.pairing_logits.unwrap())),
        St::f32("ee", &[b, 3], values(out.ee.unwrap())),
        St::f32("flow", &[b, 2, s, s], values(flow.flow)),
        St::f32("mask", &[b, 1, s, s], values(flow.mask_logits)),
    ];
    let dir = test_support::scratch_dir("repr-export");
    let export = dir.path().join("export");
    write_representation(net, cfg, normaliser, "test", &export).unwrap();
    let case_file = dir.path().join("case.safetensors");
    write(&case_file, &case, &BTreeMap::new()).unwrap();

    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = interop_venv::run_ok(
        std::process::Command::new(py)
            .arg(root.join("tests/data/torch_twin.py"))
            .arg(root.join("../bench-anchors/torch-repr"))
            .arg(&export)
            .arg(&case_file),
    );
    let mut diffs: BTreeMap<String, Diff> = serde_json::from_slice(&out).unwrap();
    println!("{diffs:#?}");
    assert_eq!(diffs.len(), 7);
    for (k, v) in &diffs {
        assert!(v.max_abs_diff <= 1e-4 * v.max_abs.max(1.0), "{k}: {v:?}");
    }
    let z = diffs.remove("z_mean").unwrap();
    assert!(z.max_abs > 1e-3, "z means all near 0: {z:?}");
    z
}

/// A model the export cannot read is named.
#[test]
fn exporting_a_directory_without_a_model_names_it() {
    let dir = test_support::scratch_dir("repr-export-missing");
    let e = learner::interop::repr_export::export_model_dir(dir.path(), &dir.path().join("out"))
        .unwrap_err();
    assert!(
        format!("{e:#}").contains(&dir.path().display().to_string()),
        "{e:#}"
    );
}

/// `learner repr export` writes both files; the spec lists every tensor
/// with its shape, and the file's metadata holds the same spec.
#[test]
fn the_command_writes_the_weights_and_their_spec() {
    let dir = test_support::scratch_dir("repr-export-cli");
    let model =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../lab/results/full-near-repro/model");
    interop_venv::run_ok(
        std::process::Command::new(env!("CARGO_BIN_EXE_learner"))
            .args(["repr", "export", "--model"])
            .arg(&model)
            .arg("--out")
            .arg(dir.path()),
    );
    let spec: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("representation-spec.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(spec["model"]["latent_dim"], 128);
    let tensors = spec["tensors"].as_array().unwrap();
    assert!(
        tensors
            .iter()
            .any(|t| t[0] == "rgb.convs.0.weight" && t[1] == serde_json::json!([16, 3, 7, 7])),
        "{tensors:?}"
    );
    assert!(
        tensors
            .iter()
            .any(|t| t[0] == "proprio.layers.3.weight" && t[1] == serde_json::json!([256, 128])),
        "{tensors:?}"
    );
    let bytes = std::fs::read(dir.path().join("representation.safetensors")).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let meta: serde_json::Value =
        serde_json::from_str(header["__metadata__"]["spec"].as_str().unwrap()).unwrap();
    assert_eq!(meta, spec);
    assert_eq!(header["rgb.fc.weight"]["dtype"], "F32");
}

/// The policy's MLP in PyTorch as the spec says: float64 `nn.Linear`
/// layers with tanh between, after the clipped normalisation.
const TORCH_ACT: &str = r#"
import json, sys, torch
from safetensors.torch import load_file
t = load_file(sys.argv[1] + "/policy.safetensors")
spec = json.load(open(sys.argv[1] + "/policy-spec.json"))
mods = []
for i in range(spec["layers"]):
    w, b = t[f"layers.{i}.weight"], t[f"layers.{i}.bias"]
    lin = torch.nn.Linear(w.shape[1], w.shape[0], dtype=torch.float64)
    lin.load_state_dict({"weight": w, "bias": b})
    mods.append(lin)
    if i + 1 < spec["layers"]:
        mods.append(torch.nn.Tanh())
net = torch.nn.Sequential(*mods)
x = torch.tensor(json.loads(sys.argv[2]), dtype=torch.float64)
c = spec["obs_norm_clip"]
if c is not None:
    x = ((x - t["obs_norm.shift"]) * t["obs_norm.scale"]).clamp(-c, c)
with torch.no_grad():
    print(json.dumps(net(x).tolist()))
"#;

/// The shipped policy through `learner policy export`: its MLP in PyTorch
/// gives our means within 1e-9, and the encoder written beside it is
/// `learner repr export`'s of its model, the one the twin checks above; so
/// a PyTorch user has the whole policy on z.
#[test]
fn the_shipped_policy_exports_for_pytorch() {
    let Some(py) = interop_venv::torch_python("torch, safetensors.torch", "PyTorch is") else {
        return;
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let ckpt = root.join("artifacts/z-ppo-square/checkpoint.json");
    let dir = test_support::scratch_dir("policy-export-torch");
    let (policy_dir, repr_dir) = (dir.join("policy"), dir.join("repr"));
    let learner = || std::process::Command::new(env!("CARGO_BIN_EXE_learner"));
    interop_venv::run_ok(
        learner()
            .args(["policy", "export", "--checkpoint"])
            .arg(&ckpt)
            .arg("--out")
            .arg(&policy_dir),
    );
    interop_venv::run_ok(
        learner()
            .args(["repr", "export", "--model"])
            .arg(root.join("artifacts/z-ppo-square/model"))
            .arg("--out")
            .arg(&repr_dir),
    );
    let st = "representation.safetensors";
    assert_eq!(
        std::fs::read(policy_dir.join(st)).unwrap(),
        std::fs::read(repr_dir.join(st)).unwrap()
    );
    let c = learner::rl::run::read_checkpoint(&ckpt).unwrap();
    let policy = c.chosen_policy(false).policy;
    let dim = policy.sizes[0];
    assert_eq!(dim, 128);
    // z-like inputs, some far outside the statistics.
    let obs: Vec<Vec<f64>> = (0..4)
        .map(|k| {
            (0..dim)
                .map(|i| ((k * 5 + i * 7) % 13) as f64 * 0.25 - 1.5)
                .collect()
        })
        .collect();
    let out = interop_venv::run_ok(
        std::process::Command::new(&py)
            .args(["-c", TORCH_ACT])
            .arg(&policy_dir)
            .arg(serde_json::to_string(&obs).unwrap()),
    );
    let theirs: Vec<Vec<f64>> = serde_json::from_slice(&out).unwrap();
    for (o, t) in obs.iter().zip(&theirs) {
        let ours = policy.means(o);
        assert_eq!(ours.len(), t.len());
        for (a, b) in ours.iter().zip(t) {
            assert!((a - b).abs() < 1e-9, "ours {ours:?}, PyTorch's {t:?}");
        }
    }
}
