//! The immutable robot description: kinematic tree, inertias, limits, frames
//! and geometry.

use crate::error::ModelError;
use crate::spatial::{Inertia, Se3};
use nalgebra::{DVector, Isometry3, Vector3};
use std::path::PathBuf;

/// Index of a joint in [`Model::joints`]; 0 is the universe (the fixed base).
pub type JointId = usize;
/// Index of a frame in [`Model::frames`].
pub type FrameId = usize;

/// How a joint moves its child body relative to its parent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// The universe: the fixed root that every tree hangs from. Only joint 0.
    Root,
    /// Rotation about `axis`, bounded by position limits.
    Revolute,
    /// Rotation about `axis` without position limits. Its configuration is
    /// the angle itself (one coordinate, not Pinocchio's (cos, sin) pair).
    Continuous,
    /// Translation along `axis`.
    Prismatic,
}

/// Limits of one joint in SI units; an absent limit is infinite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// Lower position limit (rad or m); `-inf` when unbounded.
    pub lower: f64,
    /// Upper position limit (rad or m); `+inf` when unbounded.
    pub upper: f64,
    /// Velocity limit magnitude (rad/s or m/s).
    pub velocity: f64,
    /// Effort limit magnitude (N·m or N).
    pub effort: f64,
}

impl JointLimits {
    /// No limits at all.
    pub const UNLIMITED: JointLimits = JointLimits {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
        velocity: f64::INFINITY,
        effort: f64::INFINITY,
    };
}

/// One moving joint (or the universe) of the tree.
#[derive(Clone, Debug)]
pub struct Joint {
    /// The URDF joint's name ("universe" for joint 0).
    pub name: String,
    /// The parent joint (0 for joints attached to the root link); joint 0 is
    /// its own parent. Parents always have smaller indices than children.
    pub parent: JointId,
    /// The joint frame in the parent joint's frame at zero configuration.
    /// Fixed joints between the two have been folded into it.
    pub placement: Se3,
    /// How it moves.
    pub kind: JointKind,
    /// Unit axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Index of its coordinate in q, v, a and τ (meaningless for joint 0).
    pub idx_v: usize,
    /// Position, velocity and effort limits.
    pub limits: JointLimits,
    /// Viscous damping from URDF `<dynamics>`, N·m·s/rad or N·s/m.
    pub damping: f64,
    /// Coulomb friction from URDF `<dynamics>`, N·m or N.
    pub friction: f64,
    /// The URDF link this joint moves.
    pub child_link: String,
}

impl Joint {
    /// The coordinate axis (0, 1, 2 for x, y, z) the joint's axis lies on,
    /// either way round, or `None` for an oblique axis.
    #[inline]
    pub fn aligned_axis(&self) -> Option<usize> {
        let a = &self.axis;
        (0..3).find(|&k| a[k].abs() == 1.0 && a[(k + 1) % 3] == 0.0 && a[(k + 2) % 3] == 0.0)
    }
}

/// What a frame stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameKind {
    /// A URDF link's frame.
    Link,
    /// A moving joint's frame.
    Joint,
    /// A fixed joint's frame (its child link's frame).
    FixedJoint,
    /// A frame added by the user (a tool tip with an offset).
    Extra,
}

/// A named frame rigidly attached to a joint's body.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Its name (link or joint name, or the user's).
    pub name: String,
    /// The joint whose body carries it.
    pub parent_joint: JointId,
    /// Its pose in the parent joint's frame.
    pub placement: Se3,
    /// What it stands for.
    pub kind: FrameKind,
}

/// The shape of a collision or visual element, in metres.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A box centred on its frame, full side lengths.
    Box {
        /// Side lengths along x, y, z.
        size: [f64; 3],
    },
    /// A cylinder along z, centred on its frame.
    Cylinder {
        /// Radius.
        radius: f64,
        /// Length along z.
        length: f64,
    },
    /// A capsule along z: a cylinder of `length` with hemispherical caps.
    Capsule {
        /// Radius.
        radius: f64,
        /// Length of the cylindrical part along z.
        length: f64,
    },
    /// A sphere.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// A mesh file reference; kinematics and dynamics never read it.
    Mesh {
        /// The file name as written in the URDF.
        filename: String,
        /// Scale along x, y, z.
        scale: [f64; 3],
        /// The file on disk when it was found next to the URDF.
        resolved: Option<PathBuf>,
    },
}

/// Whether a geometry is for collision or for display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryRole {
    /// From `<collision>`.
    Collision,
    /// From `<visual>`.
    Visual,
}

/// One collision or visual element of a link.
#[derive(Clone, Debug)]
pub struct GeometryObject {
    /// The link it belongs to.
    pub link: String,
    /// The link's frame.
    pub frame: FrameId,
    /// The joint whose body carries it.
    pub parent_joint: JointId,
    /// Its pose in the link frame (the URDF `<origin>`).
    pub origin: Se3,
    /// Its pose in the parent joint's frame.
    pub placement: Se3,
    /// The shape.
    pub shape: Shape,
    /// Collision or visual.
    pub role: GeometryRole,
    /// Colour (RGBA in 0..1) from a visual's inline `<material><color>`.
    pub rgba: Option<[f64; 4]>,
}

