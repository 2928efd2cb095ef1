//! The control cycle under arbitrary messages: the case strategy (hardware
//! states and policy actions with NaN, ±inf, huge values, denormals and
//! torn headers in every field) and the properties every cycle keeps.
//! Shared by tests/fuzz_cycle.rs (a few thousand cases per test run) and
//! examples/fuzz_cycle.rs (the long run).
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use robot_model::Model;
use robot_model::descriptions::{IIWA14_HOME_Q, PANDA_READY_Q, builtin};
use rt_controller::cycle::fault_code;
use rt_controller::supervisor::Supervisor;
use rt_controller::{ControlCycle, ControllerConfig};
use shared_mem_schema::{
    ControllerMode, HardwareState, MAX_JOINTS, Message, PolicyAction, SCHEMA_VERSION, SensorFrame,
    TorqueCommand, rates::CONTROL_PERIOD_NS,
};
use std::sync::OnceLock;

/// A robot of the fuzz: its model and the pose its nominal states are
/// spread around.
pub struct Robot {
    pub model: Model,
    pub home: [f64; 7],
}

/// The Panda and the iiwa 14, loaded once.
pub fn robots() -> &'static [Robot; 2] {
    static ROBOTS: OnceLock<[Robot; 2]> = OnceLock::new();
    ROBOTS.get_or_init(|| {
        let load = |name, home| Robot {
            model: builtin(name).expect("a built-in robot"),
            home,
        };
        [load("panda", PANDA_READY_Q), load("iiwa14", IIWA14_HOME_Q)]
    })
}

/// Fields of the state a nasty value can replace: q, v and the measured
/// torques over all `MAX_JOINTS` slots (the ones past the robot's joints
/// included), then the wrench.
pub const STATE_FIELDS: usize = 3 * MAX_JOINTS + 6;

/// Header fields that are consistent unless torn (`Some`).
#[derive(Debug, Clone)]
pub struct Torn {
    pub schema_version: Option<u32>,
    pub n_joints: Option<u32>,
    pub episode: Option<u64>,
    pub step: Option<u64>,
    pub t_hw_ns: Option<u64>,
    pub seq: u64,
}

/// One cycle's input.
#[derive(Debug, Clone)]
pub struct Cycle {
    /// Per field, in [-1, 1]: where in its nominal range the value lies.
    pub unit: Vec<f64>,
    /// Nasty values replacing fields (index into the fields, value).
    pub nasty: Vec<(usize, f64)>,
    pub header: Torn,
    /// The action due in this cycle: (Δx, Δy, Δz, Δroll), sequence number,
    /// its header's schema version, episode and step.
    pub action: Option<([f64; 4], u64, u32, u64, u64)>,
    /// An explicit reset ([`ControlCycle::reset`]) before the cycle.
    pub reset: bool,
}

/// One case: a robot and a run of cycles on one fresh controller.
#[derive(Debug, Clone)]
pub struct Case {
    pub robot: usize,
    pub cycles: Vec<Cycle>,
}

/// NaN, ±inf, the extremes, denormals, signed zero, huge values, values
/// around the joint and wrench limits, and any bit pattern at all.
pub fn nasty() -> impl Strategy<Value = f64> {
    let special = proptest::sample::select(vec![
        f64::NAN,
        -f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::MAX,
        f64::MIN,
        f64::MIN_POSITIVE,
        -f64::MIN_POSITIVE / 1024.0,
        5e-324,
        -0.0,
        1e155,
        -1e200,
        1e300,
    ]);
    prop_oneof![
        3 => special,
        2 => -4.0..4.0f64,
        1 => -300.0..300.0f64,
        1 => proptest::num::f64::ANY,
        1 => any::<u64>().prop_map(f64::from_bits),
    ]
}

fn torn<T: Arbitrary + Clone + 'static>() -> impl Strategy<Value = Option<T>> {
    proptest::option::weighted(0.05, any::<T>())
}

fn header() -> impl Strategy<Value = Torn> {
    (
        torn::<u32>(),
        torn::<u32>(),
        proptest::option::weighted(0.08, prop_oneof![0..4u64, any::<u64>()]),
        torn::<u64>(),
        torn::<u64>(),
        any::<u64>(),
    )
        .prop_map(
            |(schema_version, n_joints, episode, step, t_hw_ns, seq)| Torn {
                schema_version,
                n_joints,
                episode,
                step,
                t_hw_ns,
                seq,
            },
        )
}

fn action() -> impl Strategy<Value = ([f64; 4], u64, u32, u64, u64)> {
    let component = prop_oneof![6 => -0.015..0.015f64, 1 => nasty()];
    (
        [
            component.clone(),
            component.clone(),
            component.clone(),
            component,
        ],
        any::<u64>(),
        prop_oneof![9 => Just(SCHEMA_VERSION), 1 => any::<u32>()],
        any::<u64>(),
        any::<u64>(),
    )
}

