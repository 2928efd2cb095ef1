//! `hw-sim`: the simulated robot served over shared memory, as hardware.
//!
//! Publishes the joint state and wrist wrench every step, applies the torque
//! commands it receives, publishes camera frames at the camera's rate and
//! episode reports at 20 Hz, and resets episodes on request.
//!
//! - `--mode realtime`: paced at the step period by the wall clock; applies
//!   the latest command, as real hardware does. Without a fresh command for
//!   `--command-timeout-ms` the brakes hold the arm.
//! - `--mode lockstep`: after publishing state k it waits for the command
//!   answering state k, then steps; as fast as the peers allow, and
//!   deterministic.

use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use hw_sim::camera::{Camera, CameraShot};
use hw_sim::reset::ResetPolicy;
use hw_sim::{SimHardware, World, WorldConfig};
use robot_model::descriptions::RobotCatalog;
use shared_mem_schema::SCHEMA_VERSION;
use shared_mem_schema::process::{
    install_termination_handler, mono_now_ns, sleep_until_ns, termination_requested,
};
use shared_mem_schema::transport::{self, Pub, Sub};
use shared_mem_schema::{
    CameraFrame, EpisodeReport, HardwareState, Header, MAX_IMAGE_HEIGHT, MAX_IMAGE_WIDTH,
    SimCommand, TorqueCommand, hw_time_ns, write_text,
};
use std::path::PathBuf;
use std::sync::mpsc;
use tracing::{info, warn};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Mode {
    /// Paced by the wall clock; applies the latest command.
    Realtime,
    /// Each step waits for its command; deterministic.
    Lockstep,
}

/// The simulated robot, served over shared memory.
#[derive(Debug, Parser)]
#[command(name = "hw-sim", version)]
struct Args {
    /// World configuration (TOML, see docs/hw-sim.md); defaults when absent.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Pacing.
    #[arg(long, value_enum, default_value = "realtime")]
    mode: Mode,
    /// Service namespace (several stacks can share a machine).
    #[arg(long, default_value = shared_mem_schema::DEFAULT_NAMESPACE)]
    namespace: String,
    /// Seed of the first episode.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Real-time mode: brakes engage when the newest command is older than
    /// this, ms.
    #[arg(long, default_value_t = 20.0)]
    command_timeout_ms: f64,
    /// Lockstep mode: how long a step waits for its command before the
    /// brakes hold it, s.
    #[arg(long, default_value_t = 10.0)]
    lockstep_timeout_s: f64,
    /// Stop after this much simulated time, s (0: until SIGINT/SIGTERM or a
    /// shutdown command).
    #[arg(long, default_value_t = 0.0)]
    duration_s: f64,
    /// Do not render or publish camera frames.
    #[arg(long)]
    no_camera: bool,
    /// Real-time mode: SCHED_FIFO priority of the stepping thread, below
    /// the controller's (rt-controller's `realtime.priority`, 80), so that
    /// under load the simulated robot keeps its period as hardware does and
    /// the controller still comes first.
    #[arg(long, default_value_t = 70, value_parser = clap::value_parser!(i32).range(1..=99))]
    realtime_priority: i32,
    /// Real-time mode: stay at normal priority.
    #[arg(long)]
    no_realtime: bool,
    /// Directory of URDF files a reset command may name as its robot (by a
    /// relative path inside it); without it, only the built-in robots.
    #[arg(long)]
    robot_dir: Option<PathBuf>,
}

/// Work for the render thread.
enum RenderJob {
    /// A new episode's camera.
    Camera(Box<Camera>),
    /// Render this instant.
    Shot {
        shot: CameraShot,
        episode: u64,
        seq: u64,
    },
}

fn main() {
    tracing_subscriber::fmt().with_target(false).init();
    if let Err(e) = run(Args::parse()) {
        eprintln!("hw-sim: error: {e:#}");
        std::process::exit(1);
    }
}

