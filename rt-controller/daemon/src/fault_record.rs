//! The fault record: what makes a latched fault outlive the daemon's
//! process (docs/operation.md, "Faults across restarts").
//!
//! A daemon configured with `fault_record = PATH` holds an exclusive lock
//! on `PATH.lock` for its whole life and keeps `PATH` saying either
//! `running` (written before it takes the arm) or `fault` (written by the
//! monitor thread when the loop latches Fault or HardwareLost, and at exit
//! on a robot error). A clean stop removes `PATH`. So at start-up a record
//! is either a fault, or a daemon that ended without a clean stop (a crash,
//! the watchdog's kill, a power cut): both refuse the start until
//! `rt-controller reset`, which clears the record, appends the reset to
//! `PATH.history` and counts it there. Writes are atomic (a temporary file,
//! fsync, rename) and never happen on the real-time thread.

use serde::{Deserialize, Serialize};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

/// What a fault record file says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordEntry {
    /// `running` or `fault`.
    pub state: RecordState,
    /// The fault code (0 while running).
    pub code: u32,
    /// The fault in words (or what the daemon was doing).
    pub reason: String,
    /// The daemon's process id.
    pub pid: u32,
    /// When it was written, s since the Unix epoch.
    pub unix_s: f64,
}

/// The state a record holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordState {
    /// A daemon holds (or held, if it is gone) the arm.
    Running,
    /// A fault was latched.
    Fault,
}

/// Why the record could not be used.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Another daemon holds the record's lock.
    #[error(
        "another rt-controller holds the fault record {0} (its lock file {0}.lock): one daemon per \
         record"
    )]
    Held(PathBuf),
    /// The record or its lock could not be read or written.
    #[error("fault record {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The record is not a record.
    #[error(
        "fault record {path} is unreadable ({detail}); check the robot, then `rt-controller reset` \
         clears it"
    )]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
}

/// The fault code in words (the control law's, the daemon's and the
/// robot's codes).
pub fn fault_name(code: u32) -> &'static str {
    match code {
        0 => "none",
        1 => "a non-finite hardware state",
        2 => "a joint position limit",
        3 => "a joint velocity limit",
        4 => "a force overload",
        5 => "a moment overload",
        6 => "a dynamics failure",
        7 => "a non-finite torque",
        crate::FAULT_HARDWARE_SILENT => "the hardware silent",
        crate::FAULT_ROBOT_COMMUNICATION => "the robot's communication constraints",
        crate::FAULT_ROBOT_LIMIT => "one of the robot's limits",
        crate::FAULT_ROBOT_REFLEX => "a reflex of the robot (collision)",
        crate::FAULT_ROBOT_OTHER => "another robot error",
        crate::FAULT_FT_SENSOR => "the F/T sensor",
        crate::FAULT_DAEMON_ERROR => "the daemon's own error while it held the arm",
        _ => "an unknown fault code",
    }
}

/// The record of one daemon (or of the `reset` command), with its lock held.
#[derive(Debug)]
pub struct FaultRecord {
    path: PathBuf,
    _lock: File,
}

fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

impl FaultRecord {
    /// [`FaultRecord::lock`], retried for up to `wait`: a `reset` or
    /// `status` that holds the lock for a moment does not turn a start into
    /// "another daemon holds it".
    pub fn lock_within(path: &Path, wait: std::time::Duration) -> Result<Self, RecordError> {
        let start = std::time::Instant::now();
        loop {
            match Self::lock(path) {
                Err(RecordError::Held(_)) if start.elapsed() < wait => {
                    std::thread::sleep(std::time::Duration::from_millis(100));
                }
                r => return r,
            }
        }
    }

