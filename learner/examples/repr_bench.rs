//! Benchmark of the representation (docs/performance.md): one Adam step of
//! the Full Model (d = 128, 128×128 px) at batch B, or the z means of a
//! batch (inference), on random inputs of the paper's shapes; the median
//! over `steps` after warm-up, as one JSON line. The PyTorch anchor
//! (bench-anchors/torch-repr/bench.py) times the same architecture; the
//! script bench-anchors/repr.sh runs both alternately.
//!
//! Usage: `repr_bench [--kernels ours|products|burn] train|infer|infer-fast
//! BATCH STEPS [DEPTH_CONVS_PER_STAGE]` (threads: RAYON_NUM_THREADS; the
//! last argument, default 3, measures the depth encoder's share;
//! `--kernels burn` trains with burn's own operations instead of
//! learner-kernels', `learner_kernels::KernelChoice`), or `repr_bench
//! --quick`: one step of each at batch 2 and 64 px, a few seconds in a
//! debug build; it exercises the code and measures nothing. `infer` times burn's `encode`, `infer-fast` the
//! CPU path the inference API takes (`learner::models::fast`).
//! `REPR_BENCH_DEVICE=cuda|vulkan` runs `train` and `infer` on that burn GPU
//! backend (a build with the feature of that name); the side is then named
//! "burn-cuda" or "burn-vulkan".

use burn::optim::{AdamConfig, GradientsParams};
use learner::models::losses::{LabelTensors, losses};
use learner::models::net::tensor;
use learner::models::{
    InputArrays, InputTensors, LabelArrays, LossWeights, Modalities, ModelConfig, ReprNet, init,
};
use learner::train::DeviceKind;
use learner_kernels::KernelChoice;
use std::time::Instant;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

const USAGE: &str = "usage: repr_bench [--kernels ours|products|burn] train|infer|infer-fast \
                     BATCH STEPS [DEPTH_CONVS_PER_STAGE] | --quick";

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(i) = args.iter().position(|a| a == "--kernels") {
        assert!(i + 1 < args.len(), "{USAGE}");
        let choice: KernelChoice = args.remove(i + 1).parse().expect(USAGE);
        args.remove(i);
        learner_kernels::set_kernel_choice(choice);
    }
    if args.first().is_some_and(|a| a == "--quick") {
        let cfg = ModelConfig {
            image_size: 64,
            ..ModelConfig::default()
        };
        for what in ["train", "infer", "infer-fast"] {
            bench(what, 2, 1, &cfg);
        }
        return;
    }
    let what = args.first().expect(USAGE).clone();
    let b: usize = args.get(1).expect(USAGE).parse().expect(USAGE);
    let steps: usize = args.get(2).expect(USAGE).parse().expect(USAGE);
    let cfg = ModelConfig {
        depth_convs_per_stage: args.get(3).map_or(3, |v| v.parse().expect(USAGE)),
        ..ModelConfig::default()
    };
    bench(&what, b, steps, &cfg);
}

