//! The simulated arm driven by rt-controller's control core at 1 kHz with
//! 20 Hz actions, as the deployed stack runs it (minus the processes).
#![allow(dead_code)]

use hw_sim::{World, WorldConfig};
use nalgebra::{Isometry3, Vector3};
use robot_model::Model;
use rt_controller::{Action, Controller, ControllerConfig, ControllerData, RobotState};

pub struct Rig {
    pub world: World,
    pub model: Model,
    pub ctrl: Controller,
    pub data: ControllerData,
    /// Lowest peg-tip height relative to the hole's top face seen while
    /// the tip was outside the hole's outline (a pass-through check).
    pub lowest_outside_hole_m: f64,
}

/// A task with the box exactly where the caller says (no randomisation).
pub fn fixed_box_config(center: [f64; 2]) -> WorldConfig {
    let mut c = WorldConfig::default();
    c.task.box_center_xy_m = center.to_vec();
    c.task.box_xy_range_m = [0.0, 0.0];
    c.task.box_yaw_range_rad = 0.0;
    c
}

impl Rig {
    pub fn new(config: WorldConfig) -> Self {
        let world = World::new(config).expect("world builds");
        let model = world.model().clone();
        let ctrl = Controller::new(&model, ControllerConfig::default()).expect("controller");
        let data = ctrl.create_data(&model);
        Self {
            world,
            model,
            ctrl,
            data,
            lowest_outside_hole_m: f64::INFINITY,
        }
    }

    /// One 1 kHz cycle: read the sensors, control step, physics step.
    pub fn cycle(&mut self, action: Option<&Action>) {
        self.control(action);
        self.world
            .step(self.data.torques())
            .expect("finite torques");
        if let (Some(task), Some(b)) = (self.world.task(), self.world.box_geometry()) {
            let s = task.s_m;
            // Outside the hole: farther from its centre than its outline
            // reaches, minus the peg's own half-width.
            let reach = b.hole.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
            if s.x.hypot(s.y) > reach + 0.02 {
                self.lowest_outside_hole_m = self.lowest_outside_hole_m.min(s.z);
            }
        }
    }

    /// The control step alone: rt-controller on the current readings, its
    /// torques left in `self.data`.
    pub fn control(&mut self, action: Option<&Action>) {
        let r = self.world.readings();
        let state = RobotState {
            q: &r.q,
            v: &r.v,
            tau_measured: None,
            wrench: Some(&r.wrench),
        };
        rt_controller::step(
            &self.model,
            &self.ctrl,
            &mut self.data,
            &state,
            action,
            r.t_s,
        );
    }

    /// Runs `actions` at 20 Hz (one per 50 cycles), then `hold_s` more.
    pub fn run(&mut self, actions: &[Action], hold_s: f64) {
        for a in actions {
            self.cycle(Some(a));
            for _ in 1..50 {
                self.cycle(None);
            }
        }
        let n = (hold_s / 0.001).round() as usize;
        for k in 0..n {
            // Keep the policy "alive" with zero actions so the controller
            // keeps its running mode (it holds after 100 ms without one).
            let zero = Action {
                delta_pos_m: [0.0; 3],
                delta_roll_rad: 0.0,
            };
            self.cycle(if k % 50 == 0 { Some(&zero) } else { None });
        }
    }

    pub fn tip(&self) -> Isometry3<f64> {
        self.world.peg_tip_pose()
    }
}

/// An open-loop script of 20 Hz actions through waypoints (base frame, m),
/// moving at most `step_m` per action.
pub fn script(start: Vector3<f64>, waypoints: &[(Vector3<f64>, f64)]) -> Vec<Action> {
    let mut out = Vec::new();
    let mut p = start;
    for &(w, step_m) in waypoints {
        loop {
            let d = w - p;
            let n = d.norm();
            if n < 1e-12 {
                break;
            }
            let s = if n > step_m { d * (step_m / n) } else { d };
            p += s;
            out.push(Action {
                delta_pos_m: [s.x, s.y, s.z],
                delta_roll_rad: 0.0,
            });
        }
    }
    out
}
