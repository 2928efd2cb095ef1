//! The training path's 2-D convolution on the CPU.
//!
//! burn's `flex` backend runs a convolution's forward pass through its own
//! general kernels and its backward pass through burn's generic rules (the
//! input gradient as a transposed convolution, the weight gradient as a
//! convolution with batch and channels swapped), with layout conversions
//! around each. A profile of a training step put most of its time there
//! (docs/performance.md). [`ConvTrain`] is a burn backend extension that
//! gives `flex` its own three passes, per sample (per group of samples for
//! the small maps) and split over rayon's threads:
//!
//! - layers with small output maps (4² and 2²,
//!   [`KernelSettings::grouped_outs`](crate::KernelSettings); for an
//!   up-convolution its input's) before any route below: one product per
//!   group of samples per pass over the group's im2col matrix
//!   ([`grouped`]);
//! - stride-1 layers, without im2col ([`shifted`]): k² products of each
//!   tap's weights with a view of the zero-padded input; the input gradient
//!   is the same kind of convolution of `dy` with the kernel flipped;
//! - strided layers of at least 8 input channels, the same on the input
//!   split into stride² phases;
//! - strided layers of fewer channels (the encoders' first layers),
//!   [`stacked`]: the im2col tile of a band of output rows (in
//!   cache) stacked from the split input by contiguous copies, and one faer
//!   product per band, `y = W · col + b`, `dW = Σ dy · colᵀ`;
//! - the forward pass over those views (the shifted, phased and stacked
//!   layouts) through [`direct`](mod@direct)'s kernel instead of products
//!   where the output rows are a multiple of 16 wide and the output
//!   channels of 4, on a CPU with AVX and FMA, and the weight gradient
//!   through its second kernel; a strided layer's input gradient, where
//!   each phase of its input is a multiple of 16 wide, as s² stride-1
//!   convolutions of `dy` through the same forward kernel
//!   ([`split`]);
//! - other layers through im2col in bands ([`banded`]), `dx = col2im(Wᵀ · dy)`; 1×1
//!   layers read their input as the matrix; the bias's `db = Σ dy`;
//! - transposed convolutions (the flow decoder's up-convolutions,
//!   [`conv_transpose2d`]) as the input-gradient pass of the convolution
//!   with the same weight, whose forward pass is their input gradient and
//!   whose weight gradient, with the roles of input and output gradient
//!   swapped, is theirs (burn's took about 12 % of a training step).
//!
//! The GPU backends (burn's `Cube`: Vulkan, CUDA) run burn's own
//! convolution kernels through the trait's default bodies; under autodiff
//! every backend goes through one backward node ([`autodiff`]), which
//! calls the backend's kernels. [`KernelChoice::Burn`] sends both through
//! burn's own convolutions instead, [`KernelChoice::Products`] keeps faer's
//! products where [`direct`](mod@direct)'s kernels would run. The model code calls [`conv2d`] and
//! [`conv_transpose2d`] whatever the device. The parameters stay in burn's
//! [`Conv2d`] and [`ConvTranspose2d`] modules: records and checkpoints do not change.
//!
//! The layers' shapes are [`geometry`]'s; this file holds the extension,
//! the public entries and the choice of route per pass.

mod autodiff;
mod banded;
mod direct;
mod geometry;
mod grouped;
mod shifted;
mod split;
mod stacked;
#[cfg(test)]
mod tests;

#[cfg(doc)]
use crate::choice::KernelChoice;
use crate::choice::kernel_settings;
use crate::flex::{f32s, flex_tensor, written};
use banded::{forward_banded, wb_backward_banded, x_backward_banded};
use burn::backend::ops::{ConvOptions, ConvTransposeOptions, ModuleOps};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, TensorMetadata, backend_extension};
use burn::backend::{Flex, flex::FlexTensor};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::prelude::*;
use geometry::{Geometry, add_bias_grad, direct_forward, direct_weight_grad};
use grouped::{forward_grouped, grouped, wb_backward_grouped, x_backward_grouped};
use rayon::prelude::*;
use shifted::{
    Kernel, Shifted, forward_shifted, wb_backward_direct, wb_backward_shifted, x_backward_phased,
    x_backward_shifted,
};
use split::{split_direct, x_backward_split};
use stacked::{forward_stacked, wb_backward_stacked};
use std::mem::MaybeUninit;

