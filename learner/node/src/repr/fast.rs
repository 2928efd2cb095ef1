//! A CPU inference path for a trained model's z mean: the same weights and
//! arithmetic as [`ReprNet::encode`], without burn's per-operation dispatch
//! and layout conversions. Images stay channels-last through every layer;
//! each convolution is one im2col and one faer matrix product, with bias and
//! leaky ReLU applied in the same pass over its output. The convolutions'
//! buffers are reused between the calls of one thread.
//!
//! It exists because burn's `flex` backend took 10 ms per observation on one
//! core (docs/performance.md), most of it in layout changes and im2col
//! around small matrix products. It computes what `encode` computes (a test
//! holds the two together on random weights for every model kind and
//! modality mask) and nothing else: no flow maps, no gradients.

use super::config::{Modalities, ModelConfig};
use super::encoders::{LEAKY_SLOPE, Mlp};
use super::fusion::MIN_VARIANCE;
use super::inputs::InputArrays;
use super::net::ReprNet;
use crate::policy::WRENCH_WINDOW;
use crate::proprio::PROPRIO;
use burn::module::Param;
use burn::nn::conv::{Conv1d, Conv2d};
use burn::nn::{Linear, PaddingConfig1d};
use burn::prelude::*;
use faer::{Accum, MatMut, MatRef, Par};
use std::sync::Mutex;

fn values<const D: usize>(p: &Param<Tensor<D>>) -> Vec<f32> {
    p.val().try_into_vec_as::<f32>().expect("an f32 tensor")
}

/// A bias as values (zeros when the layer has none).
fn bias(b: &Option<Param<Tensor<1>>>, n: usize) -> Vec<f32> {
    b.as_ref().map_or(vec![0.0; n], values)
}

/// Convolution weights `[cout, cin, taps]` (burn's layout, the kernel
/// flattened) as the product's `[(tap, ci), cout]`, rows in tap-then-channel
/// order as the channels-last im2col lays them out.
fn taps_first(src: &[f32], cout: usize, cin: usize, taps: usize) -> Vec<f32> {
    let mut w = vec![0.0; taps * cin * cout];
    for co in 0..cout {
        for ci in 0..cin {
            for t in 0..taps {
                w[(t * cin + ci) * cout + co] = src[(co * cin + ci) * taps + t];
            }
        }
    }
    w
}

fn leaky(x: f32) -> f32 {
    if x >= 0.0 { x } else { x * LEAKY_SLOPE as f32 }
}

/// `out[M, N] = x[M, K] · w[K, N]`, all row-major.
fn matmul(x: &[f32], w: &[f32], out: &mut [f32], m: usize, k: usize, n: usize) {
    let lhs = MatRef::from_row_major_slice(&x[..m * k], m, k);
    let rhs = MatRef::from_row_major_slice(&w[..k * n], k, n);
    let dst = MatMut::from_row_major_slice_mut(&mut out[..m * n], m, n);
    faer::linalg::matmul::matmul(dst, Accum::Replace, lhs, rhs, 1.0f32, Par::Seq);
}

/// Adds the bias to every row of `out[M, N]` and, when `act`, applies the
/// leaky ReLU.
fn bias_act(out: &mut [f32], bias: &[f32], act: bool) {
    for row in out.chunks_exact_mut(bias.len()) {
        for (v, b) in row.iter_mut().zip(bias) {
            let y = *v + b;
            *v = if act { leaky(y) } else { y };
        }
    }
}

/// A fully connected layer, weights `[in, out]` row-major (burn's layout).
struct Dense {
    w: Vec<f32>,
    b: Vec<f32>,
    n_in: usize,
    n_out: usize,
}

impl Dense {
    fn new(l: &Linear) -> Self {
        let [n_in, n_out] = l.weight.val().dims();
        Self {
            w: values(&l.weight),
            b: bias(&l.bias, n_out),
            n_in,
            n_out,
        }
    }

    /// `x[M, in]` → `out[M, out]`.
    fn forward(&self, x: &[f32], out: &mut [f32], m: usize, act: bool) {
        matmul(x, &self.w, out, m, self.n_in, self.n_out);
        bias_act(&mut out[..m * self.n_out], &self.b, act);
    }
}

