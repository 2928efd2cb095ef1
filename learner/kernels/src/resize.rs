//! The decoders' bilinear upsampling (aligned corners, by an integer
//! factor) as one operation with its own backward pass.
//!
//! burn's GPU backends have no backward pass for `interpolate`, so the
//! decoders upsample by two products with constant interpolation matrices,
//! `U_h · X · U_wᵀ`, which differentiate everywhere. On `flex` that form is
//! two products, two transposes and fresh `[B·C·H·f, W·f]` buffers per pass,
//! mostly on one thread: the flow's ×4 to `[64, 3, 128, 128]` was among the
//! serial parts of a training step (docs/performance.md). [`ResizeTrain`] is
//! a burn backend extension: `flex` gets one pass each way over each plane,
//! the planes split over rayon's threads; the GPU backends (burn's `Cube`)
//! keep the products through the trait's default bodies.

use crate::flex::{f32s, flex_tensor, written};
use crate::kernel_settings;
use burn::backend::autodiff::{
    Autodiff,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, Flex, TensorMetadata, backend_extension, flex::FlexTensor};
use burn::prelude::*;
use burn::tensor::{Shape, TensorData};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Bilinear upsampling of `x [B, C, H, W]` by the integer `factor` with
/// aligned corners (the map of burn's `interpolate(.., Bilinear,
/// align_corners)`), differentiable: one operation with its own backward
/// pass ([`ResizeTrain`]; on the GPU backends two products with constant
/// interpolation matrices, `U_h · X · U_wᵀ`: burn's GPU backends have no
/// backward pass for `interpolate`). Under
/// [`KernelChoice::Burn`](crate::KernelChoice) those products of burn's
/// operations, tracked one by one.
pub fn upsample_bilinear(x: Tensor<4>, factor: usize) -> Tensor<4> {
    let x = x.into_dispatch();
    Tensor::from_dispatch(if kernel_settings().burns_own() {
        products::<Dispatch>(x, factor, false)
    } else {
        <Dispatch as ResizeTrain>::upsample_train(x, factor)
    })
}

/// Bilinear upsampling with aligned corners, differentiable.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait ResizeTrain: Backend {
    /// `x [B, C, H, W]` → `[B, C, H·factor, W·factor]`: output `(i, j)` is
    /// the input interpolated at `(i (H − 1)/(H·f − 1), j (W − 1)/(W·f − 1))`.
    fn upsample_train(x: FloatTensor<Self>, factor: usize) -> FloatTensor<Self> {
        products::<Self>(x, factor, false)
    }

    /// The input gradient of [`ResizeTrain::upsample_train`] from the
    /// output's, `grad [B, C, H·f, W·f]` → `[B, C, H, W]` (the adjoint map).
    fn upsample_train_backward(grad: FloatTensor<Self>, factor: usize) -> FloatTensor<Self> {
        products::<Self>(grad, factor, true)
    }
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl ResizeTrain for burn::backend::Cube {}

/// `Uᵀ`, row-major `[n_in, n_out]`, of linear interpolation from `n_in` to
/// `n_out` samples with aligned corners (its columns are [`taps`]).
fn interpolation_matrix_t(n_in: usize, n_out: usize) -> Vec<f32> {
    let mut u = vec![0.0f32; n_in * n_out];
    for (i, (i0, i1, frac)) in taps(n_in, n_out).into_iter().enumerate() {
        u[i0 * n_out + i] += 1.0 - frac;
        u[i1 * n_out + i] += frac;
    }
    u
}

/// For each of `n_out` samples, the two input samples it lies between and
/// its weight on the second: output `i` sits at input coordinate
/// `i (n_in − 1)/(n_out − 1)`.
fn taps(n_in: usize, n_out: usize) -> Vec<(usize, usize, f32)> {
    (0..n_out)
        .map(|i| {
            let src = if n_out > 1 {
                i as f64 * (n_in - 1) as f64 / (n_out - 1) as f64
            } else {
                0.0
            };
            let i0 = (src.floor() as usize).min(n_in - 1);
            let i1 = (i0 + 1).min(n_in - 1);
            (i0, i1, (src - i0 as f64) as f32)
        })
        .collect()
}

/// A `[B, C, H, W]` shape and a factor of at least 1, checked.
fn dims4(shape: &[usize], factor: usize) -> [usize; 4] {
    assert!(factor >= 1, "upsampling: a factor of 0");
    let dims = crate::flex::dims4("upsampling", "a tensor", shape);
    assert!(
        dims.iter().all(|&d| d > 0),
        "upsampling: an empty tensor of shape {shape:?}"
    );
    dims
}