/// A square-kernel convolution with equal stride and padding on both axes
/// (every convolution of the models), and the transposed one, each
/// differentiable in its input, weight and bias.
#[backend_extension(Flex, Cube: cfg(any(feature = "cuda", feature = "vulkan")), Autodiff)]
pub trait ConvTrain: Backend {
    /// `x [B, Cin, H, W]`, `weight [Cout, Cin, k, k]`, `bias [Cout]` →
    /// `[B, Cout, Ho, Wo]`.
    fn conv2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, weight, Some(bias), options(stride, pad))
    }

    /// The gradient of [`ConvTrain::conv2d_train`] with respect to `x`.
    fn conv2d_train_x_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv2d_x_backward(x, weight, grad, options(stride, pad))
    }

    /// The gradients with respect to the weight and the bias.
    fn conv2d_train_wb_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        burns_wb_backward::<Self>(x, weight, grad, stride, pad)
    }

    /// The transposed convolution: `x [B, Cin, H, W]`, `weight [Cin, Cout,
    /// k, k]` (burn's layout for it), `bias [Cout]` → `[B, Cout, (H − 1)·s −
    /// 2p + k, …]`; the input gradient of the convolution of the same
    /// weight, stride and padding, plus the bias.
    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, weight, Some(bias), transposed_options(stride, pad))
    }

    /// The gradient of [`ConvTrain::conv_transpose2d_train`] with respect
    /// to `x`.
    fn conv_transpose2d_train_x_backward(
        _x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d_x_backward(weight, grad, transposed_options(stride, pad))
    }

    /// The gradients of [`ConvTrain::conv_transpose2d_train`] with respect
    /// to the weight and the bias.
    fn conv_transpose2d_train_wb_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        stride: usize,
        pad: usize,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let cout = weight.shape()[1];
        let opts = transposed_options(stride, pad);
        let dw = Self::conv_transpose2d_weight_backward(x, weight, grad.clone(), opts);
        (dw, bias_grad::<Self>(grad, cout))
    }
}

fn options(stride: usize, pad: usize) -> ConvOptions<2> {
    ConvOptions::new([stride, stride], [pad, pad], [1, 1], 1)
}

fn transposed_options(stride: usize, pad: usize) -> ConvTransposeOptions<2> {
    ConvTransposeOptions::new([stride, stride], [pad, pad], [0, 0], [1, 1], 1)
}

/// `Σ grad` over the batch and the positions, per channel: `[cout]`.
fn bias_grad<B: Backend>(grad: FloatTensor<B>, cout: usize) -> FloatTensor<B> {
    let db = B::float_sum_dim(B::float_sum_dim(grad, 3), 2);
    B::float_reshape(B::float_sum_dim(db, 0), [cout].into())
}

/// burn's own weight and bias gradients on backend `B`.
fn burns_wb_backward<B: Backend>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    grad: FloatTensor<B>,
    stride: usize,
    pad: usize,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let cout = weight.shape()[0];
    let dw = B::conv2d_weight_backward(x, weight, grad.clone(), options(stride, pad));
    (dw, bias_grad::<B>(grad, cout))
}

/// The 2-D convolution `c.forward(x)` of the models, differentiable in its
/// input, weight and bias: through [`ConvTrain`] (this crate's passes on
/// `flex`, burn's kernels on the GPU backends), or `c.forward(x)` itself
/// under [`KernelChoice::Burn`].
///
/// # Panics
/// If the convolution is not one [`ConvTrain`] covers: no bias, a
/// non-square kernel, unequal strides or paddings, dilation or groups (none
/// of the models has one).
pub fn conv2d(c: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    if kernel_settings().burns_own() {
        return c.forward(x);
    }
    let (_, stride, pad) = conv2d_geometry(c);
    let bias = c.bias.as_ref().expect("conv2d: a convolution with a bias");
    Tensor::from_dispatch(<Dispatch as ConvTrain>::conv2d_train(
        x.into_dispatch(),
        c.weight.val().into_dispatch(),
        bias.val().into_dispatch(),
        stride,
        pad,
    ))
}

/// The kernel side, stride and padding `(k, stride, pad)` of a convolution
/// with a square kernel and the same stride and padding on both axes (every
/// convolution of the models; the ones [`conv2d`] runs).
///
/// # Panics
/// On any other convolution (or one with dilation or groups).
pub fn conv2d_geometry(c: &Conv2d) -> (usize, usize, usize) {
    let [_, _, kh, kw] = c.weight.dims();
    let pad = match c.padding {
        PaddingConfig2d::Explicit(t, l, b, r) if t == l && l == b && b == r => t,
        PaddingConfig2d::Valid => 0,
        ref p => panic!("conv2d: unsupported padding {p:?}"),
    };
    assert!(
        kh == kw && c.stride[0] == c.stride[1] && c.dilation == [1, 1] && c.groups == 1,
        "conv2d: only square kernels with one stride, no dilation and no groups"
    );
    (kh, c.stride[0], pad)
}

