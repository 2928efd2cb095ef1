//! The operator's commands of the `rt-controller` binary (`reset`,
//! `status`, `recover`) and the exit-status wrapper its `main` shares
//! (docs/operation.md, "Faults across restarts").

use anyhow::{Result, bail};
use rt_controller_daemon::config::{BackendKind, DaemonConfig};
use rt_controller_daemon::exit;
use rt_controller_daemon::fault_record::{self, FaultRecord, RecordError};
use rt_controller_daemon::franka;
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerCommand, ControllerMode, ControllerStatus};
use std::time::Duration;
use tracing::warn;

/// An error and the exit status it ends the process with
/// ([`rt_controller_daemon::exit`]).
pub struct Failure {
    /// The exit status.
    pub code: i32,
    /// The error.
    pub error: anyhow::Error,
}

/// Wraps an error in the exit status `code`.
pub fn with(code: i32) -> impl FnOnce(anyhow::Error) -> Failure {
    move |error| Failure { code, error }
}

/// `rt-controller reset`. With a fault record and no daemon running on
/// it: clears the record (a fault, or an unclean end), counted in its
/// history. Otherwise: a reset command to the running daemon.
pub fn reset_command(cfg: &DaemonConfig, timeout_s: f64) -> Result<i32, Failure> {
    if let Some(path) = &cfg.fault_record {
        match FaultRecord::lock(path) {
            Ok(r) => {
                let cleared = match r.read() {
                    Ok(entry) => fault_record::refusal(&entry),
                    Err(e @ RecordError::Malformed { .. }) => Some(e.to_string()),
                    Err(e) => return Err(with(exit::CONFIG)(e.into())),
                };
                let Some(why) = cleared else {
                    println!(
                        "rt-controller reset: no fault on record in {}, and no daemon runs on it",
                        path.display()
                    );
                    return Ok(exit::CLEAN);
                };
                let n = r
                    .operator_reset(&why)
                    .map_err(|e| with(exit::ERROR)(e.into()))?;
                warn!("rt-controller reset: cleared the fault record: {why}");
                println!(
                    "rt-controller reset: cleared the fault record {}: {why}; {n} resets on \
                     record ({})",
                    path.display(),
                    r.history_path().display()
                );
                return Ok(exit::CLEAN);
            }
            // A daemon runs on it: it clears its own latch.
            Err(RecordError::Held(_)) => {}
            Err(e) => return Err(with(exit::CONFIG)(e.into())),
        }
    }
    send_reset(&cfg.backend.namespace, timeout_s)
        .map(|()| exit::CLEAN)
        .map_err(with(exit::ERROR))
}

