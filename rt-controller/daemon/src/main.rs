//! `rt-controller`: the 1 kHz control daemon (see docs/rt-controller.md and
//! docs/operation.md).

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use rt_controller::SpeedLimitSource;
use rt_controller_daemon::config::{
    BackendKind, Clock, DaemonConfig, FrankaGeneration, WrenchSource,
};
use rt_controller_daemon::fault_record::{self, FaultRecord, RecordState, RecordUpdate};
use rt_controller_daemon::rt::{self, Notifier};
use rt_controller_daemon::rt_alloc::{self, RtAllocator};
use rt_controller_daemon::{
    Daemon, FAULT_DAEMON_ERROR, FAULT_HARDWARE_SILENT, FrankaBackend, Hardware, HardwareError,
    NetFt, RunSummary, Shared, SimBackend, exit, franka,
};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::process::{
    install_termination_handler, termination_requested, termination_signal,
};
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerCommand, ControllerMode};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tracing::{error, info, warn};

mod operator;

use operator::{Failure, with};

// The control loop's few dependency allocations come from static pools.
#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum ClockArg {
    Wall,
    Hardware,
}

/// The real-time control daemon: hardware state in, torques out, at 1 kHz.
#[derive(Debug, Parser)]
#[command(name = "rt-controller", version)]
struct Args {
    /// Configuration (TOML); built-in defaults when absent.
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// Overrides `backend.namespace`.
    #[arg(long)]
    namespace: Option<String>,
    /// Overrides `timing.clock`.
    #[arg(long, value_enum)]
    clock: Option<ClockArg>,
    /// Sets `timing.lockstep_actions = true` (deterministic runs with a
    /// lockstep simulator and learner).
    #[arg(long)]
    lockstep_actions: bool,
    /// Sets `realtime.enabled = false`.
    #[arg(long)]
    no_realtime: bool,
    /// Overrides `fault_record` (docs/operation.md, "Faults across
    /// restarts").
    #[arg(long)]
    fault_record: Option<PathBuf>,
    /// Prints the effective configuration and exits.
    #[arg(long)]
    print_config: bool,
    /// Instead of running the loop: a command to the running daemon.
    #[command(subcommand)]
    command: Option<Cmd>,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Clears a latched fault of the daemon running in the namespace (the
    /// configuration's, or `--namespace`): sends a reset and prints the
    /// daemon's answer. Exits non-zero when the daemon refuses (hardware
    /// still silent) or does not answer. With a fault record and no daemon
    /// running on it, clears the record instead (counted in its history).
    Reset {
        /// How long to wait for the daemon's answer, s.
        #[arg(long, default_value_t = 5.0)]
        timeout_s: f64,
    },
    /// Prints the running daemon's newest status (published every
    /// `timing.status_period_ms` on shared memory) and the fault record's
    /// state; exits 1 when no daemon answers within the time-out.
    Status {
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
        /// How long to wait for a status, s.
        #[arg(long, default_value_t = 2.0)]
        timeout_s: f64,
    },
    /// Runs the Franka's automatic error recovery once (clears a reflex
    /// the robot latched) and exits; never part of a start. A fault on
    /// record still needs `reset`.
    Recover,
}

fn main() {
    init_logging();
    let code = match run(Args::parse()) {
        Ok(code) => code,
        Err(f) => {
            error!("rt-controller: {:#}", f.error);
            f.code
        }
    };
    std::process::exit(code);
}

/// `RUST_LOG` filters (default `info`); colour only on a terminal, so
/// that journald stores plain text.
fn init_logging() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_target(false)
        .with_env_filter(filter)
        .with_ansi(std::io::stdout().is_terminal())
        .init();
}

fn load_config(args: &Args) -> Result<DaemonConfig> {
    let mut cfg = match &args.config {
        Some(p) => DaemonConfig::from_file(p)?,
        None => DaemonConfig::default(),
    };
    if let Some(ns) = &args.namespace {
        cfg.backend.namespace = ns.clone();
    }
    if let Some(c) = args.clock {
        cfg.timing.clock = match c {
            ClockArg::Wall => Clock::Wall,
            ClockArg::Hardware => Clock::Hardware,
        };
    }
    if args.lockstep_actions {
        cfg.timing.lockstep_actions = true;
    }
    if args.no_realtime {
        cfg.realtime.enabled = false;
    }
    if let Some(p) = &args.fault_record {
        cfg.fault_record = Some(p.clone());
    }
    cfg.validate()?;
    cfg.validate_for_start()?;
    Ok(cfg)
}

