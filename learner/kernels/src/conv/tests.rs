//! The convolution's tests: every route against burn's convolution and
//! against the im2col route.

use super::banded::band_rows;
use super::geometry::direct_weight_grad;
use super::grouped::group;
use super::stacked::stacked_rows;
use super::*;
use burn::module::Param;
use burn::nn::conv::Conv2dConfig;

fn filled(shape: [usize; 4], seed: u64, device: &Device) -> Tensor<4> {
    let n: usize = shape.iter().product();
    let mut rng = fastrand::Rng::with_seed(seed);
    let v: Vec<f32> = (0..n).map(|_| rng.f32() * 2.0 - 1.0).collect();
    Tensor::<1>::from_floats(v.as_slice(), device).reshape(shape)
}

fn close(a: Tensor<4>, b: Tensor<4>, what: &str) {
    let (a, b) = (
        a.try_into_vec_as::<f32>().expect("f32 values"),
        b.try_into_vec_as::<f32>().expect("f32 values"),
    );
    assert_eq!(a.len(), b.len(), "{what}: sizes");
    let scale = b.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-4 * scale,
            "{what}[{i}]: {x} against burn's {y}"
        );
    }
}

/// Forward values and all three gradients against burn's own
/// convolution, for the geometries the models use (strided, padded,
/// 1×1, odd sides where the last taps fall off the edge, the 2×2 and
/// 1×1 maps of the last stages, several row bands).
#[test]
fn matches_burns_convolution_and_its_gradients() {
    assert!(
        !kernel_settings().burns_own(),
        "KernelChoice::Burn is set: these tests would compare burn with burn"
    );
    let device = Device::flex().autodiff();
    let cases = [
        // (batch, cin, cout, side, k, stride, pad)
        (2, 3, 4, 9, 7, 2, 3),
        (3, 2, 5, 8, 5, 2, 2),
        (2, 4, 3, 7, 3, 1, 1),
        (2, 3, 2, 6, 3, 2, 1),
        (2, 5, 4, 4, 1, 1, 0),
        (1, 2, 3, 5, 3, 1, 0),
        // The last stages' small maps: 2×2 → 2×2, 2×2 → 1×1, 1×1 → 1×1.
        (2, 8, 4, 2, 3, 1, 1),
        (2, 4, 4, 2, 3, 2, 1),
        (1, 4, 3, 1, 3, 1, 1),
        // A stride-1 layer of the depth encoder's size (the shifted path).
        (2, 16, 3, 40, 3, 1, 1),
        // Strided layers in several row bands, the last one short: the
        // stacked path's (3 and 1 input channels, the encoders' first
        // layers) and the split input's.
        (1, 3, 2, 128, 5, 2, 2),
        (1, 1, 2, 256, 3, 2, 1),
        (1, 8, 2, 50, 5, 2, 2),
        (1, 16, 2, 64, 3, 2, 1),
        // The first layers with 4 output channels: conv_direct's kernel
        // on the stacked layout, where the CPU has it.
        (1, 3, 4, 64, 7, 2, 3),
        (2, 1, 4, 32, 3, 2, 1),
    ];
    for (seed, &(b, cin, cout, side, k, s, p)) in cases.iter().enumerate() {
        let g = Geometry::new(&[b, cin, side, side], &[cout, cin, k, k], s, p);
        let rows = Shifted::stacked(&g).map_or(band_rows(&g), |sh| stacked_rows(&g, sh));
        assert!(
            side < 40 || Shifted::of(&g).is_some() || (rows < g.ho && !g.ho.is_multiple_of(rows)),
            "side {side}: meant to have several bands, the last one short"
        );
        let what = format!("b {b} cin {cin} cout {cout} side {side} k {k} stride {s} pad {p}");
        let c = Conv2dConfig::new([cin, cout], [k, k])
            .with_stride([s, s])
            .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
            .init(&device);
        let x = filled([b, cin, side, side], seed as u64, &device).require_grad();
        let (ours, theirs) = (conv2d(&c, x.clone()), c.forward(x.clone()));
        let bias = c.bias.as_ref().unwrap();
        same_as_burns(&what, &x, ours, theirs, &c.weight, bias, 100 + seed as u64);
    }
}

