//! The Franka backend: the daemon's control cycle as the robot's 1 kHz
//! external torque controller, over the Franka Control Interface (FCI)
//! through `franka-rs` (docs/franka.md: why that client, and what has and
//! has not been run).
//!
//! The robot clocks the loop: [`Hardware::poll`] waits for the next state
//! (one robot period; up to franka-rs's 1 s time-out when the robot falls
//! silent), the daemon's cycle answers it, and
//! [`Hardware::send`] turns the control law's joint torques into the
//! robot's command: minus gravity (the robot adds its own), clipped to the
//! joint torque limits, optionally low-pass filtered and rate limited with
//! the client library's functions, the rate limit against the robot's last
//! commanded torque, which is zero when the motion starts. The motion
//! starts at the first poll, not at connection, so that nothing between
//! (building the controller, opening services) counts against the robot's
//! communication constraints.
//!
//! A robot error ends the session with [`HardwareError::Robot`], carrying
//! the robot's own message and a fault code ([`robot_fault_code`]); the
//! daemon publishes it as its Fault and stops.

use crate::backend::{Hardware, HardwareError};
use crate::config::{FrankaConfig, FrankaGeneration, WrenchSource};
use crate::netft::NetFt;
use crate::shared::{
    FAULT_ROBOT_COMMUNICATION, FAULT_ROBOT_LIMIT, FAULT_ROBOT_OTHER, FAULT_ROBOT_REFLEX,
};
use franka::joint_velocity_limits::PositionBasedJointVelocityLimitConstants;
use franka::{
    ActiveTorqueControl, FciVersion, FrankaError, MAX_CUTOFF_FREQUENCY, MAX_TORQUE_RATE,
    RealtimeConfig, Robot, RobotOptions, RobotState, Torques, VersionPolicy,
};
use robot_model::{Data, Model};
use rt_controller::RampLimit;
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::{HardwareState, TorqueCommand};

/// The FR3's and the Panda's joint count.
const JOINTS: usize = 7;

