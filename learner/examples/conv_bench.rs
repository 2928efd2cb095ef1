//! Benchmark of the Full Model's convolutions one layer at a time
//! (docs/performance.md): for each distinct layer geometry of the RGB and
//! depth encoders and the flow decoder (128×128 px, d = 128), the forward
//! pass and the backward pass (input, weight and bias gradients) at batch
//! B on burn's `flex` backend under autodiff, through the model's own call
//! (`learner_kernels::conv2d`, `learner_kernels::conv_transpose2d`); the median over
//! `reps` after one warm-up, in ms and in GFLOP/s of the layer's
//! multiply-adds (2 per MAC; the backward pass counts twice the forward's,
//! whether or not the layer's input needs its gradient). One JSON line per
//! layer. `--kernels burn` times burn's own convolution instead,
//! `--kernels products` ours without the direct kernels (`ours`, the
//! default: `learner_kernels::KernelChoice`); `--grouped-outs N` groups
//! the maps of up to N positions (0: none; default
//! `learner_kernels::DEFAULT_GROUPED_OUTS`).
//!
//! Usage: `conv_bench [--kernels ours|products|burn] [--grouped-outs N]
//! BATCH REPS` (threads: RAYON_NUM_THREADS), or `conv_bench --quick`: every
//! layer once at batch 1 under each choice of kernels, a few seconds in a
//! debug build; it exercises the code and measures nothing.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2dConfig, ConvTranspose2dConfig};
use burn::prelude::*;
use learner_kernels::{
    DEFAULT_GROUPED_OUTS, KernelChoice, KernelSettings, conv_transpose2d, conv2d,
    set_kernel_settings,
};
use std::time::Instant;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn filled(shape: [usize; 4], seed: u64, device: &Device) -> Tensor<4> {
    let n: usize = shape.iter().product();
    let mut rng = fastrand::Rng::with_seed(seed);
    let v: Vec<f32> = (0..n).map(|_| rng.f32() * 2.0 - 1.0).collect();
    Tensor::<1>::from_floats(v.as_slice(), device).reshape(shape)
}

/// One layer: (name, count in the model, cin, cout, input side, k, stride,
/// pad, transposed).
type Layer = (
    &'static str,
    usize,
    usize,
    usize,
    usize,
    usize,
    usize,
    usize,
    bool,
);

/// The Full Model's convolutions at 128 px (learner::models::encoders,
/// decoders), one row per distinct geometry.
const LAYERS: [Layer; 25] = [
    ("rgb1", 1, 3, 16, 128, 7, 2, 3, false),
    ("rgb2", 1, 16, 32, 64, 5, 2, 2, false),
    ("rgb3", 1, 32, 64, 32, 5, 2, 2, false),
    ("rgb4", 1, 64, 64, 16, 3, 2, 1, false),
    ("rgb5", 1, 64, 128, 8, 3, 2, 1, false),
    ("rgb6", 1, 128, 128, 4, 3, 2, 1, false),
    ("depth1", 1, 1, 16, 128, 3, 2, 1, false),
    ("depth-s1-64", 2, 16, 16, 64, 3, 1, 1, false),
    ("depth-s2-32", 1, 16, 32, 64, 3, 2, 1, false),
    ("depth-s1-32", 2, 32, 32, 32, 3, 1, 1, false),
    ("depth-s2-16", 1, 32, 64, 32, 3, 2, 1, false),
    ("depth-s1-16", 2, 64, 64, 16, 3, 1, 1, false),
    ("depth-s2-8", 1, 64, 64, 16, 3, 2, 1, false),
    ("depth-s1-8", 2, 64, 64, 8, 3, 1, 1, false),
    ("depth-s2-4", 1, 64, 128, 8, 3, 2, 1, false),
    ("depth-s1-4", 2, 128, 128, 4, 3, 1, 1, false),
    ("depth-s2-2", 1, 128, 128, 4, 3, 2, 1, false),
    ("depth-s1-2", 2, 128, 128, 2, 3, 1, 1, false),
    ("entry", 1, 256, 64, 2, 1, 1, 0, false),
    ("up1", 1, 64, 64, 2, 4, 2, 1, true),
    ("up2", 1, 192, 32, 4, 4, 2, 1, true),
    ("up3", 1, 96, 32, 8, 4, 2, 1, true),
    ("up4", 1, 96, 32, 16, 4, 2, 1, true),
    ("flow", 1, 64, 2, 32, 3, 1, 1, false),
    ("mask", 1, 64, 1, 32, 3, 1, 1, false),
];

