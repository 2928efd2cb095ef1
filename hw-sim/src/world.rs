//! The simulated world: the arm as a rapier multibody in reduced
//! coordinates, the peg on the wrist, the box with its hole, the F/T sensor,
//! the task metrics and the perturbations. A pure object: reset it, command
//! torques, step it, read it.

use crate::camera::{BodyRef, Camera, CameraFrame, CameraShot, Class, Geometry, Primitive};
use crate::config::{ConfigError, TaskConfig, WorldConfig};
use crate::convert::{from_glam, mat_to_glam, pose_from_glam, pose_to_glam, to_glam};
use crate::rng::SimRng;
use crate::shapes::{BoxWithHole, ConvexPrism};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use rapier3d_f64::geometry::NEW_CONTACT_BIT;
use rapier3d_f64::prelude::{
    ColliderBuilder, ColliderHandle, FrictionModel, GenericJointBuilder, Group, InteractionGroups,
    InteractionTestMode, JointAxesMask, MassProperties, MultibodyJointHandle, PairContacts,
    PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};
use rapier3d_f64::utils::OrthonormalBasis;
use robot_model::{JointKind, Model, ModelError, Shape};
use shared_mem_schema::Stage;

/// Why a world could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The robot description did not load.
    #[error("robot description: {0}")]
    Model(#[from] ModelError),
    /// A configuration value is unusable.
    #[error(transparent)]
    Config(#[from] ConfigError),
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

/// The task state at the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskState {
    /// The peg tip's position relative to the hole frame (centre of the
    /// opening, z up): the paper's s. The goal is (0, 0, −depth).
    pub s_m: Vector3<f64>,
    /// The peg's roll about the hole's z axis relative to the hole, wrapped
    /// into (−π/k, π/k] for a peg with k-fold symmetry: the paper's s_ψ.
    pub s_psi_rad: f64,
    /// The peg touches the box at this step.
    pub in_contact: bool,
    /// The stage reached at this step.
    pub stage_now: Stage,
    /// The best stage reached in the episode so far.
    pub best_stage: Stage,
}

/// What the sensors read at the current step (noise and bias included).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorReadings {
    /// Simulated time, s.
    pub t_s: f64,
    /// Joint positions, rad.
    pub q: Vec<f64>,
    /// Joint velocities, rad/s.
    pub v: Vec<f64>,
    /// Torques applied in the last step (after saturation), N·m.
    pub tau_applied: Vec<f64>,
    /// Wrench the peg exerts on the flange, in the sensor frame (fx, fy,
    /// fz in N, mx, my, mz in N·m about the sensor origin).
    pub wrench: [f64; 6],
}

/// The peg, as mounted on the sensor.
#[derive(Clone, Debug)]
pub struct PegInfo {
    /// Its prism in the sensor frame (z along the peg, from the sensor face).
    pub prism: ConvexPrism,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the sensor frame.
    pub com_sensor: Vector3<f64>,
    /// Inertia about the centre of mass, in the sensor frame.
    pub inertia_sensor: Matrix3<f64>,
    /// The sensor frame in the frame of the link that carries it.
    pub sensor_in_link: Isometry3<f64>,
    /// Joint index (robot-model numbering) of the link that carries it.
    pub link: usize,
}

/// The joint index whose body carries the F/T sensor (and the peg).
pub fn peg_link(model: &Model) -> usize {
    for name in ["ft_sensor", "flange"] {
        if let Ok(f) = model.frame_id(name) {
            return model.frames[f].parent_joint;
        }
    }
    model.nv()
}

