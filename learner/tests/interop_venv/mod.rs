//! The interpreters of the repository's interop and PyTorch virtual
//! environments (scripts/interop-venv.sh, scripts/torch-venv.sh), shared by
//! the tests that run other tools' Python code (interop.rs,
//! dataset_import.rs, repr_export.rs), and the check that a command they
//! run succeeded.

use std::path::PathBuf;
use std::process::Command;

/// `$INTEROP_PYTHON`, else the repository's `.venv-interop`, if it runs
/// `import {modules}` ([`test_support::venv::Venv::python`]).
#[allow(dead_code)] // Each test file uses one of the two venvs.
pub fn python(modules: &str, what: &str) -> Option<PathBuf> {
    test_support::venv::INTEROP.python(modules, what)
}

/// The same for the PyTorch environment (scripts/torch-venv.sh).
#[allow(dead_code)]
pub fn torch_python(modules: &str, what: &str) -> Option<PathBuf> {
    test_support::venv::TORCH.python(modules, what)
}

/// Runs `cmd` and returns its stdout; fails the test with its stderr when
/// it does not succeed.
pub fn run_ok(cmd: &mut Command) -> Vec<u8> {
    let run = cmd.output().unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    run.stdout
}
