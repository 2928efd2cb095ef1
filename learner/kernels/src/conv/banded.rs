//! The im2col route: the layers no other route takes (and every 1×1,
//! which reads its input as the matrix) through im2col in row bands and
//! one faer product per band; backwards `dx = col2im(Wᵀ · dy)`.

use super::geometry::{Geometry, add_bias_grad, gemm, per_task, sum_grads};
use crate::flex::zeroed;
use faer::{MatMut, MatRef};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

/// Output rows per band: a band's im2col tile (`taps × rows·Wo` values)
/// stays within about 256 KB, so that it is still in the core's cache when
/// the product reads it (a whole sample's matrix, 2.4 MB for a 16-channel
/// 3×3 layer at 64², was not, and copying it in and out cost as much as
/// the product).
pub(super) fn band_rows(g: &Geometry) -> usize {
    (BAND_TILE / (g.taps() * g.wo).max(1)).clamp(1, g.ho)
}

/// Values per band's im2col tile (256 KB of f32).
pub(super) const BAND_TILE: usize = 64 * 1024;

/// The output rows of band `i`.
pub(super) fn band(g: &Geometry, rows: usize, i: usize) -> Range<usize> {
    i * rows..((i + 1) * rows).min(g.ho)
}

/// One sample's `x [Cin, H, W]` → the im2col tile of the output rows `oy`:
/// `col [Cin·k·k, oy.len()·Wo]`, zeros where a tap falls in the padding.
pub(super) fn im2col(g: &Geometry, x: &[f32], oy: Range<usize>, col: &mut [f32]) {
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
/// The columns of the output rows `oy` in a `[C, Ho·Wo]` matrix.
fn columns<'a>(m: MatRef<'a, f32>, g: &Geometry, oy: &Range<usize>) -> MatRef<'a, f32> {
    m.subcols(oy.start * g.wo, oy.len() * g.wo)
}

/// [`forward`] through im2col in row bands (or none, for a 1×1).
pub(super) fn forward_banded(
    g: &Geometry,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    y: &mut [MaybeUninit<f32>],
) {
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
/// [`x_backward`] through col2im in row bands (or none, for a 1×1).
pub(super) fn x_backward_banded(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
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
/// [`wb_backward`] through im2col in row bands (or none, for a 1×1).
pub(super) fn wb_backward_banded(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
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