/// Connects to the robot of `cfg`, retrying refused or unanswered
/// connections for `timeout_s` (a robot or simulator still starting), then
/// applies the collision thresholds. It never runs the robot's error
/// recovery: that is [`recover`], an operator's one-shot command. Not
/// real-time: called before the loop starts.
pub fn connect(cfg: &FrankaConfig, timeout_s: f64) -> Result<Robot, HardwareError> {
    let version = match cfg.generation {
        FrankaGeneration::Fr3 => FciVersion::V10,
        FrankaGeneration::Panda => FciVersion::V5,
    };
    // Our own real-time set-up (crate::rt) runs on the control thread;
    // the client must not change the scheduling of the caller. A control
    // log of 0: the error path then copies no states.
    let options = RobotOptions::new(RealtimeConfig::Ignore)
        .with_version(VersionPolicy::Exact(version))
        .with_log_size(0);
    let start = std::time::Instant::now();
    let robot = loop {
        match Robot::with_options(&cfg.address, options.clone()) {
            Ok(r) => break r,
            Err(FrankaError::Network(_)) if start.elapsed().as_secs_f64() < timeout_s => {
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Err(e) => {
                return Err(robot_error(
                    &e,
                    &format!(
                        "connecting to the Franka at `backend.franka.address` = {:?} as \
                         `generation` = {:?}",
                        cfg.address, cfg.generation
                    ),
                ));
            }
        }
    };
    robot
        .set_collision_behavior_simple(
            cfg.contact_torque_nm,
            cfg.collision_torque_nm,
            cfg.contact_force,
            cfg.collision_force,
        )
        .map_err(|e| robot_error(&e, "setting the collision thresholds"))?;
    Ok(robot)
}

/// `rt-controller recover`: connects, runs the robot's automatic error
/// recovery once (clears a reflex the robot latched) and disconnects. An
/// operator's decision, never part of a start.
pub fn recover(cfg: &FrankaConfig, timeout_s: f64) -> Result<(), HardwareError> {
    let robot = connect(cfg, timeout_s)?;
    robot
        .automatic_error_recovery()
        .map_err(|e| robot_error(&e, "automatic error recovery"))
}

/// The fault code of a robot error: the robot's reflex reasons of the
/// aborted motion decide (a communication constraint violation first, then
/// a limit, then any reflex); every other error is
/// [`FAULT_ROBOT_OTHER`].
pub fn robot_fault_code(e: &FrankaError) -> u32 {
    let FrankaError::Control(c) = e else {
        return FAULT_ROBOT_OTHER;
    };
    let set = |pred: &dyn Fn(&str) -> bool| {
        c.last_motion_errors
            .0
            .iter()
            .zip(franka::ERROR_NAMES)
            .any(|(&on, name)| on && pred(name))
    };
    if set(&|n| n == "communication_constraints_violation") {
        FAULT_ROBOT_COMMUNICATION
    } else if set(&|n| {
        n.contains("limit")
            || n.ends_with("velocity_violation")
            || n == "tau_J_range_violation"
            || n.contains("discontinuity")
    }) {
        FAULT_ROBOT_LIMIT
    } else if set(&|n| n.contains("reflex") || n.contains("collision"))
        || c.move_status == Some(franka::MoveStatus::ReflexAborted)
    {
        FAULT_ROBOT_REFLEX
    } else {
        FAULT_ROBOT_OTHER
    }
}

/// [`HardwareError::Robot`] of `e` (what the daemon was doing, then the
/// robot's own message).
pub fn robot_error(e: &FrankaError, doing: &str) -> HardwareError {
    HardwareError::Robot {
        code: robot_fault_code(e),
        reason: format!("{doing}: {e}"),
    }
}

/// The Franka as the daemon's hardware, on a connected [`Robot`] that
/// outlives it (the daemon's thread owns both).
pub struct FrankaBackend<'r> {
    robot: &'r Robot,
    control: Option<ActiveTorqueControl<'r>>,
    cfg: FrankaConfig,
    model: Model,
    data: Data,
    effort: [f64; JOINTS],
    state: HardwareState,
    /// The robot's state answered by the next send: its joint positions
    /// (gravity) and the torque it last commanded (rate limit reference).
    q: [f64; JOINTS],
    tau_j_d: [f64; JOINTS],
    /// The last torque sent (the low-pass filter's previous value).
    sent: [f64; JOINTS],
    pending: bool,
    t0_ms: Option<u64>,
    seq: u64,
    last_command_seq: u64,
    finished: bool,
    /// Where the loop's robot I/O failed: the control handle is kept, not
    /// dropped there (dropping it cancels the motion over TCP and blocks),
    /// and [`Hardware::finish`] ends it outside the real-time section.
    failed: IoFailure,
    /// Lowest `control_command_success_rate` the robot reported (1: no
    /// command missed in its window).
    pub min_success_rate: f64,
    /// The external F/T sensor of `wrench = "net_ft"`.
    netft: Option<NetFt>,
}

impl<'r> FrankaBackend<'r> {
    /// The backend on `robot` for `model` (whose gravity is taken off the
    /// commands: it must be the robot's with its end-effector load, e.g.
    /// the built-in `fr3`). `wrench_sensor` is the external sensor of
    /// `wrench = "net_ft"`, connected and streaming ([`NetFt::connect`]:
    /// one that does not answer is a start-up error, not a Fault in the
    /// loop); it must be given exactly when the configuration names it.
    pub fn new(
        robot: &'r Robot,
        cfg: FrankaConfig,
        model: &Model,
        wrench_sensor: Option<NetFt>,
    ) -> Result<Self, HardwareError> {
        if model.nv() != JOINTS {
            return Err(HardwareError::Robot {
                code: FAULT_ROBOT_OTHER,
                reason: format!(
                    "the robot model has {} joints; a Franka has {JOINTS} (`robot` must be a \
                     Franka description such as \"fr3\")",
                    model.nv()
                ),
            });
        }
        // Start-up, not real-time: the robot's state outside a motion.
        let first = robot
            .read_once()
            .map_err(|e| robot_error(&e, "reading the robot's state at start-up"))?;
        check_load(model, cfg.generation, &first)?;
        let mut effort = [0.0; JOINTS];
        effort.copy_from_slice(model.effort_limits().as_slice());
        if (cfg.wrench == WrenchSource::NetFt) != wrench_sensor.is_some() {
            return Err(HardwareError::Robot {
                code: FAULT_ROBOT_OTHER,
                reason: format!(
                    "`backend.franka.wrench` = {:?} needs {} external sensor",
                    cfg.wrench,
                    if wrench_sensor.is_some() { "no" } else { "an" }
                ),
            });
        }
        Ok(Self {
            robot,
            control: None,
            cfg,
            model: model.clone(),
            data: model.create_data(),
            effort,
            state: HardwareState::empty(JOINTS),
            q: [0.0; JOINTS],
            tau_j_d: [0.0; JOINTS],
            sent: [0.0; JOINTS],
            pending: false,
            t0_ms: None,
            seq: 0,
            last_command_seq: 0,
            finished: false,
            failed: IoFailure::None,
            min_success_rate: 1.0,
            netft: wrench_sensor,
        })
    }

