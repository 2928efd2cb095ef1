//! The shapes of one convolution ([`Geometry`], with the kernel settings
//! in force when it was made) and what every route's passes share: faer's
//! product, the batch's split over rayon's tasks, the gradients' sums.

use super::direct;
use crate::choice::{KernelSettings, kernel_settings};
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

/// The shapes of one convolution.
#[derive(Clone, Copy, Debug)]
pub(super) struct Geometry {
    pub(super) batch: usize,
    pub(super) cin: usize,
    pub(super) cout: usize,
    pub(super) h: usize,
    pub(super) w: usize,
    pub(super) k: usize,
    pub(super) stride: usize,
    pub(super) pad: usize,
    pub(super) ho: usize,
    pub(super) wo: usize,
    /// The kernels this convolution's passes run ([`kernel_settings`] when
    /// it was made).
    pub(super) settings: KernelSettings,
}

impl Geometry {
    /// The convolution of `x [B, Cin, H, W]` by `weight [Cout, Cin, k, k]`
    /// under the kernel settings in force.
    pub(super) fn new(x: &[usize], weight: &[usize], stride: usize, pad: usize) -> Self {
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
            settings: kernel_settings(),
        }
    }

    /// The same convolution under `settings`.
    pub(super) fn with_settings(self, settings: KernelSettings) -> Self {
        Self { settings, ..self }
    }

    /// The convolution whose input gradient is the transposed convolution
    /// of `x [B, Cin, H, W]` by `weight [Cin, Cout, k, k]`: input `[B, Cout,
    /// (H − 1)·s − 2p + k, …]`, output `[B, Cin, H, W]`, the same weight.
    pub(super) fn transposed(x: &[usize], weight: &[usize], stride: usize, pad: usize) -> Self {
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
    pub(super) fn taps(&self) -> usize {
        self.cin * self.k * self.k
    }

    /// Output positions per sample.
    pub(super) fn outs(&self) -> usize {
        self.ho * self.wo
    }

    /// A 1×1 convolution of stride 1 without padding reads its input as
    /// the im2col matrix itself.
    pub(super) fn is_pointwise(&self) -> bool {
        self.k == 1 && self.stride == 1 && self.pad == 0
    }

    /// The output columns `ox` whose input column `ox·stride + kx − pad`
    /// lies inside the image.
    pub(super) fn inside(&self, kx: usize) -> std::ops::Range<usize> {
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
/// `dst (m × n) = lhs (m × k) · rhs (k × n)`, or `+=` with `add`.
pub(super) fn gemm(dst: MatMut<'_, f32>, lhs: MatRef<'_, f32>, rhs: MatRef<'_, f32>, add: bool) {
    let accum = if add { Accum::Add } else { Accum::Replace };
    faer::linalg::matmul::matmul(dst, accum, lhs, rhs, 1.0f32, Par::Seq);
}

/// Samples per rayon task: the batch split once per thread, so that each
/// thread keeps one scratch tile and one weight-gradient accumulator.
pub(super) fn per_task(batch: usize) -> usize {
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
pub(super) fn sum_grads<I>(tasks: I, dw_len: usize, cout: usize) -> (Vec<f32>, Vec<f32>)
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
pub(super) fn add_bias_grad(db: &mut [f32], dy: &[f32], outs: usize) {
    for (d, row) in db.iter_mut().zip(dy.chunks_exact(outs)) {
        *d += row.iter().sum::<f32>();
    }
}

/// `xp[a..a + n]` and `xp[b..b + m]`, two ranges that do not overlap, both
/// writable.
///
/// # Panics
/// If they overlap or either reaches past `xp`.
pub(super) fn two_mut(
    xp: &mut [f32],
    a: usize,
    b: usize,
    n: usize,
    m: usize,
) -> (&mut [f32], &mut [f32]) {
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

/// Whether `g`'s forward pass (on its [`Shifted`](super::shifted::Shifted)
/// layout) takes [`direct`](mod@direct)'s kernel.
pub(super) fn direct_forward(g: &Geometry) -> bool {
    !g.settings.products_only() && direct::covers(g.cout, g.wo)
}

/// Whether `g`'s weight gradient (on its `Shifted` or stacked layout)
/// takes [`direct::weight_grad`]: where it runs and the output rows are
/// a multiple of 16 wide. On 8-wide rows it measured slower than faer's
/// products; on 16-wide ones about even in all (the 64-channel 16² layer
/// about 7 % slower, the largest up-convolution's 11 % faster;
/// docs/performance.md).
pub(super) fn direct_weight_grad(g: &Geometry) -> bool {
    !g.settings.products_only() && g.wo.is_multiple_of(16) && direct::runs_weight_grad(g.cout, g.wo)
}