/// `ours` and burn's `theirs`, both of `x` through a layer of `weight`
/// and `bias`: the values, then the three gradients of a loss that
/// weighs every output differently (by values seeded with `seed`).
fn same_as_burns(
    what: &str,
    x: &Tensor<4>,
    ours: Tensor<4>,
    theirs: Tensor<4>,
    weight: &Param<Tensor<4>>,
    bias: &Param<Tensor<1>>,
    seed: u64,
) {
    close(ours.clone(), theirs.clone(), &format!("{what}: y"));
    let r = filled(ours.dims(), seed, &ours.device());
    let g1 = (ours * r.clone()).sum().backward();
    let g2 = (theirs * r).sum().backward();
    close(
        x.grad(&g1).unwrap(),
        x.grad(&g2).unwrap(),
        &format!("{what}: dx"),
    );
    close(
        weight.grad(&g1).unwrap(),
        weight.grad(&g2).unwrap(),
        &format!("{what}: dw"),
    );
    let cout = bias.dims()[0];
    close(
        bias.grad(&g1).unwrap().reshape([1, 1, 1, cout]),
        bias.grad(&g2).unwrap().reshape([1, 1, 1, cout]),
        &format!("{what}: db"),
    );
}

/// The transposed convolution's values and gradients against burn's
/// own, for the flow decoder's up-convolutions (k 4, stride 2, padding
/// 1, from 1×1 maps up; the 16×16 one's input gradient through
/// conv_direct's kernel), a stride-1 one (the shifted path backwards) and
/// one without padding with fewer than 8 output channels (the stacked
/// path for its input gradient, col2im for its forward pass).
#[test]
fn transposed_matches_burns_and_its_gradients() {
    use burn::nn::conv::ConvTranspose2dConfig;
    assert!(!kernel_settings().burns_own(), "KernelChoice::Burn is set");
    let device = Device::flex().autodiff();
    let cases = [
        // (batch, cin, cout, side, k, stride, pad)
        (2, 16, 8, 1, 4, 2, 1),
        // up1's and up2's input maps (2² and 4²): the grouped passes.
        (3, 8, 6, 2, 4, 2, 1),
        (2, 12, 6, 4, 4, 2, 1),
        (2, 12, 9, 5, 4, 2, 1),
        (1, 24, 8, 16, 4, 2, 1),
        (2, 5, 3, 7, 3, 1, 1),
        (2, 4, 3, 6, 3, 2, 0),
    ];
    for (seed, &(b, cin, cout, side, k, s, p)) in cases.iter().enumerate() {
        let what = format!("b {b} cin {cin} cout {cout} side {side} k {k} stride {s} pad {p}");
        let c = ConvTranspose2dConfig::new([cin, cout], [k, k])
            .with_stride([s, s])
            .with_padding([p, p])
            .init(&device);
        let x = filled([b, cin, side, side], 200 + seed as u64, &device).require_grad();
        let (ours, theirs) = (conv_transpose2d(&c, x.clone()), c.forward(x.clone()));
        let bias = c.bias.as_ref().unwrap();
        same_as_burns(&what, &x, ours, theirs, &c.weight, bias, 300 + seed as u64);
    }
}

/// Without autodiff (inference through burn) it is the same function.
#[test]
fn runs_without_autodiff() {
    assert!(!kernel_settings().burns_own(), "KernelChoice::Burn is set");
    let device = Device::flex();
    let c = Conv2dConfig::new([3, 4], [3, 3])
        .with_stride([2, 2])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(&device);
    let x = filled([2, 3, 10, 10], 7, &device);
    close(conv2d(&c, x.clone()), c.forward(x), "y");
}

/// Where conv_direct's weight-gradient kernel runs on `g`, its
/// gradients against `want` (im2col's); 1 if `g` is routed to it, else 0.
fn direct_weight_grad_as(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    dy: &[f32],
    want: (&[f32], &[f32]),
    what: &str,
) -> usize {
    if direct::runs_weight_grad(g.cout, g.wo) {
        let (dw, db) = wb_backward_direct(g, sh, x, dy);
        near(&dw, want.0, &format!("{what} dw, direct"));
        near(&db, want.1, &format!("{what} db, direct"));
    }
    usize::from(direct_weight_grad(g))
}

/// `n` values uniform in [−0.5, 0.5).
fn uniform(rng: &mut fastrand::Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.f32() - 0.5).collect()
}

