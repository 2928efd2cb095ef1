//! The daemon: the control cycle ([`rt_controller::cycle`]) between a hardware
//! backend and the learner-facing services, one cycle per call.

use crate::admission::RateGate;
use crate::backend::{Hardware, HardwareError};
use crate::config::{Clock, DaemonConfig};
use crate::queue::{ActionQueue, for_episode};
use crate::rt::pause_briefly;
use crate::shared::{FAULT_HARDWARE_SILENT, Shared};
use crate::stats::Stats;
use robot_model::Model;
use rt_controller::cycle::ControlCycle;
use rt_controller::supervisor::Supervisor;
use rt_controller::{ActionStatus, ConfigError};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport::{self, Pub, StackNode, Sub, TransportError};
use shared_mem_schema::{
    ControllerCommand, ControllerMode, ControllerStatus, HardwareState, Message, PolicyAction,
    SCHEMA_VERSION, SensorFrame, TorqueCommand,
};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Most action messages one cycle receives (the action queue's depth): a
/// flooding peer cannot stretch a cycle; the rest waits in the subscriber's
/// buffer, whose own overflow drops the oldest.
pub const MAX_ACTIONS_PER_CYCLE: usize = 16;
/// Most controller commands one cycle receives.
pub const MAX_COMMANDS_PER_CYCLE: usize = 4;

/// The largest step in sequence number from the newest action applied in
/// an episode to the next one admitted: a 20 Hz policy numbers its actions
/// one by one, and 1,000 is 50 s of them.
pub const MAX_SEQ_JUMP: u64 = 1000;

/// Why the daemon could not be built.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The controller configuration does not fit the robot.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A learner-facing service could not be opened.
    #[error(transparent)]
    Transport(#[from] TransportError),
}

/// What a cycle did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CycleOutcome {
    /// No hardware state yet.
    WaitingForHardware,
    /// No new state this cycle; nothing sent.
    Missed,
    /// Hardware silent past the timeout: Fault, no torques.
    HardwareLost,
    /// Torques sent.
    Sent,
}

/// The daemon: control cycle, hardware, services and statistics.
pub struct Daemon<H: Hardware> {
    pub(super) cfg: DaemonConfig,
    model: Model,
    /// The control law with its message plumbing.
    pub control: ControlCycle,
    pub(super) hw: H,
    actions: Sub<PolicyAction>,
    commands: Sub<ControllerCommand>,
    sensor_pub: Pub<SensorFrame>,
    status_pub: Pub<ControllerStatus>,
    queue: ActionQueue,
    state: HardwareState,
    have_state: bool,
    last_state_ns: u64,
    hardware_lost: bool,
    /// A robot error's fault code (0: none); it ends the run.
    robot_fault: u32,
    /// The fault code after the last cycle (0: none).
    last_fault_code: u32,
    /// Faults latched so far.
    faults_latched: u64,
    /// The highest sequence number of an action applied in any episode.
    top_seq: u64,
    /// Where the last action was applied: the rate and speed bounds.
    rate: RateGate,
    /// Resets counted at the last [`Self::count_latch`].
    resets_seen: u64,
    last_command: TorqueCommand,
    sensor: SensorFrame,
    status_seq: u64,
    next_status_ns: u64,
    command_seq: u64,
    command_result: u32,
    realtime: bool,
    /// Loop statistics.
    pub stats: Box<Stats>,
    /// Atomics for the monitor thread.
    pub shared: Arc<Shared>,
}

