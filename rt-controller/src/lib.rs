//! # rt-controller
//!
//! Owns the control law of the stack, run at 1 kHz: the trajectory generator
//! that turns the latest 20 Hz policy action (Δx, Δy, Δz, Δroll of the
//! end-effector) into a smooth Cartesian reference, the Cartesian impedance
//! law, operational-space control (Λ = (J M⁻¹ Jᵀ)⁻¹), the QP torque-limit
//! filter and the safety supervisor, as a pure step `(state, action) →
//! torques`, and [`cycle::ControlCycle`], that step over the wire messages
//! (hardware state and action in, torque command and sensor frame out).
//! The daemon that runs the cycle on a robot (transport, clock, real-time
//! set-up, the simulator and Franka backends, the `rt-controller` binary)
//! is its own crate, `rt-controller-daemon` (rt-controller/daemon); the
//! learner's fast path runs the same cycle in-process.
//!
//! It must not allocate, lock or block in the 1 kHz path, and it must not do
//! any learning. It does no I/O and must not depend on franka-rs, the
//! shared-memory transport or the daemon: it uses only shared-mem-schema's
//! message types. Kinematics and dynamics come from `robot-model`.
//!
//! ```no_run
//! use robot_model::{LoadOptions, Model};
//! use rt_controller::{Action, Controller, ControllerConfig, RobotState};
//! let model = Model::from_urdf_file("robot-model/urdf/panda.urdf", &LoadOptions::default())?;
//! let ctrl = Controller::new(&model, ControllerConfig::default())?;
//! let mut data = ctrl.create_data(&model);
//! let (q, v) = (vec![0.0; 7], vec![0.0; 7]);
//! let state = RobotState { q: &q, v: &v, tau_measured: None, wrench: None };
//! let action = Action { delta_pos_m: [0.0, 0.0, -0.005], delta_roll_rad: 0.0 };
//! rt_controller::step(&model, &ctrl, &mut data, &state, Some(&action), 0.0);
//! let torques: &[f64] = data.torques();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod config;
pub mod cycle;
pub mod impedance;
pub mod linalg;
pub mod osc;
pub mod qp;
pub mod speed_limits;
pub mod supervisor;
pub mod trajectory;

pub use config::{
    ConfigError, ControllerConfig, ImpedanceConfig, OscConfig, QpConfig, RampLimit, SafetyConfig,
    SpeedLimitSource, TrajectoryConfig, TrajectoryTarget,
};
pub use cycle::ControlCycle;
pub use qp::QpOutcome;
pub use speed_limits::SpeedLimits;
pub use supervisor::{Counters, FaultReason, Mode, Rejection, Supervisor, Transition};

use impedance::EeState;
use nalgebra::{DVector, Matrix6xX, Vector3, Vector6};
use osc::{OscData, OscInputs};
use qp::{QpFilter, QpProblem};
use robot_model::{FrameId, Model, Reference as Frame};
use trajectory::{ActionEffect, Reference, TrajectoryGenerator};

/// The policy's command: a displacement of the end-effector target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Action {
    /// Position step (x, y, z) in the base frame, m.
    pub delta_pos_m: [f64; 3],
    /// Roll step about the base z axis, rad.
    pub delta_roll_rad: f64,
}

impl Action {
    /// The policy's vector `(Δx, Δy, Δz, Δroll)`.
    pub fn delta(&self) -> [f64; 4] {
        let [x, y, z] = self.delta_pos_m;
        [x, y, z, self.delta_roll_rad]
    }
}

impl From<[f64; 4]> for Action {
    /// From the policy's vector `(Δx, Δy, Δz, Δroll)`.
    fn from([x, y, z, roll]: [f64; 4]) -> Self {
        Self {
            delta_pos_m: [x, y, z],
            delta_roll_rad: roll,
        }
    }
}

