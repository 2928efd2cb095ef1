//! The live policy node: subscribes to the controller's sensor frames, the
//! camera and the simulator's episode reports, acts at 20 Hz (the scripted
//! heuristic, the collection mix, or a trained policy with its encoder),
//! publishes the actions and logs every stream to MCAP, one file per
//! episode.
//!
//! Real-time mode acts on the newest frame every 50 ms of the hardware's
//! clock (the frames' `t_hw_ns`; `ActionPacer`, which [`crate::calibrated`]
//! uses too), as a deployed policy does. On a robot that clock is the wall clock;
//! hw-sim's and franky-sim's run slower than the wall clock when the machine
//! is loaded, and the policies act at 20 Hz of the arm's time, as they were
//! tuned and trained to. Lockstep mode answers each action request of a
//! lockstep simulator: on the frame of step 50m−1 it publishes the action
//! addressed to step 50m, so runs are deterministic.

mod episode;
mod node;

pub use node::PolicyNode;
pub(crate) use node::{ActionPacer, Seen};

use crate::deploy::DeployedPolicy;
use crate::log::{ChannelGaps, LogError, LogOptions};
use crate::mix::Mix;
use crate::policy::TaskGeometry;
use crate::progress::Progress;
use episode::LiveEpisode;
use hw_sim::{PegShape, WorldConfig};
use nalgebra::{Isometry3, Translation3};
use shared_mem_schema::process::termination_requested;
use shared_mem_schema::transport::{self, TransportError};
use shared_mem_schema::{EpisodeReport, Stage};
use std::path::PathBuf;
use std::sync::Arc;

/// Why the live node failed; names the episode or the peer at fault.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
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
    /// The simulator's answer to a reset carries a task geometry that
    /// cannot be (a hostile or broken peer); nothing of the episode is
    /// recorded or acted on.
    #[error("the simulator's reset report for episode {episode} is malformed: {problem}")]
    BadReport {
        /// The episode it reported.
        episode: u64,
        /// What is wrong ([`EpisodeReport::task_problem`]).
        problem: String,
    },
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
    /// No sensor frames arrived while waiting for the controller to start.
    #[error("no sensor frames from rt-controller within {0} s of waiting (is it running?)")]
    ControllerNotStarted(u64),
    /// The sensor frames stopped for 2 s during an episode.
    #[error("sensor frames stopped for 2 s in episode {0}")]
    FramesStopped(u64),
    /// The controller faulted during a run with a calibrated task (no
    /// simulator resets the arm, so the run stops there).
    #[error(
        "the controller faulted in episode {episode} (fault code {code}); see rt-controller.log"
    )]
    ControllerFault {
        /// The episode.
        episode: u64,
        /// The controller's fault code.
        code: u32,
    },
    /// A shared-memory service failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// An episode's log could not be written.
    #[error(transparent)]
    Log(#[from] LogError),
}

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
    /// A deployed policy acts instead of the heuristic (`--policy`).
    pub policy: Option<Arc<DeployedPolicy>>,
    /// Every episode's log is also served live here (`--foxglove-ws`).
    pub live_view: Option<Arc<crate::log::ws::Hub>>,
}

impl LiveConfig {
    /// The settings of `run` for `episodes` heuristic episodes.
    pub fn new(namespace: &str, world: WorldConfig, log_dir: PathBuf) -> Self {
        Self {
            namespace: namespace.to_string(),
            episodes: 1,
            seed: 1,
            world,
            episode_timeout_s: crate::cli::DEFAULT_EPISODE_TIMEOUT_S,
            log_dir,
            lockstep: false,
            settle_s: 0.3,
            mix: None,
            pegs: Vec::new(),
            max_actions: None,
            target_states: None,
            log: LogOptions::default(),
            policy: None,
            live_view: None,
        }
    }
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

/// The task as the policy needs it, from a simulator report.
pub fn task_geometry(r: &EpisodeReport, world: &WorldConfig) -> TaskGeometry {
    TaskGeometry {
        hole_pose: Isometry3::from_parts(
            Translation3::from(r.hole_pos_m),
            hw_sim::convert::unit_quaternion(r.hole_quat_xyzw),
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
) -> Result<Vec<EpisodeOutcome>, NodeError> {
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
                    "node: episode {}: {} observations could not be encoded (no camera \
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
