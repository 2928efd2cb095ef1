//! The daemon around the control step: hardware backends, the 1 kHz loop,
//! actions, sensor frames, status and timing statistics.
//!
//! One cycle: read the hardware state → take the next action without
//! waiting → control step → send torques → publish the sensor frame (and,
//! every `status_period_ms`, the status). Nothing in a cycle locks or
//! blocks, and our code allocates nothing; iceoryx2 0.10 itself takes one
//! small block per publication, freed at send (tests/daemon_alloc.rs pins
//! that down exactly), and clarabel a fixed set per solve. The daemon serves
//! those from lock-free static pools ([`rt_alloc`]), so the loop never
//! reaches the heap (tests/daemon_rt_alloc.rs).
//!
//! Transport choices: every input is *polled* (an iceoryx2 `receive` costs
//! about 1 µs) rather than waited on with an event listener, whose wake-up
//! costs 55–110 µs here: the loop already wakes on its own deadline, and in
//! hardware-clocked mode a spin-then-yield poll reacts in microseconds.
//! Outputs are plain publications, which never wait for subscribers.

pub mod config;
pub mod rt;
pub mod rt_alloc;

use crate::{ActionStatus, Controller, ControllerData, FaultReason, Mode, RobotState};
use config::{Clock, DaemonConfig};
use robot_model::Model;
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport::{self, Pub, StackNode, Sub, TransportError};
use shared_mem_schema::{
    ControllerMode, ControllerStatus, HardwareState, Header, LatencyHistogram, MAX_JOINTS,
    PolicyAction, SCHEMA_VERSION, SensorFrame, TorqueCommand, hw_time_s,
};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// A hardware interface failure.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct HardwareError(pub String);

impl From<TransportError> for HardwareError {
    fn from(e: TransportError) -> Self {
        Self(e.to_string())
    }
}

/// What the daemon needs of a robot. Implementations never block.
pub trait Hardware {
    /// Short name for logs.
    fn name(&self) -> &'static str;
    /// The newest state since the last call, or `None` when nothing new
    /// arrived.
    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError>;
    /// Sends a torque command.
    fn send(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError>;
}

/// hw-sim over shared memory.
pub struct SimBackend {
    states: Sub<HardwareState>,
    commands: Pub<TorqueCommand>,
    latest: HardwareState,
}

impl SimBackend {
    /// Opens the hardware services of `namespace` on `node`.
    pub fn open(node: &StackNode, namespace: &str) -> Result<Self, TransportError> {
        Ok(Self {
            states: transport::subscriber(node, namespace)?,
            commands: transport::publisher(node, namespace)?,
            latest: empty_state(),
        })
    }
}

fn empty_state() -> HardwareState {
    HardwareState {
        header: Header::default(),
        step: 0,
        applied_command_seq: 0,
        n_joints: 0,
        reserved: 0,
        q: [0.0; MAX_JOINTS],
        v: [0.0; MAX_JOINTS],
        tau_measured: [0.0; MAX_JOINTS],
        wrench: [0.0; 6],
    }
}

impl Hardware for SimBackend {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError> {
        let mut got = false;
        let latest = &mut self.latest;
        transport::drain(&self.states, |s| {
            if !got || s.header.seq > latest.header.seq || s.header.episode != latest.header.episode
            {
                *latest = *s;
            }
            got = true;
        })?;
        Ok(got.then_some(&self.latest))
    }

    fn send(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError> {
        Ok(transport::send(&self.commands, cmd)?)
    }
}

/// Fixed-capacity FIFO of actions (no allocation after construction).
struct ActionQueue {
    items: [Option<PolicyAction>; 16],
    head: usize,
    len: usize,
}

impl ActionQueue {
    fn new() -> Self {
        Self {
            items: [None; 16],
            head: 0,
            len: 0,
        }
    }

