//! The live policy node: subscribes to the controller's sensor frames, the
//! camera and the simulator's episode reports, acts at 20 Hz (the scripted
//! heuristic, the collection mix, or a trained policy with its encoder),
//! publishes the actions and logs every stream to MCAP, one file per
//! episode.
//!
//! Real-time mode acts on the newest frame every 50 ms of the hardware's
//! clock (the frames' `t_hw_ns`; [`ActionPacer`], which `calibrated.rs` uses
//! too), as a deployed policy does. On a robot that clock is the wall clock;
//! hw-sim's and franky-sim's run slower than the wall clock when the machine
//! is loaded, and the policies act at 20 Hz of the arm's time, as they were
//! tuned and trained to. Lockstep mode answers each action request of a
//! lockstep simulator: on the frame of step 50m−1 it publishes the action
//! addressed to step 50m, so runs are deterministic.

use crate::collect::{EpisodePolicy, Mix, MixedPolicy};
use crate::log::events::{Event, Outcome, Reset};
use crate::log::gaps::SensorGapCounter;
use crate::log::{ChannelGaps, LogOptions, LogWriter, RunConfig, RunMode};
use crate::policy::{
    Action4, HeuristicConfig, HeuristicPolicy, Observation, TaskGeometry, WrenchHistory,
};
use crate::progress::Progress;
use crate::proprio::roll_reference;
use crate::rl::deploy::{TrainedPolicy, task_state};
use crate::rl::observe::ObsView;
use crate::stack::StackError;
use hw_sim::{PegShape, WorldConfig};
use nalgebra::{Isometry3, Translation3};
use shared_mem_schema::Message;
use shared_mem_schema::process::{mono_now_ns, termination_requested};
use shared_mem_schema::rates::ACTION_PERIOD_NS;
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::transport::{self, Pub, Sub};
use shared_mem_schema::{
    CameraFrame, ControllerCommand, ControllerMode, ControllerStatus, EpisodeReport, Header,
    PolicyAction, SensorFrame, SimCommand, Stage, hw_time_s,
};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// Settings of a live run.
#[derive(Debug, Clone)]
pub struct LiveConfig {
    /// Service namespace.
    pub namespace: String,
    /// Episodes to run.
    pub episodes: u32,
    /// Seed of the first episode (+1 per episode).
    pub seed: u64,
    /// World configuration sent with every reset.
    pub world: WorldConfig,
    /// Episode length limit, s of hardware time.
    pub episode_timeout_s: f64,
    /// Where the MCAP logs go.
    pub log_dir: PathBuf,
    /// Lockstep (deterministic) instead of wall-clock acting.
    pub lockstep: bool,
    /// Hold still this long after completion before ending, s.
    pub settle_s: f64,
    /// Data collection: the random/heuristic mix (`None`: the heuristic
    /// alone, inserting).
    pub mix: Option<Mix>,
    /// Pegs taken in turn per episode (empty: the world's).
    pub pegs: Vec<PegShape>,
    /// End each episode after this many actions.
    pub max_actions: Option<u32>,
    /// Stop once this many actions (20 Hz states) are logged, with a
    /// progress bar.
    pub target_states: Option<u64>,
    /// Log options.
    pub log: LogOptions,
    /// A trained policy acts instead of the heuristic (`--policy`).
    pub policy: Option<Arc<TrainedPolicy>>,
}

