//! The routes without im2col ([`Shifted`]): stride-1 layers as k² products
//! over views of the zero-padded input, strided ones of at least
//! [`PHASED_MIN_CIN`] channels the same over the input split into phases,
//! and the weight gradient of these (and the stacked layers) through
//! [`direct`](mod@direct)'s second kernel.

use super::direct;
use super::geometry::{
    Geometry, add_bias_grad, direct_forward, gemm, per_task, sum_grads, two_mut,
};
use crate::flex::zeroed;
use faer::{MatMut, MatRef};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

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
pub(super) struct Shifted {
    /// Stride.
    pub(super) s: usize,
    /// Row length of a phase plane (the padded row length for stride 1).
    pub(super) wq: usize,
    /// Values per phase plane of a channel, with `⌈k/s⌉ − 1` zeros after it
    /// so that the last tap's view stays inside.
    pub(super) plane: usize,
    /// Output positions computed per channel (`Ho·wq`).
    pub(super) n: usize,
}

/// Strided layers with fewer input channels are not [`Shifted`]: a tap's
/// product would have an inner dimension of `Cin` (the RGB encoder's first
/// layer: 3, the depth encoder's: 1). They read the same split input as a
/// stacked matrix instead ([`Shifted::stacked`]).
pub(super) const PHASED_MIN_CIN: usize = 8;

impl Shifted {
    /// The layer as k² products over views: stride 1 with a kernel larger
    /// than 1, or strided with at least [`PHASED_MIN_CIN`] input channels.
    pub(super) fn of(g: &Geometry) -> Option<Self> {
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
    pub(super) fn stacked(g: &Geometry) -> Option<Self> {
        (g.stride > 1 && g.k >= g.stride && g.cin < PHASED_MIN_CIN).then(|| Self::layout(g))
    }

    pub(super) fn layout(g: &Geometry) -> Self {
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
    pub(super) fn len(&self, g: &Geometry) -> usize {
        self.s * self.s * g.cin * self.plane
    }

    /// Where tap `t` (`ky·k + kx`) starts in the split input.
    pub(super) fn offset(&self, g: &Geometry, t: usize) -> usize {
        let (ky, kx, s) = (t / g.k, t % g.k, self.s);
        ((ky % s) * s + kx % s) * g.cin * self.plane + (ky / s) * self.wq + kx / s
    }

    /// Where input position `(c, iy, ix)` lies in the split input.
    pub(super) fn at(&self, g: &Geometry, c: usize, iy: usize, ix: usize) -> usize {
        let (py, px, s) = (iy + g.pad, ix + g.pad, self.s);
        ((py % s) * s + px % s) * g.cin * self.plane + c * self.plane + (py / s) * self.wq + px / s
    }

    /// One sample's `x [Cin, H, W]` into its zero-padded phases. Writes
    /// the image positions only: `xp` must be zero elsewhere, as a buffer
    /// allocated zeroed that only this writes stays (every caller's, one
    /// per rayon task, reused sample after sample of one layer call).
    /// Zeroing it whole per sample took about 1 % of a training step (a
    /// profile).
    pub(super) fn pad(&self, g: &Geometry, x: &[f32], xp: &mut [f32]) {
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
    pub(super) fn unpad(&self, g: &Geometry, xp: &[f32], dx: &mut [f32]) {
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
    pub(super) fn tap_offsets(&self, g: &Geometry) -> Vec<usize> {
        (0..g.k * g.k).map(|t| self.offset(g, t)).collect()
    }

    /// The split input as [`direct`](mod@direct)'s kernels read it, the taps at
    /// `offsets` (from [`Shifted::tap_offsets`]).
    pub(super) fn views<'a>(&self, offsets: &'a [usize]) -> direct::Views<'a> {
        direct::Views {
            plane: self.plane,
            wq: self.wq,
            taps: offsets,
        }
    }

    /// The split input seen from tap `t`: `[Cin, Ho·wq]`.
    pub(super) fn view<'a>(&self, g: &Geometry, xp: &'a [f32], t: usize) -> MatRef<'a, f32> {
        let off = self.offset(g, t);
        MatRef::from_row_major_slice_with_stride(&xp[off..], g.cin, self.n, self.plane)
    }

    /// The same view, writable. Built column-major and transposed: faer
    /// 0.24.4's `from_row_major_slice_with_stride_mut` gives its view the
    /// two strides swapped (row stride 1, column stride the row stride), so
    /// a product into it writes outside the view (a heap corruption,
    /// measured here); its column-major constructor is right.
    pub(super) fn view_mut<'a>(
        &self,
        g: &Geometry,
        xp: &'a mut [f32],
        t: usize,
    ) -> MatMut<'a, f32> {
        let off = self.offset(g, t);
        MatMut::from_column_major_slice_with_stride_mut(&mut xp[off..], self.n, g.cin, self.plane)
            .transpose_mut()
    }
}