    /// Appends; when full the oldest is dropped (returns true then).
    fn push(&mut self, a: PolicyAction) -> bool {
        let cap = self.items.len();
        let dropped = self.len == cap;
        if dropped {
            self.head = (self.head + 1) % cap;
            self.len -= 1;
        }
        self.items[(self.head + self.len) % cap] = Some(a);
        self.len += 1;
        dropped
    }

    fn front(&self) -> Option<&PolicyAction> {
        (self.len > 0)
            .then(|| self.items[self.head].as_ref())
            .flatten()
    }

    fn pop(&mut self) -> Option<PolicyAction> {
        if self.len == 0 {
            return None;
        }
        let a = self.items[self.head].take();
        self.head = (self.head + 1) % self.items.len();
        self.len -= 1;
        a
    }

    fn clear(&mut self) {
        while self.pop().is_some() {}
    }
}

/// State the loop shares with its low-priority monitor thread (logging,
/// systemd watchdog) through atomics only.
#[derive(Debug, Default)]
pub struct Shared {
    /// Cycles run (the watchdog is fed only while it advances).
    pub heartbeat: AtomicU64,
    /// [`ControllerMode`] as u32.
    pub mode: AtomicU32,
    /// Fault code (see [`fault_code`]).
    pub fault_code: AtomicU32,
    /// Garbage actions counted so far.
    pub garbage_actions: AtomicU64,
    /// Overruns so far.
    pub overruns: AtomicU64,
}

/// Fault code carried in the status: 0 none, 1 non-finite state, 2 joint
/// position limit, 3 joint velocity limit, 4 force overload, 5 moment
/// overload, 6 dynamics failure, 7 non-finite torque, 100 hardware silent.
pub fn fault_code(reason: Option<FaultReason>) -> u32 {
    match reason {
        None => 0,
        Some(FaultReason::NonFiniteState) => 1,
        Some(FaultReason::JointPositionLimit { .. }) => 2,
        Some(FaultReason::JointVelocityLimit { .. }) => 3,
        Some(FaultReason::ForceOverload { .. }) => 4,
        Some(FaultReason::MomentOverload { .. }) => 5,
        Some(FaultReason::DynamicsFailure) => 6,
        Some(FaultReason::NonFiniteTorque) => 7,
    }
}

/// Fault code of a silent hardware.
pub const FAULT_HARDWARE_SILENT: u32 = 100;

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

/// Statistics of the loop (cumulative since start).
pub struct Stats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles that finished after their next deadline.
    pub overruns: u64,
    /// Cycles without a new hardware state.
    pub hardware_misses: u64,
    /// Actions received.
    pub actions_received: u64,
    /// Actions refused before the control law saw them (wrong schema
    /// version, queue overflow).
    pub actions_garbage: u64,
    /// Wake-up latency past the deadline.
    pub wakeup: LatencyHistogram,
    /// Compute time per cycle.
    pub compute: LatencyHistogram,
    /// Action publication → first torque reflecting it.
    pub action_latency: LatencyHistogram,
}

/// The daemon: controller, hardware, services and statistics.
pub struct Daemon<H: Hardware> {
    cfg: DaemonConfig,
    model: Model,
    ctrl: Controller,
    /// The control law's workspace.
    pub data: ControllerData,
    hw: H,
    actions: Sub<PolicyAction>,
    sensor_pub: Pub<SensorFrame>,
    status_pub: Pub<ControllerStatus>,
    queue: ActionQueue,
    state: HardwareState,
    have_state: bool,
    last_state_ns: u64,
    episode: u64,
    hardware_lost: bool,
    q: Vec<f64>,
    v: Vec<f64>,
    tau_meas: Vec<f64>,
    torque_seq: u64,
    last_command: TorqueCommand,
    sensor_seq: u64,
    status_seq: u64,
    next_status_ns: u64,
    last_action_seq: u64,
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
    ) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        if model.nv() > MAX_JOINTS {
            return Err(format!(
                "the robot has {} joints, messages carry at most {MAX_JOINTS}",
                model.nv()
            )
            .into());
        }
        let ctrl = Controller::new(&model, cfg.controller.clone())?;
        let data = ctrl.create_data(&model);
        let ns = &cfg.backend.namespace;
        let actions = transport::subscriber::<PolicyAction>(node, ns)?;
        let sensor_pub = transport::publisher::<SensorFrame>(node, ns)?;
        let status_pub = transport::publisher::<ControllerStatus>(node, ns)?;
        let nv = model.nv();
        Ok(Self {
            cfg,
            ctrl,
            data,
            hw,
            actions,
            sensor_pub,
            status_pub,
            queue: ActionQueue::new(),
            state: empty_state(),
            have_state: false,
            last_state_ns: 0,
            episode: 0,
            hardware_lost: false,
            q: vec![0.0; nv],
            v: vec![0.0; nv],
            tau_meas: vec![0.0; nv],
            torque_seq: 0,
            last_command: TorqueCommand {
                header: Header::default(),
                state_step: 0,
                action_seq: 0,
                n_joints: 0,
                reserved: 0,
                tau: [0.0; MAX_JOINTS],
            },
            sensor_seq: 0,
            status_seq: 0,
            next_status_ns: 0,
            last_action_seq: 0,
            realtime: false,
            stats: Box::new(Stats {
                cycles: 0,
                overruns: 0,
                hardware_misses: 0,
                actions_received: 0,
                actions_garbage: 0,
                wakeup: LatencyHistogram::EMPTY,
                compute: LatencyHistogram::EMPTY,
                action_latency: LatencyHistogram::EMPTY,
            }),
            shared: Arc::new(Shared::default()),
            model,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DaemonConfig {
        &self.cfg
    }

    /// The robot model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Records whether the real-time set-up succeeded (reported in status).
    pub fn set_realtime(&mut self, ok: bool) {
        self.realtime = ok;
    }

    /// The last hardware state received, if any.
    pub fn hardware_state(&self) -> Option<&HardwareState> {
        self.have_state.then_some(&self.state)
    }

    /// The mode as published.
    pub fn mode(&self) -> ControllerMode {
        if self.hardware_lost {
            return ControllerMode::HardwareLost;
        }
        match self.data.mode() {
            Mode::Idle => ControllerMode::Idle,
            Mode::Running => ControllerMode::Running,
            Mode::Holding => ControllerMode::Holding,
            Mode::Fault => ControllerMode::Fault,
        }
    }

    fn fault_code(&self) -> u32 {
        if self.hardware_lost {
            FAULT_HARDWARE_SILENT
        } else {
            fault_code(self.data.supervisor.fault())
        }
    }

    /// Polls the hardware once; true when a new state arrived. A state of a
    /// new episode (the robot was reset) restarts the control law.
    pub fn poll_hardware(&mut self, now_ns: u64) -> Result<bool, HardwareError> {
        let nv = self.model.nv();
        let Some(s) = self.hw.poll()? else {
            return Ok(false);
        };
        if s.header.schema_version != SCHEMA_VERSION || s.n_joints as usize != nv {
            // Not usable: treat as silence (the timeout then faults).
            return Ok(false);
        }
        if self.have_state
            && s.header.episode == self.episode
            && s.step == self.state.step
            && self.last_command.state_step == s.step
            && self.torque_seq > 0
        {
            // The same state again (a lockstep simulator re-publishes while
            // it waits): answer with the same command, do not step again.
            self.last_state_ns = now_ns;
            let cmd = self.last_command;
            self.hw.send(&cmd)?;
            return Ok(false);
        }
        self.state = *s;
        self.last_state_ns = now_ns;
        let t = hw_time_s(self.state.header.t_hw_ns);
        if !self.have_state || self.state.header.episode != self.episode {
            if self.have_state {
                self.data.restart(t);
                self.queue.clear();
            }
            self.episode = self.state.header.episode;
            self.hardware_lost = false;
        }
        self.have_state = true;
        Ok(true)
    }

    /// Takes every queued action message into the queue; garbage (another
    /// schema) is counted and dropped. The control law validates the
    /// values (NaN, out of range) itself.
    fn take_actions(&mut self) -> Result<(), HardwareError> {
        let (queue, stats) = (&mut self.queue, &mut self.stats);
        transport::drain(&self.actions, |a| {
            stats.actions_received += 1;
            // Another schema's bytes, or the oldest of an overflowing queue.
            if a.header.schema_version != SCHEMA_VERSION || queue.push(*a) {
                stats.actions_garbage += 1;
            }
        })?;
        Ok(())
    }

    /// Lockstep: waits (bounded) for the action addressed to `step`.
    fn wait_for_addressed_action(&mut self, step: u64) -> Result<(), HardwareError> {
        let limit = (self.cfg.timing.lockstep_action_timeout_s * 1e9) as u64;
        let start = mono_now_ns();
        let mut spins = 0u32;
        loop {
            self.take_actions()?;
            // Drop actions addressed to steps already past.
            while self
                .queue
                .front()
                .is_some_and(|a| a.apply_at_step != 0 && a.apply_at_step < step)
            {
                self.queue.pop();
            }
            if self.queue.front().is_some_and(|a| a.apply_at_step == step)
                || shared_mem_schema::process::termination_requested()
                || mono_now_ns() - start > limit
            {
                return Ok(());
            }
            spins += 1;
            if spins > 200 {
                std::thread::yield_now();
            }
        }
    }

    /// The next action for hardware step `step`: actions addressed to a
    /// later step wait for it.
    fn next_action(&mut self, step: u64) -> Option<PolicyAction> {
        match self.queue.front() {
            Some(a) if a.apply_at_step == 0 || a.apply_at_step <= step => self.queue.pop(),
            _ => None,
        }
    }

    /// One control cycle at `now_ns` (`CLOCK_MONOTONIC`), after the
    /// hardware was polled (`fresh`: a new state arrived). Never allocates.
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
            self.publish_status(now_ns)?;
            let period = (self.cfg.timing.status_period_ms * 1e6) as u64;
            self.next_status_ns = now_ns + period;
        }
        let mode = self.mode() as u32;
        self.shared.mode.store(mode, Ordering::Relaxed);
        self.shared
            .fault_code
            .store(self.fault_code(), Ordering::Relaxed);
        self.shared
            .garbage_actions
            .store(self.garbage(), Ordering::Relaxed);
        Ok(outcome)
    }

