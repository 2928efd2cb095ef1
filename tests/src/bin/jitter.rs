//! Timing/jitter harness: runs rt-controller at 1 kHz against hw-sim (real
//! time) for a chosen duration while a bare timer thread at the same
//! priority measures the machine's own wake-up floor (what cyclictest
//! measures), and a 20 Hz publisher sends small actions to measure the
//! latency from an action's publication to the first torque reflecting it.
//!
//! ```sh
//! cargo run --release -p tests --bin jitter -- --duration-s 30
//! ```
//!
//! Prints a table, writes `jitter.json` and `jitter.png` (the wake-up latency
//! histograms of both, log counts, titled and labelled) into `--out`. With
//! `--flood`, hostile peers load the daemon's services while it measures.

use clap::Parser;
use learner::plot::{Chart, Series};
use shared_mem_schema::process::{
    install_termination_handler, mono_now_ns, sleep_until_ns, termination_requested,
};
use shared_mem_schema::rates::CONTROL_PERIOD_NS;
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerStatus, LatencyHistogram, PolicyAction, SensorFrame};
use std::path::PathBuf;
use std::time::Duration;

/// rt-controller timing against the machine's floor.
#[derive(Debug, Parser)]
struct Args {
    /// How long to measure, s.
    #[arg(long, default_value_t = 10.0)]
    duration_s: f64,
    /// SCHED_FIFO priority of the daemon and the bare timer.
    #[arg(long, default_value_t = 80)]
    priority: i32,
    /// Run the daemon without its real-time set-up (and the timer at
    /// normal priority).
    #[arg(long)]
    no_realtime: bool,
    /// Where the JSON and the picture go.
    #[arg(long, default_value = "target/jitter")]
    out: PathBuf,
    /// Hostile peers while measuring: three more action publishers (the
    /// service's limit of four) sending as fast as they can, and a peer
    /// that joins and leaves the sensor frames and status every 10 ms
    /// (each join makes the daemon's loop set up a connection).
    #[arg(long)]
    flood: bool,
}

/// What the hostile peers of `--flood` did.
#[derive(Debug, Default, Clone, Copy)]
struct Flood {
    actions: u64,
    joins: u64,
}

/// Makes `a` answer the newest sensor frame in `frames`, as a policy does
/// (the daemon drops actions answering none, or an old one).
fn answer_newest(frames: &transport::Sub<SensorFrame>, a: &mut PolicyAction) -> anyhow::Result<()> {
    transport::drain(frames, |f| {
        a.header.episode = f.header.episode;
        a.header.t_hw_ns = f.header.t_hw_ns;
    })?;
    Ok(())
}

/// One flooding publisher: actions answering the newest sensor frame, back
/// to back, until `end_ns`.
fn flood_actions(ns: String, i: usize, end_ns: u64) -> anyhow::Result<u64> {
    let node = transport::create_node(&format!("jitter-flood-{i}"))?;
    let actions = transport::publisher::<PolicyAction>(&node, &ns)?;
    let frames = transport::subscriber::<SensorFrame>(&node, &ns)?;
    let mut sent = 0u64;
    while mono_now_ns() < end_ns && !termination_requested() {
        let mut a = PolicyAction::new(sent + 1, mono_now_ns(), [0.0; 4]);
        answer_newest(&frames, &mut a)?;
        transport::send(&actions, &a)?;
        sent += 1;
    }
    Ok(sent)
}

/// A peer joining and leaving the daemon's published services every 10 ms.
fn churn(ns: String, end_ns: u64) -> anyhow::Result<u64> {
    let mut joins = 0u64;
    while mono_now_ns() < end_ns && !termination_requested() {
        let node = transport::create_node("jitter-churn")?;
        let frames = transport::subscriber::<SensorFrame>(&node, &ns)?;
        let status = transport::subscriber::<ControllerStatus>(&node, &ns)?;
        joins += 1;
        std::thread::sleep(Duration::from_millis(10));
        drop((frames, status, node));
    }
    Ok(joins)
}

fn set_fifo(priority: i32) -> bool {
    let p = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread.
    unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) == 0 }
}

/// The bare timer: absolute 1 ms sleeps, nothing else.
fn bare_timer(duration_s: f64, priority: Option<i32>) -> (LatencyHistogram, bool) {
    let fifo = priority.is_some_and(set_fifo);
    let mut h = LatencyHistogram::EMPTY;
    let end = mono_now_ns() + (duration_s * 1e9) as u64;
    let mut deadline = mono_now_ns() + CONTROL_PERIOD_NS;
    while deadline < end && !termination_requested() {
        sleep_until_ns(deadline);
        h.record(mono_now_ns().saturating_sub(deadline));
        deadline += CONTROL_PERIOD_NS;
    }
    (h, fifo)
}