/// The measured robot state of one cycle.
#[derive(Debug, Clone, Copy)]
pub struct RobotState<'a> {
    /// Joint positions, rad (length `nv`).
    pub q: &'a [f64],
    /// Joint velocities, rad/s (length `nv`).
    pub v: &'a [f64],
    /// Measured joint torques, N·m, when the hardware has them; used to
    /// start the torque-rate limiter from what the robot applies.
    pub tau_measured: Option<&'a [f64]>,
    /// Wrist wrench (force, then moment) in the sensor frame, when a sensor
    /// is fitted; checked for overload.
    pub wrench: Option<&'a [f64; 6]>,
}

/// What happened to the action passed to a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActionStatus {
    /// No action this cycle.
    None,
    /// Applied as given.
    Applied,
    /// Applied after clamping.
    Clamped,
    /// Rejected as garbage; the target is unchanged.
    Rejected(Rejection),
    /// Valid but ignored (Fault or a requested hold).
    Ignored,
}

/// Summary of one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepInfo {
    /// Mode after the step.
    pub mode: Mode,
    /// What the QP filter did (`None` in Fault, where the safe command is
    /// clipped directly).
    pub qp: Option<QpOutcome>,
    /// What became of the action.
    pub action: ActionStatus,
}

/// The immutable part of the controller: configuration and the robot's
/// limits, shareable between many [`ControllerData`].
#[derive(Debug, Clone)]
pub struct Controller {
    config: ControllerConfig,
    ee_frame: FrameId,
    kv: [f64; 6],
    tau_max: DVector<f64>,
    speed: SpeedLimits,
    q_lo: DVector<f64>,
    q_hi: DVector<f64>,
}

impl Controller {
    /// Validates `config` against `model` and fixes the derived constants.
    pub fn new(model: &Model, config: ControllerConfig) -> Result<Self, ConfigError> {
        config.validate(model)?;
        let ee_frame = model
            .frame_id(&config.ee_frame)
            .map_err(|_| ConfigError::UnknownFrame(config.ee_frame.clone()))?;
        Ok(Self {
            kv: config.impedance.effective_kv(),
            ee_frame,
            tau_max: model.effort_limits(),
            speed: SpeedLimits::new(&config.joint_speed_limits, model)?,
            q_lo: model.lower_limits(),
            q_hi: model.upper_limits(),
            config,
        })
    }

    /// The validated configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// The joint speed limits the QP keeps to and the supervisor faults on.
    pub fn speed_limits(&self) -> &SpeedLimits {
        &self.speed
    }

    /// The controlled frame.
    pub fn ee_frame(&self) -> FrameId {
        self.ee_frame
    }

    /// Preallocates everything a step writes.
    pub fn create_data(&self, model: &Model) -> ControllerData {
        ControllerData::new(model, self)
    }
}

/// Everything the step writes: robot-model's workspace, the OSC and QP
/// buffers, the trajectory and the supervisor. Built once, reused forever.
pub struct ControllerData {
    /// robot-model workspace (placements, M, its Cholesky factor, h).
    pub dynamics: robot_model::Data,
    /// End-effector Jacobian in the base frame.
    pub jacobian: Matrix6xX<f64>,
    /// OSC results (Λ, J̄, Nᵀ, τ_osc, ...).
    pub osc: OscData,
    /// The trajectory generator.
    pub trajectory: TrajectoryGenerator,
    /// The mode machine and counters.
    pub supervisor: Supervisor,
    /// Measured end-effector state of the last step.
    pub ee: EeState,
    /// Reference of the last step.
    pub reference: Option<Reference>,
    /// Commanded task acceleration of the last step.
    pub a_u: Vector6<f64>,
    /// `J̇v` of the last step.
    pub jdot_v: Vector6<f64>,
    /// Posture target of the null-space term.
    pub rest_q: DVector<f64>,
    /// Torque box of the last step (torque and rate limits).
    pub tau_lo: DVector<f64>,
    /// Upper torque bound of the last step.
    pub tau_hi: DVector<f64>,
    /// Joint acceleration bounds of the last step.
    pub acc_lo: DVector<f64>,
    /// Upper joint acceleration bound.
    pub acc_hi: DVector<f64>,
    a_osc: DVector<f64>,
    tau_cmd: DVector<f64>,
    tau_prev: DVector<f64>,
    /// The last finite measured configuration (for the safe command when
    /// a later state is not finite).
    q_valid: DVector<f64>,
    scratch: DVector<f64>,
    qp: QpFilter,
    initialised: bool,
    capture_pending: bool,
    /// Summary of the last step.
    pub last: StepInfo,
}

