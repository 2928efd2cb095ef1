//! The representation model's pieces on known inputs: shapes of every
//! module, the product of experts and the KL against hand computation, each
//! loss, and run-time modality masking.

use burn::prelude::*;
use learner::models::fusion::{self, Gaussian};
use learner::models::losses::{bce_with_logits, endpoint_error};
use learner::models::net::tensor;
use learner::models::{InputTensors, Modalities, ModelConfig, ModelKind, ReprNet};

fn device() -> Device {
    Device::flex()
}

/// A network with seeded weights.
fn new_net(cfg: &ModelConfig, dev: &Device) -> ReprNet {
    learner::models::init::seeded(ReprNet::new(cfg, dev), 5)
}

fn vals<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.try_into_vec_as::<f32>().unwrap()
}

fn close(a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * (1.0 + y.abs()),
            "element {i}: {x} vs {y}"
        );
    }
}

/// Random normalised inputs for `b` samples of side `s`.
fn inputs(b: usize, s: usize, seed: u64, dev: &Device) -> InputTensors {
    let mut r = test_support::rng(seed);
    let mut v = |n: usize| -> Vec<f32> {
        (0..n)
            .map(|_| rand::RngExt::random_range(&mut r, -1.0f32..1.0))
            .collect()
    };
    InputTensors {
        rgb: tensor(v(b * 3 * s * s), [b, 3, s, s], dev),
        depth: tensor(v(b * s * s), [b, 1, s, s], dev),
        wrench: tensor(v(b * 6 * 32), [b, 6, 32], dev),
        proprio: tensor(v(b * 8), [b, 8], dev),
    }
}

fn config(kind: ModelKind, d: usize, side: usize) -> ModelConfig {
    ModelConfig {
        kind,
        latent_dim: d,
        image_size: side,
        ..ModelConfig::default()
    }
}

#[test]
fn every_module_gives_the_papers_shapes_at_128_px() {
    let dev = device();
    let cfg = config(ModelKind::Full, 128, 128);
    cfg.validate().unwrap();
    let net = new_net(&cfg, &dev);
    let x = inputs(2, 128, 1, &dev);
    let act = tensor(vec![0.1; 8], [2, 4], &dev);
    let eps = tensor(vec![0.5; 2 * 128], [2, 128], &dev);
    let out = net.forward(&cfg, &x, act, Some(eps), Modalities::ALL);
    // The RGB encoder's six maps: 64, 32, 16, 8, 4, 2 px.
    let sides: Vec<usize> = out.latent.maps.iter().map(|m| m.dims()[2]).collect();
    assert_eq!(sides, [64, 32, 16, 8, 4, 2]);
    assert_eq!(out.latent.maps[5].dims(), [2, 128, 2, 2]);
    assert_eq!(out.latent.mean.dims(), [2, 128]);
    assert_eq!(out.latent.var.as_ref().unwrap().dims(), [2, 128]);
    assert_eq!(out.z.dims(), [2, 128]);
    assert_eq!(out.contact_logits.as_ref().unwrap().dims(), [2]);
    assert_eq!(out.pairing_logits.as_ref().unwrap().dims(), [2]);
    assert_eq!(out.ee.as_ref().unwrap().dims(), [2, 3]);
    let f = out.flow.as_ref().unwrap();
    assert_eq!(f.flow.dims(), [2, 2, 128, 128]);
    assert_eq!(f.mask_logits.dims(), [2, 1, 128, 128]);
    assert!(out.recon.is_none());
    // Variances are positive.
    assert!(vals(out.latent.var.unwrap()).iter().all(|&v| v > 0.0));
}

