//! Controller configuration: every field documented and defaulted, validated
//! against the robot model before the controller is built.

use robot_model::Model;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::{FieldError, at_least, check, finite, non_negative, positive};
use thiserror::Error;

/// A configuration value the controller cannot run with; names the field.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ConfigError {
    /// A number is NaN, infinite, or outside its allowed range.
    #[error("controller config: {0}")]
    BadValue(#[from] FieldError),
    /// A list has the wrong number of entries for this robot.
    #[error("controller config: `{field}` has {got} entries, the robot has {expected} joints")]
    WrongLength {
        /// The field.
        field: String,
        /// Its length.
        got: usize,
        /// The robot's joint count.
        expected: usize,
    },
    /// The end-effector frame is not in the model.
    #[error("controller config: `ee_frame` = {0:?} is not a frame of the robot model")]
    UnknownFrame(String),
    /// The robot has more joints than the messages carry.
    #[error("the robot has {joints} joints, messages carry at most {max}")]
    TooManyJoints {
        /// The robot's joint count.
        joints: usize,
        /// The messages' capacity.
        max: usize,
    },
}

/// Everything the control step needs besides the robot model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Name of the controlled frame (the peg tip by default).
    pub ee_frame: String,
    /// Control period in seconds (1 kHz by default); used for torque-rate
    /// limits and nothing else (time itself comes from the caller).
    pub period_s: f64,
    /// Trajectory generator settings.
    pub trajectory: TrajectoryConfig,
    /// Cartesian impedance gains.
    pub impedance: ImpedanceConfig,
    /// Operational-space control settings.
    pub osc: OscConfig,
    /// QP torque-limit filter settings.
    pub qp: QpConfig,
    /// Safety supervisor settings.
    pub safety: SafetyConfig,
    /// The joint speed limits the QP keeps to and the supervisor faults on:
    /// `urdf` (constant) or `fr3` (the Franka Research 3's own,
    /// position-dependent).
    pub joint_speed_limits: SpeedLimitSource,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            ee_frame: "peg_tip".into(),
            period_s: shared_mem_schema::rates::CONTROL_PERIOD_S,
            trajectory: TrajectoryConfig::default(),
            impedance: ImpedanceConfig::default(),
            osc: OscConfig::default(),
            qp: QpConfig::default(),
            safety: SafetyConfig::default(),
            joint_speed_limits: Default::default(),
        }
    }
}

/// Which joint speed limits the controller keeps to and faults on (TOML
/// `joint_speed_limits`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpeedLimitSource {
    /// The URDF's `velocity` of each joint, the same at every position.
    #[default]
    Urdf,
    /// The Franka Research 3's position-dependent limits, as Franka's FCI
    /// documentation ("Limits for Franka Research 3") and libfranka's
    /// `computeUpperLimitsJointVelocity` / `computeLowerLimitsJointVelocity`
    /// (`include/franka/rate_limiting.h`) give them. On a Franka the daemon
    /// replaces them by the robot's own ([`SpeedLimitSource::Ramps`]).
    Fr3,
    /// Position-dependent limits of that form with each joint's own values,
    /// in joint order (TOML `{ ramps = [{ q_lo = …, q_hi = …, v_max = …,
    /// offset = …, decel = … }, …] }`): what an FR3 serves in its URDF.
    Ramps(Vec<RampLimit>),
}

/// One joint's position-dependent speed limit: towards a stop `d` away at
/// most `−offset + √(2·decel·d)`, and never above `v_max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RampLimit {
    /// Lower position limit of the ramp, rad.
    pub q_lo: f64,
    /// Upper position limit of the ramp, rad.
    pub q_hi: f64,
    /// Largest speed, rad/s.
    pub v_max: f64,
    /// Speed offset, rad/s.
    pub offset: f64,
    /// Deceleration, rad/s².
    pub decel: f64,
}

