//! # test-support
//!
//! What the workspace's tests share, so that no crate keeps its own copy:
//! the counting global allocator behind every allocation test ([`alloc`]),
//! the seeded generator of test inputs ([`rng`]), scratch directories
//! ([`scratch_dir`]) and what the franky-sim tests need ([`franky_sim`]).
//!
//! A dev-dependency only: nothing a deployed process runs may depend on it,
//! and it depends on no crate of the workspace (every crate can use it).

pub mod alloc;
pub mod franky_sim;
pub mod venv;

pub use rand::RngExt;
use rand::SeedableRng;
use std::path::Path;

/// The tests' generator: the same PCG-64 as the simulator's
/// (`stack_common::rng::SimRng`), seeded from a `u64`.
pub type Rng = rand_pcg::Pcg64;

/// A generator for `seed`: the same numbers on every run and platform.
pub fn rng(seed: u64) -> Rng {
    Rng::seed_from_u64(seed)
}

/// Uniform test inputs from any generator of rand's.
pub trait Uniform {
    /// Uniform in `[lo, hi)`.
    fn uniform(&mut self, lo: f64, hi: f64) -> f64;
    /// `n` values uniform in `[lo, hi)`.
    fn uniform_vec(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n).map(|_| self.uniform(lo, hi)).collect()
    }
}

impl<R: rand::Rng> Uniform for R {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.random::<f64>()
    }
}

/// A fresh scratch directory, removed when the guard drops — unless the
/// test is failing: then it is kept and its path printed, so that the logs
/// of a failed run can be read. `tag` appears in its name.
pub fn scratch_dir(tag: &str) -> ScratchDir {
    let dir = tempfile::Builder::new()
        .prefix(&format!("vt-{tag}-"))
        .tempdir()
        .expect("creating a scratch directory");
    ScratchDir(Some(dir))
}

/// A scratch directory (see [`scratch_dir`]); derefs to its path.
pub struct ScratchDir(Option<tempfile::TempDir>);

impl ScratchDir {
    /// The directory.
    pub fn path(&self) -> &Path {
        self.0.as_ref().expect("present until dropped").path()
    }
}

impl std::ops::Deref for ScratchDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.path()
    }
}

impl AsRef<Path> for ScratchDir {
    fn as_ref(&self) -> &Path {
        self.path()
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        if let Some(dir) = self.0.take()
            && std::thread::panicking()
        {
            eprintln!(
                "test failed: its files are kept in {}",
                dir.keep().display()
            );
        }
    }
}
