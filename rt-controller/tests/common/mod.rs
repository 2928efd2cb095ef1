//! Closed-loop test bench: the controller against robot-model's forward
//! dynamics, integrated with semi-implicit Euler in sub-steps of the
//! control period (zero-order hold on the torques, as on hardware).
#![allow(dead_code)]

use nalgebra::{Matrix3, Vector3};
use robot_model::Model;
use rt_controller::{Action, Controller, ControllerConfig, ControllerData, RobotState, StepInfo};

/// The Panda's "ready" pose: peg tip at (0.307, 0, 0.470) pointing down.
#[allow(unused_imports)]
pub use robot_model::descriptions::PANDA_READY_Q as PANDA_READY;

pub fn panda() -> Model {
    robot_model::descriptions::builtin("panda").expect("the built-in Panda loads")
}

pub fn iiwa() -> Model {
    robot_model::descriptions::builtin("iiwa14").expect("the built-in iiwa 14 loads")
}

/// Per-cycle record.
#[derive(Clone, Debug)]
pub struct Sample {
    pub t: f64,
    pub q: Vec<f64>,
    pub v: Vec<f64>,
    pub tau: Vec<f64>,
    pub ee_pos: Vector3<f64>,
    pub ee_rot: Matrix3<f64>,
    pub ref_pos: Vector3<f64>,
    pub ref_roll: f64,
    pub info: StepInfo,
}

/// A simulated robot driven by the controller.
pub struct Bench {
    pub model: Model,
    pub ctrl: Controller,
    pub data: ControllerData,
    pub sim: robot_model::Data,
    pub q: Vec<f64>,
    pub v: Vec<f64>,
    pub t: f64,
    pub substeps: usize,
    prev_tau: Option<Vec<f64>>,
    /// Largest torque-limit and torque-rate excess seen (≤ 0 when within).
    pub worst_torque_excess: f64,
    pub worst_rate_excess: f64,
    pub log: Vec<Sample>,
}

impl Bench {
    pub fn new(model: Model, config: ControllerConfig, q0: &[f64]) -> Self {
        let ctrl = Controller::new(&model, config).expect("valid config");
        let data = ctrl.create_data(&model);
        let sim = model.create_data();
        Self {
            q: q0.to_vec(),
            v: vec![0.0; q0.len()],
            model,
            ctrl,
            data,
            sim,
            t: 0.0,
            substeps: 4,
            prev_tau: None,
            worst_torque_excess: f64::NEG_INFINITY,
            worst_rate_excess: f64::NEG_INFINITY,
            log: Vec::new(),
        }
    }

    /// One control cycle followed by one period of simulated dynamics.
    pub fn cycle(&mut self, action: Option<&Action>) -> StepInfo {
        self.cycle_with(action, None)
    }

    /// Same, with an external joint torque added to the plant.
    pub fn cycle_with(&mut self, action: Option<&Action>, disturbance: Option<&[f64]>) -> StepInfo {
        let state = RobotState {
            q: &self.q,
            v: &self.v,
            tau_measured: None,
            wrench: None,
        };
        let info = rt_controller::step(
            &self.model,
            &self.ctrl,
            &mut self.data,
            &state,
            action,
            self.t,
        );
        let tau = self.data.torques().to_vec();
        let limits = self.model.effort_limits();
        let rate = self.ctrl.config().qp.torque_rate_limit_nm_s * self.ctrl.config().period_s;
        for i in 0..tau.len() {
            assert!(tau[i].is_finite(), "non-finite torque at t = {}", self.t);
            self.worst_torque_excess = self.worst_torque_excess.max(tau[i].abs() - limits[i]);
            if let Some(p) = &self.prev_tau {
                self.worst_rate_excess = self.worst_rate_excess.max((tau[i] - p[i]).abs() - rate);
            }
        }
        let r = self.data.reference;
        self.log.push(Sample {
            t: self.t,
            q: self.q.clone(),
            v: self.v.clone(),
            tau: tau.clone(),
            ee_pos: self.data.ee.pos,
            ee_rot: self.data.ee.rot,
            ref_pos: r.map_or(self.data.ee.pos, |r| r.pos),
            ref_roll: r.map_or(0.0, |r| r.roll),
            info,
        });
        let mut applied = tau.clone();
        if let Some(d) = disturbance {
            for (a, d) in applied.iter_mut().zip(d) {
                *a += d;
            }
        }
        let period = self.ctrl.config().period_s;
        let h = period / self.substeps as f64;
        for _ in 0..self.substeps {
            let a = robot_model::forward_dynamics(
                &self.model,
                &mut self.sim,
                &self.q,
                &self.v,
                &applied,
            )
            .expect("M is positive definite")
            .clone();
            for i in 0..self.q.len() {
                self.v[i] += h * a[i];
                self.q[i] += h * self.v[i];
            }
        }
        self.prev_tau = Some(tau);
        self.t += period;
        info
    }

    /// Runs `seconds` with an action every `action_every` cycles from `f`.
    pub fn run(
        &mut self,
        seconds: f64,
        action_every: usize,
        mut f: impl FnMut(usize) -> Option<Action>,
    ) {
        let n = (seconds / self.ctrl.config().period_s).round() as usize;
        for k in 0..n {
            let a = if action_every > 0 && k % action_every == 0 {
                f(k / action_every)
            } else {
                None
            };
            self.cycle(a.as_ref());
        }
    }

    pub fn assert_within_limits(&self) {
        assert!(
            self.worst_torque_excess <= 1e-9,
            "torque limit exceeded by {}",
            self.worst_torque_excess
        );
        assert!(
            self.worst_rate_excess <= 1e-9,
            "torque-rate limit exceeded by {}",
            self.worst_rate_excess
        );
    }

    /// End-effector pose from the model at the current state.
    pub fn ee_pose(&mut self) -> (Vector3<f64>, Matrix3<f64>) {
        robot_model::forward_kinematics(&self.model, &mut self.sim, &self.q);
        let p = robot_model::frame_se3(&self.model, &self.sim, self.ctrl.ee_frame());
        (p.trans, p.rot)
    }
}

pub fn action(dx: f64, dy: f64, dz: f64, droll: f64) -> Action {
    Action::from([dx, dy, dz, droll])
}
