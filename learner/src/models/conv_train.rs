//! The training path's 2-D convolution on the CPU.
//!
//! burn's `flex` backend runs a convolution's forward pass through its own
//! general kernels and its backward pass through burn's generic rules (the
//! input gradient as a transposed convolution, the weight gradient as a
//! convolution with batch and channels swapped), with layout conversions
//! around each. A profile of a training step put most of its time there
//! (docs/performance.md). [`ConvTrain`] is a burn backend extension that
//! gives `flex` its own three passes, per sample (per group of samples for
//! the small maps) and split over rayon's threads:
//!
//! - layers with small output maps (4² and 2², [`GROUPED_OUTS`]; for an
//!   up-convolution its input's) before any route below: one product per
//!   group of samples per pass over the group's im2col matrix
//!   ([`forward_grouped`]);
//! - stride-1 layers, without im2col ([`Shifted`]): k² products of each
//!   tap's weights with a view of the zero-padded input; the input gradient
//!   is the same kind of convolution of `dy` with the kernel flipped;
//! - strided layers of at least 8 input channels, the same on the input
//!   split into stride² phases;
//! - strided layers of fewer channels (the encoders' first layers),
//!   [`Shifted::stacked`]: the im2col tile of a band of output rows (in
//!   cache) stacked from the split input by contiguous copies, and one faer
//!   product per band, `y = W · col + b`, `dW = Σ dy · colᵀ`;
//! - the forward pass over those views (the shifted, phased and stacked
//!   layouts) through [`super::conv_direct`]'s kernel instead of products
//!   where the output rows are a multiple of 16 wide and the output
//!   channels of 4, on a CPU with AVX and FMA, and the weight gradient
//!   through its second kernel; a strided layer's input gradient, where
//!   each phase of its input is a multiple of 16 wide, as s² stride-1
//!   convolutions of `dy` through the same forward kernel
//!   ([`x_backward_split`]);
//! - other layers through im2col in bands, `dx = col2im(Wᵀ · dy)`; 1×1
//!   layers read their input as the matrix; the bias's `db = Σ dy`;
//! - transposed convolutions (the flow decoder's up-convolutions,
//!   [`conv_transpose2d`]) as the input-gradient pass of the convolution
//!   with the same weight, whose forward pass is their input gradient and
//!   whose weight gradient, with the roles of input and output gradient
//!   swapped, is theirs (burn's took about 12 % of a training step).
//!
//! The GPU backends (burn's `Cube`: Vulkan, CUDA) run burn's own
//! convolution kernels through the trait's default bodies; under autodiff
//! every backend goes through this file's backward node, which calls the
//! backend's kernels. The model code calls [`conv2d`] and
//! [`conv_transpose2d`] whatever the device. The parameters stay in burn's
//! [`Conv2d`] and [`ConvTranspose2d`] modules: records and checkpoints do not change.

use burn::backend::autodiff::{
    Autodiff,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::ops::{ConvOptions, ConvTransposeOptions, ModuleOps};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, TensorMetadata, backend_extension};
use burn::backend::{DType, Flex, flex::FlexTensor};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::prelude::*;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

use super::conv_direct;

/// A square-kernel convolution with equal stride and padding on both axes
/// (every convolution of the models), and the transposed one, each
/// differentiable in its input, weight and bias.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait ConvTrain: Backend {
    /// `x [B, Cin, H, W]`, `weight [Cout, Cin, k, k]`, `bias [Cout]` →
    /// `[B, Cout, Ho, Wo]`.
    fn conv2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, weight, Some(bias), options(stride, pad))
    }

    /// The gradient of [`ConvTrain::conv2d_train`] with respect to `x`.
    fn conv2d_train_x_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv2d_x_backward(x, weight, grad, options(stride, pad))
    }

    /// The gradients with respect to the weight and the bias.
    fn conv2d_train_wb_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        burns_wb_backward::<Self>(x, weight, grad, stride, pad)
    }

    /// The transposed convolution: `x [B, Cin, H, W]`, `weight [Cin, Cout,
    /// k, k]` (burn's layout for it), `bias [Cout]` → `[B, Cout, (H − 1)·s −
    /// 2p + k, …]`; the input gradient of the convolution of the same
    /// weight, stride and padding, plus the bias.
    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, weight, Some(bias), transposed_options(stride, pad))
    }

    /// The gradient of [`ConvTrain::conv_transpose2d_train`] with respect
    /// to `x`.
    fn conv_transpose2d_train_x_backward(
        _x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d_x_backward(weight, grad, transposed_options(stride, pad))
    }

    /// The gradients of [`ConvTrain::conv_transpose2d_train`] with respect
    /// to the weight and the bias.
    fn conv_transpose2d_train_wb_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let cout = weight.shape()[1];
        let opts = transposed_options(stride, pad);
        let dw = Self::conv_transpose2d_weight_backward(x, weight, grad.clone(), opts);
        (dw, bias_grad::<Self>(grad, cout))
    }
}

fn options(stride: usize, pad: usize) -> ConvOptions<2> {
    ConvOptions::new([stride, stride], [pad, pad], [1, 1], 1)
}

fn transposed_options(stride: usize, pad: usize) -> ConvTransposeOptions<2> {
    ConvTransposeOptions::new([stride, stride], [pad, pad], [0, 0], [1, 1], 1)
}

/// `Σ grad` over the batch and the positions, per channel: `[cout]`.
fn bias_grad<B: Backend>(grad: FloatTensor<B>, cout: usize) -> FloatTensor<B> {
    let db = B::float_sum_dim(B::float_sum_dim(grad, 3), 2);
    B::float_reshape(B::float_sum_dim(db, 0), [cout].into())
}

/// burn's own weight and bias gradients on backend `B`.
fn burns_wb_backward<B: Backend>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    grad: FloatTensor<B>,
    stride: usize,
    pad: usize,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let cout = weight.shape()[0];
    let dw = B::conv2d_weight_backward(x, weight, grad.clone(), options(stride, pad));
    (dw, bias_grad::<B>(grad, cout))
}

/// `c.forward(x)`, through [`ConvTrain`].
///
/// # Panics
/// If the convolution is not one [`ConvTrain`] covers: no bias, a
/// non-square kernel, unequal strides or paddings, dilation or groups (none
/// of the models has one).
pub fn conv2d(c: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    if burns_own() {
        return c.forward(x);
    }
    let (_, stride, pad) = square(c);
    let bias = c.bias.as_ref().expect("conv2d: a convolution with a bias");
    Tensor::from_dispatch(<Dispatch as ConvTrain>::conv2d_train(
        x.into_dispatch(),
        c.weight.val().into_dispatch(),
        bias.val().into_dispatch(),
        stride,
        pad,
    ))
}

/// The kernel side, stride and padding of a convolution with a square
/// kernel and the same stride and padding on both axes (every convolution
/// of the models).
///
/// # Panics
/// On any other convolution (or one with dilation or groups).
pub(crate) fn square(c: &Conv2d) -> (usize, usize, usize) {
    let [_, _, kh, kw] = c.weight.dims();
    let pad = match c.padding {
        PaddingConfig2d::Explicit(t, l, b, r) if t == l && l == b && b == r => t,
        PaddingConfig2d::Valid => 0,
        ref p => panic!("conv2d: unsupported padding {p:?}"),
    };
    assert!(
        kh == kw && c.stride[0] == c.stride[1] && c.dilation == [1, 1] && c.groups == 1,
        "conv2d: only square kernels with one stride, no dilation and no groups"
    );
    (kh, c.stride[0], pad)
}

/// `c.forward(x)` for a transposed convolution (the flow decoder's
/// up-convolutions), through [`ConvTrain`]: on the CPU, the input-gradient
/// pass of the convolution with the same weight, stride and padding.
///
/// # Panics
/// If it has no bias, a non-square kernel, unequal strides or paddings, an
/// output padding, dilation or groups (none of the models has one).
pub fn conv_transpose2d(c: &ConvTranspose2d, x: Tensor<4>) -> Tensor<4> {
    if burns_own() {
        return c.forward(x);
    }
    let [_, _, kh, kw] = c.weight.dims();
    assert!(
        kh == kw
            && c.stride[0] == c.stride[1]
            && c.padding[0] == c.padding[1]
            && c.padding_out == [0, 0]
            && c.dilation == [1, 1]
            && c.groups == 1,
        "conv_transpose2d: only square kernels with one stride and padding, no output \
         padding, dilation or groups"
    );
    let bias = c.bias.as_ref().expect("conv_transpose2d: one with a bias");
    Tensor::from_dispatch(<Dispatch as ConvTrain>::conv_transpose2d_train(
        x.into_dispatch(),
        c.weight.val().into_dispatch(),
        bias.val().into_dispatch(),
        c.stride[0],
        c.padding[0],
    ))
}

/// `LEARNER_CONV=burn` in the environment sends [`conv2d`] and
/// [`conv_transpose2d`] through burn's own convolutions instead (and the
/// leaky ReLU, [`super::encoders::act`], through burn's primitives): the
/// A/B switch of the training benchmark (docs/performance.md), and a way to
/// rule these paths out.
pub(crate) fn burns_own() -> bool {
    static BURN: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *BURN.get_or_init(|| std::env::var("LEARNER_CONV").is_ok_and(|v| v == "burn"))
}

/// Whether `g`'s forward pass (on its [`Shifted`] layout) takes
/// [`conv_direct`]'s kernel.
fn direct(g: &Geometry) -> bool {
    !products_only() && conv_direct::covers(g.cout, g.wo)
}

