//! The live policy node without a simulator's reports: the heuristic acts
//! on a task the user calibrated (where the hole is in the robot's base
//! frame), as on a robot. Used with franky-sim, the simulated FR3, which
//! has no peg, box, camera or episode resets (docs/franka.md, "The whole
//! stack on franky-sim").
//!
//! An episode starts wherever the arm is and ends when the tip reaches the
//! level of the calibrated hole's bottom (then rests `settle_s`), at its
//! time limit, or on a termination request. Nobody resets the arm: between
//! episodes the node drives the tip back to where the first episode
//! started. There is no stage and no insertion outcome (nothing judges
//! contact); what an episode reports is where the tip went against the
//! heuristic's goal, the hole's bottom centre.

use crate::live::NodeError;
use crate::live::{ActionPacer, PolicyNode, Seen};
use crate::log::events::{Event, Reset};
use crate::log::{ChannelGaps, LogOptions, LogWriter, RunConfig, RunMode};
use crate::mix::EpisodePolicy;
use crate::policy::{
    HeuristicConfig, HeuristicPolicy, Observation, TaskGeometry, relative_to_hole,
};
use hw_sim::{PegShape, WorldConfig};
use nalgebra::{Isometry3, Vector3};
use shared_mem_schema::process::{mono_now_ns, termination_requested};
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerMode, ControllerStatus, SensorFrame, hw_time_s};
use std::path::PathBuf;
use std::time::Duration;

/// Settings of a run on a calibrated task.
#[derive(Debug, Clone)]
pub struct CalibratedConfig {
    /// Service namespace.
    pub namespace: String,
    /// Episodes to run.
    pub episodes: u32,
    /// The task: the hole's pose (base frame), its symmetry and depth.
    pub task: TaskGeometry,
    /// The peg the symmetry is of (recorded in the logs).
    pub peg: PegShape,
    /// The daemon's robot description (recorded in the logs).
    pub robot: String,
    /// Episode time limit, s of the robot's time.
    pub episode_timeout_s: f64,
    /// Rest this long once the tip reached the bottom's level, s.
    pub settle_s: f64,
    /// How long to wait for the controller's first frame, s (a robot's
    /// daemon connects within its `startup_timeout_s`).
    pub controller_wait_s: u64,
    /// Where the MCAP logs go.
    pub log_dir: PathBuf,
    /// Log options.
    pub log: LogOptions,
    /// Every episode's log is also served live here (`--foxglove-ws`).
    pub live_view: Option<std::sync::Arc<crate::log::ws::Hub>>,
}

/// What one episode showed.
#[derive(Debug, Clone)]
pub struct CalibratedOutcome {
    /// Episode number, from 1.
    pub episode: u64,
    /// The tip reached the level of the hole's bottom (within the
    /// heuristic's `bottom_tol_m`).
    pub reached: bool,
    /// The run was interrupted during the episode.
    pub interrupted: bool,
    /// The robot's time from the first frame to the end, s.
    pub duration_s: f64,
    /// Actions sent.
    pub actions: u64,
    /// The tip at the first and the last frame (base frame), m.
    pub start_m: [f64; 3],
    /// See `start_m`.
    pub end_m: [f64; 3],
    /// The heuristic's goal: the hole's bottom centre (base frame), m.
    pub goal_m: [f64; 3],
    /// The episode's log.
    pub log: PathBuf,
    /// Gaps in its logged sensor frames.
    pub sensor_gaps: ChannelGaps,
}

impl CalibratedOutcome {
    /// The tip's end minus the goal, m.
    pub fn end_error_m(&self) -> Vector3<f64> {
        Vector3::from(self.end_m) - Vector3::from(self.goal_m)
    }

    /// How much closer to the goal the tip ended than it started, m.
    pub fn approached_m(&self) -> f64 {
        (Vector3::from(self.start_m) - Vector3::from(self.goal_m)).norm()
            - self.end_error_m().norm()
    }
}

/// A whole run: the episodes and the controller's last status.
#[derive(Debug, Clone)]
pub struct CalibratedRun {
    /// The episodes, in order.
    pub episodes: Vec<CalibratedOutcome>,
    /// The latest controller status seen (cycles, compute time).
    pub status: Option<ControllerStatus>,
}