/// The peg a task configuration describes, on `model`'s sensor link.
pub fn peg_info(model: &Model, task: &TaskConfig) -> Result<PegInfo, SimError> {
    let link = peg_link(model);
    let t = task;
    let sensor_in_link = ["ft_sensor", "flange"]
        .iter()
        .find_map(|n| model.frame_id(n).ok())
        .map(|f| model.frames[f].placement.to_isometry())
        .unwrap_or_else(Isometry3::identity);
    let length = if t.peg_length_m > 0.0 {
        t.peg_length_m
    } else if let Ok(tip) = model.frame_id("peg_tip") {
        let tip = model.frames[tip].placement.to_isometry();
        (sensor_in_link.inverse() * tip).translation.vector.norm()
    } else {
        0.08
    };
    if length <= 0.0 {
        return Err(ConfigError {
            field: "task.peg_length_m".into(),
            reason: "the peg_tip frame coincides with the sensor; set a length".into(),
        }
        .into());
    }
    let prism = ConvexPrism {
        polygon: t.peg.outline(t.peg_width_m),
        z0: 0.0,
        z1: length,
    };
    let mass_kg = prism.volume() * t.peg_density_kg_m3;
    // Inertia of the prism from its hull (rapier's own computation, so
    // the sensor model and the physics agree on it).
    let pts: Vec<_> = prism
        .points()
        .iter()
        .map(|p| to_glam(&Vector3::new(p[0], p[1], p[2])))
        .collect();
    let mp = ColliderBuilder::convex_hull(&pts)
        .expect("peg hull")
        .density(t.peg_density_kg_m3)
        .build()
        .mass_properties();
    let frame = crate::convert::rot_from_glam(mp.principal_inertia_local_frame)
        .to_rotation_matrix()
        .into_inner();
    let principal = Matrix3::from_diagonal(&from_glam(mp.principal_inertia()));
    Ok(PegInfo {
        prism,
        mass_kg,
        com_sensor: from_glam(mp.local_com),
        inertia_sensor: frame * principal * frame.transpose(),
        sensor_in_link,
        link,
    })
}

struct Peg {
    info: PegInfo,
    colliders: Vec<ColliderHandle>,
}

struct BoxState {
    geometry: BoxWithHole,
    hole_pose: Isometry3<f64>,
    colliders: Vec<ColliderHandle>,
}

#[derive(Clone, Copy, Debug)]
struct ScheduledPush {
    start_s: f64,
    duration_s: f64,
    link: usize,
    force: Vector3<f64>,
}

/// A camera occlusion scheduled for the episode (a rectangle in pixels,
/// or the whole image).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduledOcclusion {
    /// Start, s.
    pub start_s: f64,
    /// End, s.
    pub end_s: f64,
    /// `[x, y, w, h]`, or `None` for the whole image.
    pub rect: Option<[u32; 4]>,
}

const ARM: Group = Group::GROUP_1;
const PEG: Group = Group::GROUP_2;
const BOX: Group = Group::GROUP_3;
const GROUND: Group = Group::GROUP_4;