impl LiveConfig {
    /// The settings of `learner run` for `episodes` heuristic episodes.
    pub fn new(namespace: &str, world: WorldConfig, log_dir: PathBuf) -> Self {
        Self {
            namespace: namespace.to_string(),
            episodes: 1,
            seed: 1,
            world,
            episode_timeout_s: 20.0,
            log_dir,
            lockstep: false,
            settle_s: 0.3,
            mix: None,
            pegs: Vec::new(),
            max_actions: None,
            target_states: None,
            log: LogOptions::default(),
            policy: None,
        }
    }
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
/// and runs `learner run` with the collection mix.
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
    let exit = crate::stack::run(&crate::stack::StackConfig {
        hardware: crate::stack::Hardware::Sim,
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

/// How an episode ended.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeOutcome {
    /// Episode number: the simulator's reset count (1 for the first reset
    /// after hw-sim starts).
    pub episode: u64,
    /// Its seed.
    pub seed: u64,
    /// Best stage reached.
    pub stage: Stage,
    /// The run was interrupted (SIGINT/SIGTERM) during the episode.
    pub interrupted: bool,
    /// Hardware time it took, s.
    pub duration_s: f64,
    /// Actions sent.
    pub actions: u64,
    /// Its log.
    pub log: PathBuf,
    /// The gaps in its logged sensor frames: hardware steps with no frame,
    /// and which of those the controller published but the log lacks.
    pub sensor_gaps: ChannelGaps,
}

/// The policy node's services: what it reads and what it publishes.
pub struct PolicyNode {
    _node: transport::StackNode,
    /// Controller sensor frames.
    pub sensor: Sub<SensorFrame>,
    /// Camera frames.
    pub camera: Sub<CameraFrame>,
    /// Controller status.
    pub status: Sub<ControllerStatus>,
    /// Simulator episode reports.
    pub report: Sub<EpisodeReport>,
    action: Pub<PolicyAction>,
    command: Pub<SimCommand>,
    controller: Pub<ControllerCommand>,
    action_seq: u64,
    command_seq: u64,
    /// Sensor frames drained while waiting for a reset's answer (the new
    /// episode's first frames among them), logged by the next pump.
    early: VecDeque<SensorFrame>,
}

/// Sensor frames kept while a reset is answered: 2 s of frames; the new
/// episode's come last, so dropping the oldest loses the old episode's.
const EARLY_FRAMES: usize = 2000;

/// What the node has seen of the current episode.
pub(crate) struct Seen {
    pub(crate) frame: Option<SensorFrame>,
    /// The episode's roll reference: the roll of its first frame (the first
    /// one logged).
    pub(crate) roll_ref_rad: Option<f64>,
    pub(crate) report: Option<EpisodeReport>,
    pub(crate) wrench: WrenchHistory,
    pub(crate) frames: u64,
    pub(crate) last_frame_wall_ns: u64,
    pub(crate) gaps: SensorGapCounter,
    /// The latest controller status.
    pub(crate) status: Option<ControllerStatus>,
    /// The episode's latest camera frame (kept only for a policy that
    /// reads the camera).
    camera: Option<Box<CameraFrame>>,
    /// Whether camera frames are kept.
    keep_camera: bool,
}

impl Seen {
    /// Nothing seen yet (the first report, if any, given).
    pub(crate) fn new(report: Option<EpisodeReport>, keep_camera: bool) -> Self {
        Self {
            frame: None,
            roll_ref_rad: None,
            report,
            wrench: WrenchHistory::default(),
            frames: 0,
            last_frame_wall_ns: mono_now_ns(),
            gaps: SensorGapCounter::default(),
            status: None,
            camera: None,
            keep_camera,
        }
    }
}

impl PolicyNode {
    /// Opens the services of namespace `ns`.
    pub fn open(ns: &str) -> Result<Self, StackError> {
        let node = transport::create_node("learner")?;
        Ok(Self {
            sensor: transport::subscriber(&node, ns)?,
            camera: transport::subscriber(&node, ns)?,
            status: transport::subscriber(&node, ns)?,
            report: transport::subscriber(&node, ns)?,
            action: transport::publisher(&node, ns)?,
            command: transport::publisher(&node, ns)?,
            controller: transport::publisher(&node, ns)?,
            _node: node,
            action_seq: 0,
            command_seq: 0,
            early: VecDeque::new(),
        })
    }

    /// Takes everything queued; logs what belongs to `episode`.
    pub(crate) fn pump(
        &mut self,
        episode: u64,
        seen: &mut Seen,
        mut log: Option<&mut LogWriter>,
    ) -> Result<(), StackError> {
        let now = mono_now_ns();
        let mut err = None;
        let mut on_frame = |f: &SensorFrame| {
            if f.header.episode != episode {
                return;
            }
            seen.wrench.push(f.wrench);
            seen.frames += 1;
            seen.gaps.push(f);
            seen.last_frame_wall_ns = now;
            if let Some(l) = log.as_deref_mut()
                && let Err(e) = l.sensor(f)
            {
                err = Some(e);
            }
            seen.roll_ref_rad.get_or_insert_with(|| roll_reference(f));
            seen.frame = Some(*f);
        };
        for f in self.early.drain(..) {
            on_frame(&f);
        }
        transport::drain(&self.sensor, &mut on_frame)?;
        transport::drain(&self.report, |r| {
            if r.header.episode == episode {
                if let Some(l) = log.as_deref_mut()
                    && let Err(e) = l.episode(r)
                {
                    err = Some(e);
                }
                seen.report = Some(*r);
            }
        })?;
        transport::drain(&self.status, |s| {
            seen.status = Some(*s);
            if let Some(l) = log.as_deref_mut()
                && let Err(e) = l.status(s)
            {
                err = Some(e);
            }
        })?;
        transport::drain(&self.camera, |c| {
            if c.header.episode != episode {
                return;
            }
            if seen.keep_camera {
                // Byte copy: a frame is too large for a stack temporary.
                let kept = seen.camera.get_or_insert_with(CameraFrame::boxed_zeroed);
                bytemuck::bytes_of_mut(&mut **kept).copy_from_slice(bytemuck::bytes_of(c));
            }
            if let Some(l) = log.as_deref_mut()
                && let Err(e) = l.camera(c)
            {
                err = Some(e);
            }
        })?;
        if let Some(e) = err {
            return Err(e.into());
        }
        Ok(())
    }

    /// Takes the sensor frames [`Self::reset`] drained while it waited for
    /// its answer, oldest first: the old episode's last ones, then the new
    /// episode's first (in lockstep up to its first action request). A
    /// caller that drains [`Self::sensor`] itself takes these first; the
    /// node's own episode loop logs them with its next pump.
    pub fn take_early_frames(&mut self) -> Vec<SensorFrame> {
        self.early.drain(..).collect()
    }

    /// Queues a frame taken off the stream for the next pump to log.
    pub(crate) fn push_early(&mut self, f: SensorFrame) {
        self.early.push_back(f);
    }

    /// Waits (up to 10 s) until the controller publishes sensor frames.
    /// hw-sim starts an episode at the reset whether the controller runs or
    /// not, and a step before the controller's first cycle has no frame: a
    /// stack started all at once would lose the first episode's first
    /// steps.
    pub fn wait_for_controller(&mut self) -> Result<(), StackError> {
        self.wait_for_controller_within(10)
    }

    /// Waits up to `limit_s` seconds until the controller publishes sensor
    /// frames (a robot's daemon may take its start-up time to connect).
    pub fn wait_for_controller_within(&mut self, limit_s: u64) -> Result<(), StackError> {
        let start = mono_now_ns();
        loop {
            if transport::drain(&self.sensor, |_| {})? > 0 {
                return Ok(());
            }
            if termination_requested() {
                return Err(StackError::Interrupted);
            }
            if mono_now_ns() - start > limit_s * 1_000_000_000 {
                return Err(StackError::ControllerNotStarted(limit_s));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Publishes an action (`apply_at_step` 0: as soon as it arrives).
    pub fn send_action(
        &mut self,
        episode: u64,
        t_hw_ns: u64,
        apply_at_step: u64,
        a: [f64; 4],
    ) -> Result<PolicyAction, StackError> {
        self.action_seq += 1;
        let mut m = PolicyAction::new(self.action_seq, mono_now_ns(), a);
        m.header.t_hw_ns = t_hw_ns;
        m.header.episode = episode;
        m.apply_at_step = apply_at_step;
        transport::send(&self.action, &m)?;
        Ok(m)
    }

    /// Where a new episode legitimately starts (the simulator has just put
    /// the arm at its start pose for `episode`): if the controller has a
    /// fault latched (Fault, or a silent hardware's), clears it with a
    /// reset command and returns the fault code cleared. A fault never
    /// clears by itself, an episode change included. Reads the first status
    /// published from now on (10 Hz); none within 2 s: nothing is done
    /// (no controller answers; the episode then reports its missing
    /// frames).
    pub fn clear_controller_fault(&mut self, episode: u64) -> Result<Option<u32>, StackError> {
        let since = mono_now_ns();
        let Some(status) = self.next_status(since, 2_000_000_000, |_| true)? else {
            return Ok(None);
        };
        let faulted = [ControllerMode::Fault, ControllerMode::HardwareLost]
            .map(|m| m as u32)
            .contains(&status.mode);
        if !faulted {
            return Ok(None);
        }
        // Resent under a fresh id until answered with anything but "the
        // hardware is silent": that fault clears only once states come again.
        let start = mono_now_ns();
        let mut last = 0;
        while mono_now_ns() - start < 10_000_000_000 {
            self.command_seq += 1;
            let seq = (u64::from(std::process::id()) << 32) | self.command_seq;
            let sent = mono_now_ns();
            let cmd = ControllerCommand::reset(seq, sent, episode);
            transport::send(&self.controller, &cmd)?;
            // Matched by id alone: the daemon stamps a status with the
            // start of its cycle, which may precede `sent`.
            if let Some(s) = self.next_status(0, 500_000_000, |s| s.command_seq == seq)? {
                if s.command_result != ControllerCommand::RESULT_HARDWARE_SILENT {
                    return Ok(Some(status.fault_code));
                }
                last = s.command_result;
                std::thread::sleep(Duration::from_millis(100));
            }
            if termination_requested() {
                return Err(StackError::Interrupted);
            }
        }
        Err(StackError::ControllerReset(ControllerCommand::result_name(
            last,
        )))
    }

    /// The first controller status published at or after `since_ns` that
    /// satisfies `pred`, waiting at most `timeout_ns`.
    fn next_status(
        &mut self,
        since_ns: u64,
        timeout_ns: u64,
        mut pred: impl FnMut(&ControllerStatus) -> bool,
    ) -> Result<Option<ControllerStatus>, StackError> {
        let start = mono_now_ns();
        loop {
            let mut hit = None;
            transport::drain(&self.status, |s| {
                if hit.is_none() && s.header.t_mono_ns >= since_ns && pred(s) {
                    hit = Some(*s);
                }
            })?;
            if hit.is_some() {
                return Ok(hit);
            }
            if mono_now_ns() - start > timeout_ns || termination_requested() {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_micros(500));
        }
    }

    /// Resets the simulator with `world` (TOML) and `seed` and waits for
    /// its answer; returns the report of the new episode. In lockstep it
    /// answers the old episode's pending action requests with zero actions
    /// meanwhile; the new episode's first request is the caller's.
    pub fn reset(
        &mut self,
        seed: u64,
        world: &str,
        lockstep: bool,
    ) -> Result<EpisodeReport, StackError> {
        // Request ids are unique across learner processes (pid, counter):
        // the simulator ignores a repeated id, so the request can be sent
        // again until answered (a simulator still starting misses it).
        self.command_seq += 1;
        let seq = (u64::from(std::process::id()) << 32) | self.command_seq;
        if world.len() > shared_mem_schema::MAX_CONFIG_BYTES {
            return Err(StackError::WorldTooLarge {
                bytes: world.len(),
                max: shared_mem_schema::MAX_CONFIG_BYTES,
            });
        }
        let send = |publisher: &Pub<SimCommand>| {
            transport::send_with(publisher, |c| {
                c.header = Header::new(seq, mono_now_ns(), 0, 0);
                c.command = SimCommand::RESET;
                c.seed = seed;
                c.config_len = world.len() as u32;
                c.config_toml[..world.len()].copy_from_slice(world.as_bytes());
            })
        };
        send(&self.command)?;
        let start = mono_now_ns();
        let mut resend_at = start + 500_000_000;
        loop {
            if mono_now_ns() > resend_at {
                send(&self.command)?;
                resend_at += 500_000_000;
            }
            // The frames keep coming meanwhile, the new episode's first
            // among them: kept for the log rather than left to overflow
            // the subscriber's buffer. A lockstep stack may be waiting on us
            // for an action: a pending request of the old episode gets a
            // zero action so that the simulator can move on to the reset.
            // Frames are drained before reports: the simulator answers the
            // reset before it steps the new episode, so when no answer
            // follows the frames, every request among them is the old
            // episode's; one of the new episode is left to the caller's
            // policy (answered with zeros, the episode's first action would
            // not be the policy's).
            let mut pending = None;
            let early = &mut self.early;
            transport::drain(&self.sensor, |f| {
                if lockstep && (f.step + 1).is_multiple_of(ACTION_PERIOD_STEPS) {
                    pending = Some((f.header.episode, f.header.t_hw_ns, f.step + 1));
                }
                if early.len() == EARLY_FRAMES {
                    early.pop_front();
                }
                early.push_back(*f);
            })?;
            let mut answer = None;
            transport::drain(&self.report, |r| {
                if r.command_seq == seq {
                    answer = Some(*r);
                }
            })?;
            if let Some((ep, t, step)) = pending
                && answer.is_none_or(|r| r.header.episode != ep)
            {
                self.send_action(ep, t, step, [0.0; 4])?;
            }
            if let Some(r) = answer {
                if r.command_result != EpisodeReport::OK {
                    return Err(StackError::ResetRefused(r.message_text()));
                }
                return Ok(r);
            }
            if termination_requested() {
                return Err(StackError::Interrupted);
            }
            if mono_now_ns() - start > 15_000_000_000 {
                return Err(StackError::NoResetAnswer);
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

/// 20 Hz of the hardware's clock (the frames' `t_hw_ns`): when a real-time
/// node's next action is due. Its episode's frames only: hw-sim's clock
/// starts again at a reset.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ActionPacer {
    /// Hardware time of the next action (None: the first frame's).
    next: Option<u64>,
}

impl ActionPacer {
    /// Whether an action is due on a frame of hardware time `t_hw`.
    pub(crate) fn due(&self, t_hw: u64) -> bool {
        self.next.is_none_or(|n| t_hw >= n)
    }

    /// An action was sent on a frame of hardware time `t_hw`: the next is
    /// on the 50 ms grid, or a period after `t_hw` after a hold-up (no
    /// burst to catch up).
    pub(crate) fn acted(&mut self, t_hw: u64) {
        self.next = Some(match self.next {
            Some(n) if n + ACTION_PERIOD_NS > t_hw => n + ACTION_PERIOD_NS,
            _ => t_hw + ACTION_PERIOD_NS,
        });
    }
}

/// The task as the policy needs it, from a simulator report.
pub fn task_geometry(r: &EpisodeReport, world: &WorldConfig) -> TaskGeometry {
    TaskGeometry {
        hole_pose: Isometry3::from_parts(
            Translation3::from(r.hole_pos_m),
            crate::policy::unit_quaternion(r.hole_quat_xyzw),
        ),
        symmetry: world.task.peg.symmetry_order(),
        depth_m: r.hole_depth_m,
    }
}

/// Runs `cfg.episodes` episodes with the heuristic policy; prints each
/// outcome as it ends and returns them all.
pub fn run(
    cfg: &LiveConfig,
    mut on_outcome: impl FnMut(&EpisodeOutcome),
) -> Result<Vec<EpisodeOutcome>, StackError> {
    transport::quiet_logs();
    let mut node = PolicyNode::open(&cfg.namespace)?;
    node.wait_for_controller()?;
    let mut outcomes = Vec::new();
    let progress = cfg.target_states.map(|t| Progress::new(t, "states"));
    let mut total_actions = 0u64;
    let mut rejected_before = 0;
    for i in 0..cfg.episodes {
        if termination_requested() || cfg.target_states.is_some_and(|t| total_actions >= t) {
            break;
        }
        let seed = cfg.seed + i as u64;
        let ep = LiveEpisode::start(&mut node, cfg, episode_world(cfg, i), seed)?;
        let done = outcomes.len() as u64;
        let outcome = ep.run(&mut node, cfg, &mut total_actions, |total| {
            if let Some(p) = &progress {
                p.update(total, format!("{done} episodes"));
            }
        })?;
        if let Some(p) = &cfg.policy {
            let rejected = p.rejected();
            if rejected > rejected_before {
                eprintln!(
                    "learner: episode {}: {} observations could not be encoded (no camera \
                     frame yet, or one of another size); the policy saw zeros for them",
                    outcome.episode,
                    rejected - rejected_before
                );
            }
            rejected_before = rejected;
        }
        on_outcome(&outcome);
        outcomes.push(outcome);
    }
    if let Some(p) = &progress {
        p.update(total_actions, format!("{} episodes", outcomes.len()));
        p.finish();
    }
    Ok(outcomes)
}

/// The world of episode `i`: the configured one, with the peg of its turn
/// when collecting over several.
fn episode_world(cfg: &LiveConfig, i: u32) -> WorldConfig {
    let mut world = cfg.world.clone();
    if !cfg.pegs.is_empty() {
        world.task.enabled = true;
        world.task.peg = cfg.pegs[i as usize % cfg.pegs.len()];
    }
    world
}

/// One live episode: its log, task, policy and what the node has seen.
struct LiveEpisode {
    seed: u64,
    episode: u64,
    first: EpisodeReport,
    log: LogWriter,
    task: TaskGeometry,
    mixed: Option<MixedPolicy>,
    heuristic: HeuristicPolicy,
    seen: Seen,
    /// Actions sent this episode.
    actions: u64,
    /// When the next action is due (real-time mode).
    pacer: ActionPacer,
    /// The frame step last acted on (lockstep mode).
    acted_for_step: u64,
    best_stage: Stage,
    /// Hardware time the peg completed the insertion.
    completed_at: Option<u64>,
    /// The wrench read at the first action after one policy period of the
    /// episode (free space: the sensor's bias and the peg's weight), as the
    /// RL environment takes it.
    free_wrench: Option<[f64; 6]>,
}

impl LiveEpisode {
    /// Resets the simulator with `world` and `seed`, opens the episode's
    /// log and records the configuration and the reset.
    fn start(
        node: &mut PolicyNode,
        cfg: &LiveConfig,
        world: WorldConfig,
        seed: u64,
    ) -> Result<Self, StackError> {
        let world_toml = toml::to_string(&world)?;
        let first = node.reset(seed, &world_toml, cfg.lockstep)?;
        let episode = first.header.episode;
        if let Some(code) = node.clear_controller_fault(episode)? {
            eprintln!(
                "learner: the controller had fault code {code} latched; reset for episode \
                 {episode}"
            );
        }
        let path = cfg
            .log_dir
            .join(format!("episode-{episode:04}-seed-{seed}.mcap"));
        let mut log = LogWriter::create_with(&path, cfg.log.clone())?;
        let task = task_geometry(&first, &world);
        let mixed = cfg.mix.as_ref().map(|m| MixedPolicy::new(m, seed));
        let policy = match (&cfg.policy, &mixed) {
            (Some(_), _) => EpisodePolicy::Learned,
            (None, Some(m)) => m.kind(),
            (None, None) => EpisodePolicy::Heuristic,
        };
        let mut config = RunConfig::new(RunMode::Live, world.clone(), policy, episode, seed);
        config.lockstep = Some(cfg.lockstep);
        config.namespace = Some(cfg.namespace.clone());
        log.config(first.header.t_hw_ns, &config)?;
        let hole = task.hole_pose;
        log.event(
            first.header.t_hw_ns,
            &Event::Reset(Box::new(Reset {
                episode,
                seed,
                peg: world.task.peg,
                policy,
                lockstep: Some(cfg.lockstep),
                world: Some(world.clone()),
                hole_pos_m: hole.translation.vector.into(),
                hole_quat_xyzw: hole.rotation.coords.into(),
                hole_depth_m: task.depth_m,
            })),
        )?;
        Ok(Self {
            seed,
            episode,
            first,
            log,
            task,
            mixed,
            heuristic: HeuristicPolicy::new(HeuristicConfig::default()),
            seen: Seen::new(
                Some(first),
                cfg.policy.as_ref().is_some_and(|p| p.needs_camera()),
            ),
            free_wrench: None,
            actions: 0,
            pacer: ActionPacer::default(),
            acted_for_step: u64::MAX,
            best_stage: Stage::Failed,
            completed_at: None,
        })
    }

    /// Acts until the episode ends (settled after completion, enough
    /// actions, its time-out, or a termination request), then records the
    /// outcome and closes the log. `total_actions` counts across episodes;
    /// `on_action` sees it after every action.
    fn run(
        mut self,
        node: &mut PolicyNode,
        cfg: &LiveConfig,
        total_actions: &mut u64,
        mut on_action: impl FnMut(u64),
    ) -> Result<EpisodeOutcome, StackError> {
        let t_end = loop {
            node.pump(self.episode, &mut self.seen, Some(&mut self.log))?;
            self.note_stage()?;
            let Some(frame) = self.seen.frame else {
                if mono_now_ns() - self.seen.last_frame_wall_ns > 10_000_000_000 {
                    return Err(StackError::NoSensorFrames);
                }
                std::thread::sleep(Duration::from_micros(200));
                continue;
            };
            if self.over(cfg, &frame, *total_actions) {
                break frame.header.t_hw_ns;
            }
            if mono_now_ns() - self.seen.last_frame_wall_ns > 2_000_000_000 {
                return Err(StackError::FramesStopped(self.episode));
            }
            if !self.due(cfg, &frame) {
                if cfg.lockstep {
                    std::thread::yield_now();
                } else {
                    std::thread::sleep(Duration::from_micros(500));
                }
                continue;
            }
            self.act(node, cfg, &frame)?;
            *total_actions += 1;
            on_action(*total_actions);
        };
        self.finish(t_end)
    }

    /// Logs a newly reached stage from the latest report.
    fn note_stage(&mut self) -> Result<(), StackError> {
        if let Some(r) = &self.seen.report
            && r.best_stage() > self.best_stage
        {
            self.best_stage = r.best_stage();
            self.log.event(
                r.header.t_hw_ns,
                &Event::Stage {
                    stage: self.best_stage,
                },
            )?;
            if self.best_stage == Stage::Completed && self.completed_at.is_none() {
                self.completed_at = Some(r.header.t_hw_ns);
            }
        }
        Ok(())
    }

    /// Whether the episode is over at `frame`. Collection runs its episodes
    /// to their length, or to the mix's `end_after_completion`; insertion
    /// episodes end once the peg has settled at the bottom.
    fn over(&self, cfg: &LiveConfig, frame: &SensorFrame, total_actions: u64) -> bool {
        let t = frame.header.t_hw_ns;
        let t_ep = hw_time_s(t.saturating_sub(self.first.header.t_hw_ns));
        let since_completed = self.completed_at.map(|c| t.saturating_sub(c));
        let rest_ns = match cfg.max_actions {
            None => Some((cfg.settle_s * 1e9) as u64),
            Some(_) => cfg
                .mix
                .as_ref()
                .and_then(|m| m.end_after_completion)
                .map(|n| (n as u64 + 1) * ACTION_PERIOD_NS),
        };
        let settled = since_completed
            .zip(rest_ns)
            .is_some_and(|(since, rest)| since >= rest);
        let enough = cfg.max_actions.is_some_and(|n| self.actions >= n as u64)
            || cfg.target_states.is_some_and(|n| total_actions >= n);
        settled || enough || t_ep >= cfg.episode_timeout_s || termination_requested()
    }

    /// Whether an action is due: in lockstep on the frame before each
    /// action step (once), in real time at 20 Hz of hardware time.
    fn due(&self, cfg: &LiveConfig, frame: &SensorFrame) -> bool {
        if cfg.lockstep {
            (frame.step + 1).is_multiple_of(ACTION_PERIOD_STEPS)
                && self.acted_for_step != frame.step
        } else {
            self.pacer.due(frame.header.t_hw_ns)
        }
    }

    /// Computes, sends and logs the policy's action on `frame`.
    fn act(
        &mut self,
        node: &mut PolicyNode,
        cfg: &LiveConfig,
        frame: &SensorFrame,
    ) -> Result<(), StackError> {
        let roll_ref = self.seen.roll_ref_rad.expect("set with the first frame");
        let obs = Observation::from_frame(frame, roll_ref);
        let a = if let Some(p) = &cfg.policy {
            self.learned(p, &obs, frame)
        } else {
            match self.mixed.as_mut() {
                Some(m) => m.act(&obs, &self.seen.wrench, &self.task),
                None => self.heuristic.act(&obs, &self.seen.wrench, &self.task),
            }
        };
        let apply_at = if cfg.lockstep { frame.step + 1 } else { 0 };
        let m = node.send_action(self.episode, frame.header.t_hw_ns, apply_at, a)?;
        self.log.action(&m)?;
        self.actions += 1;
        self.acted_for_step = frame.step;
        self.pacer.acted(frame.header.t_hw_ns);
        Ok(())
    }

    /// The trained policy's action on the state the node has seen: the
    /// view the RL environment gives it, from the frame, the wrench
    /// history, the simulator's latest report and the latest camera frame.
    fn learned(&mut self, p: &TrainedPolicy, obs: &Observation, frame: &SensorFrame) -> Action4 {
        // Fixed once the arm has rested a policy period, as the RL
        // environment takes it (real-time mode acts from the first frame).
        let free = match self.free_wrench {
            Some(w) => w,
            None => {
                if self.seen.frames >= ACTION_PERIOD_STEPS {
                    self.free_wrench = Some(frame.wrench);
                }
                frame.wrench
            }
        };
        let report = self.seen.report.unwrap_or(self.first);
        let task = task_state(&report);
        let view = ObsView {
            obs,
            wrench: &self.seen.wrench,
            free_wrench: &free,
            task: &task,
            hole_pose: &self.task.hole_pose,
            symmetry: self.task.symmetry,
            camera: self.seen.camera.as_deref(),
        };
        p.act(&view)
    }

    /// Records the outcome at hardware time `t_end` and closes the log.
    fn finish(self, t_end: u64) -> Result<EpisodeOutcome, StackError> {
        let duration_s = hw_time_s(t_end.saturating_sub(self.first.header.t_hw_ns));
        let mut log = self.log;
        log.event(
            t_end,
            &Event::Outcome(Outcome {
                stage: self.best_stage,
                duration_s: Some(duration_s),
                actions: Some(self.actions),
                states: None,
                interrupted: None,
            }),
        )?;
        let path = log.finish()?;
        Ok(EpisodeOutcome {
            episode: self.episode,
            seed: self.seed,
            stage: self.best_stage,
            interrupted: termination_requested() && self.completed_at.is_none(),
            duration_s,
            actions: self.actions,
            log: path,
            sensor_gaps: self.seen.gaps.gaps().clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actions_are_paced_by_the_hardware_clock() {
        const MS: u64 = 1_000_000;
        let mut p = ActionPacer::default();
        assert!(p.due(7 * MS), "the first frame acts");
        p.acted(7 * MS);
        // Wall time does not enter: only the frames' hardware time does.
        assert!(!p.due(56 * MS));
        assert!(p.due(57 * MS));
        // Acted 3 ms late: the grid is kept (107, not 110).
        p.acted(60 * MS);
        assert!(!p.due(106 * MS) && p.due(107 * MS));
        // Held up for 200 ms: one action, then a period later, no burst.
        p.acted(300 * MS);
        assert!(!p.due(301 * MS) && !p.due(349 * MS) && p.due(350 * MS));
    }
}