#[test]
fn the_baselines_have_their_own_parts() {
    let dev = device();
    let x = inputs(3, 64, 2, &dev);
    let act = tensor(vec![0.0; 12], [3, 4], &dev);
    let det = config(ModelKind::Deterministic, 16, 64);
    let out = new_net(&det, &dev).forward(&det, &x, act.clone(), None, Modalities::ALL);
    assert!(
        out.latent.var.is_none(),
        "the deterministic model has no variance"
    );
    assert_eq!(out.z.dims(), [3, 16]);
    assert_eq!(out.flow.unwrap().flow.dims(), [3, 2, 64, 64]);
    // The authors' end-effector target: the next position and roll.
    let pose = ModelConfig {
        ee_target: learner::models::EeTarget::Pose,
        ..config(ModelKind::Full, 16, 64)
    };
    let out = new_net(&pose, &dev).forward(&pose, &x, act.clone(), None, Modalities::ALL);
    assert_eq!(out.ee.unwrap().dims(), [3, 4]);
    let rec = config(ModelKind::Reconstruction, 16, 64);
    let out = new_net(&rec, &dev).forward(&rec, &x, act, None, Modalities::ALL);
    assert!(out.flow.is_none() && out.contact_logits.is_none() && out.pairing_logits.is_none());
    let r = out.recon.unwrap();
    assert_eq!(r.rgb.dims(), [3, 3, 64, 64]);
    assert_eq!(r.wrench.dims(), [3, 6]);
    assert_eq!(r.proprio.dims(), [3, 8]);
    let rgb = vals(r.rgb);
    assert!(
        rgb.iter().all(|&v| (0.0..=1.0).contains(&v)),
        "sigmoid output"
    );
}

#[test]
fn the_product_of_experts_matches_a_hand_computed_case() {
    let dev = device();
    // Two experts over d = 2: means (1, −2) and (3, 0), variances (1, 4)
    // and (0.5, 1). With the prior (0, 1):
    //   precision = 1 + 1 + 2 = 4 and 1 + 0.25 + 1 = 2.25
    //   mean = (1·1 + 3·2) / 4 = 1.75 and (−2·0.25 + 0) / 2.25 = −0.2222…
    let e = [
        Gaussian {
            mean: tensor(vec![1.0, -2.0], [1, 2], &dev),
            var: tensor(vec![1.0, 4.0], [1, 2], &dev),
        },
        Gaussian {
            mean: tensor(vec![3.0, 0.0], [1, 2], &dev),
            var: tensor(vec![0.5, 1.0], [1, 2], &dev),
        },
    ];
    let g = fusion::product_of_experts(&e);
    close(&vals(g.var), &[0.25, 1.0 / 2.25], 1e-6);
    close(&vals(g.mean), &[1.75, -0.5 / 2.25], 1e-6);
}

#[test]
fn the_kl_matches_its_closed_form() {
    let dev = device();
    let (mu, var) = ([0.5f32, -1.0, 0.0], [2.0f32, 0.25, 1.0]);
    let g = Gaussian {
        mean: tensor(mu.to_vec(), [1, 3], &dev),
        var: tensor(var.to_vec(), [1, 3], &dev),
    };
    let want: f32 = mu
        .iter()
        .zip(&var)
        .map(|(m, v)| 0.5 * (v + m * m - 1.0 - v.ln()))
        .sum();
    close(&vals(fusion::kl_to_prior(&g)), &[want], 1e-6);
    // The prior itself: zero.
    let p = Gaussian {
        mean: tensor(vec![0.0; 3], [1, 3], &dev),
        var: tensor(vec![1.0; 3], [1, 3], &dev),
    };
    close(&vals(fusion::kl_to_prior(&p)), &[0.0], 1e-7);
}

#[test]
fn the_gaussian_split_and_the_sample_are_as_documented() {
    let dev = device();
    let g = fusion::gaussian(tensor(vec![1.0, 2.0, 0.0, 10.0], [1, 4], &dev));
    close(&vals(g.mean.clone()), &[1.0, 2.0], 1e-6);
    let softplus = |x: f32| (1.0 + x.exp()).ln();
    close(
        &vals(g.var.clone()),
        &[softplus(0.0) + 1e-4, softplus(10.0) + 1e-4],
        1e-5,
    );
    let z = fusion::sample(&g, tensor(vec![1.0, -1.0], [1, 2], &dev));
    let v = vals(g.var);
    close(&vals(z), &[1.0 + v[0].sqrt(), 2.0 - v[1].sqrt()], 1e-6);
}