fn run(args: Args) -> Result<i32, Failure> {
    let cfg = load_config(&args).map_err(with(exit::CONFIG))?;
    if args.print_config {
        print!("{}", cfg.to_toml());
        return Ok(exit::CLEAN);
    }
    match args.command {
        Some(Cmd::Reset { timeout_s }) => return operator::reset_command(&cfg, timeout_s),
        Some(Cmd::Recover) => return operator::recover_command(&cfg),
        Some(Cmd::Status { json, timeout_s }) => {
            return operator::status_command(&cfg, json, timeout_s);
        }
        None => {}
    }
    cfg.validate_for_motion()
        .map_err(|e| with(exit::CONFIG)(e.into()))?;
    install_termination_handler();
    transport::quiet_logs();
    // Before anything touches the arm: one daemon per record, and none
    // past a fault on record.
    let record = match &cfg.fault_record {
        Some(p) => Some(Arc::new(
            FaultRecord::lock_within(p, Duration::from_secs(5))
                .map_err(|e| with(exit::CONFIG)(e.into()))?,
        )),
        None => None,
    };
    if let Some(r) = &record {
        let entry = r.read().map_err(|e| with(exit::FAULT)(e.into()))?;
        if let Some(why) = fault_record::refusal(&entry) {
            return Err(Failure {
                code: exit::FAULT,
                error: anyhow::anyhow!(
                    "start refused by the fault record {}: {why}. Look at the robot and the \
                     journal, then `rt-controller reset` clears the record (counted in {})",
                    r.path().display(),
                    r.history_path().display()
                ),
            });
        }
    }
    println!("# rt-controller effective configuration\n{}", cfg.to_toml());
    let model = robot_model::descriptions::load(&cfg.robot)
        .with_context(|| format!("loading the robot `robot` = {:?}", cfg.robot))
        .map_err(with(exit::CONFIG))?;
    // The control law against the robot: a bad value is the configuration's.
    cfg.controller
        .validate(&model)
        .map_err(|e| with(exit::CONFIG)(anyhow::anyhow!("{e}")))?;
    if let Some(r) = &record {
        r.mark_running().map_err(|e| with(exit::ERROR)(e.into()))?;
    }
    let ending = start_and_drive(&cfg, model, record.clone());
    conclude(ending, record.as_deref())
}

/// How a daemon's run ended.
struct Ending {
    /// The loop ran (the daemon held the arm).
    ready: bool,
    /// The fault latched at the end (0: none).
    latched: u32,
    /// The error that ended it, with the fault code it is recorded as
    /// (0: none).
    error: Option<(anyhow::Error, u32)>,
}

impl Ending {
    /// An error before the arm was held: nothing latched, nothing to record.
    fn before_ready(e: anyhow::Error) -> Self {
        Self {
            ready: false,
            latched: 0,
            error: Some((e, 0)),
        }
    }
}

/// The record and the exit status of an ending: a fault (latched, a robot
/// error, or an error while the arm was held) is recorded and exits
/// [`exit::FAULT`]; an error before the arm was held [`exit::ERROR`].
fn conclude(end: Ending, record: Option<&FaultRecord>) -> Result<i32, Failure> {
    let fault = match &end.error {
        _ if end.latched != 0 => end.latched,
        Some((_, code)) if *code != 0 => *code,
        Some(_) if end.ready => FAULT_DAEMON_ERROR,
        _ => 0,
    };
    if let Some(r) = record {
        let written = if fault != 0 {
            // The monitor may have recorded it already.
            match r.read() {
                Ok(Some(e)) if e.state == RecordState::Fault => Ok(()),
                _ => r.record_fault(fault),
            }
        } else {
            r.clear_clean()
        };
        if let Err(e) = written {
            error!("rt-controller: {e}");
        }
    }
    match (end.error, fault) {
        (Some((e, _)), 0) if matches!(e.downcast_ref(), Some(HardwareError::Mismatch(_))) => {
            Err(with(exit::CONFIG)(e))
        }
        (Some((e, _)), 0) => Err(with(exit::ERROR)(e)),
        (Some((e, _)), _) => Err(with(exit::FAULT)(e)),
        (None, 0) => Ok(exit::CLEAN),
        (None, code) => Err(Failure {
            code: exit::FAULT,
            error: anyhow::anyhow!(
                "stopped with fault {code} ({}) latched{}",
                fault_record::fault_name(code),
                if record.is_some() {
                    "; it stays on record until `rt-controller reset`"
                } else {
                    ""
                }
            ),
        }),
    }
}

