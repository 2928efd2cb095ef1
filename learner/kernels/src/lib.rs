//! The representation's training kernels on the CPU: each operation of the
//! models whose burn composition was a serial or slow part of a training
//! step on `flex` (docs/performance.md), as a burn backend extension with
//! its own forward and backward passes, split over rayon's threads.
//!
//! One public entry per operation; the model code (`learner::models`)
//! calls these, never a kernel:
//!
//! - [`conv2d`] and [`conv_transpose2d`]: the 2-D convolution and the
//!   transposed one of burn's [`Conv2d`](burn::nn::conv::Conv2d) and
//!   [`ConvTranspose2d`](burn::nn::conv::ConvTranspose2d) modules (the
//!   parameters stay in burn's modules, so records do not change);
//!   [`conv2d_geometry`] their kernel side, stride and padding;
//! - [`leaky_relu`]: the activation;
//! - [`bce_with_logits`] and [`endpoint_error`]: the losses' elementwise
//!   parts;
//! - [`upsample_bilinear`]: the decoders' upsampling;
//! - [`cat_channels`]: the flow decoder's skip connections.
//!
//! Each runs on whatever device its tensors are on: the GPU backends
//! (burn's `Cube`, with the `vulkan` or `cuda` feature) keep burn's own
//! operations through the traits' default bodies. [`KernelChoice`] (set
//! programmatically, [`set_kernel_choice`]; no environment variable is
//! read) switches the CPU back to burn's operations or the convolutions to
//! faer's products, for the benchmarks' A/B comparisons.
//!
//! What it owns: the arithmetic of these operations and their autodiff
//! nodes. What it must not depend on: the learner, the simulator (hw-sim),
//! the node (learner-node), or anything else of the workspace; burn only
//! with the backend features these operations need (`flex`, autodiff, the
//! `extension` macro; the GPU backends behind this crate's `cuda` and
//! `vulkan` features), faer for the products and rayon for the threads.

mod act;
mod cat;
mod choice;
mod conv;
mod flex;
mod loss;
mod resize;

pub use act::leaky_relu;
pub use cat::cat_channels;
pub use choice::{
    DEFAULT_GROUPED_OUTS, KernelChoice, KernelSettings, kernel_settings, set_kernel_choice,
    set_kernel_settings,
};
pub use conv::{conv_transpose2d, conv2d, conv2d_geometry};
pub use loss::{bce_with_logits, endpoint_error};
pub use resize::upsample_bilinear;