    fn garbage(&self) -> u64 {
        self.stats.actions_garbage + self.data.supervisor.counters.actions_rejected
    }

    fn control(&mut self, now_ns: u64, fresh: bool) -> Result<CycleOutcome, HardwareError> {
        if !self.have_state {
            self.take_actions()?;
            self.queue.clear();
            return Ok(CycleOutcome::WaitingForHardware);
        }
        let timeout_ns = (self.cfg.timing.hardware_timeout_ms * 1e6) as u64;
        if now_ns.saturating_sub(self.last_state_ns) > timeout_ns {
            self.hardware_lost = true;
        }
        if self.hardware_lost {
            // Latched until the hardware comes back with a new episode.
            self.take_actions()?;
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
            self.wait_for_addressed_action(step)?;
        } else {
            self.take_actions()?;
        }
        let action = self.next_action(step);
        let nv = self.model.nv();
        self.q.copy_from_slice(&self.state.q[..nv]);
        self.v.copy_from_slice(&self.state.v[..nv]);
        self.tau_meas
            .copy_from_slice(&self.state.tau_measured[..nv]);
        let wrench = self.state.wrench;
        let t_s = hw_time_s(self.state.header.t_hw_ns);
        let core_action = action.map(|a| crate::Action {
            delta_pos_m: a.delta_pos_m,
            delta_roll_rad: a.delta_roll_rad,
        });
        let info = crate::step(
            &self.model,
            &self.ctrl,
            &mut self.data,
            &RobotState {
                q: &self.q,
                v: &self.v,
                tau_measured: Some(&self.tau_meas),
                wrench: Some(&wrench),
            },
            core_action.as_ref(),
            t_s,
        );
        let applied = matches!(info.action, ActionStatus::Applied | ActionStatus::Clamped);
        if applied && let Some(a) = &action {
            self.last_action_seq = a.header.seq;
        }
        self.torque_seq += 1;
        let header = Header::new(
            self.torque_seq,
            mono_now_ns(),
            self.state.header.t_hw_ns,
            self.episode,
        );
        let mut cmd = TorqueCommand {
            header,
            state_step: step,
            action_seq: self.last_action_seq,
            n_joints: nv as u32,
            reserved: 0,
            tau: [0.0; MAX_JOINTS],
        };
        cmd.tau[..nv].copy_from_slice(self.data.torques());
        self.hw.send(&cmd)?;
        self.last_command = cmd;
        if applied && let Some(a) = &action {
            let sent = cmd.header.t_mono_ns;
            self.stats
                .action_latency
                .record(sent.saturating_sub(a.header.t_mono_ns));
        }
        self.publish_sensor(&cmd)?;
        Ok(CycleOutcome::Sent)
    }

