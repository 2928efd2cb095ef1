//! Direct, register-blocked convolution kernels for the training path on
//! x86-64 with AVX and FMA, for the convolution's layers that read a
//! zero-padded, possibly phase-split input ([`super::shifted::Shifted`]) and whose
//! output rows are a multiple of 16 wide and output channels a multiple of
//! 4 (the depth encoder's 64², 32² and 16² stages, the RGB encoder's first
//! three layers, the first layers of both):
//!
//! - [`forward`], the forward pass (and the stride-1 input gradient, itself
//!   such a convolution, and each phase of a strided layer's input
//!   gradient, [`super::split`]). Through faer a layer was k² products with an
//!   inner dimension of `Cin` (16–64), each reading and adding into the
//!   whole output: the 16-channel layers ran at about 27 GFLOP/s where wider
//!   products reach 50 (docs/performance.md). Here each block of 6 (or 4)
//!   output channels × 16 positions of a row stays in registers while all
//!   `Cin·k²` taps are added into it, so the output is written once.
//! - [`weight_grad`], the weight gradient: 4 output channels × 3 taps of an
//!   input channel in registers over every output position, where faer's
//!   products had a small output and a long inner dimension.
//!
//! It owns nothing but the arithmetic: [`super`] builds the input and
//! says where each tap's view starts; other geometries and other CPUs keep
//! the other routes' products.

use std::mem::MaybeUninit;

/// Output channels per register block.
const CO: usize = 4;
/// Output positions per register block (two 8-wide vectors).
const PX: usize = 16;

/// Whether [`forward`] runs a layer with `cout` output channels and output
/// rows `wo` wide on this CPU: multiples of [`CO`] and [`PX`] (its blocks
/// read and write whole rows of 16).
pub(crate) fn covers(cout: usize, wo: usize) -> bool {
    cout.is_multiple_of(CO) && wo.is_multiple_of(PX) && cpu()
}

/// Whether this CPU runs the kernel (x86-64 with AVX and FMA).
#[cfg(target_arch = "x86_64")]
pub(crate) fn cpu() -> bool {
    static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *HAS.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx") && std::arch::is_x86_feature_detected!("fma")
    })
}

/// Whether this CPU runs the kernel (x86-64 with AVX and FMA).
#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn cpu() -> bool {
    false
}

/// Output channels per register block of the forward pass where `Cout`
/// allows: 6 × 16 positions in twelve accumulators, where four channels'
/// eight leave the FMA units waiting on their latency.
const WIDE: usize = 6;

/// The forward pass's blocks of output channels, `(first, count)`: as many
/// of [`WIDE`] as leave a multiple of [`CO`], then blocks of [`CO`]
/// (16 = 6 + 6 + 4, 32 = 4·6 + 2·4, 64 = 10·6 + 4).
fn blocks(cout: usize) -> impl Iterator<Item = (usize, usize)> {
    let wide = (0..=cout / WIDE)
        .rev()
        .find(|a| (cout - a * WIDE).is_multiple_of(CO))
        .unwrap_or(0);
    let sizes =
        std::iter::repeat_n(WIDE, wide).chain(std::iter::repeat_n(CO, (cout - wide * WIDE) / CO));
    sizes.scan(0, |first, c| {
        let block = (*first, c);
        *first += c;
        Some(block)
    })
}

/// The weights `tap(t)[co, ci]` of `taps` taps packed for the kernel: per
/// block of [`blocks`], `[Cin][taps][c]`, the block's `c` output channels
/// side by side.
pub(crate) fn pack(
    cout: usize,
    cin: usize,
    taps: usize,
    tap: impl Fn(usize, usize, usize) -> f32,
) -> Vec<f32> {
    let mut out = Vec::with_capacity(cout * cin * taps);
    for (first, c) in blocks(cout) {
        for ci in 0..cin {
            for t in 0..taps {
                out.extend((first..first + c).map(|co| tap(t, co, ci)));
            }
        }
    }
    out
}

/// Where a layer reads its input: channel `c`'s view from tap `t` starts at
/// `c·plane + taps[t]` and output position `(oy, ox)` reads `oy·wq + ox`
/// further on.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Views<'a> {
    /// Values per channel.
    pub plane: usize,
    /// Row length of a view.
    pub wq: usize,
    /// Each tap's offset.
    pub taps: &'a [usize],
}