/// Whether `g`'s weight gradient (on its [`Shifted`] or stacked layout)
/// takes [`conv_direct::weight_grad`]: where it runs and the output rows are
/// a multiple of 16 wide. On 8-wide rows it measured slower than faer's
/// products; on 16-wide ones about even in all (the 64-channel 16² layer
/// about 7 % slower, the largest up-convolution's 11 % faster;
/// docs/performance.md).
fn direct_weight_grad(g: &Geometry) -> bool {
    !products_only() && g.wo.is_multiple_of(16) && conv_direct::runs_weight_grad(g.cout, g.wo)
}

/// `LEARNER_CONV=products` keeps our passes but runs every layer's products
/// through faer rather than [`conv_direct`]'s kernel (the A/B switch of that
/// kernel's benchmark).
fn products_only() -> bool {
    static PRODUCTS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *PRODUCTS.get_or_init(|| std::env::var("LEARNER_CONV").is_ok_and(|v| v == "products"))
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl ConvTrain for burn::backend::Cube {}

/// `v` zeroed, as the initialised values it then is. Each pass's output is
/// allocated without zeroing; a task whose kernel writes every value of its
/// part leaves it so, the others zero their own part just before writing
/// it, in their cache: `vec![0.0; n]` zeroed the whole output on
/// the calling thread first (with the leaky ReLU's, 4.6 % of a one-thread
/// training step in a profile; burn's tensors own their buffers, so none
/// is reused).
pub(crate) fn zeroed(v: &mut [MaybeUninit<f32>]) -> &mut [f32] {
    for x in v.iter_mut() {
        x.write(0.0);
    }
    // SAFETY: every value was just written, and `MaybeUninit<f32>` has
    // `f32`'s layout.
    unsafe { &mut *(v as *mut [MaybeUninit<f32>] as *mut [f32]) }
}

/// `v` seen as values that may be written uninitialised.
///
/// # Safety
/// Only initialised values are written through the result (a kernel that
/// writes `f32`s), never `MaybeUninit::uninit()`.
unsafe fn as_uninit(v: &mut [f32]) -> &mut [MaybeUninit<f32>] {
    // SAFETY: the same layout; the caller's contract keeps `v` initialised.
    unsafe { &mut *(v as *mut [f32] as *mut [MaybeUninit<f32>]) }
}

/// A vector of `n` values written by `fill`, which is given them
/// uninitialised.
///
/// # Safety
/// `fill` writes every one of them (each of this module's passes does: its
/// tasks write their part through [`conv_direct::forward`], which covers
/// it, write each value ([`forward_grouped`]), or [`zeroed`] it first).
pub(crate) unsafe fn written(n: usize, fill: impl FnOnce(&mut [MaybeUninit<f32>])) -> Vec<f32> {
    let mut v = Vec::with_capacity(n);
    fill(&mut v.spare_capacity_mut()[..n]);
    // SAFETY: the caller's contract: `fill` wrote all `n`.
    unsafe { v.set_len(n) };
    v
}

/// The shapes of one convolution.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    batch: usize,
    cin: usize,
    cout: usize,
    h: usize,
    w: usize,
    k: usize,
    stride: usize,
    pad: usize,
    ho: usize,
    wo: usize,
}

impl Geometry {
    fn new(x: &[usize], weight: &[usize], stride: usize, pad: usize) -> Self {
        let (batch, cin, h, w) = (x[0], x[1], x[2], x[3]);
        let (cout, k) = (weight[0], weight[2]);
        assert_eq!(weight[1], cin, "conv2d: weight and input channels differ");
        assert!(
            h + 2 * pad >= k && w + 2 * pad >= k,
            "conv2d: input smaller than the kernel"
        );
        Self {
            batch,
            cin,
            cout,
            h,
            w,
            k,
            stride,
            pad,
            ho: (h + 2 * pad - k) / stride + 1,
            wo: (w + 2 * pad - k) / stride + 1,
        }
    }

    /// The convolution whose input gradient is the transposed convolution
    /// of `x [B, Cin, H, W]` by `weight [Cin, Cout, k, k]`: input `[B, Cout,
    /// (H − 1)·s − 2p + k, …]`, output `[B, Cin, H, W]`, the same weight.
    fn transposed(x: &[usize], weight: &[usize], stride: usize, pad: usize) -> Self {
        assert_eq!(
            weight[0], x[1],
            "conv_transpose2d: weight and input channels differ"
        );
        let k = weight[2];
        let side = |n: usize| {
            ((n - 1) * stride + k)
                .checked_sub(2 * pad)
                .filter(|&v| v > 0)
                .expect("conv_transpose2d: padding larger than the output")
        };
        let g = Self::new(
            &[x[0], weight[1], side(x[2]), side(x[3])],
            weight,
            stride,
            pad,
        );
        debug_assert_eq!((g.ho, g.wo), (x[2], x[3]));
        g
    }

    /// Rows of the im2col matrix (one per input channel and tap).
    fn taps(&self) -> usize {
        self.cin * self.k * self.k
    }

    /// Output positions per sample.
    fn outs(&self) -> usize {
        self.ho * self.wo
    }

    /// A 1×1 convolution of stride 1 without padding reads its input as
    /// the im2col matrix itself.
    fn is_pointwise(&self) -> bool {
        self.k == 1 && self.stride == 1 && self.pad == 0
    }

    /// The output columns `ox` whose input column `ox·stride + kx − pad`
    /// lies inside the image.
    fn inside(&self, kx: usize) -> std::ops::Range<usize> {
        let (s, p) = (self.stride, self.pad);
        let lo = p.saturating_sub(kx).div_ceil(s);
        // ox·s + kx − p ≤ w − 1  ⇔  ox ≤ (w − 1 + p − kx)/s
        let hi = if self.w + p > kx {
            ((self.w - 1 + p - kx) / s + 1).min(self.wo)
        } else {
            0
        };
        lo.min(hi)..hi
    }
}

/// Output rows per band: a band's im2col tile (`taps × rows·Wo` values)
/// stays within about 256 KB, so that it is still in the core's cache when
/// the product reads it (a whole sample's matrix, 2.4 MB for a 16-channel
/// 3×3 layer at 64², was not, and copying it in and out cost as much as
/// the product).
fn band_rows(g: &Geometry) -> usize {
    (BAND_TILE / (g.taps() * g.wo).max(1)).clamp(1, g.ho)
}

/// Values per band's im2col tile (256 KB of f32).
const BAND_TILE: usize = 64 * 1024;

/// The output rows of band `i`.
fn band(g: &Geometry, rows: usize, i: usize) -> Range<usize> {
    i * rows..((i + 1) * rows).min(g.ho)
}

/// One sample's `x [Cin, H, W]` → the im2col tile of the output rows `oy`:
/// `col [Cin·k·k, oy.len()·Wo]`, zeros where a tap falls in the padding.
fn im2col(g: &Geometry, x: &[f32], oy: Range<usize>, col: &mut [f32]) {
    let (k, s, n) = (g.k, g.stride, oy.len() * g.wo);
    for c in 0..g.cin {
        let plane = &x[c * g.h * g.w..][..g.h * g.w];
        for ky in 0..k {
            for kx in 0..k {
                let row = &mut col[((c * k + ky) * k + kx) * n..][..n];
                let cols = g.inside(kx);
                for (r, y) in oy.clone().enumerate() {
                    let dst = &mut row[r * g.wo..][..g.wo];
                    let iy = (y * s + ky) as isize - g.pad as isize;
                    if iy < 0 || iy >= g.h as isize || cols.is_empty() {
                        dst.fill(0.0);
                        continue;
                    }
                    let src = &plane[iy as usize * g.w..][..g.w];
                    dst[..cols.start].fill(0.0);
                    dst[cols.end..].fill(0.0);
                    let x0 = cols.start * s + kx - g.pad;
                    if s == 1 {
                        dst[cols.clone()].copy_from_slice(&src[x0..x0 + cols.len()]);
                    } else {
                        let taps = src[x0..].iter().step_by(s);
                        for (d, &v) in dst[cols.clone()].iter_mut().zip(taps) {
                            *d = v;
                        }
                    }
                }
            }
        }
    }
}

/// The adjoint of [`im2col`]: adds each tap of the tile `col` of the
/// output rows `oy` back onto the input position it was read from, into
/// `dx [Cin, H, W]`.
fn col2im(g: &Geometry, col: &[f32], oy: Range<usize>, dx: &mut [f32]) {
    let (k, s, n) = (g.k, g.stride, oy.len() * g.wo);
    for c in 0..g.cin {
        let plane = &mut dx[c * g.h * g.w..][..g.h * g.w];
        for ky in 0..k {
            for kx in 0..k {
                let row = &col[((c * k + ky) * k + kx) * n..][..n];
                let cols = g.inside(kx);
                if cols.is_empty() {
                    continue;
                }
                let x0 = cols.start * s + kx - g.pad;
                for (r, y) in oy.clone().enumerate() {
                    let iy = (y * s + ky) as isize - g.pad as isize;
                    if iy < 0 || iy >= g.h as isize {
                        continue;
                    }
                    let src = &row[r * g.wo..][..g.wo][cols.clone()];
                    let dst = &mut plane[iy as usize * g.w..][..g.w];
                    if s == 1 {
                        for (d, v) in dst[x0..x0 + src.len()].iter_mut().zip(src) {
                            *d += v;
                        }
                    } else {
                        for (d, v) in dst[x0..].iter_mut().step_by(s).zip(src) {
                            *d += v;
                        }
                    }
                }
            }
        }
    }
}

/// `dst (m × n) = lhs (m × k) · rhs (k × n)`, or `+=` with `add`.
fn gemm(dst: MatMut<'_, f32>, lhs: MatRef<'_, f32>, rhs: MatRef<'_, f32>, add: bool) {
    let accum = if add { Accum::Add } else { Accum::Replace };
    faer::linalg::matmul::matmul(dst, accum, lhs, rhs, 1.0f32, Par::Seq);
}