impl ControllerData {
    /// Buffers for `model`; the QP solver is set up at the rest (or neutral)
    /// configuration.
    pub fn new(model: &Model, ctrl: &Controller) -> Self {
        let nv = model.nv();
        let mut dynamics = model.create_data();
        let q0 = match &ctrl.config.osc.rest_q {
            Some(r) => DVector::from_column_slice(r),
            None => model.neutral_configuration(),
        };
        robot_model::crba(model, &mut dynamics, q0.as_slice());
        let mut minv = nalgebra::DMatrix::identity(nv, nv);
        let mut chol = dynamics.chol.clone();
        if robot_model::cholesky_factor(&dynamics.mass, &mut chol).is_ok() {
            osc::inverse_from_cholesky(&chol, &mut DVector::zeros(nv), &mut minv);
        }
        let qp = QpFilter::new(nv, &ctrl.config.qp, &minv);
        Self {
            dynamics,
            jacobian: Matrix6xX::zeros(nv),
            osc: OscData::new(nv),
            trajectory: TrajectoryGenerator::default(),
            supervisor: Supervisor::default(),
            ee: EeState {
                pos: Vector3::zeros(),
                rot: nalgebra::Matrix3::identity(),
                twist: Vector6::zeros(),
            },
            reference: None,
            a_u: Vector6::zeros(),
            jdot_v: Vector6::zeros(),
            rest_q: q0,
            tau_lo: DVector::zeros(nv),
            tau_hi: DVector::zeros(nv),
            acc_lo: DVector::zeros(nv),
            acc_hi: DVector::zeros(nv),
            a_osc: DVector::zeros(nv),
            tau_cmd: DVector::zeros(nv),
            tau_prev: DVector::zeros(nv),
            q_valid: DVector::zeros(nv),
            scratch: DVector::zeros(nv),
            qp,
            initialised: false,
            capture_pending: true,
            last: StepInfo {
                mode: Mode::Idle,
                qp: None,
                action: ActionStatus::None,
            },
        }
    }

    /// The torques of the last step (always finite, within the torque and
    /// torque-rate limits).
    pub fn torques(&self) -> &[f64] {
        self.tau_cmd.as_slice()
    }

    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.supervisor.mode()
    }

    /// Leaves Fault for Idle; the next step holds the pose it then sees.
    pub fn reset(&mut self, now: f64) {
        if self.supervisor.mode() == Mode::Fault {
            self.supervisor.reset(now);
            self.capture_pending = true;
        }
    }

    /// Starts over at whatever state the next step sees (the robot was
    /// moved externally, e.g. a simulator reset): Idle from any mode, the
    /// pose, rest posture and torque-rate limiter re-captured. Counters are
    /// kept. Never allocates.
    pub fn restart(&mut self, now: f64) {
        self.supervisor.restart(now);
        self.initialised = false;
        self.capture_pending = true;
        self.reference = None;
    }
}

/// Torque box: torque limits intersected with the rate limit around the
/// previous command. If the previous command was outside the limits (a
/// measured torque at start), the limit wins over the rate; if it is not
/// finite (it never should be) there is no rate reference and the box is
/// the limits. Either way every bound is finite and `lo <= hi`.
fn torque_box(ctrl: &Controller, d: &mut ControllerData) {
    let r = ctrl.config.qp.torque_rate_limit_nm_s * ctrl.config.period_s;
    for i in 0..d.tau_prev.len() {
        let m = ctrl.tau_max[i];
        let p = d.tau_prev[i];
        if p.is_finite() {
            d.tau_lo[i] = (-m).max((p - r).min(m));
            d.tau_hi[i] = m.min((p + r).max(-m));
        } else {
            (d.tau_lo[i], d.tau_hi[i]) = (-m, m);
        }
    }
}