/// A multilayer perceptron: leaky ReLU between layers.
struct Layers(Vec<Dense>);

impl Layers {
    fn new(mlp: &Mlp) -> Self {
        Self(mlp.layers.iter().map(Dense::new).collect())
    }

    /// `x[M, in]` → `out[M, out]`, through `tmp`.
    fn forward(&self, x: &[f32], m: usize, tmp: &mut Vec<f32>, out: &mut Vec<f32>) {
        let last = self.0.len() - 1;
        let mut cur = x.to_vec();
        for (i, l) in self.0.iter().enumerate() {
            tmp.resize(m * l.n_out, 0.0);
            l.forward(&cur, tmp, m, i < last);
            std::mem::swap(&mut cur, tmp);
        }
        *out = cur;
    }
}

/// A square 2-D convolution on channels-last images, weights `[k·k·cin,
/// cout]` with rows in (ky, kx, ci) order.
struct Conv {
    k: usize,
    stride: usize,
    pad: usize,
    cin: usize,
    cout: usize,
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Conv {
    fn new(c: &Conv2d) -> Self {
        let [cout, cin, _, _] = c.weight.val().dims();
        let (k, stride, pad) = super::conv_train::square(c);
        Self {
            k,
            stride,
            pad,
            cin,
            cout,
            w: taps_first(&values(&c.weight), cout, cin, k * k),
            b: bias(&c.bias, cout),
        }
    }

    fn out_side(&self, side: usize) -> usize {
        (side + 2 * self.pad - self.k) / self.stride + 1
    }

    /// `x[side, side, cin]` → `out[o, o, cout]` (o = `out_side(side)`),
    /// leaky ReLU applied; `col` is the im2col scratch.
    fn forward(&self, x: &[f32], side: usize, col: &mut Vec<f32>, out: &mut Vec<f32>) -> usize {
        let o = self.out_side(side);
        let (k, cin) = (self.k, self.cin);
        let kk = k * k * cin;
        col.clear();
        col.resize(o * o * kk, 0.0);
        for oy in 0..o {
            for ox in 0..o {
                let row = &mut col[(oy * o + ox) * kk..][..kk];
                for ky in 0..k {
                    let iy = (oy * self.stride + ky) as isize - self.pad as isize;
                    if iy < 0 || iy >= side as isize {
                        continue; // zeros already
                    }
                    for kx in 0..k {
                        let ix = (ox * self.stride + kx) as isize - self.pad as isize;
                        if ix < 0 || ix >= side as isize {
                            continue;
                        }
                        let src = (iy as usize * side + ix as usize) * cin;
                        row[(ky * k + kx) * cin..][..cin].copy_from_slice(&x[src..src + cin]);
                    }
                }
            }
        }
        out.resize(o * o * self.cout, 0.0);
        matmul(col, &self.w, out, o * o, kk, self.cout);
        bias_act(&mut out[..o * o * self.cout], &self.b, true);
        o
    }
}

/// An image encoder: convolutions, then the fully connected layer (its rows
/// permuted from burn's channels-first flatten to channels-last).
struct ImageEncoder {
    convs: Vec<Conv>,
    fc: Dense,
}

impl ImageEncoder {
    fn new(convs: &[Conv2d], fc: &Linear, side: usize) -> Self {
        let convs: Vec<Conv> = convs.iter().map(Conv::new).collect();
        let last = convs.last().expect("one convolution or more");
        let o = convs.iter().fold(side, |s, c| c.out_side(s));
        let c = last.cout;
        let mut fc = Dense::new(fc);
        assert_eq!(fc.n_in, c * o * o);
        let src = std::mem::take(&mut fc.w);
        fc.w = vec![0.0; src.len()];
        for ch in 0..c {
            for p in 0..o * o {
                let from = (ch * o * o + p) * fc.n_out;
                let to = (p * c + ch) * fc.n_out;
                fc.w[to..to + fc.n_out].copy_from_slice(&src[from..from + fc.n_out]);
            }
        }
        Self { convs, fc }
    }