/// Samples per rayon task: the batch split once per thread, so that each
/// thread keeps one scratch tile and one weight-gradient accumulator.
fn per_task(batch: usize) -> usize {
    batch.div_ceil(rayon::current_num_threads().max(1)).max(1)
}

/// `acc += v`, element by element (a thread's weight-gradient sums into
/// another's).
fn add(acc: &mut [f32], v: &[f32]) {
    acc.iter_mut().zip(v).for_each(|(a, b)| *a += b);
}

/// The weight and bias gradients summed over the rayon tasks of a fold,
/// `(dW, db)` each; the folds' scratch buffers are dropped before this, so
/// the identity allocates only the two sums.
fn sum_grads<I>(tasks: I, dw_len: usize, cout: usize) -> (Vec<f32>, Vec<f32>)
where
    I: ParallelIterator<Item = (Vec<f32>, Vec<f32>)>,
{
    tasks.reduce(
        || (vec![0.0f32; dw_len], vec![0.0f32; cout]),
        |(mut dw, mut db), (dw2, db2)| {
            add(&mut dw, &dw2);
            add(&mut db, &db2);
            (dw, db)
        },
    )
}

/// `db[c] += Σ dy[c, ·]` for one sample's `dy [Cout, outs]`.
fn add_bias_grad(db: &mut [f32], dy: &[f32], outs: usize) {
    for (d, row) in db.iter_mut().zip(dy.chunks_exact(outs)) {
        *d += row.iter().sum::<f32>();
    }
}

/// The columns of the output rows `oy` in a `[C, Ho·Wo]` matrix.
fn columns<'a>(m: MatRef<'a, f32>, g: &Geometry, oy: &Range<usize>) -> MatRef<'a, f32> {
    m.subcols(oy.start * g.wo, oy.len() * g.wo)
}

/// `xp[a..a + n]` and `xp[b..b + m]`, two ranges that do not overlap, both
/// writable.
///
/// # Panics
/// If they overlap or either reaches past `xp`.
fn two_mut(xp: &mut [f32], a: usize, b: usize, n: usize, m: usize) -> (&mut [f32], &mut [f32]) {
    if a < b {
        assert!(a + n <= b, "two_mut: overlapping ranges");
        let (lo, hi) = xp.split_at_mut(b);
        (&mut lo[a..][..n], &mut hi[..m])
    } else {
        assert!(b + m <= a, "two_mut: overlapping ranges");
        let (lo, hi) = xp.split_at_mut(a);
        (&mut hi[..n], &mut lo[b..][..m])
    }
}

/// A convolution without im2col. With the input zero-padded into planes of
/// `Hp × Wp` and the output computed over `Ho × Wp` positions (the last
/// `Wp − Wo` of each row are discarded), tap `(ky, kx)` of a stride-1 layer
/// reads the padded input as one matrix `[Cin, Ho·Wp]` starting at
/// `ky·Wp + kx`: each layer is `k²` products of `[Cout, Cin]` weights with
/// views of the padded input, and nothing is copied per tap. The depth
/// encoder's twelve stride-1 3×3 layers are most of its work.
///
/// A layer of stride s reads the same way from its input split into s²
/// phases (phase `(ry, rx)` holds the padded positions `(s·i + ry, s·j +
/// rx)`, planes of `⌈Hp/s⌉ × ⌈Wp/s⌉`): tap `(ky, kx)` reads phase `(ky mod
/// s, kx mod s)` from `(ky div s, kx div s)` on, as a stride-1 tap (the
/// output computed over `Ho × wq` positions, the last `wq − Wo` of each row
/// discarded). The
/// split copies the input once, where im2col (and col2im, backwards) wrote
/// `k²/s²` times the input per pass.
#[derive(Clone, Copy, Debug)]
struct Shifted {
    /// Stride.
    s: usize,
    /// Row length of a phase plane (the padded row length for stride 1).
    wq: usize,
    /// Values per phase plane of a channel, with `⌈k/s⌉ − 1` zeros after it
    /// so that the last tap's view stays inside.
    plane: usize,
    /// Output positions computed per channel (`Ho·wq`).
    n: usize,
}

/// Strided layers with fewer input channels are not [`Shifted`]: a tap's
/// product would have an inner dimension of `Cin` (the RGB encoder's first
/// layer: 3, the depth encoder's: 1). They read the same split input as a
/// stacked matrix instead ([`Shifted::stacked`]).
const PHASED_MIN_CIN: usize = 8;

impl Shifted {
    /// The layer as k² products over views: stride 1 with a kernel larger
    /// than 1, or strided with at least [`PHASED_MIN_CIN`] input channels.
    fn of(g: &Geometry) -> Option<Self> {
        let s = g.stride;
        let usable = if s == 1 {
            g.k > 1
        } else {
            g.k >= s && g.cin >= PHASED_MIN_CIN
        };
        usable.then(|| Self::layout(g))
    }

    /// A strided layer with fewer than [`PHASED_MIN_CIN`] input channels:
    /// its im2col matrix is stacked from the split input's tap views, each
    /// row one contiguous copy (`im2col` gathers every s-th value and fills
    /// the padding row by row, 9 % of a training step in a profile).
    fn stacked(g: &Geometry) -> Option<Self> {
        (g.stride > 1 && g.k >= g.stride && g.cin < PHASED_MIN_CIN).then(|| Self::layout(g))
    }

    fn layout(g: &Geometry) -> Self {
        let s = g.stride;
        let (hp, wp) = (g.h + 2 * g.pad, g.w + 2 * g.pad);
        let wq = wp.div_ceil(s);
        Self {
            s,
            wq,
            plane: hp.div_ceil(s) * wq + g.k.div_ceil(s) - 1,
            n: g.ho * wq,
        }
    }

    /// Values of one sample's split input: s² phases of `Cin` planes.
    fn len(&self, g: &Geometry) -> usize {
        self.s * self.s * g.cin * self.plane
    }

    /// Where tap `t` (`ky·k + kx`) starts in the split input.
    fn offset(&self, g: &Geometry, t: usize) -> usize {
        let (ky, kx, s) = (t / g.k, t % g.k, self.s);
        ((ky % s) * s + kx % s) * g.cin * self.plane + (ky / s) * self.wq + kx / s
    }

    /// Where input position `(c, iy, ix)` lies in the split input.
    fn at(&self, g: &Geometry, c: usize, iy: usize, ix: usize) -> usize {
        let (py, px, s) = (iy + g.pad, ix + g.pad, self.s);
        ((py % s) * s + px % s) * g.cin * self.plane + c * self.plane + (py / s) * self.wq + px / s
    }

    /// One sample's `x [Cin, H, W]` into its zero-padded phases. Writes
    /// the image positions only: `xp` must be zero elsewhere, as a buffer
    /// allocated zeroed that only this writes stays (every caller's, one
    /// per rayon task, reused sample after sample of one layer call).
    /// Zeroing it whole per sample took about 1 % of a training step (a
    /// profile).
    fn pad(&self, g: &Geometry, x: &[f32], xp: &mut [f32]) {
        for c in 0..g.cin {
            for iy in 0..g.h {
                let src = &x[(c * g.h + iy) * g.w..][..g.w];
                if self.s == 2 && g.w > 1 {
                    // The two phases' columns of the row at once: a
                    // deinterleave the compiler vectorises, where the loop
                    // below stores one value at a time (3.5 % of a step).
                    let (a0, a1) = (self.at(g, c, iy, 0), self.at(g, c, iy, 1));
                    let (even, odd) = two_mut(xp, a0, a1, g.w.div_ceil(2), g.w / 2);
                    for ((e, o), pair) in
                        even.iter_mut().zip(odd.iter_mut()).zip(src.chunks_exact(2))
                    {
                        *e = pair[0];
                        *o = pair[1];
                    }
                    if g.w % 2 == 1 {
                        even[g.w / 2] = src[g.w - 1];
                    }
                    continue;
                }
                // The row's columns of each phase, every s-th from `ix0`, lie
                // side by side in that phase's plane.
                for ix0 in 0..self.s.min(g.w) {
                    let at = self.at(g, c, iy, ix0);
                    let dst = &mut xp[at..];
                    if self.s == 1 {
                        dst[..g.w].copy_from_slice(src);
                    } else {
                        for (d, &v) in dst.iter_mut().zip(src[ix0..].iter().step_by(self.s)) {
                            *d = v;
                        }
                    }
                }
            }
        }
    }

    /// The adjoint of [`Shifted::pad`]: the image positions of `xp` into
    /// `dx [Cin, H, W]` (the padding's dropped).
    fn unpad(&self, g: &Geometry, xp: &[f32], dx: &mut [f32]) {
        for c in 0..g.cin {
            for iy in 0..g.h {
                let dst = &mut dx[(c * g.h + iy) * g.w..][..g.w];
                for ix0 in 0..self.s.min(g.w) {
                    let src = &xp[self.at(g, c, iy, ix0)..];
                    for (d, &v) in dst[ix0..].iter_mut().step_by(self.s).zip(src) {
                        *d = v;
                    }
                }
            }
        }
    }

    /// Each tap's [`Shifted::offset`], for [`Shifted::views`].
    fn tap_offsets(&self, g: &Geometry) -> Vec<usize> {
        (0..g.k * g.k).map(|t| self.offset(g, t)).collect()
    }

