//! The interpreters of the repository's interop and PyTorch virtual
//! environments (scripts/interop-venv.sh, scripts/torch-venv.sh), shared by
//! the tests that run other tools' Python code (interop.rs,
//! dataset_import.rs, repr_export.rs), and the check that a command they
//! run succeeded.

use std::path::PathBuf;
use std::process::{Command, Stdio};

/// `$INTEROP_PYTHON`, else the repository's `.venv-interop`, if it runs
/// `import {modules}`. None (the test then skips, saying so) when it cannot
/// and `$INTEROP_REQUIRED` is not 1 (scripts/test.sh sets it) and `$CI` is
/// unset; otherwise a failure naming `what` is missing.
#[allow(dead_code)] // Each test file uses one of the two venvs.
pub fn python(modules: &str, what: &str) -> Option<PathBuf> {
    venv_python(
        ("INTEROP_PYTHON", "INTEROP_REQUIRED", ".venv-interop"),
        "scripts/interop-venv.sh",
        modules,
        what,
    )
}

/// The same for the PyTorch environment (scripts/torch-venv.sh):
/// `$TORCH_PYTHON` else `.venv-torch`, required under `$TORCH_REQUIRED`.
#[allow(dead_code)]
pub fn torch_python(modules: &str, what: &str) -> Option<PathBuf> {
    venv_python(
        ("TORCH_PYTHON", "TORCH_REQUIRED", ".venv-torch"),
        "scripts/torch-venv.sh",
        modules,
        what,
    )
}

fn venv_python(
    (var, required_var, dir): (&str, &str, &str),
    script: &str,
    modules: &str,
    what: &str,
) -> Option<PathBuf> {
    let py = std::env::var_os(var).map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(dir)
            .join("bin/python")
    });
    let check = format!("import {modules}");
    let ok = Command::new(&py)
        .args(["-c", &check])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let required =
        std::env::var(required_var).is_ok_and(|v| v == "1") || std::env::var("CI").is_ok();
    assert!(
        ok || !required,
        "{what} required here but `{} -c '{check}'` fails; run {script}",
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
