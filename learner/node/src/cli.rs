//! The node's command line: the argument structs of `run` (the live node)
//! and `stack` (the whole stack), shared by `policy-node` and `learner`, and
//! the commands themselves.

use crate::calibrated::{self, CalibratedConfig};
use crate::deploy::DeployedPolicy;
use crate::live::{self, LiveConfig};
use crate::log::{ChannelGaps, LogOptions};
use crate::mix::Mix;
use crate::policy::TaskGeometry;
use crate::stack::{self, StackConfig};
use anyhow::{Context, Result};
use hw_sim::{PegShape, Stage, WorldConfig};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The episodes to run and where, shared by `run` and `stack`.
#[derive(Debug, Clone, clap::Args)]
pub struct EpisodeArgs {
    /// Episodes to run.
    #[arg(long, default_value_t = 3)]
    pub episodes: u32,
    /// Peg [default: the world's (`--world`, or a training checkpoint's
    /// with `learner run|stack`), else square].
    #[arg(long, value_enum)]
    pub peg: Option<PegShape>,
    /// Seed of the first episode.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// World configuration (TOML) sent with every reset; `--peg` overrides
    /// its peg [default: hw-sim's; `learner run|stack` with a training
    /// checkpoint: the world it was trained in].
    #[arg(long)]
    pub world: Option<PathBuf>,
    /// Episode time limit, s [default: 20; `learner run|stack` with a
    /// training checkpoint: its episode length].
    #[arg(long)]
    pub episode_timeout_s: Option<f64>,
    /// Where logs go.
    #[arg(long, default_value = "logs")]
    pub log_dir: PathBuf,
    /// Service namespace.
    #[arg(long, default_value = shared_mem_schema::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Deterministic lockstep run.
    #[arg(long)]
    pub lockstep: bool,
    /// A trained policy acts instead of the heuristic: a deployed policy
    /// (policy.json, `learner policy export`; its encoder's weights beside
    /// it). `learner` also takes a training run's checkpoint.json, converts
    /// it and runs it in its training world, episode length and (stack)
    /// controller unless those are given.
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Also serve every channel the node logs, live, over the Foxglove
    /// WebSocket protocol on this port (0: any free one; the address is
    /// printed). Off by default. Foxglove: Open connection → Foxglove
    /// WebSocket → ws://127.0.0.1:PORT.
    #[arg(long)]
    pub foxglove_ws: Option<u16>,
    /// The address --foxglove-ws listens on: loopback by default; any other
    /// shows the robot's data to that network, unauthenticated.
    #[arg(long, default_value = "127.0.0.1", requires = "foxglove_ws")]
    pub foxglove_ws_host: std::net::IpAddr,
    /// With a training checkpoint as --policy (`learner` only): its last
    /// policy (a distillation's last round, as `policy eval --last`) instead
    /// of its best validated or best logged one.
    #[arg(long, requires = "policy")]
    pub last: bool,
}

/// A task the user calibrated instead of a simulator's report (a robot,
/// franky-sim).
#[derive(Debug, Clone, clap::Args)]
pub struct CalibrationArgs {
    /// The hole's top centre in the robot's base frame, m, as `X,Y,Z` (the
    /// hole's axis is the base's z): the heuristic acts on this calibration
    /// instead of a simulator's report. On a robot, where the box was
    /// calibrated; on franky-sim (no box), any point the arm can reach.
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 1,
        allow_negative_numbers = true
    )]
    pub hole_pos: Option<Vec<f64>>,
    /// The calibrated hole's depth, m: the heuristic descends to its bottom.
    #[arg(long, default_value_t = 0.03)]
    pub hole_depth_m: f64,
}