/// Opens the backend and runs the daemon on it.
fn start_and_drive(
    cfg: &DaemonConfig,
    model: robot_model::Model,
    record: Option<Arc<FaultRecord>>,
) -> Ending {
    let node = match transport::create_rt_node("rt-controller") {
        Ok(n) => n,
        Err(e) => return Ending::before_ready(e.into()),
    };
    match cfg.backend.kind {
        BackendKind::Sim => match SimBackend::open(&node, &cfg.backend.namespace) {
            Ok(hw) => drive(cfg, model, hw, &node, record, |_| {}),
            Err(e) => Ending::before_ready(e.into()),
        },
        BackendKind::Franka => {
            let f = &cfg.backend.franka;
            info!(
                "rt-controller: connecting to the Franka at {} ({:?})",
                f.address, f.generation
            );
            // Before the arm is held nothing is recorded: a robot not yet
            // reachable, or one that refuses the motion (its reflex is its
            // own to report), exits 1 and the unit tries again.
            let robot = match franka::connect(f, cfg.timing.startup_timeout_s) {
                Ok(r) => r,
                Err(e) => return Ending::before_ready(e.into()),
            };
            info!(
                "rt-controller: connected, robot server version {}",
                robot.server_version()
            );
            // The sensor is found and streaming before the motion starts.
            let wrench_sensor = match f.wrench {
                WrenchSource::NetFt => match NetFt::connect(&f.net_ft, mono_now_ns()) {
                    Ok(s) => Some(s),
                    Err(e) => return Ending::before_ready(e.into()),
                },
                WrenchSource::RobotEstimate | WrenchSource::None => None,
            };
            // An FR3 limits joint speeds by position, with the values it
            // serves: the controller keeps to those.
            let mut cfg = cfg.clone();
            let documented = cfg.controller.joint_speed_limits == SpeedLimitSource::Fr3;
            if f.generation == FrankaGeneration::Fr3 && documented {
                match franka::served_speed_limits(&robot) {
                    Ok(ramps) => {
                        let same = ramps.as_slice() == rt_controller::speed_limits::FR3_RAMPS;
                        info!(
                            "rt-controller: joint speed limits from the robot's model{}: {ramps:?}",
                            if same {
                                " (Franka's documented ones)"
                            } else {
                                ""
                            }
                        );
                        cfg.controller.joint_speed_limits = SpeedLimitSource::Ramps(ramps);
                    }
                    Err(e) => return Ending::before_ready(e.into()),
                }
            }
            match FrankaBackend::new(&robot, f.clone(), &model, wrench_sensor) {
                Ok(hw) => drive(&cfg, model, hw, &node, record, |hw| {
                    info!(
                        "rt-controller: the robot's lowest control command success rate: {:.3}",
                        hw.min_success_rate
                    );
                }),
                Err(e) => Ending::before_ready(e.into()),
            }
        }
    }
}

/// The fault code a hardware error is recorded as (0: it left no fault).
fn robot_code(e: &HardwareError) -> u32 {
    match e {
        HardwareError::Robot { code, .. } => *code,
        _ => 0,
    }
}