    /// Takes the record at `path`: its lock, held until drop, so that no
    /// second daemon (or a `reset` while one runs) uses it.
    pub fn lock(path: &Path) -> Result<Self, RecordError> {
        let io = |source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        };
        let lock_path = with_suffix(path, ".lock");
        // Read-only when it exists (flock needs no write access): a lock
        // file another user created does not lock the daemon out.
        let lock = match File::open(&lock_path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&lock_path)
                .map_err(io)?,
            Err(e) => return Err(io(e)),
        };
        // SAFETY: flock on a descriptor this function owns.
        let r = unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if r != 0 {
            let e = std::io::Error::last_os_error();
            return Err(if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
                RecordError::Held(path.to_path_buf())
            } else {
                io(e)
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            _lock: lock,
        })
    }

    /// The record's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the record says (None: no record, the last daemon stopped
    /// cleanly).
    pub fn read(&self) -> Result<Option<RecordEntry>, RecordError> {
        let text = match std::fs::read_to_string(&self.path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(RecordError::Io {
                    path: self.path.clone(),
                    source: e,
                });
            }
        };
        toml::from_str(&text)
            .map(Some)
            .map_err(|e| RecordError::Malformed {
                path: self.path.clone(),
                detail: e.message().to_string(),
            })
    }

    fn write(&self, state: RecordState, code: u32, reason: &str) -> Result<(), RecordError> {
        let entry = RecordEntry {
            state,
            code,
            reason: reason.to_string(),
            pid: std::process::id(),
            unix_s: unix_now_s(),
        };
        let text = toml::to_string(&entry).expect("a record serialises");
        let tmp = with_suffix(&self.path, ".tmp");
        let io = |source| RecordError::Io {
            path: self.path.clone(),
            source,
        };
        let mut f = File::create(&tmp).map_err(io)?;
        f.write_all(text.as_bytes()).map_err(io)?;
        f.sync_all().map_err(io)?;
        std::fs::rename(&tmp, &self.path).map_err(io)?;
        self.sync_dir()
    }

    fn sync_dir(&self) -> Result<(), RecordError> {
        let dir = match self.path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|source| RecordError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// Says a daemon is about to take the arm.
    pub fn mark_running(&self) -> Result<(), RecordError> {
        self.write(RecordState::Running, 0, "controlling the arm")
    }

    /// Records a latched fault and appends it to the history.
    pub fn record_fault(&self, code: u32) -> Result<(), RecordError> {
        self.write(RecordState::Fault, code, fault_name(code))?;
        self.append_history(&format!("fault {code} ({})", fault_name(code)))
    }

    /// The daemon stopped cleanly, no fault latched: no record.
    pub fn clear_clean(&self) -> Result<(), RecordError> {
        match std::fs::remove_file(&self.path) {
            Ok(()) => self.sync_dir(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(source) => Err(RecordError::Io {
                path: self.path.clone(),
                source,
            }),
        }
    }

    /// The operator's reset with no daemon running: the record (a fault,
    /// an unclean end or an unreadable file) is removed and the reset
    /// appended to the history. Returns the resets on record in all.
    pub fn operator_reset(&self, cleared: &str) -> Result<u64, RecordError> {
        self.append_history(&format!(
            "reset by `rt-controller reset`: cleared {cleared}"
        ))?;
        self.clear_clean()?;
        self.resets()
    }

    /// The history file (`PATH.history`).
    pub fn history_path(&self) -> PathBuf {
        with_suffix(&self.path, ".history")
    }

    fn append_history(&self, line: &str) -> Result<(), RecordError> {
        let path = self.history_path();
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        let mut f = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io)?;
        writeln!(f, "{:.3} pid {} {line}", unix_now_s(), std::process::id()).map_err(io)?;
        f.sync_all().map_err(io)
    }

    /// Resets counted in the history.
    pub fn resets(&self) -> Result<u64, RecordError> {
        match std::fs::read_to_string(self.history_path()) {
            Ok(t) => Ok(t.lines().filter(|l| l.contains(" reset by ")).count() as u64),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
            Err(source) => Err(RecordError::Io {
                path: self.history_path(),
                source,
            }),
        }
    }
}

/// What changed since the monitor's last look, for the record's writer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordUpdate {
    /// Faults latched since (each gets a history line).
    pub new_faults: u64,
    /// The code of the last of them.
    pub latched_code: u32,
    /// Resets by command since (each gets a history line).
    pub new_resets: u64,
    /// The fault latched now (0: none): the record's final state.
    pub fault_now: u32,
}