impl CalibrationArgs {
    /// The task, when a hole position is given (`--peg` gives its symmetry).
    pub fn task(&self, peg: PegShape) -> Result<Option<TaskGeometry>> {
        let Some(p) = &self.hole_pos else {
            return Ok(None);
        };
        anyhow::ensure!(
            p.len() == 3 && p.iter().all(|v| v.is_finite()),
            "--hole-pos {p:?}: must be three finite numbers X,Y,Z (m, the robot's base frame)"
        );
        anyhow::ensure!(
            self.hole_depth_m.is_finite() && self.hole_depth_m > 0.0 && self.hole_depth_m <= 0.2,
            "--hole-depth-m {}: must be within (0, 0.2] m",
            self.hole_depth_m
        );
        Ok(Some(TaskGeometry {
            hole_pose: nalgebra::Isometry3::translation(p[0], p[1], p[2]),
            symmetry: peg.symmetry_order(),
            depth_m: self.hole_depth_m,
        }))
    }
}

/// What `stack` runs the controller against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RobotArg {
    /// hw-sim: the simulated arm, peg, box and camera.
    Sim,
    /// franky-sim: a simulated Franka FR3 over the robot's own protocol,
    /// without peg, box or camera (needs --hole-pos).
    FrankySim,
}

/// `run` as a collector (what `learner collect --live` passes).
#[derive(Debug, Clone, clap::Args)]
pub struct RunCollectArgs {
    /// Pegs taken in turn per episode, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub pegs: Vec<PegShape>,
    /// Collect with the random/heuristic mix, this share heuristic.
    #[arg(long)]
    pub mix_heuristic_fraction: Option<f64>,
    /// End each episode after this many actions.
    #[arg(long)]
    pub episode_actions: Option<u32>,
    /// Stop after this many states (actions), with a progress bar.
    #[arg(long)]
    pub states: Option<u64>,
    /// Collection: run completed episodes to their length instead of
    /// ending them shortly after completion.
    #[arg(long)]
    pub full_episodes: bool,
    /// Leave out the Foxglove view channels.
    #[arg(long)]
    pub no_foxglove: bool,
    /// Rate of the 1 kHz view channels, Hz.
    #[arg(long, default_value_t = 1000.0)]
    pub view_rate_hz: f64,
}

/// The live policy node (`run`): heuristic insertion episodes against a
/// running hw-sim and rt-controller, logged to MCAP. With --hole-pos,
/// against a running rt-controller alone (a robot, franky-sim): the task
/// from the calibration, no resets.
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub episodes: EpisodeArgs,
    #[command(flatten)]
    pub collect: RunCollectArgs,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
    /// With --hole-pos: the daemon's robot description, recorded in the
    /// logs.
    #[arg(long, default_value = "fr3")]
    pub robot_description: String,
    /// With --hole-pos: how long to wait for the controller's first
    /// frame, s (a robot's daemon connects within its start-up timeout).
    #[arg(long, default_value_t = 180)]
    pub controller_wait_s: u64,
}

/// The whole stack (`stack`): starts hw-sim (or franky-sim), rt-controller
/// and the node (`run`) as separate processes, runs the episodes, stops
/// everything.
#[derive(Debug, Clone, clap::Args)]
pub struct StackArgs {
    #[command(flatten)]
    pub episodes: EpisodeArgs,
    /// rt-controller configuration (TOML); with --robot franky-sim, the
    /// default is the repository's configs/rt-controller/franky-sim.toml;
    /// `learner stack` with a training checkpoint: its controller.
    #[arg(long)]
    pub controller_config: Option<PathBuf>,
    /// What the controller drives.
    #[arg(long, value_enum, default_value_t = RobotArg::Sim)]
    pub robot: RobotArg,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
    /// With --robot franky-sim: the loopback address franky-sim serves
    /// on (default: one of this process's own in 127.20.0.0/16).
    #[arg(long)]
    pub franky_sim_address: Option<String>,
    /// With --robot franky-sim: the Python interpreter that has franky-sim
    /// installed (default: the repository's .venv-franky-sim, which
    /// scripts/franky-sim-venv.sh makes).
    #[arg(long)]
    pub franky_sim_python: Option<PathBuf>,
}