/// Builds the daemon on `hw` and runs it until a termination signal;
/// `report_backend` logs the backend's own figures at the end.
fn drive<H: Hardware>(
    cfg: &DaemonConfig,
    model: robot_model::Model,
    hw: H,
    node: &transport::StackNode,
    record: Option<Arc<FaultRecord>>,
    report_backend: impl FnOnce(&H),
) -> Ending {
    let mut daemon = match Daemon::new(cfg.clone(), model, hw, node) {
        Ok(d) => d,
        Err(e) => {
            return Ending::before_ready(anyhow::anyhow!("{e}").context("building the controller"));
        }
    };

    // The monitor runs at normal priority: it logs what the loop reports
    // through atomics, feeds systemd's watchdog while the loop advances and
    // keeps the fault record.
    let notifier = Arc::new(Notifier::from_env());
    let monitor_stop = Arc::new(AtomicBool::new(false));
    let writer = match record.map(FaultRecord::spawn_writer).transpose() {
        Ok(w) => w,
        Err(e) => {
            return Ending::before_ready(e.into());
        }
    };
    let (updates, writer) = writer.unzip();
    let monitor = {
        let (shared, stop, notifier) = (
            daemon.shared.clone(),
            monitor_stop.clone(),
            notifier.clone(),
        );
        std::thread::Builder::new()
            .name("rt-monitor".into())
            .spawn(move || monitor_loop(&shared, &stop, &notifier, updates))
    };
    let monitor = match monitor {
        Ok(m) => m,
        Err(e) => {
            return Ending::before_ready(e.into());
        }
    };

    let report = rt::setup(&cfg.realtime);
    for w in &report.warnings {
        warn!("rt-controller: {w}");
    }
    info!(
        "rt-controller: real-time set-up: memory locked {}, SCHED_FIFO {}, pinned {}",
        report.memory_locked, report.fifo, report.pinned
    );
    daemon.set_realtime(report.realtime());
    info!(
        "rt-controller: {} joints, backend {}, namespace '{}', clock {:?}, period {} s; waiting \
         for the hardware",
        daemon.model().nv(),
        match cfg.backend.kind {
            BackendKind::Sim => "sim",
            BackendKind::Franka => "franka",
        },
        cfg.backend.namespace,
        cfg.timing.clock,
        cfg.controller.period_s
    );
    let ready_notifier = notifier.clone();
    let ready = Arc::new(AtomicBool::new(false));
    let ready_flag = ready.clone();
    let result = daemon.run(termination_requested, move || {
        ready_flag.store(true, Ordering::Relaxed);
        ready_notifier.notify("READY=1\nSTATUS=running");
        info!("rt-controller: hardware connected, control loop running");
    });
    notifier.notify("STOPPING=1");
    monitor_stop.store(true, Ordering::Relaxed);
    let _ = monitor.join();
    // The monitor's end drops the sender: the writer finishes its queue.
    if let Some(w) = writer {
        let _ = w.join();
    }
    report_backend(daemon.hardware());
    let a = rt_alloc::stats();
    log_allocations(&a);
    let latched = if faulted(daemon.shared.mode.load(Ordering::Relaxed)) {
        daemon.shared.fault_code.load(Ordering::Relaxed)
    } else {
        0
    };
    let ready = ready.load(Ordering::Relaxed);
    let summary = match result {
        Ok(s) => s,
        Err(e) => {
            let code = robot_code(&e);
            return Ending {
                ready,
                latched,
                error: Some((e.into(), code)),
            };
        }
    };
    log_summary(&daemon, &summary);
    Ending {
        ready,
        latched,
        error: None,
    }
}

fn log_summary<H: Hardware>(daemon: &Daemon<H>, summary: &RunSummary) {
    let s = &daemon.stats;
    // Two lines: each stays short enough for a journal line (the tests
    // bound log lines at 300 characters).
    info!(
        "rt-controller: stopped{} after {} cycles: {} overruns, {} hardware misses, {} hardware \
         states skipped, {} stale, wake-up p99 {} µs max {:.0} µs, compute p99 {} µs max {:.0} µs",
        match termination_signal() {
            0 => String::new(),
            s => format!(" (signal {s})"),
        },
        summary.cycles,
        summary.overruns,
        s.hardware_misses,
        s.hardware_states_skipped,
        s.hardware_states_stale,
        s.wakeup.quantile_us(0.99),
        s.wakeup.max_ns as f64 / 1e3,
        s.compute.quantile_us(0.99),
        s.compute.max_ns as f64 / 1e3,
    );
    // Two lines: journald and the tests keep a line under 300 characters.
    info!(
        "rt-controller: actions: {} garbage ({} misaddressed), {} dropped from the full queue, \
         {} with their step cut by the speed bound",
        daemon.shared.garbage_actions.load(Ordering::Relaxed),
        s.actions_misaddressed,
        s.actions_overflow,
        s.actions_speed_cut,
    );
    info!(
        "rt-controller: actions: {} stale ({} too old, \
         {} from the future, {} of another episode, {} replayed, {} jumped); {} resets, {} refused commands, \
         {} failed publications, {} failed action receives",
        s.actions_stale(),
        s.actions_too_old,
        s.actions_from_future,
        s.actions_other_episode,
        s.actions_replayed,
        s.actions_seq_jump,
        daemon.control.resets(),
        s.commands_refused,
        s.publish_errors,
        s.receive_errors
    );
}

