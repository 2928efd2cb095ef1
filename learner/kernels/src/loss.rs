//! Binary cross-entropy with logits, and the flow's endpoint error, each as
//! one operation with its own backward pass.
//!
//! The stable form `max(x, 0) − x·y + ln(1 + e^−|x|)` of burn's primitives
//! is nine elementwise passes forward and as many backward, each a fresh
//! tensor and each on one thread in `flex`; on the flow mask's logits
//! (`[B, 1, 128, 128]`) they were among the serial parts of a training
//! step (docs/performance.md). [`LossTrain`] is a burn backend extension:
//! `flex` gets one pass each way, split over rayon's threads; the GPU
//! backends (burn's `Cube`) keep the composition through the trait's default
//! bodies. The endpoint error on the flow at full size (`[B, 2, 128, 128]`)
//! was six such passes forward and about as many backward, so it is one
//! each way too. The targets are data: no gradient flows to them.

use crate::flex::CHUNK;
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
use burn::tensor::Shape;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Binary cross-entropy of `logits` against 0/1 `targets`, elementwise, in
/// the stable form `max(x, 0) − x·y + ln(1 + e^−|x|)`: one operation with
/// its own backward pass ([`LossTrain`]); the targets get no gradient.
/// Under [`KernelChoice::Burn`](crate::KernelChoice) the same form of
/// burn's primitives.
pub fn bce_with_logits<const D: usize>(logits: Tensor<D>, targets: Tensor<D>) -> Tensor<D> {
    let (x, y) = (logits.into_dispatch(), targets.into_dispatch());
    Tensor::from_dispatch(if kernel_settings().burns_own() {
        composed::<Dispatch>(x, y)
    } else {
        <Dispatch as LossTrain>::bce_train(x, y)
    })
}

/// Per-sample average endpoint error of the flow `pred` against `target`,
/// both `[B, 2, S, S]`: the mean over pixels of `sqrt(Δu² + Δv² + eps)`,
/// `[B]` (`eps` keeps the square root differentiable at zero). One
/// operation with its own backward pass ([`LossTrain`]); the target gets
/// no gradient. Under [`KernelChoice::Burn`](crate::KernelChoice) the same
/// formula of burn's primitives.
pub fn endpoint_error(pred: Tensor<4>, target: Tensor<4>, eps: f32) -> Tensor<1> {
    let (p, t) = (pred.into_dispatch(), target.into_dispatch());
    Tensor::from_dispatch(if kernel_settings().burns_own() {
        epe_composed::<Dispatch>(p, t, eps)
    } else {
        <Dispatch as LossTrain>::epe_train(p, t, eps)
    })
}

/// Elementwise binary cross-entropy of logits against targets, and the
/// flow's endpoint error, each differentiable in its prediction.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait LossTrain: Backend {
    /// `max(x, 0) − x·y + ln(1 + e^−|x|)` for logits `x` and targets `y`.
    fn bce_train(x: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        composed::<Self>(x, y)
    }

    /// The gradient with respect to the logits: `grad·(σ(x) − y)`.
    fn bce_train_backward(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        composed_backward::<Self>(x, y, grad)
    }

    /// The per-sample mean endpoint error `[B]` of the flow `pred` against
    /// `target`, both `[B, 2, H, W]`: the mean over pixels of
    /// `√(Σ_c (pred − target)_c² + eps)`.
    fn epe_train(
        pred: FloatTensor<Self>,
        target: FloatTensor<Self>,
        eps: f32,
    ) -> FloatTensor<Self> {
        epe_composed::<Self>(pred, target, eps)
    }

    /// The gradient in `pred` for the per-sample gradient `grad` `[B]`:
    /// `grad_b · d / (H·W · √(Σ_c d_c² + eps))`, `d = pred − target`.
    fn epe_train_backward(
        pred: FloatTensor<Self>,
        target: FloatTensor<Self>,
        eps: f32,
        grad: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        epe_composed_backward::<Self>(pred, target, eps, grad)
    }
}

/// A flow's `[B, 2, H, W]`, checked.
fn flow_dims(shape: &[usize]) -> [usize; 3] {
    match crate::flex::dims4("endpoint error", "a flow", shape) {
        [b, 2, h, w] => [b, h, w],
        _ => panic!("endpoint error: a flow of shape {shape:?}, not two channels"),
    }
}

