//! `rt-controller`: the 1 kHz control daemon (see docs/rt-controller.md and
//! docs/operation.md).

use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use rt_controller::daemon::config::{BackendKind, Clock, DaemonConfig};
use rt_controller::daemon::rt::{self, Notifier};
use rt_controller::daemon::rt_alloc::{self, RtAllocator};
use rt_controller::daemon::{Daemon, FAULT_HARDWARE_SILENT, Shared, SimBackend};
use shared_mem_schema::ControllerMode;
use shared_mem_schema::process::{
    install_termination_handler, termination_requested, termination_signal,
};
use shared_mem_schema::transport;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tracing::{error, info, warn};

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
    /// Prints the effective configuration and exits.
    #[arg(long)]
    print_config: bool,
}

fn main() {
    tracing_subscriber::fmt().with_target(false).init();
    match run(Args::parse()) {
        Ok(()) => {}
        Err(e) => {
            error!("rt-controller: {e:#}");
            std::process::exit(1);
        }
    }
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
    cfg.validate()?;
    Ok(cfg)
}

fn run(args: Args) -> Result<()> {
    let cfg = load_config(&args)?;
    if args.print_config {
        print!("{}", cfg.to_toml());
        return Ok(());
    }
    install_termination_handler();
    transport::quiet_logs();
    println!("# rt-controller effective configuration\n{}", cfg.to_toml());
    let model = robot_model::descriptions::load(&cfg.robot)
        .with_context(|| format!("loading the robot `robot` = {:?}", cfg.robot))?;
    let node = transport::create_node("rt-controller")?;
    let hw = match cfg.backend.kind {
        BackendKind::Sim => SimBackend::open(&node, &cfg.backend.namespace)?,
        BackendKind::Franka => bail!(
            "`backend.kind` = \"franka\": the Franka backend is not part of this build yet \
             (it arrives with the Franka adapter issue); use \"sim\""
        ),
    };
    let mut daemon = Daemon::new(cfg.clone(), model, hw, &node)
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("building the controller")?;

    // The monitor runs at normal priority: it logs what the loop reports
    // through atomics and feeds systemd's watchdog while the loop advances.
    let notifier = Arc::new(Notifier::from_env());
    let monitor_stop = Arc::new(AtomicBool::new(false));
    let monitor = {
        let (shared, stop, notifier) = (
            daemon.shared.clone(),
            monitor_stop.clone(),
            notifier.clone(),
        );
        std::thread::Builder::new()
            .name("rt-monitor".into())
            .spawn(move || monitor_loop(&shared, &stop, &notifier))?
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
    let result = daemon.run(termination_requested, move || {
        ready_notifier.notify("READY=1\nSTATUS=running");
        info!("rt-controller: hardware connected, control loop running");
    });
    notifier.notify("STOPPING=1");
    monitor_stop.store(true, Ordering::Relaxed);
    let _ = monitor.join();
    let summary = result?;
    let a = rt_alloc::stats();
    info!(
        "rt-controller: control-loop allocations: {} from the real-time pools, {} from the heap; \
         {} frees to the heap",
        a.pool_allocs, a.system_allocs_on_rt_thread, a.system_frees_on_rt_thread
    );
    let s = &daemon.stats;
    info!(
        "rt-controller: stopped{} after {} cycles: {} overruns, {} hardware misses, {} hardware \
         states skipped, wake-up p99 {} µs max {:.0} µs, compute p99 {} µs max {:.0} µs, {} \
         garbage actions, {} actions dropped from the full queue, {} failed publications, {} \
         failed action receives",
        match termination_signal() {
            0 => String::new(),
            s => format!(" (signal {s})"),
        },
        summary.cycles,
        summary.overruns,
        s.hardware_misses,
        s.hardware_states_skipped,
        s.wakeup.quantile_us(0.99),
        s.wakeup.max_ns as f64 / 1e3,
        s.compute.quantile_us(0.99),
        s.compute.max_ns as f64 / 1e3,
        daemon.shared.garbage_actions.load(Ordering::Relaxed),
        s.actions_overflow,
        s.publish_errors,
        s.receive_errors
    );
    Ok(())
}

fn monitor_loop(shared: &Shared, stop: &AtomicBool, notifier: &Notifier) {
    let mut last_beat = 0;
    let mut last_mode = u32::MAX;
    let mut last_garbage = 0;
    let mut last_overflow = 0;
    let mut last_overruns = 0;
    let mut last_io_errors = 0;
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
            match shared.fault_code.load(Ordering::Relaxed) {
                0 => info!("rt-controller: mode {name}"),
                FAULT_HARDWARE_SILENT => {
                    error!("rt-controller: hardware silent: fault, no torques are sent")
                }
                code => error!("rt-controller: mode {name} (fault code {code})"),
            }
            last_mode = mode;
        }
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
