//! One live episode: the reset, its log, its policy's actions at 20 Hz and
//! its outcome.

use super::node::{ActionPacer, PolicyNode, Seen};
use super::{EpisodeOutcome, LiveConfig, NodeError, task_geometry};
use crate::deploy::DeployedPolicy;
use crate::log::LogWriter;
use crate::log::events::{EpisodeEnd, Event, Reset};
use crate::log::{RunConfig, RunMode};
use crate::mix::{EpisodePolicy, MixedPolicy};
use crate::observe::{ObsView, task_state};
use crate::policy::{Action4, HeuristicConfig, HeuristicPolicy, Observation, TaskGeometry};
use hw_sim::WorldConfig;
use shared_mem_schema::process::{mono_now_ns, termination_requested};
use shared_mem_schema::rates::{ACTION_PERIOD_NS, ACTION_PERIOD_STEPS};
use shared_mem_schema::{EpisodeReport, SensorFrame, Stage, hw_time_s};
use std::time::Duration;

/// One live episode: its log, task, policy and what the node has seen.
pub(super) struct LiveEpisode {
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
    pub(super) fn start(
        node: &mut PolicyNode,
        cfg: &LiveConfig,
        world: WorldConfig,
        seed: u64,
    ) -> Result<Self, NodeError> {
        let world_toml = toml::to_string(&world)?;
        let first = node.reset(seed, &world_toml, cfg.lockstep)?;
        let episode = first.header.episode;
        if let Some(problem) = world.task.enabled.then(|| first.task_problem()).flatten() {
            return Err(NodeError::BadReport { episode, problem });
        }
        if let Some(code) = node.clear_controller_fault(episode)? {
            eprintln!(
                "node: the controller had fault code {code} latched; reset for episode \
                 {episode}"
            );
        }
        let path = cfg
            .log_dir
            .join(format!("episode-{episode:04}-seed-{seed}.mcap"));
        let mut log = LogWriter::create_with(&path, cfg.log.clone())?;
        if let Some(hub) = &cfg.live_view {
            log.serve_live(hub.clone());
        }
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
    pub(super) fn run(
        mut self,
        node: &mut PolicyNode,
        cfg: &LiveConfig,
        total_actions: &mut u64,
        mut on_action: impl FnMut(u64),
    ) -> Result<EpisodeOutcome, NodeError> {
        let t_end = loop {
            node.pump(self.episode, &mut self.seen, Some(&mut self.log))?;
            self.note_stage()?;
            let Some(frame) = self.seen.frame else {
                if mono_now_ns() - self.seen.last_frame_wall_ns > 10_000_000_000 {
                    return Err(NodeError::NoSensorFrames);
                }
                std::thread::sleep(Duration::from_micros(200));
                continue;
            };
            if self.over(cfg, &frame, *total_actions) {
                break frame.header.t_hw_ns;
            }
            if mono_now_ns() - self.seen.last_frame_wall_ns > 2_000_000_000 {
                return Err(NodeError::FramesStopped(self.episode));
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
    fn note_stage(&mut self) -> Result<(), NodeError> {
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
    ) -> Result<(), NodeError> {
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
    fn learned(&mut self, p: &DeployedPolicy, obs: &Observation, frame: &SensorFrame) -> Action4 {
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
    fn finish(self, t_end: u64) -> Result<EpisodeOutcome, NodeError> {
        let duration_s = hw_time_s(t_end.saturating_sub(self.first.header.t_hw_ns));
        let mut log = self.log;
        log.event(
            t_end,
            &Event::Outcome(EpisodeEnd {
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