/// The transposed convolution `c.forward(x)` (the flow decoder's
/// up-convolutions), differentiable in its input, weight and bias: through
/// [`ConvTrain`] (on `flex`, the input-gradient pass of the convolution
/// with the same weight, stride and padding), or `c.forward(x)` itself
/// under [`KernelChoice::Burn`].
///
/// # Panics
/// If it has no bias, a non-square kernel, unequal strides or paddings, an
/// output padding, dilation or groups (none of the models has one).
pub fn conv_transpose2d(c: &ConvTranspose2d, x: Tensor<4>) -> Tensor<4> {
    if kernel_settings().burns_own() {
        return c.forward(x);
    }
    let [_, _, kh, kw] = c.weight.dims();
    assert!(
        kh == kw
            && c.stride[0] == c.stride[1]
            && c.padding[0] == c.padding[1]
            && c.padding_out == [0, 0]
            && c.dilation == [1, 1]
            && c.groups == 1,
        "conv_transpose2d: only square kernels with one stride and padding, no output \
         padding, dilation or groups"
    );
    let bias = c.bias.as_ref().expect("conv_transpose2d: one with a bias");
    Tensor::from_dispatch(<Dispatch as ConvTrain>::conv_transpose2d_train(
        x.into_dispatch(),
        c.weight.val().into_dispatch(),
        bias.val().into_dispatch(),
        c.stride[0],
        c.padding[0],
    ))
}

#[cfg(any(feature = "cuda", feature = "vulkan"))]
impl ConvTrain for burn::backend::Cube {}

/// The forward pass on contiguous f32 arrays.
fn forward(g: &Geometry, x: &[f32], w: &[f32], b: &[f32], y: &mut [MaybeUninit<f32>]) {
    // Every pass pairs output and input samples with rayon's `zip`, which
    // stops at the shorter: a short input would leave outputs unwritten
    // (`written` relies on all being written).
    assert!(
        x.len() == g.batch * g.cin * g.h * g.w
            && y.len() == g.batch * g.cout * g.outs()
            && w.len() == g.cout * g.taps()
            && b.len() == g.cout,
        "conv2d: the input, weight, bias or output does not match the layer's shape"
    );
    // A stacked layer the kernel covers reads its views tap by tap too.
    let by_taps = Shifted::of(g).or_else(|| Shifted::stacked(g).filter(|_| direct_forward(g)));
    if grouped(g) {
        forward_grouped(g, x, w, b, y)
    } else if let Some(sh) = by_taps {
        forward_shifted(g, sh, x, Kernel::Own(w), b, y)
    } else if let Some(sh) = Shifted::stacked(g) {
        forward_stacked(g, sh, x, w, b, y)
    } else {
        forward_banded(g, x, w, b, y)
    }
}

/// The input gradient on contiguous f32 arrays.
fn x_backward(g: &Geometry, w: &[f32], dy: &[f32], dx: &mut [MaybeUninit<f32>]) {
    // As in [`forward`]: a short `dy` would leave `dx` partly unwritten.
    assert!(
        dy.len() == g.batch * g.cout * g.outs()
            && dx.len() == g.batch * g.cin * g.h * g.w
            && w.len() == g.cout * g.taps(),
        "conv2d input gradient: the output gradient or weight does not match the layer's shape"
    );
    match Shifted::of(g) {
        _ if grouped(g) => x_backward_grouped(g, w, dy, dx),
        Some(_) if g.stride == 1 && g.pad < g.k => x_backward_shifted(g, w, dy, dx),
        Some(_) if g.stride > 1 && split_direct(g) => x_backward_split(g, w, dy, dx),
        Some(sh) if g.stride > 1 => x_backward_phased(g, sh, w, dy, dx),
        _ => x_backward_banded(g, w, dy, dx),
    }
}

/// The weight and bias gradients on contiguous f32 arrays.
fn wb_backward(g: &Geometry, x: &[f32], dy: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let views = Shifted::of(g).or_else(|| Shifted::stacked(g));
    if grouped(g) {
        wb_backward_grouped(g, x, dy)
    } else if let Some(sh) = views.filter(|_| direct_weight_grad(g)) {
        wb_backward_direct(g, sh, x, dy)
    } else if let Some(sh) = Shifted::of(g) {
        wb_backward_shifted(g, sh, x, dy)
    } else if let Some(sh) = Shifted::stacked(g) {
        wb_backward_stacked(g, sh, x, dy)
    } else {
        wb_backward_banded(g, x, dy)
    }
}