/// `rt-controller status`: the newest status on shared memory and what the
/// fault record says (read without its lock: a daemon may hold it).
pub fn status_command(cfg: &DaemonConfig, json: bool, timeout_s: f64) -> Result<i32, Failure> {
    let record = match &cfg.fault_record {
        Some(p) => match std::fs::read_to_string(p) {
            Ok(t) => match toml::from_str::<fault_record::RecordEntry>(&t) {
                Ok(e) => {
                    let state = match e.state {
                        fault_record::RecordState::Running => "running",
                        fault_record::RecordState::Fault => "fault",
                    };
                    format!("{state} (code {}: {})", e.code, e.reason)
                }
                Err(e) => format!("unreadable ({})", e.message()),
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => "none".into(),
            Err(e) => format!("cannot be read ({e})"),
        },
        None => "not configured".into(),
    };
    transport::quiet_logs();
    let ns = &cfg.backend.namespace;
    let found = (|| -> Result<Option<ControllerStatus>> {
        let node = transport::create_node("rt-controller-status")?;
        let sub = transport::subscriber::<ControllerStatus>(&node, ns)?;
        let start = std::time::Instant::now();
        while start.elapsed().as_secs_f64() < timeout_s {
            let mut last = None;
            transport::drain(&sub, |s| last = Some(*s))?;
            if last.is_some() {
                return Ok(last);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(None)
    })()
    .map_err(with(exit::ERROR))?;
    let Some(s) = found else {
        return Err(Failure {
            code: exit::ERROR,
            error: anyhow::anyhow!(
                "no status from an rt-controller in namespace '{ns}' within {timeout_s} s \
                 (fault record: {record})"
            ),
        });
    };
    let mode = ControllerMode::from_u32(s.mode).map_or("?", |m| m.name());
    let fault = fault_record::fault_name(s.fault_code);
    let p99 = s.compute.quantile_us(0.99);
    if json {
        let v = serde_json::json!({
            "namespace": ns,
            "mode": mode,
            "fault_code": s.fault_code,
            "fault": fault,
            "cycles": s.cycles,
            "overruns": s.overruns,
            "faults": s.faults,
            "resets": s.resets,
            "hardware_misses": s.hardware_misses,
            "actions_accepted": s.actions_accepted,
            "actions_rejected": s.actions_rejected,
            "realtime": s.realtime != 0,
            "compute_p99_us": p99,
            "fault_record": record,
        });
        println!("{v}");
    } else {
        println!(
            "rt-controller in '{ns}': mode {mode}, fault code {} ({fault}); {} cycles, {} \
             overruns, {} faults, {} resets, {} hardware misses; actions {} accepted, {} \
             rejected; compute p99 {p99} µs; fault record: {record}",
            s.fault_code,
            s.cycles,
            s.overruns,
            s.faults,
            s.resets,
            s.hardware_misses,
            s.actions_accepted,
            s.actions_rejected,
        );
    }
    Ok(exit::CLEAN)
}

/// `rt-controller recover`: the Franka's automatic error recovery, once,
/// with no daemon running on the record.
pub fn recover_command(cfg: &DaemonConfig) -> Result<i32, Failure> {
    if cfg.backend.kind != BackendKind::Franka {
        return Err(Failure {
            code: exit::CONFIG,
            error: anyhow::anyhow!(
                "`recover` runs the Franka's error recovery: needs backend.kind = \"franka\""
            ),
        });
    }
    let _record = match &cfg.fault_record {
        Some(p) => Some(FaultRecord::lock(p).map_err(|e| with(exit::CONFIG)(e.into()))?),
        None => None,
    };
    franka::recover(&cfg.backend.franka, cfg.timing.startup_timeout_s)
        .map_err(|e| with(exit::ERROR)(e.into()))?;
    println!(
        "rt-controller recover: the robot's error recovery ran; a fault on record still needs \
         `rt-controller reset`"
    );
    Ok(exit::CLEAN)
}

/// `rt-controller reset`: one reset command to the daemon of `namespace`,
/// and its answer from the status.
fn send_reset(namespace: &str, timeout_s: f64) -> Result<()> {
    transport::quiet_logs();
    let node = transport::create_node("rt-controller-reset")?;
    let commands = transport::publisher::<ControllerCommand>(&node, namespace)?;
    let status = transport::subscriber::<ControllerStatus>(&node, namespace)?;
    // Unique across senders: this process's id and the time.
    let seq = (u64::from(std::process::id()) << 32) | (mono_now_ns() & 0xffff_ffff);
    let start = std::time::Instant::now();
    let mut next_send = start;
    let mut before: Option<ControllerStatus> = None;
    while start.elapsed().as_secs_f64() < timeout_s {
        if std::time::Instant::now() >= next_send {
            // Resent until answered: a daemon starting may miss the first.
            let episode = before.map_or(0, |s| s.header.episode);
            transport::send(
                &commands,
                &ControllerCommand::reset(seq, mono_now_ns(), episode),
            )?;
            next_send += Duration::from_millis(500);
        }
        let mut answer = None;
        transport::drain(&status, |s| {
            if s.command_seq == seq {
                answer = Some(*s);
            } else if before.is_none() {
                before = Some(*s);
            }
        })?;
        if let Some(s) = answer {
            let mode = ControllerMode::from_u32(s.mode).map_or("?", |m| m.name());
            println!(
                "rt-controller reset: {}; mode {mode}, fault code {}, {} resets in all",
                ControllerCommand::result_name(s.command_result),
                s.fault_code,
                s.resets
            );
            return match s.command_result {
                ControllerCommand::RESULT_CLEARED | ControllerCommand::RESULT_NO_FAULT => Ok(()),
                r => bail!(
                    "the daemon refused the reset: {}",
                    ControllerCommand::result_name(r)
                ),
            };
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    bail!("no answer from an rt-controller in namespace '{namespace}' within {timeout_s} s")
}
