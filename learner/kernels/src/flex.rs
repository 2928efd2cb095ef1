//! What the operations' `flex` passes share: f32 storage in and out, and
//! outputs allocated without zeroing.

use burn::backend::{DType, flex::FlexTensor};
use std::mem::MaybeUninit;

/// Values per rayon task of the elementwise passes: large enough that a
/// task is worth its start (the activation's and the losses').
pub(crate) const CHUNK: usize = 1 << 15;

/// `v` zeroed, as the initialised values it then is. Each pass's output is
/// allocated without zeroing; a task whose kernel writes every value of its
/// part leaves it so, the others zero their own part just before writing
/// it, in their cache: `vec![0.0; n]` zeroed the whole output on
/// the calling thread first (with the leaky ReLU's, 4.6 % of a one-thread
/// training step in a profile; burn's tensors own their buffers, so none
/// is reused).
pub(crate) fn zeroed(v: &mut [MaybeUninit<f32>]) -> &mut [f32] {
    for x in v.iter_mut() {
        x.write(0.0);
    }
    // SAFETY: every value was just written, and `MaybeUninit<f32>` has
    // `f32`'s layout.
    unsafe { &mut *(v as *mut [MaybeUninit<f32>] as *mut [f32]) }
}

/// `v` seen as values that may be written uninitialised.
///
/// # Safety
/// Only initialised values are written through the result (a kernel that
/// writes `f32`s), never `MaybeUninit::uninit()`.
pub(crate) unsafe fn as_uninit(v: &mut [f32]) -> &mut [MaybeUninit<f32>] {
    // SAFETY: the same layout; the caller's contract keeps `v` initialised.
    unsafe { &mut *(v as *mut [f32] as *mut [MaybeUninit<f32>]) }
}

/// A vector of `n` values written by `fill`, which is given them
/// uninitialised.
///
/// # Safety
/// `fill` writes every one of them (each of the convolution's passes does:
/// its tasks write their part through the direct kernel, which covers it,
/// write each value (the grouped passes), or [`zeroed`] it first).
pub(crate) unsafe fn written(n: usize, fill: impl FnOnce(&mut [MaybeUninit<f32>])) -> Vec<f32> {
    let mut v = Vec::with_capacity(n);
    fill(&mut v.spare_capacity_mut()[..n]);
    // SAFETY: the caller's contract: `fill` wrote all `n`.
    unsafe { v.set_len(n) };
    v
}
/// The tensor in contiguous layout (copied only if it is not), or `None`
/// for another dtype than f32.
pub(crate) fn f32s(t: &FlexTensor) -> Option<FlexTensor> {
    (t.dtype() == DType::F32).then(|| t.to_contiguous())
}

/// A `[B, C, H, W]` shape, or a panic naming `what` in `op`.
pub(crate) fn dims4(op: &str, what: &str, shape: &[usize]) -> [usize; 4] {
    match *shape {
        [b, c, h, w] => [b, c, h, w],
        _ => panic!("{op}: {what} of shape {shape:?}, not [B, C, H, W]"),
    }
}

/// A contiguous f32 flex tensor of `shape` holding `values`.
pub(crate) fn flex_tensor(values: Vec<f32>, shape: Vec<usize>) -> FlexTensor {
    FlexTensor::from_data(burn::tensor::TensorData::new(values, shape))
}
