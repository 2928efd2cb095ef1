//! The CPU inference of a trained model's z mean: the same weights and
//! arithmetic as the training crate's network (`ReprNet::encode`), without
//! burn's per-operation dispatch and layout conversions, on plain arrays
//! (the training crate converts its parameters into [`EncoderWeights`]). Images stay channels-last through every layer;
//! each convolution is one im2col and one faer matrix product, with bias and
//! leaky ReLU applied in the same pass over its output. The convolutions'
//! buffers are reused between the calls of one thread.
//!
//! It exists because burn's `flex` backend took 10 ms per observation on one
//! core (docs/performance.md), most of it in layout changes and im2col
//! around small matrix products. It computes what `encode` computes (a test
//! holds the two together on random weights for every model kind and
//! modality mask) and nothing else: no flow maps, no gradients.

use super::Modalities;
use super::inputs::InputArrays;
use crate::policy::WRENCH_WINDOW;
use crate::proprio::PROPRIO;
use faer::{Accum, MatMut, MatRef, Par};
use std::sync::Mutex;

/// Why an encoder's weights do not fit together or do not load; the
/// file is named by [`super::weights::FileError`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum WeightsError {
    /// An array of another shape than the model's layers ask for.
    #[error("array {tensor}: shape {found:?}, expected {expected:?}")]
    Shape {
        /// The array.
        tensor: String,
        /// What the layers ask for.
        expected: Vec<usize>,
        /// What the file holds.
        found: Vec<usize>,
    },
    /// An array the header names no layer for, or a layer without its array.
    #[error("array {0} is missing")]
    Missing(String),
    /// The values end before the header's arrays do.
    #[error(
        "truncated: the header's arrays take {expected} bytes of values, the file holds {found}"
    )]
    Truncated {
        /// Bytes the header's arrays take.
        expected: u64,
        /// Bytes after the header.
        found: u64,
    },
    /// Not this format, or a header that does not parse.
    #[error("{0}")]
    Format(String),
}

fn leaky(x: f32, slope: f32) -> f32 {
    if x >= 0.0 { x } else { x * slope }
}

/// `out[M, N] = x[M, K] · w[K, N]`, all row-major.
fn matmul(x: &[f32], w: &[f32], out: &mut [f32], m: usize, k: usize, n: usize) {
    let lhs = MatRef::from_row_major_slice(&x[..m * k], m, k);
    let rhs = MatRef::from_row_major_slice(&w[..k * n], k, n);
    let dst = MatMut::from_row_major_slice_mut(&mut out[..m * n], m, n);
    faer::linalg::matmul::matmul(dst, Accum::Replace, lhs, rhs, 1.0f32, Par::Seq);
}

/// Adds the bias to every row of `out[M, N]` and, with `act` (the leaky
/// ReLU's slope), applies the activation.
fn bias_act(out: &mut [f32], bias: &[f32], act: Option<f32>) {
    for row in out.chunks_exact_mut(bias.len()) {
        for (v, b) in row.iter_mut().zip(bias) {
            let y = *v + b;
            *v = match act {
                Some(slope) => leaky(y, slope),
                None => y,
            };
        }
    }
}

/// A fully connected layer, `y = x·W + b`, weights `[in, out]` row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    /// Weights, `n_in × n_out`, row-major.
    pub w: Vec<f32>,
    /// Biases, `n_out` (zeros for a layer without).
    pub b: Vec<f32>,
    /// Inputs.
    pub n_in: usize,
    /// Outputs.
    pub n_out: usize,
}

impl Dense {
    /// `x[M, in]` → `out[M, out]`.
    fn forward(&self, x: &[f32], out: &mut [f32], m: usize, act: Option<f32>) {
        matmul(x, &self.w, out, m, self.n_in, self.n_out);
        bias_act(&mut out[..m * self.n_out], &self.b, act);
    }
}