/// What a policy step is added to (TOML `trajectory.target`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrajectoryTarget {
    /// The previous target plus the step, kept within `max_lead_m` /
    /// `max_lead_rad` of the measured pose. Steps add up exactly while the
    /// arm lags behind its reference, so the policy's steps are what the arm
    /// ends up doing in free space.
    #[default]
    Accumulated,
    /// The paper's literal scheme: the measured pose plus the step. In
    /// contact, the target then leads the pose by one step at most; in free
    /// space, a step shorter than the arm's tracking lag moves it less than
    /// asked.
    Measured,
}

impl TrajectoryTarget {
    /// The TOML value.
    pub fn name(self) -> &'static str {
        match self {
            Self::Accumulated => "accumulated",
            Self::Measured => "measured",
        }
    }
}

/// How policy actions become a Cartesian reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajectoryConfig {
    /// What each step is added to: `"accumulated"` (the previous target,
    /// the default) or `"measured"` (the measured pose, as in the paper).
    /// docs/paper.md has the measurement that chose the
    /// default.
    pub target: TrajectoryTarget,
    /// Duration of the quintic towards each new target. The default is two
    /// policy periods (2 × 50 ms): consecutive actions then blend into one
    /// smooth motion, where one period makes every segment stop at rest
    /// (20 Hz stop-and-go) with a peak jerk of 60·Δx/T³, which at the Panda's
    /// task inertia asks for ~10× the 1000 N·m/s torque-rate limit
    /// (docs/rt-controller.md has the measurements). Set it to the policy
    /// period for the paper's literal scheme.
    pub interpolation_s: f64,
    /// Largest accepted position step per action and axis; larger steps are
    /// clamped to it (and counted).
    pub max_step_m: f64,
    /// Largest accepted roll step per action; larger ones are clamped.
    pub max_step_rad: f64,
    /// Lower corner of the Cartesian box (base frame) the target is kept in.
    pub workspace_min_m: [f64; 3],
    /// Upper corner of the workspace box.
    pub workspace_max_m: [f64; 3],
    /// The roll target stays within this distance of the roll at start.
    pub roll_range_rad: f64,
    /// Anti-windup: the target never leads the measured pose by more than
    /// this per axis, so that pushing against a surface saturates the
    /// contact force at `Λ·Kp·max_lead` instead of winding it up.
    pub max_lead_m: f64,
    /// Same for roll.
    pub max_lead_rad: f64,
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        Self {
            target: TrajectoryTarget::default(),
            interpolation_s: 0.1,
            max_step_m: 0.01,
            max_step_rad: 0.05,
            workspace_min_m: [0.15, -0.6, 0.0],
            workspace_max_m: [0.85, 0.6, 0.9],
            roll_range_rad: std::f64::consts::PI,
            max_lead_m: 0.03,
            max_lead_rad: 0.3,
        }
    }
}

/// Gains of `a_u = a_d + Kp·e − Kv·(v − v_d)`, per axis of the base frame
/// (x, y, z, then rotations about x, y, z).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImpedanceConfig {
    /// Stiffness in 1/s² (OSC decouples the task into unit masses, so this
    /// is ω² of each axis).
    pub kp: [f64; 6],
    /// Damping in 1/s; `None` gives critical damping `2·√kp` per axis.
    pub kv: Option<[f64; 6]>,
}

impl Default for ImpedanceConfig {
    /// 300/s² on every axis. The tilts (rotations about base x and y) may
    /// be set stiffer for insertion: OSC's stiffness is Λ·Kp, coupled, so a
    /// side load on the tip also tilts the tool, and at 300/s² a policy
    /// pressing the peg against a hole's wall wedged it (docs/experiments.md,
    /// "The wrist tilted"); ten times stiffer tilts make rim impacts harder
    /// (the collection's heuristic then faults more), so it is not the
    /// default.
    fn default() -> Self {
        Self {
            kp: [300.0; 6],
            kv: None,
        }
    }
}