fn peg_code(world: &World) -> u32 {
    match world.config().task.enabled {
        false => 0,
        true => {
            hw_sim::PegShape::ALL
                .iter()
                .position(|&p| p == world.config().task.peg)
                .unwrap_or(0) as u32
                + 1
        }
    }
}

/// Why a simulator command was refused (sent back in the episode report).
#[derive(Debug, thiserror::Error)]
enum Refusal {
    /// The command was built from another schema.
    #[error("command of schema version {0}, this simulator speaks {SCHEMA_VERSION}")]
    SchemaVersion(u32),
    /// The reset's configuration is unusable (the running world is kept).
    #[error("{0}")]
    Reset(String),
    /// No such command.
    #[error("unknown command {0}")]
    UnknownCommand(u32),
}

/// The answer to a simulator command.
struct Answer {
    /// The command's sequence number (0: none yet).
    seq: u64,
    outcome: Result<(), Refusal>,
}

struct Server {
    args: Args,
    world: World,
    namespace: String,
    /// Resets so far: 0 is the idle start (the schema's "before any"), so
    /// the first reset a user asks for is episode 1. Every reset changes
    /// it, which is what restarts the controller's law.
    episode: u64,
    seed: u64,
    state_pub: Pub<HardwareState>,
    report_pub: Pub<EpisodeReport>,
    torque_sub: Sub<TorqueCommand>,
    command_sub: Sub<SimCommand>,
    render_tx: Option<mpsc::SyncSender<RenderJob>>,
    report_seq: u64,
    camera_seq: u64,
    /// Newest valid command of the current episode.
    command: Option<TorqueCommand>,
    /// The robot's side of the messages (state out, command in, brakes).
    hardware: SimHardware,
    /// What a reset command may ask for.
    resets: ResetPolicy,
    /// The answer to the newest command.
    last_result: Answer,
    rejected_commands: u64,
    /// Camera frames not rendered because the renderer was behind.
    camera_dropped: u64,
    /// Real-time mode: steps that started more than a period after their
    /// deadline (their states reach the controller late, in a burst).
    late_steps: u64,
    shutdown: bool,
}

fn run(args: Args) -> Result<()> {
    install_termination_handler();
    transport::quiet_logs();
    let mut config = match &args.config {
        Some(path) => WorldConfig::from_file(path)?,
        None => WorldConfig::default(),
    };
    config.seed = args.seed;
    let robots = match &args.robot_dir {
        Some(dir) => RobotCatalog::with_dir(dir).context("--robot-dir")?,
        None => RobotCatalog::builtin_only(),
    };
    let resets = ResetPolicy::new(config.clone(), robots);
    let world = World::new(config).context("building the simulated world")?;
    let hardware = SimHardware::new(&world);
    let ns = args.namespace.clone();
    let node = transport::create_node("hw-sim")?;
    let state_pub = transport::publisher::<HardwareState>(&node, &ns)?;
    let report_pub = transport::publisher::<EpisodeReport>(&node, &ns)?;
    let torque_sub = transport::subscriber::<TorqueCommand>(&node, &ns)?;
    let command_sub = transport::subscriber::<SimCommand>(&node, &ns)?;
    // Camera frames are published by the render thread (iceoryx2 ports stay
    // on the thread that made them); it opens its service before we go on
    // so that a schema mismatch stops the start.
    let (render_tx, render_thread) = if args.no_camera {
        (None, None)
    } else {
        let (tx, rx) = mpsc::sync_channel::<RenderJob>(4);
        let (ready_tx, ready_rx) = mpsc::channel::<Result<(), String>>();
        let ns2 = ns.clone();
        let handle = std::thread::Builder::new()
            .name("hw-sim-render".into())
            .spawn(move || render_loop(&ns2, rx, ready_tx))?;
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => bail!("camera service: {e}"),
            Err(_) => bail!("the render thread stopped at start"),
        }
        (Some(tx), Some(handle))
    };
    let mut server = Server {
        seed: args.seed,
        args,
        world,
        namespace: ns,
        episode: 0,
        state_pub,
        report_pub,
        torque_sub,
        command_sub,
        render_tx,
        report_seq: 0,
        camera_seq: 0,
        command: None,
        hardware,
        resets,
        last_result: Answer {
            seq: 0,
            outcome: Ok(()),
        },
        rejected_commands: 0,
        camera_dropped: 0,
        late_steps: 0,
        shutdown: false,
    };
    info!(
        "hw-sim: robot {}, peg {}, {} mode, namespace '{}', dt {} s",
        server.world.config().robot,
        if server.world.config().task.enabled {
            server.world.config().task.peg.name()
        } else {
            "none"
        },
        match server.args.mode {
            Mode::Realtime => "real-time",
            Mode::Lockstep => "lockstep",
        },
        server.namespace,
        server.world.config().dt_s
    );
    server.new_episode_camera();
    // After the render thread started: it inherits the normal priority, and
    // only the stepping loop runs ahead of the machine's other work.
    if server.args.mode == Mode::Realtime && !server.args.no_realtime {
        let priority = server.args.realtime_priority;
        match shared_mem_schema::process::set_fifo_priority(priority) {
            Ok(()) => info!("hw-sim: stepping at SCHED_FIFO priority {priority}"),
            Err(e) => warn!(
                "hw-sim: SCHED_FIFO priority {priority} refused ({e}): stepping at normal \
                 priority, so under load steps run late and the controller misses states; \
                 grant LimitRTPRIO=99 or CAP_SYS_NICE, or pass --no-realtime to silence this"
            ),
        }
    }
    let result = server.serve();
    drop(server.render_tx.take());
    if let Some(h) = render_thread {
        let _ = h.join();
    }
    info!(
        "hw-sim: stopped after {} steps ({} torque commands refused, {} steps late by more than \
         a period, {} camera frames dropped)",
        server.world.step_index(),
        server.rejected_commands,
        server.late_steps,
        server.camera_dropped
    );
    result
}

