//! Safety supervisor: the controller's mode machine, action validation and
//! fault detection.
//!
//! ```text
//!            valid action                 no action for `action_timeout_s`
//!   Idle ───────────────────► Running ─────────────────────────────────► Holding
//!     ▲                          ▲ ◄──────────── valid action ────────────┘
//!     │ reset()                  │   (not while a hold is requested)
//!     │                    any mode ── limit, overload, NaN ──► Fault (latched)
//!     └─────────────────────────────────────────────────────────────┘
//! ```
//!
//! Idle holds the pose seen at the first step; Holding keeps the last target
//! (the running segment finishes, so the stop is smooth); Fault commands
//! gravity compensation with joint damping until `reset`.

use crate::config::SafetyConfig;
use robot_model::Model;

/// The controller's mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Started, no action yet: holds the pose seen at the first step.
    Idle,
    /// Following actions.
    Running,
    /// Holding the last target: actions stopped coming, or a hold was
    /// requested.
    Holding,
    /// Latched safe state after a fault; leaves only by [`Supervisor::reset`].
    Fault,
}

/// Why the controller went to Fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultReason {
    /// q, v or the wrench had a NaN or infinite value.
    NonFiniteState,
    /// A joint is past its position limit (index, position).
    JointPositionLimit {
        /// Joint index (0-based coordinate).
        joint: usize,
        /// Its position, rad.
        q: f64,
    },
    /// A joint moves faster than its limit allows.
    JointVelocityLimit {
        /// Joint index.
        joint: usize,
        /// Its velocity, rad/s.
        v: f64,
    },
    /// The measured force exceeds `max_force_n`.
    ForceOverload {
        /// Force norm, N.
        force_n: f64,
    },
    /// The measured moment exceeds `max_moment_nm`.
    MomentOverload {
        /// Moment norm, N·m.
        moment_nm: f64,
    },
    /// The mass matrix could not be factored.
    DynamicsFailure,
    /// The control law produced a non-finite torque.
    NonFiniteTorque,
}

/// Why an action was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// A component is NaN or infinite.
    NonFinite,
    /// A component is beyond the rejection bound.
    OutOfRange,
}

/// One mode change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Mode before.
    pub from: Mode,
    /// Mode after.
    pub to: Mode,
    /// Controller time of the change, s.
    pub at: f64,
}

/// Event counters, monotonic since construction.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Control steps run.
    pub steps: u64,
    /// Actions applied (clamped ones included).
    pub actions_accepted: u64,
    /// Actions applied after clamping.
    pub actions_clamped: u64,
    /// Actions rejected as non-finite or out of range.
    pub actions_rejected: u64,
    /// Valid actions ignored because of a fault or a requested hold.
    pub actions_ignored: u64,
    /// Times the action stream timed out.
    pub action_timeouts: u64,
    /// Faults raised.
    pub faults: u64,
    /// Cycles where the OSC torques were feasible and passed through.
    pub qp_skipped: u64,
    /// Cycles where the QP was solved.
    pub qp_solved: u64,
    /// Cycles where the solver failed and clipping was used.
    pub qp_fallbacks: u64,
    /// Mode transitions.
    pub transitions: u64,
}

/// Mode machine and counters.
#[derive(Debug, Clone, PartialEq)]
pub struct Supervisor {
    mode: Mode,
    fault: Option<FaultReason>,
    last_action_at: f64,
    hold_requested: bool,
    last_transition: Option<Transition>,
    /// Event counters.
    pub counters: Counters,
}

impl Default for Supervisor {
    fn default() -> Self {
        Self {
            mode: Mode::Idle,
            fault: None,
            last_action_at: f64::NEG_INFINITY,
            hold_requested: false,
            last_transition: None,
            counters: Counters::default(),
        }
    }
}