#[test]
fn the_losses_give_known_values() {
    let dev = device();
    // BCE: −ln σ(2) for label 1, −ln(1 − σ(−3)) for label 0, ln 2 at 0,
    // and the stable form at a huge logit.
    let l = vals(bce_with_logits(
        tensor(vec![2.0, -3.0, 0.0, 200.0], [4], &dev),
        tensor(vec![1.0, 0.0, 1.0, 0.0], [4], &dev),
    ));
    let sig = |x: f32| 1.0 / (1.0 + (-x).exp());
    close(
        &l,
        &[-sig(2.0).ln(), -(1.0 - sig(-3.0)).ln(), 2f32.ln(), 200.0],
        1e-5,
    );
    // EPE: two pixels, errors (3, 4) and (0, 0): mean 2.5 px.
    let pred = tensor(vec![3.0, 0.0, 4.0, 0.0], [1, 2, 1, 2], &dev);
    let gt = tensor(vec![0.0; 4], [1, 2, 1, 2], &dev);
    close(&vals(endpoint_error(pred, gt)), &[2.5], 1e-4);
}

#[test]
fn the_end_effector_target_is_the_normalised_displacement_or_next_pose() {
    use learner::models::{EeTarget, Normaliser};
    let mut norm = Normaliser::identity();
    norm.ee_delta_mean = [0.001, -0.002, 0.0];
    norm.ee_delta_std = [0.002, 0.004, 0.01];
    norm.proprio_mean[..4].copy_from_slice(&[0.5, 0.1, 0.3, 0.05]);
    norm.proprio_std[..4].copy_from_slice(&[0.1, 0.2, 0.05, 0.25]);
    let mut s = learner::dataset::Sample {
        rgb: vec![0; 3],
        depth: vec![0.0],
        flow: vec![0.0; 2],
        mask: vec![0],
        wrench: vec![0.0; 32 * 6],
        ee_next: [0.51, 0.096, 0.28, 0.3],
        ..Default::default()
    };
    s.proprio[..4].copy_from_slice(&[0.505, 0.1, 0.29, 0.2]);
    let d = learner::models::inputs::labels(
        &norm,
        std::slice::from_ref(&s),
        &[1],
        1,
        EeTarget::Displacement,
        false,
    );
    // (next − now − mean) / sd, position only.
    close(
        &d.ee,
        &[(0.005 - 0.001) / 0.002, (-0.004 + 0.002) / 0.004, -1.0],
        1e-4,
    );
    let p = learner::models::inputs::labels(
        &norm,
        std::slice::from_ref(&s),
        &[1],
        1,
        EeTarget::Pose,
        false,
    );
    // (next − proprioception's mean) / its sd, position and roll.
    close(&p.ee, &[0.1, -0.02, -0.4, 1.0], 1e-4);
}

#[test]
fn the_whole_loss_weights_its_terms_and_skips_unaligned_samples() {
    use learner::models::LossWeights;
    use learner::models::losses::{LabelTensors, losses};
    let dev = device();
    let cfg = config(ModelKind::Full, 8, 64);
    let net = new_net(&cfg, &dev);
    let x = inputs(2, 64, 3, &dev);
    let labels = |paired: Vec<f32>| learner::models::LabelArrays {
        action: vec![0.0; 8],
        flow: vec![0.5; 2 * 2 * 64 * 64],
        mask: vec![1.0; 2 * 64 * 64],
        contact_next: vec![1.0, 0.0],
        paired,
        ee: vec![0.1; 6],
        ee_dim: 3,
        rgb01: vec![0.5; 2 * 3 * 64 * 64],
        last_wrench: vec![0.0; 12],
    };
    let y = LabelTensors::new(&labels(vec![1.0, 1.0]), 64, &dev);
    let out = net.forward(&cfg, &x, y.action.clone(), None, Modalities::ALL);
    let w = LossWeights::default();
    let l = losses(&out, &y, &x.proprio, &w);
    let s = |t: &Option<Tensor<1>>| vals(t.clone().unwrap())[0];
    let want = w.flow as f32 * s(&l.flow)
        + w.mask as f32 * s(&l.mask)
        + w.contact as f32 * s(&l.contact)
        + w.pairing as f32 * s(&l.pairing)
        + w.ee as f32 * s(&l.ee)
        + w.kl as f32 * s(&l.kl);
    close(&vals(l.total), &[want], 1e-5);
    // The second sample unaligned: the action-conditional losses are the
    // first sample's alone.
    let y1 = LabelTensors::new(&labels(vec![1.0, 0.0]), 64, &dev);
    let l1 = losses(&out, &y1, &x.proprio, &w);
    let first = vals(bce_with_logits(
        out.contact_logits.clone().unwrap(),
        y.contact_next.clone(),
    ))[0];
    close(&[s(&l1.contact)], &[first], 1e-5);
}