impl<H: Hardware> Daemon<H> {
    /// Builds the controller for `model` and opens the learner-facing
    /// services on `node`. All buffers are allocated here.
    pub fn new(
        cfg: DaemonConfig,
        model: Model,
        hw: H,
        node: &StackNode,
    ) -> Result<Self, DaemonError> {
        let control = ControlCycle::new(&model, cfg.controller.clone())?;
        let ns = &cfg.backend.namespace;
        let actions = transport::subscriber::<PolicyAction>(node, ns)?;
        let commands = transport::subscriber::<ControllerCommand>(node, ns)?;
        let sensor_pub = transport::publisher::<SensorFrame>(node, ns)?;
        let status_pub = transport::publisher::<ControllerStatus>(node, ns)?;
        let empty = HardwareState::empty(0);
        Ok(Self {
            cfg,
            control,
            hw,
            actions,
            commands,
            sensor_pub,
            status_pub,
            queue: ActionQueue::new(),
            state: empty,
            have_state: false,
            last_state_ns: 0,
            hardware_lost: false,
            robot_fault: 0,
            last_fault_code: 0,
            faults_latched: 0,
            top_seq: 0,
            rate: RateGate::default(),
            resets_seen: 0,
            last_command: TorqueCommand::empty(0),
            sensor: *SensorFrame::boxed_zeroed(),
            status_seq: 0,
            next_status_ns: 0,
            command_seq: 0,
            command_result: 0,
            realtime: false,
            stats: Box::new(Stats::EMPTY),
            shared: Arc::new(Shared::default()),
            model,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DaemonConfig {
        &self.cfg
    }

    /// The hardware backend.
    pub fn hardware(&self) -> &H {
        &self.hw
    }

    /// The robot model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Records whether the real-time set-up succeeded (reported in status).
    pub fn set_realtime(&mut self, ok: bool) {
        self.realtime = ok;
    }

    /// The mode as published.
    pub fn mode(&self) -> ControllerMode {
        if self.robot_fault != 0 {
            ControllerMode::Fault
        } else if self.hardware_lost {
            ControllerMode::HardwareLost
        } else {
            self.control.mode()
        }
    }

    /// The fault code as published.
    pub fn fault_code(&self) -> u32 {
        if self.robot_fault != 0 {
            self.robot_fault
        } else if self.hardware_lost {
            FAULT_HARDWARE_SILENT
        } else {
            self.control.fault_code()
        }
    }

    /// Polls the hardware once; true when a new state arrived. A state of a
    /// new episode (the robot was reset) restarts the control law unless a
    /// fault is latched. States keep being read while the hardware is
    /// counted lost (a reset needs a live hardware), but nothing is sent.
    pub fn poll_hardware(&mut self, now_ns: u64) -> Result<bool, HardwareError> {
        let nv = self.model.nv();
        let Some(s) = self.hw.poll()? else {
            return Ok(false);
        };
        if s.header.schema_version != SCHEMA_VERSION || s.n_joints as usize != nv {
            // Not usable: treat as silence (the timeout then faults).
            return Ok(false);
        }
        // While the hardware is counted lost any state is read (a restarted
        // hardware counts from its own start; a reset needs it live).
        let same_episode = Some(s.header.episode) == self.control.episode();
        if self.have_state
            && self.hardware_lost
            && !self.cfg.timing.lockstep_actions
            && same_episode
            && s.step == self.state.step
            && s.header.t_hw_ns == self.state.header.t_hw_ns
        {
            // Lost, and still frozen: not a live hardware a reset may trust
            // (in lockstep the simulator re-publishes while it waits for a
            // command, which a lost daemon does not send: that is live).
            self.stats.hardware_states_stale += 1;
            return Ok(false);
        }
        if self.have_state
            && !self.hardware_lost
            && same_episode
            && (s.step <= self.state.step || s.header.t_hw_ns <= self.state.header.t_hw_ns)
        {
            let repeat = s.step == self.state.step
                && s.header.t_hw_ns == self.state.header.t_hw_ns
                && self.cfg.timing.lockstep_actions
                && self.last_command.state_step == s.step
                && self.last_command.header.seq > 0;
            if repeat {
                // The same state again (a lockstep simulator re-publishes
                // while it waits): answer with the same command, do not
                // step again.
                self.last_state_ns = now_ns;
                let cmd = self.last_command;
                self.hw.send(&cmd)?;
            } else {
                // A state that does not advance (a frozen or replaying
                // hardware): not fresh, and the silence timer runs on.
                self.stats.hardware_states_stale += 1;
            }
            return Ok(false);
        }
        if self.have_state
            && s.header.episode == self.state.header.episode
            && s.step > self.state.step + 1
        {
            // The states between were superseded in the hardware's queue
            // before a cycle took them: their steps get no command and no
            // sensor frame.
            self.stats.hardware_states_skipped += s.step - self.state.step - 1;
        }
        self.state = *s;
        self.last_state_ns = now_ns;
        if self.control.observe_episode(&self.state) {
            self.restart_admission();
        }
        self.have_state = true;
        Ok(true)
    }

    /// Takes the queued action messages (at most [`MAX_ACTIONS_PER_CYCLE`])
    /// into the queue; garbage (another
    /// schema) is counted and dropped. The control law validates the
    /// values (NaN, out of range) itself. A failed receive is counted and
    /// the cycle goes on: without actions the control law holds.
    fn take_actions(&mut self) {
        let (queue, stats) = (&mut self.queue, &mut self.stats);
        let episode = self.control.episode();
        let t = &self.cfg.timing;
        let lockstep = t.clock == Clock::Hardware && t.lockstep_actions;
        let period = t.action_period_steps;
        // In lockstep the policy addresses the next boundary; one further
        // out would wait at the queue's front through every boundary.
        let horizon = self.state.step + 2 * period;
        let drained = transport::try_drain_at_most(&self.actions, MAX_ACTIONS_PER_CYCLE, |a| {
            stats.actions_received += 1;
            let at = a.apply_at_step;
            if a.header.schema_version != SCHEMA_VERSION {
                // Another schema's bytes.
                stats.actions_garbage += 1;
            } else if at != 0 && !(lockstep && at.is_multiple_of(period) && at <= horizon) {
                stats.actions_misaddressed += 1;
            } else if !for_episode(a, episode) {
                // Sent for the episode before a reset, arriving after it: in
                // lockstep it would sit at the queue's front, addressed to a
                // step of the old episode, and hold back the new one's.
                stats.actions_other_episode += 1;
            } else if queue.push(*a) {
                // A flood: the oldest queued action went, unread. Counted
                // apart from garbage, which says something about the values.
                stats.actions_overflow += 1;
            }
        });
        if drained.is_err() {
            self.stats.receive_errors += 1;
        }
    }

    /// Handles the controller commands that arrived (resets), at `now_ns`;
    /// `silent`: no hardware state within `hardware_timeout_ms`. A reset
    /// clears a latched Fault, or a silent hardware's fault once states
    /// come again (the control law then restarts at the state it sees: the
    /// arm may have been moved or braked meanwhile); it is refused while
    /// the hardware is silent. The answer goes out in a status published
    /// at once. Never allocates.
    fn take_commands(&mut self, now_ns: u64, silent: bool) {
        let mut last: Option<ControllerCommand> = None;
        let mut received = 0u64;
        // Several at once: the newest counts (each asks for the same reset).
        let drained = transport::try_drain_at_most(&self.commands, MAX_COMMANDS_PER_CYCLE, |c| {
            received += 1;
            last = Some(*c);
        });
        if drained.is_err() {
            self.stats.receive_errors += 1;
        }
        let Some(c) = last else {
            return;
        };
        self.stats.commands += received;
        if c.header.seq == self.command_seq {
            // A sender that missed the answer asks again: answer again.
            self.next_status_ns = now_ns;
            return;
        }
        let t_hw = self.state.header.t_hw_ns;
        let result =
            if c.header.schema_version != SCHEMA_VERSION || c.command != ControllerCommand::RESET {
                ControllerCommand::RESULT_UNKNOWN
            } else if self.hardware_lost {
                if silent || !self.have_state {
                    ControllerCommand::RESULT_HARDWARE_SILENT
                } else {
                    self.hardware_lost = false;
                    self.restart_admission();
                    self.control.restart(t_hw);
                    ControllerCommand::RESULT_CLEARED
                }
            } else if self.control.reset(t_hw) {
                self.restart_admission();
                ControllerCommand::RESULT_CLEARED
            } else {
                ControllerCommand::RESULT_NO_FAULT
            };
        if matches!(
            result,
            ControllerCommand::RESULT_HARDWARE_SILENT | ControllerCommand::RESULT_UNKNOWN
        ) {
            self.stats.commands_refused += 1;
        }
        self.command_seq = c.header.seq;
        self.command_result = result;
        self.shared
            .command_seq
            .store(c.header.seq, Ordering::Relaxed);
        self.shared.command_result.store(result, Ordering::Relaxed);
        // The sender waits for the answer: publish the status now.
        self.next_status_ns = now_ns;
    }

    /// Whether `a` may be applied to the current state: it must answer an
    /// observation of this episode (its `header.t_hw_ns`, a hardware time
    /// this daemon published in a sensor frame) made at most
    /// `timing.max_action_age_ms` ago on the hardware's clock, and be newer
    /// than the last action applied this episode by at most
    /// [`MAX_SEQ_JUMP`]. Stale ones are counted by reason.
    fn admit(&mut self, a: PolicyAction) -> Option<PolicyAction> {
        let now_hw = self.state.header.t_hw_ns;
        let max_age = (self.cfg.timing.max_action_age_ms * 1e6) as u64;
        let s = &mut self.stats;
        let counter = if a.header.episode != self.state.header.episode {
            &mut s.actions_other_episode
        } else if a.header.t_hw_ns > now_hw {
            &mut s.actions_from_future
        } else if now_hw - a.header.t_hw_ns > max_age {
            &mut s.actions_too_old
        } else if a.header.seq <= self.control.last_action_seq() {
            &mut s.actions_replayed
        } else if a
            .header
            .seq
            .saturating_sub(self.control.last_action_seq().max(self.top_seq))
            > MAX_SEQ_JUMP
            && (self.control.last_action_seq() > 0 || self.top_seq > 0)
        {
            // Past the newest applied this episode, or, for an episode's
            // first, past the newest applied in any (the policy numbers its
            // actions across episodes; a restarted one counts from 1 again,
            // which stays below).
            &mut s.actions_seq_jump
        } else {
            return Some(a);
        };
        *counter += 1;
        None
    }

    /// Lockstep: waits (bounded) for the action addressed to `step`.
    fn wait_for_addressed_action(&mut self, step: u64) {
        let limit = (self.cfg.timing.lockstep_action_timeout_s * 1e9) as u64;
        let start = mono_now_ns();
        let mut spins = 0u32;
        loop {
            self.take_actions();
            self.queue.drop_before(step);
            // Commands and the status are answered while waiting: a learner
            // that resets a fault before acting must not wait for this wait.
            let now = mono_now_ns();
            self.take_commands(now, false);
            if now >= self.next_status_ns {
                self.publish_status(now);
                self.next_status_ns = now + (self.cfg.timing.status_period_ms * 1e6) as u64;
            }
            if self.queue.front().is_some_and(|a| a.apply_at_step == step)
                || shared_mem_schema::process::termination_requested()
                || mono_now_ns() - start > limit
            {
                return;
            }
            spins += 1;
            if spins > 200 {
                pause_briefly();
            }
        }
    }

    /// One control cycle at `now_ns` (`CLOCK_MONOTONIC`), after the
    /// hardware was polled (`fresh`: a new state arrived). Never allocates.
    /// Only a failure to send the torques is an error: failed publications
    /// to the learner (sensor frame, status) and failed action receives are
    /// counted in [`Stats`] and the arm stays under control.
    pub fn cycle(&mut self, now_ns: u64, fresh: bool) -> Result<CycleOutcome, HardwareError> {
        self.stats.cycles += 1;
        self.shared
            .heartbeat
            .store(self.stats.cycles, Ordering::Relaxed);
        if !fresh {
            self.stats.hardware_misses += 1;
        }
        let outcome = self.control(now_ns, fresh)?;
        if now_ns >= self.next_status_ns {
            self.publish_status(now_ns);
            let period = (self.cfg.timing.status_period_ms * 1e6) as u64;
            self.next_status_ns = now_ns + period;
        }
        let mode = self.mode() as u32;
        self.shared.mode.store(mode, Ordering::Relaxed);
        let code = self.fault_code();
        self.shared.fault_code.store(code, Ordering::Relaxed);
        self.count_latch(code);
        self.shared
            .garbage_actions
            .store(self.garbage(), Ordering::Relaxed);
        self.shared
            .overflow_actions
            .store(self.stats.actions_overflow, Ordering::Relaxed);
        self.shared
            .skipped_states
            .store(self.stats.hardware_states_skipped, Ordering::Relaxed);
        let io_errors = self.stats.publish_errors + self.stats.receive_errors;
        self.shared
            .learner_io_errors
            .store(io_errors, Ordering::Relaxed);
        self.shared
            .stale_actions
            .store(self.stats.actions_stale(), Ordering::Relaxed);
        self.shared
            .commands_refused
            .store(self.stats.commands_refused, Ordering::Relaxed);
        Ok(outcome)
    }

    /// Forgets the queued actions and the last applied one's place: a new
    /// episode, a reset or a restarted hardware starts admission afresh.
    fn restart_admission(&mut self) {
        self.queue.clear();
        self.rate = RateGate::default();
    }

    fn garbage(&self) -> u64 {
        self.stats.actions_garbage
            + self.stats.actions_misaddressed
            + self.control.data.supervisor.counters.actions_rejected
    }

    fn control(&mut self, now_ns: u64, fresh: bool) -> Result<CycleOutcome, HardwareError> {
        let timeout_ns = (self.cfg.timing.hardware_timeout_ms * 1e6) as u64;
        let silent = now_ns.saturating_sub(self.last_state_ns) > timeout_ns;
        if self.have_state && silent {
            self.hardware_lost = true;
        }
        self.take_commands(now_ns, silent);
        if !self.have_state {
            self.take_actions();
            self.queue.clear();
            return Ok(CycleOutcome::WaitingForHardware);
        }
        if self.hardware_lost {
            // Latched until a reset command once the hardware streams
            // again (a restarted robot or simulator is no reason to move).
            self.take_actions();
            self.queue.clear();
            return Ok(CycleOutcome::HardwareLost);
        }
        if !fresh {
            return Ok(CycleOutcome::Missed);
        }
        let step = self.state.step;
        let t = &self.cfg.timing;
        if t.clock == Clock::Hardware
            && t.lockstep_actions
            && step > 0
            && step.is_multiple_of(t.action_period_steps)
        {
            self.wait_for_addressed_action(step);
        } else {
            self.take_actions();
        }
        let episode = self.state.header.episode;
        let timing = &self.cfg.timing;
        let min_interval = timing
            .min_action_interval_steps
            .min(timing.action_period_steps);
        let action = if self.rate.due(episode, step, min_interval) {
            self.queue.next_for(step).and_then(|a| self.admit(a))
        } else {
            None
        };
        let action = action.map(|mut a| {
            let traj = &self.cfg.controller.trajectory;
            let (m, r) = (traj.max_step_m, traj.max_step_rad);
            let period = self.cfg.timing.action_period_steps;
            let mut d = a.delta();
            // An invalid action is left whole, for the supervisor to refuse.
            let valid = Supervisor::check_action(&self.cfg.controller.safety, &d).is_ok();
            if valid && self.rate.bound(&mut d, (episode, step), period, m, r) {
                self.stats.actions_speed_cut += 1;
                a.delta_pos_m = [d[0], d[1], d[2]];
                a.delta_roll_rad = d[3];
            }
            a
        });
        let info = self.control.cycle(
            &self.model,
            &self.state,
            action.as_ref(),
            now_ns,
            &mut self.last_command,
            &mut self.sensor,
        );
        self.top_seq = self.top_seq.max(self.control.last_action_seq());
        if matches!(info.action, ActionStatus::Applied | ActionStatus::Clamped) {
            self.rate.applied(episode, step);
        }
        // Stamped at sending: the action latency includes the step.
        let sent = mono_now_ns();
        self.last_command.header.t_mono_ns = sent;
        self.hw.send(&self.last_command)?;
        if let Some(tau) = self.hw.sent_torques() {
            // What the backend made of the command (a copy, no allocation).
            let n = tau.len().min(self.sensor.tau_sent.len());
            self.sensor.tau_sent[..n].copy_from_slice(&tau[..n]);
        }
        // Silence counts from the command the hardware answers: a lockstep
        // wait for the policy's action above can be long, and the hardware
        // cannot step before it has the command.
        self.last_state_ns = self.last_state_ns.max(sent);
        if matches!(info.action, ActionStatus::Applied | ActionStatus::Clamped)
            && let Some(a) = &action
        {
            self.stats
                .action_latency
                .record(sent.saturating_sub(a.header.t_mono_ns));
        }
        self.sensor.header.t_mono_ns = mono_now_ns();
        // The learner's loss, not the arm's: counted, the loop goes on
        // (`try_send` builds no error text: no allocation when it fails).
        if transport::try_send(&self.sensor_pub, &self.sensor).is_err() {
            self.stats.publish_errors += 1;
        }
        Ok(CycleOutcome::Sent)
    }

    /// Publishes the status now (also called at ~10 Hz by [`Daemon::cycle`]).
    /// A failure is counted in [`Stats::publish_errors`], never fatal.
    pub fn publish_status(&mut self, now_ns: u64) {
        self.status_seq += 1;
        let c = self.control.data.supervisor.counters;
        let s = &self.stats;
        let header = shared_mem_schema::Header::new(
            self.status_seq,
            now_ns,
            self.state.header.t_hw_ns,
            self.control.episode().unwrap_or(0),
        );
        let (mode, fault, garbage) = (self.mode() as u32, self.fault_code(), self.garbage());
        let (last_action, realtime) = (self.control.last_action_seq(), self.realtime as u32);
        let (resets, command_seq, command_result) =
            (self.control.resets(), self.command_seq, self.command_result);
        let sent = transport::try_send_with(&self.status_pub, |m| {
            m.header = header;
            m.cycles = s.cycles;
            m.overruns = s.overruns;
            m.actions_received = s.actions_received;
            m.actions_accepted = c.actions_accepted;
            m.actions_rejected = garbage;
            m.actions_overflow = s.actions_overflow;
            m.actions_ignored = c.actions_ignored;
            m.action_timeouts = c.action_timeouts;
            m.faults = c.faults;
            m.hardware_misses = s.hardware_misses;
            m.hardware_states_skipped = s.hardware_states_skipped;
            m.last_action_seq = last_action;
            m.actions_too_old = s.actions_too_old;
            m.actions_from_future = s.actions_from_future;
            m.actions_other_episode = s.actions_other_episode;
            m.actions_replayed = s.actions_replayed;
            m.resets = resets;
            m.command_seq = command_seq;
            m.mode = mode;
            m.fault_code = fault;
            m.realtime = realtime;
            m.command_result = command_result;
            m.wakeup_latency = s.wakeup;
            m.compute = s.compute;
            m.action_latency = s.action_latency;
        });
        if sent.is_err() {
            self.stats.publish_errors += 1;
        }
    }

    /// Counts a fault latched since the last cycle for the monitor (the
    /// code before the count, so that a monitor that sees the count sees
    /// its code).
    fn count_latch(&mut self, code: u32) {
        // A reset and a fault again in one cycle is a latch too.
        let resets = self.control.resets();
        let reset_since = resets != self.resets_seen;
        self.resets_seen = resets;
        // Before the fault count: a monitor that sees a fault sees the
        // resets before it.
        self.shared.resets.store(resets, Ordering::Release);
        if code != 0 && (self.last_fault_code == 0 || reset_since) {
            self.faults_latched += 1;
            self.shared.latched_code.store(code, Ordering::Release);
            self.shared
                .faults_latched
                .store(self.faults_latched, Ordering::Release);
        }
        self.last_fault_code = code;
    }

    /// Latches a robot error's fault (`HardwareError::Robot`): published
    /// at once in the status and the shared atomics.
    pub fn latch_robot_fault(&mut self, code: u32, now_ns: u64) {
        self.robot_fault = code;
        self.count_latch(code);
        self.shared
            .mode
            .store(ControllerMode::Fault as u32, Ordering::Relaxed);
        self.shared.fault_code.store(code, Ordering::Relaxed);
        self.publish_status(now_ns);
    }

    /// Asks the control law to hold the current target (shutdown).
    pub fn request_hold(&mut self) {
        self.control.request_hold(&self.state);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SimBackend;
    use robot_model::descriptions::{IIWA14_HOME_Q, builtin};
    use shared_mem_schema::rates::CONTROL_PERIOD_NS;

    /// Holds every sample `publisher` will lend (iceoryx2 lends
    /// `publisher_max_loaned_samples`, 2 by default): its next publication
    /// fails with `ExceedsMaxLoans`, a real transport error.
    fn exhaust<T: Message>(publisher: &Pub<T>) -> Vec<impl Sized + use<T>> {
        let mut held = Vec::new();
        while let Ok(s) = publisher.loan_uninit() {
            held.push(s);
            assert!(held.len() < 64, "iceoryx2 kept lending");
        }
        held
    }

    #[test]
    fn failed_publications_to_the_learner_are_counted_and_the_torques_keep_going() {
        transport::quiet_logs();
        let ns = format!("pub-fail-{}", std::process::id());
        let mut cfg = DaemonConfig::default();
        cfg.backend.namespace = ns.clone();
        cfg.timing.clock = Clock::Hardware;
        cfg.realtime.enabled = false;
        let model = builtin("iiwa14").unwrap();
        let nv = model.nv();
        let peer = transport::create_node("pub-fail-peer").unwrap();
        let hw = transport::publisher::<HardwareState>(&peer, &ns).unwrap();
        let torques = transport::subscriber::<TorqueCommand>(&peer, &ns).unwrap();
        let sensor = transport::subscriber::<SensorFrame>(&peer, &ns).unwrap();
        let node = transport::create_node("pub-fail-daemon").unwrap();
        let backend = SimBackend::open(&node, &ns).unwrap();
        let mut daemon = Daemon::new(cfg, model, backend, &node).unwrap();
        let mut state = HardwareState::empty(nv);
        state.header.episode = 1;
        state.q[..nv].copy_from_slice(&IIWA14_HOME_Q);
        let mut run = |daemon: &mut Daemon<SimBackend>, k: u64| {
            state.header.seq = k + 1;
            state.header.t_hw_ns = k * CONTROL_PERIOD_NS;
            state.step = k;
            transport::send(&hw, &state).unwrap();
            let now = mono_now_ns();
            let fresh = daemon.poll_hardware(now).unwrap();
            assert!(fresh, "step {k}");
            let outcome = daemon
                .cycle(now, fresh)
                .expect("publication failures are not fatal");
            assert_eq!(outcome, CycleOutcome::Sent, "step {k}");
            let mut commands = 0;
            transport::drain(&torques, |c| {
                assert_eq!(c.state_step, k);
                assert!(c.tau[..nv].iter().all(|t| t.is_finite()));
                commands += 1;
            })
            .unwrap();
            assert_eq!(commands, 1, "step {k}: the hardware got its command");
        };

        let held_sensor = exhaust(&daemon.sensor_pub);
        let held_status = exhaust(&daemon.status_pub);
        for k in 0..20 {
            run(&mut daemon, k);
        }
        // 20 sensor frames and at least the first status.
        assert!(
            daemon.stats.publish_errors >= 21,
            "{}",
            daemon.stats.publish_errors
        );
        assert_eq!(daemon.mode(), ControllerMode::Idle);
        assert_eq!(daemon.control.fault_code(), 0);
        assert_eq!(
            daemon.shared.learner_io_errors.load(Ordering::Relaxed),
            daemon.stats.publish_errors
        );
        assert_eq!(transport::drain(&sensor, |_| {}).unwrap(), 0);

        // The loans back: publications work again, nothing more is counted.
        drop((held_sensor, held_status));
        let errors = daemon.stats.publish_errors;
        for k in 20..25 {
            run(&mut daemon, k);
        }
        assert_eq!(daemon.stats.publish_errors, errors);
        assert_eq!(transport::drain(&sensor, |_| {}).unwrap(), 5);
        daemon.publish_status(mono_now_ns());
        assert_eq!(daemon.stats.publish_errors, errors);
    }
}
