//! The repository's Python virtual environments that tests run other tools'
//! code in (scripts/interop-venv.sh, scripts/torch-venv.sh): which
//! interpreter, and whether a test may skip without it.

use std::path::PathBuf;
use std::process::{Command, Stdio};

/// One environment: the variable naming its interpreter, the variable
/// that makes it required, its directory under the repository root and the
/// script that makes it.
#[derive(Debug, Clone, Copy)]
pub struct Venv {
    /// Names the interpreter (e.g. `INTEROP_PYTHON`).
    pub var: &'static str,
    /// `1` makes it required (e.g. `INTEROP_REQUIRED`; scripts/test.sh sets it).
    pub required_var: &'static str,
    /// Its directory under the repository root (e.g. `.venv-interop`).
    pub dir: &'static str,
    /// The script that installs it.
    pub script: &'static str,
}

/// scripts/interop-venv.sh's environment.
pub const INTEROP: Venv = Venv {
    var: "INTEROP_PYTHON",
    required_var: "INTEROP_REQUIRED",
    dir: ".venv-interop",
    script: "scripts/interop-venv.sh",
};

/// scripts/torch-venv.sh's environment.
pub const TORCH: Venv = Venv {
    var: "TORCH_PYTHON",
    required_var: "TORCH_REQUIRED",
    dir: ".venv-torch",
    script: "scripts/torch-venv.sh",
};

impl Venv {
    /// `$var`, else the repository's `dir`, if it runs `import {modules}`.
    /// None (the test then skips, saying so) when it cannot and neither
    /// `$required_var` is 1 nor `$CI` is set; otherwise a failure naming
    /// `what` is missing.
    pub fn python(&self, modules: &str, what: &str) -> Option<PathBuf> {
        let py = std::env::var_os(self.var)
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                    .join("..")
                    .join(self.dir)
                    .join("bin/python")
            });
        let check = format!("import {modules}");
        let ok = Command::new(&py)
            .args(["-c", &check])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        let required =
            std::env::var(self.required_var).is_ok_and(|v| v == "1") || std::env::var("CI").is_ok();
        assert!(
            ok || !required,
            "{what} required here but `{} -c '{check}'` fails; run {}",
            py.display(),
            self.script
        );
        if !ok {
            eprintln!(
                "\n*** SKIPPED: {what} not importable by {} ***\n",
                py.display()
            );
        }
        ok.then_some(py)
    }
}