    /// Fills the message from a robot state; never allocates.
    fn take_state(&mut self, s: &RobotState) {
        let t_ms = s.time.as_millis();
        let t0 = *self.t0_ms.get_or_insert(t_ms);
        self.seq += 1;
        let st = &mut self.state;
        // One episode per process: a robot error ends the run.
        st.header = shared_mem_schema::Header::new(self.seq, mono_now_ns(), t_ms * 1_000_000, 1);
        st.step = t_ms.saturating_sub(t0);
        st.applied_command_seq = self.last_command_seq;
        st.n_joints = JOINTS as u32;
        st.q[..JOINTS].copy_from_slice(&s.q);
        st.v[..JOINTS].copy_from_slice(&s.dq);
        st.tau_measured[..JOINTS].copy_from_slice(&s.tau_J);
        st.wrench = match self.cfg.wrench {
            WrenchSource::RobotEstimate => flange_wrench(s),
            // Read in `poll`, which can fail.
            WrenchSource::NetFt | WrenchSource::None => [0.0; 6],
        };
        self.q = s.q;
        self.tau_j_d = s.tau_J_d;
        self.min_success_rate = self.min_success_rate.min(s.control_command_success_rate);
    }

    /// The robot's command for the control law's joint torques `tau`
    /// (gravity included) at the pending state.
    fn command(&mut self, tau: &[f64]) -> Result<[f64; JOINTS], FrankaError> {
        let g = robot_model::gravity(&self.model, &mut self.data, &self.q);
        let mut out = [0.0; JOINTS];
        for i in 0..JOINTS {
            // The control law keeps its torques within the limits with
            // gravity; without it they may not be.
            out[i] = (tau[i] - g[i]).clamp(-self.effort[i], self.effort[i]);
        }
        if self.cfg.cutoff_hz < MAX_CUTOFF_FREQUENCY {
            // Filtered against the robot's last commanded torque, as
            // libfranka's control loop does.
            for (o, &last) in out.iter_mut().zip(&self.tau_j_d) {
                *o = franka::low_pass_filter(1e-3, *o, last, self.cfg.cutoff_hz)?;
            }
        }
        if self.cfg.rate_limit {
            let mut max = MAX_TORQUE_RATE;
            if self.cfg.generation == FrankaGeneration::Fr3 {
                // The FR3 publishes tau_J_d as an f32 but judges our rate
                // against the f64 it received: half an f32 ulp of |tau_J_d|
                // per 1 ms is up to 3.8e-3 N·m/s at 64 N·m, more than the
                // 1e-3 N·m/s MAX_TORQUE_RATE keeps below 1000. Give it up.
                for (m, t) in max.iter_mut().zip(&self.tau_j_d) {
                    *m -= f64::from(f32::EPSILON) * t.abs() / 2.0 / 1e-3;
                }
            }
            out = franka::limit_rate_torques(&max, &out, &self.tau_j_d)?;
        }
        Ok(out)
    }
}

/// Where the loop's robot I/O failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum IoFailure {
    /// Nothing failed.
    None,
    /// Reading the robot's state.
    Read,
    /// Sending the torques.
    Write,
}

/// The joint speed limits the connected FR3 serves in its URDF, which
/// franka-rs's own rate limiter reads (`JointVelocityLimitsConfig`), in the
/// controller's form: the daemon keeps to these rather than to the
/// documented table, since an FR3 may serve other values. A model without
/// them is a [`HardwareError::Mismatch`] (exit status 2).
pub fn served_speed_limits(robot: &Robot) -> Result<Vec<RampLimit>, HardwareError> {
    let urdf = robot
        .robot_model()
        .map_err(|e| robot_error(&e, "reading the robot's model"))?;
    let limits = franka::JointVelocityLimitsConfig::from_urdf(&urdf).map_err(|e| {
        HardwareError::Mismatch(format!(
            "the robot's model has no joint speed limits the controller can keep to: {e}"
        ))
    })?;
    Ok(ramps_of(limits.joint_params()))
}