fn cycle() -> impl Strategy<Value = Cycle> {
    (
        proptest::collection::vec(-1.0..=1.0f64, STATE_FIELDS),
        prop_oneof![
            3 => Just(Vec::new()),
            2 => proptest::collection::vec((0..STATE_FIELDS, nasty()), 1..4),
        ],
        header(),
        proptest::option::weighted(0.4, action()),
        proptest::bool::weighted(0.1),
    )
        .prop_map(|(unit, nasty, header, action, reset)| Cycle {
            unit,
            nasty,
            header,
            action,
            reset,
        })
}

/// A robot and 1 to 16 cycles.
pub fn case() -> impl Strategy<Value = Case> {
    (0..2usize, proptest::collection::vec(cycle(), 1..=16))
        .prop_map(|(robot, cycles)| Case { robot, cycles })
}

/// The state message of `c`: nominal values (around the robot's pose,
/// within its limits, moderate speeds, torques and wrench) with the nasty
/// ones put in and the header torn where asked. `prev` is the state of the
/// cycle before (its episode, step and time continue).
fn state_of(robot: &Robot, c: &Cycle, prev: &HardwareState) -> HardwareState {
    let nv = robot.model.nv();
    let effort = robot.model.effort_limits();
    let mut s = HardwareState::empty(nv);
    // Past the robot's joints: around 0, torques around ±1 N·m.
    let home = |i: usize| if i < nv { robot.home[i] } else { 0.0 };
    let tau_max = |i: usize| if i < nv { effort[i] } else { 1.0 };
    let (q, rest) = c.unit.split_at(MAX_JOINTS);
    let (v, rest) = rest.split_at(MAX_JOINTS);
    let (tau, wrench) = rest.split_at(MAX_JOINTS);
    let mut fields = Vec::with_capacity(STATE_FIELDS);
    fields.extend(q.iter().enumerate().map(|(i, u)| home(i) + 0.3 * u));
    fields.extend(v.iter().copied());
    fields.extend(tau.iter().enumerate().map(|(i, u)| 0.5 * tau_max(i) * u));
    // Forces within ±40 N, moments within ±6 N·m: under the overload limits.
    fields.extend(
        wrench
            .iter()
            .enumerate()
            .map(|(k, u)| if k < 3 { 40.0 * u } else { 6.0 * u }),
    );
    for &(k, x) in &c.nasty {
        fields[k] = x;
    }
    s.q.copy_from_slice(&fields[..MAX_JOINTS]);
    s.v.copy_from_slice(&fields[MAX_JOINTS..2 * MAX_JOINTS]);
    s.tau_measured
        .copy_from_slice(&fields[2 * MAX_JOINTS..3 * MAX_JOINTS]);
    s.wrench.copy_from_slice(&fields[3 * MAX_JOINTS..]);
    let h = &c.header;
    s.header.schema_version = h.schema_version.unwrap_or(SCHEMA_VERSION);
    s.n_joints = h.n_joints.unwrap_or(nv as u32);
    s.header.episode = h.episode.unwrap_or(prev.header.episode);
    s.step = h.step.unwrap_or(prev.step.wrapping_add(1));
    s.header.t_hw_ns = h
        .t_hw_ns
        .unwrap_or(prev.header.t_hw_ns.wrapping_add(CONTROL_PERIOD_NS));
    s.header.seq = h.seq;
    s
}

