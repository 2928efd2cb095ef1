//! The simulated world: the arm as a rapier multibody in reduced
//! coordinates, the peg on the wrist, the box with its hole, the F/T sensor,
//! the task metrics and the perturbations. A pure object: reset it, command
//! torques, step it, read it.
//!
//! Files: `build` (the physics world, the ground, the arm, the peg and the
//! box, and what the camera draws of them), `perturb` (pushes and
//! occlusions), `sensors` (the F/T wrench, noise and filter, the readings),
//! `task` (the peg, the contact and the stages).

use crate::camera::{Camera, CameraFrame, CameraShot};
use crate::config::WorldConfig;
use crate::convert::{from_glam, pose_from_glam, to_glam};
use crate::rng::{self, SimRng};
use crate::shapes::BoxWithHole;
use nalgebra::{Isometry3, Translation3, Vector3};
use rapier3d_f64::prelude::{MultibodyJointHandle, PhysicsWorld, RigidBodyHandle};
use robot_model::{JointKind, Model, ModelError};
use shared_mem_schema::config::FieldError;

mod build;
mod perturb;
mod sensors;
mod task;

pub use sensors::SensorReadings;
pub use task::{PegInfo, TaskState, peg_info, peg_link};

use build::{BoxState, Peg};
use perturb::ScheduledPush;