/// One pass's output of `n` values, as the layers allocate it.
fn pass(n: usize, f: impl FnOnce(&mut [MaybeUninit<f32>])) -> Vec<f32> {
    // SAFETY: each of the passes tested writes every value.
    unsafe { written(n, f) }
}

/// `a` against `b`, value by value, within 1e-4.
fn near(a: &[f32], b: &[f32], label: &str) {
    assert_eq!(a.len(), b.len(), "{label}: sizes");
    for (i, (u, v)) in a.iter().zip(b).enumerate() {
        assert!((u - v).abs() < 1e-4, "{label}[{i}]: {u} against {v}");
    }
}

/// The paths without im2col (stride 1; strided, on the split input)
/// against the im2col path, on raw arrays, one pass at a time.
#[test]
fn shifted_paths_match_im2col() {
    assert!(
        !kernel_settings().products_only(),
        "KernelChoice::Products is set"
    );
    let (mut direct_passes, mut weight_grads, mut splits) = (0, 0, 0);
    for (i, &(b, cin, cout, side, k, s, p)) in [
        (2, 4, 3, 7, 3, 1, 1),
        (1, 2, 3, 5, 3, 1, 0),
        (2, 3, 5, 9, 5, 1, 2),
        // Strided: even and odd sides, kernels 3, 5, 7, stride 3.
        (2, 8, 3, 9, 3, 2, 1),
        (2, 16, 3, 10, 3, 2, 1),
        (1, 8, 4, 12, 5, 2, 2),
        (1, 9, 2, 11, 7, 2, 3),
        (1, 8, 2, 13, 5, 3, 2),
        (2, 8, 3, 2, 3, 2, 1),
        (1, 8, 3, 10, 3, 3, 1),
        // conv_direct's kernel (rows a multiple of 16 wide, output
        // channels a multiple of 4; its blocks of 6 and 4 channels:
        // 16 = 6 + 6 + 4, 8 = 4 + 4, 12 = 6 + 6): 32×32, and 13×16
        // with the input gradient's too (8 input channels, stride 1).
        (2, 3, 16, 32, 3, 1, 1),
        (1, 8, 8, 13, 3, 1, 1),
        // And strided on the split input: 16×16 out of 32×32, k 5.
        (1, 8, 12, 32, 5, 2, 2),
        // The strided input gradient by phases (x_backward_split):
        // 29 rows (phases of 14 and 15, or 15 and 14) × 32 columns
        // (16 per phase), k 3 and 5; and k 4, the up-convolutions'.
        (1, 8, 6, 29, 3, 2, 1),
        (2, 16, 5, 32, 4, 2, 1),
        (1, 12, 3, 29, 5, 2, 2),
        // k = s without padding (one tap per phase), and stride 3
        // (45×48: phases 15 high, 16 wide).
        (1, 8, 3, 32, 2, 2, 0),
        (1, 8, 3, 45, 3, 3, 1),
    ]
    .iter()
    .enumerate()
    {
        // Every other case 3 columns wider than high.
        let width = if i % 2 == 1 { side + 3 } else { side };
        let g = Geometry::new(&[b, cin, side, width], &[cout, cin, k, k], s, p);
        direct_passes += usize::from(direct_forward(&g));
        if s == 1 {
            // The input gradient's own convolution (padded by k − 1 − p).
            let gt = Geometry::new(&[b, cout, g.ho, g.wo], &[cin, cout, k, k], 1, k - 1 - p);
            direct_passes += usize::from(direct_forward(&gt));
        }
        let sh = Shifted::of(&g).expect("a shifted geometry");
        let mut rng = fastrand::Rng::with_seed(3);
        let (x, w, bias) = (
            uniform(&mut rng, b * cin * side * width),
            uniform(&mut rng, cout * cin * k * k),
            uniform(&mut rng, cout),
        );
        let dy = uniform(&mut rng, b * cout * g.outs());
        let what = format!("b {b} cin {cin} cout {cout} {side}×{width} k {k} stride {s} pad {p}");
        let near = |a: &[f32], b: &[f32], pass: &str| near(a, b, &format!("{what} {pass}"));
        let y1 = pass(dy.len(), |y| {
            forward_shifted(&g, sh, &x, Kernel::Own(&w), &bias, y)
        });
        let y2 = pass(dy.len(), |y| forward_banded(&g, &x, &w, &bias, y));
        near(&y1, &y2, "y");
        let dx1 = pass(x.len(), |dx| {
            if s == 1 {
                x_backward_shifted(&g, &w, &dy, dx);
            } else {
                x_backward_phased(&g, sh, &w, &dy, dx);
            }
        });
        let dx2 = pass(x.len(), |dx| x_backward_banded(&g, &w, &dy, dx));
        near(&dx1, &dx2, "dx");
        if s > 1 && split_direct(&g) {
            let dx3 = pass(x.len(), |dx| x_backward_split(&g, &w, &dy, dx));
            near(&dx3, &dx2, "dx by phases");
            splits += 1;
        }
        let ((dw1, db1), (dw2, db2)) = (
            wb_backward_shifted(&g, sh, &x, &dy),
            wb_backward_banded(&g, &x, &dy),
        );
        near(&dw1, &dw2, "dw");
        near(&db1, &db2, "db");
        weight_grads += direct_weight_grad_as(&g, sh, &x, &dy, (&dw2, &db2), &what);
    }
    // The last three cases' forward passes take conv_direct's kernel,
    // and the second's input gradient (8 input channels, 16 wide).
    assert_eq!(direct_passes, if direct::cpu() { 4 } else { 0 });
    // The weight-gradient kernel runs on those three and the 8-wide
    // strided case (12×15, k 5); the three are routed to it.
    assert_eq!(weight_grads, if direct::cpu() { 3 } else { 0 });
    // The strided input gradient by phases: the strided cases 16 wide
    // per phase with input channels a multiple of 4.
    assert_eq!(splits, if direct::cpu() { 6 } else { 0 });
    // The RGB encoder's first layer (3 channels) is not Shifted.
    let g = Geometry::new(&[1, 3, 16, 16], &[4, 3, 7, 7], 2, 3);
    assert!(Shifted::of(&g).is_none());
}