/// `x` limited to `[lo, hi]` without `f64::clamp`'s panic (it asserts
/// `lo <= hi` and no NaN bound): a box that is not one (a NaN bound or
/// `lo > hi`) gives 0, a NaN `x` the box's point nearest 0. The result is
/// finite whenever the bounds are.
pub(crate) fn clamp_torque(x: f64, lo: f64, hi: f64) -> f64 {
    if lo.is_nan() || hi.is_nan() || lo > hi {
        return 0.0;
    }
    let x = if x.is_nan() { 0.0 } else { x };
    x.max(lo).min(hi)
}

fn all_finite<'a>(xs: impl IntoIterator<Item = &'a f64>) -> bool {
    xs.into_iter().all(|x| x.is_finite())
}

/// Joint position and velocity limits as acceleration bounds.
fn acceleration_bounds(ctrl: &Controller, d: &mut ControllerData, q: &[f64], v: &[f64]) {
    let c = &ctrl.config.qp;
    let h = c.position_horizon_s;
    let hv = c.velocity_horizon_s;
    for i in 0..q.len() {
        let p_hi = 2.0 * (ctrl.q_hi[i] - c.position_margin_rad - q[i] - v[i] * h) / (h * h);
        let p_lo = 2.0 * (ctrl.q_lo[i] + c.position_margin_rad - q[i] - v[i] * h) / (h * h);
        let scale = c.velocity_limit_scale;
        // `Controller::new` builds a limit per joint; without one only the
        // position bound would hold.
        let (v_lo, v_hi) = match ctrl.speed.joint(i) {
            Some(limit) => (
                (speed_limits::scaled(limit.lower(q[i]), scale, false) - v[i]) / hv,
                (speed_limits::scaled(limit.upper(q[i]), scale, true) - v[i]) / hv,
            ),
            None => (f64::NEG_INFINITY, f64::INFINITY),
        };
        let (mut lo, mut hi) = (p_lo.max(v_lo), p_hi.min(v_hi));
        if lo > hi {
            // Position limits matter more than speed limits.
            (lo, hi) = (p_lo, p_hi);
        }
        if lo > hi {
            let mid = 0.5 * (lo + hi);
            (lo, hi) = (mid, mid);
        }
        d.acc_lo[i] = lo;
        d.acc_hi[i] = hi;
    }
}

/// Largest fraction of a joint's velocity the Fault damping may remove in
/// one control period (on the joint's own inertia, the mass matrix's
/// diagonal entry). Below 1 the discrete decay `v ← (1 − d·h/m)·v` is
/// monotone; at 5 N·m·s/rad on the iiwa's light wrist `d·h/m` was above 2,
/// and joint 7 chattered at the rate limit (issue 16).
pub const FAULT_DAMPING_STEP_FRACTION: f64 = 0.5;

/// The joint damping of the safe command, N·m·s/rad: the configured value,
/// bounded per joint by what its inertia allows at the control period
/// (`FAULT_DAMPING_STEP_FRACTION · M_ii / h`), zero for a joint whose
/// inertia is not known (a mass matrix that is not finite or not positive).
pub fn fault_damping(ctrl: &Controller, mass: &nalgebra::DMatrix<f64>, joint: usize) -> f64 {
    let m = mass[(joint, joint)];
    if !(m.is_finite() && m > 0.0) {
        return 0.0;
    }
    let bound = FAULT_DAMPING_STEP_FRACTION * m / ctrl.config.period_s;
    ctrl.config.safety.fault_damping_nms.min(bound)
}

