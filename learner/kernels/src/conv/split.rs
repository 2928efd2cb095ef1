//! A strided layer's input gradient by phases: s² stride-1 convolutions
//! of `dy` through [`direct`](mod@direct)'s forward kernel, one per phase of the
//! input.

use super::direct;
use super::geometry::{Geometry, per_task};
use crate::flex::as_uninit;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

/// One phase of a strided layer's input gradient ([`x_backward_split`]):
/// the input positions `(qy·s + a − pad, qx·s + b − pad)` for `qy` in `qy`
/// and `qx` in `qx`, and the taps `(ky, kx) = (a + s·i, b + s·j)` that
/// reach them, as `(i, j)`.
pub(super) struct Phase {
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
/// [`direct::forward`] covers each phase (the layer's `Cin` a multiple
/// of 4, each phase's rows of input positions a multiple of 16 wide).
pub(super) fn split_direct(g: &Geometry) -> bool {
    !g.settings.products_only()
        && g.stride > 1
        && g.k >= g.stride
        && Phase::all(g)
            .iter()
            .all(|ph| direct::covers(g.cin, ph.qx.len()))
}

/// [`x_backward`] for a strided layer as `s²` stride-1 convolutions of
/// `dy`, one per phase of the input (every s-th row and column from `(a,
/// b)`), each by the taps that reach that phase, flipped, with the
/// channels swapped: [`direct::forward`] adds every tap into
/// registers and writes each input position's gradient once, where
/// [`x_backward_phased`]'s products added `k²` transposed products into
/// views of the whole split input.
///
/// Phase `(a, b)`'s gradient at `(qy, qx)` is `Σ_(i, j) Σ_co W[co, ci, a +
/// s·i, b + s·j] · dy[co, qy − i, qx − j]` (zero outside `dy`); `dy` is
/// read from a copy with `m = ⌈k/s⌉ − 1` rows and columns of zeros before
/// it, so that tap `(i, j)` reads it from `(qy + m − i, qx + m − j)`.
pub(super) fn x_backward_split(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
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
            direct::pack(g.cin, g.cout, ph.taps.len(), |t, ci, co| {
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
                    let views = direct::Views {
                        plane,
                        wq,
                        taps: offsets,
                    };
                    let part = &mut part[..g.cin * ny * nx];
                    // SAFETY: the kernel writes only values, never
                    // uninitialised ones, through the view.
                    let out = unsafe { as_uninit(part) };
                    direct::forward(dyp, views, g.cout, packed, &zero, ny, nx, out);
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