/// One sample: `y [Cout, Ho·Wo] = Σ_t W_t · view_t(xp) + b`, with `packed`
/// from [`pack`]. Every value of `y` is written (its blocks cover all
/// channels, its rows every position), so `y` may come uninitialised.
///
/// # Panics
/// If a view reaches past `xp`, the buffers do not match the shapes, or
/// [`covers`] is false.
#[allow(clippy::too_many_arguments)]
pub(crate) fn forward(
    xp: &[f32],
    views: Views<'_>,
    cin: usize,
    packed: &[f32],
    b: &[f32],
    ho: usize,
    wo: usize,
    y: &mut [MaybeUninit<f32>],
) {
    let cout = b.len();
    assert!(cin > 0 && ho > 0 && wo > 0, "conv_direct: an empty layer");
    // Asserted apart from `covers`, whose CPU check it also needs: the
    // unchecked loads and stores rely on whole rows of 16 and blocks of 4.
    assert!(
        cout.is_multiple_of(CO) && wo.is_multiple_of(PX),
        "conv_direct: a layer of {cout} channels, rows {wo} wide"
    );
    assert!(covers(cout, wo), "conv_direct: a CPU without AVX and FMA");
    let last = last_read(views, cin, ho, wo);
    assert!(
        wo <= views.wq && last < xp.len(),
        "conv_direct: a view reaches past the input"
    );
    assert!(packed.len() == cout * cin * views.taps.len() && y.len() == cout * ho * wo);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `covers` checked AVX and FMA; every value read is at most
    // `last` (asserted inside `xp`), every value written inside `y`.
    unsafe {
        avx::forward(xp, views, cin, packed, b, ho, wo, y)
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!()
}

/// Output positions per step of [`weight_grad`] (one 8-wide vector).
const GX: usize = 8;

/// Whether [`weight_grad`] runs a layer with `cout` output channels and
/// output rows `wo` wide on this CPU: multiples of [`CO`] and [`GX`] (its
/// loads read whole rows of 8). Where it is faster than faer's products is
/// the convolution's choice ([`super::geometry::direct_weight_grad`]).
pub(crate) fn runs_weight_grad(cout: usize, wo: usize) -> bool {
    cout.is_multiple_of(CO) && wo.is_multiple_of(GX) && cpu()
}

/// One sample's weight gradient added into `dw [Cout, Cin, taps]` (the
/// layer's own layout): `dw[co, ci, t] += Σ_(oy, ox) dy[co, oy·Wo + ox] ·
/// xp[ci·plane + taps[t] + oy·wq + ox]`, with `dy [Cout, Ho·Wo]` as the
/// layer's output gradient comes (no discarded positions to skip).
///
/// Through faer this was k² products `[Cout, Ho·wq] · [Ho·wq, Cin]` (for
/// the stacked first layers one `[Cout, Ho·wq] · [Ho·wq, Cin·k²]` per band
/// of rows), each with a small output and a long inner dimension; here 4
/// output channels × 3 taps of one input channel stay in twelve registers
/// over every output position, each position's 3 input and 4 gradient
/// vectors loaded once.
///
/// # Panics
/// If a view reaches past `xp`, the buffers do not match the shapes, or
/// [`runs_weight_grad`] is false.
#[allow(clippy::too_many_arguments)]
pub(crate) fn weight_grad(
    xp: &[f32],
    views: Views<'_>,
    cin: usize,
    dy: &[f32],
    ho: usize,
    wo: usize,
    dw: &mut [f32],
) {
    let kk = views.taps.len();
    assert!(
        cin > 0 && ho > 0 && wo > 0 && kk > 0,
        "conv_direct: an empty layer"
    );
    let cout = dy.len() / (ho * wo);
    // Asserted apart from `runs_weight_grad`, whose CPU check it also
    // needs: the unchecked loads rely on whole rows of 8 and blocks of 4.
    assert!(
        cout.is_multiple_of(CO) && wo.is_multiple_of(GX),
        "conv_direct: a weight gradient of {cout} channels, rows {wo} wide"
    );
    assert!(
        runs_weight_grad(cout, wo),
        "conv_direct: a CPU without AVX and FMA"
    );
    let last = last_read(views, cin, ho, wo);
    assert!(
        wo <= views.wq && last < xp.len(),
        "conv_direct: a view reaches past the input"
    );
    assert!(dw.len() == cout * cin * kk && dy.len() == cout * ho * wo);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `runs_weight_grad` checked AVX and FMA; every value of `xp`
    // read is at most `last` (asserted inside it), every value of `dy` read
    // and of `dw` written inside them (their lengths asserted).
    unsafe {
        avx::weight_grad(xp, views, cin, dy, ho, wo, dw)
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!()
}

/// The last value of the input any view reads for an output of `ho` rows
/// `wo` wide, computed without wrapping: the bound the unchecked loads rely
/// on.
///
/// # Panics
/// If it lies beyond the address space, or a dimension is 0.
fn last_read(views: Views<'_>, cin: usize, ho: usize, wo: usize) -> usize {
    (cin - 1)
        .checked_mul(views.plane)
        .zip((ho - 1).checked_mul(views.wq))
        .and_then(|(a, b)| a.checked_add(b))
        .and_then(|v| v.checked_add(*views.taps.iter().max()?))
        .and_then(|v| v.checked_add(wo - 1))
        .expect("conv_direct: views beyond the address space")
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{CO, GX, MaybeUninit, PX, Views, WIDE};
    use std::arch::x86_64::*;

    /// [`super::forward`]'s loops.
    ///
    /// # Safety
    /// The CPU has AVX and FMA; `xp` holds every value the views read (the
    /// last at `super::forward`'s `last`); `packed` holds `Cout·Cin·taps`
    /// weights and `b` is `Cout` long, a multiple of 4.
    #[target_feature(enable = "avx,fma")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn forward(
        xp: &[f32],
        views: Views<'_>,
        cin: usize,
        packed: &[f32],
        b: &[f32],
        ho: usize,
        wo: usize,
        y: &mut [MaybeUninit<f32>],
    ) {
        let (kk, outs) = (views.taps.len(), ho * wo);
        for (first, c) in super::blocks(b.len()) {
            let w = &packed[first * cin * kk..][..cin * kk * c];
            let bias = &b[first..][..c];
            for oy in 0..ho {
                for ox in (0..wo).step_by(PX) {
                    let (at, to) = (oy * views.wq + ox, first * outs + oy * wo + ox);
                    // SAFETY: the values read are at most `forward`'s `last`.
                    unsafe {
                        match c {
                            WIDE => block::<WIDE>(xp, views, cin, w, bias, at, y, outs, to),
                            CO => block::<CO>(xp, views, cin, w, bias, at, y, outs, to),
                            _ => unreachable!("blocks() yields blocks of 6 and 4"),
                        }
                    };
                }
            }
        }
    }

    /// `C` output channels × 16 positions: 2·C accumulators over all of
    /// `Cin`'s taps, then the bias, stored once.
    ///
    /// # Safety
    /// The CPU has AVX and FMA; for every channel `ci` and tap offset `off`,
    /// `ci·plane + at + off + 15` is inside `xp`; `w` holds `Cin·taps·C`
    /// weights, `bias` C; `y` holds C rows of `outs` from `to` on.
    #[target_feature(enable = "avx,fma")]
    #[allow(clippy::too_many_arguments)]
    #[inline]
    unsafe fn block<const C: usize>(
        xp: &[f32],
        views: Views<'_>,
        cin: usize,
        w: &[f32],
        bias: &[f32],
        at: usize,
        y: &mut [MaybeUninit<f32>],
        outs: usize,
        to: usize,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; C];
        let (xs, mut ws) = (xp.as_ptr(), w.as_ptr());
        for ci in 0..cin {
            let base = ci * views.plane + at;
            for &off in views.taps {
                // SAFETY: the 16 values from `base + off` are inside `xp`
                // and `ws` stays inside `w` (this function's contract).
                unsafe {
                    let p = xs.add(base + off);
                    let (v0, v1) = (_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
                    for (j, a) in acc.iter_mut().enumerate() {
                        let wj = _mm256_broadcast_ss(&*ws.add(j));
                        a[0] = _mm256_fmadd_ps(wj, v0, a[0]);
                        a[1] = _mm256_fmadd_ps(wj, v1, a[1]);
                    }
                    ws = ws.add(C);
                }
            }
        }
        for (j, a) in acc.iter().enumerate() {
            let bj = _mm256_set1_ps(bias[j]);
            let out = y[to + j * outs..][..PX].as_mut_ptr().cast::<f32>();
            // SAFETY: `out` points at 16 values (a checked slice), of
            // `MaybeUninit<f32>`'s layout, which is `f32`'s.
            unsafe {
                _mm256_storeu_ps(out, _mm256_add_ps(a[0], bj));
                _mm256_storeu_ps(out.add(8), _mm256_add_ps(a[1], bj));
            }
        }
    }

    /// [`super::weight_grad`]'s loops: per block of 4 output channels and
    /// input channel, the taps in groups of 3 (the last group 1 or 2).
    ///
    /// # Safety
    /// As [`super::weight_grad`] asserts: the CPU has AVX and FMA; `xp`
    /// holds every value the views read; `dy` is `Cout·Ho·Wo` and `dw`
    /// `Cout·Cin·taps` long, `Cout` a multiple of 4 and `Wo` of 8.
    #[target_feature(enable = "avx,fma")]
    pub(super) unsafe fn weight_grad(
        xp: &[f32],
        views: Views<'_>,
        cin: usize,
        dy: &[f32],
        ho: usize,
        wo: usize,
        dw: &mut [f32],
    ) {
        let (kk, outs) = (views.taps.len(), ho * wo);
        let cout = dy.len() / outs;
        for cb in 0..cout / CO {
            let d = &dy[cb * CO * outs..][..CO * outs];
            for ci in 0..cin {
                let base = ci * views.plane;
                let mut t0 = 0;
                while t0 < kk {
                    let offs = &views.taps[t0..];
                    // SAFETY: this function's contract, passed on.
                    let (n, sums) = unsafe {
                        match kk - t0 {
                            1 => (
                                1,
                                group::<1>(xp, base, offs, views.wq, d, ho, wo).map(widen),
                            ),
                            2 => (
                                2,
                                group::<2>(xp, base, offs, views.wq, d, ho, wo).map(widen),
                            ),
                            _ => (3, group::<3>(xp, base, offs, views.wq, d, ho, wo)),
                        }
                    };
                    for (j, s) in sums.iter().enumerate() {
                        let at = ((cb * CO + j) * cin + ci) * kk + t0;
                        for (w, v) in dw[at..][..n].iter_mut().zip(s) {
                            *w += v;
                        }
                    }
                    t0 += n;
                }
            }
        }
    }

    /// A group's sums widened to three (the unused ones never read).
    fn widen<const T: usize>(s: [f32; T]) -> [f32; 3] {
        let mut out = [0.0; 3];
        out[..T].copy_from_slice(&s);
        out
    }

    /// `Σ_(oy, ox) d[j, oy·Wo + ox] · xp[base + offs[t] + oy·wq + ox]` for
    /// the 4 channels `j` of `d` and the first `T` taps of `offs`: 4·T
    /// accumulators, 8 positions at a time.
    ///
    /// # Safety
    /// The CPU has AVX and FMA; every `base + offs[t] + oy·wq + ox + 7` read
    /// is inside `xp`; `d` holds 4 rows of `Ho·Wo`, `Wo` a multiple of 8.
    #[target_feature(enable = "avx,fma")]
    #[inline]
    unsafe fn group<const T: usize>(
        xp: &[f32],
        base: usize,
        offs: &[usize],
        wq: usize,
        d: &[f32],
        ho: usize,
        wo: usize,
    ) -> [[f32; T]; CO] {
        let outs = ho * wo;
        let mut acc = [[_mm256_setzero_ps(); T]; CO];
        // Loops, not closures: a closure would not inherit this function's
        // target features, and its intrinsics would not be inlined.
        let mut xs = [xp.as_ptr(); T];
        for (t, p) in xs.iter_mut().enumerate() {
            // SAFETY: inside `xp` (this function's contract).
            *p = unsafe { p.add(base + offs[t]) };
        }
        let ds = d.as_ptr();
        let mut xv = [_mm256_setzero_ps(); T];
        for oy in 0..ho {
            let (xrow, drow) = (oy * wq, oy * wo);
            for ox in (0..wo).step_by(GX) {
                // SAFETY: the 8 values from each `xs[t] + xrow + ox` are
                // inside `xp`, those from `ds + j·outs + drow + ox` inside `d`.
                unsafe {
                    for (v, p) in xv.iter_mut().zip(&xs) {
                        *v = _mm256_loadu_ps(p.add(xrow + ox));
                    }
                    for (j, a) in acc.iter_mut().enumerate() {
                        let dv = _mm256_loadu_ps(ds.add(j * outs + drow + ox));
                        for (a, &x) in a.iter_mut().zip(&xv) {
                            *a = _mm256_fmadd_ps(dv, x, *a);
                        }
                    }
                }
            }
        }
        let mut sums = [[0.0; T]; CO];
        for (s, a) in sums.iter_mut().zip(&acc) {
            for (s, &v) in s.iter_mut().zip(a) {
                // SAFETY: the CPU has AVX (this function's contract).
                *s = unsafe { hsum(v) };
            }
        }
        sums
    }

    /// The sum of a vector's eight lanes.
    ///
    /// # Safety
    /// The CPU has AVX.
    #[target_feature(enable = "avx,fma")]
    #[inline]
    unsafe fn hsum(v: __m256) -> f32 {
        let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
        let s = _mm_add_ps(s, _mm_movehl_ps(s, s));
        let s = _mm_add_ss(s, _mm_shuffle_ps(s, s, 1));
        _mm_cvtss_f32(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both kernels against their definitions on views of a plain array,
    /// with 5 taps at arbitrary offsets (the weight gradient's groups of 3
    /// and 2, which no layer of the model has) and 16, 8 and 12 output
    /// channels (blocks of 6 + 6 + 4, 4 + 4, 6 + 6).
    #[test]
    fn kernels_match_their_definitions() {
        if !cpu() {
            return;
        }
        let (cin, ho, wo, wq) = (3, 3, 16, 19);
        let taps = [0, 1, 2, wq, wq + 3];
        let plane = (ho + 1) * wq + 3;
        let views = Views {
            plane,
            wq,
            taps: &taps,
        };
        let mut rng = fastrand::Rng::with_seed(11);
        let xp: Vec<f32> = (0..cin * plane).map(|_| rng.f32() - 0.5).collect();
        let at =
            |ci: usize, t: usize, oy: usize, ox: usize| xp[ci * plane + taps[t] + oy * wq + ox];
        let outs = ho * wo;
        for cout in [16, 8, 12] {
            let kk = taps.len();
            let w: Vec<f32> = (0..cout * cin * kk).map(|_| rng.f32() - 0.5).collect();
            let b: Vec<f32> = (0..cout).map(|_| rng.f32()).collect();
            let wat = |co: usize, ci: usize, t: usize| w[(co * cin + ci) * kk + t];
            let packed = pack(cout, cin, kk, |t, co, ci| wat(co, ci, t));
            // SAFETY: `forward` writes every value.
            let y = unsafe {
                crate::flex::written(cout * outs, |y| {
                    forward(&xp, views, cin, &packed, &b, ho, wo, y)
                })
            };
            let dy: Vec<f32> = (0..cout * outs).map(|_| rng.f32() - 0.5).collect();
            let mut dw = vec![0.0; cout * cin * kk];
            weight_grad(&xp, views, cin, &dy, ho, wo, &mut dw);
            for co in 0..cout {
                for p in 0..outs {
                    let (oy, ox) = (p / wo, p % wo);
                    let mut want = b[co];
                    for ci in 0..cin {
                        for t in 0..kk {
                            want += wat(co, ci, t) * at(ci, t, oy, ox);
                        }
                    }
                    let got = y[co * outs + p];
                    assert!(
                        (got - want).abs() < 1e-4,
                        "cout {cout} y[{co}, {p}]: {got} against {want}"
                    );
                }
                for ci in 0..cin {
                    for t in 0..kk {
                        let want: f32 = (0..outs)
                            .map(|p| dy[co * outs + p] * at(ci, t, p / wo, p % wo))
                            .sum();
                        let got = dw[(co * cin + ci) * kk + t];
                        assert!(
                            (got - want).abs() < 1e-4,
                            "cout {cout} dw[{co}, {ci}, {t}]: {got} against {want}"
                        );
                    }
                }
            }
        }
    }

    /// A view past the input is refused before any load.
    #[test]
    #[should_panic(expected = "reaches past the input")]
    fn refuses_a_view_past_the_input() {
        if !cpu() {
            panic!("reaches past the input (no AVX here: nothing to test)");
        }
        let views = Views {
            plane: 20,
            wq: 16,
            taps: &[0, 5],
        };
        let (xp, dy) = (vec![0.0; 20], vec![0.0; 4 * 16]);
        weight_grad(&xp, views, 1, &dy, 1, 16, &mut [0.0; 8]);
    }
}
