//! A direct, register-blocked convolution kernel for the training path on
//! x86-64 with AVX and FMA: the forward pass (and the stride-1 input
//! gradient) of `conv_train`'s layers that read a zero-padded, possibly
//! phase-split input (`conv_train::Shifted`) and whose output rows are a
//! multiple of 16 wide (the depth encoder's 64², 32² and 16² stages, the RGB
//! encoder's first three layers, the first layers of both).
//!
//! Through faer, such a layer is k² products with an inner dimension of
//! `Cin` (16–64), each reading and adding into the whole output (the 1- and
//! 3-channel first layers one stacked product per band): the
//! 16-channel layers ran at about 27 GFLOP/s where wider products reach 50
//! (docs/performance.md). Here each block of 4 output channels × 16
//! positions of a row stays in eight registers while all `Cin·k²` taps are
//! added into it, so the output is written once.
//!
//! It owns nothing but the arithmetic: `conv_train` builds the input and
//! says where each tap's view starts; other geometries and other CPUs keep
//! `conv_train`'s products.

/// Output channels per register block.
const CO: usize = 4;
/// Output positions per register block (two 8-wide vectors).
const PX: usize = 16;

/// Whether the kernel covers a layer with `cout` output channels and
/// output rows `wo` wide on this CPU: multiples of [`CO`] and [`PX`].
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

/// The weights `tap(t)[co, ci]` of `taps` taps packed for the kernel:
/// `[Cout/4][Cin][taps][4]`, the four output channels of a block side by
/// side.
pub(crate) fn pack(
    cout: usize,
    cin: usize,
    taps: usize,
    tap: impl Fn(usize, usize, usize) -> f32,
) -> Vec<f32> {
    let mut out = Vec::with_capacity(cout * cin * taps);
    for cb in 0..cout / CO {
        for ci in 0..cin {
            for t in 0..taps {
                out.extend((0..CO).map(|j| tap(t, cb * CO + j, ci)));
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
/// from [`pack`].
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
    y: &mut [f32],
) {
    let cout = b.len();
    assert!(covers(cout, wo), "conv_direct: a layer it does not cover");
    assert!(cin > 0 && ho > 0, "conv_direct: an empty layer");
    // The last value any view reads, computed without wrapping: the bound
    // the unchecked loads rely on.
    let last = (cin - 1)
        .checked_mul(views.plane)
        .zip((ho - 1).checked_mul(views.wq))
        .and_then(|(a, b)| a.checked_add(b))
        .and_then(|v| v.checked_add(*views.taps.iter().max()?))
        .and_then(|v| v.checked_add(wo - 1))
        .expect("conv_direct: views beyond the address space");
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

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{CO, PX, Views};
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
        y: &mut [f32],
    ) {
        let (kk, outs) = (views.taps.len(), ho * wo);
        for cb in 0..b.len() / CO {
            let w = &packed[cb * cin * kk * CO..][..cin * kk * CO];
            let bias = &b[cb * CO..][..CO];
            for oy in 0..ho {
                for ox in (0..wo).step_by(PX) {
                    let to = cb * CO * outs + oy * wo + ox;
                    // SAFETY: the values read are at most `forward`'s `last`.
                    unsafe { block(xp, views, cin, w, bias, oy * views.wq + ox, y, outs, to) };
                }
            }
        }
    }

    /// Four output channels × 16 positions: eight accumulators over all of
    /// `Cin`'s taps, then the bias, stored once.
    ///
    /// # Safety
    /// The CPU has AVX and FMA; for every channel `ci` and tap offset `off`,
    /// `ci·plane + at + off + 15` is inside `xp`; `w` holds `Cin·taps·4`
    /// weights.
    #[target_feature(enable = "avx,fma")]
    #[allow(clippy::too_many_arguments)]
    #[inline]
    unsafe fn block(
        xp: &[f32],
        views: Views<'_>,
        cin: usize,
        w: &[f32],
        bias: &[f32],
        at: usize,
        y: &mut [f32],
        outs: usize,
        to: usize,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; CO];
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
                    ws = ws.add(CO);
                }
            }
        }
        for (j, a) in acc.iter().enumerate() {
            let bj = _mm256_set1_ps(bias[j]);
            let out = &mut y[to + j * outs..][..PX];
            unsafe {
                _mm256_storeu_ps(out.as_mut_ptr(), _mm256_add_ps(a[0], bj));
                _mm256_storeu_ps(out.as_mut_ptr().add(8), _mm256_add_ps(a[1], bj));
            }
        }
    }
}
