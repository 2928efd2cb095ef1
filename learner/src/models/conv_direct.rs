//! A direct, register-blocked kernel for the stride-1 3×3 convolutions of
//! the training path on x86-64 with AVX and FMA (`conv_train`'s shifted
//! layers whose output rows are a multiple of 16 wide: the depth encoder's
//! 64², 32² and 16² stages, and their input gradients).
//!
//! Through faer, such a layer is nine products with an inner dimension of
//! `Cin` (16–64), each reading and writing the whole output: the 16-channel
//! layers ran at about 27 GFLOP/s where wider products reach 50
//! (docs/performance.md). Here each block of 4 output channels × 16
//! positions of a row stays in eight registers while all `Cin·9` taps are
//! added into it, so the output is written once.
//!
//! It reads the zero-padded input `conv_train` already builds (padding 1,
//! rows `wo + 2` apart) and owns nothing else; other geometries and other
//! CPUs keep `conv_train`'s products.

/// Output channels per register block.
const CO: usize = 4;
/// Output positions per register block (two 8-wide vectors).
const PX: usize = 16;

/// Whether the kernel covers a layer (stride 1, kernel 3, padding 1, output
/// rows a multiple of [`PX`], output channels a multiple of [`CO`]) on this
/// CPU.
pub(crate) fn covers(k: usize, stride: usize, pad: usize, cout: usize, wo: usize) -> bool {
    k == 3 && stride == 1 && pad == 1 && cout.is_multiple_of(CO) && wo.is_multiple_of(PX) && cpu()
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

/// The weights `tap(t)[co, ci]` (`t = ky·3 + kx`) packed for the kernel:
/// `[Cout/4][Cin][9][4]`, the four output channels of a block side by side.
pub(crate) fn pack(cout: usize, cin: usize, tap: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
    let mut out = Vec::with_capacity(cout * cin * 9);
    for cb in 0..cout / CO {
        for ci in 0..cin {
            for t in 0..9 {
                out.extend((0..CO).map(|j| tap(t, cb * CO + j, ci)));
            }
        }
    }
    out
}

/// One sample: `y [Cout, Ho·Wo] = W ⊛ xp + b`, with `xp` the padded input
/// `[Cin][plane]` (rows `wo + 2` apart, at least `Ho + 2` rows per plane)
/// and `packed` from [`pack`].
///
/// # Panics
/// If the buffers are smaller than the shapes say, or [`covers`] is false
/// for this layer.
#[allow(clippy::too_many_arguments)]
pub(crate) fn forward(
    xp: &[f32],
    plane: usize,
    cin: usize,
    packed: &[f32],
    b: &[f32],
    ho: usize,
    wo: usize,
    y: &mut [f32],
) {
    let cout = b.len();
    assert!(
        covers(3, 1, 1, cout, wo),
        "conv_direct: a layer it does not cover"
    );
    let wq = wo + 2;
    assert!(
        plane >= (ho + 2) * wq && xp.len() >= cin * plane,
        "conv_direct: input too short"
    );
    assert!(packed.len() == cout * cin * 9 && y.len() == cout * ho * wo);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `covers` checked AVX and FMA; the asserts above bound every
    // index the kernel reads or writes (see `block`).
    unsafe {
        avx::forward(xp, plane, cin, packed, b, ho, wo, y)
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!()
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{CO, PX};
    use std::arch::x86_64::*;

    #[target_feature(enable = "avx,fma")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn forward(
        xp: &[f32],
        plane: usize,
        cin: usize,
        packed: &[f32],
        b: &[f32],
        ho: usize,
        wo: usize,
        y: &mut [f32],
    ) {
        let (wq, outs) = (wo + 2, ho * wo);
        for cb in 0..b.len() / CO {
            let w = &packed[cb * cin * 9 * CO..][..cin * 9 * CO];
            let bias = &b[cb * CO..][..CO];
            for oy in 0..ho {
                for ox in (0..wo).step_by(PX) {
                    let (at, to) = (oy * wq + ox, cb * CO * outs + oy * wo + ox);
                    // SAFETY: within plane ci the highest value read is at
                    // (oy + 2)·wq + ox + 2 + 15 ≤ (ho + 2)·wq − 1 < plane
                    // (ox + 16 ≤ wo = wq − 2); the values written are y's.
                    unsafe { block(xp, plane, wq, cin, w, bias, at, y, outs, to) };
                }
            }
        }
    }

    /// Four output channels × 16 positions: eight accumulators over all of
    /// `Cin`'s nine taps, then the bias, stored once.
    #[target_feature(enable = "avx,fma")]
    #[allow(clippy::too_many_arguments)]
    #[inline]
    unsafe fn block(
        xp: &[f32],
        plane: usize,
        wq: usize,
        cin: usize,
        w: &[f32],
        bias: &[f32],
        at: usize,
        y: &mut [f32],
        outs: usize,
        to: usize,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; CO];
        let (xs, ws) = (xp.as_ptr(), w.as_ptr());
        for ci in 0..cin {
            for ky in 0..3 {
                for kx in 0..3 {
                    unsafe {
                        let p = xs.add(ci * plane + at + ky * wq + kx);
                        let (v0, v1) = (_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
                        let wt = ws.add((ci * 9 + ky * 3 + kx) * CO);
                        for (j, a) in acc.iter_mut().enumerate() {
                            let wj = _mm256_broadcast_ss(&*wt.add(j));
                            a[0] = _mm256_fmadd_ps(wj, v0, a[0]);
                            a[1] = _mm256_fmadd_ps(wj, v1, a[1]);
                        }
                    }
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
