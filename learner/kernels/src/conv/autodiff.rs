//! The autodiff node of both convolutions, whatever the backend underneath.

use super::ConvTrain;
use burn::backend::Backend;
use burn::backend::autodiff::{
    Autodiff,
    checkpoint::{base::Checkpointer, strategy::CheckpointStrategy},
    grads::Gradients,
    ops::{Backward, Ops, OpsKind},
};
use burn::backend::tensor::FloatTensor;

/// The autodiff node of both convolutions: their three passes are
/// [`ConvTrain`]'s, whatever the backend.
#[derive(Debug)]
struct ConvBackward {
    transposed: bool,
}

impl<B: Backend + ConvTrain> Backward<B, 3> for ConvBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, usize, usize);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_w, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (x, w, stride, pad) = ops.state;
        if let Some(node) = node_x {
            let (x, w, g) = (x.clone(), w.clone(), grad.clone());
            let dx = if self.transposed {
                B::conv_transpose2d_train_x_backward(x, w, g, stride, pad)
            } else {
                B::conv2d_train_x_backward(x, w, g, stride, pad)
            };
            grads.register::<B>(node.id, dx);
        }
        if node_w.is_some() || node_b.is_some() {
            let (dw, db) = if self.transposed {
                B::conv_transpose2d_train_wb_backward(x, w, grad, stride, pad)
            } else {
                B::conv2d_train_wb_backward(x, w, grad, stride, pad)
            };
            if let Some(node) = node_w {
                grads.register::<B>(node.id, dw);
            }
            if let Some(node) = node_b {
                grads.register::<B>(node.id, db);
            }
        }
    }
}

impl ConvBackward {
    /// The forward pass on `B`, recorded for the backward pass when any
    /// of its inputs is tracked.
    fn run<B: Backend + ConvTrain, C: CheckpointStrategy>(
        self,
        x: FloatTensor<Autodiff<B, C>>,
        weight: FloatTensor<Autodiff<B, C>>,
        bias: FloatTensor<Autodiff<B, C>>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Autodiff<B, C>> {
        let transposed = self.transposed;
        let fwd = |x, w, b| {
            if transposed {
                B::conv_transpose2d_train(x, w, b, stride, pad)
            } else {
                B::conv2d_train(x, w, b, stride, pad)
            }
        };
        match self
            .prepare::<C>([x.node(), weight.node(), bias.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (xp, wp) = (x.primitive().clone(), weight.primitive().clone());
                let y = fwd(xp.clone(), wp.clone(), bias.into_primitive());
                prep.finish((xp, wp, stride, pad), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(fwd(
                x.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            )),
        }
    }
}

impl<B: Backend + ConvTrain, C: CheckpointStrategy> ConvTrain for Autodiff<B, C> {
    fn conv2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        ConvBackward { transposed: false }.run::<B, C>(x, weight, bias, stride, pad)
    }

    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        ConvBackward { transposed: true }.run::<B, C>(x, weight, bias, stride, pad)
    }
}
