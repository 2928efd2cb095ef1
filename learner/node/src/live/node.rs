//! The policy node's services ([`PolicyNode`]): what it reads from the
//! controller and the simulator, what it publishes, the reset handshake and
//! the clearing of a latched controller fault; what it has seen of an
//! episode ([`Seen`]) and when its next action is due ([`ActionPacer`]).

use super::NodeError;
use crate::log::LogWriter;
use crate::log::gaps::SensorGapCounter;
use crate::policy::WrenchHistory;
use crate::proprio::roll_reference;
use shared_mem_schema::process::{mono_now_ns, termination_requested};
use shared_mem_schema::rates::{ACTION_PERIOD_NS, ACTION_PERIOD_STEPS};
use shared_mem_schema::transport::{self, Pub, Sub};
use shared_mem_schema::{
    CameraFrame, ControllerCommand, ControllerMode, ControllerStatus, EpisodeReport, Header,
    Message, PolicyAction, SensorFrame, SimCommand,
};
use std::collections::VecDeque;
use std::time::Duration;

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
    pub(crate) camera: Option<Box<CameraFrame>>,
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
    pub fn open(ns: &str) -> Result<Self, NodeError> {
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
    ) -> Result<(), NodeError> {
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
    pub fn wait_for_controller(&mut self) -> Result<(), NodeError> {
        self.wait_for_controller_within(10)
    }

    /// Waits up to `limit_s` seconds until the controller publishes sensor
    /// frames (a robot's daemon may take its start-up time to connect).
    pub fn wait_for_controller_within(&mut self, limit_s: u64) -> Result<(), NodeError> {
        let start = mono_now_ns();
        loop {
            if transport::drain(&self.sensor, |_| {})? > 0 {
                return Ok(());
            }
            if termination_requested() {
                return Err(NodeError::Interrupted);
            }
            if mono_now_ns() - start > limit_s * 1_000_000_000 {
                return Err(NodeError::ControllerNotStarted(limit_s));
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
    ) -> Result<PolicyAction, NodeError> {
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
    pub fn clear_controller_fault(&mut self, episode: u64) -> Result<Option<u32>, NodeError> {
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
                return Err(NodeError::Interrupted);
            }
        }
        Err(NodeError::ControllerReset(ControllerCommand::result_name(
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
    ) -> Result<Option<ControllerStatus>, NodeError> {
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
    ) -> Result<EpisodeReport, NodeError> {
        // Request ids are unique across learner processes (pid, counter):
        // the simulator ignores a repeated id, so the request can be sent
        // again until answered (a simulator still starting misses it).
        self.command_seq += 1;
        let seq = (u64::from(std::process::id()) << 32) | self.command_seq;
        if world.len() > shared_mem_schema::MAX_CONFIG_BYTES {
            return Err(NodeError::WorldTooLarge {
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
                    return Err(NodeError::ResetRefused(r.message_text()));
                }
                return Ok(r);
            }
            if termination_requested() {
                return Err(NodeError::Interrupted);
            }
            if mono_now_ns() - start > 15_000_000_000 {
                return Err(NodeError::NoResetAnswer);
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