/// The grouped passes (one product per group of samples) against the
/// im2col path, on raw arrays: the small maps they are routed, strided
/// and padded, an up-convolution's k 4, a side where the last taps fall
/// off the edge, and a batch cut into groups whose last one is short.
#[test]
fn grouped_paths_match_im2col() {
    // The groups follow the threads (each thread's share of the batch is
    // cut into groups): two, this project's machine's, wherever it runs.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build();
    pool.expect("a thread pool").install(|| {
        let (mut short_last, mut tiled) = (0, 0);
        for &(b, cin, cout, h, w, k, s, p) in &[
            // (batch, cin, cout, height, width, k, stride, pad)
            (3, 8, 4, 2, 2, 3, 1, 1),
            (2, 6, 5, 4, 4, 3, 2, 1),
            (2, 5, 3, 8, 8, 4, 2, 1),
            (1, 4, 2, 5, 3, 3, 2, 0),
            (3, 3, 4, 4, 3, 3, 1, 1),
            // 18 432 im2col values a sample: groups of at most 14.
            (31, 128, 6, 4, 4, 3, 1, 1),
        ] {
            let g = Geometry::new(&[b, cin, h, w], &[cout, cin, k, k], s, p);
            let (m, groups) = group(&g);
            short_last += usize::from(!b.is_multiple_of(m));
            tiled += usize::from(groups > 1);
            assert!(
                g.outs() <= crate::DEFAULT_GROUPED_OUTS && grouped(&g),
                "{g:?} is not grouped: grouped_outs set below the default?"
            );
            let mut rng = fastrand::Rng::with_seed(11);
            let (x, wt, bias) = (
                uniform(&mut rng, b * cin * h * w),
                uniform(&mut rng, cout * cin * k * k),
                uniform(&mut rng, cout),
            );
            let dy = uniform(&mut rng, b * cout * g.outs());
            let what = format!("{g:?}");
            let near = |a: &[f32], b: &[f32], pass: &str| near(a, b, &format!("{what} {pass}"));
            let y1 = pass(dy.len(), |y| forward_grouped(&g, &x, &wt, &bias, y));
            let y2 = pass(dy.len(), |y| forward_banded(&g, &x, &wt, &bias, y));
            near(&y1, &y2, "y");
            let dx1 = pass(x.len(), |dx| x_backward_grouped(&g, &wt, &dy, dx));
            let dx2 = pass(x.len(), |dx| x_backward_banded(&g, &wt, &dy, dx));
            near(&dx1, &dx2, "dx");
            let ((dw1, db1), (dw2, db2)) = (
                wb_backward_grouped(&g, &x, &dy),
                wb_backward_banded(&g, &x, &dy),
            );
            near(&dw1, &dw2, "dw");
            near(&db1, &db2, "db");
        }
        assert!(short_last > 0, "no batch left a short last group");
        assert!(tiled > 0, "no thread's share cut into several groups");
    });
}