/// Each pixel's `√(Σ_c d_c² + eps)` of `B`'s primitives, `[B, 1, H, W]`, and `d`.
fn epe_norms<B: Backend>(
    pred: FloatTensor<B>,
    target: FloatTensor<B>,
    eps: f32,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let d = B::float_sub(pred, target);
    let sq = B::float_sum_dim(B::float_mul(d.clone(), d.clone()), 1);
    (B::float_sqrt(B::float_add_scalar(sq, eps.into())), d)
}

/// The endpoint error of `B`'s primitives: the GPU backends', and flex's
/// for other dtypes than f32.
fn epe_composed<B: Backend>(
    pred: FloatTensor<B>,
    target: FloatTensor<B>,
    eps: f32,
) -> FloatTensor<B> {
    let [b, h, w] = flow_dims(&pred.shape().to_vec());
    let (r, _) = epe_norms::<B>(pred, target, eps);
    let r = B::float_reshape(r, Shape::new([b, h * w]));
    B::float_reshape(B::float_mean_dim(r, 1), Shape::new([b]))
}

/// [`epe_composed`]'s gradient in `pred`.
fn epe_composed_backward<B: Backend>(
    pred: FloatTensor<B>,
    target: FloatTensor<B>,
    eps: f32,
    grad: FloatTensor<B>,
) -> FloatTensor<B> {
    let [b, h, w] = flow_dims(&pred.shape().to_vec());
    let full = Shape::new([b, 2, h, w]);
    let (r, d) = epe_norms::<B>(pred, target, eps);
    let g = B::float_div_scalar(grad, ((h * w) as f32).into());
    let g = B::float_expand(B::float_reshape(g, Shape::new([b, 1, 1, 1])), full.clone());
    B::float_mul(B::float_div(d, B::float_expand(r, full)), g)
}

/// The stable form of `B`'s primitives: the GPU backends' cross-entropy,
/// flex's for other dtypes than f32, and the model's under
/// `KernelChoice::Burn` (where autodiff tracks each primitive).
fn composed<B: Backend>(x: FloatTensor<B>, y: FloatTensor<B>) -> FloatTensor<B> {
    let softplus = B::float_log(B::float_add_scalar(
        B::float_exp(B::float_neg(B::float_abs(x.clone()))),
        1.0.into(),
    ));
    let pos = B::float_clamp_min(x.clone(), 0.0.into());
    B::float_add(B::float_sub(pos, B::float_mul(x, y)), softplus)
}

