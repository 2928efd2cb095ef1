//! The simulated arm driven by rt-controller's control cycle at 1 kHz with
//! 20 Hz actions, as the deployed stack runs it in lockstep (minus the
//! processes): hw-sim's hardware state → `ControlCycle` → torque command →
//! physics step, the same code as the daemon and the learner's fast path.
#![allow(dead_code)]

use hw_sim::{SimHardware, World, WorldConfig};
use nalgebra::{Isometry3, Vector3};
use robot_model::Model;
use rt_controller::{ControlCycle, ControllerConfig, ControllerData};
use shared_mem_schema::rates::{ACTION_PERIOD_STEPS, CONTROL_PERIOD_S};
use shared_mem_schema::{
    HardwareState, Message, PolicyAction, SensorFrame, TorqueCommand, hw_time_ns,
};

/// A policy action: Δx, Δy, Δz (m), Δroll (rad).
pub type Action = [f64; 4];

/// The zero action (keeps the controller running without moving).
pub const ZERO: Action = [0.0; 4];

pub struct Rig {
    pub world: World,
    pub model: Model,
    pub hardware: SimHardware,
    pub control: ControlCycle,
    pub state: HardwareState,
    pub command: TorqueCommand,
    pub frame: SensorFrame,
    actions: u64,
    /// Lowest peg-tip height relative to the hole's top face seen while
    /// the tip was outside the hole's outline (a pass-through check).
    pub lowest_outside_hole_m: f64,
}

/// A task with the box exactly where the caller says (no randomisation).
pub fn fixed_box_config(center: [f64; 2]) -> WorldConfig {
    let mut c = WorldConfig::default();
    c.task.box_center_xy_m = Some(center);
    c.task.box_xy_range_m = [0.0, 0.0];
    c.task.box_yaw_range_rad = 0.0;
    c
}

impl Rig {
    pub fn new(config: WorldConfig) -> Self {
        let world = World::new(config).expect("world builds");
        let model = world.model().clone();
        let control = ControlCycle::new(&model, ControllerConfig::default()).expect("controller");
        let frame = *SensorFrame::boxed_zeroed();
        Self {
            hardware: SimHardware::new(&world),
            world,
            model,
            control,
            state: HardwareState::empty(0),
            command: TorqueCommand::empty(0),
            frame,
            actions: 0,
            lowest_outside_hole_m: f64::INFINITY,
        }
    }

    /// The control law's workspace.
    pub fn data(&self) -> &ControllerData {
        &self.control.data
    }

    /// One 1 kHz cycle: hardware state, control cycle, physics step.
    pub fn cycle(&mut self, action: Option<&Action>) {
        self.control(action);
        self.apply();
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

    /// The control cycle alone: the hardware state of the world now through
    /// rt-controller's cycle, its command left in `self.command`.
    pub fn control(&mut self, action: Option<&Action>) {
        let t = hw_time_ns(self.world.time_s());
        self.hardware.state(&self.world, 1, t, &mut self.state);
        let action = action.map(|&a| {
            self.actions += 1;
            PolicyAction::new(self.actions, t, a)
        });
        self.control.cycle(
            &self.model,
            &self.state,
            action.as_ref(),
            t,
            &mut self.command,
            &mut self.frame,
        );
    }

    /// The physics step under the last command.
    pub fn apply(&mut self) {
        self.hardware
            .apply(&mut self.world, Some(&self.command))
            .expect("finite torques");
    }

    /// Runs `actions` at 20 Hz (one per 50 cycles), then `hold_s` more.
    pub fn run(&mut self, actions: &[Action], hold_s: f64) {
        for a in actions {
            self.cycle(Some(a));
            for _ in 1..ACTION_PERIOD_STEPS {
                self.cycle(None);
            }
        }
        let n = (hold_s / CONTROL_PERIOD_S).round() as u64;
        for k in 0..n {
            // Keep the policy "alive" with zero actions so the controller
            // keeps its running mode (it holds after 100 ms without one).
            self.cycle(if k % ACTION_PERIOD_STEPS == 0 {
                Some(&ZERO)
            } else {
                None
            });
        }
    }

    pub fn tip(&self) -> Isometry3<f64> {
        self.world.peg_tip_pose()
    }
}

/// The insertion script: above the hole, then down to 5 mm below its bottom
/// (the controller's lead limit and impedance turn that into a moderate
/// push).
pub fn insertion_script(rig: &Rig, hole: &Isometry3<f64>) -> Vec<Action> {
    let depth = rig.world.box_geometry().unwrap().depth;
    let start = rig.tip().translation.vector;
    let above = hole * nalgebra::Point3::new(0.0, 0.0, 0.02);
    let bottom = hole * nalgebra::Point3::new(0.0, 0.0, -depth - 0.005);
    script(start, &[(above.coords, 0.005), (bottom.coords, 0.002)])
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
            out.push([s.x, s.y, s.z, 0.0]);
        }
    }
    out
}
