//! One control cycle over the wire messages: the newest [`HardwareState`]
//! and the action due (a [`PolicyAction`]) in, the [`TorqueCommand`] for the
//! robot and the [`SensorFrame`] for the learner out.
//!
//! This is the only place where messages become a control step and a step
//! becomes messages. The daemon wraps it with transport and a clock, the
//! learner's fast path and hw-sim's tests call it in-process; so lockstep
//! through the processes and the fast path run the same code by
//! construction. No iceoryx2 and no clock here: every time is an argument.
//! Never allocates after [`ControlCycle::new`].

use crate::{
    Action, ActionStatus, ConfigError, Controller, ControllerConfig, ControllerData, FaultReason,
    Mode, RobotState, StepInfo,
};
use robot_model::Model;
use shared_mem_schema::{
    ControllerMode, HardwareState, Header, MAX_JOINTS, PolicyAction, SensorFrame, TorqueCommand,
    hw_time_s,
};

impl From<&PolicyAction> for Action {
    fn from(a: &PolicyAction) -> Self {
        Self::from(a.delta())
    }
}

impl From<Mode> for ControllerMode {
    fn from(m: Mode) -> Self {
        match m {
            Mode::Idle => ControllerMode::Idle,
            Mode::Running => ControllerMode::Running,
            Mode::Holding => ControllerMode::Holding,
            Mode::Fault => ControllerMode::Fault,
        }
    }
}

/// Fault code carried in the status: 0 none, 1 non-finite state, 2 joint
/// position limit, 3 joint velocity limit, 4 force overload, 5 moment
/// overload, 6 dynamics failure, 7 non-finite torque (100, hardware silent,
/// is the daemon's: `rt_controller_daemon::FAULT_HARDWARE_SILENT`).
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

/// The control law with its message plumbing: the controller, its
/// workspace, the joint buffers the messages are unpacked into, the
/// episode seen last and the output sequence numbers.
pub struct ControlCycle {
    ctrl: Controller,
    /// The control law's workspace.
    pub data: ControllerData,
    q: Vec<f64>,
    v: Vec<f64>,
    tau_meas: Vec<f64>,
    episode: Option<u64>,
    seq: u64,
    last_action_seq: u64,
    resets: u64,
}

impl ControlCycle {
    /// Builds the controller for `model`; all buffers are allocated here.
    pub fn new(model: &Model, config: ControllerConfig) -> Result<Self, ConfigError> {
        let nv = model.nv();
        if nv > MAX_JOINTS {
            return Err(ConfigError::TooManyJoints {
                joints: nv,
                max: MAX_JOINTS,
            });
        }
        let ctrl = Controller::new(model, config)?;
        let data = ctrl.create_data(model);
        Ok(Self {
            ctrl,
            data,
            q: vec![0.0; nv],
            v: vec![0.0; nv],
            tau_meas: vec![0.0; nv],
            episode: None,
            seq: 0,
            last_action_seq: 0,
            resets: 0,
        })
    }

    /// The controller (configuration and limits).
    pub fn controller(&self) -> &Controller {
        &self.ctrl
    }

    /// The episode of the last state seen, if any.
    pub fn episode(&self) -> Option<u64> {
        self.episode
    }

    /// Sequence number of the newest action reflected in the torques (0:
    /// none yet).
    pub fn last_action_seq(&self) -> u64 {
        self.last_action_seq
    }

    /// The mode as published.
    pub fn mode(&self) -> ControllerMode {
        self.data.mode().into()
    }

    /// The fault code as published.
    pub fn fault_code(&self) -> u32 {
        fault_code(self.data.supervisor.fault())
    }

    /// Faults cleared by [`ControlCycle::reset`] so far.
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// Notes the episode of `state`: a state of another episode than the
    /// last (the robot was reset) restarts the control law at it, with no
    /// action of the new episode applied yet, unless a fault is latched: a
    /// fault outlives the episode and only [`ControlCycle::reset`] clears
    /// it. Returns true on a new episode. [`ControlCycle::cycle`] calls
    /// it; transports call it when a state arrives, to drop what they
    /// queued for the old episode.
    pub fn observe_episode(&mut self, state: &HardwareState) -> bool {
        let e = state.header.episode;
        if self.episode == Some(e) {
            return false;
        }
        if self.data.mode() != Mode::Fault {
            self.data.restart(hw_time_s(state.header.t_hw_ns));
        }
        self.episode = Some(e);
        self.last_action_seq = 0;
        true
    }

