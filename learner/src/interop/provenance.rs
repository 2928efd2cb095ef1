//! What a run directory records about how it came to be (`run.json`): the
//! commit and whether the tree was dirty, the host, the start time, the
//! command line and the fully resolved configuration.

use serde::Serialize;
use std::path::Path;

/// The machine's host name ("unknown" when it cannot be read).
pub fn host_name() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most `buf.len()` bytes into `buf`.
    let r = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if r != 0 {
        return "unknown".into();
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    let name = String::from_utf8_lossy(&buf[..end]).into_owned();
    // The name ends up in file names (TensorBoard's event files).
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `git` run in the repository the binary was built from.
fn git(args: &[&str]) -> Option<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = std::process::Command::new("git")
        .arg("-C")
        .arg(&root)
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// A UTC time stamp, RFC 3339, from seconds since the Unix epoch.
pub fn utc_rfc3339(unix_s: u64) -> String {
    let days = (unix_s / 86_400) as i64;
    let secs = unix_s % 86_400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// One start of a command in a run directory.
#[derive(Debug, Serialize)]
pub struct RunStart {
    /// The commit the repository the binary was built from holds at the
    /// start (None: no git, or not a repository); with `dirty`, what the
    /// sources were if the binary was built from that tree.
    pub commit: Option<String>,
    /// Whether that tree had uncommitted changes.
    pub dirty: Option<bool>,
    /// The host.
    pub host: String,
    /// Start time, UTC.
    pub started: String,
    /// The command line.
    pub argv: Vec<String>,
    /// The resolved configuration the command runs with.
    pub config: serde_json::Value,
}

impl RunStart {
    /// This process's start with `config`.
    pub fn now(config: &impl Serialize) -> Self {
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        Self {
            commit: git(&["rev-parse", "HEAD"]),
            dirty: git(&["status", "--porcelain", "--untracked-files=no"]).map(|s| !s.is_empty()),
            host: host_name(),
            started: utc_rfc3339(unix),
            argv: std::env::args().collect(),
            config: serde_json::to_value(config).unwrap_or(serde_json::Value::Null),
        }
    }
}

/// Appends this start to `dir/run.json` (a JSON list: a resumed run keeps
/// every start it had).
pub fn record_start(dir: &Path, config: &impl Serialize) -> std::io::Result<()> {
    let path = dir.join("run.json");
    let mut starts: Vec<serde_json::Value> = match std::fs::read_to_string(&path) {
        Ok(t) => match serde_json::from_str(&t) {
            Ok(v) => v,
            Err(_) => {
                // Kept aside, not lost: the earlier starts stay readable.
                std::fs::rename(&path, dir.join("run.json.unreadable"))?;
                Vec::new()
            }
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e),
    };
    starts.push(serde_json::to_value(RunStart::now(config)).unwrap_or_default());
    let text = serde_json::to_string_pretty(&starts).map_err(std::io::Error::other)?;
    crate::write_atomic(&path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_stamps_are_utc_calendar_dates() {
        assert_eq!(utc_rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_rfc3339(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_rfc3339(1_796_173_413), "2026-12-02T01:03:33Z");
    }
}