/// Writes the safe command of Fault (gravity compensation with joint
/// damping bounded per joint by [`fault_damping`], or the gravity torque at
/// the last finite configuration when the state is unusable, zero before
/// any), clipped to the torque box. Gravity is computed here, off the
/// normal path, which never needs it alone. A non-finite gravity torque is
/// not used: the previous command is held. With `v`, the mass matrix is the
/// one the step computed at this state.
fn safe_command(model: &Model, ctrl: &Controller, d: &mut ControllerData, v: Option<&[f64]>) {
    if d.initialised {
        robot_model::gravity(model, &mut d.dynamics, d.q_valid.as_slice());
    } else {
        d.dynamics.g.fill(0.0);
    }
    if !all_finite(d.dynamics.g.iter()) {
        d.dynamics.g.copy_from(&d.tau_prev);
    }
    torque_box(ctrl, d);
    for i in 0..d.tau_cmd.len() {
        let t =
            d.dynamics.g[i] - v.map_or(0.0, |v| fault_damping(ctrl, &d.dynamics.mass, i) * v[i]);
        d.tau_cmd[i] = clamp_torque(t, d.tau_lo[i], d.tau_hi[i]);
    }
    d.tau_prev.copy_from(&d.tau_cmd);
}

/// Whether everything the step derived from the state is finite: a finite
/// state can still overflow (a huge velocity squares to infinity in `h`).
fn dynamics_finite(d: &ControllerData) -> bool {
    let rm = &d.dynamics;
    all_finite(rm.mass.iter())
        && all_finite(rm.nle.iter())
        && all_finite(d.jacobian.iter())
        && all_finite(d.jdot_v.iter())
        && all_finite(d.ee.pos.iter())
        && all_finite(d.ee.rot.iter())
        && all_finite(d.ee.twist.iter())
}

/// Starts the rate limiter from what the robot applies now: the measured
/// torques if they are there and finite, else the torques that hold it
/// (`h`, or gravity alone) if they are finite and within the effort limits,
/// else zero. A finite state can give an absurd `h` (a garbage speed of
/// 1e155 rad/s): started there, the box would pin the command at a limit.
fn seed_rate_limiter(
    model: &Model,
    ctrl: &Controller,
    d: &mut ControllerData,
    tau_measured: Option<&[f64]>,
) {
    let nv = d.tau_prev.len();
    let holds = |t: &DVector<f64>| (0..nv).all(|i| t[i].abs() <= ctrl.tau_max[i]);
    match tau_measured {
        Some(t) if t.len() == nv && all_finite(t) => d.tau_prev.copy_from_slice(t),
        _ if holds(&d.dynamics.nle) => d.tau_prev.copy_from(&d.dynamics.nle),
        _ => {
            robot_model::gravity(model, &mut d.dynamics, d.q_valid.as_slice());
            if holds(&d.dynamics.g) {
                d.tau_prev.copy_from(&d.dynamics.g);
            } else {
                d.tau_prev.fill(0.0);
            }
        }
    }
}

fn finish(d: &mut ControllerData, qp: Option<QpOutcome>, action: ActionStatus) -> StepInfo {
    d.last = StepInfo {
        mode: d.supervisor.mode(),
        qp,
        action,
    };
    d.last
}