fn groups(member: Group, filter: Group) -> InteractionGroups {
    InteractionGroups::new(member, filter, InteractionTestMode::And)
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
    occlusions: Vec<ScheduledOcclusion>,
    /// Noise streams: joint positions, velocities, force, moment.
    noise_rngs: [SimRng; 4],
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
            noise_rngs: [0, 1, 2, 3].map(|k| SimRng::new(0, k)),
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
        let mut physics = PhysicsWorld::new();
        physics.gravity = to_glam(&self.gravity);
        let ip = &mut physics.integration_parameters;
        ip.dt = cfg.dt_s;
        ip.num_solver_iterations = cfg.solver_iterations;
        ip.length_unit = cfg.length_unit_m;
        ip.friction_model = FrictionModel::Coulomb;
        // rapier's default recycling distance (0.05 length units, 0.5 mm)
        // is too coarse for millimetre clearances; ours is in metres.
        ip.contact_recycling = cfg.contact_recycle_distance_m > 0.0;
        ip.normalized_contact_recycle_distance = cfg.contact_recycle_distance_m / cfg.length_unit_m;

        // Ground: a slab whose top face is z = 0.
        let ground_body = physics
            .bodies
            .insert(RigidBodyBuilder::fixed().translation(to_glam(&Vector3::new(0.0, 0.0, -0.05))));
        physics.colliders.insert_with_parent(
            ColliderBuilder::cuboid(3.0, 3.0, 0.05)
                .collision_groups(groups(GROUND, ARM | PEG))
                .friction(cfg.task.friction),
            ground_body,
            &mut physics.bodies,
        );

        // The arm, built at q = 0 (where every body frame equals the joint
        // frame of robot-model), then moved to the initial pose.
        let mut fk = self.model.create_data();
        robot_model::forward_kinematics(&self.model, &mut fk, &vec![0.0; nv]);
        self.bodies.clear();
        self.joints.clear();
        self.dof.clear();
        self.link_ids.clear();
        self.axis.clear();
        self.prismatic.clear();
        let peg_info = if cfg.task.enabled {
            Some(peg_info(&self.model, &cfg.task)?)
        } else {
            None
        };
        for j in 0..=nv {
            let pose = fk.o_m_i[j].to_isometry();
            let builder = if j == 0 {
                RigidBodyBuilder::fixed()
            } else {
                let inertia = self.model.inertias[j];
                let props = MassProperties::with_inertia_matrix(
                    to_glam(&inertia.com()),
                    inertia.mass,
                    mat_to_glam(&inertia.inertia_about_com()),
                );
                RigidBodyBuilder::dynamic()
                    .additional_mass_properties(props)
                    .can_sleep(false)
            };
            let handle = physics.bodies.insert(builder.pose(pose_to_glam(&pose)));
            for geom in
                self.model.geometries.iter().filter(|g| {
                    g.role == robot_model::GeometryRole::Collision && g.parent_joint == j
                })
            {
                if let Some(collider) = collider_for(&geom.shape) {
                    let local = geom.placement.to_isometry() * collider.1;
                    physics.colliders.insert_with_parent(
                        collider
                            .0
                            .position(pose_to_glam(&local))
                            .density(0.0)
                            .collision_groups(groups(ARM, BOX | GROUND))
                            .friction(cfg.task.friction),
                        handle,
                        &mut physics.bodies,
                    );
                }
            }
            self.bodies.push(handle);
        }
        for j in 1..=nv {
            let joint = &self.model.joints[j];
            let placement = joint.placement.to_isometry();
            // rapier's free axis is the local x of both joint frames: align x
            // with the joint axis.
            let align = UnitQuaternion::rotation_between(&Vector3::x(), &joint.axis)
                .unwrap_or_else(|| {
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
                });
            let align_iso = Isometry3::from_parts(Translation3::identity(), align);
            let prismatic = joint.kind == JointKind::Prismatic;
            let mask = if prismatic {
                JointAxesMask::LOCKED_PRISMATIC_AXES
            } else {
                JointAxesMask::LOCKED_REVOLUTE_AXES
            };
            let generic = GenericJointBuilder::new(mask)
                .local_frame1(pose_to_glam(&(placement * align_iso)))
                .local_frame2(pose_to_glam(&align_iso))
                .contacts_enabled(false)
                .build();
            let handle = physics
                .multibody_joints
                .insert(self.bodies[joint.parent], self.bodies[j], generic, true)
                .ok_or_else(|| SimError::UnsupportedJoint {
                    joint: joint.name.clone(),
                    reason: "rapier refused the multibody joint".into(),
                })?;
            self.joints.push(handle);
            self.axis.push(joint.axis);
            self.prismatic.push(prismatic);
        }
        {
            let (mb, _) = physics
                .multibody_joints
                .get_mut(self.joints[0])
                .expect("multibody exists");
            mb.set_self_contacts_enabled(false);
            // A new multibody treats its root as free (6 extra coordinates)
            // until forward kinematics sees that the base is fixed.
            mb.forward_kinematics(&physics.bodies, true);
        }
        // Link ids and generalized coordinate indices, looked up once here
        // rather than on every step.
        {
            let (mb, _) = physics
                .multibody_joints
                .get(self.joints[0])
                .expect("multibody");
            for &body in &self.bodies[1..] {
                let id = physics
                    .multibody_joints
                    .rigid_body_link(body)
                    .expect("every moving body is a multibody link")
                    .id;
                self.link_ids.push(id);
                self.dof.push(mb.link(id).expect("link").assembly_id());
            }
        }
        {
            let (mb, _) = physics
                .multibody_joints
                .get_mut(self.joints[0])
                .expect("multibody exists");
            let damping = per_joint(&cfg.joint_damping, nv, |j| self.model.joints[j + 1].damping);
            let friction = per_joint(&cfg.joint_friction, nv, |j| {
                self.model.joints[j + 1].friction
            });
            for k in 0..nv {
                mb.damping_mut()[self.dof[k]] = damping[k];
                mb.frictions_mut()[self.dof[k]] = friction[k];
            }
        }

        // The peg on the sensor.
        self.peg = None;
        if let Some(info) = peg_info {
            let prism_pose = info.sensor_in_link;
            let pts: Vec<_> = info
                .prism
                .points()
                .iter()
                .map(|p| to_glam(&Vector3::new(p[0], p[1], p[2])))
                .collect();
            let collider = ColliderBuilder::convex_hull(&pts)
                .expect("a peg prism has a hull")
                .position(pose_to_glam(&prism_pose))
                .density(cfg.task.peg_density_kg_m3)
                .collision_groups(groups(PEG, BOX | GROUND))
                .friction(cfg.task.friction);
            let h = physics.colliders.insert_with_parent(
                collider,
                self.bodies[info.link],
                &mut physics.bodies,
            );
            self.peg = Some(Peg {
                info,
                colliders: vec![h],
            });
        }

        // Episode randomness: one stream per use.
        let mut box_rng = SimRng::new(seed, 1);
        let mut perturb_rng = SimRng::new(seed, 2);
        // Streams 1–2 are the box and the perturbations, 4 the camera.
        self.noise_rngs = [3, 5, 6, 7].map(|k| SimRng::new(seed, k));
        let hz = cfg.noise.ft_filter_hz;
        self.ft_alpha = if hz > 0.0 {
            1.0 - (-std::f64::consts::TAU * hz * cfg.dt_s).exp()
        } else {
            1.0
        };

        let q0 = if cfg.initial_q.is_empty() {
            default_initial_q(&self.model)
        } else {
            cfg.initial_q.clone()
        };
        self.physics = physics;
        self.set_joint_state(&q0, &vec![0.0; nv])?;

        // The box, placed from the seed.
        self.box_state = None;
        if cfg.task.enabled {
            let t = &cfg.task;
            let center = if t.box_center_xy_m.len() == 2 {
                [t.box_center_xy_m[0], t.box_center_xy_m[1]]
            } else {
                let tip = self.peg_tip_pose().translation.vector;
                [tip.x, tip.y]
            };
            let x = center[0] + box_rng.uniform(-t.box_xy_range_m[0], t.box_xy_range_m[0]);
            let y = center[1] + box_rng.uniform(-t.box_xy_range_m[1], t.box_xy_range_m[1]);
            // The yaw about which the hole fits the peg as the arm starts
            // (s_ψ = 0): the drawn yaw is then a roll error for the policy to
            // correct, never a half turn that ends at the wrist's limit.
            let peg_x = self.peg_tip_pose().rotation * Vector3::x();
            let yaw =
                peg_x.y.atan2(peg_x.x) + box_rng.uniform(-t.box_yaw_range_rad, t.box_yaw_range_rad);
            let peg = &self.peg.as_ref().expect("task has a peg").info;
            // The hole frame has z up and the peg's frame z down the peg:
            // aligned (s_ψ = 0) they differ by a half turn about x, which
            // mirrors y. The hole is the peg's cross-section seen from the
            // hole (mirrored, reversed to stay counter-clockwise); without
            // this, the triangle and the semicircle meet an upside-down hole.
            let seen_from_hole: Vec<[f64; 2]> = peg
                .prism
                .polygon
                .iter()
                .rev()
                .map(|p| [p[0], -p[1]])
                .collect();
            let geometry = BoxWithHole::new(
                &seen_from_hole,
                t.clearance_m,
                t.box_side_m,
                t.box_height_m,
                t.hole_depth_m,
            );
            let hole_pose = Isometry3::new(
                Vector3::new(x, y, t.box_height_m),
                Vector3::new(0.0, 0.0, yaw),
            );
            self.place_box(geometry, hole_pose);
        }

        // Perturbation schedule.
        let p = &cfg.perturbations;
        self.pushes = p
            .pushes
            .iter()
            .map(|push| ScheduledPush {
                start_s: push.start_s,
                duration_s: push.duration_s,
                link: push.link,
                force: Vector3::from(push.force_n),
            })
            .collect();
        for _ in 0..p.random_pushes {
            let start = perturb_rng.uniform(p.random_window_s[0], p.random_window_s[1]);
            let mag = perturb_rng.uniform(p.random_push_force_n[0], p.random_push_force_n[1]);
            let dir = perturb_rng.uniform(0.0, std::f64::consts::TAU);
            self.pushes.push(ScheduledPush {
                start_s: start,
                duration_s: p.random_push_duration_s,
                link: nv,
                force: Vector3::new(mag * dir.cos(), mag * dir.sin(), 0.0),
            });
        }
        self.occlusions = p
            .occlusions
            .iter()
            .map(|o| ScheduledOcclusion {
                start_s: o.start_s,
                end_s: o.end_s,
                rect: (o.rect.len() == 4).then(|| [o.rect[0], o.rect[1], o.rect[2], o.rect[3]]),
            })
            .collect();
        for _ in 0..p.random_occlusions {
            let start = perturb_rng.uniform(p.random_window_s[0], p.random_window_s[1]);
            let side = p.random_occlusion_side_px;
            let x = (perturb_rng.unit() * cfg.camera.width.saturating_sub(side) as f64) as u32;
            let y = (perturb_rng.unit() * cfg.camera.height.saturating_sub(side) as f64) as u32;
            self.occlusions.push(ScheduledOcclusion {
                start_s: start,
                end_s: start + p.random_occlusion_duration_s,
                rect: Some([x, y, side, side]),
            });
        }

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

    fn place_box(&mut self, geometry: BoxWithHole, hole_pose: Isometry3<f64>) {
        let body = self
            .physics
            .bodies
            .insert(RigidBodyBuilder::fixed().pose(pose_to_glam(&hole_pose)));
        let mut colliders = Vec::new();
        for piece in &geometry.pieces {
            let pts: Vec<_> = piece
                .points()
                .iter()
                .map(|p| to_glam(&Vector3::new(p[0], p[1], p[2])))
                .collect();
            let c = ColliderBuilder::convex_hull(&pts)
                .expect("box pieces are convex with volume")
                .collision_groups(groups(BOX, ARM | PEG))
                .friction(self.config.task.friction);
            colliders.push(self.physics.colliders.insert_with_parent(
                c,
                body,
                &mut self.physics.bodies,
            ));
        }
        self.box_state = Some(BoxState {
            geometry,
            hole_pose,
            colliders,
        });
    }

    /// What the camera draws: the collision geometry of every body.
    fn primitives(&self) -> Vec<Primitive> {
        let mut prims = vec![Primitive {
            body: BodyRef::Static,
            local: Isometry3::translation(0.0, 0.0, -0.05),
            geometry: Geometry::Cuboid {
                half: Vector3::new(3.0, 3.0, 0.05),
            },
            class: Class::Ground,
            color: [0.45, 0.45, 0.40],
        }];
        prims.extend(crate::camera::robot_primitives(&self.model));
        if let Some(peg) = &self.peg {
            prims.push(crate::camera::peg_primitive(&peg.info));
        }
        if let Some(b) = &self.box_state {
            for piece in &b.geometry.pieces {
                prims.push(Primitive {
                    body: BodyRef::Box,
                    local: Isometry3::identity(),
                    geometry: crate::camera::prism_geometry(piece),
                    class: Class::Box,
                    color: [0.20, 0.42, 0.85],
                });
            }
        }
        prims
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
            noise: (self.config.noise.depth_std_m, self.config.noise.rgb_std),
        }
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
        for push in &self.pushes {
            let body = self.bodies[push.link];
            let rb = &mut self.physics.bodies[body];
            let origin = rb.position().translation;
            if push.duration_s == 0.0 {
                if t <= push.start_s && push.start_s < t + dt {
                    rb.apply_impulse_at_point(to_glam(&push.force), origin, false);
                }
            } else if t + 0.5 * dt >= push.start_s && t + 0.5 * dt < push.start_s + push.duration_s
            {
                rb.add_force_at_point(to_glam(&push.force), origin, false);
            }
        }

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

    /// (COM velocity, angular velocity, COM position) of the peg, world.
    fn peg_motion(&self) -> Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
        let peg = self.peg.as_ref()?;
        let rb = &self.physics.bodies[self.bodies[peg.info.link]];
        let pose = pose_from_glam(rb.position());
        let c = pose * (peg.info.sensor_in_link * nalgebra::Point3::from(peg.info.com_sensor));
        let body_com = from_glam(rb.mass_properties().world_com);
        let w = from_glam(rb.angvel());
        let v = from_glam(rb.linvel()) + w.cross(&(c.coords - body_com));
        Some((v, w, c.coords))
    }

    /// The F/T reading at rest (weight only), used right after a reset.
    fn static_wrench(&self) -> [f64; 6] {
        match self.peg_motion() {
            Some(m) => self.compute_wrench(Some(m), Some(m)),
            None => [0.0; 6],
        }
    }

    /// Wrench the peg exerts on the flange, from the peg's Newton–Euler
    /// equations: contact forces (normal and friction, per contact point),
    /// its weight, minus its inertial forces.
    fn compute_wrench(
        &self,
        before: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
        after: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
    ) -> [f64; 6] {
        let (Some(peg), Some(before), Some(after)) = (self.peg.as_ref(), before, after) else {
            return [0.0; 6];
        };
        let dt = self.config.dt_s;
        let link_pose = pose_from_glam(self.physics.bodies[self.bodies[peg.info.link]].position());
        let sensor = link_pose * peg.info.sensor_in_link;
        let o = sensor.translation.vector;
        let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
        for &h in &peg.colliders {
            let (cf, cm) = self.contact_wrench_on(h, &o);
            f += cf;
            m += cm;
        }
        let f_c = f / dt;
        let m_c = m / dt;
        let mass = peg.info.mass_kg;
        let a = (after.0 - before.0) / dt;
        let alpha = (after.1 - before.1) / dt;
        let w = after.1;
        let r = sensor.rotation.to_rotation_matrix();
        let inertia = r * peg.info.inertia_sensor * r.transpose();
        let lin = mass * (self.gravity - a);
        let force = f_c + lin;
        let moment = m_c + (after.2 - o).cross(&lin) - (inertia * alpha + w.cross(&(inertia * w)));
        let fs = r.transpose() * force;
        let ms = r.transpose() * moment;
        [fs.x, fs.y, fs.z, ms.x, ms.y, ms.z]
    }

    /// Sum of the contact impulses (normal and tangential) on collider `h`
    /// in the last step and their moment about `o`, world frame, N·s.
    fn contact_wrench_on(
        &self,
        h: ColliderHandle,
        o: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
        for pair in self.physics.narrow_phase.contact_pairs_with(h) {
            let PairContacts::Rigid(rigid) = &pair.contacts else {
                continue;
            };
            // rapier stores impulses as applied to collider1's body.
            let sign = if pair.collider1 == h { 1.0 } else { -1.0 };
            for manifold in rigid.solver_manifolds() {
                let dir1 = -manifold.data.normal;
                let t1 = dir1.orthonormal_vector();
                let t2 = dir1.cross(t1);
                for sc in &manifold.data.solver_contacts {
                    let id = (sc.contact_id[0] & !NEW_CONTACT_BIT) as usize;
                    let Some(point) = manifold.points.get(id) else {
                        continue;
                    };
                    let d = &point.data;
                    let imp =
                        dir1 * d.impulse + t1 * d.tangent_impulse[0] + t2 * d.tangent_impulse[1];
                    let (p1, p2) = manifold
                        .data
                        .solver_contact_world_points(sc, &self.physics.bodies);
                    let p = from_glam((p1 + p2) * 0.5);
                    let imp = from_glam(imp) * sign;
                    f += imp;
                    m += (p - o).cross(&imp);
                }
            }
        }
        (f, m)
    }

    fn peg_box_contact(&self) -> bool {
        let (Some(peg), Some(b)) = (self.peg.as_ref(), self.box_state.as_ref()) else {
            return false;
        };
        peg.colliders.iter().any(|&h| {
            self.physics.narrow_phase.contact_pairs_with(h).any(|pair| {
                let other = if pair.collider1 == h {
                    pair.collider2
                } else {
                    pair.collider1
                };
                b.colliders.contains(&other) && pair.has_any_active_contact()
            })
        })
    }

    fn update_task(&mut self, contact: bool) {
        let (Some(b), Some(_)) = (self.box_state.as_ref(), self.peg.as_ref()) else {
            self.task = None;
            return;
        };
        let tip = self.peg_tip_pose();
        let rel = b.hole_pose.inverse() * tip;
        let s = rel.translation.vector;
        // Roll: the angle of the peg's x axis about the hole's z axis.
        let x = rel.rotation * Vector3::x();
        let raw = x.y.atan2(x.x);
        let k = self.config.task.peg.symmetry_order() as f64;
        let period = std::f64::consts::TAU / k;
        let mut psi = raw.rem_euclid(period);
        if psi > 0.5 * period {
            psi -= period;
        }
        let t = &self.config.task;
        let stage_now = if s.z <= -(b.geometry.depth - t.completed_tolerance_m) {
            Stage::Completed
        } else if s.z <= -t.inserted_depth_m {
            Stage::Inserted
        } else if contact {
            Stage::Touched
        } else {
            Stage::Failed
        };
        let best = self
            .task
            .map(|t| t.best_stage)
            .unwrap_or(Stage::Failed)
            .max(stage_now);
        self.task = Some(TaskState {
            s_m: s,
            s_psi_rad: psi,
            in_contact: contact,
            stage_now,
            best_stage: best,
        });
    }

    fn update_readings(&mut self) {
        let n = &self.config.noise;
        let r = &mut self.readings;
        r.t_s = self.step_index as f64 * self.config.dt_s;
        // One stream per channel, drawn only when its noise is on: noise-free
        // channels cost nothing and turning one on leaves the others' draws.
        let [q_rng, v_rng, f_rng, m_rng] = &mut self.noise_rngs;
        let draw = |rng: &mut SimRng, std: f64| {
            if std > 0.0 { std * rng.normal() } else { 0.0 }
        };
        for k in 0..self.q.len() {
            r.q[k] = self.q[k] + draw(q_rng, n.q_std_rad);
            r.v[k] = self.v[k] + draw(v_rng, n.v_std_rad_s);
            r.tau_applied[k] = self.tau_applied[k];
        }
        let alpha = self.ft_alpha;
        for i in 0..6 {
            self.wrench_filtered[i] += alpha * (self.wrench_true[i] - self.wrench_filtered[i]);
            let noise = if i < 3 {
                draw(f_rng, n.force_std_n)
            } else {
                draw(m_rng, n.torque_std_nm)
            };
            r.wrench[i] = self.wrench_filtered[i] + n.ft_bias[i] + noise;
        }
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

    /// Moves the box so that its hole frame is at `hole_pose` (tests and
    /// scripted set-ups; an episode places it from the seed).
    pub fn set_hole_pose(&mut self, hole_pose: Isometry3<f64>) {
        if let Some(b) = self.box_state.take() {
            let body = self.physics.colliders[b.colliders[0]]
                .parent()
                .expect("box body");
            self.physics.bodies.remove(
                body,
                &mut self.physics.islands,
                &mut self.physics.colliders,
                &mut self.physics.impulse_joints,
                &mut self.physics.multibody_joints,
                &mut self.physics.soft_bodies,
                true,
            );
            self.place_box(b.geometry, hole_pose);
            self.task = None;
            self.update_task(false);
            self.camera = Some(Camera::new(
                &self.config.camera,
                self.primitives(),
                self.config.seed,
            ));
        }
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

    /// The occlusions active at simulated time `t_s`.
    pub fn occlusions_at(&self, t_s: f64) -> impl Iterator<Item = &ScheduledOcclusion> {
        self.occlusions
            .iter()
            .filter(move |o| o.start_s <= t_s && t_s < o.end_s)
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

fn per_joint(values: &[f64], nv: usize, urdf: impl Fn(usize) -> f64) -> Vec<f64> {
    match values.len() {
        0 => (0..nv).map(urdf).collect(),
        1 => vec![values[0]; nv],
        _ => values.to_vec(),
    }
}

/// A rapier collider for a URDF collision shape, with the pose of the
/// rapier shape in the URDF geometry frame (rapier's cylinders run along y,
/// URDF's along z). Meshes are not simulated.
fn collider_for(shape: &Shape) -> Option<(ColliderBuilder, Isometry3<f64>)> {
    let id = Isometry3::identity();
    match shape {
        Shape::Box { size } => Some((
            ColliderBuilder::cuboid(0.5 * size[0], 0.5 * size[1], 0.5 * size[2]),
            id,
        )),
        Shape::Sphere { radius } => Some((ColliderBuilder::ball(*radius), id)),
        Shape::Capsule { radius, length } => {
            Some((ColliderBuilder::capsule_z(0.5 * length, *radius), id))
        }
        Shape::Cylinder { radius, length } => Some((
            ColliderBuilder::cylinder(0.5 * length, *radius),
            Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
        )),
        Shape::Mesh { .. } => None,
    }
}