const USAGE: &str =
    "usage: conv_bench [--kernels ours|products|burn] [--grouped-outs N] BATCH REPS | --quick";

/// The value after flag `name` in `args`, removed with it.
fn take_flag(args: &mut Vec<String>, name: &str) -> Option<String> {
    let i = args.iter().position(|a| a == name)?;
    assert!(i + 1 < args.len(), "{USAGE}");
    let v = args.remove(i + 1);
    args.remove(i);
    Some(v)
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let kernels = take_flag(&mut args, "--kernels").map(|v| v.parse().expect(USAGE));
    let grouped_outs = take_flag(&mut args, "--grouped-outs")
        .map_or(DEFAULT_GROUPED_OUTS, |v| v.parse().expect(USAGE));
    let settings = |choice| KernelSettings {
        choice,
        grouped_outs,
    };
    if args.first().is_some_and(|a| a == "--quick") {
        let choices = kernels.map_or(KernelChoice::ALL.to_vec(), |k| vec![k]);
        for choice in choices {
            set_kernel_settings(settings(choice));
            bench(1, 1);
        }
        return;
    }
    let b: usize = args.first().expect(USAGE).parse().expect(USAGE);
    let reps: usize = args.get(1).expect(USAGE).parse().expect(USAGE);
    set_kernel_settings(settings(kernels.unwrap_or_default()));
    bench(b, reps);
}

/// Every layer at batch `b`, the median over `reps`, under the kernel
/// settings in force.
fn bench(b: usize, reps: usize) {
    let threads = rayon::current_num_threads();
    let device = Device::flex().autodiff();
    let side_name = match learner_kernels::kernel_settings().choice {
        KernelChoice::Burn => "burn-flex",
        KernelChoice::Products => "ours-products",
        KernelChoice::Ours => "ours-conv",
    };
    for (i, &(name, count, cin, cout, side, k, s, p, transposed)) in LAYERS.iter().enumerate() {
        let x = filled([b, cin, side, side], i as u64, &device).require_grad();
        // The layer as a closure over its module, so that both kinds time
        // the same way.
        let (run, macs): (Box<dyn Fn(Tensor<4>) -> Tensor<4>>, usize) = if transposed {
            let c = ConvTranspose2dConfig::new([cin, cout], [k, k])
                .with_stride([s, s])
                .with_padding([p, p])
                .init(&device);
            // Each input position meets every output channel through k² taps.
            let macs = b * side * side * cin * cout * k * k;
            (Box::new(move |x| conv_transpose2d(&c, x)), macs)
        } else {
            let c = Conv2dConfig::new([cin, cout], [k, k])
                .with_stride([s, s])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .init(&device);
            let out = (side + 2 * p - k) / s + 1;
            let macs = b * out * out * cin * cout * k * k;
            (Box::new(move |x| conv2d(&c, x)), macs)
        };
        let r = run(x.clone().detach());
        let r = filled(r.dims(), 100 + i as u64, &device);
        let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
        for rep in 0..reps + 1 {
            let t = Instant::now();
            // flex runs each operation when it is called.
            let y = run(x.clone());
            let t_fwd = t.elapsed().as_secs_f64();
            let loss = (y * r.clone()).sum();
            let t = Instant::now();
            let grads = loss.backward();
            assert!(x.grad(&grads).is_some(), "{name}: no input gradient");
            let t_bwd = t.elapsed().as_secs_f64();
            if rep > 0 {
                fwd.push(t_fwd);
                bwd.push(t_bwd);
            }
        }
        let (f, bk) = (median(fwd), median(bwd));
        let gflop = 2.0 * macs as f64 / 1e9;
        println!(
            "{{\"side\": \"{side_name}\", \"layer\": \"{name}\", \"count\": {count}, \"batch\": {b}, \"threads\": {threads}, \"fwd_ms\": {:.3}, \"bwd_ms\": {:.3}, \"fwd_gflops\": {:.1}, \"bwd_gflops\": {:.1}}}",
            f * 1e3,
            bk * 1e3,
            gflop / f,
            2.0 * gflop / bk
        );
    }
}