    /// The explicit reset (an operator's or the learner's command): leaves
    /// a latched Fault for Idle, restarting the control law at the state
    /// the next cycle sees (its pose held, the torque-rate limiter started
    /// from the measured torques), at hardware time `t_hw_ns`. Counted;
    /// returns false, changing nothing, when no fault is latched.
    pub fn reset(&mut self, t_hw_ns: u64) -> bool {
        if self.data.mode() != Mode::Fault {
            return false;
        }
        self.restart(t_hw_ns);
        true
    }

    /// Restarts the control law whatever its mode (the daemon's reset after
    /// a silent hardware came back: the arm may have moved meanwhile), at
    /// hardware time `t_hw_ns`. Counted as a reset.
    pub fn restart(&mut self, t_hw_ns: u64) {
        self.data.restart(hw_time_s(t_hw_ns));
        self.last_action_seq = 0;
        self.resets += 1;
    }

    /// Asks the control law to hold its target (shutdown), at the time of
    /// `state`.
    pub fn request_hold(&mut self, state: &HardwareState) {
        let t = hw_time_s(state.header.t_hw_ns);
        self.data.supervisor.request_hold(t);
    }

    /// One control cycle on `state` (whose `n_joints` must equal the
    /// model's) with `action` applied in it, if any. Writes the command
    /// answering `state` into `cmd` and the sensor frame into `frame`, both
    /// stamped `t_mono_ns`; the frame carries the mode and the fault after
    /// the step. Never allocates.
    pub fn cycle(
        &mut self,
        model: &Model,
        state: &HardwareState,
        action: Option<&PolicyAction>,
        t_mono_ns: u64,
        cmd: &mut TorqueCommand,
        frame: &mut SensorFrame,
    ) -> StepInfo {
        self.observe_episode(state);
        let nv = model.nv();
        self.q.copy_from_slice(&state.q[..nv]);
        self.v.copy_from_slice(&state.v[..nv]);
        self.tau_meas.copy_from_slice(&state.tau_measured[..nv]);
        let core_action = action.map(Action::from);
        let info = crate::step(
            model,
            &self.ctrl,
            &mut self.data,
            &RobotState {
                q: &self.q,
                v: &self.v,
                tau_measured: Some(&self.tau_meas),
                wrench: Some(&state.wrench),
            },
            core_action.as_ref(),
            hw_time_s(state.header.t_hw_ns),
        );
        if matches!(info.action, ActionStatus::Applied | ActionStatus::Clamped)
            && let Some(a) = action
        {
            self.last_action_seq = a.header.seq;
        }
        self.seq += 1;
        let header = Header::new(
            self.seq,
            t_mono_ns,
            state.header.t_hw_ns,
            state.header.episode,
        );
        let tau = self.data.torques();
        cmd.header = header;
        cmd.state_step = state.step;
        cmd.action_seq = self.last_action_seq;
        cmd.n_joints = nv as u32;
        cmd.reserved = 0;
        cmd.tau = [0.0; MAX_JOINTS];
        cmd.tau[..nv].copy_from_slice(tau);

        let ee = &self.data.ee;
        let rot = nalgebra::Rotation3::from_matrix_unchecked(ee.rot);
        let quat = nalgebra::UnitQuaternion::from_rotation_matrix(&rot);
        frame.header = header;
        frame.step = state.step;
        frame.action_seq = self.last_action_seq;
        frame.n_joints = nv as u32;
        frame.mode = ControllerMode::from(info.mode) as u32;
        frame.fault_code = self.fault_code();
        frame.reserved = 0;
        frame.q = state.q;
        frame.v = state.v;
        frame.tau_cmd = cmd.tau;
        frame.tau_measured = state.tau_measured;
        frame.ee_pos_m = [ee.pos.x, ee.pos.y, ee.pos.z];
        frame.ee_quat_xyzw = [quat.i, quat.j, quat.k, quat.w];
        frame.ee_twist.copy_from_slice(ee.twist.as_slice());
        frame.wrench = state.wrench;
        // What the hardware is sent unless its backend changes it (the
        // daemon's Franka backend overwrites it after sending).
        frame.tau_sent = cmd.tau;
        info
    }
}