#[test]
fn a_masked_modality_has_no_effect_on_z() {
    let dev = device();
    let cfg = config(ModelKind::Full, 16, 64);
    let net = new_net(&cfg, &dev);
    let a = inputs(2, 64, 7, &dev);
    let mut b = a.clone();
    b.rgb = b.rgb.mul_scalar(-3.0).add_scalar(1.0);
    b.wrench = b.wrench.mul_scalar(5.0);
    let no_rgb_haptics = Modalities {
        rgb: false,
        haptics: false,
        ..Modalities::ALL
    };
    let za = vals(net.encode(&cfg, &a, no_rgb_haptics).mean);
    let zb = vals(net.encode(&cfg, &b, no_rgb_haptics).mean);
    close(&za, &zb, 0.0);
    // With the sensors on, the same change moves z: the test can fail.
    let za = vals(net.encode(&cfg, &a, Modalities::ALL).mean);
    let zb = vals(net.encode(&cfg, &b, Modalities::ALL).mean);
    assert!(za.iter().zip(&zb).any(|(x, y)| (x - y).abs() > 1e-4));
    // The deterministic model masks by zero features, to the same effect.
    let det = config(ModelKind::Deterministic, 16, 64);
    let net = new_net(&det, &dev);
    let za = vals(net.encode(&det, &a, no_rgb_haptics).mean);
    let zb = vals(net.encode(&det, &b, no_rgb_haptics).mean);
    close(&za, &zb, 0.0);
}

#[test]
fn configurations_are_checked_and_the_shipped_files_load() {
    let mut c = ModelConfig {
        image_size: 100,
        ..ModelConfig::default()
    };
    assert_eq!(c.validate().unwrap_err().field, "model.image_size");
    c.image_size = 128;
    c.modalities = Modalities {
        rgb: false,
        depth: false,
        haptics: false,
        proprio: false,
    };
    assert_eq!(c.validate().unwrap_err().field, "model.modalities");
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/repr");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let cfg = learner::train::ReprTrainConfig::from_file(&p)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        n += 1;
        let name = p.file_stem().unwrap().to_str().unwrap().to_string();
        match name.as_str() {
            "deterministic" => assert_eq!(cfg.model.kind, ModelKind::Deterministic),
            "reconstruction" => assert_eq!(cfg.model.kind, ModelKind::Reconstruction),
            "no_pairing" => {
                assert_eq!(cfg.loss.pairing, 0.0);
                assert!(!cfg.learns_pairing() && cfg.negatives() == 0.0);
            }
            // Without haptics a pairing negative (another moment's wrench
            // window) is invisible: no negatives, no pairing loss.
            "no_haptics" => {
                assert!(!cfg.model.modalities.haptics);
                assert!(!cfg.learns_pairing() && cfg.negatives() == 0.0);
                assert_eq!(cfg.loss_weights().pairing, 0.0);
            }
            "full" => {
                assert!(cfg.learns_pairing() && cfg.negatives() == 0.5);
                assert_eq!(cfg.model.ee_target, learner::models::EeTarget::Displacement);
            }
            "full-ee-pose" => assert_eq!(cfg.model.ee_target, learner::models::EeTarget::Pose),
            "no_rgb" => assert!(!cfg.model.modalities.rgb),
            "d16" => assert_eq!(cfg.model.latent_dim, 16),
            _ => {}
        }
    }
    assert_eq!(n, 11, "the paper's ten models and full-ee-pose");
    // A model exported before the target was a choice predicts the
    // displacement.
    let old: ModelConfig = serde_json::from_str(r#"{"kind": "full", "latent_dim": 128}"#).unwrap();
    assert_eq!(old.ee_target, learner::models::EeTarget::Displacement);
    let bad = test_support::scratch_dir("bad-config");
    let p = bad.join("x.toml");
    std::fs::write(&p, "[train]\nlr = -1.0\n").unwrap();
    let e = learner::train::ReprTrainConfig::from_file(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("train.lr"), "{e}");
    std::fs::write(&p, "[model]\nlatent = 3\n").unwrap();
    let e = learner::train::ReprTrainConfig::from_file(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("latent"), "{e}");
}