impl Server {
    fn serve(&mut self) -> Result<()> {
        let dt_ns = (self.world.config().dt_s * 1e9).round() as u64;
        let end_step = if self.args.duration_s > 0.0 {
            (self.args.duration_s / self.world.config().dt_s).round() as u64
        } else {
            u64::MAX
        };
        self.publish_state();
        self.publish_report()?;
        let mut deadline = mono_now_ns();
        while !termination_requested() && !self.shutdown && self.world.step_index() < end_step {
            self.handle_commands()?;
            if self.shutdown {
                break;
            }
            let step = self.world.step_index();
            let have = match self.args.mode {
                Mode::Realtime => {
                    self.take_latest_command();
                    let timeout_steps =
                        (self.args.command_timeout_ms * 1e-3 / self.world.config().dt_s).ceil();
                    self.command
                        .filter(|c| (step.saturating_sub(c.state_step)) as f64 <= timeout_steps)
                }
                Mode::Lockstep => {
                    let episode = self.episode;
                    let c = self.wait_for_command(step)?;
                    if self.episode != episode {
                        // Reset while waiting: state 0 of the new episode is
                        // out; wait for its command.
                        continue;
                    }
                    c
                }
            };
            if self.shutdown {
                break;
            }
            self.hardware
                .apply(&mut self.world, have.as_ref())
                .context("stepping the world")?;
            self.publish_state();
            if self.world.camera_due() {
                self.publish_report()?;
                if let Some(tx) = &self.render_tx {
                    self.camera_seq += 1;
                    let job = RenderJob::Shot {
                        shot: self.world.camera_shot(),
                        episode: self.episode,
                        seq: self.camera_seq,
                    };
                    match tx.try_send(job) {
                        Ok(()) => {}
                        // The renderer is behind: the frame is dropped (and
                        // counted) rather than the robot's next step delayed.
                        Err(mpsc::TrySendError::Full(_)) => {
                            if self.camera_dropped == 0 {
                                warn!("hw-sim: the renderer is behind; camera frames dropped");
                            }
                            self.camera_dropped += 1;
                        }
                        Err(mpsc::TrySendError::Disconnected(_)) => {
                            bail!("the render thread stopped")
                        }
                    }
                }
            }
            if self.args.mode == Mode::Realtime {
                deadline += dt_ns;
                let now = mono_now_ns();
                if now > deadline + dt_ns {
                    self.late_steps += 1;
                }
                if now > deadline + 20 * dt_ns {
                    // Far behind (a stall): restart the schedule instead of
                    // racing through the missed steps.
                    deadline = now;
                } else {
                    sleep_until_ns(deadline);
                }
            }
        }
        Ok(())
    }

