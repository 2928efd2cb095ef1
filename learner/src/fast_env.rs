//! The fast path: simulator and control core in one process, in lockstep,
//! with no IPC. It runs exactly what the deployed stack runs in lockstep
//! mode (same order, same time stamps), so both give the same trajectory
//! for the same seed (`lockstep_stack_and_fast_path_give_the_same_trajectory`
//! in the `tests` crate's tests/stack.rs checks it).
//!
//! One cycle k: the hardware state after k physics steps → the control step
//! (with the action addressed to step k, if any) → the physics step. The
//! policy acts every [`ACTION_PERIOD_STEPS`] cycles on the observation of the
//! cycle before the one its action is applied in.

use hw_sim::{SimError, SimHardware, World, WorldConfig};
use learner_node::policy::{Action4, Observation, WrenchHistory};
use learner_node::proprio::roll_reference;
use robot_model::Model;
use rt_controller::{ControlCycle, ControllerConfig, ControllerData};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::{
    HardwareState, Header, Message, PolicyAction, SensorFrame, TorqueCommand, hw_time_ns,
};

/// Why the fast path could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// The world could not be built, or refused a physics step.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The controller configuration does not fit the robot.
    #[error(transparent)]
    Controller(#[from] rt_controller::ConfigError),
}

/// One environment of the fast path.
pub struct FastEnv {
    world: World,
    model: Model,
    hardware: SimHardware,
    control: ControlCycle,
    state: HardwareState,
    command: TorqueCommand,
    episodes: u64,
    /// Wrench readings of every cycle (the policy's window).
    pub wrench: WrenchHistory,
    /// The largest force norm the controller read since the last
    /// [`FastEnv::step`] began, N (the supervisor's overload measure).
    peak_force_n: f64,
    /// The same for the moment norm, N·m.
    peak_moment_nm: f64,
    cycled: bool,
    /// The episode's roll reference: the roll of its first sensor frame.
    roll_ref_rad: f64,
    frame: SensorFrame,
    image: hw_sim::CameraFrame,
    camera_seq: u64,
    action_seq: u64,
}

impl FastEnv {
    /// Builds the world and the controller; call [`FastEnv::reset`] before
    /// stepping.
    pub fn new(world: WorldConfig, controller: ControllerConfig) -> Result<Self, EnvError> {
        let world = World::new(world)?;
        let model = world.model().clone();
        let control = ControlCycle::new(&model, controller)?;
        let frame = *SensorFrame::boxed_zeroed();
        Ok(Self {
            hardware: SimHardware::new(&world),
            world,
            model,
            control,
            state: HardwareState::empty(0),
            command: TorqueCommand::empty(0),
            episodes: 0,
            wrench: WrenchHistory::default(),
            peak_force_n: 0.0,
            peak_moment_nm: 0.0,
            cycled: false,
            roll_ref_rad: 0.0,
            frame,
            image: hw_sim::CameraFrame::default(),
            camera_seq: 0,
            action_seq: 0,
        })
    }

    /// The observation of the last cycle (what the policy node reads from
    /// its sensor frame).
    pub fn last_observation(&self) -> Option<Observation> {
        self.cycled
            .then(|| Observation::from_frame(&self.frame, self.roll_ref_rad))
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
        &self.control.data
    }

    /// The largest force norm read in the cycles of the last
    /// [`FastEnv::step`], N: what the supervisor's force overload compares.
    pub fn peak_force_n(&self) -> f64 {
        self.peak_force_n
    }

    /// The largest moment norm read in the cycles of the last
    /// [`FastEnv::step`], N·m: what the supervisor's moment overload compares.
    pub fn peak_moment_nm(&self) -> f64 {
        self.peak_moment_nm
    }

    /// Starts an episode: as hw-sim's reset with a configuration (a world
    /// built afresh with `seed`); the controller restarts when it sees the
    /// new episode, as the daemon does, after a fault once reset.
    pub fn reset(&mut self, seed: u64) -> Result<(), EnvError> {
        let cfg = self.world.config().clone();
        self.reset_with(cfg, seed)
    }

    /// Starts an episode in another world configuration (same robot). A
    /// fault latched in the episode before is cleared by the explicit reset
    /// the live node sends at this point (`ControlCycle::reset`).
    pub fn reset_with(&mut self, mut cfg: WorldConfig, seed: u64) -> Result<(), EnvError> {
        cfg.seed = seed;
        self.world = World::with_model(self.model.clone(), cfg)?;
        self.control.reset(hw_time_ns(self.world.time_s()));
        self.hardware.reset();
        self.episodes += 1;
        self.wrench.clear();
        self.cycled = false;
        self.camera_seq = 0;
        self.action_seq = 0;
        Ok(())
    }

    /// One control cycle and physics step; `action` is applied in it. The
    /// same cycle as the deployed stack's in lockstep: hw-sim's hardware
    /// state → rt-controller's [`ControlCycle`] → the physics step, with
    /// every time stamp taken from the simulated clock. Returns the action
    /// message the controller got, as a policy node would have sent it
    /// (numbered from 1 per episode, stamped with the observation it
    /// answers, addressed to this step).
    pub fn cycle(&mut self, action: Option<&Action4>) -> Result<Option<PolicyAction>, EnvError> {
        let t = hw_time_ns(self.world.time_s());
        self.hardware
            .state(&self.world, self.episodes, t, &mut self.state);
        let observed = if self.cycled {
            self.frame.header.t_hw_ns
        } else {
            t
        };
        let action = action.map(|&a| {
            self.action_seq += 1;
            let mut m = PolicyAction::new(self.action_seq, observed, a);
            m.header.t_hw_ns = observed;
            m.header.episode = self.episodes;
            m.apply_at_step = self.state.step;
            m
        });
        self.control.cycle(
            &self.model,
            &self.state,
            action.as_ref(),
            t,
            &mut self.command,
            &mut self.frame,
        );
        if !self.cycled {
            self.roll_ref_rad = roll_reference(&self.frame);
        }
        self.cycled = true;
        self.wrench.push(self.frame.wrench);
        let w = &self.frame.wrench;
        let f = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        self.peak_force_n = self.peak_force_n.max(f);
        let m = (w[3] * w[3] + w[4] * w[4] + w[5] * w[5]).sqrt();
        self.peak_moment_nm = self.peak_moment_nm.max(m);
        self.hardware.apply(&mut self.world, Some(&self.command))?;
        Ok(action)
    }

    /// Runs cycles up to the one before the next action step and returns
    /// its observation; `action` (if any) is applied in the first cycle.
    pub fn step(&mut self, action: Option<&Action4>) -> Result<Observation, EnvError> {
        self.peak_force_n = 0.0;
        self.peak_moment_nm = 0.0;
        self.cycle(action)?;
        while !self.world.step_index().is_multiple_of(ACTION_PERIOD_STEPS) {
            self.cycle(None)?;
        }
        Ok(Observation::from_frame(&self.frame, self.roll_ref_rad))
    }
}