/// The products form of `B`'s primitives: `x [B, C, H, W]` upsampled by
/// `factor` (`U_h · X · U_wᵀ` per plane), or with `adjoint` a gradient
/// `[B, C, H·f, W·f]` taken back (`U_hᵀ · G · U_w`). The GPU backends' both
/// ways, and flex's for other dtypes than f32.
fn products<B: Backend>(x: FloatTensor<B>, factor: usize, adjoint: bool) -> FloatTensor<B> {
    let [b, c, h, w] = dims4(&x.shape().to_vec(), factor);
    let (ho, wo) = if adjoint {
        assert!(
            h.is_multiple_of(factor) && w.is_multiple_of(factor),
            "upsampling: a gradient of {h}×{w} for a factor of {factor}"
        );
        (h / factor, w / factor)
    } else {
        (h * factor, w * factor)
    };
    let device = x.device();
    // The matrix that takes a row of `w` values to one of `wo`, as `[w, wo]`.
    let matrix = |n: usize, n_out: usize| {
        let m = if adjoint {
            // `U` itself: the transpose of the forward map's `Uᵀ`.
            let t = interpolation_matrix_t(n_out, n);
            let mut u = vec![0.0f32; n * n_out];
            for r in 0..n_out {
                for k in 0..n {
                    u[k * n_out + r] = t[r * n + k];
                }
            }
            u
        } else {
            interpolation_matrix_t(n, n_out)
        };
        B::float_from_data(TensorData::new(m, [n, n_out]), &device)
    };
    let rows = B::float_matmul(
        B::float_reshape(x, Shape::new([b * c * h, w])),
        matrix(w, wo),
    );
    let cols = B::float_reshape(
        B::float_swap_dims(B::float_reshape(rows, Shape::new([b * c, h, wo])), 1, 2),
        Shape::new([b * c * wo, h]),
    );
    let y = B::float_matmul(cols, matrix(h, ho));
    B::float_reshape(
        B::float_swap_dims(B::float_reshape(y, Shape::new([b * c, wo, ho])), 1, 2),
        Shape::new([b, c, ho, wo]),
    )
}

impl ResizeTrain for Flex {
    fn upsample_train(x: FlexTensor, factor: usize) -> FlexTensor {
        let [b, c, h, w] = dims4(&x.shape().to_vec(), factor);
        let Some(xc) = f32s(&x) else {
            return products::<Flex>(x, factor, false);
        };
        let (ho, wo) = (h * factor, w * factor);
        let (rows, cols) = (taps(h, ho), taps(w, wo));
        let src = xc.storage::<f32>();
        let fill = |y: &mut [MaybeUninit<f32>]| {
            y.par_chunks_mut(ho * wo)
                .zip(src.par_chunks(h * w))
                .for_each_init(
                    || vec![0.0f32; h * wo],
                    |across, (y, x)| {
                        // Each input row interpolated across, then the
                        // output rows blended from two of those.
                        for (a, xr) in across.chunks_exact_mut(wo).zip(x.chunks_exact(w)) {
                            for (v, &(j0, j1, f)) in a.iter_mut().zip(&cols) {
                                *v = xr[j0] * (1.0 - f) + xr[j1] * f;
                            }
                        }
                        for (yr, &(i0, i1, f)) in y.chunks_exact_mut(wo).zip(&rows) {
                            let (a0, a1) = (&across[i0 * wo..][..wo], &across[i1 * wo..][..wo]);
                            for ((v, &p), &q) in yr.iter_mut().zip(a0).zip(a1) {
                                v.write(p * (1.0 - f) + q * f);
                            }
                        }
                    },
                )
        };
        // SAFETY: `y` holds `B·C` planes of `Ho·Wo`, `src` as many of `H·W`;
        // every output row of every plane is written whole.
        let y = unsafe { written(b * c * ho * wo, fill) };
        flex_tensor(y, vec![b, c, ho, wo])
    }

    fn upsample_train_backward(grad: FlexTensor, factor: usize) -> FlexTensor {
        let [b, c, ho, wo] = dims4(&grad.shape().to_vec(), factor);
        assert!(
            ho.is_multiple_of(factor) && wo.is_multiple_of(factor),
            "upsampling: a gradient of {ho}×{wo} for a factor of {factor}"
        );
        let Some(gc) = f32s(&grad) else {
            return products::<Flex>(grad, factor, true);
        };
        let (h, w) = (ho / factor, wo / factor);
        let (rows, cols) = (taps(h, ho), taps(w, wo));
        let gs = gc.storage::<f32>();
        let fill = |dx: &mut [MaybeUninit<f32>]| {
            dx.par_chunks_mut(h * w)
                .zip(gs.par_chunks(ho * wo))
                .for_each_init(
                    || (vec![0.0f32; h * wo], vec![0.0f32; w]),
                    |(across, row), (dx, g)| {
                        // The blend's adjoint: each output row's gradient
                        // into its two input rows, then across.
                        across.fill(0.0);
                        for (gr, &(i0, i1, f)) in g.chunks_exact(wo).zip(&rows) {
                            for (a, &v) in across[i0 * wo..][..wo].iter_mut().zip(gr) {
                                *a += v * (1.0 - f);
                            }
                            for (a, &v) in across[i1 * wo..][..wo].iter_mut().zip(gr) {
                                *a += v * f;
                            }
                        }
                        for (dr, a) in dx.chunks_exact_mut(w).zip(across.chunks_exact(wo)) {
                            row.fill(0.0);
                            for (&v, &(j0, j1, f)) in a.iter().zip(&cols) {
                                row[j0] += v * (1.0 - f);
                                row[j1] += v * f;
                            }
                            dr.write_copy_of_slice(row);
                        }
                    },
                )
        };
        // SAFETY: `dx` holds `B·C` planes of `H·W`, `gs` as many of `Ho·Wo`;
        // every row of every plane is written whole.
        let dx = unsafe { written(b * c * h * w, fill) };
        flex_tensor(dx, vec![b, c, h, w])
    }
}

