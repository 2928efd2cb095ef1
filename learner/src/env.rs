//! The fast path: simulator and control core in one process, in lockstep,
//! with no IPC. It runs exactly what the deployed stack runs in lockstep
//! mode (same order, same time stamps), so both give the same trajectory
//! for the same seed (tests/lockstep.rs in the `tests` crate checks it).
//!
//! One cycle k: the hardware state after k physics steps → the control step
//! (with the action addressed to step k, if any) → the physics step. The
//! policy acts every [`ACTION_PERIOD`] cycles on the observation of the
//! cycle before the one its action is applied in.

use crate::policy::{Action4, Observation, WrenchHistory};
use hw_sim::{World, WorldConfig};
use nalgebra::{UnitQuaternion, Vector3};
use robot_model::Model;
use rt_controller::{Action, Controller, ControllerConfig, ControllerData, RobotState};
use shared_mem_schema::{Header, Pod, SensorFrame, hw_time_ns, hw_time_s};

/// Control cycles per policy action (20 Hz at 1 kHz).
pub const ACTION_PERIOD: u64 = 50;

/// One environment of the fast path.
pub struct FastEnv {
    world: World,
    model: Model,
    ctrl: Controller,
    data: ControllerData,
    tau_meas: Vec<f64>,
    gravity: robot_model::Data,
    episodes: u64,
    /// Wrench readings of every cycle (the policy's window).
    pub wrench: WrenchHistory,
    last_obs: Option<Observation>,
    frame: SensorFrame,
    image: hw_sim::CameraFrame,
    camera_seq: u64,
    action_seq: u64,
}

impl FastEnv {
    /// Builds the world and the controller; call [`FastEnv::reset`] before
    /// stepping.
    pub fn new(world: WorldConfig, controller: ControllerConfig) -> anyhow::Result<Self> {
        let world = World::new(world)?;
        let model = world.model().clone();
        let ctrl = Controller::new(&model, controller)?;
        let data = ctrl.create_data(&model);
        let gravity = model.create_data();
        Ok(Self {
            tau_meas: vec![0.0; model.nv()],
            world,
            model,
            ctrl,
            data,
            gravity,
            episodes: 0,
            wrench: WrenchHistory::default(),
            last_obs: None,
            frame: *SensorFrame::boxed_zeroed(),
            image: hw_sim::CameraFrame::default(),
            camera_seq: 0,
            action_seq: 0,
        })
    }

    /// The observation of the last cycle.
    pub fn last_observation(&self) -> Option<Observation> {
        self.last_obs.clone()
    }

    /// The sensor frame of the last cycle, as the daemon publishes it.
    pub fn sensor_frame(&self) -> &SensorFrame {
        &self.frame
    }

    /// Renders the camera's view of the current state into `msg` (what
    /// hw-sim publishes), with the ground-truth flow from the previous
    /// render kept in [`FastEnv::rendered`]. Call it when
    /// `world().camera_due()`, as hw-sim does.
    pub fn render_camera(&mut self, msg: &mut shared_mem_schema::CameraFrame) {
        self.world.render(&mut self.image);
        self.camera_seq += 1;
        let t = hw_time_ns(self.world.time_s());
        hw_sim::camera::fill_message(self.world.camera(), &self.image, msg);
        msg.header = Header::new(self.camera_seq, t, t, self.episodes);
    }

    /// The last rendered frame with its ground truth (segmentation, flow).
    pub fn rendered(&self) -> &hw_sim::CameraFrame {
        &self.image
    }

    /// The simulated world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The control law's workspace.
    pub fn controller_data(&self) -> &ControllerData {
        &self.data
    }

    /// Starts an episode: as hw-sim's reset with a configuration (a world
    /// built afresh with `seed`), the controller restarted as the daemon
    /// restarts it when it sees a new episode.
    pub fn reset(&mut self, seed: u64) -> anyhow::Result<()> {
        let cfg = self.world.config().clone();
        self.reset_with(cfg, seed)
    }

