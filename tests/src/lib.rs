//! # tests
//!
//! Holds the workspace's end-to-end tests: multi-process runs of hw-sim,
//! rt-controller and the learner, fault tests, and the timing/jitter harness
//! (`cargo run --release -p tests --bin jitter`). The library part holds only
//! helpers for those (paths, building and starting the stack's processes).
//!
//! It must not hold product code: anything a deployed process runs belongs to
//! another crate.

use learner_node::stack::Managed;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

/// Absolute path of the workspace root, for tests that need the repository's
/// files (robot descriptions, configuration).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate lives one level below the workspace root")
        .to_path_buf()
}

/// The directory of the stack's executables of this build profile, built
/// (once per test process) so that a test never runs stale binaries.
pub fn stack_bins() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = learner_node::stack::bin_dir().expect("locating the target directory");
        let release = dir.ends_with("release");
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.current_dir(workspace_root()).args([
            "build",
            "--quiet",
            "-p",
            "hw-sim",
            "-p",
            "rt-controller-daemon",
            "-p",
            "learner",
            "-p",
            "learner-node",
            "--bins",
        ]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("running cargo build for the stack");
        assert!(status.success(), "building the stack's binaries failed");
        dir
    })
}

/// Serialises the tests that start processes: two cores cannot run two
/// stacks side by side without their timing interfering.
pub fn exclusive() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// A namespace no other run uses.
pub fn unique_namespace(tag: &str) -> String {
    format!("e2e-{tag}-{}", std::process::id())
}

/// Starts one of the stack's executables with `args`; its output goes to
/// `<log_dir>/<name>.log`.
pub fn start(name: &str, args: &[&str], log_dir: &Path) -> Managed {
    let bin = stack_bins().join(name);
    let mut cmd = Command::new(&bin);
    cmd.args(args);
    std::fs::create_dir_all(log_dir).expect("log directory");
    Managed::spawn(name, cmd, Some(&log_dir.join(format!("{name}.log"))))
        .unwrap_or_else(|e| panic!("starting {}: {e:#}", bin.display()))
}

/// Drains `sub` until `pred` holds for a message or `timeout` passes.
pub fn wait_for<T: shared_mem_schema::Message>(
    sub: &shared_mem_schema::transport::Sub<T>,
    timeout: Duration,
    mut pred: impl FnMut(&T) -> bool,
) -> Option<T> {
    let start = Instant::now();
    while start.elapsed() < timeout {
        let mut hit = None;
        shared_mem_schema::transport::drain(sub, |m| {
            if hit.is_none() && pred(m) {
                hit = Some(*m);
            }
        })
        .unwrap();
        if hit.is_some() {
            return hit;
        }
        std::thread::sleep(Duration::from_micros(300));
    }
    None
}
