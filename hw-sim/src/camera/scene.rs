//! Scene assembly: the poses a frame is rendered at and the primitives of
//! the robot and of prisms.

use super::*;
use nalgebra::{Isometry3, Vector3};

/// Poses of the bodies at render time.
pub struct BodyPoses<'a> {
    /// Per robot-model joint (0: the base).
    pub links: &'a [Isometry3<f64>],
    /// The box's hole frame, if there is a box.
    pub box_pose: Option<Isometry3<f64>>,
}

impl BodyPoses<'_> {
    pub(super) fn get(&self, b: BodyRef) -> Isometry3<f64> {
        match b {
            BodyRef::Static => Isometry3::identity(),
            BodyRef::Link(j) => self.links[j],
            BodyRef::Box => self.box_pose.unwrap_or_else(Isometry3::identity),
        }
    }
}

/// The robot's collision geometry as camera primitives (meshes are not
/// drawn).
pub fn robot_primitives(model: &robot_model::Model) -> Vec<Primitive> {
    use robot_model::Shape;
    let mut prims = Vec::new();
    for g in model
        .geometries
        .iter()
        .filter(|g| g.role == robot_model::GeometryRole::Collision)
    {
        let geometry = match &g.shape {
            Shape::Box { size } => Geometry::Cuboid {
                half: Vector3::from(*size) * 0.5,
            },
            Shape::Sphere { radius } => Geometry::Sphere { radius: *radius },
            Shape::Capsule { radius, length } => Geometry::Capsule {
                half_length: 0.5 * length,
                radius: *radius,
            },
            Shape::Cylinder { radius, length } => Geometry::Cylinder {
                half_length: 0.5 * length,
                radius: *radius,
            },
            Shape::Mesh { .. } => continue,
        };
        // Alternate two greys along the chain so links stand apart.
        let grey = if g.parent_joint % 2 == 0 { 0.80 } else { 0.62 };
        prims.push(Primitive {
            body: BodyRef::Link(g.parent_joint),
            local: g.placement.to_isometry(),
            geometry,
            class: Class::Robot,
            color: [grey, grey, grey + 0.04],
        });
    }
    prims
}

/// A convex prism as an analytic shape.
pub fn prism_geometry(prism: &crate::shapes::ConvexPrism) -> Geometry {
    Geometry::Convex {
        planes: prism
            .planes()
            .into_iter()
            .map(|(n, c)| (Vector3::from(n), c))
            .collect(),
        points: prism.points().into_iter().map(Vector3::from).collect(),
    }
}