/// `x[M, in]` → `out[M, out]` through `layers`, leaky ReLU (`slope`) between
/// them, through `tmp`.
fn mlp_forward(
    layers: &[Dense],
    slope: f32,
    x: &[f32],
    m: usize,
    tmp: &mut Vec<f32>,
    out: &mut Vec<f32>,
) {
    let last = layers.len() - 1;
    let mut cur = x.to_vec();
    for (i, l) in layers.iter().enumerate() {
        tmp.resize(m * l.n_out, 0.0);
        l.forward(&cur, tmp, m, (i < last).then_some(slope));
        std::mem::swap(&mut cur, tmp);
    }
    *out = cur;
}

/// A square 2-D convolution on channels-last images, weights `[k·k·cin,
/// cout]` with rows in (ky, kx, ci) order.
#[derive(Debug, Clone, PartialEq)]
pub struct Conv {
    /// Kernel side.
    pub k: usize,
    /// Stride.
    pub stride: usize,
    /// Zero padding on every side.
    pub pad: usize,
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// Weights, `k·k·cin × cout`, row-major.
    pub w: Vec<f32>,
    /// Biases, `cout`.
    pub b: Vec<f32>,
}

impl Conv {
    /// Output side for an input of `side` px (0 when the kernel does not
    /// fit).
    pub fn out_side(&self, side: usize) -> usize {
        match (side + 2 * self.pad).checked_sub(self.k) {
            Some(n) if self.stride > 0 => n / self.stride + 1,
            _ => 0,
        }
    }

    /// `x[side, side, cin]` → `out[o, o, cout]` (o = `out_side(side)`),
    /// leaky ReLU applied; `col` is the im2col scratch.
    fn forward(
        &self,
        x: &[f32],
        side: usize,
        slope: f32,
        col: &mut Vec<f32>,
        out: &mut Vec<f32>,
    ) -> usize {
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
        bias_act(&mut out[..o * o * self.cout], &self.b, Some(slope));
        o
    }
}

/// An image encoder: leaky-ReLU convolutions, then the fully connected
/// layer, whose input rows are in channels-last order (pixel, then
/// channel).
#[derive(Debug, Clone, PartialEq)]
pub struct ImageEncoder {
    /// The convolutions, input first.
    pub convs: Vec<Conv>,
    /// The fully connected layer to the expert's 2d values.
    pub fc: Dense,
}

impl ImageEncoder {
    /// The channels-last image in `s.a` → `out[2d]`.
    fn forward(&self, side: usize, slope: f32, s: &mut Scratch, out: &mut [f32]) {
        let mut side = side;
        for c in &self.convs {
            side = c.forward(&s.a, side, slope, &mut s.col, &mut s.b);
            std::mem::swap(&mut s.a, &mut s.b);
        }
        self.fc.forward(&s.a, out, 1, None);
    }
}

/// The wrench encoder: kernel 2, stride 2, no padding, so on time-major
/// `[T, C]` data each layer is one product of the input viewed as
/// `[T/2, 2C]` with weights `[2C, cout]` (rows in (k, ci) order).
#[derive(Debug, Clone, PartialEq)]
pub struct WrenchStack(pub Vec<Dense>);