    /// The split input as [`conv_direct`]'s kernels read it, the taps at
    /// `offsets` (from [`Shifted::tap_offsets`]).
    fn views<'a>(&self, offsets: &'a [usize]) -> conv_direct::Views<'a> {
        conv_direct::Views {
            plane: self.plane,
            wq: self.wq,
            taps: offsets,
        }
    }

    /// The split input seen from tap `t`: `[Cin, Ho·wq]`.
    fn view<'a>(&self, g: &Geometry, xp: &'a [f32], t: usize) -> MatRef<'a, f32> {
        let off = self.offset(g, t);
        MatRef::from_row_major_slice_with_stride(&xp[off..], g.cin, self.n, self.plane)
    }

    /// The same view, writable. Built column-major and transposed: faer
    /// 0.24.4's `from_row_major_slice_with_stride_mut` gives its view the
    /// two strides swapped (row stride 1, column stride the row stride), so
    /// a product into it writes outside the view (a heap corruption,
    /// measured here); its column-major constructor is right.
    fn view_mut<'a>(&self, g: &Geometry, xp: &'a mut [f32], t: usize) -> MatMut<'a, f32> {
        let off = self.offset(g, t);
        MatMut::from_column_major_slice_with_stride_mut(&mut xp[off..], self.n, g.cin, self.plane)
            .transpose_mut()
    }
}

/// `weight [Cout, Cin, k, k]` → tap-major `[k·k][Cout, Cin]`, written in
/// order (a scattered write per value took 1.5 % of a training step in a
/// profile).
fn taps_major(g: &Geometry, w: &[f32]) -> Vec<f32> {
    let (kk, n) = (g.k * g.k, g.cout * g.cin);
    let mut out = Vec::with_capacity(w.len());
    for t in 0..kk {
        out.extend(w[t..].iter().step_by(kk).take(n));
    }
    out
}

/// The adjoint of [`taps_major`]: `[k·k][Cout, Cin]` → `[Cout, Cin, k, k]`.
fn taps_minor(g: &Geometry, wt: &[f32]) -> Vec<f32> {
    let (kk, n) = (g.k * g.k, g.cout * g.cin);
    let mut out = Vec::with_capacity(wt.len());
    for oc in 0..n {
        out.extend(wt[oc..].iter().step_by(n).take(kk));
    }
    out
}

/// Tap `t`'s `[Cout, Cin]` block of [`taps_major`]'s layout.
fn tap<'a>(g: &Geometry, wt: &'a [f32], t: usize) -> MatRef<'a, f32> {
    MatRef::from_row_major_slice(&wt[t * g.cout * g.cin..][..g.cout * g.cin], g.cout, g.cin)
}

/// Which kernel [`forward_shifted`] applies, given by a layer's own
/// `[Cout, Cin, k, k]` weights (packed for [`conv_direct`] straight from
/// them; put in [`taps_major`]'s layout only for faer's products).
#[derive(Clone, Copy)]
enum Kernel<'a> {
    /// The layer's own.
    Own(&'a [f32]),
    /// The kernel flipped with its input and output channels swapped, of
    /// the layer whose weights these are (the stride-1 input gradient,
    /// [`x_backward_shifted`]): tap `t` is that layer's tap `k² − 1 − t`,
    /// transposed.
    Flipped(&'a [f32]),
}

impl Kernel<'_> {
    /// The weights as given.
    fn weights(&self) -> &[f32] {
        match *self {
            Kernel::Own(w) | Kernel::Flipped(w) => w,
        }
    }

    /// Tap `t`'s weight from input channel `ci` to output channel `co` of
    /// the convolution `g` applies.
    fn at(&self, g: &Geometry, t: usize, co: usize, ci: usize) -> f32 {
        let kk = g.k * g.k;
        match *self {
            Kernel::Own(w) => w[(co * g.cin + ci) * kk + t],
            Kernel::Flipped(w) => w[(ci * g.cout + co) * kk + kk - 1 - t],
        }
    }

    /// Tap `t`'s `[Cout, Cin]` matrix for the convolution `g` applies, from
    /// `wt`, [`taps_major`] of [`Kernel::weights`].
    fn tap<'b>(&self, g: &Geometry, wt: &'b [f32], t: usize) -> MatRef<'b, f32> {
        match *self {
            Kernel::Own(_) => tap(g, wt, t),
            Kernel::Flipped(_) => {
                let n = g.cout * g.cin;
                let at = (g.k * g.k - 1 - t) * n;
                MatRef::from_column_major_slice(&wt[at..][..n], g.cout, g.cin)
            }
        }
    }
}

/// [`forward`] for a [`Shifted`] convolution.
fn forward_shifted(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    kernel: Kernel<'_>,
    b: &[f32],
    y: &mut [MaybeUninit<f32>],
) {
    let outs = g.outs();
    let kk = g.k * g.k;
    let direct = direct(g);
    let packed =
        direct.then(|| conv_direct::pack(g.cout, g.cin, kk, |t, co, ci| kernel.at(g, t, co, ci)));
    // (Both layouts hold Cout·Cin per tap, so the flipped layer's is built
    // with `g`'s shape too.)
    let wt = (!direct).then(|| taps_major(g, kernel.weights()));
    let offsets = sh.tap_offsets(g);
    let views = sh.views(&offsets);
    y.par_chunks_mut(g.cout * outs)
        .zip(x.par_chunks(g.cin * g.h * g.w))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            || {
                let n = if direct { 0 } else { g.cout * sh.n };
                (vec![0.0f32; sh.len(g)], vec![0.0f32; n])
            },
            |(xp, yp), (ys, xs)| {
                sh.pad(g, xs, xp);
                if let Some(packed) = &packed {
                    // It writes every value: no zeroing.
                    conv_direct::forward(xp, views, g.cin, packed, b, g.ho, g.wo, ys);
                    return;
                }
                let ys = zeroed(ys);
                let wt = wt.as_deref().expect("the products' taps-major weights");
                let mut ypm = MatMut::from_row_major_slice_mut(yp, g.cout, sh.n);
                for t in 0..g.k * g.k {
                    gemm(ypm.as_mut(), kernel.tap(g, wt, t), sh.view(g, xp, t), t > 0);
                }
                unspread_rows(g, sh, yp, 0..g.ho, b, ys);
            },
        );
}

/// The output rows `oy` of `yp [Cout, oy.len()·wq]` (the product over the
/// split input, with each row's discarded positions) into `y [Cout, Ho·Wo]`,
/// plus the bias.
fn unspread_rows(
    g: &Geometry,
    sh: Shifted,
    yp: &[f32],
    oy: Range<usize>,
    b: &[f32],
    y: &mut [f32],
) {
    let n = oy.len() * sh.wq;
    for ((row, src), &bias) in y.chunks_exact_mut(g.outs()).zip(yp.chunks_exact(n)).zip(b) {
        for (r, y) in oy.clone().enumerate() {
            let (d, s) = (&mut row[y * g.wo..][..g.wo], &src[r * sh.wq..][..g.wo]);
            for (d, s) in d.iter_mut().zip(s) {
                *d = s + bias;
            }
        }
    }
}

/// Output rows per band of a [`Shifted::stacked`] layer, its stacked tile
/// kept within [`band_rows`]'s size.
fn stacked_rows(g: &Geometry, sh: Shifted) -> usize {
    (BAND_TILE / (g.taps() * sh.wq).max(1)).clamp(1, g.ho)
}

/// The stacked im2col tile of the output rows `oy` from the split input
/// `xp`: `col [Cin·k·k, oy.len()·wq]`, row `(c, tap)` the tap's view of
/// channel `c`, one contiguous copy (the padding is in `xp`).
fn stack_band(g: &Geometry, sh: Shifted, xp: &[f32], oy: &Range<usize>, col: &mut [f32]) {
    let (kk, n) = (g.k * g.k, oy.len() * sh.wq);
    for (r, row) in col.chunks_exact_mut(n).enumerate() {
        let (c, t) = (r / kk, r % kk);
        let at = sh.offset(g, t) + c * sh.plane + oy.start * sh.wq;
        row.copy_from_slice(&xp[at..at + n]);
    }
}

/// [`forward`] for a [`Shifted::stacked`] layer: per band, one product of
/// the `[Cout, Cin·k·k]` weights with the stacked tile.
fn forward_stacked(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    y: &mut [MaybeUninit<f32>],
) {
    let (taps, rows) = (g.taps(), stacked_rows(g, sh));
    let wm = MatRef::from_row_major_slice(w, g.cout, taps);
    y.par_chunks_mut(g.cout * g.outs())
        .zip(x.par_chunks(g.cin * g.h * g.w))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            || {
                let tile = rows * sh.wq;
                (
                    vec![0.0f32; sh.len(g)],
                    vec![0.0f32; taps * tile],
                    vec![0.0f32; g.cout * tile],
                )
            },
            |(xp, col, yb), (ys, xs)| {
                let ys = zeroed(ys);
                sh.pad(g, xs, xp);
                for i in 0..g.ho.div_ceil(rows) {
                    let oy = band(g, rows, i);
                    let n = oy.len() * sh.wq;
                    stack_band(g, sh, xp, &oy, &mut col[..taps * n]);
                    gemm(
                        MatMut::from_row_major_slice_mut(&mut yb[..g.cout * n], g.cout, n),
                        wm,
                        MatRef::from_row_major_slice(&col[..taps * n], taps, n),
                        false,
                    );
                    unspread_rows(g, sh, &yb[..g.cout * n], oy, b, ys);
                }
            },
        );
}