    /// The channels-last image in `s.a` → `out[2d]`.
    fn forward(&self, side: usize, s: &mut Scratch, out: &mut [f32]) {
        let mut side = side;
        for c in &self.convs {
            side = c.forward(&s.a, side, &mut s.col, &mut s.b);
            std::mem::swap(&mut s.a, &mut s.b);
        }
        self.fc.forward(&s.a, out, 1, false);
    }
}

/// The wrench encoder: kernel 2, stride 2, no padding, so on time-major
/// `[T, C]` data each layer is one product of the input viewed as
/// `[T/2, 2C]` with weights `[2C, cout]` (rows in (k, ci) order).
struct WrenchStack(Vec<Dense>);

impl WrenchStack {
    fn new(convs: &[Conv1d]) -> Self {
        Self(
            convs
                .iter()
                .map(|c| {
                    let [cout, cin, k] = c.weight.val().dims();
                    assert!(k == 2 && c.stride == 2 && c.groups == 1 && c.dilation == 1);
                    assert!(matches!(c.padding, PaddingConfig1d::Valid));
                    Dense {
                        w: taps_first(&values(&c.weight), cout, cin, k),
                        b: bias(&c.bias, cout),
                        n_in: k * cin,
                        n_out: cout,
                    }
                })
                .collect(),
        )
    }

    /// One `[6, T]` window (channels first, as the arrays hold it) → `out[2d]`.
    fn forward(&self, x: &[f32], s: &mut Scratch, out: &mut [f32]) {
        let t = WRENCH_WINDOW;
        let c = x.len() / t;
        s.a.clear();
        s.a.resize(t * c, 0.0);
        for ch in 0..c {
            for k in 0..t {
                s.a[k * c + ch] = x[ch * t + k];
            }
        }
        let mut rows = t;
        let last = self.0.len() - 1;
        for (i, l) in self.0.iter().enumerate() {
            rows /= 2;
            s.b.resize(rows * l.n_out, 0.0);
            l.forward(&s.a, &mut s.b, rows, i < last);
            std::mem::swap(&mut s.a, &mut s.b);
        }
        out.copy_from_slice(&s.a[..out.len()]);
    }
}

#[derive(Default)]
struct Scratch {
    a: Vec<f32>,
    b: Vec<f32>,
    col: Vec<f32>,
    feats: Vec<f32>,
}

/// The encoders and fusion of a [`ReprNet`], copied out for fast CPU
/// inference of z means.
pub struct FastEncoder {
    d: usize,
    side: usize,
    rgb: Option<ImageEncoder>,
    depth: Option<ImageEncoder>,
    haptics: Option<WrenchStack>,
    proprio: Option<Layers>,
    concat: Option<Layers>,
    threads: usize,
    /// Buffers of single-threaded calls, reused.
    scratch: Mutex<Scratch>,
}

impl FastEncoder {
    /// Copies the weights of `net` (built for `cfg`).
    pub fn new(net: &ReprNet, cfg: &ModelConfig) -> Self {
        let side = cfg.image_size;
        Self {
            d: cfg.latent_dim,
            side,
            rgb: net
                .rgb
                .as_ref()
                .map(|e| ImageEncoder::new(&e.convs, &e.fc, side)),
            depth: net
                .depth
                .as_ref()
                .map(|e| ImageEncoder::new(&e.convs, &e.fc, side)),
            haptics: net.haptics.as_ref().map(|e| WrenchStack::new(&e.convs)),
            proprio: net.proprio.as_ref().map(|e| Layers::new(&e.mlp)),
            concat: net.concat_fusion.as_ref().map(Layers::new),
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            scratch: Mutex::new(Scratch::default()),
        }
    }

    /// Splits batches over at most `n` threads (the default: every core).
    pub fn with_threads(mut self, n: usize) -> Self {
        self.threads = n.max(1);
        self
    }

