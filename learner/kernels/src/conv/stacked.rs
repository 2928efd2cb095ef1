//! The stacked route: strided layers of fewer than
//! [`PHASED_MIN_CIN`] input channels (the encoders' first layers), their
//! im2col tile of a band of output rows stacked from the split input by
//! contiguous copies, one faer product per band.

use super::banded::{BAND_TILE, band};
use super::geometry::{Geometry, add_bias_grad, gemm, per_task, sum_grads};
#[cfg(doc)]
use super::shifted::PHASED_MIN_CIN;
use super::shifted::{Shifted, spread, unspread_rows};
use crate::flex::zeroed;
use faer::{MatMut, MatRef};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

/// Output rows per band of a [`Shifted::stacked`] layer, its stacked tile
/// kept within [`band_rows`](super::banded::band_rows)'s size.
pub(super) fn stacked_rows(g: &Geometry, sh: Shifted) -> usize {
    (BAND_TILE / (g.taps() * sh.wq).max(1)).clamp(1, g.ho)
}

/// The stacked im2col tile of the output rows `oy` from the split input
/// `xp`: `col [Cin·k·k, oy.len()·wq]`, row `(c, tap)` the tap's view of
/// channel `c`, one contiguous copy (the padding is in `xp`).
pub(super) fn stack_band(
    g: &Geometry,
    sh: Shifted,
    xp: &[f32],
    oy: &Range<usize>,
    col: &mut [f32],
) {
    let (kk, n) = (g.k * g.k, oy.len() * sh.wq);
    for (r, row) in col.chunks_exact_mut(n).enumerate() {
        let (c, t) = (r / kk, r % kk);
        let at = sh.offset(g, t) + c * sh.plane + oy.start * sh.wq;
        row.copy_from_slice(&xp[at..at + n]);
    }
}

/// [`forward`] for a [`Shifted::stacked`] layer: per band, one product of
/// the `[Cout, Cin·k·k]` weights with the stacked tile.
pub(super) fn forward_stacked(
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
pub(super) fn wb_backward_stacked(
    g: &Geometry,
    sh: Shifted,
    x: &[f32],
    dy: &[f32],
) -> (Vec<f32>, Vec<f32>) {
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