/// `what` at batch `b`, the median over `steps`, as one JSON line.
fn bench(what: &str, b: usize, steps: usize, cfg: &ModelConfig) {
    let threads = rayon_threads();
    let (s, d) = (cfg.image_size, cfg.latent_dim);
    let mut r = stack_common::rng::seeded(1, 0);
    let mut randn = |n: usize| -> Vec<f32> {
        (0..n)
            .map(|_| stack_common::rng::normal(&mut r) as f32)
            .collect()
    };
    let train = what == "train";
    let (kind, gpu_side) = match std::env::var("REPR_BENCH_DEVICE").as_deref() {
        Ok("cuda") => (DeviceKind::Cuda, Some("burn-cuda")),
        Ok("vulkan") => (DeviceKind::Vulkan, Some("burn-vulkan")),
        Ok("cpu") | Err(_) => (DeviceKind::Cpu, None),
        Ok(other) => panic!("REPR_BENCH_DEVICE={other}: expected cpu, cuda or vulkan"),
    };
    if gpu_side.is_some() && what == "infer-fast" {
        panic!("infer-fast is the CPU path; on a GPU use infer");
    }
    let dev = kind.device(train).unwrap_or_else(|e| panic!("{e}"));
    let arrays = InputArrays {
        batch: b,
        side: s,
        rgb: randn(b * 3 * s * s),
        depth: randn(b * s * s),
        wrench: randn(b * 6 * 32),
        proprio: randn(b * 8),
    };
    let x = InputTensors::new(&arrays, &dev);
    let mut net = init::seeded(ReprNet::new(cfg, &dev), 0);
    let mut times = Vec::new();
    if train {
        let sign = |v: Vec<f32>| v.into_iter().map(|x| (x > 0.0) as u8 as f32).collect();
        let labels = LabelArrays {
            action: randn(b * 4),
            flow: randn(b * 2 * s * s),
            mask: sign(randn(b * s * s)),
            contact_next: sign(randn(b)),
            paired: sign(randn(b)),
            ee: randn(b * 3),
            ee_dim: 3,
            rgb01: vec![0.5; b * 3 * s * s],
            last_wrench: randn(b * 6),
        };
        let y = LabelTensors::new(&labels, s, &dev);
        let eps = tensor(randn(b * d), [b, d], &dev);
        let w = LossWeights::default();
        let mut optim = AdamConfig::new().with_beta_1(0.5).with_epsilon(1e-8).init();
        // Forward with losses, backward, optimiser: exact on the CPU, where
        // burn runs each operation eagerly; on a GPU only the total counts.
        let mut phases: Vec<[f64; 3]> = Vec::new();
        for i in 0..steps + 2 {
            let t = Instant::now();
            let out = net.forward(
                cfg,
                &x,
                y.action.clone(),
                Some(eps.clone()),
                Modalities::ALL,
            );
            let l = losses(&out, &y, &x.proprio, &w);
            let t_fwd = t.elapsed().as_secs_f64();
            let grads = GradientsParams::from_grads(l.total.backward(), &net);
            let t_bwd = t.elapsed().as_secs_f64();
            net = optim.step(1e-4, net, grads);
            // Reading the loss back waits for the step to finish (on a GPU
            // too: the timed step includes its kernels).
            let _ = l.total.into_scalar::<f32>();
            if i >= 2 {
                let all = t.elapsed().as_secs_f64();
                times.push(all);
                phases.push([t_fwd, t_bwd - t_fwd, all - t_bwd]);
            }
        }
        let step = median(times);
        let phase = |k: usize| 1e3 * median(phases.iter().map(|p| p[k]).collect());
        // `--kernels burn`: burn's own operations (learner_kernels::KernelChoice).
        let side = match (gpu_side, learner_kernels::kernel_settings().choice) {
            (Some(g), _) => g,
            (None, KernelChoice::Burn) => "burn-flex",
            (None, KernelChoice::Products) => "ours-products",
            (None, KernelChoice::Ours) => "ours-conv",
        };
        println!(
            "{{\"side\": \"{side}\", \"what\": \"train\", \"batch\": {b}, \"threads\": {threads}, \"step_s\": {step:.5}, \"samples_per_s\": {:.2}, \"steps\": {steps}, \"depth_convs_per_stage\": {}, \"forward_ms\": {:.1}, \"backward_ms\": {:.1}, \"optimiser_ms\": {:.1}}}",
            b as f64 / step,
            cfg.depth_convs_per_stage,
            phase(0),
            phase(1),
            phase(2)
        );
    } else {
        let fast = (what == "infer-fast")
            .then(|| learner::models::fast::fast_encoder(&net, cfg).with_threads(threads));
        for i in 0..steps + 3 {
            let t = Instant::now();
            match &fast {
                Some(f) => drop(f.encode(&arrays, Modalities::ALL)),
                None => drop(net.encode(cfg, &x, Modalities::ALL).mean.into_data()),
            }
            if i >= 3 {
                times.push(t.elapsed().as_secs_f64());
            }
        }
        let per = median(times);
        println!(
            "{{\"side\": \"{}\", \"what\": \"infer\", \"batch\": {b}, \"threads\": {threads}, \"batch_s\": {per:.6}, \"per_obs_ms\": {:.4}, \"steps\": {steps}}}",
            if fast.is_some() {
                "ours-fast"
            } else {
                gpu_side.unwrap_or("burn-flex")
            },
            1e3 * per / b as f64
        );
    }
}

/// The thread count rayon (and so flex) uses.
fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}