/// [`Shifted::pad`] writes every image position and nothing else: a
/// buffer that held another sample's padded input holds this one's
/// exactly as a fresh one does (its callers rely on it, zeroing their
/// buffers once).
#[test]
fn padding_into_a_used_buffer_is_padding_into_a_fresh_one() {
    for (cin, h, w, k, s, p) in [
        (3, 7, 9, 3, 1, 1),
        (2, 9, 8, 5, 2, 2),
        // Stride 2 by its deinterleave: an odd width, an odd padding.
        (2, 9, 7, 3, 2, 1),
        (8, 11, 13, 3, 3, 1),
    ] {
        let g = Geometry::new(&[1, cin, h, w], &[4, cin, k, k], s, p);
        let sh = Shifted::layout(&g);
        let mut rng = fastrand::Rng::with_seed(9);
        let (a, b) = (
            uniform(&mut rng, cin * h * w),
            uniform(&mut rng, cin * h * w),
        );
        let mut fresh = vec![0.0; sh.len(&g)];
        sh.pad(&g, &a, &mut fresh);
        let mut used = vec![0.0; sh.len(&g)];
        sh.pad(&g, &b, &mut used);
        sh.pad(&g, &a, &mut used);
        assert_eq!(fresh, used, "cin {cin} {h}×{w} k {k} stride {s} pad {p}");
        // Every image value where `at` places it.
        for (i, &v) in a.iter().enumerate() {
            let (c, iy, ix) = (i / (h * w), i / w % h, i % w);
            assert_eq!(
                fresh[sh.at(&g, c, iy, ix)],
                v,
                "stride {s}: ({c}, {iy}, {ix})"
            );
        }
        // And the padding is zeros: all but the image's values.
        let nonzero = fresh.iter().filter(|v| **v != 0.0).count();
        assert_eq!(nonzero, a.iter().filter(|v| **v != 0.0).count());
    }
}

/// Strided layers of few input channels (the stacked tile from the
/// split input) against the im2col path, forward and weight gradient.
#[test]
fn stacked_paths_match_im2col() {
    assert!(
        !kernel_settings().products_only(),
        "KernelChoice::Products is set"
    );
    let mut weight_grads = 0;
    for &(b, cin, cout, h, w, k, s, p) in &[
        // The RGB encoder's first layer at full size: many bands.
        (2, 3, 4, 128, 128, 7, 2, 3),
        // The depth encoder's first layer, odd sides, wider than high.
        (2, 1, 3, 11, 14, 3, 2, 1),
        // Narrower than the stride; a kernel as wide as the stride,
        // no padding (no zeros after a phase plane).
        (1, 2, 3, 7, 2, 3, 3, 1),
        (2, 3, 2, 8, 9, 2, 2, 0),
        (1, 2, 3, 13, 9, 5, 2, 2),
        (2, 3, 2, 10, 12, 5, 3, 2),
        (1, 7, 2, 2, 3, 3, 2, 1),
    ] {
        let g = Geometry::new(&[b, cin, h, w], &[cout, cin, k, k], s, p);
        let what = format!("b {b} cin {cin} cout {cout} {h}×{w} k {k} stride {s} pad {p}");
        assert!(Shifted::of(&g).is_none(), "{what}: Shifted");
        let sh = Shifted::stacked(&g).expect("a stacked geometry");
        let mut rng = fastrand::Rng::with_seed(5);
        let (x, wt, bias) = (
            uniform(&mut rng, b * cin * h * w),
            uniform(&mut rng, cout * cin * k * k),
            uniform(&mut rng, cout),
        );
        let dy = uniform(&mut rng, b * cout * g.outs());
        let near = |a: &[f32], b: &[f32], pass: &str| near(a, b, &format!("{what} {pass}"));
        let y1 = pass(dy.len(), |y| forward_stacked(&g, sh, &x, &wt, &bias, y));
        let y2 = pass(dy.len(), |y| forward_banded(&g, &x, &wt, &bias, y));
        near(&y1, &y2, "y");
        let ((dw1, db1), (dw2, db2)) = (
            wb_backward_stacked(&g, sh, &x, &dy),
            wb_backward_banded(&g, &x, &dy),
        );
        near(&dw1, &dw2, "dw");
        near(&db1, &db2, "db");
        weight_grads += direct_weight_grad_as(&g, sh, &x, &dy, (&dw2, &db2), &what);
    }
    // conv_direct's weight gradient takes the first case (4 output
    // channels, 64 wide; 49 taps: groups of 3 and a last one of 1); the
    // others are not a multiple of 8 wide, or of 4 channels.
    assert_eq!(weight_grads, if direct::cpu() { 1 } else { 0 });
    // The first case is split into bands.
    let g = Geometry::new(&[1, 3, 128, 128], &[4, 3, 7, 7], 2, 3);
    let sh = Shifted::stacked(&g).expect("stacked");
    assert!(stacked_rows(&g, sh) < g.ho);
}