/// franka-rs's per-joint speed-limit constants as the controller's ramps.
pub fn ramps_of(params: &[PositionBasedJointVelocityLimitConstants]) -> Vec<RampLimit> {
    params
        .iter()
        .map(|p| RampLimit {
            q_lo: p.lower_position_limit,
            q_hi: p.upper_position_limit,
            v_max: p.max_velocity,
            offset: p.velocity_offset,
            decel: p.deceleration_limit,
        })
        .collect()
}

/// Largest difference, N·m on any joint, between the gravity our model
/// takes off the commands and the gravity the robot adds for its own
/// end-effector load. 0.2 N·m is about 40 g at the hand of an outstretched
/// arm: within it the impedance's steady-state error stays under 1 mm.
/// robot-model's `panda` and franka-rs's identified FER model already
/// differ by up to 0.08 N·m (joint 5), which leaves 0.12 N·m of it there.
pub const LOAD_GRAVITY_TOLERANCE_NM: f64 = 0.2;

/// Refuses a robot whose configured end-effector load (Desk's end-effector
/// and load settings: `m_total` at `F_x_Ctotal` in its state `s`) is not
/// the load `model` carries: the backend takes `model`'s gravity off every
/// command and the robot adds its own, so a difference would push the arm
/// steadily, unseen by the control law.
pub fn check_load(
    model: &Model,
    generation: FrankaGeneration,
    s: &RobotState,
) -> Result<(), HardwareError> {
    let urdf = match generation {
        FrankaGeneration::Fr3 => franka::model::FR3_URDF,
        FrankaGeneration::Panda => franka::model::FER_URDF,
    };
    let theirs = franka::Model::from_urdf(urdf)
        .map_err(|e| robot_error(&e, "building the robot's model"))?;
    let mut data = model.create_data();
    // The robot's pose now and two with long lever arms (the ready pose,
    // the arm stretched forward): a load missing at one pose shows at
    // another (0.2 kg: 0.17 N·m at q = 0, 0.93 N·m at the ready pose).
    let poses = [
        ("at its pose now", s.q),
        ("at the ready pose", robot_model::descriptions::FR3_READY_Q),
        (
            "with the arm stretched forward",
            [0.0, 1.2, 0.0, -0.3, 0.0, 1.5, 0.785],
        ),
    ];
    // The first joint beyond the tolerance; a NaN (a state the robot
    // filled badly) is beyond it too.
    let beyond = poses.iter().find_map(|(at, q)| {
        let want = theirs.gravity_q(
            q,
            s.m_total,
            &s.F_x_Ctotal,
            &franka::model::DEFAULT_GRAVITY_EARTH,
        );
        let ours = robot_model::gravity(model, &mut data, q);
        (0..JOINTS)
            .map(|i| (i, (ours[i] - want[i]).abs()))
            .find(|(_, d)| d.is_nan() || *d > LOAD_GRAVITY_TOLERANCE_NM)
            .map(|(i, d)| (i, d, *at))
    });
    if let Some((joint, d, at)) = beyond {
        return Err(HardwareError::Mismatch(format!(
            "the robot adds gravity for an end-effector load of {:.3} kg (hand {:.3} kg, \
             load {:.3} kg) at {:?} m in the flange frame, but the robot model's gravity \
             differs by {d:.2} N·m at joint {} {at} (more than {LOAD_GRAVITY_TOLERANCE_NM} \
             N·m): set the end effector and load in Desk to what the model carries, or the \
             model's load to the robot's",
            s.m_total,
            s.m_ee,
            s.m_load,
            s.F_x_Ctotal,
            joint + 1
        )));
    }
    Ok(())
}

