//! Starting and stopping the whole stack as separate processes: hw-sim (or
//! franky-sim, a simulated Franka FR3), rt-controller and the live policy
//! node (the `run` command of the executable that starts the stack:
//! `policy-node` or `learner`), found next to the running executable (all
//! are built into one target directory).

use crate::log::LogOptions;
use crate::mix::Mix;
use hw_sim::{PegShape, WorldConfig};
use shared_mem_schema::process::termination_requested;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Why the stack failed to start or stop its processes; names the process
/// or file at fault (the node's own failures are its exit status).
#[derive(Debug, thiserror::Error)]
pub enum StackError {
    /// The running executable could not be located.
    #[error("locating the running executable: {0}")]
    CurrentExe(#[source] std::io::Error),
    /// The running executable's path has no directory.
    #[error("the executable {} has no directory", .0.display())]
    NoExeDir(PathBuf),
    /// A stack executable is missing.
    #[error(
        "{} not found: build the stack first (cargo build --release -p hw-sim -p rt-controller \
         -p learner-node)",
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
    /// The policy node (`run`) failed.
    #[error("the policy node failed ({0})")]
    PolicyNodeFailed(ExitStatus),
    /// The world configuration could not be printed as TOML.
    #[error("printing the world configuration: {0}")]
    WorldToml(#[from] toml::ser::Error),
    /// franky-sim cannot be run with the given interpreter.
    #[error(
        "franky-sim is not installed: `{} -c 'import franky_sim'` fails; run \
         `. scripts/franky-sim-venv.sh` (./scripts/run.sh --robot franky-sim does) or give \
         --franky-sim-python"
    , .0.display())]
    FrankySimMissing(PathBuf),
    /// The rt-controller configuration for franky-sim is unusable.
    #[error("{}: {source}", path.display())]
    ControllerConfig {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: rt_controller_daemon::config::DaemonConfigError,
    },
    /// The rt-controller configuration for franky-sim does not drive a
    /// Franka.
    #[error(
        "{}: backend.kind must be \"franka\" to drive franky-sim (found {kind:?})",
        path.display()
    )]
    NotFranka {
        /// The file.
        path: PathBuf,
        /// Its backend kind, as the file spells it.
        kind: String,
    },
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

/// What the controller drives.
#[derive(Debug, Clone)]
pub enum Hardware {
    /// hw-sim (the default): the peg, the box, the camera and the episode
    /// resets.
    Sim,
    /// franky-sim, a simulated FR3 over the Franka Control Interface: no
    /// peg, box, camera or resets (docs/franka.md, "The whole stack on
    /// franky-sim").
    FrankySim(FrankySim),
}

/// How to start franky-sim.
#[derive(Debug, Clone)]
pub struct FrankySim {
    /// A Python interpreter that imports `franky_sim`.
    pub python: PathBuf,
    /// Our shim, scripts/franky_sim_server.py.
    pub server: PathBuf,
    /// The loopback address it serves port 1337 on (one client at a time,
    /// so a run takes an address of its own).
    pub address: String,
}

impl FrankySim {
    /// The repository's defaults: `.venv-franky-sim`
    /// (scripts/franky-sim-venv.sh), and an address of
    /// this process's own in 127.20.0.0/16 (the Franka backend's test uses
    /// 127.19.0.0/16).
    pub fn from_repository() -> Self {
        let repo = repository_root();
        let pid = std::process::id();
        Self {
            python: repo.join(".venv-franky-sim/bin/python"),
            server: repo.join("scripts/franky_sim_server.py"),
            address: format!(
                "127.20.{}.{}",
                (pid >> 8) & 0xff,
                (pid & 0xff).clamp(1, 254)
            ),
        }
    }
}

