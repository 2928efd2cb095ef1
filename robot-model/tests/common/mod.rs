//! Helpers shared by robot-model's integration tests.
#![allow(dead_code)]

use robot_model::{LoadOptions, Model};
use std::path::PathBuf;
use test_support::Uniform;

/// Path of a file under the crate directory.
pub fn crate_path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The robots every identity runs on: the three arms and the test tree.
pub fn robots() -> Vec<(&'static str, Model)> {
    [
        "urdf/panda.urdf",
        "urdf/iiwa14.urdf",
        "urdf/fr3.urdf",
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

/// A configuration inside the joint limits (within ±π for unbounded).
pub fn random_config(rng: &mut test_support::Rng, model: &Model) -> Vec<f64> {
    model.joints[1..]
        .iter()
        .map(|j| {
            let lo = j.limits.lower.max(-std::f64::consts::PI);
            let hi = j.limits.upper.min(std::f64::consts::PI);
            rng.uniform(lo, hi)
        })
        .collect()
}

pub fn axpy(x: &[f64], s: f64, d: &[f64]) -> Vec<f64> {
    x.iter().zip(d).map(|(a, b)| a + s * b).collect()
}