impl ImpedanceConfig {
    /// The damping actually used: the configured one or critical damping.
    pub fn effective_kv(&self) -> [f64; 6] {
        self.kv.unwrap_or_else(|| self.kp.map(|k| 2.0 * k.sqrt()))
    }
}

/// Operational-space control settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OscConfig {
    /// Singularity threshold ε on the eigenvalues σ of `Λ⁻¹ = J M⁻¹ Jᵀ`:
    /// Λ is exact where every σ ≥ ε; below, the direction's inertia is
    /// `σ/ε²` (damped least squares with `λ² = ε² − σ²`), which is
    /// continuous, bounded by `1/ε` and zero at the singularity. The Panda's
    /// smallest σ in its ready pose is about 0.09.
    pub singular_eps: f64,
    /// Posture stiffness of the null-space term, 1/s².
    pub null_kp: f64,
    /// Posture damping of the null-space term, 1/s.
    pub null_kv: f64,
    /// Rest configuration the null-space term pulls towards; `None` takes
    /// the configuration at the first step.
    pub rest_q: Option<Vec<f64>>,
    /// Cap on the QR sweeps of the eigen-decomposition of `Λ⁻¹` (≥ 1):
    /// nalgebra's uncapped one can loop forever. Running out is a
    /// `DynamicsFailure` fault. The default is LAPACK's budget (`dsteqr`:
    /// 30 per eigenvalue).
    pub eigen_max_iter: u32,
}

impl Default for OscConfig {
    fn default() -> Self {
        Self {
            singular_eps: 0.02,
            null_kp: 25.0,
            null_kv: 10.0,
            rest_q: None,
            eigen_max_iter: 180,
        }
    }
}

/// QP torque-limit filter settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QpConfig {
    /// Weights `w` of the task-space force error per axis (force, then
    /// moment). The error is measured as `eᵀ D Λ⁻¹ D e` with `D = diag(√w)`:
    /// in the kinetic-energy metric, so a moment error counts by the angular
    /// acceleration it causes, not by its size in N·m.
    pub task_weight: [f64; 6],
    /// Extra weight κ of the force error across the demanded force direction
    /// (the shortfall along it has weight 1): how strongly a saturated
    /// command gives up magnitude rather than direction. 0 gives the plain
    /// closest point.
    pub direction_weight: f64,
    /// Weight of the null-space torque error, measured in the `M⁻¹` metric
    /// (by the joint accelerations it causes), relative to the task error.
    pub null_weight: f64,
    /// Weight of the whole torque error in the `M⁻¹` metric (keeps the
    /// problem strictly convex).
    pub regularization: f64,
    /// Torque-rate limit per joint, N·m/s (Franka: 1000).
    pub torque_rate_limit_nm_s: f64,
    /// Joint position limits are approached no closer than this.
    pub position_margin_rad: f64,
    /// Horizon of the position-limit acceleration bound: the allowed
    /// acceleration is `2(q_lim − q − v·h)/h²`.
    pub position_horizon_s: f64,
    /// Fraction of the model's velocity limit the filter keeps to.
    pub velocity_limit_scale: f64,
    /// Horizon of the velocity-limit acceleration bound: `(v_lim − v)/h`.
    pub velocity_horizon_s: f64,
    /// Penalty on violating a joint position/velocity acceleration bound.
    /// The bounds are soft (one slack per joint) so that the problem stays
    /// feasible when the torque and rate limits cannot brake in time; the
    /// torque box stays hard.
    pub limit_slack_weight: f64,
    /// Interior-point iteration budget; a solve that runs out falls back to
    /// clipping (and is counted).
    pub max_iter: u32,
    /// Optional wall-clock budget of one solve, seconds. Off by default: a
    /// clock-dependent result would make lockstep simulation runs differ
    /// from run to run; `max_iter` bounds the work deterministically.
    pub time_limit_s: Option<f64>,
}

