//! The grouped route: convolutions with small output maps as one product
//! per group of samples per pass.

use super::geometry::{Geometry, add_bias_grad, gemm, per_task, sum_grads};
use crate::flex::zeroed;
use faer::{MatMut, MatRef};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Values of a group's im2col matrix at most (1 MB of f32), unless a single
/// sample's is larger.
const GROUP_TILE: usize = 256 * 1024;

/// Whether `g` runs through the grouped passes ([`forward_grouped`]): its
/// output map has at most [`KernelSettings::grouped_outs`](crate::KernelSettings)
/// positions.
pub(super) fn grouped(g: &Geometry) -> bool {
    !g.is_pointwise() && g.outs() <= g.settings.grouped_outs
}

/// `(samples per group, groups per rayon task)`: each thread's share of the
/// batch ([`per_task`]) cut into equal groups whose im2col matrix stays
/// within [`GROUP_TILE`].
pub(super) fn group(g: &Geometry) -> (usize, usize) {
    let task = per_task(g.batch);
    let cap = (GROUP_TILE / (g.taps() * g.outs()).max(1)).max(1);
    let groups = task.div_ceil(cap);
    (task.div_ceil(groups), groups)
}

/// For each tap `t` and output position `o` of one sample, the input
/// position (`iy·W + ix`) that tap reads there, or `usize::MAX` in the
/// padding: `[k·k][Ho·Wo]`. A map of a few positions per row made
/// [`im2col`](super::banded::im2col)'s row-by-row copies cost as much as the product.
pub(super) fn tap_table(g: &Geometry) -> Vec<usize> {
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
pub(super) fn forward_grouped(
    g: &Geometry,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    y: &mut [MaybeUninit<f32>],
) {
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
pub(super) fn x_backward_grouped(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
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
pub(super) fn wb_backward_grouped(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
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
