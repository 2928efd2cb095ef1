//! The leaky ReLU of the training path as one operation with its own
//! backward pass.
//!
//! burn composes a leaky ReLU of a comparison and a `mask_where`; our
//! earlier `slope·x + (1 − slope)·relu(x)` took four elementwise passes
//! forward (each a fresh tensor) and as many backward, on one thread in
//! `flex` (docs/performance.md). [`ActTrain`] is a burn backend extension:
//! `flex` gets one pass each way, split over rayon's threads; the GPU
//! backends (burn's `Cube`) keep the composition through the trait's
//! default bodies. The backward pass reads the output, not the input: with
//! a positive slope both have the same sign, and the output is the tensor
//! the next layer keeps for its own backward pass anyway.

use crate::flex::{CHUNK, f32s, flex_tensor, written};
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
use burn::tensor::activation::relu;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// The leaky ReLU `x` where `x > 0`, else `slope·x` (`slope` in (0, 1)),
/// elementwise and differentiable: one operation with its own backward
/// pass ([`ActTrain`]; one pass each way on `flex`). Under
/// [`KernelChoice::Burn`](crate::KernelChoice) it is the composition
/// `slope·x + (1 − slope)·relu(x)` of burn's tensor operations: ReLU has
/// its own backward, while burn's `leaky_relu` is a comparison and a
/// `mask_where` whose two passes took 11 % of a training step on `flex`
/// (docs/performance.md).
pub fn leaky_relu<const D: usize>(x: Tensor<D>, slope: f64) -> Tensor<D> {
    if kernel_settings().burns_own() {
        return x.clone().mul_scalar(slope) + relu(x).mul_scalar(1.0 - slope);
    }
    Tensor::from_dispatch(<Dispatch as ActTrain>::leaky_train(
        x.into_dispatch(),
        slope,
    ))
}

/// Elementwise leaky ReLU, differentiable.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait ActTrain: Backend {
    /// `x` where `x > 0`, else `slope·x` (`slope` in (0, 1)).
    fn leaky_train(x: FloatTensor<Self>, slope: f64) -> FloatTensor<Self> {
        composed::<Self>(x, slope)
    }

    /// The gradient with respect to `x`, from the forward pass's output `y`
    /// and the output's gradient: `grad` where `y > 0`, else `slope·grad`.
    fn leaky_train_backward(
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        slope: f64,
    ) -> FloatTensor<Self> {
        composed_backward::<Self>(y, grad, slope)
    }
}

/// `slope·x + (1 − slope)·relu(x)` of `B`'s primitives: the GPU backends'
/// leaky ReLU, and flex's for other dtypes than f32.
fn composed<B: Backend>(x: FloatTensor<B>, slope: f64) -> FloatTensor<B> {
    let pos = B::float_mul_scalar(B::relu(x.clone()), (1.0 - slope).into());
    B::float_add(B::float_mul_scalar(x, slope.into()), pos)
}