/// The fault code the state itself must raise (checks in the supervisor's
/// order: any non-finite value, then joint by joint position and speed,
/// then force, then moment), or `None` for a valid state.
fn expected_fault(robot: &Robot, cfg: &ControllerConfig, s: &HardwareState) -> Option<u32> {
    let nv = robot.model.nv();
    let (q, v, w) = (&s.q[..nv], &s.v[..nv], &s.wrench);
    let finite = |x: &[f64]| x.iter().all(|x| x.is_finite());
    if !finite(q) || !finite(v) || !finite(w) {
        return Some(1);
    }
    let c = &cfg.safety;
    for (k, j) in robot.model.joints[1..].iter().enumerate() {
        let tol = c.position_limit_tolerance_rad;
        if q[k] < j.limits.lower - tol || q[k] > j.limits.upper + tol {
            return Some(2);
        }
        if v[k].abs() > j.limits.velocity * c.velocity_fault_scale {
            return Some(3);
        }
    }
    if (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt() > c.max_force_n {
        return Some(4);
    }
    if (w[3] * w[3] + w[4] * w[4] + w[5] * w[5]).sqrt() > c.max_moment_nm {
        return Some(5);
    }
    None
}

/// Runs `case` on a fresh controller and checks every cycle: no panic;
/// torques finite, within the effort limits and within the rate limit of
/// the command before (after a new episode: of the measured torques the
/// limiter restarts from, when they are finite); nothing past the robot's
/// joints; the sensor frame's mode and fault code as the state demands
/// (a fault latches its first reason, across episodes, until a reset).
pub fn check(case: &Case) -> Result<(), TestCaseError> {
    let robot = &robots()[case.robot];
    let model = &robot.model;
    let nv = model.nv();
    let cfg = ControllerConfig::default();
    let mut cc = ControlCycle::new(model, cfg.clone()).expect("the default configuration");
    let effort = model.effort_limits();
    let rate = cfg.qp.torque_rate_limit_nm_s * cfg.period_s;
    let mut cmd = TorqueCommand::empty(nv);
    let mut frame = *SensorFrame::boxed_zeroed();
    let mut prev_state = HardwareState::empty(nv);
    prev_state.header.episode = 1;
    let mut prev_cmd = vec![0.0; nv];
    let mut latched: Option<u32> = None;
    let mut seed_pending = true;
    for (k, c) in case.cycles.iter().enumerate() {
        let s = state_of(robot, c, &prev_state);
        // A reset clears a latched fault and restarts the limiter; a new
        // episode restarts it too, but leaves a latched fault latched.
        if c.reset {
            let resets = cc.resets();
            prop_assert_eq!(cc.reset(prev_state.header.t_hw_ns), latched.is_some());
            prop_assert_eq!(cc.resets(), resets + u64::from(latched.is_some()));
            if latched.take().is_some() {
                seed_pending = true;
            }
        }
        let new_episode = cc.episode() != Some(s.header.episode);
        if new_episode && latched.is_none() {
            seed_pending = true;
        }
        let from_state = expected_fault(robot, &cfg, &s);
        let expected = latched.or(from_state);
        let action = c.action.map(|(delta, seq, version, episode, step)| {
            let mut a = PolicyAction::new(seq, 0, delta);
            a.header.schema_version = version;
            a.header.episode = episode;
            a.apply_at_step = step;
            a
        });
        cc.cycle(model, &s, action.as_ref(), k as u64, &mut cmd, &mut frame);

        let tau = &cmd.tau[..nv];
        // The rate limit's reference: the command before, except in the
        // cycle that restarts the limiter (the first finite state of an
        // episode), which starts from the measured torques if all are
        // finite (and from h(q, v), unknown here, otherwise).
        let reference: Option<Vec<f64>> = if seed_pending && from_state != Some(1) {
            seed_pending = false;
            let meas = &s.tau_measured[..nv];
            meas.iter().all(|t| t.is_finite()).then(|| {
                meas.iter()
                    .zip(effort.iter())
                    .map(|(t, m)| t.max(-m).min(*m))
                    .collect()
            })
        } else {
            Some(prev_cmd.clone())
        };
        for (i, (&t, &m)) in tau.iter().zip(effort.iter()).enumerate() {
            prop_assert!(t.is_finite(), "cycle {k}: torque {i} = {t}");
            prop_assert!(
                t.abs() <= m,
                "cycle {k}: torque {i} = {t} past its limit {m}"
            );
            if let Some(r) = &reference {
                let tol = 1e-9 * (1.0 + r[i].abs());
                prop_assert!(
                    (t - r[i]).abs() <= rate + tol,
                    "cycle {k}: torque {i} moved from {} to {t}",
                    r[i]
                );
            }
        }
        prop_assert!(cmd.tau[nv..].iter().all(|&t| t == 0.0));
        prop_assert_eq!(cmd.n_joints as usize, nv);
        prop_assert_eq!(frame.n_joints as usize, nv);
        prop_assert_eq!(&frame.tau_cmd, &cmd.tau);

        let code = frame.fault_code;
        prop_assert_eq!(
            code,
            expected.unwrap_or(0),
            "cycle {}: fault {:?}, state {:?}",
            k,
            cc.data.supervisor.fault(),
            s
        );
        prop_assert_eq!(code, fault_code(cc.data.supervisor.fault()));
        let fault = frame.mode == ControllerMode::Fault as u32;
        prop_assert_eq!(
            fault,
            expected.is_some(),
            "cycle {}: mode {}",
            k,
            frame.mode
        );
        if let Some(code) = expected {
            latched = Some(code);
        }
        // The state check agrees with this model of it.
        let speed = cc.controller().speed_limits();
        let (q, v) = (&s.q[..nv], &s.v[..nv]);
        let checked = Supervisor::check_state(&cfg.safety, model, speed, q, v, Some(&s.wrench));
        prop_assert_eq!(checked.err().map(|r| fault_code(Some(r))), from_state);
        prev_cmd.copy_from_slice(tau);
        prev_state = s;
    }
    Ok(())
}
