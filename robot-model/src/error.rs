//! Errors of model loading and of the algorithms that can fail.

use std::path::PathBuf;

/// Why a robot description could not be turned into a [`crate::Model`].
/// Every variant names the element at fault.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file could not be read.
    #[error("cannot read URDF file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// urdf-rs rejected the XML (syntax, unknown joint type, bad number).
    #[error("cannot parse URDF{}: {message}", .path.as_ref().map(|p| format!(" {}", p.display())).unwrap_or_default())]
    Parse {
        /// The file, when loaded from one.
        path: Option<PathBuf>,
        /// urdf-rs's message.
        message: String,
    },
    /// The description has no link.
    #[error("URDF has no <link>")]
    NoLinks,
    /// Two links or two joints (or frames) share a name.
    #[error("duplicate {kind} name '{name}'")]
    DuplicateName {
        /// "link", "joint" or "frame".
        kind: &'static str,
        /// The name.
        name: String,
    },
    /// A joint refers to a link that does not exist.
    #[error("joint '{joint}': {role} link '{link}' does not exist")]
    MissingLink {
        /// The joint.
        joint: String,
        /// "parent" or "child".
        role: &'static str,
        /// The missing link's name.
        link: String,
    },
    /// A link is the child of more than one joint (a closed chain).
    #[error(
        "link '{link}' is the child of both joint '{first}' and joint '{second}': closed kinematic loops are not supported"
    )]
    MultipleParents {
        /// The link.
        link: String,
        /// One joint.
        first: String,
        /// The other joint.
        second: String,
    },
    /// The joints form a cycle, or the links form more than one tree.
    #[error("kinematic loop: links {links:?} are not reachable from a single root link")]
    Loop {
        /// The links that cannot be reached from the root.
        links: Vec<String>,
    },
    /// More than one link has no parent joint.
    #[error("URDF has several root links ({roots:?}); exactly one link may have no parent joint")]
    MultipleRoots {
        /// The roots.
        roots: Vec<String>,
    },
    /// A joint type this library does not model (floating, planar, spherical).
    #[error(
        "joint '{joint}': joint type '{kind}' is not supported (revolute, continuous, prismatic and fixed are)"
    )]
    UnsupportedJoint {
        /// The joint.
        joint: String,
        /// Its type.
        kind: String,
    },
    /// A number is NaN, infinite where it must be finite, or out of range.
    #[error("{element}: invalid {field} {value:?}: {reason}")]
    InvalidValue {
        /// Which element (`joint 'j2' <origin>`, `link 'l3' <inertial>`...).
        element: String,
        /// Which attribute.
        field: &'static str,
        /// The values found.
        value: Vec<f64>,
        /// What is wrong.
        reason: &'static str,
    },
    /// A revolute or prismatic joint without `<limit>`.
    #[error(
        "joint '{joint}': {kind} joint has no <limit> (urdf-rs reports all limits as zero); add one, or load with MissingLimits::Unlimited"
    )]
    MissingLimit {
        /// The joint.
        joint: String,
        /// "revolute" or "prismatic".
        kind: &'static str,
    },
    /// A frame name that the model does not have.
    #[error("no frame named '{0}'")]
    UnknownFrame(String),
}

/// Why forward dynamics could not be computed.
#[derive(Debug, thiserror::Error, Clone, Copy, PartialEq)]
pub enum DynamicsError {
    /// The mass matrix is not positive definite (for example a joint that
    /// moves no mass); the pivot that failed is given.
    #[error("mass matrix is not positive definite (pivot {pivot} = {value:e})")]
    SingularMassMatrix {
        /// Index of the failing pivot.
        pivot: usize,
        /// Its value.
        value: f64,
    },
}