/// The robot's estimated external wrench (`K_F_ext_hat_K`, at and in the
/// stiffness frame K) in the flange frame F, about F's origin: the frame
/// the robot descriptions' wrench is read in, with its sign turned. libfranka
/// documents the estimate as the wrench the robot applies to the
/// environment ("forces applied by the robot to the environment are
/// positive"); the schema's is the wrench the tool exerts on the flange,
/// which through a rigid tool is the environment's on the tool: the
/// opposite.
pub fn flange_wrench(s: &RobotState) -> [f64; 6] {
    use nalgebra::{Matrix4, Vector3};
    let f_t_k = Matrix4::from_column_slice(&s.F_T_EE) * Matrix4::from_column_slice(&s.EE_T_K);
    let r = f_t_k.fixed_view::<3, 3>(0, 0);
    let p = Vector3::new(f_t_k[(0, 3)], f_t_k[(1, 3)], f_t_k[(2, 3)]);
    let w = &s.K_F_ext_hat_K;
    let f = -(r * Vector3::new(w[0], w[1], w[2]));
    let m = -(r * Vector3::new(w[3], w[4], w[5])) + p.cross(&f);
    [f.x, f.y, f.z, m.x, m.y, m.z]
}

impl Hardware for FrankaBackend<'_> {
    fn name(&self) -> &'static str {
        "franka"
    }

    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError> {
        if self.finished || self.failed != IoFailure::None {
            return Ok(None);
        }
        let control = match &mut self.control {
            Some(c) => c,
            None => {
                let c = self
                    .robot
                    .start_torque_control()
                    .map_err(|e| robot_error(&e, "starting torque control"))?;
                if let Some(ft) = &mut self.netft {
                    // What the sensor sent before the motion is old now.
                    ft.discard_queued(mono_now_ns());
                }
                self.control.insert(c)
            }
        };
        let (s, _since_last) = match control.read_once() {
            Ok(r) => r,
            Err(e) => {
                // The motion is over on the robot's side; `finish` drops
                // the handle (cancelling it on ours) once the loop has
                // left the real-time section.
                self.failed = IoFailure::Read;
                return Err(robot_error(&e, "reading the robot state"));
            }
        };
        self.take_state(&s);
        self.pending = true;
        if let Some(ft) = &mut self.netft {
            // A silent or faulted sensor ends the run like a robot error;
            // the state stays pending, so `finish` answers it.
            self.state.wrench = ft.read(mono_now_ns())?;
        }
        Ok(Some(&self.state))
    }

    fn send(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError> {
        // One command per state: a repeated send has nothing to answer.
        if !self.pending || self.control.is_none() || self.failed != IoFailure::None {
            return Ok(());
        }
        self.pending = false;
        self.last_command_seq = cmd.header.seq;
        let written = self.command_torques(cmd).and_then(|tau| {
            self.sent = tau;
            match self.control.as_mut() {
                Some(c) => c.write_once(&Torques::new(tau)),
                None => Ok(()),
            }
        });
        written.map_err(|e| {
            self.failed = IoFailure::Write;
            robot_error(&e, "sending torques")
        })
    }

    fn sent_torques(&self) -> Option<&[f64]> {
        Some(&self.sent)
    }

    fn finish(&mut self) -> Result<(), HardwareError> {
        let Some(mut control) = self.control.take() else {
            return Ok(());
        };
        self.finished = true;
        match self.failed {
            IoFailure::None => {}
            IoFailure::Read => {
                // The robot ended the motion itself (its error) or went
                // silent; franka-rs's cancel would wait for a TCP reply
                // without a time-out. Nothing is cancelled and the process
                // ends next: the handle is let go as it is.
                std::mem::forget(control);
                return Ok(());
            }
            IoFailure::Write => {
                // The robot still runs the motion: cancel it (a blocking
                // TCP request), here outside the real-time section. Were
                // it left, the robot's own communication reflex would stop
                // it within milliseconds of the missing commands.
                drop(control);
                return Ok(());
            }
        }
        if !self.pending {
            control
                .read_once()
                .map_err(|e| robot_error(&e, "reading the robot state to finish"))?;
        }
        self.pending = false;
        // The last torque once more, as the motion's end: no jump when
        // the robot's own controller takes over.
        let last = Torques {
            tau_J: self.sent,
            motion_finished: true,
        };
        control
            .write_once(&last)
            .map_err(|e| robot_error(&e, "finishing the motion"))
    }
}

impl FrankaBackend<'_> {
    fn command_torques(&mut self, cmd: &TorqueCommand) -> Result<[f64; JOINTS], FrankaError> {
        let mut tau = [0.0; JOINTS];
        tau.copy_from_slice(&cmd.tau[..JOINTS]);
        self.command(&tau)
    }
}

#[cfg(test)]
mod tests;
