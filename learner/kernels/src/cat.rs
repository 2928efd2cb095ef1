//! Two feature maps joined along the channels as one operation with its
//! own backward pass: the flow decoder's skip connections.
//!
//! burn's `cat` on `flex` copies on one thread into a fresh buffer, and its
//! backward pass hands each input a strided view of the gradient, which the
//! convolution that consumes it then copies to contiguous memory on one
//! thread too: at `[64, 64, 32, 32]` these were among the serial parts of a
//! training step (docs/performance.md). [`CatTrain`] is a burn backend
//! extension: `flex` gets one copy each way, sample by sample over rayon's
//! threads, the gradients contiguous; the GPU backends (burn's `Cube`) keep
//! burn's `cat` and slices through the trait's default bodies.

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
use burn::tensor::Slice;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// `a [B, Ca, H, W]` and `b [B, Cb, H, W]` joined along the channels, `[B,
/// Ca + Cb, H, W]`, differentiable in both: one operation with its own
/// backward pass ([`CatTrain`]), or burn's `cat` under
/// [`KernelChoice::Burn`](crate::KernelChoice).
pub fn cat_channels(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    if kernel_settings().burns_own() {
        return Tensor::cat(vec![a, b], 1);
    }
    Tensor::from_dispatch(<Dispatch as CatTrain>::cat_channels_train(
        a.into_dispatch(),
        b.into_dispatch(),
    ))
}

/// Channel concatenation of two `[B, C, H, W]` maps, differentiable in both.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait CatTrain: Backend {
    /// `a [B, Ca, H, W]` and `b [B, Cb, H, W]` → `[B, Ca + Cb, H, W]`.
    fn cat_channels_train(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        joined::<Self>(a, b)
    }

    /// Channels `start..start + len` of `x [B, C, H, W]`: a joined map's
    /// gradient taken back to one of its inputs.
    fn channels_train(x: FloatTensor<Self>, start: usize, len: usize) -> FloatTensor<Self> {
        sliced::<Self>(x, start, len)
    }
}

/// `B`'s `cat` along the channels: the GPU backends', and flex's for other
/// dtypes.
fn joined<B: Backend>(a: FloatTensor<B>, b: FloatTensor<B>) -> FloatTensor<B> {
    B::float_cat(vec![a, b], 1)
}