    /// Keeps the newest valid command of the current episode.
    fn take_latest_command(&mut self) {
        let nv = self.world.model().nv();
        let episode = self.episode;
        let mut newest = self.command;
        let mut refused = 0;
        let r = transport::drain(&self.torque_sub, |c| {
            if c.header.episode != episode {
                return; // answers a state of the previous episode
            }
            if !SimHardware::valid_command(c, nv) {
                refused += 1;
                return;
            }
            if newest.is_none_or(|n| c.header.seq > n.header.seq || c.state_step > n.state_step) {
                newest = Some(*c);
            }
        });
        if let Err(e) = r {
            warn!("hw-sim: {e}");
        }
        self.rejected_commands += refused;
        self.command = newest;
    }

    /// Lockstep: waits for the command answering state `step`.
    fn wait_for_command(&mut self, step: u64) -> Result<Option<TorqueCommand>> {
        let start = mono_now_ns();
        let limit = (self.args.lockstep_timeout_s * 1e9) as u64;
        let mut republish_at = 20_000_000;
        let mut spins = 0u32;
        loop {
            self.take_latest_command();
            if let Some(c) = self.command
                && c.state_step == step
            {
                return Ok(Some(c));
            }
            if termination_requested() || self.shutdown {
                return Ok(None);
            }
            // Commands may also come while we wait (a reset, a shutdown).
            let episode = self.episode;
            self.handle_commands()?;
            if self.episode != episode {
                return Ok(None);
            }
            let waited = mono_now_ns() - start;
            if waited > limit {
                return Ok(None);
            }
            // Re-publish the state now and then: a controller that started
            // after it was sent would otherwise wait for it forever.
            if waited > republish_at {
                self.publish_state();
                republish_at += 20_000_000;
            }
            spins += 1;
            if spins > 200 {
                std::thread::yield_now();
            }
        }
    }

    fn handle_commands(&mut self) -> Result<()> {
        let mut pending = Vec::new();
        transport::drain(&self.command_sub, |c| pending.push(Box::new(*c)))?;
        for c in pending {
            self.handle_command(&c)?;
        }
        Ok(())
    }

    fn handle_command(&mut self, c: &SimCommand) -> Result<()> {
        if c.header.seq != 0 && c.header.seq == self.last_result.seq {
            // A repeated request (sent again before our answer arrived).
            return self.publish_report();
        }
        if c.header.schema_version != SCHEMA_VERSION {
            self.last_result = Answer {
                seq: c.header.seq,
                outcome: Err(Refusal::SchemaVersion(c.header.schema_version)),
            };
            return self.publish_report();
        }
        match c.command {
            SimCommand::SHUTDOWN => {
                info!("hw-sim: shutdown requested");
                self.shutdown = true;
                self.last_result = Answer {
                    seq: c.header.seq,
                    outcome: Ok(()),
                };
            }
            SimCommand::RESET => {
                let outcome = self.reset(c).map_err(|e| {
                    warn!("hw-sim: reset refused: {e:#}");
                    Refusal::Reset(format!("{e:#}"))
                });
                self.last_result = Answer {
                    seq: c.header.seq,
                    outcome,
                };
            }
            other => {
                self.last_result = Answer {
                    seq: c.header.seq,
                    outcome: Err(Refusal::UnknownCommand(other)),
                };
            }
        }
        self.publish_report()
    }