    /// Starts an episode in another world configuration (same robot).
    pub fn reset_with(&mut self, mut cfg: WorldConfig, seed: u64) -> anyhow::Result<()> {
        cfg.seed = seed;
        self.world = World::with_model(self.model.clone(), cfg)?;
        let t = hw_time_s(hw_time_ns(self.world.time_s()));
        self.data.restart(t);
        self.episodes += 1;
        self.wrench.clear();
        self.last_obs = None;
        self.camera_seq = 0;
        self.action_seq = 0;
        // Until the first command the brakes hold the arm: the joints then
        // carry the gravity load, which is what the torque sensors read.
        robot_model::gravity(&self.model, &mut self.gravity, self.world.q());
        self.tau_meas.copy_from_slice(self.gravity.g.as_slice());
        Ok(())
    }

    /// One control cycle and physics step; `action` is applied in it.
    pub fn cycle(&mut self, action: Option<&Action4>) -> anyhow::Result<()> {
        let r = self.world.readings();
        let t = hw_time_s(hw_time_ns(self.world.time_s()));
        let wrench = r.wrench;
        let a = action.map(|a| Action {
            delta_pos_m: [a[0], a[1], a[2]],
            delta_roll_rad: a[3],
        });
        if a.is_some() {
            self.action_seq += 1;
        }
        rt_controller::step(
            &self.model,
            &self.ctrl,
            &mut self.data,
            &RobotState {
                q: &r.q,
                v: &r.v,
                tau_measured: Some(&self.tau_meas),
                wrench: Some(&wrench),
            },
            a.as_ref(),
            t,
        );
        self.wrench.push(wrench);
        let ee = &self.data.ee;
        let rot = nalgebra::Rotation3::from_matrix_unchecked(ee.rot);
        let mut twist = [0.0; 6];
        twist.copy_from_slice(ee.twist.as_slice());
        self.last_obs = Some(Observation {
            t_hw_ns: hw_time_ns(self.world.time_s()),
            step: self.world.step_index(),
            episode: self.episodes,
            ee_pos: Vector3::new(ee.pos.x, ee.pos.y, ee.pos.z),
            ee_rot: UnitQuaternion::from_rotation_matrix(&rot),
            ee_twist: twist,
        });
        let nv = self.model.nv();
        let f = &mut self.frame;
        let step = self.world.step_index();
        f.header = Header::new(step + 1, hw_time_ns(t), hw_time_ns(t), self.episodes);
        f.step = step;
        f.action_seq = self.action_seq;
        f.n_joints = nv as u32;
        f.mode = shared_mem_schema::ControllerMode::Running as u32;
        f.q[..nv].copy_from_slice(&r.q);
        f.v[..nv].copy_from_slice(&r.v);
        f.tau_cmd[..nv].copy_from_slice(self.data.torques());
        f.tau_measured[..nv].copy_from_slice(&self.tau_meas);
        f.ee_pos_m = [ee.pos.x, ee.pos.y, ee.pos.z];
        let q = self.last_obs.as_ref().expect("just set").ee_rot;
        f.ee_quat_xyzw = [q.i, q.j, q.k, q.w];
        f.ee_twist = twist;
        f.wrench = wrench;
        self.world.step(self.data.torques())?;
        self.tau_meas
            .copy_from_slice(&self.world.readings().tau_applied);
        Ok(())
    }

    /// Runs cycles up to the one before the next action step and returns
    /// its observation; `action` (if any) is applied in the first cycle.
    pub fn step(&mut self, action: Option<&Action4>) -> anyhow::Result<Observation> {
        self.cycle(action)?;
        while !self.world.step_index().is_multiple_of(ACTION_PERIOD) {
            self.cycle(None)?;
        }
        Ok(self.last_obs.clone().expect("a cycle ran"))
    }
}