/// [`wb_backward`] for a [`Shifted::stacked`] layer: per band,
/// `dW += dy · colᵀ` with the stacked tile.
fn wb_backward_stacked(g: &Geometry, sh: Shifted, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (taps, outs, rows) = (g.taps(), g.outs(), stacked_rows(g, sh));
    let zero = || {
        (
            vec![0.0f32; sh.len(g)],
            vec![0.0f32; taps * rows * sh.wq],
            vec![0.0f32; g.cout * sh.n],
            vec![0.0f32; g.cout * taps],
            vec![0.0f32; g.cout],
        )
    };
    let folds = x
        .par_chunks(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .fold(
            zero,
            |(mut xp, mut col, mut dyp, mut dw, mut db), (xs, dys)| {
                sh.pad(g, xs, &mut xp);
                spread(g, sh, dys, &mut dyp);
                let dym = MatRef::from_row_major_slice(&dyp, g.cout, sh.n);
                for i in 0..g.ho.div_ceil(rows) {
                    let oy = band(g, rows, i);
                    let n = oy.len() * sh.wq;
                    stack_band(g, sh, &xp, &oy, &mut col[..taps * n]);
                    let colm = MatRef::from_row_major_slice(&col[..taps * n], taps, n);
                    let dwm = MatMut::from_row_major_slice_mut(&mut dw, g.cout, taps);
                    gemm(
                        dwm,
                        dym.subcols(oy.start * sh.wq, n),
                        colm.transpose(),
                        true,
                    );
                }
                add_bias_grad(&mut db, dys, outs);
                (xp, col, dyp, dw, db)
            },
        )
        .map(|(_, _, _, dw, db)| (dw, db));
    sum_grads(folds, g.cout * taps, g.cout)
}

/// One sample's `dy [Cout, Ho·Wo]` spread into `[Cout, Ho·wq]` with zeros
/// at the discarded positions, so that they add nothing.
fn spread(g: &Geometry, sh: Shifted, dy: &[f32], dyp: &mut [f32]) {
    dyp.fill(0.0);
    for (co, row) in dy.chunks_exact(g.outs()).enumerate() {
        for oy in 0..g.ho {
            dyp[co * sh.n + oy * sh.wq..][..g.wo].copy_from_slice(&row[oy * g.wo..][..g.wo]);
        }
    }
}

/// [`x_backward`] for a stride-1 convolution: the input gradient is itself
/// a stride-1 convolution of `dy`, padded by `k − 1 − pad`, with the kernel
/// flipped and its channels swapped, so it takes [`forward_shifted`], whose
/// products (or [`conv_direct`]'s kernel) only read strided views; the
/// gradient is written once, not accumulated tap by tap as strided layers
/// do into writable views ([`x_backward_phased`]).
fn x_backward_shifted(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    let k = g.k;
    let gt = Geometry::new(
        &[g.batch, g.cout, g.ho, g.wo],
        &[g.cin, g.cout, k, k],
        1,
        k - 1 - g.pad,
    );
    debug_assert_eq!((gt.ho, gt.wo), (g.h, g.w));
    let sh = Shifted::of(&gt).expect("stride 1");
    forward_shifted(&gt, sh, dy, Kernel::Flipped(w), &vec![0.0; g.cin], dx);
}

/// [`x_backward`] for a strided [`Shifted`] convolution: tap by tap, the
/// transposed product `W_tᵀ·dy` added into the tap's view of the split
/// input's gradient, which is then gathered back without its padding. (The
/// discarded output positions of `dy` are zeros and add nothing.)
fn x_backward_phased(
    g: &Geometry,
    sh: Shifted,
    w: &[f32],
    dy: &[f32],
    dx: &mut [MaybeUninit<f32>],
) {
    let wt = taps_major(g, w);
    let outs = g.outs();
    dx.par_chunks_mut(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            || (vec![0.0f32; sh.len(g)], vec![0.0f32; g.cout * sh.n]),
            |(xp, dyp), (dxs, dys)| {
                let dxs = zeroed(dxs);
                spread(g, sh, dys, dyp);
                xp.fill(0.0);
                let dym = MatRef::from_row_major_slice(dyp, g.cout, sh.n);
                for t in 0..g.k * g.k {
                    gemm(sh.view_mut(g, xp, t), tap(g, &wt, t).transpose(), dym, true);
                }
                sh.unpad(g, xp, dxs);
            },
        );
}

/// One phase of a strided layer's input gradient ([`x_backward_split`]):
/// the input positions `(qy·s + a − pad, qx·s + b − pad)` for `qy` in `qy`
/// and `qx` in `qx`, and the taps `(ky, kx) = (a + s·i, b + s·j)` that
/// reach them, as `(i, j)`.
struct Phase {
    a: usize,
    b: usize,
    qy: Range<usize>,
    qx: Range<usize>,
    taps: Vec<(usize, usize)>,
}

impl Phase {
    /// The `s²` phases of `g`'s input.
    fn all(g: &Geometry) -> Vec<Phase> {
        let s = g.stride;
        // q with q·s + a − pad inside 0..n.
        let along = |a: usize, n: usize| {
            let lo = g.pad.saturating_sub(a).div_ceil(s);
            let hi = (n + g.pad).saturating_sub(a).div_ceil(s);
            lo..hi.max(lo)
        };
        let taps = |a: usize| (g.k.saturating_sub(a)).div_ceil(s);
        let mut out = Vec::with_capacity(s * s);
        for a in 0..s {
            for b in 0..s {
                out.push(Phase {
                    a,
                    b,
                    qy: along(a, g.h),
                    qx: along(b, g.w),
                    taps: (0..taps(a))
                        .flat_map(|i| (0..taps(b)).map(move |j| (i, j)))
                        .collect(),
                });
            }
        }
        out
    }
}

/// Whether a strided layer's input gradient takes [`x_backward_split`]:
/// [`conv_direct::forward`] covers each phase (the layer's `Cin` a multiple
/// of 4, each phase's rows of input positions a multiple of 16 wide).
fn split_direct(g: &Geometry) -> bool {
    !products_only()
        && g.stride > 1
        && g.k >= g.stride
        && Phase::all(g)
            .iter()
            .all(|ph| conv_direct::covers(g.cin, ph.qx.len()))
}

/// [`x_backward`] for a strided layer as `s²` stride-1 convolutions of
/// `dy`, one per phase of the input (every s-th row and column from `(a,
/// b)`), each by the taps that reach that phase, flipped, with the
/// channels swapped: [`conv_direct::forward`] adds every tap into
/// registers and writes each input position's gradient once, where
/// [`x_backward_phased`]'s products added `k²` transposed products into
/// views of the whole split input.
///
/// Phase `(a, b)`'s gradient at `(qy, qx)` is `Σ_(i, j) Σ_co W[co, ci, a +
/// s·i, b + s·j] · dy[co, qy − i, qx − j]` (zero outside `dy`); `dy` is
/// read from a copy with `m = ⌈k/s⌉ − 1` rows and columns of zeros before
/// it, so that tap `(i, j)` reads it from `(qy + m − i, qx + m − j)`.
fn x_backward_split(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    let (s, k) = (g.stride, g.k);
    let m = k.div_ceil(s) - 1;
    let phases = Phase::all(g);
    // The phases are disjoint (each a residue class of rows and columns
    // mod s): covering h·w positions between them, they write every one
    // of dx's, which comes uninitialised.
    assert_eq!(
        phases
            .iter()
            .map(|p| p.qy.len() * p.qx.len())
            .sum::<usize>(),
        g.h * g.w,
        "x_backward_split: the phases do not cover the input"
    );
    let qy_end = phases.iter().map(|p| p.qy.end).max().unwrap_or(0);
    let qx_end = phases.iter().map(|p| p.qx.end).max().unwrap_or(0);
    // Wide and high enough that no read leaves its row or its channel.
    let wq = (qx_end.max(g.wo) + m).max(1);
    let plane = (qy_end.max(g.ho) + m) * wq;
    let packed: Vec<Vec<f32>> = phases
        .iter()
        .map(|ph| {
            conv_direct::pack(g.cin, g.cout, ph.taps.len(), |t, ci, co| {
                let (i, j) = ph.taps[t];
                w[((co * g.cin + ci) * k + ph.a + s * i) * k + ph.b + s * j]
            })
        })
        .collect();
    let offsets: Vec<Vec<usize>> = phases
        .iter()
        .map(|ph| {
            ph.taps
                .iter()
                .map(|&(i, j)| (ph.qy.start + m - i) * wq + ph.qx.start + m - j)
                .collect()
        })
        .collect();
    let largest = phases
        .iter()
        .map(|p| p.qy.len() * p.qx.len())
        .max()
        .unwrap_or(0);
    let zero = vec![0.0f32; g.cin];
    let (outs, image) = (g.outs(), g.h * g.w);
    dx.par_chunks_mut(g.cin * image)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            // The margins are zeros from here on: only `dy`'s positions are
            // written, sample after sample.
            || (vec![0.0f32; g.cout * plane], vec![0.0f32; g.cin * largest]),
            |(dyp, part), (dxs, dys)| {
                for (co, src) in dys.chunks_exact(outs).enumerate() {
                    for (oy, row) in src.chunks_exact(g.wo).enumerate() {
                        dyp[co * plane + (oy + m) * wq + m..][..g.wo].copy_from_slice(row);
                    }
                }
                for ((ph, packed), offsets) in phases.iter().zip(&packed).zip(&offsets) {
                    let (ny, nx) = (ph.qy.len(), ph.qx.len());
                    if ny == 0 || nx == 0 {
                        continue;
                    }
                    let views = conv_direct::Views {
                        plane,
                        wq,
                        taps: offsets,
                    };
                    let part = &mut part[..g.cin * ny * nx];
                    // SAFETY: the kernel writes only values, never
                    // uninitialised ones, through the view.
                    let out = unsafe { as_uninit(part) };
                    conv_direct::forward(dyp, views, g.cout, packed, &zero, ny, nx, out);
                    // Into every s-th row and column of dx from the phase's
                    // first input position.
                    let (iy0, ix0) = (
                        ph.qy.start * s + ph.a - g.pad,
                        ph.qx.start * s + ph.b - g.pad,
                    );
                    for (ci, src) in part.chunks_exact(ny * nx).enumerate() {
                        let dst = &mut dxs[ci * image..][..image];
                        for (r, row) in src.chunks_exact(nx).enumerate() {
                            let to = &mut dst[(iy0 + r * s) * g.w + ix0..];
                            for (d, &v) in to.iter_mut().step_by(s).zip(row) {
                                d.write(v);
                            }
                        }
                    }
                }
            },
        );
}