    fn reset(&mut self, c: &SimCommand) -> Result<()> {
        let n = (c.config_len as usize).min(c.config_toml.len());
        if n > 0 {
            // Built aside: a refused configuration leaves the running world.
            self.world = self.resets.world(&c.config_toml[..n], c.seed)?;
        } else {
            self.world.reset(c.seed)?;
        }
        self.seed = c.seed;
        self.episode += 1;
        self.command = None;
        self.hardware.reset();
        self.new_episode_camera();
        info!("hw-sim: episode {} (seed {})", self.episode, self.seed);
        self.publish_state();
        Ok(())
    }

    fn new_episode_camera(&mut self) {
        if let Some(tx) = &self.render_tx {
            let _ = tx.send(RenderJob::Camera(Box::new(self.world.camera().clone())));
        }
    }

    fn header(&self, seq: u64) -> Header {
        Header::new(
            seq,
            mono_now_ns(),
            hw_time_ns(self.world.time_s()),
            self.episode,
        )
    }

    fn publish_state(&mut self) {
        let mut m = HardwareState::empty(0);
        self.hardware
            .state(&self.world, self.episode, mono_now_ns(), &mut m);
        if let Err(e) = transport::send(&self.state_pub, &m) {
            warn!("hw-sim: {e}");
        }
    }

    fn publish_report(&mut self) -> Result<()> {
        self.report_seq += 1;
        let header = self.header(self.report_seq);
        let (world, answer, seed) = (&self.world, &self.last_result, self.seed);
        let (result, message) = match &answer.outcome {
            Ok(()) => (EpisodeReport::OK, String::new()),
            Err(why) => (EpisodeReport::REJECTED, why.to_string()),
        };
        transport::send_with(&self.report_pub, |m| {
            m.header = header;
            m.command_seq = answer.seq;
            m.seed = seed;
            m.step = world.step_index();
            m.command_result = result;
            m.peg = peg_code(world);
            if let Some(t) = world.task() {
                m.stage_now = t.stage_now.code();
                m.best_stage = t.best_stage.code();
                m.in_contact = t.in_contact as u32;
                m.s_m = [t.s_m.x, t.s_m.y, t.s_m.z];
                m.s_psi_rad = t.s_psi_rad;
            }
            if let Some(h) = world.hole_pose() {
                m.hole_pos_m = h.translation.vector.into();
                m.hole_quat_xyzw = h.rotation.coords.into();
            }
            let task = &world.config().task;
            m.peg_width_m = task.peg_width_m;
            m.hole_depth_m = task.hole_depth_m;
            m.message_len = write_text(&mut m.message, &message);
        })?;
        Ok(())
    }
}

/// Renders shots in order and publishes them.
fn render_loop(
    namespace: &str,
    rx: mpsc::Receiver<RenderJob>,
    ready: mpsc::Sender<Result<(), String>>,
) {
    let opened = transport::create_node("hw-sim-camera")
        .and_then(|node| Ok((transport::publisher::<CameraFrame>(&node, namespace)?, node)));
    let (publisher, _node) = match opened {
        Ok(p) => {
            let _ = ready.send(Ok(()));
            p
        }
        Err(e) => {
            let _ = ready.send(Err(e.to_string()));
            return;
        }
    };
    let mut camera: Option<Box<Camera>> = None;
    let mut frame = hw_sim::CameraFrame::default();
    while let Ok(job) = rx.recv() {
        match job {
            RenderJob::Camera(c) => camera = Some(c),
            RenderJob::Shot { shot, episode, seq } => {
                let Some(cam) = camera.as_mut() else { continue };
                cam.render_shot(&shot, &mut frame);
                let (w, h) = (frame.width as usize, frame.height as usize);
                if w > MAX_IMAGE_WIDTH || h > MAX_IMAGE_HEIGHT {
                    warn!("hw-sim: a {w}×{h} image exceeds the message's maximum size");
                    continue;
                }
                let r = transport::send_with(&publisher, |m| {
                    m.header = Header::new(seq, mono_now_ns(), hw_time_ns(shot.t_s), episode);
                    hw_sim::camera::fill_message(cam, &frame, m);
                });
                if let Err(e) = r {
                    warn!("hw-sim: {e}");
                }
            }
        }
    }
}
