//! # tests
//!
//! Holds the workspace's end-to-end tests: multi-process runs of hw-sim,
//! rt-controller and the learner, fault tests, and the timing/jitter harness.
//! The library part holds only helpers for those tests (paths to the robot
//! descriptions, process handling).
//!
//! It must not hold product code: anything a deployed process runs belongs to
//! another crate.

use std::path::PathBuf;

/// Absolute path of the workspace root, for tests that need the repository's
/// files (robot descriptions, configuration).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate lives one level below the workspace root")
        .to_path_buf()
}