impl<B: Backend + ResizeTrain, C: CheckpointStrategy> ResizeTrain for Autodiff<B, C> {
    fn upsample_train(x: FloatTensor<Self>, factor: usize) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct UpsampleBackward;

        impl<B: Backend + ResizeTrain> Backward<B, 1> for UpsampleBackward {
            type State = usize;

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_x] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                if let Some(node) = node_x {
                    grads.register::<B>(node.id, B::upsample_train_backward(grad, ops.state));
                }
            }
        }

        match UpsampleBackward
            .prepare::<C>([x.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                prep.finish(factor, B::upsample_train(x.into_primitive(), factor))
            }
            OpsKind::UnTracked(prep) => prep.finish(B::upsample_train(x.into_primitive(), factor)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Dispatch;

    /// flex's passes against the products form (the GPU backends' default
    /// bodies, run on flex's primitives), forward and adjoint, on the
    /// shapes of the decoders' test (non-square, one pixel high, one pixel
    /// square) and the flow's ×4 at 32²; the adjoint checked as one:
    /// `⟨up(x), g⟩ = ⟨x, up*(g)⟩`.
    #[test]
    fn the_passes_match_the_products_and_are_adjoint() {
        let cases = [
            ([2, 3, 5, 7], 2),
            ([2, 3, 5, 7], 4),
            ([1, 2, 1, 3], 2),
            ([1, 2, 1, 1], 2),
            ([2, 2, 32, 32], 4),
        ];
        let mut rng = fastrand::Rng::with_seed(12);
        let flex = |v: &[f32], shape: [usize; 4]| {
            FlexTensor::from_data(TensorData::new(v.to_vec(), shape))
        };
        let values = |t: FlexTensor| t.into_data().try_to_vec::<f32>().expect("f32 values");
        for (shape, f) in cases {
            let [b, c, h, w] = shape;
            let out = [b, c, h * f, w * f];
            let x: Vec<f32> = (0..b * c * h * w).map(|_| rng.f32() * 2.0 - 1.0).collect();
            let g: Vec<f32> = (0..out.iter().product())
                .map(|_| rng.f32() * 2.0 - 1.0)
                .collect();
            let ours = values(Flex::upsample_train(flex(&x, shape), f));
            let theirs = values(products::<Flex>(flex(&x, shape), f, false));
            let back = values(Flex::upsample_train_backward(flex(&g, out), f));
            let back_theirs = values(products::<Flex>(flex(&g, out), f, true));
            for (what, a, t) in [
                ("forward", &ours, &theirs),
                ("adjoint", &back, &back_theirs),
            ] {
                assert_eq!(a.len(), t.len(), "{shape:?} ×{f} {what}");
                for (i, (p, q)) in a.iter().zip(t).enumerate() {
                    assert!(
                        (p - q).abs() < 1e-5,
                        "{shape:?} ×{f} {what} {i}: {p} against {q}"
                    );
                }
            }
            let dot =
                |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(p, q)| f64::from(p * q)).sum::<f64>();
            let (lhs, rhs) = (dot(&ours, &g), dot(&x, &back));
            assert!(
                (lhs - rhs).abs() < 1e-4 * (1.0 + lhs.abs()),
                "{shape:?} ×{f}: {lhs} against {rhs}"
            );
        }
    }

    /// Through autodiff: the input gradient is the adjoint pass's.
    #[test]
    fn autodiff_takes_the_adjoint_pass() {
        let device = Device::flex().autodiff();
        let (shape, f) = ([1, 2, 3, 4], 2);
        let n: usize = shape.iter().product();
        let x: Vec<f32> = (0..n).map(|i| i as f32 * 0.3 - 1.0).collect();
        let wv: Vec<f32> = (0..4 * n).map(|i| (i % 7) as f32 - 3.0).collect();
        let xt = Tensor::<4>::from_data(TensorData::new(x, shape), &device).require_grad();
        let wt = Tensor::<4>::from_data(TensorData::new(wv.clone(), [1, 2, 6, 8]), &device);
        let y = Tensor::<4>::from_dispatch(<Dispatch as ResizeTrain>::upsample_train(
            xt.clone().into_dispatch(),
            f,
        ));
        let grads = (y * wt).sum().backward();
        let got = xt
            .grad(&grads)
            .expect("x's gradient")
            .try_into_vec_as::<f32>()
            .expect("f32");
        let want = Flex::upsample_train_backward(
            FlexTensor::from_data(TensorData::new(wv, [1, 2, 6, 8])),
            f,
        )
        .into_data()
        .try_to_vec::<f32>()
        .expect("f32");
        assert_eq!(got, want);
    }
}