/// The episode time limit without `--episode-timeout-s`, s.
pub const DEFAULT_EPISODE_TIMEOUT_S: f64 = 20.0;

impl EpisodeArgs {
    /// `--peg`, or the square (a run without a world: a robot, franky-sim).
    pub fn peg_or_square(&self) -> PegShape {
        self.peg.unwrap_or(PegShape::Square)
    }

    /// `--episode-timeout-s`, or [`DEFAULT_EPISODE_TIMEOUT_S`].
    pub fn timeout_s(&self) -> f64 {
        self.episode_timeout_s.unwrap_or(DEFAULT_EPISODE_TIMEOUT_S)
    }

    /// [`Self::timeout_s`], refused unless finite and positive (an episode
    /// must end).
    pub fn checked_timeout_s(&self) -> Result<f64> {
        let t = self.timeout_s();
        anyhow::ensure!(
            t.is_finite() && t > 0.0,
            "--episode-timeout-s {t} must be positive and finite"
        );
        Ok(t)
    }

    /// The live view's server when `--foxglove-ws` asks for one, serving
    /// the channels of logs written with `log`.
    pub fn live_view(&self, log: &LogOptions) -> Result<Option<Arc<crate::log::ws::Hub>>> {
        let Some(port) = self.foxglove_ws else {
            return Ok(None);
        };
        let server = crate::log::ws::LiveServer::start((self.foxglove_ws_host, port), log)
            .with_context(|| {
                format!(
                    "--foxglove-ws: listening on {}:{port}",
                    self.foxglove_ws_host
                )
            })?;
        eprintln!(
            "node: Foxglove WebSocket on ws://{} (Foxglove: Open connection → Foxglove \
             WebSocket)",
            server.local_addr()
        );
        Ok(Some(server.hub()))
    }

    /// The arguments that pass `--foxglove-ws` on to the node `stack` starts.
    fn live_view_args(&self) -> Vec<String> {
        match self.foxglove_ws {
            Some(port) => vec![
                "--foxglove-ws".into(),
                port.to_string(),
                "--foxglove-ws-host".into(),
                self.foxglove_ws_host.to_string(),
            ],
            None => Vec::new(),
        }
    }
}

/// The world of a run: `--world` (or the default) with the task on and
/// `--peg`'s peg.
pub fn world_config(a: &EpisodeArgs) -> Result<WorldConfig> {
    let mut w = match &a.world {
        Some(p) => WorldConfig::from_file(p)?,
        None => WorldConfig::default(),
    };
    w.task.enabled = true;
    if let Some(peg) = a.peg {
        w.task.peg = peg;
    }
    Ok(w)
}

/// Loads `--policy` as a deployed policy; refuses `--last`, which picks
/// among a training checkpoint's policies (the `learner` CLI converts
/// those).
pub fn deployed_policy(a: &EpisodeArgs) -> Result<Option<DeployedPolicy>> {
    let Some(path) = &a.policy else {
        return Ok(None);
    };
    anyhow::ensure!(
        !a.last,
        "--last picks among a training checkpoint's policies; {} must then be a checkpoint, \
         which `learner run`/`learner stack` convert (the node reads deployed policies only)",
        path.display()
    );
    Ok(Some(DeployedPolicy::load(path)?))
}