impl WrenchStack {
    /// One `[6, T]` window (channels first, as the arrays hold it) → `out[2d]`.
    fn forward(&self, x: &[f32], slope: f32, s: &mut Scratch, out: &mut [f32]) {
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
            l.forward(&s.a, &mut s.b, rows, (i < last).then_some(slope));
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

/// A trained model's encoders and fusion as plain arrays: what the CPU
/// inference runs and what the weights file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderWeights {
    /// Latent size d.
    pub latent_dim: usize,
    /// Image side the model takes, px.
    pub image_side: usize,
    /// The leaky ReLU's slope for negative inputs.
    pub leaky_slope: f32,
    /// Added to every expert's variance (the product of experts' floor).
    pub min_variance: f32,
    /// The RGB encoder (3 input channels).
    pub rgb: Option<ImageEncoder>,
    /// The depth encoder (1 input channel).
    pub depth: Option<ImageEncoder>,
    /// The wrench encoder.
    pub haptics: Option<WrenchStack>,
    /// The proprioception MLP.
    pub proprio: Option<Vec<Dense>>,
    /// The deterministic model's fusion MLP over the concatenated experts'
    /// outputs (`None`: the product of experts).
    pub concat: Option<Vec<Dense>>,
}

impl EncoderWeights {
    /// Checks that every layer's arrays have the sizes its neighbours and
    /// the inputs ask for; names the first that does not.
    pub fn check(&self) -> Result<(), WeightsError> {
        let d = self.latent_dim;
        let shape = |name: String, expected: Vec<usize>, found: Vec<usize>| {
            if expected == found {
                Ok(())
            } else {
                Err(WeightsError::Shape {
                    tensor: name,
                    expected,
                    found,
                })
            }
        };
        let dense = |name: &str, l: &Dense, n_in: usize, n_out: Option<usize>| {
            shape(
                format!("{name}.weight"),
                vec![n_in, n_out.unwrap_or(l.n_out)],
                vec![l.n_in, l.n_out],
            )?;
            shape(
                format!("{name}.weight"),
                vec![l.n_in * l.n_out],
                vec![l.w.len()],
            )?;
            shape(format!("{name}.bias"), vec![l.n_out], vec![l.b.len()])
        };
        let mlp = |name: &str, layers: &[Dense], n_in: usize, n_out: usize| {
            if layers.is_empty() {
                return Err(WeightsError::Missing(format!("{name}.layer0.weight")));
            }
            let mut n = n_in;
            for (i, l) in layers.iter().enumerate() {
                let last = i + 1 == layers.len();
                dense(&format!("{name}.layer{i}"), l, n, last.then_some(n_out))?;
                n = l.n_out;
            }
            Ok(())
        };
        for (name, e, channels) in [("rgb", &self.rgb, 3), ("depth", &self.depth, 1)] {
            let Some(e) = e else { continue };
            let (mut side, mut cin) = (self.image_side, channels);
            if e.convs.is_empty() {
                return Err(WeightsError::Missing(format!("{name}.conv0.weight")));
            }
            for (i, c) in e.convs.iter().enumerate() {
                let t = format!("{name}.conv{i}");
                shape(
                    format!("{t}.weight"),
                    vec![c.k * c.k * cin, c.cout],
                    vec![c.k * c.k * c.cin, c.cout],
                )?;
                shape(
                    format!("{t}.weight"),
                    vec![c.k * c.k * c.cin * c.cout],
                    vec![c.w.len()],
                )?;
                shape(format!("{t}.bias"), vec![c.cout], vec![c.b.len()])?;
                side = c.out_side(side);
                if side == 0 {
                    return Err(WeightsError::Format(format!(
                        "{t}: a kernel of {} px with padding {} and stride {} does not fit the \
                         image",
                        c.k, c.pad, c.stride
                    )));
                }
                cin = c.cout;
            }
            dense(&format!("{name}.fc"), &e.fc, cin * side * side, Some(2 * d))?;
        }
        if let Some(WrenchStack(layers)) = &self.haptics {
            let (mut rows, mut cin) = (WRENCH_WINDOW, 6);
            for (i, l) in layers.iter().enumerate() {
                dense(&format!("haptics.layer{i}"), l, 2 * cin, None)?;
                rows /= 2;
                cin = l.n_out;
            }
            shape("haptics (output)".into(), vec![2 * d], vec![rows * cin])?;
        }
        if let Some(l) = &self.proprio {
            mlp("proprio", l, PROPRIO, 2 * d)?;
        }
        if let Some(l) = &self.concat {
            mlp("concat", l, 8 * d, d)?;
        }
        Ok(())
    }
}

/// The z means of a model on the CPU: its [`EncoderWeights`] and the
/// buffers their layers reuse.
pub struct FastEncoder {
    w: EncoderWeights,
    threads: usize,
    /// Buffers of single-threaded calls, reused.
    scratch: Mutex<Scratch>,
}

impl std::fmt::Debug for FastEncoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FastEncoder")
            .field("latent_dim", &self.w.latent_dim)
            .field("image_side", &self.w.image_side)
            .field("threads", &self.threads)
            .finish()
    }
}