/// [`composed`]'s gradient in the logits.
fn composed_backward<B: Backend>(
    x: FloatTensor<B>,
    y: FloatTensor<B>,
    grad: FloatTensor<B>,
) -> FloatTensor<B> {
    B::float_mul(grad, B::float_sub(B::sigmoid(x), y))
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl LossTrain for burn::backend::Cube {}

/// One value's cross-entropy, the stable form.
fn bce(x: f32, y: f32) -> f32 {
    x.max(0.0) - x * y + (-x.abs()).exp().ln_1p()
}

/// One sample's endpoint error: `p` and `t` its two planes of `n` pixels
/// each, side by side.
fn epe_sample(p: &[f32], t: &[f32], n: usize, eps: f32) -> f32 {
    let (p0, p1) = p.split_at(n);
    let (t0, t1) = t.split_at(n);
    let sum: f32 = p0
        .iter()
        .zip(p1)
        .zip(t0.iter().zip(t1))
        .map(|((&a0, &a1), (&b0, &b1))| {
            let (d0, d1) = (a0 - b0, a1 - b1);
            (d0 * d0 + d1 * d1 + eps).sqrt()
        })
        .sum();
    sum / n as f32
}

/// The flow's prediction and target as contiguous f32 values (their shapes
/// checked equal), or `None` for another dtype.
fn epe_inputs(pred: &FlexTensor, target: &FlexTensor) -> Option<(FlexTensor, FlexTensor)> {
    assert_eq!(
        pred.shape().to_vec(),
        target.shape().to_vec(),
        "endpoint error: prediction and target differ in shape"
    );
    Some((f32s(pred)?, f32s(target)?))
}

impl LossTrain for Flex {
    fn epe_train(pred: FlexTensor, target: FlexTensor, eps: f32) -> FlexTensor {
        let [b, h, w] = flow_dims(&pred.shape().to_vec());
        let Some((pc, tc)) = epe_inputs(&pred, &target) else {
            return epe_composed::<Flex>(pred, target, eps);
        };
        let (ps, ts, n) = (pc.storage::<f32>(), tc.storage::<f32>(), h * w);
        let e: Vec<f32> = ps
            .par_chunks(2 * n)
            .zip(ts.par_chunks(2 * n))
            .map(|(p, t)| epe_sample(p, t, n, eps))
            .collect();
        flex_tensor(e, vec![b])
    }

    fn epe_train_backward(
        pred: FlexTensor,
        target: FlexTensor,
        eps: f32,
        grad: FlexTensor,
    ) -> FlexTensor {
        let [b, h, w] = flow_dims(&pred.shape().to_vec());
        let (Some((pc, tc)), Some(gc)) = (epe_inputs(&pred, &target), f32s(&grad)) else {
            return epe_composed_backward::<Flex>(pred, target, eps, grad);
        };
        let (ps, ts, gs, n) = (
            pc.storage::<f32>(),
            tc.storage::<f32>(),
            gc.storage::<f32>(),
            h * w,
        );
        assert_eq!(
            gs.len(),
            b,
            "endpoint error: a gradient of {} for {b} samples",
            gs.len()
        );
        let fill = |dp: &mut [MaybeUninit<f32>]| {
            dp.par_chunks_mut(2 * n)
                .zip(ps.par_chunks(2 * n).zip(ts.par_chunks(2 * n)))
                .zip(gs.par_iter())
                .for_each(|((d, (p, t)), &g)| {
                    let scale = g / n as f32;
                    let (d0, d1) = d.split_at_mut(n);
                    let ((p0, p1), (t0, t1)) = (p.split_at(n), t.split_at(n));
                    for (((o0, o1), (&a0, &a1)), (&b0, &b1)) in d0
                        .iter_mut()
                        .zip(d1.iter_mut())
                        .zip(p0.iter().zip(p1))
                        .zip(t0.iter().zip(t1))
                    {
                        let (e0, e1) = (a0 - b0, a1 - b1);
                        let k = scale / (e0 * e0 + e1 * e1 + eps).sqrt();
                        o0.write(k * e0);
                        o1.write(k * e1);
                    }
                })
        };
        // SAFETY: `dp`, `ps` and `ts` are `B·2·H·W` long (the shapes checked
        // equal) and `gs` `B`: every sample's chunk pairs up and is written whole.
        let dp = unsafe { written(ps.len(), fill) };
        flex_tensor(dp, vec![b, 2, h, w])
    }

    fn bce_train(x: FlexTensor, y: FlexTensor) -> FlexTensor {
        let (Some(xc), Some(yc)) = (f32s(&x), f32s(&y)) else {
            return composed::<Flex>(x, y);
        };
        let (xs, ys) = (xc.storage::<f32>(), yc.storage::<f32>());
        assert_eq!(
            xs.len(),
            ys.len(),
            "bce_train: logits and targets differ in size"
        );
        let fill = |l: &mut [MaybeUninit<f32>]| {
            l.par_chunks_mut(CHUNK)
                .zip(xs.par_chunks(CHUNK).zip(ys.par_chunks(CHUNK)))
                .for_each(|(d, (x, y))| {
                    for ((d, &x), &y) in d.iter_mut().zip(x).zip(y) {
                        d.write(bce(x, y));
                    }
                })
        };
        // SAFETY: the chunks of `l`, `xs` and `ys` pair up whole (the same
        // length, checked), and every value of each is written.
        let l = unsafe { written(xs.len(), fill) };
        flex_tensor(l, x.shape().to_vec())
    }

    fn bce_train_backward(x: FlexTensor, y: FlexTensor, grad: FlexTensor) -> FlexTensor {
        let (Some(xc), Some(yc), Some(gc)) = (f32s(&x), f32s(&y), f32s(&grad)) else {
            return composed_backward::<Flex>(x, y, grad);
        };
        let (xs, ys, gs) = (
            xc.storage::<f32>(),
            yc.storage::<f32>(),
            gc.storage::<f32>(),
        );
        assert!(
            xs.len() == ys.len() && xs.len() == gs.len(),
            "bce_train_backward: logits, targets and gradient differ in size"
        );
        let fill = |dx: &mut [MaybeUninit<f32>]| {
            dx.par_chunks_mut(CHUNK)
                .zip(xs.par_chunks(CHUNK).zip(ys.par_chunks(CHUNK)))
                .zip(gs.par_chunks(CHUNK))
                .for_each(|((d, (x, y)), g)| {
                    for (((d, &x), &y), &g) in d.iter_mut().zip(x).zip(y).zip(g) {
                        d.write(g * (1.0 / (1.0 + (-x).exp()) - y));
                    }
                })
        };
        // SAFETY: as in `bce_train`, the lengths checked above.
        let dx = unsafe { written(xs.len(), fill) };
        flex_tensor(dx, x.shape().to_vec())
    }
}

impl<B: Backend + LossTrain, C: CheckpointStrategy> LossTrain for Autodiff<B, C> {
    fn epe_train(
        pred: FloatTensor<Self>,
        target: FloatTensor<Self>,
        eps: f32,
    ) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct EpeBackward;

        impl<B: Backend + LossTrain> Backward<B, 1> for EpeBackward {
            type State = (FloatTensor<B>, FloatTensor<B>, f32);

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_pred] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (pred, target, eps) = ops.state;
                if let Some(node) = node_pred {
                    grads.register::<B>(node.id, B::epe_train_backward(pred, target, eps, grad));
                }
            }
        }

        // The target's node is not a parent: no gradient reaches it.
        let target = target.into_primitive();
        match EpeBackward
            .prepare::<C>([pred.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let pred = pred.into_primitive();
                let e = B::epe_train(pred.clone(), target.clone(), eps);
                prep.finish((pred, target, eps), e)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::epe_train(pred.into_primitive(), target, eps))
            }
        }
    }

    fn bce_train(x: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct BceBackward;

        impl<B: Backend + LossTrain> Backward<B, 1> for BceBackward {
            type State = (FloatTensor<B>, FloatTensor<B>);

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_x] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (x, y) = ops.state;
                if let Some(node) = node_x {
                    grads.register::<B>(node.id, B::bce_train_backward(x, y, grad));
                }
            }
        }

        // The targets' node is not a parent: no gradient reaches them.
        let y = y.into_primitive();
        match BceBackward
            .prepare::<C>([x.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let x = x.into_primitive();
                let l = B::bce_train(x.clone(), y.clone());
                prep.finish((x, y), l)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::bce_train(x.into_primitive(), y)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Dispatch;

    /// The endpoint error's values and gradient against the same formula of
    /// burn's tensor operations (tracked op by op by autodiff), on a flow of
    /// 3 samples with pixels of zero error among them (where `eps` keeps the
    /// gradient finite); the target gets no gradient; both backends' paths
    /// agree with plain arithmetic on one pixel.
    #[test]
    fn the_endpoint_error_matches_its_composition_and_its_gradient() {
        let device = Device::flex().autodiff();
        let (b, h, w) = (3, 5, 7);
        let n = b * 2 * h * w;
        let mut rng = fastrand::Rng::with_seed(8);
        let p: Vec<f32> = (0..n).map(|_| rng.f32() * 4.0 - 2.0).collect();
        let mut t: Vec<f32> = (0..n).map(|_| rng.f32() * 4.0 - 2.0).collect();
        // Sample 1's first pixel: no error in either component.
        let first = 2 * h * w;
        t[first] = p[first];
        t[first + h * w] = p[first + h * w];
        let sample_w = [0.5f32, 2.0, -1.0];
        let data =
            |v: &[f32]| Tensor::<4>::from_data(TensorData::new(v.to_vec(), [b, 2, h, w]), &device);
        let (pred, target) = (data(&p), data(&t));
        let weights = Tensor::<1>::from_floats(sample_w.as_slice(), &device);
        let eps = 1e-8f32;
        let run = |ours: bool| {
            let (pred, target) = (pred.clone().require_grad(), target.clone().require_grad());
            let e = if ours {
                Tensor::from_dispatch(<Dispatch as LossTrain>::epe_train(
                    pred.clone().into_dispatch(),
                    target.clone().into_dispatch(),
                    eps,
                ))
            } else {
                let d = pred.clone() - target.clone();
                (d.clone() * d)
                    .sum_dim(1)
                    .add_scalar(eps)
                    .sqrt()
                    .reshape([b as i32, -1])
                    .mean_dim(1)
                    .squeeze_dim(1)
            };
            let grads = (e.clone() * weights.clone()).sum().backward();
            let dp = pred.grad(&grads).expect("the prediction's gradient");
            (
                e.try_into_vec_as::<f32>().expect("f32 values"),
                dp.try_into_vec_as::<f32>().expect("f32 values"),
                target.grad(&grads).is_some(),
            )
        };
        let ((e1, dp1, dt1), (e2, dp2, _)) = (run(true), run(false));
        assert!(!dt1, "the target got a gradient");
        assert_eq!((e1.len(), dp1.len()), (b, n));
        for (what, a, c) in [("value", &e1, &e2), ("gradient", &dp1, &dp2)] {
            for (i, (x, &y)) in a.iter().zip(c.iter()).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                    "{what} {i}: {x} against {y}"
                );
            }
        }
        // Plain arithmetic: sample 0's gradient at its pixel 3, channel 1.
        let (i0, i1) = (3, h * w + 3);
        let (d0, d1) = (p[i0] - t[i0], p[i1] - t[i1]);
        let want = sample_w[0] / (h * w) as f32 * d1 / (d0 * d0 + d1 * d1 + eps).sqrt();
        assert!((dp1[i1] - want).abs() <= 1e-6, "{} against {want}", dp1[i1]);
        assert_eq!(dp1[first], 0.0, "a pixel of no error has no gradient");

        // The GPU backends' default bodies (`B`'s primitives), run on flex's.
        let flex = |v: &[f32], shape: Vec<usize>| {
            FlexTensor::from_data(TensorData::new(v.to_vec(), shape))
        };
        let shape = vec![b, 2, h, w];
        let values = |t: FlexTensor| t.into_data().try_to_vec::<f32>().expect("f32 values");
        let e3 = values(epe_composed::<Flex>(
            flex(&p, shape.clone()),
            flex(&t, shape.clone()),
            eps,
        ));
        let g = flex(&sample_w, vec![b]);
        let dp3 = values(epe_composed_backward::<Flex>(
            flex(&p, shape.clone()),
            flex(&t, shape),
            eps,
            g,
        ));
        for (what, a, c) in [
            ("composed value", &e3, &e1),
            ("composed gradient", &dp3, &dp1),
        ] {
            assert_eq!(a.len(), c.len(), "{what}s");
            for (i, (x, &y)) in a.iter().zip(c.iter()).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                    "{what} {i}: {x} against {y}"
                );
            }
        }
    }

    /// Values and the logits' gradient against the stable form of burn's
    /// primitives, on logits of both signs and large magnitudes, 0/1 and
    /// fractional targets, over more than one rayon chunk; the targets get
    /// no gradient.
    #[test]
    fn matches_the_composed_cross_entropy_and_its_gradient() {
        let device = Device::flex().autodiff();
        let n = 3 * CHUNK + 123;
        let mut rng = fastrand::Rng::with_seed(4);
        let mut v: Vec<f32> = (0..n).map(|_| rng.f32() * 16.0 - 8.0).collect();
        v[0] = 40.0;
        v[1] = -40.0;
        v[2] = 0.0;
        let t: Vec<f32> = (0..n)
            .map(|i| {
                if i % 7 == 0 {
                    rng.f32()
                } else {
                    f32::from(rng.bool())
                }
            })
            .collect();
        let w: Vec<f32> = (0..n).map(|_| rng.f32()).collect();
        let (x, y, wt) = (
            Tensor::<1>::from_floats(v.as_slice(), &device),
            Tensor::<1>::from_floats(t.as_slice(), &device),
            Tensor::<1>::from_floats(w.as_slice(), &device),
        );
        let run = |ours: bool| {
            let (x, y) = (x.clone().require_grad(), y.clone().require_grad());
            let l = if ours {
                Tensor::from_dispatch(<Dispatch as LossTrain>::bce_train(
                    x.clone().into_dispatch(),
                    y.clone().into_dispatch(),
                ))
            } else {
                x.clone().clamp_min(0.0) - x.clone() * y.clone()
                    + x.clone().abs().neg().exp().add_scalar(1.0).log()
            };
            let grads = (l.clone() * wt.clone()).sum().backward();
            let dx = x.grad(&grads).expect("the logits' gradient");
            (
                l.try_into_vec_as::<f32>().expect("f32 values"),
                dx.try_into_vec_as::<f32>().expect("f32 values"),
                y.grad(&grads).is_some(),
            )
        };
        let ((l1, dx1, dy1), (l2, dx2, _)) = (run(true), run(false));
        assert!(!dy1, "the targets got a gradient");
        for (what, a, b) in [("value", &l1, &l2), ("gradient", &dx1, &dx2)] {
            assert_eq!(a.len(), n, "{what}s");
            for (i, (p, &q)) in a.iter().zip(b.iter()).enumerate() {
                // At 0 the composition's kinks (max, |x|) give it a
                // subgradient; the loss itself is smooth there: σ(0) − y.
                let q = if what == "gradient" && i == 2 {
                    w[2] * (0.5 - t[2])
                } else {
                    q
                };
                assert!(
                    (p - q).abs() <= 1e-5 * (1.0 + q.abs()),
                    "{what} {i}: {p} against {q}"
                );
            }
        }
    }
}