/// `run`: the live node, acting with `policy` (the loaded `--policy`) or the
/// heuristic.
pub fn run(r: RunArgs, policy: Option<DeployedPolicy>) -> Result<()> {
    let (a, c) = (&r.episodes, &r.collect);
    if let Some(task) = r.calibration.task(a.peg_or_square())? {
        return run_calibrated(a, c, task, r.robot_description, r.controller_wait_s);
    }
    let mut cfg = LiveConfig::new(&a.namespace, world_config(a)?, a.log_dir.clone());
    cfg.episodes = a.episodes;
    cfg.seed = a.seed;
    cfg.episode_timeout_s = a.checked_timeout_s()?;
    cfg.lockstep = a.lockstep;
    cfg.pegs = c.pegs.clone();
    cfg.mix = c.mix_heuristic_fraction.map(|f| {
        let mut m = Mix {
            heuristic_fraction: f,
            ..Default::default()
        };
        if c.full_episodes {
            m.end_after_completion = None;
        }
        m
    });
    cfg.max_actions = c.episode_actions;
    cfg.target_states = c.states;
    cfg.log.foxglove = !c.no_foxglove;
    cfg.log.view_rate_hz = c.view_rate_hz;
    cfg.live_view = a.live_view(&cfg.log)?;
    if let Some(p) = policy {
        anyhow::ensure!(
            cfg.mix.is_none(),
            "--policy and --mix-heuristic-fraction exclude each other"
        );
        p.check_world(&cfg.world)?;
        eprintln!("node: acting with {}", p.source());
        if p.trained_peg() != cfg.world.task.peg {
            eprintln!(
                "node: the policy was trained on the {} peg; running it on the {} peg",
                p.trained_peg().name(),
                cfg.world.task.peg.name()
            );
        }
        cfg.policy = Some(Arc::new(p));
    }
    let outcomes = live::run(&cfg, |o| {
        println!(
            "episode {} (seed {}): {}{} after {:.2} s, {} actions; {}",
            o.episode,
            o.seed,
            o.stage,
            if o.interrupted { " (interrupted)" } else { "" },
            o.duration_s,
            o.actions,
            frames_and_log(&o.sensor_gaps, &o.log)
        );
    })?;
    let done = outcomes
        .iter()
        .filter(|o| o.stage == Stage::Completed)
        .count();
    println!(
        "{done} of {} episodes completed the insertion",
        outcomes.len()
    );
    Ok(())
}

/// `stack`: the whole stack, this executable's `run` as its node. A
/// `--policy` must be a deployed policy (loaded here first, so that a bad
/// file fails before any process starts).
pub fn stack(s: StackArgs) -> Result<()> {
    let a = &s.episodes;
    if s.robot == RobotArg::FrankySim {
        return stack_franky_sim(
            a,
            s.controller_config,
            &s.calibration,
            s.franky_sim_address,
            s.franky_sim_python,
        );
    }
    anyhow::ensure!(
        s.calibration.hole_pos.is_none()
            && s.franky_sim_address.is_none()
            && s.franky_sim_python.is_none(),
        "--hole-pos, --franky-sim-address and --franky-sim-python are for --robot franky-sim \
         (hw-sim reports the hole itself)"
    );
    let world = world_config(a)?; // fail early on a bad peg or file
    let mut run_args = vec![
        "--episodes".to_string(),
        a.episodes.to_string(),
        "--peg".into(),
        world.task.peg.name().into(),
        "--seed".into(),
        a.seed.to_string(),
        "--episode-timeout-s".into(),
        a.checked_timeout_s()?.to_string(),
    ];
    if let Some(w) = &a.world {
        run_args.push("--world".into());
        run_args.push(w.display().to_string());
    }
    run_args.extend(a.live_view_args());
    if let Some(p) = deployed_policy(a)? {
        p.check_world(&world)?;
        run_args.push("--policy".into());
        run_args.push(a.policy.as_ref().expect("loaded").display().to_string());
    }
    let exit = stack::run(&StackConfig {
        hardware: stack::Hardware::Sim,
        namespace: a.namespace.clone(),
        lockstep: a.lockstep,
        node: std::env::current_exe().context("locating this executable")?,
        run_args,
        log_dir: a.log_dir.clone(),
        controller_config: s.controller_config,
    })?;
    println!("stack stopped; process logs in {}", a.log_dir.display());
    if !exit.policy.success() {
        anyhow::bail!("the policy node failed ({})", exit.policy);
    }
    Ok(())
}