/// Why a world could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The robot description did not load.
    #[error("robot description: {0}")]
    Model(#[from] ModelError),
    /// A configuration value is unusable.
    #[error("invalid hw-sim configuration: {0}")]
    Config(#[from] FieldError),
    /// The robot has a joint the simulator cannot build.
    #[error("joint '{joint}': {reason}")]
    UnsupportedJoint {
        /// Joint name.
        joint: String,
        /// Why.
        reason: String,
    },
    /// A torque command of the wrong length.
    #[error("torque command has {got} values, the robot has {expected} joints")]
    TorqueLength {
        /// Values given.
        got: usize,
        /// Joints.
        expected: usize,
    },
    /// A NaN or infinite torque; the step is refused and nothing changes.
    #[error("torque command for joint {joint} is not finite ({value})")]
    NonFiniteTorque {
        /// 0-based joint index.
        joint: usize,
        /// The value.
        value: f64,
    },
    /// A joint state of the wrong length or not finite.
    #[error("joint state: {0}")]
    State(String),
}

/// The default initial pose of the built-in robots: the peg points down
/// about 25 to 35 cm above the floor in front of the robot.
pub fn default_initial_q(model: &Model) -> Vec<f64> {
    match robot_model::descriptions::home_configuration(&model.name) {
        Some(q) => q.to_vec(),
        None => model.neutral_configuration().as_slice().to_vec(),
    }
}

/// The simulated world.
pub struct World {
    config: WorldConfig,
    model: Model,
    physics: PhysicsWorld,
    /// Body per robot-model joint index (0: the fixed base).
    bodies: Vec<RigidBodyHandle>,
    /// Multibody joint per moving joint.
    joints: Vec<MultibodyJointHandle>,
    /// rapier generalized coordinate index per moving joint.
    dof: Vec<usize>,
    /// rapier multibody link id per moving joint.
    link_ids: Vec<usize>,
    /// Joint axis in the child body frame, per moving joint.
    axis: Vec<Vector3<f64>>,
    prismatic: Vec<bool>,
    effort: Vec<f64>,
    peg: Option<Peg>,
    box_state: Option<BoxState>,
    pushes: Vec<ScheduledPush>,
    occlusions: Vec<crate::config::Occlusion>,
    /// Noise streams: joint positions, velocities, force, moment.
    noise_rngs: [SimRng; 4],
    /// This episode's factor on the noise's deviations
    /// (`noise.episode_scale`).
    noise_scale: f64,
    /// The F/T low-pass filter's gain per step.
    ft_alpha: f64,
    step_index: u64,
    q: Vec<f64>,
    v: Vec<f64>,
    tau_applied: Vec<f64>,
    wrench_true: [f64; 6],
    wrench_filtered: [f64; 6],
    readings: SensorReadings,
    task: Option<TaskState>,
    gravity: Vector3<f64>,
    camera: Option<Camera>,
}

impl World {
    /// Builds the world for `config` and resets it to its episode.
    pub fn new(config: WorldConfig) -> Result<Self, SimError> {
        let model = robot_model::descriptions::load(&config.robot)?;
        Self::with_model(model, config)
    }

    /// Builds the world around an already loaded robot.
    pub fn with_model(model: Model, config: WorldConfig) -> Result<Self, SimError> {
        let nv = model.nv();
        config.validate(nv)?;
        for j in &model.joints[1..] {
            if !matches!(
                j.kind,
                JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic
            ) {
                return Err(SimError::UnsupportedJoint {
                    joint: j.name.clone(),
                    reason: "only revolute, continuous and prismatic joints".into(),
                });
            }
            if j.parent + 1 != model.joint_id(&j.name).unwrap_or(0) {
                return Err(SimError::UnsupportedJoint {
                    joint: j.name.clone(),
                    reason: "hw-sim builds serial chains only".into(),
                });
            }
        }
        let mut world = World {
            gravity: model.gravity,
            effort: model.effort_limits().as_slice().to_vec(),
            config,
            model,
            physics: PhysicsWorld::new(),
            bodies: Vec::new(),
            joints: Vec::new(),
            dof: Vec::new(),
            link_ids: Vec::new(),
            axis: Vec::new(),
            prismatic: Vec::new(),
            peg: None,
            box_state: None,
            pushes: Vec::new(),
            occlusions: Vec::new(),
            noise_rngs: [0, 1, 2, 3].map(|k| rng::seeded(0, k)),
            noise_scale: 1.0,
            ft_alpha: 1.0,
            step_index: 0,
            q: vec![0.0; nv],
            v: vec![0.0; nv],
            tau_applied: vec![0.0; nv],
            wrench_true: [0.0; 6],
            wrench_filtered: [0.0; 6],
            readings: SensorReadings {
                t_s: 0.0,
                q: vec![0.0; nv],
                v: vec![0.0; nv],
                tau_applied: vec![0.0; nv],
                wrench: [0.0; 6],
            },
            task: None,
            camera: None,
        };
        world.reset(world.config.seed)?;
        Ok(world)
    }

    /// Rebuilds the world from scratch for a new episode with `seed`: the
    /// box placement, the noise and the random perturbations all follow
    /// from it. Rebuilding (rather than moving bodies back) leaves no solver
    /// state behind, which keeps episodes bit-reproducible.
    pub fn reset(&mut self, seed: u64) -> Result<(), SimError> {
        self.config.seed = seed;
        let cfg = self.config.clone();
        let nv = self.model.nv();
        let peg_info = if cfg.task.enabled {
            Some(peg_info(&self.model, &cfg.task)?)
        } else {
            None
        };
        let mut physics = build::new_physics(&cfg, &self.gravity);
        build::add_ground(&mut physics, &cfg);
        self.build_arm(&mut physics, &cfg)?;
        self.peg = peg_info.map(|info| build::attach_peg(&mut physics, &self.bodies, info, &cfg));

        // Episode randomness: one stream per use. Streams 1–2 are the box
        // and the perturbations, 3 and 5–7 the sensors, 4 the camera, 8 the
        // noise's per-episode scale.
        let mut box_rng = rng::seeded(seed, 1);
        let mut perturb_rng = rng::seeded(seed, 2);
        self.reset_sensors(seed);

        let q0 = cfg
            .initial_q
            .clone()
            .unwrap_or_else(|| default_initial_q(&self.model));
        self.physics = physics;
        self.set_joint_state(&q0, &vec![0.0; nv])?;
        self.box_state = None;
        if cfg.task.enabled {
            self.draw_box(&cfg, &mut box_rng);
        }
        self.schedule_perturbations(&cfg, &mut perturb_rng);
        self.camera = Some(Camera::new(&cfg.camera, self.primitives(), seed));
        self.step_index = 0;
        self.tau_applied.iter_mut().for_each(|t| *t = 0.0);
        self.wrench_true = self.static_wrench();
        self.wrench_filtered = self.wrench_true;
        self.task = None;
        self.update_task(false);
        self.update_readings();
        Ok(())
    }

    /// Renders the camera's view of the current state into `frame`, with
    /// the ground-truth flow from the previous render (normally every
    /// `camera.period_steps` steps: see [`World::camera_due`]).
    pub fn render(&mut self, frame: &mut CameraFrame) {
        let shot = self.camera_shot();
        self.camera
            .as_mut()
            .expect("built at reset")
            .render_shot(&shot, frame);
    }

    /// The current instant as the camera needs it, detached from the world:
    /// a clone of [`World::camera`] can render it on another thread and
    /// produce exactly the frame [`World::render`] would.
    pub fn camera_shot(&self) -> CameraShot {
        let t_s = self.time_s();
        CameraShot {
            links: (0..self.bodies.len()).map(|j| self.link_pose(j)).collect(),
            box_pose: self.hole_pose(),
            t_s,
            occlusions: self.occlusions_at(t_s).map(|o| o.rect).collect(),
            noise: (
                self.noise_scale * self.config.noise.depth_std_m,
                self.noise_scale * self.config.noise.rgb_std,
            ),
        }
    }

    /// This episode's factor on the sensors' noise deviations, drawn at
    /// reset from `noise.episode_scale` (1 when that is `[1, 1]`).
    pub fn noise_scale(&self) -> f64 {
        self.noise_scale
    }

    /// The camera (intrinsics, pose, projection).
    pub fn camera(&self) -> &Camera {
        self.camera.as_ref().expect("built at reset")
    }

    /// Sets the joint positions and velocities (for tests and resets).
    pub fn set_joint_state(&mut self, q: &[f64], v: &[f64]) -> Result<(), SimError> {
        let nv = self.model.nv();
        if q.len() != nv || v.len() != nv {
            return Err(SimError::State(format!(
                "q has {} and v has {} values, the robot has {nv} joints",
                q.len(),
                v.len()
            )));
        }
        if q.iter().chain(v).any(|x| !x.is_finite()) {
            return Err(SimError::State("q and v must be finite".into()));
        }
        self.read_joints();
        let (mb, _) = self
            .physics
            .multibody_joints
            .get_mut(self.joints[0])
            .expect("multibody");
        let mut disp = vec![0.0; mb.ndofs()];
        for k in 0..nv {
            disp[self.dof[k]] = q[k] - self.q[k];
        }
        mb.apply_displacements(&disp);
        {
            let mut gv = mb.generalized_velocity_mut();
            for k in 0..nv {
                gv[self.dof[k]] = v[k];
            }
        }
        mb.forward_kinematics(&self.physics.bodies, false);
        mb.update_rigid_bodies(&mut self.physics.bodies, true);
        self.read_joints();
        // Body velocities follow from the joint rates before the next solve;
        // set them now too so that readers between resets see them.
        self.sync_body_velocities();
        Ok(())
    }

    fn sync_body_velocities(&mut self) {
        let nv = self.model.nv();
        let mut fk = self.model.create_data();
        robot_model::forward_kinematics_second_order(&self.model, &mut fk, &self.q, &self.v, None);
        for j in 1..=nv {
            let pose = fk.o_m_i[j].to_isometry();
            // Spatial velocity of body j in its own frame → world linear
            // velocity of its centre of mass and world angular velocity.
            let vel = fk.v[j];
            let rot = pose.rotation;
            let w = rot * vel.ang;
            let rb = &mut self.physics.bodies[self.bodies[j]];
            let com_local = from_glam(rb.mass_properties().local_mprops.local_com);
            let v_com = rot * (vel.lin + vel.ang.cross(&com_local));
            rb.set_linvel(to_glam(&v_com), false);
            rb.set_angvel(to_glam(&w), false);
        }
    }

    fn read_joints(&mut self) {
        let (mb, _) = self
            .physics
            .multibody_joints
            .get(self.joints[0])
            .expect("multibody");
        let gv = mb.generalized_velocity();
        for (k, &link_id) in self.link_ids.iter().enumerate() {
            let coords = mb.link(link_id).expect("link").joint().coords();
            self.q[k] = if self.prismatic[k] {
                coords[0]
            } else {
                coords[3]
            };
            self.v[k] = gv[self.dof[k]];
        }
    }

    /// Advances the world by one physics step with `tau` (N·m per joint)
    /// held over the step. A non-finite or wrongly sized command is refused
    /// with nothing changed.
    pub fn step(&mut self, tau: &[f64]) -> Result<(), SimError> {
        let nv = self.model.nv();
        if tau.len() != nv {
            return Err(SimError::TorqueLength {
                got: tau.len(),
                expected: nv,
            });
        }
        if let Some((joint, &value)) = tau.iter().enumerate().find(|(_, t)| !t.is_finite()) {
            return Err(SimError::NonFiniteTorque { joint, value });
        }
        let clamp = self.config.clamp_torques;
        for ((applied, &cmd), &lim) in self.tau_applied.iter_mut().zip(tau).zip(&self.effort) {
            *applied = if clamp && lim.is_finite() {
                cmd.clamp(-lim, lim)
            } else {
                cmd
            };
        }
        let t = self.time_s();
        let dt = self.config.dt_s;
        for &h in &self.bodies[1..] {
            let rb = &mut self.physics.bodies[h];
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
        // Joint torques: equal and opposite on child and parent about the
        // joint axis (forces along it for prismatic joints).
        for k in 0..nv {
            let child = self.bodies[k + 1];
            let parent = self.bodies[self.model.joints[k + 1].parent];
            let axis_world = {
                let rb = &self.physics.bodies[child];
                rb.position().rotation * to_glam(&self.axis[k])
            };
            let tau_k = self.tau_applied[k];
            let parent_dynamic = self.physics.bodies[parent].is_dynamic();
            if self.prismatic[k] {
                let f = axis_world * tau_k;
                self.physics.bodies[child].add_force(f, false);
                if parent_dynamic {
                    self.physics.bodies[parent].add_force(-f, false);
                }
            } else {
                let m = axis_world * tau_k;
                self.physics.bodies[child].add_torque(m, false);
                if parent_dynamic {
                    self.physics.bodies[parent].add_torque(-m, false);
                }
            }
        }
        self.apply_pushes(t, dt);

        let before = self.peg_motion();
        self.physics.step();
        self.step_index += 1;
        self.read_joints();
        let after = self.peg_motion();
        self.wrench_true = self.compute_wrench(before, after);
        let contact = self.peg_box_contact();
        self.update_task(contact);
        self.update_readings();
        Ok(())
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.step_index as f64 * self.config.dt_s
    }

    /// Steps since the reset.
    pub fn step_index(&self) -> u64 {
        self.step_index
    }

    /// A camera frame is due after this step (every `camera.period_steps`).
    pub fn camera_due(&self) -> bool {
        self.step_index
            .is_multiple_of(self.config.camera.period_steps as u64)
    }

    /// What the sensors read (noise and bias included).
    pub fn readings(&self) -> &SensorReadings {
        &self.readings
    }

    /// The true joint positions, rad.
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// The true joint velocities, rad/s.
    pub fn v(&self) -> &[f64] {
        &self.v
    }

    /// The true F/T wrench (no filter, noise or bias), sensor frame.
    pub fn wrench_true(&self) -> [f64; 6] {
        self.wrench_true
    }

    /// Task state (None without a task).
    pub fn task(&self) -> Option<&TaskState> {
        self.task.as_ref()
    }

    /// The hole frame in the base frame (None without a task).
    pub fn hole_pose(&self) -> Option<Isometry3<f64>> {
        self.box_state.as_ref().map(|b| b.hole_pose)
    }

    /// The box geometry (None without a task).
    pub fn box_geometry(&self) -> Option<&BoxWithHole> {
        self.box_state.as_ref().map(|b| &b.geometry)
    }

    /// The peg (None without a task).
    pub fn peg(&self) -> Option<&PegInfo> {
        self.peg.as_ref().map(|p| &p.info)
    }

    /// Pose of the body moved by joint `j` (0: the base), base frame.
    pub fn link_pose(&self, j: usize) -> Isometry3<f64> {
        pose_from_glam(self.physics.bodies[self.bodies[j]].position())
    }

    /// The peg tip (the sensor frame moved along the peg by its length).
    pub fn peg_tip_pose(&self) -> Isometry3<f64> {
        match self.peg.as_ref() {
            Some(peg) => {
                self.link_pose(peg.info.link)
                    * peg.info.sensor_in_link
                    * Translation3::new(0.0, 0.0, peg.info.prism.z1)
            }
            None => self.link_pose(peg_link(&self.model)),
        }
    }

    /// The robot model the world was built from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The configuration in force.
    pub fn config(&self) -> &WorldConfig {
        &self.config
    }

    /// The rapier world, read-only (rendering, queries, cross-checks).
    pub fn physics(&self) -> &PhysicsWorld {
        &self.physics
    }
}