/// Channels `start..start + len` by `B`'s slice (a view where the backend
/// makes one): the GPU backends' gradients, and flex's for other dtypes.
fn sliced<B: Backend>(x: FloatTensor<B>, start: usize, len: usize) -> FloatTensor<B> {
    let channels = Slice::new(start as isize, Some((start + len) as isize), 1);
    B::float_slice(x, &[Slice::full(), channels, Slice::full(), Slice::full()])
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl CatTrain for burn::backend::Cube {}

/// A `[B, C, H, W]` shape, checked.
fn dims4(what: &str, shape: &[usize]) -> [usize; 4] {
    crate::flex::dims4("channel concatenation", what, shape)
}

impl CatTrain for Flex {
    fn cat_channels_train(a: FlexTensor, b: FlexTensor) -> FlexTensor {
        let [n, ca, h, w] = dims4("the first map", &a.shape().to_vec());
        let [nb, cb, hb, wb] = dims4("the second map", &b.shape().to_vec());
        assert!(
            (n, h, w) == (nb, hb, wb),
            "channel concatenation: maps of {n}×{h}×{w} and {nb}×{hb}×{wb}"
        );
        let (Some(ac), Some(bc)) = (f32s(&a), f32s(&b)) else {
            return joined::<Flex>(a, b);
        };
        let (xa, xb, hw) = (ac.storage::<f32>(), bc.storage::<f32>(), h * w);
        let fill = |y: &mut [MaybeUninit<f32>]| {
            y.par_chunks_mut((ca + cb) * hw)
                .zip(xa.par_chunks(ca * hw).zip(xb.par_chunks(cb * hw)))
                .for_each(|(y, (a, b))| {
                    let (ya, yb) = y.split_at_mut(ca * hw);
                    ya.write_copy_of_slice(a);
                    yb.write_copy_of_slice(b);
                })
        };
        // SAFETY: each sample's chunk of `y` is `(Ca + Cb)·H·W`, its two
        // parts as long as the inputs' chunks, each written whole.
        let y = unsafe { written(n * (ca + cb) * hw, fill) };
        flex_tensor(y, vec![n, ca + cb, h, w])
    }

    fn channels_train(x: FlexTensor, start: usize, len: usize) -> FlexTensor {
        let [n, c, h, w] = dims4("the joined map", &x.shape().to_vec());
        assert!(
            start + len <= c,
            "channel concatenation: channels {start}..{} of {c}",
            start + len
        );
        let Some(xc) = f32s(&x) else {
            return sliced::<Flex>(x, start, len);
        };
        let (xs, hw) = (xc.storage::<f32>(), h * w);
        let fill = |y: &mut [MaybeUninit<f32>]| {
            y.par_chunks_mut(len * hw)
                .zip(xs.par_chunks(c * hw))
                .for_each(|(y, x)| {
                    y.write_copy_of_slice(&x[start * hw..][..len * hw]);
                })
        };
        // SAFETY: each sample's chunk of `y` is `len·H·W`, written whole from
        // its chunk of `x` (`start + len ≤ C`, checked).
        let y = unsafe { written(n * len * hw, fill) };
        flex_tensor(y, vec![n, len, h, w])
    }
}

impl<B: Backend + CatTrain, C: CheckpointStrategy> CatTrain for Autodiff<B, C> {
    fn cat_channels_train(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct CatBackward;

        impl<B: Backend + CatTrain> Backward<B, 2> for CatBackward {
            /// Each input's channels.
            type State = (usize, usize);

            fn backward(
                self,
                ops: Ops<Self::State, 2>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_a, node_b] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (ca, cb) = ops.state;
                if let Some(node) = node_a {
                    grads.register::<B>(node.id, B::channels_train(grad.clone(), 0, ca));
                }
                if let Some(node) = node_b {
                    grads.register::<B>(node.id, B::channels_train(grad, ca, cb));
                }
            }
        }

        let channels = |what, t: &FloatTensor<Self>| dims4(what, &t.shape().to_vec())[1];
        let (ca, cb) = (
            channels("the first map", &a),
            channels("the second map", &b),
        );
        match CatBackward
            .prepare::<C>([a.node(), b.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => prep.finish(
                (ca, cb),
                B::cat_channels_train(a.into_primitive(), b.into_primitive()),
            ),
            OpsKind::UnTracked(prep) => prep.finish(B::cat_channels_train(
                a.into_primitive(),
                b.into_primitive(),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Dispatch;

    /// Values and both inputs' gradients against burn's `cat` under
    /// autodiff, with the second input a broadcast view (the flow
    /// decoder's tiled feature); the slices' default body (the GPU
    /// backends') on flex against ours.
    #[test]
    fn matches_burns_cat_and_its_gradients() {
        let device = Device::flex().autodiff();
        let (n, ca, cb, h, w) = (3, 2, 5, 4, 3);
        let mut rng = fastrand::Rng::with_seed(21);
        let mut data = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.f32() - 0.5).collect() };
        let a = Tensor::<4>::from_data(
            TensorData::new(data(n * ca * h * w), [n, ca, h, w]),
            &device,
        );
        let feature = Tensor::<4>::from_data(TensorData::new(data(n * cb), [n, cb, 1, 1]), &device);
        let weights = Tensor::<4>::from_data(
            TensorData::new(data(n * (ca + cb) * h * w), [n, ca + cb, h, w]),
            &device,
        );
        let run = |ours: bool| {
            let (a, f) = (a.clone().require_grad(), feature.clone().require_grad());
            let b = f.clone().expand([n, cb, h, w]);
            let y = if ours {
                Tensor::<4>::from_dispatch(<Dispatch as CatTrain>::cat_channels_train(
                    a.clone().into_dispatch(),
                    b.into_dispatch(),
                ))
            } else {
                Tensor::cat(vec![a.clone(), b], 1)
            };
            let grads = (y.clone() * weights.clone()).sum().backward();
            let values = |t: Tensor<4>| t.try_into_vec_as::<f32>().expect("f32 values");
            (
                values(y),
                values(a.grad(&grads).expect("a's gradient")),
                values(f.grad(&grads).expect("the feature's gradient")),
            )
        };
        let (ours, theirs) = (run(true), run(false));
        assert_eq!(ours.0, theirs.0, "values");
        assert_eq!(ours.1, theirs.1, "the first map's gradient");
        for (i, (p, q)) in ours.2.iter().zip(&theirs.2).enumerate() {
            assert!(
                (p - q).abs() < 1e-5,
                "the feature's gradient {i}: {p} against {q}"
            );
        }

        let x: Vec<f32> = (0..n * 7 * h * w).map(|i| i as f32).collect();
        let flex = || FlexTensor::from_data(TensorData::new(x.clone(), [n, 7, h, w]));
        let values = |t: FlexTensor| t.into_data().try_to_vec::<f32>().expect("f32 values");
        let (mine, default) = (
            values(Flex::channels_train(flex(), 2, 4)),
            values(sliced::<Flex>(flex(), 2, 4)),
        );
        assert_eq!(mine, default, "channels 2..6");
    }
}