/// An episode line's tail: its sensor frames logged and missing, and its log.
fn frames_and_log(g: &ChannelGaps, log: &Path) -> String {
    let loss = g.sensor.unwrap_or_default();
    format!(
        "sensor frames: {} logged, {} missing in {} gaps ({} hardware steps without a controller \
         frame, {} published but not recorded); log {}",
        g.messages,
        g.missing,
        g.gaps,
        loss.not_published,
        loss.not_recorded,
        log.display()
    )
}

/// Refuses the episode options that need hw-sim, for `mode` (a run without
/// the simulator: a robot, franky-sim).
fn without_simulator(a: &EpisodeArgs, mode: &str) -> Result<()> {
    for (given, flag) in [
        (
            a.lockstep,
            "--lockstep (the robot clocks the loop and never waits for the learner)",
        ),
        (
            a.policy.is_some(),
            "--policy (a trained policy reads the simulator's task state)",
        ),
        (
            a.world.is_some(),
            "--world (there is no simulator to configure)",
        ),
    ] {
        anyhow::ensure!(!given, "{mode} excludes {flag}");
    }
    Ok(())
}

/// `run --hole-pos`: the heuristic on a calibrated task against a
/// running controller alone (a robot, franky-sim).
fn run_calibrated(
    a: &EpisodeArgs,
    c: &RunCollectArgs,
    task: TaskGeometry,
    robot: String,
    controller_wait_s: u64,
) -> Result<()> {
    without_simulator(a, "--hole-pos")?;
    for (given, flag) in [
        (
            c.mix_heuristic_fraction.is_some(),
            "--mix-heuristic-fraction",
        ),
        (!c.pegs.is_empty(), "--pegs"),
        (c.states.is_some(), "--states"),
        (c.episode_actions.is_some(), "--episode-actions"),
    ] {
        anyhow::ensure!(!given, "--hole-pos excludes {flag}");
    }
    let cfg = CalibratedConfig {
        namespace: a.namespace.clone(),
        episodes: a.episodes,
        task,
        peg: a.peg_or_square(),
        robot,
        episode_timeout_s: a.checked_timeout_s()?,
        settle_s: 0.5,
        controller_wait_s,
        log_dir: a.log_dir.clone(),
        log: LogOptions {
            foxglove: !c.no_foxglove,
            view_rate_hz: c.view_rate_hz,
            ..Default::default()
        },
        live_view: None,
    };
    let cfg = CalibratedConfig {
        live_view: a.live_view(&cfg.log)?,
        ..cfg
    };
    std::fs::create_dir_all(&cfg.log_dir)
        .with_context(|| format!("creating {}", cfg.log_dir.display()))?;
    let mm = |v: [f64; 3]| format!("[{:.1}, {:.1}, {:.1}]", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
    let run = calibrated::run(&cfg, |o| {
        let e = o.end_error_m();
        println!(
            "episode {}: {} after {:.2} s, {} actions; tip from {} to {} mm, goal (the hole's \
             bottom centre) {} mm: moved {:.1} mm towards it, ended {:.1} mm from it ({:.1} mm \
             sideways, {:+.1} mm in z); {}",
            o.episode,
            if o.reached {
                "reached the hole's bottom level"
            } else if o.interrupted {
                "interrupted"
            } else {
                "did not reach the hole's bottom level"
            },
            o.duration_s,
            o.actions,
            mm(o.start_m),
            mm(o.end_m),
            mm(o.goal_m),
            o.approached_m() * 1e3,
            e.norm() * 1e3,
            e.xy().norm() * 1e3,
            e.z * 1e3,
            frames_and_log(&o.sensor_gaps, &o.log)
        );
    })?;
    let reached = run.episodes.iter().filter(|o| o.reached).count();
    println!(
        "{reached} of {} episodes reached the calibrated hole's bottom level, in free space: \
         there is no peg or box, so no contact and no insertion outcome",
        run.episodes.len()
    );
    match &run.status {
        Some(s) => println!(
            "controller: {} cycles, {} hardware states skipped, compute p50 {} µs, p99 {} µs, \
             max {:.0} µs (the robot's period: 1000 µs), fault code {}",
            s.cycles,
            s.hardware_states_skipped,
            s.compute.quantile_us(0.5),
            s.compute.quantile_us(0.99),
            s.compute.max_ns as f64 / 1e3,
            s.fault_code
        ),
        None => println!("controller: no status received"),
    }
    Ok(())
}

/// `stack --robot franky-sim`: franky-sim, rt-controller with the
/// Franka backend, and the heuristic on the calibrated task.
fn stack_franky_sim(
    a: &EpisodeArgs,
    controller_config: Option<PathBuf>,
    calibration: &CalibrationArgs,
    address: Option<String>,
    python: Option<PathBuf>,
) -> Result<()> {
    let Some(task) = calibration.task(a.peg_or_square())? else {
        anyhow::bail!(
            "--robot franky-sim needs --hole-pos X,Y,Z: where the hole is in the robot's base \
             frame, m (franky-sim has no box; on a robot this is the box's calibration), e.g. \
             --hole-pos 0.60,0.0,0.42, 5 cm in front of and 10 cm below the FR3's start pose"
        );
    };
    without_simulator(a, "--robot franky-sim")?;
    let mut franky = stack::FrankySim::from_repository();
    if let Some(p) = python {
        franky.python = p;
    }
    if let Some(addr) = address {
        anyhow::ensure!(
            addr.parse::<std::net::Ipv4Addr>()
                .is_ok_and(|ip| ip.is_loopback()),
            "--franky-sim-address {addr:?}: must be an IPv4 loopback address (127.x.y.z)"
        );
        franky.address = addr;
    }
    let template = controller_config
        .unwrap_or_else(|| stack::repository_root().join("configs/rt-controller/franky-sim.toml"));
    std::fs::create_dir_all(&a.log_dir)
        .with_context(|| format!("creating {}", a.log_dir.display()))?;
    let written = a.log_dir.join("rt-controller.toml");
    stack::franky_sim_controller_config(&template, &franky.address, &a.namespace, &written)?;
    let daemon = rt_controller_daemon::config::DaemonConfig::from_file(&written)?;
    let p = task.hole_pose.translation.vector;
    let mut run_args = vec![
        "--episodes".to_string(),
        a.episodes.to_string(),
        "--peg".into(),
        a.peg_or_square().name().into(),
        "--episode-timeout-s".into(),
        a.checked_timeout_s()?.to_string(),
        "--hole-pos".into(),
        format!("{},{},{}", p.x, p.y, p.z),
        "--hole-depth-m".into(),
        task.depth_m.to_string(),
        "--robot-description".into(),
        daemon.robot.clone(),
        // The daemon retries connecting for its start-up timeout.
        "--controller-wait-s".into(),
        (daemon.timing.startup_timeout_s.ceil() as u64 + 60).to_string(),
    ];
    run_args.extend(a.live_view_args());
    let exit = stack::run(&StackConfig {
        hardware: stack::Hardware::FrankySim(franky),
        node: std::env::current_exe().context("locating this executable")?,
        namespace: a.namespace.clone(),
        lockstep: false,
        run_args,
        log_dir: a.log_dir.clone(),
        controller_config: Some(written),
    })?;
    let show = |s: Option<std::process::ExitStatus>| {
        s.map_or("still running after SIGKILL".to_string(), |s| s.to_string())
    };
    println!(
        "stack stopped: rt-controller {} after SIGTERM, franky-sim {}; process logs in {}",
        show(exit.controller),
        show(exit.hardware),
        a.log_dir.display()
    );
    if !exit.policy.success() {
        anyhow::bail!("the policy node failed ({})", exit.policy);
    }
    if !exit.controller.is_some_and(|s| s.success()) {
        anyhow::bail!(
            "rt-controller did not stop cleanly ({}); see {}",
            show(exit.controller),
            a.log_dir.join("rt-controller.log").display()
        );
    }
    Ok(())
}
