//! Initial weights from our own seeded generator, not burn's: burn's
//! generator is one per process and draws lazily, at a parameter's first
//! use, so two models initialised in parallel (tests, or a sweep in one
//! process) would interleave their draws. With ours, a seed gives the same
//! network on any backend and in any order.
//!
//! The scheme is the authors' (their code's `init_weights`): convolutions
//! (rank 3 and 4 weights) He-normal, std √(2 / fan_in) with fan_in the
//! input channels times the kernel size (`dims[1]·k…`, PyTorch's rule, for
//! transposed convolutions too); fully connected weights (burn's layout
//! `[in, out]`) uniform in ±1/√in, PyTorch's default; every bias zero.

use burn::module::{Module, ModuleMapper, Param};
use burn::prelude::*;
use stack_common::rng;

struct SeededInit {
    rng: rng::SimRng,
}

impl ModuleMapper for SeededInit {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let r = &mut self.rng;
        param.map(|t| {
            let dims = t.dims();
            let device = t.device();
            let tracked = t.is_require_grad();
            let n: usize = dims.iter().product();
            let values: Vec<f32> = match D {
                1 => vec![0.0; n],
                2 => {
                    let bound = 1.0 / (dims[0].max(1) as f64).sqrt();
                    (0..n)
                        .map(|_| ((2.0 * rng::unit(r) - 1.0) * bound) as f32)
                        .collect()
                }
                _ => {
                    let fan_in: usize = dims[1..].iter().product();
                    let std = (2.0 / fan_in.max(1) as f64).sqrt();
                    (0..n).map(|_| (rng::normal(r) * std) as f32).collect()
                }
            };
            // A fresh tensor is a constant: track it as the one it replaces.
            Tensor::from_data(TensorData::new(values, dims), &device).set_require_grad(tracked)
        })
    }
}

/// `m` with every float parameter drawn afresh from `seed`.
pub fn seeded<M: Module>(m: M, seed: u64) -> M {
    m.map(&mut SeededInit {
        rng: rng::seeded(seed, 53),
    })
}