impl FastEncoder {
    /// Around `w`, once its sizes are checked ([`EncoderWeights::check`]);
    /// batches are split over every core.
    pub fn new(w: EncoderWeights) -> Result<Self, WeightsError> {
        w.check()?;
        Ok(Self {
            w,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            scratch: Mutex::new(Scratch::default()),
        })
    }

    /// Its weights.
    pub fn weights(&self) -> &EncoderWeights {
        &self.w
    }

    /// Splits batches over at most `n` threads (the default: every core).
    pub fn with_threads(mut self, n: usize) -> Self {
        self.threads = n.max(1);
        self
    }

    /// The z means of the batch `a` with the sensors `on` (the model's own
    /// modalities already applied), `batch × d` values row after row, as
    /// the training crate's network computes them. A batch is split over the
    /// threads by samples.
    ///
    /// # Panics
    /// If `a` is not of the model's image side or its arrays are not of
    /// its batch's sizes (the normaliser's `inputs` checks both first).
    pub fn encode(&self, a: &InputArrays, on: Modalities) -> Vec<f32> {
        let d = self.w.latent_dim;
        let (b, px) = (a.batch, a.side * a.side);
        assert_eq!(
            a.side, self.w.image_side,
            "image side: the model takes {} px",
            self.w.image_side
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
        let (side, d) = (a.side, self.w.latent_dim);
        let (w, slope) = (&self.w, self.w.leaky_slope);
        let px = side * side;
        let mut feats = std::mem::take(&mut s.feats);
        feats.clear();
        feats.resize(8 * d, 0.0);
        let mut present = [false; 4];
        if let (Some(e), true) = (&w.rgb, on.rgb) {
            // Channels-first to channels-last, into the encoder's input.
            let src = &a.rgb[i * 3 * px..][..3 * px];
            s.a.resize(3 * px, 0.0);
            for p in 0..px {
                for c in 0..3 {
                    s.a[p * 3 + c] = src[c * px + p];
                }
            }
            e.forward(side, slope, s, &mut feats[..2 * d]);
            present[0] = true;
        }
        if let (Some(e), true) = (&w.depth, on.depth) {
            s.a.clear();
            s.a.extend_from_slice(&a.depth[i * px..][..px]);
            e.forward(side, slope, s, &mut feats[2 * d..4 * d]);
            present[1] = true;
        }
        if let (Some(e), true) = (&w.haptics, on.haptics) {
            let n = 6 * WRENCH_WINDOW;
            e.forward(&a.wrench[i * n..][..n], slope, s, &mut feats[4 * d..6 * d]);
            present[2] = true;
        }
        let mut out = Vec::new();
        if let (Some(e), true) = (&w.proprio, on.proprio) {
            let x = &a.proprio[i * PROPRIO..][..PROPRIO];
            mlp_forward(e, slope, x, 1, &mut s.b, &mut out);
            feats[6 * d..8 * d].copy_from_slice(&out[..2 * d]);
            present[3] = true;
        }
        match &w.concat {
            Some(mlp) => {
                // Masked modalities are zeros, as in the network's `encode`.
                mlp_forward(mlp, slope, &feats, 1, &mut s.b, &mut out);
                z.copy_from_slice(&out[..d]);
            }
            None => product_of_experts(&feats, &present, d, w.min_variance, z),
        }
        s.feats = feats;
    }
}

/// The mean of the product of the present experts and the standard-normal
/// prior (each expert: d means, then d raw values whose softplus plus
/// `min_variance` is the variance); with none present, the prior's 0.
fn product_of_experts(
    feats: &[f32],
    present: &[bool; 4],
    d: usize,
    min_variance: f32,
    z: &mut [f32],
) {
    for (j, zj) in z.iter_mut().enumerate() {
        let (mut precision, mut weighted) = (0.0f32, 0.0f32);
        for (e, _) in present.iter().enumerate().filter(|(_, p)| **p) {
            let p = &feats[e * 2 * d..][..2 * d];
            let var = softplus(p[d + j]) + min_variance;
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