/// `weight [Cout, Cin, k, k]` → tap-major `[k·k][Cout, Cin]`, written in
/// order (a scattered write per value took 1.5 % of a training step in a
/// profile).
pub(super) fn taps_major(g: &Geometry, w: &[f32]) -> Vec<f32> {
    let (kk, n) = (g.k * g.k, g.cout * g.cin);
    let mut out = Vec::with_capacity(w.len());
    for t in 0..kk {
        out.extend(w[t..].iter().step_by(kk).take(n));
    }
    out
}

/// The adjoint of [`taps_major`]: `[k·k][Cout, Cin]` → `[Cout, Cin, k, k]`.
pub(super) fn taps_minor(g: &Geometry, wt: &[f32]) -> Vec<f32> {
    let (kk, n) = (g.k * g.k, g.cout * g.cin);
    let mut out = Vec::with_capacity(wt.len());
    for oc in 0..n {
        out.extend(wt[oc..].iter().step_by(n).take(kk));
    }
    out
}

/// Tap `t`'s `[Cout, Cin]` block of [`taps_major`]'s layout.
pub(super) fn tap<'a>(g: &Geometry, wt: &'a [f32], t: usize) -> MatRef<'a, f32> {
    MatRef::from_row_major_slice(&wt[t * g.cout * g.cin..][..g.cout * g.cin], g.cout, g.cin)
}

/// Which kernel [`forward_shifted`] applies, given by a layer's own
/// `[Cout, Cin, k, k]` weights (packed for [`direct`](mod@direct) straight from
/// them; put in [`taps_major`]'s layout only for faer's products).
#[derive(Clone, Copy)]
pub(super) enum Kernel<'a> {
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
    pub(super) fn weights(&self) -> &[f32] {
        match *self {
            Kernel::Own(w) | Kernel::Flipped(w) => w,
        }
    }

    /// Tap `t`'s weight from input channel `ci` to output channel `co` of
    /// the convolution `g` applies.
    pub(super) fn at(&self, g: &Geometry, t: usize, co: usize, ci: usize) -> f32 {
        let kk = g.k * g.k;
        match *self {
            Kernel::Own(w) => w[(co * g.cin + ci) * kk + t],
            Kernel::Flipped(w) => w[(ci * g.cout + co) * kk + kk - 1 - t],
        }
    }

    /// Tap `t`'s `[Cout, Cin]` matrix for the convolution `g` applies, from
    /// `wt`, [`taps_major`] of [`Kernel::weights`].
    pub(super) fn tap<'b>(&self, g: &Geometry, wt: &'b [f32], t: usize) -> MatRef<'b, f32> {
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
pub(super) fn forward_shifted(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    kernel: Kernel<'_>,
    b: &[f32],
    y: &mut [MaybeUninit<f32>],
) {
    let outs = g.outs();
    let kk = g.k * g.k;
    let direct = direct_forward(g);
    let packed =
        direct.then(|| direct::pack(g.cout, g.cin, kk, |t, co, ci| kernel.at(g, t, co, ci)));
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
                    direct::forward(xp, views, g.cin, packed, b, g.ho, g.wo, ys);
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
pub(super) fn unspread_rows(
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
/// One sample's `dy [Cout, Ho·Wo]` spread into `[Cout, Ho·wq]` with zeros
/// at the discarded positions, so that they add nothing.
pub(super) fn spread(g: &Geometry, sh: Shifted, dy: &[f32], dyp: &mut [f32]) {
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
/// products (or [`direct`](mod@direct)'s kernel) only read strided views; the
/// gradient is written once, not accumulated tap by tap as strided layers
/// do into writable views ([`x_backward_phased`]).
pub(super) fn x_backward_shifted(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    let k = g.k;
    let gt = Geometry::new(
        &[g.batch, g.cout, g.ho, g.wo],
        &[g.cin, g.cout, k, k],
        1,
        k - 1 - g.pad,
    )
    .with_settings(g.settings);
    debug_assert_eq!((gt.ho, gt.wo), (g.h, g.w));
    let sh = Shifted::of(&gt).expect("stride 1");
    forward_shifted(&gt, sh, dy, Kernel::Flipped(w), &vec![0.0; g.cin], dx);
}

/// [`x_backward`] for a strided [`Shifted`] convolution: tap by tap, the
/// transposed product `W_tᵀ·dy` added into the tap's view of the split
/// input's gradient, which is then gathered back without its padding. (The
/// discarded output positions of `dy` are zeros and add nothing.)
pub(super) fn x_backward_phased(
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
/// [`wb_backward`] for a [`Shifted`] convolution.
pub(super) fn wb_backward_shifted(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    dy: &[f32],
) -> (Vec<f32>, Vec<f32>) {
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
/// [`direct::weight_grad`]: per sample, straight into the layer's own
/// `[Cout, Cin, k, k]` layout from its padded input and its output gradient
/// as it comes.
pub(super) fn wb_backward_direct(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    dy: &[f32],
) -> (Vec<f32>, Vec<f32>) {
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
            direct::weight_grad(&xp, views, g.cin, dys, g.ho, g.wo, &mut dw);
            add_bias_grad(&mut db, dys, outs);
            (xp, dw, db)
        })
        .map(|(_, dw, db)| (dw, db));
    sum_grads(folds, g.cout * g.cin * kk, g.cout)
}