fn row(name: &str, h: &LatencyHistogram) -> String {
    format!(
        "| {name} | {} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} |",
        h.count,
        h.quantile_us(0.5),
        h.quantile_us(0.99),
        h.quantile_us(0.999),
        h.max_ns as f64 / 1e3,
        h.mean_us()
    )
}

fn json(h: &LatencyHistogram) -> serde_json::Value {
    serde_json::json!({
        "count": h.count,
        "p50_us": h.quantile_us(0.5),
        "p99_us": h.quantile_us(0.99),
        "p999_us": h.quantile_us(0.999),
        "max_us": h.max_ns as f64 / 1e3,
        "mean_us": h.mean_us(),
        "overflow": h.overflow,
    })
}

/// The wake-up latency histograms of the daemon and the bare timer, up to
/// a little past the larger p99.99, as a chart (log counts); the legend
/// says how many cycles lie beyond the axis.
fn chart(daemon: &LatencyHistogram, bare: &LatencyHistogram, duration_s: f64) -> Chart {
    let span = (daemon.quantile_us(0.9999).max(bare.quantile_us(0.9999)) * 1.2)
        .clamp(20.0, shared_mem_schema::HISTOGRAM_BINS as f64) as usize;
    let series = |name: &str, h: &LatencyHistogram| {
        let counts: Vec<f64> = h.bins[..span].iter().map(|&c| f64::from(c)).collect();
        let beyond = h.count - counts.iter().sum::<f64>() as u64;
        let name = if beyond > 0 {
            format!("{name}; {beyond} beyond {span} µs")
        } else {
            name.to_string()
        };
        Series::histogram(&name, 0.0, 1.0, &counts)
    };
    Chart::new(
        &format!("Wake-up latency of the 1 kHz loop ({duration_s} s)"),
        "wake-up latency (µs)",
        "cycles",
    )
    .log_y()
    .with(series("rt-controller daemon", daemon))
    .with(series("bare timer thread (the machine's floor)", bare))
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    install_termination_handler();
    transport::quiet_logs();
    let ns = format!("jitter-{}", std::process::id());
    let dir = args.out.clone();
    std::fs::create_dir_all(&dir)?;
    tests::stack_bins();
    // The simulated robot below the daemon: at hw-sim's default (70) unless
    // the daemon runs lower.
    let sim_prio = (args.priority - 1).clamp(1, 70).to_string();
    let mut sim_args = vec!["--namespace", ns.as_str(), "--mode", "realtime"];
    if args.no_realtime {
        sim_args.push("--no-realtime");
    } else {
        sim_args.extend(["--realtime-priority", sim_prio.as_str()]);
    }
    let _sim = tests::start("hw-sim", &sim_args, &dir);
    let prio = args.priority.to_string();
    let mut ctl_args = vec!["--namespace", ns.as_str()];
    if args.no_realtime {
        ctl_args.push("--no-realtime");
    }
    let cfg_path = dir.join("jitter-rt.toml");
    std::fs::write(
        &cfg_path,
        format!("[realtime]\npriority = {prio}\n[timing]\nstatus_period_ms = 100.0\n"),
    )?;
    let cfg = cfg_path.to_string_lossy().into_owned();
    ctl_args.extend(["--config", cfg.as_str()]);
    let mut ctl = tests::start("rt-controller", &ctl_args, &dir);
    let node = transport::create_node("jitter-harness")?;
    let status = transport::subscriber::<ControllerStatus>(&node, &ns)?;
    let actions = transport::publisher::<PolicyAction>(&node, &ns)?;
    let frames = transport::subscriber::<SensorFrame>(&node, &ns)?;
    // Wait until the loop runs.
    let start = std::time::Instant::now();
    let mut first: Option<ControllerStatus> = None;
    while first.is_none() {
        anyhow::ensure!(
            start.elapsed() < Duration::from_secs(30),
            "the daemon never published a status (see {})",
            dir.join("rt-controller.log").display()
        );
        transport::drain(&status, |s| {
            if s.cycles > 100 {
                first = Some(*s)
            }
        })?;
        std::thread::sleep(Duration::from_millis(10));
    }
    let first = first.unwrap();
    println!(
        "measuring for {} s (daemon real-time set-up: {})",
        args.duration_s,
        if first.realtime == 1 { "yes" } else { "no" }
    );
    // The bare timer on its own thread; actions from this one.
    let (d, prio_opt) = (
        args.duration_s,
        (!args.no_realtime).then_some(args.priority),
    );
    let timer = std::thread::spawn(move || bare_timer(d, prio_opt));
    let end = mono_now_ns() + (args.duration_s * 1e9) as u64;
    let peers: Vec<std::thread::JoinHandle<anyhow::Result<Flood>>> = if args.flood {
        let mut v: Vec<_> = (0..3)
            .map(|i| {
                let ns = ns.clone();
                std::thread::spawn(move || {
                    flood_actions(ns, i, end).map(|actions| Flood { actions, joins: 0 })
                })
            })
            .collect();
        let ns = ns.clone();
        v.push(std::thread::spawn(move || {
            churn(ns, end).map(|joins| Flood { actions: 0, joins })
        }));
        v
    } else {
        Vec::new()
    };
    let mut seq = 0u64;
    let mut next = mono_now_ns();
    while mono_now_ns() < end && !termination_requested() {
        seq += 1;
        let dx = if (seq / 10).is_multiple_of(2) {
            0.0005
        } else {
            -0.0005
        };
        let mut a = PolicyAction::new(seq, mono_now_ns(), [dx, 0.0, 0.0, 0.0]);
        answer_newest(&frames, &mut a)?;
        transport::send(&actions, &a)?;
        // 20 Hz, each at another phase of the daemon's 1 ms cycle (both
        // clocks are absolute: a fixed phase would measure one point of
        // the latency's range).
        next += 50_000_000;
        sleep_until_ns(next + (seq * 7919 % 1000) * 1000);
    }
    let (bare, bare_fifo) = timer.join().expect("timer thread");
    let mut flood = Flood::default();
    for p in peers {
        let f = p.join().expect("flood thread")?;
        flood.actions += f.actions;
        flood.joins += f.joins;
    }
    std::thread::sleep(Duration::from_millis(250));
    let mut last: Option<Box<ControllerStatus>> = None;
    transport::drain(&status, |s| last = Some(Box::new(*s)))?;
    let last = last.ok_or_else(|| anyhow::anyhow!("no status at the end"))?;
    ctl.stop(Duration::from_secs(5));

    // Differences of the cumulative histograms: the measured window only.
    let window = |a: &LatencyHistogram, b: &LatencyHistogram| {
        let mut h = *b;
        h.count -= a.count;
        h.overflow -= a.overflow;
        h.sum_ns -= a.sum_ns;
        for (x, y) in h.bins.iter_mut().zip(a.bins.iter()) {
            *x -= *y;
        }
        h
    };
    let wake = window(&first.wakeup_latency, &last.wakeup_latency);
    let compute = window(&first.compute, &last.compute);
    let latency = window(&first.action_latency, &last.action_latency);
    let cycles = last.cycles - first.cycles;
    let overruns = last.overruns - first.overruns;
    let misses = last.hardware_misses - first.hardware_misses;
    let skipped = last.hardware_states_skipped - first.hardware_states_skipped;
    println!("\n| µs | samples | p50 | p99 | p99.9 | max | mean |\n|---|---|---|---|---|---|---|");
    println!("{}", row("daemon wake-up latency", &wake));
    println!(
        "{}",
        row(
            &format!(
                "bare timer wake-up latency ({})",
                if bare_fifo {
                    "SCHED_FIFO"
                } else {
                    "normal priority"
                }
            ),
            &bare
        )
    );
    println!("{}", row("daemon compute per cycle", &compute));
    println!("{}", row("action → first torque", &latency));
    println!(
        "\ncycles {cycles}, overruns {overruns}, cycles without a new hardware state {misses}, \
         hardware states skipped {skipped}, daemon real-time {}",
        last.realtime == 1
    );
    println!("(max of the daemon histograms: since the daemon started)");
    if args.flood {
        println!(
            "flood: {} actions from three more publishers ({:.0}/s), {} joins of a peer",
            flood.actions,
            flood.actions as f64 / args.duration_s,
            flood.joins
        );
    }
    let report = serde_json::json!({
        "duration_s": args.duration_s,
        "daemon_realtime": last.realtime == 1,
        "bare_timer_fifo": bare_fifo,
        "cycles": cycles,
        "overruns": overruns,
        "hardware_misses": misses,
        "hardware_states_skipped": skipped,
        "daemon_wakeup_latency": json(&wake),
        "bare_timer_wakeup_latency": json(&bare),
        "compute": json(&compute),
        "action_to_torque": json(&latency),
        "flood": args.flood.then(|| serde_json::json!({
            "actions": flood.actions,
            "joins": flood.joins,
        })),
    });
    std::fs::write(
        dir.join("jitter.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    chart(&wake, &bare, args.duration_s).write_png(dir.join("jitter.png"))?;
    println!(
        "wrote {} and {}",
        dir.join("jitter.json").display(),
        dir.join("jitter.png").display()
    );
    Ok(())
}