impl ConvTrain for Flex {
    fn conv2d_train(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(xc), Some(wc), Some(bc)) = (f32s(&x), f32s(&weight), f32s(&bias)) else {
            return Flex::conv2d(x, weight, Some(bias), options(stride, pad));
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (xs, ws, bs) = (
            xc.storage::<f32>(),
            wc.storage::<f32>(),
            bc.storage::<f32>(),
        );
        // SAFETY: `forward` writes every value.
        let y = unsafe { written(g.batch * g.cout * g.outs(), |y| forward(&g, xs, ws, bs, y)) };
        flex_tensor(y, vec![g.batch, g.cout, g.ho, g.wo])
    }

    fn conv2d_train_x_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(wc), Some(dyc)) = (f32s(&weight), f32s(&grad)) else {
            return Flex::conv2d_x_backward(x, weight, grad, options(stride, pad));
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (ws, dys) = (wc.storage::<f32>(), dyc.storage::<f32>());
        // SAFETY: `x_backward` writes every value.
        let dx = unsafe {
            written(g.batch * g.cin * g.h * g.w, |dx| {
                x_backward(&g, ws, dys, dx)
            })
        };
        flex_tensor(dx, vec![g.batch, g.cin, g.h, g.w])
    }

    fn conv2d_train_wb_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> (FlexTensor, FlexTensor) {
        let (Some(xc), Some(dyc)) = (f32s(&x), f32s(&grad)) else {
            return burns_wb_backward::<Flex>(x, weight, grad, stride, pad);
        };
        let g = Geometry::new(&x.shape(), &weight.shape(), stride, pad);
        let (dw, db) = wb_backward(&g, xc.storage::<f32>(), dyc.storage::<f32>());
        (
            flex_tensor(dw, vec![g.cout, g.cin, g.k, g.k]),
            flex_tensor(db, vec![g.cout]),
        )
    }

    fn conv_transpose2d_train(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(xc), Some(wc), Some(bc)) = (f32s(&x), f32s(&weight), f32s(&bias)) else {
            return Flex::conv_transpose2d(x, weight, Some(bias), transposed_options(stride, pad));
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let (ws, xs) = (wc.storage::<f32>(), xc.storage::<f32>());
        // SAFETY: `x_backward` writes every value.
        let mut y = unsafe { written(g.batch * g.cin * g.h * g.w, |y| x_backward(&g, ws, xs, y)) };
        let plane = g.h * g.w;
        let b = bc.storage::<f32>();
        y.par_chunks_mut(g.cin * plane).for_each(|sample| {
            for (p, &bias) in sample.chunks_exact_mut(plane).zip(b) {
                p.iter_mut().for_each(|v| *v += bias);
            }
        });
        flex_tensor(y, vec![g.batch, g.cin, g.h, g.w])
    }

    fn conv_transpose2d_train_x_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> FlexTensor {
        let (Some(wc), Some(dyc)) = (f32s(&weight), f32s(&grad)) else {
            return Flex::conv_transpose2d_x_backward(
                weight,
                grad,
                transposed_options(stride, pad),
            );
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let zero = vec![0.0f32; g.cout];
        let (dys, ws) = (dyc.storage::<f32>(), wc.storage::<f32>());
        // SAFETY: `forward` writes every value.
        let dx = unsafe {
            written(g.batch * g.cout * g.outs(), |dx| {
                forward(&g, dys, ws, &zero, dx)
            })
        };
        flex_tensor(dx, vec![g.batch, g.cout, g.ho, g.wo])
    }

    fn conv_transpose2d_train_wb_backward(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        stride: usize,
        pad: usize,
    ) -> (FlexTensor, FlexTensor) {
        let (Some(xc), Some(dyc)) = (f32s(&x), f32s(&grad)) else {
            let opts = transposed_options(stride, pad);
            let cout = weight.shape()[1];
            let dw = Flex::conv_transpose2d_weight_backward(x, weight, grad.clone(), opts);
            return (dw, bias_grad::<Flex>(grad, cout));
        };
        let g = Geometry::transposed(&x.shape(), &weight.shape(), stride, pad);
        let dys = dyc.storage::<f32>();
        // The convolution's weight gradient with the roles of its input and
        // output gradient taken by this one's output gradient and input (its
        // bias gradient, Σ x, is not this one's).
        let (dw, _) = wb_backward(&g, dys, xc.storage::<f32>());
        let mut db = vec![0.0f32; g.cin];
        for sample in dys.chunks_exact(g.cin * g.h * g.w) {
            add_bias_grad(&mut db, sample, g.h * g.w);
        }
        (
            flex_tensor(dw, vec![g.cout, g.cin, g.k, g.k]),
            flex_tensor(db, vec![g.cin]),
        )
    }
}