/// [`composed`]'s input gradient from its output `y`.
fn composed_backward<B: Backend>(
    y: FloatTensor<B>,
    grad: FloatTensor<B>,
    slope: f64,
) -> FloatTensor<B> {
    let pos = B::float_mul_scalar(B::relu_backward(y, grad.clone()), (1.0 - slope).into());
    B::float_add(B::float_mul_scalar(grad, slope.into()), pos)
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl ActTrain for burn::backend::Cube {}

impl ActTrain for Flex {
    fn leaky_train(x: FlexTensor, slope: f64) -> FlexTensor {
        let Some(xc) = f32s(&x) else {
            return composed::<Flex>(x, slope);
        };
        let (src, a) = (xc.storage::<f32>(), slope as f32);
        let fill = |y: &mut [MaybeUninit<f32>]| {
            y.par_chunks_mut(CHUNK)
                .zip(src.par_chunks(CHUNK))
                .for_each(move |(d, s)| {
                    // A select, not a branch, and `a` a local of the closure:
                    // a branch per value (random signs) or `a` read through a
                    // reference kept this loop scalar (perf annotate). Not
                    // `max`/`min`, which would turn NaN into 0.
                    for (d, &v) in d.iter_mut().zip(s) {
                        d.write(v * if v > 0.0 { 1.0 } else { a });
                    }
                })
        };
        // SAFETY: the chunks of `y` and `src` pair up whole, and every
        // value of each is written.
        let y = unsafe { written(src.len(), fill) };
        flex_tensor(y, x.shape().to_vec())
    }

    fn leaky_train_backward(y: FlexTensor, grad: FlexTensor, slope: f64) -> FlexTensor {
        let (Some(yc), Some(gc)) = (f32s(&y), f32s(&grad)) else {
            return composed_backward::<Flex>(y, grad, slope);
        };
        let (ys, gs, a) = (yc.storage::<f32>(), gc.storage::<f32>(), slope as f32);
        let fill = |dx: &mut [MaybeUninit<f32>]| {
            dx.par_chunks_mut(CHUNK)
                .zip(ys.par_chunks(CHUNK).zip(gs.par_chunks(CHUNK)))
                .for_each(move |(d, (y, g))| {
                    for ((d, &y), &g) in d.iter_mut().zip(y).zip(g) {
                        d.write(g * if y > 0.0 { 1.0 } else { a });
                    }
                })
        };
        assert_eq!(
            ys.len(),
            gs.len(),
            "leaky_train_backward: the output and its gradient differ in size"
        );
        // SAFETY: the chunks of `dx`, `ys` and `gs` pair up whole (the same
        // length, checked), and every value of each is written.
        let dx = unsafe { written(gs.len(), fill) };
        flex_tensor(dx, grad.shape().to_vec())
    }
}

impl<B: Backend + ActTrain, C: CheckpointStrategy> ActTrain for Autodiff<B, C> {
    fn leaky_train(x: FloatTensor<Self>, slope: f64) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct LeakyBackward;

        impl<B: Backend + ActTrain> Backward<B, 1> for LeakyBackward {
            type State = (FloatTensor<B>, f64);

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_x] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (y, slope) = ops.state;
                if let Some(node) = node_x {
                    grads.register::<B>(node.id, B::leaky_train_backward(y, grad, slope));
                }
            }
        }

        match LeakyBackward
            .prepare::<C>([x.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let y = B::leaky_train(x.into_primitive(), slope);
                prep.finish((y.clone(), slope), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::leaky_train(x.into_primitive(), slope)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Dispatch;

    /// Values and input gradient against the composition the model used
    /// before, `0.1·x + 0.9·relu(x)` (whose gradient at 0 is the slope, as
    /// ours is), on values of both signs, zeros included, over more than
    /// one rayon chunk.
    #[test]
    fn matches_the_composed_leaky_relu_and_its_gradient() {
        let device = Device::flex().autodiff();
        let n = 17 * 6000;
        assert!(n > 3 * CHUNK && n % CHUNK != 0);
        let mut rng = fastrand::Rng::with_seed(9);
        let mut v: Vec<f32> = (0..n).map(|_| rng.f32() * 2.0 - 1.0).collect();
        v[5] = 0.0;
        v[n - 1] = 0.0;
        v[7] = f32::NAN;
        let x = Tensor::<1>::from_floats(v.as_slice(), &device).reshape([n / 17, 17]);
        let w: Vec<f32> = (0..n).map(|_| rng.f32()).collect();
        let w = Tensor::<1>::from_floats(w.as_slice(), &device).reshape([n / 17, 17]);
        let run = |ours: bool| {
            let x = x.clone().require_grad();
            let y = if ours {
                Tensor::from_dispatch(<Dispatch as ActTrain>::leaky_train(
                    x.clone().into_dispatch(),
                    0.1,
                ))
            } else {
                x.clone().mul_scalar(0.1)
                    + burn::tensor::activation::relu(x.clone()).mul_scalar(0.9)
            };
            let grads = (y.clone() * w.clone()).sum().backward();
            let dx = x.grad(&grads).expect("x's gradient");
            (
                y.try_into_vec_as::<f32>().expect("f32 values"),
                dx.try_into_vec_as::<f32>().expect("f32 values"),
            )
        };
        let ((y1, dx1), (y2, dx2)) = (run(true), run(false));
        for (what, a, b) in [("value", &y1, &y2), ("gradient", &dx1, &dx2)] {
            assert_eq!(a.len(), n, "{what}s");
            for (i, (p, q)) in a.iter().zip(b.iter()).enumerate() {
                if i == 7 {
                    // NaN stays NaN, so that a diverged run shows in its
                    // loss. (Its gradient, 1 through the composition and 0.1
                    // through ours, is not compared: NaN has no slope.)
                    if what == "value" {
                        assert!(p.is_nan() && q.is_nan(), "value of NaN: {p} against {q}");
                    }
                    continue;
                }
                assert!((p - q).abs() <= 1e-6, "{what} {i}: {p} against {q}");
            }
        }
    }
}