    /// The z means of the batch `a` with the sensors `on` (the model's own
    /// modalities already applied), `batch × d` values row after row, as
    /// [`ReprNet::encode`] computes them. A batch is split over the threads
    /// by samples.
    ///
    /// # Panics
    /// If `a` is not of the model's image side or its arrays are not of
    /// its batch's sizes ([`super::Encoder::encode`] checks both first).
    pub fn encode(&self, a: &InputArrays, on: Modalities) -> Vec<f32> {
        let d = self.d;
        let (b, px) = (a.batch, a.side * a.side);
        assert_eq!(
            a.side, self.side,
            "image side: the model takes {} px",
            self.side
        );
        assert!(
            a.rgb.len() == b * 3 * px
                && a.depth.len() == b * px
                && a.wrench.len() == b * 6 * WRENCH_WINDOW
                && a.proprio.len() == b * PROPRIO,
            "input arrays of another size than a batch of {b}"
        );
        let mut z = vec![0.0f32; a.batch * d];
        let threads = self.threads.min(a.batch);
        if threads <= 1 {
            let mut s = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
            for (i, zi) in z.chunks_exact_mut(d).enumerate() {
                self.encode_one(a, i, on, &mut s, zi);
            }
            return z;
        }
        let per = a.batch.div_ceil(threads);
        std::thread::scope(|sc| {
            for (t, zs) in z.chunks_mut(per * d).enumerate() {
                sc.spawn(move || {
                    let mut s = Scratch::default();
                    for (j, zi) in zs.chunks_exact_mut(d).enumerate() {
                        self.encode_one(a, t * per + j, on, &mut s, zi);
                    }
                });
            }
        });
        z
    }

    /// Sample `i` of `a` into `z` (d values).
    fn encode_one(
        &self,
        a: &InputArrays,
        i: usize,
        on: Modalities,
        s: &mut Scratch,
        z: &mut [f32],
    ) {
        let (side, d) = (a.side, self.d);
        let px = side * side;
        let mut feats = std::mem::take(&mut s.feats);
        feats.clear();
        feats.resize(8 * d, 0.0);
        let mut present = [false; 4];
        if let (Some(e), true) = (&self.rgb, on.rgb) {
            // Channels-first to channels-last, into the encoder's input.
            let src = &a.rgb[i * 3 * px..][..3 * px];
            s.a.resize(3 * px, 0.0);
            for p in 0..px {
                for c in 0..3 {
                    s.a[p * 3 + c] = src[c * px + p];
                }
            }
            e.forward(side, s, &mut feats[..2 * d]);
            present[0] = true;
        }
        if let (Some(e), true) = (&self.depth, on.depth) {
            s.a.clear();
            s.a.extend_from_slice(&a.depth[i * px..][..px]);
            e.forward(side, s, &mut feats[2 * d..4 * d]);
            present[1] = true;
        }
        if let (Some(e), true) = (&self.haptics, on.haptics) {
            let n = 6 * WRENCH_WINDOW;
            e.forward(&a.wrench[i * n..][..n], s, &mut feats[4 * d..6 * d]);
            present[2] = true;
        }
        let mut out = Vec::new();
        if let (Some(e), true) = (&self.proprio, on.proprio) {
            e.forward(&a.proprio[i * PROPRIO..][..PROPRIO], 1, &mut s.b, &mut out);
            feats[6 * d..8 * d].copy_from_slice(&out[..2 * d]);
            present[3] = true;
        }
        match &self.concat {
            Some(mlp) => {
                // Masked modalities are zeros, as in `encode`.
                mlp.forward(&feats, 1, &mut s.b, &mut out);
                z.copy_from_slice(&out[..d]);
            }
            None => product_of_experts(&feats, &present, d, z),
        }
        s.feats = feats;
    }
}

/// The mean of the product of the present experts and the standard-normal
/// prior (docs in [`super::fusion`]); with none present, the prior's 0.
fn product_of_experts(feats: &[f32], present: &[bool; 4], d: usize, z: &mut [f32]) {
    for (j, zj) in z.iter_mut().enumerate() {
        let (mut precision, mut weighted) = (0.0f32, 0.0f32);
        for (e, _) in present.iter().enumerate().filter(|(_, p)| **p) {
            let p = &feats[e * 2 * d..][..2 * d];
            let var = softplus(p[d + j]) + MIN_VARIANCE as f32;
            precision += 1.0 / var;
            weighted += p[j] / var;
        }
        *zj = weighted / (precision + 1.0);
    }
}

/// ln(1 + eˣ), without overflow.
fn softplus(x: f32) -> f32 {
    if x > 20.0 { x } else { x.exp().ln_1p() }
}