impl Default for QpConfig {
    fn default() -> Self {
        Self {
            task_weight: [1.0; 6],
            direction_weight: 100.0,
            null_weight: 1e-2,
            regularization: 1e-6,
            torque_rate_limit_nm_s: 1000.0,
            position_margin_rad: 0.05,
            position_horizon_s: 0.1,
            velocity_limit_scale: 0.9,
            velocity_horizon_s: 0.05,
            limit_slack_weight: 1e4,
            max_iter: 40,
            time_limit_s: None,
        }
    }
}

/// Safety supervisor settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyConfig {
    /// With no fresh action for this long, the controller holds its target.
    pub action_timeout_s: f64,
    /// Actions with any position component beyond this are rejected (not
    /// clamped): they are garbage, not large steps.
    pub reject_step_m: f64,
    /// Same for roll.
    pub reject_step_rad: f64,
    /// Fault when the measured force exceeds this norm, N.
    pub max_force_n: f64,
    /// Fault when the measured moment exceeds this norm, N·m.
    pub max_moment_nm: f64,
    /// Fault when a joint is this far past its position limit, rad.
    pub position_limit_tolerance_rad: f64,
    /// Fault when a joint's speed exceeds its limit (`joint_speed_limits`,
    /// at its position) times this factor; above `qp.velocity_limit_scale`.
    /// Below 1 on a Franka, whose own reflex sits at its limit.
    pub velocity_fault_scale: f64,
    /// Joint damping of the safe command in Fault, N·m·s/rad.
    pub fault_damping_nms: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            action_timeout_s: 0.1,
            reject_step_m: 0.1,
            reject_step_rad: 0.5,
            max_force_n: 100.0,
            max_moment_nm: 15.0,
            position_limit_tolerance_rad: 0.02,
            velocity_fault_scale: 1.2,
            fault_damping_nms: 5.0,
        }
    }
}