impl FaultRecord {
    /// Appends the update's faults and resets to the history, then leaves
    /// the record as the daemon is now: `fault` with the code latched now,
    /// else `running`.
    pub fn apply(&self, u: &RecordUpdate) -> Result<(), RecordError> {
        for _ in 0..u.new_faults {
            let c = u.latched_code;
            self.append_history(&format!("fault {c} ({})", fault_name(c)))?;
        }
        for _ in 0..u.new_resets {
            self.append_history("reset by a reset command to the running daemon")?;
        }
        if u.fault_now != 0 {
            self.write(RecordState::Fault, u.fault_now, fault_name(u.fault_now))
        } else {
            self.mark_running()
        }
    }

    /// Starts the thread that writes the record (fsync can take long on a
    /// busy disk: never on the thread that feeds the watchdog); it ends
    /// when the sender is dropped.
    pub fn spawn_writer(
        self: std::sync::Arc<Self>,
    ) -> std::io::Result<(
        std::sync::mpsc::Sender<RecordUpdate>,
        std::thread::JoinHandle<()>,
    )> {
        let (tx, rx) = std::sync::mpsc::channel::<RecordUpdate>();
        let handle = std::thread::Builder::new()
            .name("rt-record".into())
            .spawn(move || {
                for u in rx {
                    if let Err(e) = self.apply(&u) {
                        tracing::error!("rt-controller: {e}");
                    }
                }
            })?;
        Ok((tx, handle))
    }
}

/// Why a start-up is refused: the record's entry in words, or None when a
/// daemon may start.
pub fn refusal(entry: &Option<RecordEntry>) -> Option<String> {
    let e = entry.as_ref()?;
    Some(match e.state {
        RecordState::Fault => format!(
            "fault {} ({}) latched by rt-controller pid {} at {:.0} s (Unix time)",
            e.code, e.reason, e.pid, e.unix_s
        ),
        RecordState::Running => format!(
            "rt-controller pid {} took the arm at {:.0} s (Unix time) and ended without a clean \
             stop (a crash, the watchdog's kill or a power cut)",
            e.pid, e.unix_s
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_is_locked_written_read_and_cleared() {
        let dir = std::env::temp_dir().join(format!("fault-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rt.fault");
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(with_suffix(&path, ".history"));
        let r = FaultRecord::lock(&path).unwrap();
        assert!(matches!(
            FaultRecord::lock(&path),
            Err(RecordError::Held(_))
        ));
        assert_eq!(r.read().unwrap(), None);
        assert_eq!(refusal(&None), None);
        r.mark_running().unwrap();
        let e = r.read().unwrap();
        assert_eq!(e.as_ref().unwrap().state, RecordState::Running);
        assert!(refusal(&e).unwrap().contains("without a clean stop"));
        r.record_fault(4).unwrap();
        let e = r.read().unwrap().unwrap();
        assert_eq!((e.state, e.code), (RecordState::Fault, 4));
        // The monitor's update: two faults and a reset between its looks,
        // none latched now.
        let u = RecordUpdate {
            new_faults: 2,
            latched_code: 5,
            new_resets: 1,
            fault_now: 0,
        };
        r.apply(&u).unwrap();
        assert_eq!(r.read().unwrap().unwrap().state, RecordState::Running);
        let history = std::fs::read_to_string(r.history_path()).unwrap();
        assert_eq!(history.matches("fault 5").count(), 2, "{history}");
        assert_eq!(r.resets().unwrap(), 1);
        r.apply(&RecordUpdate {
            fault_now: 100,
            ..u
        })
        .unwrap();
        let e = r.read().unwrap().unwrap();
        assert_eq!((e.state, e.code), (RecordState::Fault, 100));
        assert_eq!(r.operator_reset("a test").unwrap(), 3);
        assert_eq!(r.read().unwrap(), None);
        // A record that is no record is refused by name, and a reset
        // clears it.
        std::fs::write(&path, "state = 'sideways'").unwrap();
        let err = r.read().unwrap_err();
        assert!(err.to_string().contains("rt.fault"), "{err}");
        drop(r);
        let r = FaultRecord::lock(&path).unwrap();
        r.operator_reset("garbage").unwrap();
        assert_eq!(r.read().unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