/// Runs `cfg.episodes` heuristic episodes on the calibrated task; reports
/// each as it ends.
pub fn run(
    cfg: &CalibratedConfig,
    mut on_episode: impl FnMut(&CalibratedOutcome),
) -> Result<CalibratedRun, NodeError> {
    transport::quiet_logs();
    let mut node = PolicyNode::open(&cfg.namespace)?;
    node.wait_for_controller_within(cfg.controller_wait_s)?;
    let mut run = CalibratedRun {
        episodes: Vec::new(),
        status: None,
    };
    let mut home: Option<SensorFrame> = None;
    for n in 1..=u64::from(cfg.episodes) {
        if termination_requested() {
            break;
        }
        if let Some(h) = &home {
            return_to(&mut node, h, n, &mut run.status)?;
        }
        let (outcome, first) = episode(&mut node, cfg, n, &mut run.status)?;
        home.get_or_insert(first);
        on_episode(&outcome);
        run.episodes.push(outcome);
    }
    Ok(run)
}

/// One episode; returns its outcome and its first frame.
fn episode(
    node: &mut PolicyNode,
    cfg: &CalibratedConfig,
    n: u64,
    status: &mut Option<ControllerStatus>,
) -> Result<(CalibratedOutcome, SensorFrame), NodeError> {
    let first = newest_frame(node)?;
    // The controller's episode: a robot's daemon has one per process.
    let stream = first.header.episode;
    let path = cfg.log_dir.join(format!("episode-{n:04}.mcap"));
    let mut log = LogWriter::create_with(&path, cfg.log.clone())?;
    if let Some(hub) = &cfg.live_view {
        log.serve_live(hub.clone());
    }
    let mut world = WorldConfig {
        robot: cfg.robot.clone(),
        ..Default::default()
    };
    // No box, no peg: the simulator's task is off.
    world.task.enabled = false;
    world.task.peg = cfg.peg;
    let mut config = RunConfig::new(RunMode::Live, world, EpisodePolicy::Heuristic, n, 0);
    config.lockstep = Some(false);
    config.namespace = Some(cfg.namespace.clone());
    log.config(first.header.t_hw_ns, &config)?;
    let hole = cfg.task.hole_pose;
    log.event(
        first.header.t_hw_ns,
        &Event::Reset(Box::new(Reset {
            episode: n,
            seed: 0,
            peg: cfg.peg,
            policy: EpisodePolicy::Heuristic,
            lockstep: Some(false),
            // Nothing was reset: the hole is the calibration's.
            world: None,
            hole_pos_m: hole.translation.vector.into(),
            hole_quat_xyzw: hole.rotation.coords.into(),
            hole_depth_m: cfg.task.depth_m,
        })),
    )?;
    let heuristic_cfg = HeuristicConfig::default();
    let bottom_tol = heuristic_cfg.bottom_tol_m;
    let mut heuristic = HeuristicPolicy::new(heuristic_cfg);
    let mut seen = Seen::new(None, false);
    // The first frame was taken off the stream to start: log it too.
    node.push_early(first);
    let goal = hole * nalgebra::Point3::new(0.0, 0.0, -cfg.task.depth_m);
    let mut actions = 0u64;
    let mut pacer = ActionPacer::default();
    let mut reached_at: Option<u64> = None;
    let last = loop {
        node.pump(stream, &mut seen, Some(&mut log))?;
        if seen.status.is_some() {
            *status = seen.status;
        }
        let Some(frame) = seen.frame else {
            std::thread::sleep(Duration::from_micros(200));
            continue;
        };
        if frame.mode == ControllerMode::Fault as u32 {
            return Err(NodeError::ControllerFault {
                episode: n,
                code: frame.fault_code,
            });
        }
        let t = frame.header.t_hw_ns;
        let (s, _) = relative_to_hole(
            &Vector3::from(frame.ee_pos_m),
            &hw_sim::convert::unit_quaternion(frame.ee_quat_xyzw),
            &cfg.task,
        );
        if reached_at.is_none() && s.z < -(cfg.task.depth_m - bottom_tol) {
            reached_at = Some(t);
        }
        let settled = reached_at.is_some_and(|r| hw_time_s(t - r) >= cfg.settle_s);
        if settled
            || hw_time_s(t.saturating_sub(first.header.t_hw_ns)) >= cfg.episode_timeout_s
            || termination_requested()
        {
            break frame;
        }
        if mono_now_ns() - seen.last_frame_wall_ns > 2_000_000_000 {
            return Err(NodeError::FramesStopped(n));
        }
        // Once at the bottom's level the node stops acting: the heuristic
        // would press on for a contact force free space never gives, and
        // the controller holds the last target.
        if reached_at.is_some() || !pacer.due(t) {
            std::thread::sleep(Duration::from_micros(500));
            continue;
        }
        let roll_ref = seen.roll_ref_rad.expect("set with the first frame");
        let obs = Observation::from_frame(&frame, roll_ref);
        let a = heuristic.act(&obs, &seen.wrench, &cfg.task);
        let m = node.send_action(stream, t, 0, a)?;
        log.action(&m)?;
        actions += 1;
        pacer.acted(t);
    };
    let path = log.finish()?;
    let outcome = CalibratedOutcome {
        episode: n,
        reached: reached_at.is_some(),
        interrupted: termination_requested() && reached_at.is_none(),
        duration_s: hw_time_s(last.header.t_hw_ns.saturating_sub(first.header.t_hw_ns)),
        actions,
        start_m: first.ee_pos_m,
        end_m: last.ee_pos_m,
        goal_m: goal.coords.into(),
        log: path,
        sensor_gaps: seen.gaps.gaps().clone(),
    };
    Ok((outcome, first))
}