/// The robot description. Immutable once built (except for adding frames
/// before use); everything an algorithm writes goes to [`crate::Data`].
#[derive(Clone, Debug)]
pub struct Model {
    /// The URDF robot name.
    pub name: String,
    /// Joint 0 is the universe; then the moving joints in topological order.
    pub joints: Vec<Joint>,
    /// Per joint, the inertia of the body it moves (fixed children lumped
    /// in), expressed in the joint frame. Index 0 is the root link's (unused
    /// by dynamics: the base does not move).
    pub inertias: Vec<Inertia>,
    /// All frames: every link, every joint, and extra frames.
    pub frames: Vec<Frame>,
    /// Collision and visual geometry.
    pub geometries: Vec<GeometryObject>,
    /// Gravity in the base frame, m/s². Defaults to (0, 0, −9.81).
    pub gravity: Vector3<f64>,
    /// Name of the root link.
    pub root_link: String,
}

/// Standard gravity used by default, m/s².
pub const STANDARD_GRAVITY: f64 = 9.81;

impl Model {
    /// Number of configuration coordinates (equal to [`Model::nv`]: every
    /// joint has one coordinate).
    pub fn nq(&self) -> usize {
        self.joints.len() - 1
    }

    /// Number of velocity coordinates (degrees of freedom).
    pub fn nv(&self) -> usize {
        self.joints.len() - 1
    }

    /// Number of joints including the universe.
    pub fn njoints(&self) -> usize {
        self.joints.len()
    }

    /// The moving joint with this name.
    pub fn joint_id(&self, name: &str) -> Option<JointId> {
        self.joints
            .iter()
            .skip(1)
            .position(|j| j.name == name)
            .map(|i| i + 1)
    }

    /// The frame with this name. When a link and a joint share a name the
    /// link's frame is returned.
    pub fn frame_id(&self, name: &str) -> Result<FrameId, ModelError> {
        self.frames
            .iter()
            .position(|f| f.name == name && f.kind == FrameKind::Link)
            .or_else(|| self.frames.iter().position(|f| f.name == name))
            .ok_or_else(|| ModelError::UnknownFrame(name.to_string()))
    }

    /// Adds a frame rigidly attached to an existing frame, `offset` being its
    /// pose in that frame (for example a tool tip). Data made before the call
    /// stays valid: frames have no per-frame storage in [`crate::Data`].
    pub fn add_frame(
        &mut self,
        name: &str,
        parent_frame: &str,
        offset: &Isometry3<f64>,
    ) -> Result<FrameId, ModelError> {
        if self.frames.iter().any(|f| f.name == name) {
            return Err(ModelError::DuplicateName {
                kind: "frame",
                name: name.to_string(),
            });
        }
        let off = Se3::from_isometry(offset);
        if !(off.rot.iter().all(|x| x.is_finite()) && off.trans.iter().all(|x| x.is_finite())) {
            return Err(ModelError::InvalidValue {
                element: format!("frame '{name}'"),
                field: "offset",
                value: off.trans.iter().copied().collect(),
                reason: "must be finite",
            });
        }
        let parent = &self.frames[self.frame_id(parent_frame)?];
        let frame = Frame {
            name: name.to_string(),
            parent_joint: parent.parent_joint,
            placement: parent.placement.mul(&off),
            kind: FrameKind::Extra,
        };
        self.frames.push(frame);
        Ok(self.frames.len() - 1)
    }

    /// Lower position limits of all coordinates.
    pub fn lower_limits(&self) -> DVector<f64> {
        DVector::from_iterator(self.nv(), self.joints[1..].iter().map(|j| j.limits.lower))
    }

    /// Upper position limits of all coordinates.
    pub fn upper_limits(&self) -> DVector<f64> {
        DVector::from_iterator(self.nv(), self.joints[1..].iter().map(|j| j.limits.upper))
    }

    /// Velocity limits of all coordinates.
    pub fn velocity_limits(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.nv(),
            self.joints[1..].iter().map(|j| j.limits.velocity),
        )
    }

    /// Effort limits of all coordinates.
    pub fn effort_limits(&self) -> DVector<f64> {
        DVector::from_iterator(self.nv(), self.joints[1..].iter().map(|j| j.limits.effort))
    }

    /// The configuration in the middle of the position limits (0 for
    /// unbounded joints): a safe default pose.
    pub fn neutral_configuration(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.nv(),
            self.joints[1..].iter().map(|j| {
                let l = j.limits;
                if l.lower.is_finite() && l.upper.is_finite() {
                    0.5 * (l.lower + l.upper)
                } else {
                    0.0
                }
            }),
        )
    }

    /// Total mass of the moving bodies, kg.
    pub fn moving_mass(&self) -> f64 {
        self.inertias[1..].iter().map(|i| i.mass).sum()
    }

    /// True when joint `ancestor` is `joint` or one of its ancestors.
    pub fn supports(&self, ancestor: JointId, joint: JointId) -> bool {
        let mut j = joint;
        loop {
            if j == ancestor {
                return true;
            }
            if j == 0 {
                return false;
            }
            j = self.joints[j].parent;
        }
    }
}
