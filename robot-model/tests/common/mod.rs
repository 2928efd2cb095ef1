//! Helpers shared by robot-model's integration tests.
#![allow(dead_code)]

use robot_model::{LoadOptions, Model};
use std::path::PathBuf;

/// Path of a file under the crate directory.
pub fn crate_path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The robots every identity runs on: the two arms and the test tree.
pub fn robots() -> Vec<(&'static str, Model)> {
    [
        "urdf/panda.urdf",
        "urdf/iiwa14.urdf",
        "tests/fixtures/tree.urdf",
    ]
    .into_iter()
    .map(|p| {
        let m = Model::from_urdf_file(crate_path(p), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{p}: {e}"));
        (p, m)
    })
    .collect()
}

/// Deterministic pseudo-random numbers (splitmix64): tests must be
/// reproducible without a rand dependency.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }

    pub fn vec(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n).map(|_| self.uniform(lo, hi)).collect()
    }

    /// A configuration inside the joint limits (within ±π for unbounded).
    pub fn config(&mut self, model: &Model) -> Vec<f64> {
        model.joints[1..]
            .iter()
            .map(|j| {
                let lo = j.limits.lower.max(-std::f64::consts::PI);
                let hi = j.limits.upper.min(std::f64::consts::PI);
                self.uniform(lo, hi)
            })
            .collect()
    }
}

pub fn axpy(x: &[f64], s: f64, d: &[f64]) -> Vec<f64> {
    x.iter().zip(d).map(|(a, b)| a + s * b).collect()
}
