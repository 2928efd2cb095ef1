//! What the tests that run franky-sim (a simulated FR3, docs/franka.md)
//! share: its interpreter, whether a test may run here, and a loopback
//! address of the test's own.

use std::path::PathBuf;
use std::process::{Command, Stdio};

/// franky-sim's interpreter: `$FRANKY_SIM_PYTHON`, else the repository's
/// `.venv-franky-sim` (scripts/franky-sim-venv.sh).
pub fn python() -> PathBuf {
    std::env::var_os("FRANKY_SIM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv-franky-sim/bin/python")
        })
}

/// Whether `test` can run: franky-sim imports. When it does not, the test
/// fails if `$FRANKY_SIM_REQUIRED=1` or `$CI` is set (scripts/test.sh sets
/// the first), and is otherwise skipped with a message on stderr.
pub fn available_for(test: &str) -> bool {
    let importable = Command::new(python())
        .args(["-c", "import franky_sim"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if importable {
        return true;
    }
    let required =
        std::env::var("FRANKY_SIM_REQUIRED").is_ok_and(|v| v == "1") || std::env::var("CI").is_ok();
    assert!(
        !required,
        "franky-sim is required here but `{} -c 'import franky_sim'` fails; run \
         scripts/franky-sim-venv.sh",
        python().display()
    );
    eprintln!(
        "\n*** {test} SKIPPED: franky-sim is not importable by {}; run ./scripts/test.sh or set \
         FRANKY_SIM_PYTHON. ***\n",
        python().display()
    );
    false
}

/// A loopback address of this process's own in 127.`net`.0.0/16: franky-sim
/// always serves port 1337 but binds any 127.x.y.z, and serves one client at
/// a time, so concurrent runs must not meet. Each test takes its own `net`.
pub fn loopback_address(net: u8) -> String {
    let pid = std::process::id();
    format!(
        "127.{net}.{}.{}",
        (pid >> 8) & 0xff,
        (pid & 0xff).clamp(1, 254)
    )
}