fn log_allocations(a: &rt_alloc::RtAllocStats) {
    info!(
        "rt-controller: control-loop allocations: {} from the real-time pools, {} from the heap; \
         {} frees to the heap",
        a.pool_allocs, a.system_allocs_on_rt_thread, a.system_frees_on_rt_thread
    );
}

/// Fault or HardwareLost.
fn faulted(mode: u32) -> bool {
    mode == ControllerMode::Fault as u32 || mode == ControllerMode::HardwareLost as u32
}

fn monitor_loop(
    shared: &Shared,
    stop: &AtomicBool,
    notifier: &Notifier,
    record: Option<std::sync::mpsc::Sender<RecordUpdate>>,
) {
    let mut seen_faults = 0;
    let mut seen_resets = 0;
    let mut last_beat = 0;
    let mut last_mode = u32::MAX;
    let mut last_command = 0;
    let mut last_stale = 0;
    let mut last_garbage = 0;
    let mut last_overflow = 0;
    let mut last_overruns = 0;
    let mut last_io_errors = 0;
    let mut last_degraded = 0;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        let beat = shared.heartbeat.load(Ordering::Relaxed);
        if beat != last_beat && notifier.watchdog_usec.is_some() {
            notifier.notify("WATCHDOG=1");
        }
        last_beat = beat;
        let mode = shared.mode.load(Ordering::Relaxed);
        if mode != last_mode && beat > 0 {
            let name = ControllerMode::from_u32(mode).map_or("?", |m| m.name());
            let code = shared.fault_code.load(Ordering::Relaxed);
            match code {
                0 => info!("rt-controller: mode {name}"),
                FAULT_HARDWARE_SILENT => error!(
                    "rt-controller: hardware silent: fault, no torques are sent; latched until \
                     `rt-controller reset` once the hardware streams again"
                ),
                code @ 101..=104 => error!(
                    "rt-controller: mode {name} (fault code {code}): the robot stopped the \
                     control session; the daemon stops"
                ),
                code => error!(
                    "rt-controller: mode {name} (fault code {code}); latched until \
                     `rt-controller reset`"
                ),
            }
            // systemd shows it in `systemctl status`.
            notifier.notify(&format!("STATUS={name} (fault code {code})"));
            last_mode = mode;
        }
        // The loop's counters, not the mode: a fault latched and reset
        // between two looks is recorded too.
        let faults = shared.faults_latched.load(Ordering::Acquire);
        let resets = shared.resets.load(Ordering::Acquire);
        if let Some(tx) = &record
            && (faults != seen_faults || resets != seen_resets)
        {
            let fault_now = if faulted(mode) {
                shared.fault_code.load(Ordering::Relaxed)
            } else {
                0
            };
            let _ = tx.send(RecordUpdate {
                new_faults: faults - seen_faults,
                latched_code: shared.latched_code.load(Ordering::Acquire),
                new_resets: resets - seen_resets,
                fault_now,
            });
            seen_faults = faults;
            seen_resets = resets;
        }
        let command = shared.command_seq.load(Ordering::Relaxed);
        if command != last_command {
            let result = shared.command_result.load(Ordering::Relaxed);
            let text = ControllerCommand::result_name(result);
            let resets = shared.resets.load(Ordering::Relaxed);
            let refused = shared.commands_refused.load(Ordering::Relaxed);
            if result == ControllerCommand::RESULT_CLEARED {
                warn!("rt-controller: reset command {command:#x}: fault {text} ({resets} resets)");
            } else {
                warn!("rt-controller: reset command {command:#x}: {text} ({refused} refused)");
            }
            last_command = command;
        }
        warn_on_increase(
            &shared.stale_actions,
            &mut last_stale,
            "stale actions dropped (too old, another episode or replayed)",
        );
        warn_on_increase(
            &shared.garbage_actions,
            &mut last_garbage,
            "garbage actions ignored",
        );
        warn_on_increase(
            &shared.overflow_actions,
            &mut last_overflow,
            "actions dropped from the full action queue",
        );
        warn_on_increase(&shared.overruns, &mut last_overruns, "overruns");
        warn_on_increase(
            &shared.learner_io_errors,
            &mut last_io_errors,
            "failed publications to or receives from the learner",
        );
        let degraded = transport::degraded_connections();
        if degraded > last_degraded {
            warn!(
                "rt-controller: {} shared-memory connections to a peer could not be set up \
                 within {:?} or were corrupted; that peer gets nothing ({degraded} in all)",
                degraded - last_degraded,
                transport::RT_CREATION_TIMEOUT
            );
            last_degraded = degraded;
        }
    }
}