/// [`wb_backward`] for a [`Shifted`] convolution.
fn wb_backward_shifted(g: &Geometry, sh: Shifted, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (kk, outs) = (g.k * g.k, g.outs());
    let zero = || {
        (
            vec![0.0f32; sh.len(g)],
            vec![0.0f32; g.cout * sh.n],
            vec![0.0f32; g.cout * g.cin * kk],
            vec![0.0f32; g.cout],
        )
    };
    let folds = x
        .par_chunks(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .fold(zero, |(mut xp, mut dyp, mut dwt, mut db), (xs, dys)| {
            sh.pad(g, xs, &mut xp);
            spread(g, sh, dys, &mut dyp);
            let dym = MatRef::from_row_major_slice(&dyp, g.cout, sh.n);
            for t in 0..kk {
                let dst = MatMut::from_row_major_slice_mut(
                    &mut dwt[t * g.cout * g.cin..][..g.cout * g.cin],
                    g.cout,
                    g.cin,
                );
                gemm(dst, dym, sh.view(g, &xp, t).transpose(), true);
            }
            add_bias_grad(&mut db, dys, outs);
            (xp, dyp, dwt, db)
        })
        .map(|(_, _, dwt, db)| (dwt, db));
    let (dwt, db) = sum_grads(folds, g.cout * g.cin * kk, g.cout);
    (taps_minor(g, &dwt), db)
}

/// [`wb_backward`] for a [`Shifted`] or [`Shifted::stacked`] layer through
/// [`conv_direct::weight_grad`]: per sample, straight into the layer's own
/// `[Cout, Cin, k, k]` layout from its padded input and its output gradient
/// as it comes.
fn wb_backward_direct(g: &Geometry, sh: Shifted, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (kk, outs) = (g.k * g.k, g.outs());
    let offsets = sh.tap_offsets(g);
    let views = sh.views(&offsets);
    let zero = || {
        (
            vec![0.0f32; sh.len(g)],
            vec![0.0f32; g.cout * g.cin * kk],
            vec![0.0f32; g.cout],
        )
    };
    let folds = x
        .par_chunks(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .fold(zero, |(mut xp, mut dw, mut db), (xs, dys)| {
            sh.pad(g, xs, &mut xp);
            conv_direct::weight_grad(&xp, views, g.cin, dys, g.ho, g.wo, &mut dw);
            add_bias_grad(&mut db, dys, outs);
            (xp, dw, db)
        })
        .map(|(_, dw, db)| (dw, db));
    sum_grads(folds, g.cout * g.cin * kk, g.cout)
}

/// The forward pass on contiguous f32 arrays.
fn forward(g: &Geometry, x: &[f32], w: &[f32], b: &[f32], y: &mut [MaybeUninit<f32>]) {
    // Every pass pairs output and input samples with rayon's `zip`, which
    // stops at the shorter: a short input would leave outputs unwritten
    // (`written` relies on all being written).
    assert!(
        x.len() == g.batch * g.cin * g.h * g.w
            && y.len() == g.batch * g.cout * g.outs()
            && w.len() == g.cout * g.taps()
            && b.len() == g.cout,
        "conv2d: the input, weight, bias or output does not match the layer's shape"
    );
    // A stacked layer the kernel covers reads its views tap by tap too.
    let by_taps = Shifted::of(g).or_else(|| Shifted::stacked(g).filter(|_| direct(g)));
    if grouped(g) {
        forward_grouped(g, x, w, b, y)
    } else if let Some(sh) = by_taps {
        forward_shifted(g, sh, x, Kernel::Own(w), b, y)
    } else if let Some(sh) = Shifted::stacked(g) {
        forward_stacked(g, sh, x, w, b, y)
    } else {
        forward_banded(g, x, w, b, y)
    }
}

/// [`forward`] through im2col in row bands (or none, for a 1×1).
fn forward_banded(g: &Geometry, x: &[f32], w: &[f32], b: &[f32], y: &mut [MaybeUninit<f32>]) {
    let (taps, outs, rows) = (g.taps(), g.outs(), band_rows(g));
    let wm = MatRef::from_row_major_slice(w, g.cout, taps);
    y.par_chunks_mut(g.cout * outs)
        .zip(x.par_chunks(g.cin * g.h * g.w))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            || vec![0.0f32; taps * rows * g.wo],
            |col, (ys, xs)| {
                let ys = zeroed(ys);
                let mut ym = MatMut::from_row_major_slice_mut(ys, g.cout, outs);
                if g.is_pointwise() {
                    gemm(ym, wm, MatRef::from_row_major_slice(xs, taps, outs), false);
                } else {
                    for i in 0..g.ho.div_ceil(rows) {
                        let oy = band(g, rows, i);
                        let n = oy.len() * g.wo;
                        im2col(g, xs, oy.clone(), &mut col[..taps * n]);
                        gemm(
                            ym.as_mut().subcols_mut(oy.start * g.wo, n),
                            wm,
                            MatRef::from_row_major_slice(&col[..taps * n], taps, n),
                            false,
                        );
                    }
                }
                for (row, &bias) in ys.chunks_exact_mut(outs).zip(b) {
                    row.iter_mut().for_each(|v| *v += bias);
                }
            },
        );
}

/// The input gradient on contiguous f32 arrays.
fn x_backward(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    // As in [`forward`]: a short `dy` would leave `dx` partly unwritten.
    assert!(
        dy.len() == g.batch * g.cout * g.outs()
            && dx.len() == g.batch * g.cin * g.h * g.w
            && w.len() == g.cout * g.taps(),
        "conv2d input gradient: the output gradient or weight does not match the layer's shape"
    );
    match Shifted::of(g) {
        _ if grouped(g) => x_backward_grouped(g, w, dy, dx),
        Some(_) if g.stride == 1 && g.pad < g.k => x_backward_shifted(g, w, dy, dx),
        Some(_) if g.stride > 1 && split_direct(g) => x_backward_split(g, w, dy, dx),
        Some(sh) if g.stride > 1 => x_backward_phased(g, sh, w, dy, dx),
        _ => x_backward_banded(g, w, dy, dx),
    }
}

/// [`x_backward`] through col2im in row bands (or none, for a 1×1).
fn x_backward_banded(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    let (taps, outs, rows) = (g.taps(), g.outs(), band_rows(g));
    let wt = MatRef::from_row_major_slice(w, g.cout, taps).transpose();
    dx.par_chunks_mut(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .for_each_init(
            || vec![0.0f32; taps * rows * g.wo],
            |col, (dxs, dys)| {
                let dxs = zeroed(dxs);
                let dym = MatRef::from_row_major_slice(dys, g.cout, outs);
                if g.is_pointwise() {
                    let dxm = MatMut::from_row_major_slice_mut(dxs, taps, outs);
                    gemm(dxm, wt, dym, false);
                    return;
                }
                for i in 0..g.ho.div_ceil(rows) {
                    let oy = band(g, rows, i);
                    let n = oy.len() * g.wo;
                    let colm = MatMut::from_row_major_slice_mut(&mut col[..taps * n], taps, n);
                    gemm(colm, wt, columns(dym, g, &oy), false);
                    col2im(g, &col[..taps * n], oy, dxs);
                }
            },
        );
}

/// The weight and bias gradients on contiguous f32 arrays.
fn wb_backward(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let views = Shifted::of(g).or_else(|| Shifted::stacked(g));
    if grouped(g) {
        wb_backward_grouped(g, x, dy)
    } else if let Some(sh) = views.filter(|_| direct_weight_grad(g)) {
        wb_backward_direct(g, sh, x, dy)
    } else if let Some(sh) = Shifted::of(g) {
        wb_backward_shifted(g, sh, x, dy)
    } else if let Some(sh) = Shifted::stacked(g) {
        wb_backward_stacked(g, sh, x, dy)
    } else {
        wb_backward_banded(g, x, dy)
    }
}

/// [`wb_backward`] through im2col in row bands (or none, for a 1×1).
fn wb_backward_banded(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (taps, outs, rows) = (g.taps(), g.outs(), band_rows(g));
    let zero = || {
        (
            vec![0.0f32; taps * rows * g.wo],
            vec![0.0f32; g.cout * taps],
            vec![0.0f32; g.cout],
        )
    };
    let folds = x
        .par_chunks(g.cin * g.h * g.w)
        .zip(dy.par_chunks(g.cout * outs))
        .with_min_len(per_task(g.batch))
        .fold(zero, |(mut col, mut dw, mut db), (xs, dys)| {
            let dym = MatRef::from_row_major_slice(dys, g.cout, outs);
            if g.is_pointwise() {
                let xm = MatRef::from_row_major_slice(xs, taps, outs);
                let dwm = MatMut::from_row_major_slice_mut(&mut dw, g.cout, taps);
                gemm(dwm, dym, xm.transpose(), true);
            } else {
                for i in 0..g.ho.div_ceil(rows) {
                    let oy = band(g, rows, i);
                    let n = oy.len() * g.wo;
                    im2col(g, xs, oy.clone(), &mut col[..taps * n]);
                    let colm = MatRef::from_row_major_slice(&col[..taps * n], taps, n);
                    let dwm = MatMut::from_row_major_slice_mut(&mut dw, g.cout, taps);
                    gemm(dwm, columns(dym, g, &oy), colm.transpose(), true);
                }
            }
            add_bias_grad(&mut db, dys, outs);
            (col, dw, db)
        })
        .map(|(_, dw, db)| (dw, db));
    sum_grads(folds, g.cout * taps, g.cout)
}

/// Output maps of at most this many positions (the encoders' 4² and 2²
/// outputs, the flow decoder's first two up-convolutions, the
/// Reconstruction Model decoder's first layer) run each pass as
/// one product over a group of samples. Per sample a tap's product has
/// only 6–24 columns, where faer ran at 9–36 GFLOP/s and PyTorch's layers
/// of these shapes about twice as fast as ours. The 8² maps (64 positions)
/// measured slower grouped (docs/performance.md).
const GROUPED_OUTS: usize = 16;

/// Values of a group's im2col matrix at most (1 MB of f32), unless a single
/// sample's is larger.
const GROUP_TILE: usize = 256 * 1024;

/// Whether `g` runs through the grouped passes ([`forward_grouped`]).
fn grouped(g: &Geometry) -> bool {
    !g.is_pointwise() && g.outs() <= grouped_outs()
}

/// [`GROUPED_OUTS`], or `LEARNER_CONV_GROUPED_OUTS` where set (0: no layer
/// grouped; the A/B switch of the benchmarks).
fn grouped_outs() -> usize {
    static OUTS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *OUTS.get_or_init(|| {
        std::env::var("LEARNER_CONV_GROUPED_OUTS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(GROUPED_OUTS)
    })
}

/// `(samples per group, groups per rayon task)`: each thread's share of the
/// batch ([`per_task`]) cut into equal groups whose im2col matrix stays
/// within [`GROUP_TILE`].
fn group(g: &Geometry) -> (usize, usize) {
    let task = per_task(g.batch);
    let cap = (GROUP_TILE / (g.taps() * g.outs()).max(1)).max(1);
    let groups = task.div_ceil(cap);
    (task.div_ceil(groups), groups)
}

/// For each tap `t` and output position `o` of one sample, the input
/// position (`iy·W + ix`) that tap reads there, or `usize::MAX` in the
/// padding: `[k·k][Ho·Wo]`. A map of a few positions per row made
/// [`im2col`]'s row-by-row copies cost as much as the product.
fn tap_table(g: &Geometry) -> Vec<usize> {
    let mut table = Vec::with_capacity(g.k * g.k * g.outs());
    for ky in 0..g.k {
        for kx in 0..g.k {
            for oy in 0..g.ho {
                for ox in 0..g.wo {
                    let iy = (oy * g.stride + ky).checked_sub(g.pad).filter(|&v| v < g.h);
                    let ix = (ox * g.stride + kx).checked_sub(g.pad).filter(|&v| v < g.w);
                    table.push(match (iy, ix) {
                        (Some(iy), Some(ix)) => iy * g.w + ix,
                        _ => usize::MAX,
                    });
                }
            }
        }
    }
    table
}

/// One group's samples `xs [m][Cin, H, W]` → its im2col matrix `col [Cin·k·k,
/// m·Ho·Wo]`, sample after sample along the columns; returns `m·Ho·Wo`.
fn im2col_group(g: &Geometry, table: &[usize], xs: &[f32], col: &mut [f32]) -> usize {
    let (hw, outs, kk) = (g.h * g.w, g.outs(), g.k * g.k);
    let n = xs.len() / (g.cin * hw) * outs;
    for (j, xj) in xs.chunks_exact(g.cin * hw).enumerate() {
        for (c, plane) in xj.chunks_exact(hw).enumerate() {
            for (t, idx) in table.chunks_exact(outs).enumerate() {
                let row = &mut col[(c * kk + t) * n + j * outs..][..outs];
                for (d, &i) in row.iter_mut().zip(idx) {
                    *d = plane.get(i).copied().unwrap_or(0.0);
                }
            }
        }
    }
    n
}

/// The adjoint of [`im2col_group`]: adds `dcol [Cin·k·k, m·Ho·Wo]` onto
/// `dxs [m][Cin, H, W]`.
fn col2im_group(g: &Geometry, table: &[usize], dcol: &[f32], dxs: &mut [f32]) {
    let (hw, outs, kk) = (g.h * g.w, g.outs(), g.k * g.k);
    let n = dxs.len() / (g.cin * hw) * outs;
    for (j, dxj) in dxs.chunks_exact_mut(g.cin * hw).enumerate() {
        for (c, plane) in dxj.chunks_exact_mut(hw).enumerate() {
            for (t, idx) in table.chunks_exact(outs).enumerate() {
                let row = &dcol[(c * kk + t) * n + j * outs..][..outs];
                for (&v, &i) in row.iter().zip(idx) {
                    if let Some(d) = plane.get_mut(i) {
                        *d += v;
                    }
                }
            }
        }
    }
}

/// One group's output gradients `dys [m][Cout, Ho·Wo]` → `dyg [Cout,
/// m·Ho·Wo]`, the columns as [`im2col_group`] orders them.
fn gather_group(g: &Geometry, dys: &[f32], dyg: &mut [f32]) -> usize {
    let (yl, outs) = (g.cout * g.outs(), g.outs());
    let n = dys.len() / yl * outs;
    for (j, dyj) in dys.chunks_exact(yl).enumerate() {
        for (co, src) in dyj.chunks_exact(outs).enumerate() {
            dyg[co * n + j * outs..][..outs].copy_from_slice(src);
        }
    }
    n
}

/// [`forward`] as one product per group of samples: `Y = W · col` with
/// `col` [`im2col_group`]'s.
fn forward_grouped(g: &Geometry, x: &[f32], w: &[f32], b: &[f32], y: &mut [MaybeUninit<f32>]) {
    let (taps, outs, (m, groups)) = (g.taps(), g.outs(), group(g));
    let (xl, yl) = (g.cin * g.h * g.w, g.cout * outs);
    let wm = MatRef::from_row_major_slice(w, g.cout, taps);
    let table = tap_table(g);
    y.par_chunks_mut(m * yl)
        .zip(x.par_chunks(m * xl))
        .with_min_len(groups)
        .for_each_init(
            || {
                (
                    vec![0.0f32; taps * m * outs],
                    vec![0.0f32; g.cout * m * outs],
                )
            },
            |(col, yg), (ys, xs)| {
                let n = im2col_group(g, &table, xs, col);
                let ym = MatMut::from_row_major_slice_mut(&mut yg[..g.cout * n], g.cout, n);
                gemm(
                    ym,
                    wm,
                    MatRef::from_row_major_slice(&col[..taps * n], taps, n),
                    false,
                );
                for (j, yj) in ys.chunks_exact_mut(yl).enumerate() {
                    let rows = yj.chunks_exact_mut(outs).zip(yg.chunks_exact(n)).zip(b);
                    for ((row, src), &bias) in rows {
                        for (d, &v) in row.iter_mut().zip(&src[j * outs..][..outs]) {
                            d.write(v + bias);
                        }
                    }
                }
            },
        );
}

/// [`x_backward`] as one product per group: `dcol = Wᵀ · dY`, then col2im
/// sample by sample.
fn x_backward_grouped(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    let (taps, outs, (m, groups)) = (g.taps(), g.outs(), group(g));
    let (xl, yl) = (g.cin * g.h * g.w, g.cout * outs);
    let wt = MatRef::from_row_major_slice(w, g.cout, taps).transpose();
    let table = tap_table(g);
    dx.par_chunks_mut(m * xl)
        .zip(dy.par_chunks(m * yl))
        .with_min_len(groups)
        .for_each_init(
            || {
                (
                    vec![0.0f32; taps * m * outs],
                    vec![0.0f32; g.cout * m * outs],
                )
            },
            |(col, dyg), (dxs, dys)| {
                let n = gather_group(g, dys, dyg);
                let colm = MatMut::from_row_major_slice_mut(&mut col[..taps * n], taps, n);
                gemm(
                    colm,
                    wt,
                    MatRef::from_row_major_slice(&dyg[..g.cout * n], g.cout, n),
                    false,
                );
                col2im_group(g, &table, &col[..taps * n], zeroed(dxs));
            },
        );
}

/// [`wb_backward`] as one product per group: `dW += dY · colᵀ`.
fn wb_backward_grouped(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (taps, outs, (m, groups)) = (g.taps(), g.outs(), group(g));
    let (xl, yl) = (g.cin * g.h * g.w, g.cout * outs);
    let zero = || {
        (
            vec![0.0f32; taps * m * outs],
            vec![0.0f32; g.cout * m * outs],
            vec![0.0f32; g.cout * taps],
            vec![0.0f32; g.cout],
        )
    };
    let table = tap_table(g);
    let folds = x
        .par_chunks(m * xl)
        .zip(dy.par_chunks(m * yl))
        .with_min_len(groups)
        .fold(zero, |(mut col, mut dyg, mut dw, mut db), (xs, dys)| {
            let n = im2col_group(g, &table, xs, &mut col);
            gather_group(g, dys, &mut dyg);
            gemm(
                MatMut::from_row_major_slice_mut(&mut dw, g.cout, taps),
                MatRef::from_row_major_slice(&dyg[..g.cout * n], g.cout, n),
                MatRef::from_row_major_slice(&col[..taps * n], taps, n).transpose(),
                true,
            );
            for dyj in dys.chunks_exact(yl) {
                add_bias_grad(&mut db, dyj, outs);
            }
            (col, dyg, dw, db)
        })
        .map(|(_, _, dw, db)| (dw, db));
    sum_grads(folds, g.cout * taps, g.cout)
}

/// The tensor in contiguous layout (copied only if it is not), or `None`
/// for another dtype than f32.
pub(crate) fn f32s(t: &FlexTensor) -> Option<FlexTensor> {
    (t.dtype() == DType::F32).then(|| t.to_contiguous())
}

/// A `[B, C, H, W]` shape, or a panic naming `what` in `op`.
pub(crate) fn dims4(op: &str, what: &str, shape: &[usize]) -> [usize; 4] {
    match *shape {
        [b, c, h, w] => [b, c, h, w],
        _ => panic!("{op}: {what} of shape {shape:?}, not [B, C, H, W]"),
    }
}

/// A contiguous f32 flex tensor of `shape` holding `values`.
pub(crate) fn flex_tensor(values: Vec<f32>, shape: Vec<usize>) -> FlexTensor {
    FlexTensor::from_data(burn::tensor::TensorData::new(values, shape))
}

impl ConvTrain for Flex {
    fn conv2d_train(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(xc), Some(wc), Some(bc)) = (f32s(&x), f32s(&weight), f32s(&bias)) else {
            return Flex::conv2d(x, weight, Some(bias), options(stride, pad));
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (xs, ws, bs) = (
            xc.storage::<f32>(),
            wc.storage::<f32>(),
            bc.storage::<f32>(),
        );
        // SAFETY: `forward` writes every value.
        let y = unsafe { written(g.batch * g.cout * g.outs(), |y| forward(&g, xs, ws, bs, y)) };
        flex_tensor(y, vec![g.batch, g.cout, g.ho, g.wo])
    }

    fn conv2d_train_x_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(wc), Some(dyc)) = (f32s(&weight), f32s(&grad)) else {
            return Flex::conv2d_x_backward(x, weight, grad, options(stride, pad));
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (ws, dys) = (wc.storage::<f32>(), dyc.storage::<f32>());
        // SAFETY: `x_backward` writes every value.
        let dx = unsafe {
            written(g.batch * g.cin * g.h * g.w, |dx| {
                x_backward(&g, ws, dys, dx)
            })
        };
        flex_tensor(dx, vec![g.batch, g.cin, g.h, g.w])
    }

    fn conv2d_train_wb_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> (FlexTensor, FlexTensor) {
        let (Some(xc), Some(dyc)) = (f32s(&x), f32s(&grad)) else {
            return burns_wb_backward::<Flex>(x, weight, grad, stride, pad);
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (dw, db) = wb_backward(&g, xc.storage::<f32>(), dyc.storage::<f32>());
        (
            flex_tensor(dw, vec![g.cout, g.cin, g.k, g.k]),
            flex_tensor(db, vec![g.cout]),
        )
    }

    fn conv_transpose2d_train(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(xc), Some(wc), Some(bc)) = (f32s(&x), f32s(&weight), f32s(&bias)) else {
            return Flex::conv_transpose2d(x, weight, Some(bias), transposed_options(stride, pad));
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let (ws, xs) = (wc.storage::<f32>(), xc.storage::<f32>());
        // SAFETY: `x_backward` writes every value.
        let mut y = unsafe { written(g.batch * g.cin * g.h * g.w, |y| x_backward(&g, ws, xs, y)) };
        let plane = g.h * g.w;
        let b = bc.storage::<f32>();
        y.par_chunks_mut(g.cin * plane).for_each(|sample| {
            for (p, &bias) in sample.chunks_exact_mut(plane).zip(b) {
                p.iter_mut().for_each(|v| *v += bias);
            }
        });
        flex_tensor(y, vec![g.batch, g.cin, g.h, g.w])
    }

    fn conv_transpose2d_train_x_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(wc), Some(dyc)) = (f32s(&weight), f32s(&grad)) else {
            return Flex::conv_transpose2d_x_backward(
                weight,
                grad,
                transposed_options(stride, pad),
            );
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let zero = vec![0.0f32; g.cout];
        let (dys, ws) = (dyc.storage::<f32>(), wc.storage::<f32>());
        // SAFETY: `forward` writes every value.
        let dx = unsafe {
            written(g.batch * g.cout * g.outs(), |dx| {
                forward(&g, dys, ws, &zero, dx)
            })
        };
        flex_tensor(dx, vec![g.batch, g.cout, g.ho, g.wo])
    }

    fn conv_transpose2d_train_wb_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> (FlexTensor, FlexTensor) {
        let (Some(xc), Some(dyc)) = (f32s(&x), f32s(&grad)) else {
            let opts = transposed_options(stride, pad);
            let cout = weight.shape()[1];
            let dw = Flex::conv_transpose2d_weight_backward(x, weight, grad.clone(), opts);
            return (dw, bias_grad::<Flex>(grad, cout));
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let dys = dyc.storage::<f32>();
        // The convolution's weight gradient with the roles of its input and
        // output gradient taken by this one's output gradient and input (its
        // bias gradient, Σ x, is not this one's).
        let (dw, _) = wb_backward(&g, dys, xc.storage::<f32>());
        let mut db = vec![0.0f32; g.cin];
        for sample in dys.chunks_exact(g.cin * g.h * g.w) {
            add_bias_grad(&mut db, sample, g.h * g.w);
        }
        (
            flex_tensor(dw, vec![g.cout, g.cin, g.k, g.k]),
            flex_tensor(db, vec![g.cin]),
        )
    }
}

/// The autodiff node of both convolutions: their three passes are
/// [`ConvTrain`]'s, whatever the backend.
#[derive(Debug)]
struct ConvBackward {
    transposed: bool,
}

impl<B: Backend + ConvTrain> Backward<B, 3> for ConvBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, usize, usize);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_w, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (x, w, stride, pad) = ops.state;
        if let Some(node) = node_x {
            let (x, w, g) = (x.clone(), w.clone(), grad.clone());
            let dx = if self.transposed {
                B::conv_transpose2d_train_x_backward(x, w, g, stride, pad)
            } else {
                B::conv2d_train_x_backward(x, w, g, stride, pad)
            };
            grads.register::<B>(node.id, dx);
        }
        if node_w.is_some() || node_b.is_some() {
            let (dw, db) = if self.transposed {
                B::conv_transpose2d_train_wb_backward(x, w, grad, stride, pad)
            } else {
                B::conv2d_train_wb_backward(x, w, grad, stride, pad)
            };
            if let Some(node) = node_w {
                grads.register::<B>(node.id, dw);
            }
            if let Some(node) = node_b {
                grads.register::<B>(node.id, db);
            }
        }
    }
}