/// One control cycle: supervisor checks, trajectory, impedance, OSC and the
/// QP filter. The torques are left in [`ControllerData::torques`].
///
/// `action` is `Some` only in the cycle a new action arrives; `now` is the
/// controller's monotonic time in seconds. Lengths of `state.q` and
/// `state.v` must equal `model.nv()` (checked; a mismatch is a programming
/// error and panics). Whatever the values (NaN, ±inf, huge, denormal), it
/// does not panic and the torques are finite and within the torque and
/// rate box: whatever it derives that is not finite (dynamics, OSC, QP) is
/// a fault, not an input. Never allocates.
pub fn step(
    model: &Model,
    ctrl: &Controller,
    d: &mut ControllerData,
    state: &RobotState<'_>,
    action: Option<&Action>,
    now: f64,
) -> StepInfo {
    let nv = model.nv();
    assert!(
        state.q.len() == nv && state.v.len() == nv,
        "rt_controller::step: state has {} positions and {} velocities, the model {nv} joints",
        state.q.len(),
        state.v.len()
    );
    d.supervisor.counters.steps += 1;
    let cfg = &ctrl.config;
    let (q, v) = (state.q, state.v);

    let state_check =
        supervisor::Supervisor::check_state(&cfg.safety, model, &ctrl.speed, q, v, state.wrench);
    if let Err(supervisor::FaultReason::NonFiniteState) = state_check {
        d.supervisor.raise(FaultReason::NonFiniteState, now);
        safe_command(model, ctrl, d, None);
        let status = ignored_if_some(d, action);
        return finish(d, None, status);
    }

    d.q_valid.copy_from_slice(q);

    // Kinematics and dynamics at the measured state.
    let rm = &mut d.dynamics;
    let jdv = robot_model::frame_jdot_v(model, rm, q, v, ctrl.ee_frame, Frame::Base);
    let pose = robot_model::frame_se3(model, rm, ctrl.ee_frame);
    let twist = robot_model::frame_velocity(model, rm, ctrl.ee_frame, Frame::Base);
    robot_model::frame_jacobian(model, rm, ctrl.ee_frame, Frame::Base, &mut d.jacobian);
    robot_model::crba(model, rm, q);
    robot_model::nonlinear_effects(model, rm, q, v);
    let chol_ok = robot_model::cholesky_factor(&rm.mass, &mut rm.chol).is_ok();
    d.jdot_v = jdv.to_vector();
    d.ee = EeState {
        pos: pose.trans,
        rot: pose.rot,
        twist: twist.to_vector(),
    };

    let dynamics_ok = chol_ok && dynamics_finite(d);

    if !d.initialised {
        seed_rate_limiter(model, ctrl, d, state.tau_measured);
        if cfg.osc.rest_q.is_none() {
            d.rest_q.copy_from_slice(q);
        }
        d.initialised = true;
    }
    if d.capture_pending && dynamics_ok {
        d.trajectory.reset(&d.ee.pos, &d.ee.rot, now);
        d.capture_pending = false;
    }

    // The state's reason first: it is the one kept.
    if let Err(reason) = state_check {
        d.supervisor.raise(reason, now);
    }
    if !dynamics_ok {
        d.supervisor.raise(FaultReason::DynamicsFailure, now);
    }
    if d.supervisor.mode() == Mode::Fault {
        safe_command(model, ctrl, d, Some(v));
        let status = ignored_if_some(d, action);
        return finish(d, None, status);
    }

    // The action.
    let mut action_status = ActionStatus::None;
    if let Some(a) = action {
        let delta = a.delta();
        action_status = match Supervisor::check_action(&cfg.safety, &delta) {
            Err(r) => {
                d.supervisor.counters.actions_rejected += 1;
                ActionStatus::Rejected(r)
            }
            Ok(()) if d.supervisor.admit_action(now) => {
                let (_, _, meas_roll) = trajectory::fixed_xyz_angles(&d.ee.rot);
                let effect =
                    d.trajectory
                        .apply_action(&cfg.trajectory, delta, &d.ee.pos, meas_roll, now);
                d.supervisor.counters.actions_accepted += 1;
                if effect == ActionEffect::Clamped {
                    d.supervisor.counters.actions_clamped += 1;
                    ActionStatus::Clamped
                } else {
                    ActionStatus::Applied
                }
            }
            Ok(()) => ActionStatus::Ignored,
        };
    }
    d.supervisor.check_timeout(&cfg.safety, now);

    // Reference → impedance → OSC.
    let reference = d.trajectory.eval(now);
    d.reference = Some(reference);
    d.a_u = impedance::task_acceleration(&reference, &d.ee, &cfg.impedance.kp, &ctrl.kv);
    let rm = &d.dynamics;
    let osc_result = osc::compute(
        &mut d.osc,
        &OscInputs {
            q,
            v,
            mass: &rm.mass,
            chol: &rm.chol,
            h: &rm.nle,
            jac: &d.jacobian,
            jdot_v: &d.jdot_v,
            a_u: &d.a_u,
            rest_q: d.rest_q.as_slice(),
        },
        &osc::OscParams {
            singular_eps: cfg.osc.singular_eps,
            eigen_max_iter: cfg.osc.eigen_max_iter as usize,
            null_kp: cfg.osc.null_kp,
            null_kv: cfg.osc.null_kv,
        },
    );
    if osc_result.is_err() {
        d.supervisor.raise(FaultReason::DynamicsFailure, now);
        safe_command(model, ctrl, d, Some(v));
        return finish(d, None, action_status);
    }

    // Limits → QP filter.
    torque_box(ctrl, d);
    acceleration_bounds(ctrl, d, q, v);
    d.scratch.copy_from(&d.osc.tau);
    d.scratch -= &d.dynamics.nle;
    linalg::mul_into(&d.osc.minv, &d.scratch, &mut d.a_osc);
    // The QP must never see a NaN (clarabel's answer to one is undefined).
    if !osc_finite(d) {
        d.supervisor.raise(FaultReason::NonFiniteTorque, now);
        safe_command(model, ctrl, d, Some(v));
        return finish(d, None, action_status);
    }
    let outcome = d.qp.filter(
        &QpProblem {
            jbar: &d.osc.jbar,
            task_force: &d.osc.force,
            lambda_inv: &d.osc.lambda_inv,
            null_t: &d.osc.null_t,
            minv: &d.osc.minv,
            tau_osc: &d.osc.tau,
            a_osc: &d.a_osc,
            tau_lo: &d.tau_lo,
            tau_hi: &d.tau_hi,
            acc_lo: &d.acc_lo,
            acc_hi: &d.acc_hi,
        },
        &mut d.tau_cmd,
    );
    let c = &mut d.supervisor.counters;
    match outcome {
        QpOutcome::Skipped => c.qp_skipped += 1,
        QpOutcome::Solved { .. } => c.qp_solved += 1,
        QpOutcome::Fallback(_) => c.qp_fallbacks += 1,
    }
    if !all_finite(d.tau_cmd.iter()) {
        d.supervisor.raise(FaultReason::NonFiniteTorque, now);
        safe_command(model, ctrl, d, Some(v));
        return finish(d, Some(outcome), action_status);
    }
    d.tau_prev.copy_from(&d.tau_cmd);
    finish(d, Some(outcome), action_status)
}