/// Logs how much a counter grew since the last look.
fn warn_on_increase(counter: &std::sync::atomic::AtomicU64, last: &mut u64, what: &str) {
    let now = counter.load(Ordering::Relaxed);
    if now > *last {
        warn!("rt-controller: {} {what} ({now} in all)", now - *last);
        *last = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rt_controller_daemon::shared::FAULT_ROBOT_REFLEX;

    fn end(ready: bool, latched: u32, error: Option<(anyhow::Error, u32)>) -> Ending {
        Ending {
            ready,
            latched,
            error,
        }
    }

    fn code(r: Result<i32, Failure>) -> i32 {
        r.unwrap_or_else(|f| f.code)
    }

    #[test]
    fn each_ending_maps_to_its_exit_status() {
        let mismatch = || anyhow::Error::new(HardwareError::Mismatch("load".into()));
        // A robot that is not the configured one: a bad configuration (2),
        // which the unit never restarts after.
        assert_eq!(
            code(conclude(end(false, 0, Some((mismatch(), 0))), None)),
            exit::CONFIG
        );
        // Any other error before the arm was held: a crash (1), restarted.
        let other = anyhow::anyhow!("no such device");
        assert_eq!(
            code(conclude(end(false, 0, Some((other, 0))), None)),
            exit::ERROR
        );
        // A robot error recorded as a fault, a latched fault, an error
        // after the arm was held: a fault (3), never restarted.
        let reflex = anyhow::anyhow!("reflex");
        let e = end(true, 0, Some((reflex, FAULT_ROBOT_REFLEX)));
        assert_eq!(code(conclude(e, None)), exit::FAULT);
        assert_eq!(code(conclude(end(true, 102, None), None)), exit::FAULT);
        let late = anyhow::anyhow!("lost the socket");
        assert_eq!(
            code(conclude(end(true, 0, Some((late, 0))), None)),
            exit::FAULT
        );
        // A mismatch found while a fault is latched is still the fault.
        let e = end(true, 105, Some((mismatch(), 0)));
        assert_eq!(code(conclude(e, None)), exit::FAULT);
        assert_eq!(code(conclude(end(true, 0, None), None)), exit::CLEAN);
    }

    #[test]
    fn a_fault_is_recorded_and_a_clean_stop_clears_the_record() {
        let dir = test_support::scratch_dir("conclude");
        let r = FaultRecord::lock(&dir.path().join("fault.json")).unwrap();
        r.mark_running().unwrap();
        assert_eq!(code(conclude(end(true, 102, None), Some(&r))), exit::FAULT);
        let entry = r.read().unwrap().expect("recorded");
        assert_eq!((entry.state, entry.code), (RecordState::Fault, 102));
        // A clean stop removes the running record.
        let r2_dir = test_support::scratch_dir("conclude-clean");
        let r2 = FaultRecord::lock(&r2_dir.path().join("fault.json")).unwrap();
        r2.mark_running().unwrap();
        assert_eq!(code(conclude(end(true, 0, None), Some(&r2))), exit::CLEAN);
        assert_eq!(r2.read().unwrap(), None);
    }
}
