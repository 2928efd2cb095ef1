//! The interpreter of the repository's interop virtual environment
//! (scripts/interop-venv.sh), shared by the tests that run other tools'
//! Python code (interop.rs, dataset_import.rs).

use std::path::PathBuf;
use std::process::{Command, Stdio};

/// `$INTEROP_PYTHON`, else the repository's `.venv-interop`, if it runs
/// `import {modules}`. None (the test then skips, saying so) when it cannot
/// and `$INTEROP_REQUIRED` is not 1 (scripts/test.sh sets it) and `$CI` is
/// unset; otherwise a failure naming `what` is missing.
pub fn python(modules: &str, what: &str) -> Option<PathBuf> {
    let py = std::env::var_os("INTEROP_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv-interop/bin/python")
        });
    let check = format!("import {modules}");
    let ok = Command::new(&py)
        .args(["-c", &check])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let required =
        std::env::var("INTEROP_REQUIRED").is_ok_and(|v| v == "1") || std::env::var("CI").is_ok();
    assert!(
        ok || !required,
        "{what} required here but `{} -c '{check}'` fails; run scripts/interop-venv.sh",
        py.display()
    );
    if !ok {
        eprintln!(
            "\n*** SKIPPED: {what} not importable by {} ***\n",
            py.display()
        );
    }
    ok.then_some(py)
}