/// Whether the OSC results the QP filter reads are finite.
fn osc_finite(d: &ControllerData) -> bool {
    let o = &d.osc;
    all_finite(o.tau.iter())
        && all_finite(o.force.iter())
        && all_finite(o.jbar.iter())
        && all_finite(o.null_t.iter())
        && all_finite(o.minv.iter())
        && all_finite(o.lambda_inv.iter())
        && all_finite(d.a_osc.iter())
        // Infinite acceleration bounds mean "none" (the filter caps them).
        && !d.acc_lo.iter().chain(d.acc_hi.iter()).any(|x| x.is_nan())
}

fn ignored_if_some(d: &mut ControllerData, action: Option<&Action>) -> ActionStatus {
    match action {
        Some(_) => {
            d.supervisor.counters.actions_ignored += 1;
            ActionStatus::Ignored
        }
        None => ActionStatus::None,
    }
}

#[cfg(test)]
mod tests {
    use super::clamp_torque;

    #[test]
    fn clamp_torque_never_panics_and_stays_in_a_finite_box() {
        assert_eq!(clamp_torque(5.0, -1.0, 2.0), 2.0);
        assert_eq!(clamp_torque(-5.0, -1.0, 2.0), -1.0);
        assert_eq!(clamp_torque(0.5, -1.0, 2.0), 0.5);
        assert_eq!(clamp_torque(f64::NAN, -1.0, 2.0), 0.0, "NaN: nearest 0");
        assert_eq!(clamp_torque(f64::NAN, 1.0, 2.0), 1.0);
        assert_eq!(clamp_torque(f64::INFINITY, -1.0, 2.0), 2.0);
        // Not a box: f64::clamp would panic on each of these.
        assert_eq!(clamp_torque(0.5, 2.0, -1.0), 0.0);
        assert_eq!(clamp_torque(0.5, f64::NAN, 1.0), 0.0);
        assert_eq!(clamp_torque(0.5, -1.0, f64::NAN), 0.0);
    }
}