impl ConvBackward {
    /// The forward pass on `B`, recorded for the backward pass when any
    /// of its inputs is tracked.
    fn run<B: Backend + ConvTrain, C: CheckpointStrategy>(
        self,
        x: FloatTensor<Autodiff<B, C>>,
        weight: FloatTensor<Autodiff<B, C>>,
        bias: FloatTensor<Autodiff<B, C>>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Autodiff<B, C>> {
        let transposed = self.transposed;
        let fwd = |x, w, b| {
            if transposed {
                B::conv_transpose2d_train(x, w, b, stride, pad)
            } else {
                B::conv2d_train(x, w, b, stride, pad)
            }
        };
        match self
            .prepare::<C>([x.node(), weight.node(), bias.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (xp, wp) = (x.primitive().clone(), weight.primitive().clone());
                let y = fwd(xp.clone(), wp.clone(), bias.into_primitive());
                prep.finish((xp, wp, stride, pad), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(fwd(
                x.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            )),
        }
    }
}

impl<B: Backend + ConvTrain, C: CheckpointStrategy> ConvTrain for Autodiff<B, C> {
    fn conv2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        ConvBackward { transposed: false }.run::<B, C>(x, weight, bias, stride, pad)
    }

    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        ConvBackward { transposed: true }.run::<B, C>(x, weight, bias, stride, pad)
    }
}

#[cfg(test)]
mod tests {
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
            !burns_own(),
            "LEARNER_CONV=burn is set: these tests would compare burn with burn"
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
                side < 40
                    || Shifted::of(&g).is_some()
                    || (rows < g.ho && !g.ho.is_multiple_of(rows)),
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
        assert!(!burns_own(), "LEARNER_CONV=burn is set");
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
        assert!(!burns_own(), "LEARNER_CONV=burn is set");
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
        if conv_direct::runs_weight_grad(g.cout, g.wo) {
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
        assert!(!products_only(), "LEARNER_CONV=products is set");
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
            direct_passes += usize::from(direct(&g));
            if s == 1 {
                // The input gradient's own convolution (padded by k − 1 − p).
                let gt = Geometry::new(&[b, cout, g.ho, g.wo], &[cin, cout, k, k], 1, k - 1 - p);
                direct_passes += usize::from(direct(&gt));
            }
            let sh = Shifted::of(&g).expect("a shifted geometry");
            let mut rng = fastrand::Rng::with_seed(3);
            let (x, w, bias) = (
                uniform(&mut rng, b * cin * side * width),
                uniform(&mut rng, cout * cin * k * k),
                uniform(&mut rng, cout),
            );
            let dy = uniform(&mut rng, b * cout * g.outs());
            let what =
                format!("b {b} cin {cin} cout {cout} {side}×{width} k {k} stride {s} pad {p}");
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
        assert_eq!(direct_passes, if conv_direct::cpu() { 4 } else { 0 });
        // The weight-gradient kernel runs on those three and the 8-wide
        // strided case (12×15, k 5); the three are routed to it.
        assert_eq!(weight_grads, if conv_direct::cpu() { 3 } else { 0 });
        // The strided input gradient by phases: the strided cases 16 wide
        // per phase with input channels a multiple of 4.
        assert_eq!(splits, if conv_direct::cpu() { 6 } else { 0 });
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
                    g.outs() <= GROUPED_OUTS && grouped(&g),
                    "{g:?} is not grouped: LEARNER_CONV_GROUPED_OUTS set?"
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
        assert!(!products_only(), "LEARNER_CONV=products is set");
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
        assert_eq!(weight_grads, if conv_direct::cpu() { 1 } else { 0 });
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
}