impl ControllerConfig {
    /// Checks every value against its range and against the robot.
    pub fn validate(&self, model: &Model) -> Result<(), ConfigError> {
        if model.frame_id(&self.ee_frame).is_err() {
            return Err(ConfigError::UnknownFrame(self.ee_frame.clone()));
        }
        positive("period_s", self.period_s)?;
        let t = &self.trajectory;
        positive("trajectory.interpolation_s", t.interpolation_s)?;
        positive("trajectory.max_step_m", t.max_step_m)?;
        positive("trajectory.max_step_rad", t.max_step_rad)?;
        positive("trajectory.max_lead_m", t.max_lead_m)?;
        positive("trajectory.max_lead_rad", t.max_lead_rad)?;
        non_negative("trajectory.roll_range_rad", t.roll_range_rad)?;
        for i in 0..3 {
            let (lo, hi) = (t.workspace_min_m[i], t.workspace_max_m[i]);
            check(
                &format!("trajectory.workspace_min_m[{i}]"),
                lo,
                hi.is_finite() && lo < hi,
                "must be finite and below workspace_max_m",
            )?;
            finite(&format!("trajectory.workspace_max_m[{i}]"), hi)?;
        }
        for (i, &k) in self.impedance.kp.iter().enumerate() {
            positive(&format!("impedance.kp[{i}]"), k)?;
        }
        for (i, &k) in self.impedance.effective_kv().iter().enumerate() {
            non_negative(&format!("impedance.kv[{i}]"), k)?;
        }
        positive("osc.singular_eps", self.osc.singular_eps)?;
        non_negative("osc.null_kp", self.osc.null_kp)?;
        non_negative("osc.null_kv", self.osc.null_kv)?;
        at_least("osc.eigen_max_iter", self.osc.eigen_max_iter, 1)?;
        if let Some(rest) = &self.osc.rest_q {
            if rest.len() != model.nv() {
                return Err(ConfigError::WrongLength {
                    field: "osc.rest_q".into(),
                    got: rest.len(),
                    expected: model.nv(),
                });
            }
            for (i, &x) in rest.iter().enumerate() {
                finite(&format!("osc.rest_q[{i}]"), x)?;
            }
        }
        let q = &self.qp;
        for (i, &w) in q.task_weight.iter().enumerate() {
            positive(&format!("qp.task_weight[{i}]"), w)?;
        }
        non_negative("qp.direction_weight", q.direction_weight)?;
        non_negative("qp.null_weight", q.null_weight)?;
        positive("qp.regularization", q.regularization)?;
        positive("qp.torque_rate_limit_nm_s", q.torque_rate_limit_nm_s)?;
        non_negative("qp.position_margin_rad", q.position_margin_rad)?;
        positive("qp.position_horizon_s", q.position_horizon_s)?;
        check(
            "qp.velocity_limit_scale",
            q.velocity_limit_scale,
            q.velocity_limit_scale > 0.0 && q.velocity_limit_scale <= 1.0,
            "must be in (0, 1]",
        )?;
        positive("qp.velocity_horizon_s", q.velocity_horizon_s)?;
        positive("qp.limit_slack_weight", q.limit_slack_weight)?;
        at_least("qp.max_iter", q.max_iter, 1)?;
        if let Some(t) = q.time_limit_s {
            positive("qp.time_limit_s", t)?;
        }
        let s = &self.safety;
        positive("safety.action_timeout_s", s.action_timeout_s)?;
        check(
            "safety.reject_step_m",
            s.reject_step_m,
            s.reject_step_m >= t.max_step_m,
            "must be finite and >= trajectory.max_step_m",
        )?;
        check(
            "safety.reject_step_rad",
            s.reject_step_rad,
            s.reject_step_rad >= t.max_step_rad,
            "must be finite and >= trajectory.max_step_rad",
        )?;
        positive("safety.max_force_n", s.max_force_n)?;
        positive("safety.max_moment_nm", s.max_moment_nm)?;
        non_negative(
            "safety.position_limit_tolerance_rad",
            s.position_limit_tolerance_rad,
        )?;
        check(
            "safety.velocity_fault_scale",
            s.velocity_fault_scale,
            s.velocity_fault_scale.is_finite()
                && s.velocity_fault_scale > self.qp.velocity_limit_scale,
            "must be finite and above qp.velocity_limit_scale (the QP keeps below it)",
        )?;
        non_negative("safety.fault_damping_nms", s.fault_damping_nms)?;
        for (i, j) in model.joints.iter().enumerate().skip(1) {
            let l = &j.limits;
            check(
                &format!("robot joint {:?} (#{i}) effort limit", j.name),
                l.effort,
                l.effort > 0.0,
                "the torque filter needs a finite positive effort limit per joint",
            )?;
            // robot-model reads a zero or absent velocity limit as
            // unlimited: the velocity fault could then never fire.
            check(
                &format!("robot joint {:?} (#{i}) velocity limit", j.name),
                l.velocity,
                l.velocity > 0.0,
                "the velocity fault and the torque filter need a finite positive velocity \
                 limit per joint (a zero or absent URDF velocity reads as unlimited)",
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trajectory_target_reads_from_toml_and_names_a_bad_value() {
        let c: ControllerConfig = toml::from_str("[trajectory]\ntarget = \"measured\"\n").unwrap();
        assert_eq!(c.trajectory.target, TrajectoryTarget::Measured);
        let c: ControllerConfig = toml::from_str("").unwrap();
        assert_eq!(c.trajectory.target, TrajectoryTarget::default());
        for t in [TrajectoryTarget::Accumulated, TrajectoryTarget::Measured] {
            let text = format!("[trajectory]\ntarget = \"{}\"\n", t.name());
            let c: ControllerConfig = toml::from_str(&text).unwrap();
            assert_eq!(c.trajectory.target, t);
        }
        let e = toml::from_str::<ControllerConfig>("[trajectory]\ntarget = \"paper\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("paper") && e.contains("accumulated") && e.contains("measured"),
            "{e}"
        );
    }
}
