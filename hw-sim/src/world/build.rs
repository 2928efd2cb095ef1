//! Building the physics world of an episode: integration parameters, the
//! ground, the arm as a multibody from the robot model, the peg on the
//! sensor, the box from the seed; and what the camera draws of them.

use super::*;
use crate::camera::{BodyRef, Class, Geometry, Primitive};
use crate::convert::{mat_to_glam, pose_to_glam};
use crate::shapes::ConvexPrism;
use nalgebra::UnitQuaternion;
use rapier3d_f64::prelude::{
    ColliderBuilder, ColliderHandle, FrictionModel, GenericJointBuilder, Group, InteractionGroups,
    InteractionTestMode, JointAxesMask, MassProperties, RigidBodyBuilder,
};
use robot_model::Shape;

pub(super) struct Peg {
    pub(super) info: PegInfo,
    pub(super) colliders: Vec<ColliderHandle>,
}

pub(super) struct BoxState {
    pub(super) geometry: BoxWithHole,
    pub(super) hole_pose: Isometry3<f64>,
    pub(super) colliders: Vec<ColliderHandle>,
}

const ARM: Group = Group::GROUP_1;
const PEG: Group = Group::GROUP_2;
const BOX: Group = Group::GROUP_3;
const GROUND: Group = Group::GROUP_4;

/// Half extents of the ground slab, whose top face is z = 0, m (the physics
/// collider and the camera's primitive).
const GROUND_HALF_M: [f64; 3] = [3.0, 3.0, 0.05];

fn groups(member: Group, filter: Group) -> InteractionGroups {
    InteractionGroups::new(member, filter, InteractionTestMode::And)
}

/// A convex-hull collider of a prism (the peg, the box's pieces).
pub(super) fn hull_collider(prism: &ConvexPrism) -> ColliderBuilder {
    let pts: Vec<_> = prism
        .points()
        .iter()
        .map(|p| to_glam(&Vector3::new(p[0], p[1], p[2])))
        .collect();
    ColliderBuilder::convex_hull(&pts).expect("a prism of positive volume has a hull")
}

/// An empty physics world with the configuration's integration parameters.
pub(super) fn new_physics(cfg: &WorldConfig, gravity: &Vector3<f64>) -> PhysicsWorld {
    let mut physics = PhysicsWorld::new();
    physics.gravity = to_glam(gravity);
    let ip = &mut physics.integration_parameters;
    ip.dt = cfg.dt_s;
    ip.num_solver_iterations = cfg.solver_iterations;
    ip.length_unit = cfg.length_unit_m;
    ip.friction_model = FrictionModel::Coulomb;
    // rapier's default recycling distance (0.05 length units, 0.5 mm)
    // is too coarse for millimetre clearances; ours is in metres.
    ip.contact_recycling = cfg.contact_recycle_distance_m > 0.0;
    ip.normalized_contact_recycle_distance = cfg.contact_recycle_distance_m / cfg.length_unit_m;
    physics
}

/// The ground: a fixed slab whose top face is z = 0.
pub(super) fn add_ground(physics: &mut PhysicsWorld, cfg: &WorldConfig) {
    let [hx, hy, hz] = GROUND_HALF_M;
    let ground_body = physics
        .bodies
        .insert(RigidBodyBuilder::fixed().translation(to_glam(&Vector3::new(0.0, 0.0, -hz))));
    physics.colliders.insert_with_parent(
        ColliderBuilder::cuboid(hx, hy, hz)
            .collision_groups(groups(GROUND, ARM | PEG))
            .friction(cfg.task.friction),
        ground_body,
        &mut physics.bodies,
    );
}

/// The peg's collider on the body that carries the sensor.
pub(super) fn attach_peg(
    physics: &mut PhysicsWorld,
    bodies: &[RigidBodyHandle],
    info: PegInfo,
    cfg: &WorldConfig,
) -> Peg {
    let collider = hull_collider(&info.prism)
        .position(pose_to_glam(&info.sensor_in_link))
        .density(cfg.task.peg_density_kg_m3)
        .collision_groups(groups(PEG, BOX | GROUND))
        .friction(cfg.task.friction);
    let h = physics
        .colliders
        .insert_with_parent(collider, bodies[info.link], &mut physics.bodies);
    Peg {
        info,
        colliders: vec![h],
    }
}

impl World {
    /// The arm: one body per link, built at q = 0 (where every body frame
    /// equals the joint frame of robot-model), joined into one multibody
    /// with the joints' damping and friction.
    pub(super) fn build_arm(
        &mut self,
        physics: &mut PhysicsWorld,
        cfg: &WorldConfig,
    ) -> Result<(), SimError> {
        let nv = self.model.nv();
        // frame of robot-model), then moved to the initial pose.
        let mut fk = self.model.create_data();
        robot_model::forward_kinematics(&self.model, &mut fk, &vec![0.0; nv]);
        self.bodies.clear();
        self.joints.clear();
        self.dof.clear();
        self.link_ids.clear();
        self.axis.clear();
        self.prismatic.clear();
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
        Ok(())
    }

    /// Places the box from the seed: about the configured centre (or under
    /// the peg), its yaw about the one that fits the peg at the start.
    pub(super) fn draw_box(&mut self, cfg: &WorldConfig, rng: &mut SimRng) {
        let t = &cfg.task;
        let center = if let Some(c) = t.box_center_xy_m {
            c
        } else {
            let tip = self.peg_tip_pose().translation.vector;
            [tip.x, tip.y]
        };
        let x = center[0] + rng::uniform(rng, -t.box_xy_range_m[0], t.box_xy_range_m[0]);
        let y = center[1] + rng::uniform(rng, -t.box_xy_range_m[1], t.box_xy_range_m[1]);
        // The yaw about which the hole fits the peg as the arm starts
        // (s_ψ = 0): the drawn yaw is then a roll error for the policy to
        // correct, never a half turn that ends at the wrist's limit.
        let peg_x = self.peg_tip_pose().rotation * Vector3::x();
        let yaw =
            peg_x.y.atan2(peg_x.x) + rng::uniform(rng, -t.box_yaw_range_rad, t.box_yaw_range_rad);
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

    pub(super) fn place_box(&mut self, geometry: BoxWithHole, hole_pose: Isometry3<f64>) {
        let body = self
            .physics
            .bodies
            .insert(RigidBodyBuilder::fixed().pose(pose_to_glam(&hole_pose)));
        let mut colliders = Vec::new();
        for piece in &geometry.pieces {
            let c = hull_collider(piece)
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
    pub(super) fn primitives(&self) -> Vec<Primitive> {
        let mut prims = vec![Primitive {
            body: BodyRef::Static,
            local: Isometry3::translation(0.0, 0.0, -GROUND_HALF_M[2]),
            geometry: Geometry::Cuboid {
                half: Vector3::from(GROUND_HALF_M),
            },
            class: Class::Ground,
            color: [0.45, 0.45, 0.40],
        }];
        prims.extend(crate::camera::robot_primitives(&self.model));
        if let Some(peg) = &self.peg {
            prims.push(peg.info.primitive());
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