/// The columns kept inside the image, against a direct count.
#[test]
fn inside_columns_are_exactly_those_in_the_image() {
    for (w, k, s, p) in [
        (9, 7, 2, 3),
        (8, 5, 2, 2),
        (7, 3, 1, 1),
        (5, 3, 1, 0),
        (4, 1, 1, 0),
    ] {
        let g = Geometry::new(&[1, 1, w, w], &[1, 1, k, k], s, p);
        for kx in 0..k {
            let want: Vec<usize> = (0..g.wo)
                .filter(|&ox| {
                    let ix = (ox * s + kx) as isize - p as isize;
                    ix >= 0 && ix < w as isize
                })
                .collect();
            let got: Vec<usize> = g.inside(kx).collect();
            assert_eq!(got, want, "w {w} k {k} s {s} p {p} kx {kx}");
        }
    }
}

/// The kernel settings a geometry carries choose its routes:
/// `KernelChoice::Products` keeps faer's products where the direct kernels
/// would run, `grouped_outs: 0` groups no layer, and each pass's values
/// stay the same.
#[test]
fn settings_choose_the_routes_not_the_values() {
    use crate::{KernelChoice, KernelSettings};
    let products = KernelSettings {
        choice: KernelChoice::Products,
        ..KernelSettings::DEFAULT
    };
    let ungrouped = KernelSettings {
        grouped_outs: 0,
        ..KernelSettings::DEFAULT
    };
    // (batch, cin, cout, side, k, stride, pad, settings): a layer the
    // direct kernels cover, a strided one by phases, a grouped 4² map.
    let cases = [
        (2, 8, 16, 32, 3, 1, 1, products),
        (1, 8, 12, 32, 4, 2, 1, products),
        (3, 8, 4, 4, 3, 1, 1, ungrouped),
    ];
    for (b, cin, cout, side, k, s, p, settings) in cases {
        let ours = Geometry::new(&[b, cin, side, side], &[cout, cin, k, k], s, p)
            .with_settings(KernelSettings::DEFAULT);
        let other = ours.with_settings(settings);
        assert!(!direct_forward(&other) && !direct_weight_grad(&other) && !split_direct(&other));
        if settings.grouped_outs == 0 {
            assert!(grouped(&ours) && !grouped(&other));
        }
        let mut rng = fastrand::Rng::with_seed(5);
        let (x, w, bias) = (
            uniform(&mut rng, b * cin * side * side),
            uniform(&mut rng, cout * cin * k * k),
            uniform(&mut rng, cout),
        );
        let dy = uniform(&mut rng, b * cout * ours.outs());
        let what = format!("b {b} cin {cin} cout {cout} side {side} k {k} stride {s} pad {p}");
        let run = |g: &Geometry| {
            let y = pass(dy.len(), |y| forward(g, &x, &w, &bias, y));
            let dx = pass(x.len(), |dx| x_backward(g, &w, &dy, dx));
            (y, dx, wb_backward(g, &x, &dy))
        };
        let ((y1, dx1, (dw1, db1)), (y2, dx2, (dw2, db2))) = (run(&ours), run(&other));
        near(&y1, &y2, &format!("{what} y"));
        near(&dx1, &dx2, &format!("{what} dx"));
        near(&dw1, &dw2, &format!("{what} dw"));
        near(&db1, &db2, &format!("{what} db"));
    }
}