impl Supervisor {
    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The fault that latched the Fault mode, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.fault
    }

    /// The most recent mode change.
    pub fn last_transition(&self) -> Option<Transition> {
        self.last_transition
    }

    /// Whether a hold was requested (and not released).
    pub fn hold_requested(&self) -> bool {
        self.hold_requested
    }

    fn go(&mut self, to: Mode, now: f64) {
        if self.mode != to {
            self.last_transition = Some(Transition {
                from: self.mode,
                to,
                at: now,
            });
            self.counters.transitions += 1;
            self.mode = to;
        }
    }

    /// Latches Fault (the first reason is kept).
    pub fn raise(&mut self, reason: FaultReason, now: f64) {
        if self.mode != Mode::Fault {
            self.fault = Some(reason);
            self.counters.faults += 1;
            self.go(Mode::Fault, now);
        }
    }

    /// Leaves Fault for Idle; the next step re-captures the pose. No effect
    /// in other modes.
    pub fn reset(&mut self, now: f64) {
        if self.mode == Mode::Fault {
            self.fault = None;
            self.last_action_at = f64::NEG_INFINITY;
            self.go(Mode::Idle, now);
        }
    }

    /// Back to Idle from any mode, the fault and any hold cleared (the
    /// robot was moved by someone else: a new episode). Counters are kept.
    pub fn restart(&mut self, now: f64) {
        self.fault = None;
        self.hold_requested = false;
        self.last_action_at = f64::NEG_INFINITY;
        self.go(Mode::Idle, now);
    }

    /// Asks for a hold (e.g. on shutdown): actions are ignored until
    /// [`Supervisor::release_hold`].
    pub fn request_hold(&mut self, now: f64) {
        self.hold_requested = true;
        if matches!(self.mode, Mode::Idle | Mode::Running) {
            self.go(Mode::Holding, now);
        }
    }

    /// Lets actions through again after [`Supervisor::request_hold`].
    pub fn release_hold(&mut self) {
        self.hold_requested = false;
    }

    /// Validates an action `(Δx, Δy, Δz, Δroll)`.
    pub fn check_action(cfg: &SafetyConfig, delta: &[f64; 4]) -> Result<(), Rejection> {
        if delta.iter().any(|x| !x.is_finite()) {
            return Err(Rejection::NonFinite);
        }
        if delta[..3].iter().any(|x| x.abs() > cfg.reject_step_m)
            || delta[3].abs() > cfg.reject_step_rad
        {
            return Err(Rejection::OutOfRange);
        }
        Ok(())
    }

    /// Decides whether a valid action may be applied now, updating the mode.
    pub fn admit_action(&mut self, now: f64) -> bool {
        match self.mode {
            Mode::Fault => {
                self.counters.actions_ignored += 1;
                false
            }
            _ if self.hold_requested => {
                self.counters.actions_ignored += 1;
                false
            }
            _ => {
                self.last_action_at = now;
                self.go(Mode::Running, now);
                true
            }
        }
    }

    /// Moves Running to Holding when the action stream has gone quiet.
    pub fn check_timeout(&mut self, cfg: &SafetyConfig, now: f64) {
        if self.mode == Mode::Running && now - self.last_action_at > cfg.action_timeout_s {
            self.counters.action_timeouts += 1;
            self.go(Mode::Holding, now);
        }
    }

    /// Checks the measured state against limits. Every value of `q`, `v`
    /// and the wrench is checked for finiteness, and that outranks any
    /// limit: a limit fault never hides a NaN or an infinity in a later
    /// joint (with a limit fault the step still computes the dynamics and
    /// the safe command at this state). Then every joint against its
    /// position limits and its speed limits at its position (`speed`; the
    /// first joint at fault is reported), then the wrench.
    pub fn check_state(
        cfg: &SafetyConfig,
        model: &Model,
        speed: &crate::SpeedLimits,
        q: &[f64],
        v: &[f64],
        wrench: Option<&[f64; 6]>,
    ) -> Result<(), FaultReason> {
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        if !finite(q) || !finite(v) || wrench.is_some_and(|w| !finite(w)) {
            return Err(FaultReason::NonFiniteState);
        }
        let tol = cfg.position_limit_tolerance_rad;
        let joints = model.joints[1..].iter().zip(q.iter().zip(v));
        for (k, (j, (&q, &v))) in joints.enumerate() {
            if q < j.limits.lower - tol || q > j.limits.upper + tol {
                return Err(FaultReason::JointPositionLimit { joint: k, q });
            }
            // The robot's own limit at q (a joint without one in `speed`,
            // which `Controller::new` never builds, gets no speed fault).
            let Some(limit) = speed.joint(k) else {
                continue;
            };
            let scale = cfg.velocity_fault_scale;
            if v > limit.robot_upper(q) * scale || v < limit.robot_lower(q) * scale {
                return Err(FaultReason::JointVelocityLimit { joint: k, v });
            }
        }
        if let Some(w) = wrench {
            let f = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            if f > cfg.max_force_n {
                return Err(FaultReason::ForceOverload { force_n: f });
            }
            let m = (w[3] * w[3] + w[4] * w[4] + w[5] * w[5]).sqrt();
            if m > cfg.max_moment_nm {
                return Err(FaultReason::MomentOverload { moment_nm: m });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_follow_the_documented_transitions() {
        let cfg = SafetyConfig::default();
        let mut s = Supervisor::default();
        assert_eq!(s.mode(), Mode::Idle);
        s.check_timeout(&cfg, 10.0);
        assert_eq!(s.mode(), Mode::Idle, "Idle does not time out");
        assert!(s.admit_action(0.0));
        assert_eq!(s.mode(), Mode::Running);
        s.check_timeout(&cfg, 0.05);
        assert_eq!(s.mode(), Mode::Running);
        s.check_timeout(&cfg, 0.1001);
        assert_eq!(s.mode(), Mode::Holding);
        assert_eq!(s.counters.action_timeouts, 1);
        assert!(s.admit_action(0.2));
        assert_eq!(s.mode(), Mode::Running);
        s.request_hold(0.21);
        assert_eq!(s.mode(), Mode::Holding);
        assert!(!s.admit_action(0.22));
        assert_eq!(s.counters.actions_ignored, 1);
        s.release_hold();
        assert!(s.admit_action(0.23));
        s.raise(FaultReason::DynamicsFailure, 0.3);
        s.raise(FaultReason::NonFiniteTorque, 0.31);
        assert_eq!(
            s.fault(),
            Some(FaultReason::DynamicsFailure),
            "first reason kept"
        );
        assert_eq!(s.counters.faults, 1);
        assert!(!s.admit_action(0.32), "Fault is latched");
        s.check_timeout(&cfg, 5.0);
        assert_eq!(s.mode(), Mode::Fault);
        s.reset(1.0);
        assert_eq!(s.mode(), Mode::Idle);
        assert_eq!(
            s.last_transition(),
            Some(Transition {
                from: Mode::Fault,
                to: Mode::Idle,
                at: 1.0
            })
        );
    }

    #[test]
    fn garbage_actions_are_rejected() {
        let cfg = SafetyConfig::default();
        let ok = |d: [f64; 4]| Supervisor::check_action(&cfg, &d);
        assert_eq!(ok([0.0, -0.0, 0.01, 0.01]), Ok(()));
        assert_eq!(
            ok([f64::MIN_POSITIVE / 4.0, 0.0, 0.0, 0.0]),
            Ok(()),
            "denormal"
        );
        assert_eq!(ok([f64::NAN, 0.0, 0.0, 0.0]), Err(Rejection::NonFinite));
        assert_eq!(
            ok([0.0, 0.0, 0.0, f64::INFINITY]),
            Err(Rejection::NonFinite)
        );
        assert_eq!(ok([0.0, 0.2, 0.0, 0.0]), Err(Rejection::OutOfRange));
        assert_eq!(ok([0.0, 0.0, 0.0, -1.0]), Err(Rejection::OutOfRange));
        assert_eq!(ok([1e300, 0.0, 0.0, 0.0]), Err(Rejection::OutOfRange));
    }

    #[test]
    fn a_limit_fault_never_hides_a_non_finite_value_in_a_later_joint() {
        let cfg = SafetyConfig::default();
        let model = robot_model::descriptions::builtin("panda").unwrap();
        let ok_q = robot_model::descriptions::PANDA_READY_Q;
        let speed = crate::SpeedLimits::new(&crate::SpeedLimitSource::Urdf, &model).unwrap();
        let check = |q: &[f64], v: &[f64], w: Option<&[f64; 6]>| {
            Supervisor::check_state(&cfg, &model, &speed, q, v, w)
        };
        let mut q = ok_q;
        q[0] = 10.0; // joint 0 far past its limit
        let zero = [0.0; 7];
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for k in 1..7 {
                let mut v = zero;
                v[k] = bad;
                assert_eq!(check(&q, &v, None), Err(FaultReason::NonFiniteState));
                let mut q2 = q;
                q2[k] = bad;
                assert_eq!(check(&q2, &zero, None), Err(FaultReason::NonFiniteState));
            }
            let mut w = [0.0; 6];
            w[5] = bad;
            assert_eq!(check(&q, &zero, Some(&w)), Err(FaultReason::NonFiniteState));
        }
        // Every joint is checked: the first one at fault is reported.
        let mut v = zero;
        v[6] = 100.0;
        assert_eq!(
            check(&ok_q, &v, None),
            Err(FaultReason::JointVelocityLimit { joint: 6, v: 100.0 })
        );
        assert_eq!(
            check(&q, &v, None),
            Err(FaultReason::JointPositionLimit { joint: 0, q: 10.0 })
        );
        assert_eq!(check(&ok_q, &zero, Some(&[0.0; 6])), Ok(()));
    }
}
