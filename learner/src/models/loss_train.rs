//! Binary cross-entropy with logits as one operation with its own backward
//! pass.
//!
//! The stable form `max(x, 0) − x·y + ln(1 + e^−|x|)` of burn's primitives
//! is nine elementwise passes forward and as many backward, each a fresh
//! tensor and each on one thread in `flex`; on the flow mask's logits
//! (`[B, 1, 128, 128]`) they were among the serial parts of a training
//! step (docs/performance.md). [`LossTrain`] is a burn backend extension:
//! `flex` gets one pass each way, split over rayon's threads; the GPU
//! backends (burn's `Cube`) keep the composition through the trait's default
//! bodies. The targets are data: no gradient flows to them.

use super::act_train::CHUNK;
use super::conv_train::{f32s, flex_tensor, written};
use burn::backend::autodiff::{
    Autodiff,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Flex, TensorMetadata, backend_extension, flex::FlexTensor};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Elementwise binary cross-entropy of logits against targets,
/// differentiable in the logits.
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
}

/// The stable form of `B`'s primitives: the GPU backends' cross-entropy,
/// flex's for other dtypes than f32, and the model's under
/// `LEARNER_CONV=burn` (where autodiff tracks each primitive).
pub(super) fn composed<B: Backend>(x: FloatTensor<B>, y: FloatTensor<B>) -> FloatTensor<B> {
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

impl LossTrain for Flex {
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
    use burn::prelude::*;

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