/// Every bias of `m` set to random values (seeded initialisation makes
/// them zero, which would hide a bias left out).
fn random_biases<M: burn::module::Module>(m: M, seed: u64) -> M {
    struct Biases(test_support::Rng);
    impl burn::module::ModuleMapper for Biases {
        fn map_float<const D: usize>(
            &mut self,
            p: burn::module::Param<Tensor<D>>,
        ) -> burn::module::Param<Tensor<D>> {
            if D != 1 {
                return p;
            }
            let r = &mut self.0;
            p.map(|t| {
                let dims = t.dims();
                let n: usize = dims.iter().product();
                let v: Vec<f32> = (0..n)
                    .map(|_| rand::RngExt::random_range(r, -0.3f32..0.3))
                    .collect();
                Tensor::from_data(TensorData::new(v, dims), &t.device())
            })
        }
    }
    m.map(&mut Biases(test_support::rng(seed)))
}

#[test]
fn the_fast_cpu_path_computes_what_encode_computes() {
    // Every model kind, a model built without a modality, and every sensor
    // lost at run time: the inference API's CPU path against burn's encode,
    // with random biases. 64 px leaves 1×1 maps before the fully connected
    // layers; the Full Model at 128 px (2×2) checks their reordering.
    let dev = device();
    let no_rgb = Modalities {
        rgb: false,
        ..Modalities::ALL
    };
    let mut models = vec![
        config(ModelKind::Full, 16, 64),
        config(ModelKind::Deterministic, 16, 64),
        config(ModelKind::Reconstruction, 8, 64),
        config(ModelKind::Full, 8, 128),
    ];
    let mut lacking = config(ModelKind::Full, 16, 64);
    lacking.modalities = no_rgb;
    models.push(lacking);
    let b = 5;
    let mut r = test_support::rng(11);
    let mut v = |n: usize| -> Vec<f32> {
        (0..n)
            .map(|_| rand::RngExt::random_range(&mut r, -1.0f32..1.0))
            .collect()
    };
    for cfg in &models {
        let s = cfg.image_size;
        let a = learner::models::InputArrays {
            batch: b,
            side: s,
            rgb: v(b * 3 * s * s),
            depth: v(b * s * s),
            wrench: v(b * 6 * 32),
            proprio: v(b * 8),
        };
        let x = InputTensors::new(&a, &dev);
        let net = random_biases(new_net(cfg, &dev), 3);
        // Split unevenly over three threads (2, 2, 1), and on one.
        let fast = learner::models::fast::fast_encoder(&net, cfg).with_threads(3);
        let single = learner::models::fast::fast_encoder(&net, cfg).with_threads(1);
        let masks = [
            Modalities::ALL,
            no_rgb,
            Modalities {
                depth: false,
                ..Modalities::ALL
            },
            Modalities {
                haptics: false,
                ..Modalities::ALL
            },
            Modalities {
                proprio: false,
                ..Modalities::ALL
            },
        ];
        for m in masks {
            let on = cfg.modalities.and(m);
            let want = vals(net.encode(cfg, &x, on).mean);
            let got = fast.encode(&a, on);
            close(&got, &want, 1e-4);
            close(&single.encode(&a, on), &want, 1e-4);
            // The result is not trivially zero.
            assert!(got.iter().any(|z| z.abs() > 1e-3), "{:?} {m:?}", cfg.kind);
        }
    }
}
