//! Starting and stopping the whole stack as separate processes: hw-sim,
//! rt-controller and the live policy node (`learner run`), found next to
//! the running executable (all three are built into one target directory).

use crate::log::LogError;
use shared_mem_schema::process::termination_requested;
use shared_mem_schema::transport::TransportError;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Why the stack, or the live policy node in it, failed; names the process,
/// file or episode at fault.
#[derive(Debug, thiserror::Error)]
pub enum StackError {
    /// The running executable could not be located.
    #[error("locating the learner executable: {0}")]
    CurrentExe(#[source] std::io::Error),
    /// The running executable's path has no directory.
    #[error("the executable {} has no directory", .0.display())]
    NoExeDir(PathBuf),
    /// A stack executable is missing.
    #[error(
        "{} not found: build the stack first (cargo build --release -p hw-sim -p rt-controller \
         -p learner)",
        .0.display()
    )]
    NotBuilt(PathBuf),
    /// A file or directory could not be created or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A process could not be started.
    #[error("starting {name} ({}): {source}", program.display())]
    Spawn {
        /// Its name for messages.
        name: String,
        /// The executable.
        program: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// hw-sim or rt-controller ended while the policy node ran.
    #[error("{name} exited early ({status}); see {}", log.display())]
    ExitedEarly {
        /// The process.
        name: String,
        /// How it ended.
        status: ExitStatus,
        /// Its output.
        log: PathBuf,
    },
    /// The policy node (`learner run`) failed.
    #[error("the policy node failed ({0})")]
    PolicyNodeFailed(ExitStatus),
    /// The world configuration could not be printed as TOML.
    #[error("printing the world configuration: {0}")]
    WorldToml(#[from] toml::ser::Error),
    /// The world configuration does not fit in a reset command.
    #[error("the world configuration is {bytes} bytes, a command carries at most {max}")]
    WorldTooLarge {
        /// Its size.
        bytes: usize,
        /// [`shared_mem_schema::MAX_CONFIG_BYTES`].
        max: usize,
    },
    /// The simulator refused a reset.
    #[error("the simulator refused the reset: {0}")]
    ResetRefused(String),
    /// No answer to a reset within 15 s.
    #[error("no answer from the simulator to a reset within 15 s (is hw-sim running?)")]
    NoResetAnswer,
    /// A termination request came while waiting for the simulator.
    #[error("interrupted while waiting for the simulator")]
    Interrupted,
    /// The controller kept its fault through 10 s of reset commands.
    #[error("the controller did not clear its fault on reset ({0})")]
    ControllerReset(&'static str),
    /// No sensor frames arrived for 10 s at the start of an episode.
    #[error("no sensor frames from rt-controller for 10 s (is it running?)")]
    NoSensorFrames,
    /// The sensor frames stopped for 2 s during an episode.
    #[error("sensor frames stopped for 2 s in episode {0}")]
    FramesStopped(u64),
    /// A shared-memory service failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// An episode's log could not be written.
    #[error(transparent)]
    Log(#[from] LogError),
}

/// Where the stack's executables are: next to the current one.
pub fn bin_dir() -> Result<PathBuf, StackError> {
    let exe = std::env::current_exe().map_err(StackError::CurrentExe)?;
    let dir = exe
        .parent()
        .ok_or_else(|| StackError::NoExeDir(exe.clone()))?;
    // Test binaries run from target/<profile>/deps.
    Ok(if dir.ends_with("deps") {
        dir.parent().unwrap_or(dir).to_path_buf()
    } else {
        dir.to_path_buf()
    })
}

/// Path of a stack executable, with a clear error when it is not built.
pub fn executable(dir: &Path, name: &str) -> Result<PathBuf, StackError> {
    let p = dir.join(name);
    if !p.is_file() {
        return Err(StackError::NotBuilt(p));
    }
    Ok(p)
}

/// A child process that is stopped (SIGTERM, then SIGKILL) when dropped.
pub struct Managed {
    /// Name for messages.
    pub name: String,
    child: Option<Child>,
}

impl Managed {
    /// Starts `cmd`; its output goes to `log` when given.
    pub fn spawn(name: &str, mut cmd: Command, log: Option<&Path>) -> Result<Self, StackError> {
        if let Some(log) = log {
            let err = |source: std::io::Error| StackError::Io {
                path: log.to_path_buf(),
                source,
            };
            let f = std::fs::File::create(log).map_err(err)?;
            cmd.stdout(f.try_clone().map_err(err)?).stderr(f);
        }
        cmd.stdin(Stdio::null());
        let child = cmd.spawn().map_err(|source| StackError::Spawn {
            name: name.into(),
            program: cmd.get_program().into(),
            source,
        })?;
        Ok(Self {
            name: name.into(),
            child: Some(child),
        })
    }

    /// The process id.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }

    /// Sends a signal.
    pub fn signal(&self, sig: i32) {
        if let Some(pid) = self.pid() {
            // SAFETY: plain syscall on our own child.
            unsafe { libc::kill(pid as i32, sig) };
        }
    }

    /// Exit status if it has exited.
    pub fn try_wait(&mut self) -> Option<std::process::ExitStatus> {
        self.child
            .as_mut()
            .and_then(|c| c.try_wait().ok().flatten())
    }

    /// Waits up to `timeout` for an exit.
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let start = Instant::now();
        loop {
            if let Some(s) = self.try_wait() {
                return Some(s);
            }
            if start.elapsed() > timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// SIGTERM, wait up to `grace`, then SIGKILL. Returns the exit status.
    pub fn stop(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        if let Some(s) = self.try_wait() {
            self.child = None;
            return Some(s);
        }
        self.signal(libc::SIGTERM);
        let s = self.wait_timeout(grace).or_else(|| {
            self.signal(libc::SIGKILL);
            self.wait_timeout(Duration::from_secs(2))
        });
        self.child = None;
        s
    }
}

impl Drop for Managed {
    fn drop(&mut self) {
        if self.child.is_some() {
            self.stop(Duration::from_secs(2));
        }
    }
}

/// Settings of a stack run.
#[derive(Debug, Clone)]
pub struct StackConfig {
    /// Service namespace.
    pub namespace: String,
    /// Lockstep instead of real time.
    pub lockstep: bool,
    /// Extra arguments for `learner run`.
    pub run_args: Vec<String>,
    /// Directory of logs (process logs and MCAP).
    pub log_dir: PathBuf,
    /// Daemon configuration file, if any.
    pub controller_config: Option<PathBuf>,
}

/// Starts hw-sim and rt-controller, runs `learner run` to completion in the
/// foreground (its output is ours), and stops everything. Returns the
/// policy node's exit status.
pub fn run(cfg: &StackConfig) -> Result<ExitStatus, StackError> {
    let dir = bin_dir()?;
    let sim_bin = executable(&dir, "hw-sim")?;
    let ctl_bin = executable(&dir, "rt-controller")?;
    let learner_bin = executable(&dir, "learner")?;
    std::fs::create_dir_all(&cfg.log_dir).map_err(|source| StackError::Io {
        path: cfg.log_dir.clone(),
        source,
    })?;
    shared_mem_schema::transport::cleanup_dead_nodes();
    let mode = if cfg.lockstep { "lockstep" } else { "realtime" };
    let mut sim_cmd = Command::new(&sim_bin);
    sim_cmd.args(["--mode", mode, "--namespace", &cfg.namespace]);
    let mut sim = Managed::spawn("hw-sim", sim_cmd, Some(&cfg.log_dir.join("hw-sim.log")))?;
    let mut ctl_cmd = Command::new(&ctl_bin);
    ctl_cmd.args(["--namespace", &cfg.namespace]);
    if cfg.lockstep {
        ctl_cmd.args(["--clock", "hardware", "--lockstep-actions"]);
    }
    if let Some(c) = &cfg.controller_config {
        ctl_cmd.arg("--config").arg(c);
    }
    let mut ctl = Managed::spawn(
        "rt-controller",
        ctl_cmd,
        Some(&cfg.log_dir.join("rt-controller.log")),
    )?;
    let mut run_cmd = Command::new(&learner_bin);
    run_cmd
        .arg("run")
        .args(["--namespace", &cfg.namespace])
        .arg("--log-dir")
        .arg(&cfg.log_dir)
        .args(&cfg.run_args);
    if cfg.lockstep {
        run_cmd.arg("--lockstep");
    }
    let mut policy = Managed::spawn("learner run", run_cmd, None)?;
    let status = loop {
        if let Some(s) = policy.try_wait() {
            break s;
        }
        for p in [&mut sim, &mut ctl] {
            if let Some(s) = p.try_wait() {
                policy.stop(Duration::from_secs(3));
                return Err(StackError::ExitedEarly {
                    name: p.name.clone(),
                    status: s,
                    log: cfg.log_dir.join(format!("{}.log", p.name)),
                });
            }
        }
        if termination_requested() {
            // The children got the terminal's SIGINT too; make sure.
            policy.stop(Duration::from_secs(3));
            break policy.try_wait().unwrap_or_default();
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    // Controller first: it holds the pose, then stops sending; the
    // simulator's brakes then hold the arm.
    ctl.stop(Duration::from_secs(5));
    sim.stop(Duration::from_secs(5));
    shared_mem_schema::transport::cleanup_dead_nodes();
    Ok(status)
}