    fn publish_sensor(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError> {
        let nv = self.model.nv();
        self.sensor_seq += 1;
        let ee = &self.data.ee;
        let rot = nalgebra::Rotation3::from_matrix_unchecked(ee.rot);
        let quat = nalgebra::UnitQuaternion::from_rotation_matrix(&rot);
        let mut f = SensorFrame {
            header: Header::new(
                self.sensor_seq,
                mono_now_ns(),
                self.state.header.t_hw_ns,
                self.episode,
            ),
            step: self.state.step,
            action_seq: self.last_action_seq,
            n_joints: nv as u32,
            mode: self.mode() as u32,
            q: self.state.q,
            v: self.state.v,
            tau_cmd: cmd.tau,
            tau_measured: self.state.tau_measured,
            ee_pos_m: [ee.pos.x, ee.pos.y, ee.pos.z],
            ee_quat_xyzw: [quat.i, quat.j, quat.k, quat.w],
            ee_twist: [0.0; 6],
            wrench: self.state.wrench,
        };
        f.ee_twist.copy_from_slice(ee.twist.as_slice());
        Ok(transport::send(&self.sensor_pub, &f)?)
    }

    /// Publishes the status now (also called at ~10 Hz by [`Daemon::cycle`]).
    pub fn publish_status(&mut self, now_ns: u64) -> Result<(), HardwareError> {
        self.status_seq += 1;
        let c = self.data.supervisor.counters;
        let s = &self.stats;
        let header = Header::new(
            self.status_seq,
            now_ns,
            self.state.header.t_hw_ns,
            self.episode,
        );
        let (mode, fault, garbage) = (self.mode() as u32, self.fault_code(), self.garbage());
        let (last_action, realtime) = (self.last_action_seq, self.realtime as u32);
        transport::send_with(&self.status_pub, |m| {
            m.header = header;
            m.cycles = s.cycles;
            m.overruns = s.overruns;
            m.actions_received = s.actions_received;
            m.actions_accepted = c.actions_accepted;
            m.actions_rejected = garbage;
            m.actions_ignored = c.actions_ignored;
            m.action_timeouts = c.action_timeouts;
            m.faults = c.faults;
            m.hardware_misses = s.hardware_misses;
            m.last_action_seq = last_action;
            m.mode = mode;
            m.fault_code = fault;
            m.realtime = realtime;
            m.wakeup_latency = s.wakeup;
            m.compute = s.compute;
            m.action_latency = s.action_latency;
        })?;
        Ok(())
    }

    /// Asks the control law to hold the current target (shutdown).
    pub fn request_hold(&mut self) {
        let t = hw_time_s(self.state.header.t_hw_ns);
        self.data.supervisor.request_hold(t);
    }

    /// Runs the loop until `stop()` returns true; then holds for
    /// `timing.shutdown_hold_s` and returns. `on_ready` runs once the first
    /// hardware state is in (systemd's READY).
    pub fn run(
        &mut self,
        mut stop: impl FnMut() -> bool,
        on_ready: impl FnOnce(),
    ) -> Result<RunSummary, HardwareError> {
        let timing = self.cfg.timing.clone();
        let period_ns = (self.cfg.controller.period_s * 1e9).round() as u64;
        // Start-up: wait for the hardware (not real-time yet).
        let start = mono_now_ns();
        loop {
            let now = mono_now_ns();
            if self.poll_hardware(now)? {
                break;
            }
            if stop() {
                return Ok(RunSummary::default());
            }
            if now - start > (timing.startup_timeout_s * 1e9) as u64 {
                return Err(HardwareError(format!(
                    "no hardware state from the {} backend within {} s (is hw-sim running in \
                     namespace '{}'?)",
                    self.hw.name(),
                    timing.startup_timeout_s,
                    self.cfg.backend.namespace
                )));
            }
            std::thread::sleep(std::time::Duration::from_micros(500));
        }
        on_ready();
        // From here on the loop's small allocations (iceoryx2's, clarabel's)
        // come from the real-time pools when the binary installs
        // `rt_alloc::RtAllocator`.
        rt_alloc::enter_realtime();
        let mut stopping_until: Option<u64> = None;
        let mut deadline = mono_now_ns();
        let mut fresh = true; // the state of the start-up poll
        loop {
            if stopping_until.is_none() && stop() {
                self.request_hold();
                stopping_until = Some(mono_now_ns() + (timing.shutdown_hold_s * 1e9) as u64);
            }
            if let Some(until) = stopping_until
                && mono_now_ns() >= until
            {
                break;
            }
            let woke = match timing.clock {
                Clock::Wall => {
                    shared_mem_schema::process::sleep_until_ns(deadline);
                    let now = mono_now_ns();
                    self.stats.wakeup.record(now.saturating_sub(deadline));
                    fresh |= self.poll_hardware(now)?;
                    now
                }
                Clock::Hardware => {
                    let wait_start = mono_now_ns();
                    let mut spins = 0u32;
                    let mut now = wait_start;
                    while !fresh {
                        now = mono_now_ns();
                        fresh = self.poll_hardware(now)?;
                        // Stop waiting on a stop request, or when the
                        // shutdown hold is over; keep waiting during it.
                        let stopping = match stopping_until {
                            Some(until) => now >= until,
                            None => stop(),
                        };
                        if fresh
                            || now - wait_start > (timing.hardware_timeout_ms * 1e6) as u64
                            || stopping
                        {
                            break;
                        }
                        spins += 1;
                        if spins > 200 {
                            std::thread::yield_now();
                        }
                    }
                    now
                }
            };
            self.cycle(woke, fresh)?;
            fresh = false;
            let done = mono_now_ns();
            self.stats.compute.record(done.saturating_sub(woke));
            if timing.clock == Clock::Wall {
                deadline += period_ns;
                if done > deadline {
                    self.stats.overruns += 1;
                    self.shared
                        .overruns
                        .store(self.stats.overruns, Ordering::Relaxed);
                    if done > deadline + 10 * period_ns {
                        // A long stall: restart the schedule rather than
                        // running the missed cycles back to back.
                        deadline = done;
                    }
                }
            }
        }
        rt_alloc::leave_realtime();
        let now = mono_now_ns();
        self.publish_status(now)?;
        Ok(RunSummary {
            cycles: self.stats.cycles,
            overruns: self.stats.overruns,
        })
    }
}

/// Totals of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunSummary {
    /// Cycles run.
    pub cycles: u64,
    /// Overruns.
    pub overruns: u64,
}