/// The source tree this executable was built from (where scripts/ and
/// configs/ are during development).
pub fn repository_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The rt-controller configuration for franky-sim: `template` (a daemon
/// configuration with `backend.kind = "franka"`) with franky-sim's
/// address and the stack's namespace (and, unless the template names one,
/// a fault record beside `out`), written to `out` (the run's record of
/// what the daemon ran with).
pub fn franky_sim_controller_config(
    template: &Path,
    address: &str,
    namespace: &str,
    out: &Path,
) -> Result<(), StackError> {
    use rt_controller_daemon::config::{BackendKind, DaemonConfig};
    let mut c =
        DaemonConfig::from_file(template).map_err(|source| StackError::ControllerConfig {
            path: template.to_path_buf(),
            source,
        })?;
    if c.backend.kind != BackendKind::Franka {
        return Err(StackError::NotFranka {
            path: template.to_path_buf(),
            kind: format!("{:?}", c.backend.kind).to_lowercase(),
        });
    }
    c.backend.franka.address = address.to_string();
    c.backend.namespace = namespace.to_string();
    // A simulated robot's run keeps its fault record beside its logs, so
    // that one run's fault does not refuse the next run's start.
    if c.fault_record.is_none() {
        c.fault_record = Some(out.with_extension("fault"));
    }
    let text = format!(
        "# {} with franky-sim's address and the stack's namespace (learner stack --robot \
         franky-sim)\n{}",
        template.display(),
        c.to_toml()
    );
    std::fs::write(out, text).map_err(|source| StackError::Io {
        path: out.to_path_buf(),
        source,
    })
}

/// Settings of a stack run.
#[derive(Debug, Clone)]
pub struct StackConfig {
    /// What the controller drives.
    pub hardware: Hardware,
    /// Service namespace.
    pub namespace: String,
    /// Lockstep instead of real time.
    pub lockstep: bool,
    /// The node's executable, run as `<node> run` (the running one:
    /// [`std::env::current_exe`]).
    pub node: PathBuf,
    /// Extra arguments for the node's `run`.
    pub run_args: Vec<String>,
    /// Directory of logs (process logs and MCAP).
    pub log_dir: PathBuf,
    /// Daemon configuration file, if any (with franky-sim: the one the
    /// stack wrote, see [`franky_sim_controller_config`]).
    pub controller_config: Option<PathBuf>,
}

/// How the stack's processes ended.
#[derive(Debug, Clone, Copy)]
pub struct StackExit {
    /// The policy node's exit status.
    pub policy: ExitStatus,
    /// rt-controller's, after its SIGTERM (`None`: it did not end even on
    /// SIGKILL).
    pub controller: Option<ExitStatus>,
    /// The simulator's (hw-sim or franky-sim) after its SIGTERM.
    pub hardware: Option<ExitStatus>,
}

/// Starts the simulator (hw-sim or franky-sim) and rt-controller, runs
/// the node (`<node> run`) to completion in the foreground (its output is ours), and
/// stops everything: the controller first (SIGTERM: it holds the pose, then
/// exits), then the simulator.
pub fn run(cfg: &StackConfig) -> Result<StackExit, StackError> {
    let dir = bin_dir()?;
    let ctl_bin = executable(&dir, "rt-controller")?;
    std::fs::create_dir_all(&cfg.log_dir).map_err(|source| StackError::Io {
        path: cfg.log_dir.clone(),
        source,
    })?;
    shared_mem_schema::transport::cleanup_dead_nodes();
    let mode = if cfg.lockstep { "lockstep" } else { "realtime" };
    let mut sim = match &cfg.hardware {
        Hardware::Sim => {
            let mut sim_cmd = Command::new(executable(&dir, "hw-sim")?);
            sim_cmd.args(["--mode", mode, "--namespace", &cfg.namespace]);
            Managed::spawn("hw-sim", sim_cmd, Some(&cfg.log_dir.join("hw-sim.log")))?
        }
        Hardware::FrankySim(f) => {
            let importable = Command::new(&f.python)
                .args(["-c", "import franky_sim"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success());
            if !importable {
                return Err(StackError::FrankySimMissing(f.python.clone()));
            }
            if !f.server.is_file() {
                return Err(StackError::NotBuilt(f.server.clone()));
            }
            let mut cmd = Command::new(&f.python);
            cmd.arg(&f.server)
                .args(["-s", "mujoco", "--hostname", &f.address])
                .env("PYTHONUNBUFFERED", "1");
            eprintln!("stack: franky-sim on {}:1337", f.address);
            Managed::spawn("franky-sim", cmd, Some(&cfg.log_dir.join("franky-sim.log")))?
        }
    };
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
    let mut run_cmd = Command::new(&cfg.node);
    run_cmd
        .arg("run")
        .args(["--namespace", &cfg.namespace])
        .arg("--log-dir")
        .arg(&cfg.log_dir)
        .args(&cfg.run_args);
    if cfg.lockstep {
        run_cmd.arg("--lockstep");
    }
    let mut policy = Managed::spawn("policy node", run_cmd, None)?;
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
    // simulator's brakes (hw-sim) or the robot's own controller
    // (franky-sim, as a Franka) then hold the arm.
    let controller = ctl.stop(Duration::from_secs(5));
    let hardware = sim.stop(Duration::from_secs(5));
    shared_mem_schema::transport::cleanup_dead_nodes();
    Ok(StackExit {
        policy: status,
        controller,
        hardware,
    })
}

/// Live collection: `learner collect --live`.
#[derive(Debug, Clone)]
pub struct LiveCollect {
    /// Where the shards go (and the processes' logs).
    pub out_dir: PathBuf,
    /// States to collect.
    pub states: u64,
    /// Actions per episode.
    pub episode_actions: u32,
    /// Pegs taken in turn.
    pub pegs: Vec<PegShape>,
    /// Seed of the first episode.
    pub seed: u64,
    /// World configuration.
    pub world: WorldConfig,
    /// The policy mix.
    pub mix: Mix,
    /// Log options.
    pub log: LogOptions,
    /// rt-controller configuration file.
    pub controller_config: Option<PathBuf>,
}

/// Collects through the real-time stack: starts hw-sim and rt-controller
/// and runs the node (this executable's `run`) with the collection mix.
pub fn collect_live(c: &LiveCollect) -> Result<(), StackError> {
    std::fs::create_dir_all(&c.out_dir).map_err(|source| StackError::Io {
        path: c.out_dir.clone(),
        source,
    })?;
    let world_path = c.out_dir.join("world.toml");
    std::fs::write(&world_path, toml::to_string(&c.world)?).map_err(|source| StackError::Io {
        path: world_path.clone(),
        source,
    })?;
    let pegs: Vec<&str> = c.pegs.iter().map(|p| p.name()).collect();
    let mut run_args = vec![
        "--episodes".to_string(),
        u32::MAX.to_string(),
        "--seed".into(),
        c.seed.to_string(),
        "--world".into(),
        world_path.display().to_string(),
        "--pegs".into(),
        pegs.join(","),
        "--mix-heuristic-fraction".into(),
        c.mix.heuristic_fraction.to_string(),
        "--episode-actions".into(),
        c.episode_actions.to_string(),
        "--states".into(),
        c.states.to_string(),
        "--view-rate-hz".into(),
        c.log.view_rate_hz.to_string(),
    ];
    if !c.log.foxglove {
        run_args.push("--no-foxglove".into());
    }
    if c.mix.end_after_completion.is_none() {
        run_args.push("--full-episodes".into());
    }
    let exit = run(&StackConfig {
        hardware: Hardware::Sim,
        node: std::env::current_exe().map_err(StackError::CurrentExe)?,
        namespace: shared_mem_schema::DEFAULT_NAMESPACE.into(),
        lockstep: false,
        run_args,
        log_dir: c.out_dir.clone(),
        controller_config: c.controller_config.clone(),
    })?;
    if !exit.policy.success() {
        return Err(StackError::PolicyNodeFailed(exit.policy));
    }
    Ok(())
}