/// The newest sensor frame, waiting at most 10 s for one.
fn newest_frame(node: &mut PolicyNode) -> Result<SensorFrame, NodeError> {
    let start = mono_now_ns();
    loop {
        let mut newest = None;
        transport::drain(&node.sensor, |f| newest = Some(*f))?;
        if let Some(f) = newest {
            return Ok(f);
        }
        if termination_requested() {
            return Err(NodeError::Interrupted);
        }
        if mono_now_ns() - start > 10_000_000_000 {
            return Err(NodeError::NoSensorFrames);
        }
        std::thread::sleep(Duration::from_micros(500));
    }
}

/// Drives the tip back to `home`'s position and roll at 20 Hz (8 mm and
/// 0.05 rad per action at most), until within 2 mm and 0.02 rad, or 20 s:
/// what hw-sim's reset does on the simulator. Not logged, as a reset is
/// not; a fault is reported as episode `next`'s.
fn return_to(
    node: &mut PolicyNode,
    home: &SensorFrame,
    next: u64,
    status: &mut Option<ControllerStatus>,
) -> Result<(), NodeError> {
    // The home pose as a "hole" of symmetry 1, z up like a hole frame: the
    // home position, turned about the base's z by the tool's roll there.
    // (The tool's own frame, z down, would measure the roll with the
    // opposite sign, and the correction below would add to the error.)
    let home_x = hw_sim::convert::unit_quaternion(home.ee_quat_xyzw) * Vector3::x();
    let home_pose = Isometry3::from_parts(
        Vector3::from(home.ee_pos_m).into(),
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), home_x.y.atan2(home_x.x)),
    );
    let task = TaskGeometry {
        hole_pose: home_pose,
        symmetry: 1,
        depth_m: 0.0,
    };
    let start = mono_now_ns();
    let mut pacer = ActionPacer::default();
    loop {
        let frame = newest_frame(node)?;
        transport::drain(&node.status, |s| *status = Some(*s))?;
        if frame.mode == ControllerMode::Fault as u32 {
            return Err(NodeError::ControllerFault {
                episode: next,
                code: frame.fault_code,
            });
        }
        let (s, psi) = relative_to_hole(
            &Vector3::from(frame.ee_pos_m),
            &hw_sim::convert::unit_quaternion(frame.ee_quat_xyzw),
            &task,
        );
        if s.norm() < 0.002 && psi.abs() < 0.02 {
            return Ok(());
        }
        if termination_requested() {
            return Err(NodeError::Interrupted);
        }
        if mono_now_ns() - start > 20_000_000_000 {
            eprintln!(
                "node: the tip did not get back within 2 mm of the first episode's start in \
                 20 s ({:.1} mm off); the next episode starts where it is",
                s.norm() * 1e3
            );
            return Ok(());
        }
        if !pacer.due(frame.header.t_hw_ns) {
            continue;
        }
        let mut d = home_pose.rotation * -s;
        if d.norm() > 0.008 {
            d *= 0.008 / d.norm();
        }
        let roll = (-psi).clamp(-0.05, 0.05);
        node.send_action(
            frame.header.episode,
            frame.header.t_hw_ns,
            0,
            [d.x, d.y, d.z, roll],
        )?;
        pacer.acted(frame.header.t_hw_ns);
    }
}
