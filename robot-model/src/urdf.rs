//! URDF → [`Model`], through urdf-rs, with every problem reported by the
//! element it was found in.

use crate::error::ModelError;
use crate::model::{
    Frame, FrameKind, GeometryObject, GeometryRole, Joint, JointKind, JointLimits, Model,
    STANDARD_GRAVITY, Shape,
};
use crate::spatial::{Inertia, Se3};
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// What to do with a revolute or prismatic joint that has no `<limit>`.
///
/// urdf-rs (for URDF versions before 1.2) cannot tell an absent `<limit>` from
/// one whose values are all zero: both arrive as zeros. A joint locked at zero
/// with zero effort makes no sense, so all-zero limits are taken to mean
/// "absent", never "locked".
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissingLimits {
    /// Refuse the URDF, naming the joint (the default: a controller must not
    /// run with unknown torque limits).
    #[default]
    Reject,
    /// Treat the joint as unlimited in position, velocity and effort.
    Unlimited,
}

/// Options of the URDF loader.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Policy for revolute and prismatic joints without `<limit>`.
    pub missing_limits: MissingLimits,
}

impl Model {
    /// Loads a URDF file. Relative mesh paths are resolved against the
    /// file's directory; missing meshes are not an error.
    pub fn from_urdf_file(
        path: impl AsRef<Path>,
        options: &LoadOptions,
    ) -> Result<Model, ModelError> {
        let path = path.as_ref();
        let text = read_urdf_text(path).map_err(|source| ModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let robot = parse(&text, Some(path))?;
        build(&robot, path.parent(), options)
    }

    /// Loads a URDF from a string. Relative mesh paths stay unresolved.
    pub fn from_urdf_str(text: &str, options: &LoadOptions) -> Result<Model, ModelError> {
        build(&parse(text, None)?, None, options)
    }
}

/// urdf-rs's parse; where it fails, the joints whose `<limit>` lacks an
/// attribute it requires are named (its own message gives no location).
fn parse(text: &str, path: Option<&Path>) -> Result<urdf_rs::Robot, ModelError> {
    urdf_rs::read_from_string(text).map_err(|e| {
        let mut message = e.to_string();
        for (joint, attr) in incomplete_limits(text) {
            message.push_str(&format!(
                "; joint `{joint}`: <limit> has no `{attr}` attribute"
            ));
        }
        ModelError::Parse {
            path: path.map(Path::to_path_buf),
            message,
        }
    })
}

/// (joint, attribute) for every `<limit>` without `effort` or `velocity`,
/// which urdf-rs requires.
fn incomplete_limits(text: &str) -> Vec<(String, &'static str)> {
    use quick_xml::events::{BytesStart, Event};
    let value = |e: &BytesStart<'_>, name: &str| {
        e.try_get_attribute(name)
            .ok()
            .flatten()
            .map(|a| String::from_utf8_lossy(&a.value).into_owned())
    };
    let mut reader = quick_xml::Reader::from_str(text);
    let mut joint: Option<String> = None;
    let mut out = Vec::new();
    loop {
        match reader.read_event() {
            Ok(Event::Start(e)) if e.name().as_ref() == b"joint" => joint = value(&e, "name"),
            Ok(Event::End(e)) if e.name().as_ref() == b"joint" => joint = None,
            Ok(Event::Start(e) | Event::Empty(e)) if e.name().as_ref() == b"limit" => {
                if let Some(j) = &joint {
                    for attr in ["effort", "velocity"] {
                        if value(&e, attr).is_none() {
                            out.push((j.clone(), attr));
                        }
                    }
                }
            }
            Ok(Event::Eof) | Err(_) => break,
            _ => {}
        }
    }
    out
}

fn check_finite(element: &str, field: &'static str, values: &[f64]) -> Result<(), ModelError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ModelError::InvalidValue {
            element: element.to_string(),
            field,
            value: values.to_vec(),
            reason: "must be finite",
        })
    }
}

fn pose(element: &str, p: &urdf_rs::Pose) -> Result<Se3, ModelError> {
    check_finite(element, "origin xyz", &p.xyz.0)?;
    check_finite(element, "origin rpy", &p.rpy.0)?;
    Ok(Se3::from_xyz_rpy(p.xyz.0, p.rpy.0))
}

fn link_inertia(link: &urdf_rs::Link) -> Result<Inertia, ModelError> {
    let el = format!("link '{}' <inertial>", link.name);
    let inertial = &link.inertial;
    let frame = pose(&el, &inertial.origin)?;
    let m = inertial.mass.value;
    if !m.is_finite() || m < 0.0 {
        return Err(ModelError::InvalidValue {
            element: el,
            field: "mass",
            value: vec![m],
            reason: "must be finite and non-negative",
        });
    }
    let i = &inertial.inertia;
    let vals = [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
    check_finite(&el, "inertia", &vals)?;
    if i.ixx < 0.0 || i.iyy < 0.0 || i.izz < 0.0 {
        return Err(ModelError::InvalidValue {
            element: el,
            field: "inertia",
            value: vals.to_vec(),
            reason: "principal moments ixx, iyy, izz must be non-negative",
        });
    }
    let i_frame = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    // The tensor is given in the inertial frame, whose origin is the centre of mass.
    let i_link = frame.rot * i_frame * frame.rot.transpose();
    Ok(Inertia::from_com(m, frame.trans, i_link))
}

fn shape(el: &str, g: &urdf_rs::Geometry, base_dir: Option<&Path>) -> Result<Shape, ModelError> {
    let positive = |field: &'static str, v: &[f64]| -> Result<(), ModelError> {
        if v.iter().all(|x| x.is_finite() && *x >= 0.0) {
            Ok(())
        } else {
            Err(ModelError::InvalidValue {
                element: el.to_string(),
                field,
                value: v.to_vec(),
                reason: "must be finite and non-negative",
            })
        }
    };
    Ok(match g {
        urdf_rs::Geometry::Box { size } => {
            positive("box size", &size.0)?;
            Shape::Box { size: size.0 }
        }
        urdf_rs::Geometry::Cylinder { radius, length } => {
            positive("cylinder radius/length", &[*radius, *length])?;
            Shape::Cylinder {
                radius: *radius,
                length: *length,
            }
        }
        urdf_rs::Geometry::Capsule { radius, length } => {
            positive("capsule radius/length", &[*radius, *length])?;
            Shape::Capsule {
                radius: *radius,
                length: *length,
            }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            positive("sphere radius", &[*radius])?;
            Shape::Sphere { radius: *radius }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            check_finite(el, "mesh scale", &scale)?;
            Shape::Mesh {
                filename: filename.clone(),
                scale,
                resolved: resolve_mesh(filename, base_dir),
            }
        }
    })
}

/// The largest URDF file read, bytes (the shipped descriptions are 10 kB;
/// URDFs reference their meshes rather than holding them).
pub const MAX_URDF_BYTES: u64 = 4 << 20;

/// Reads a URDF file: a regular file of at most [`MAX_URDF_BYTES`], UTF-8.
/// Opened without blocking and checked on the open descriptor, so a FIFO
/// cannot hang the caller, `/dev/zero` cannot fill its memory, and the file
/// cannot be swapped between the check and the read.
pub(crate) fn read_urdf_text(path: &Path) -> std::io::Result<String> {
    use std::io::{Error, ErrorKind, Read};
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(Error::new(ErrorKind::InvalidInput, "not a regular file"));
    }
    if meta.len() > MAX_URDF_BYTES {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!(
                "{} bytes, more than the {MAX_URDF_BYTES} allowed",
                meta.len()
            ),
        ));
    }
    let mut text = String::new();
    // The bound holds even if the file grows after the check.
    let n = file.take(MAX_URDF_BYTES + 1).read_to_string(&mut text)?;
    if n as u64 > MAX_URDF_BYTES {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("grew past the {MAX_URDF_BYTES} bytes allowed while read"),
        ));
    }
    Ok(text)
}

/// The mesh's path on disk when it can be found; `package://` URIs need a
/// ROS package index, which this library does not have.
fn resolve_mesh(filename: &str, base_dir: Option<&Path>) -> Option<PathBuf> {
    let path = filename.strip_prefix("file://").unwrap_or(filename);
    if path.contains("://") {
        return None;
    }
    let p = Path::new(path);
    let full = if p.is_absolute() {
        p.to_path_buf()
    } else {
        base_dir?.join(p)
    };
    full.is_file().then_some(full)
}

fn limits(
    joint: &urdf_rs::Joint,
    kind: JointKind,
    options: &LoadOptions,
) -> Result<JointLimits, ModelError> {
    let l = &joint.limit;
    let el = format!("joint '{}' <limit>", joint.name);
    for (field, v) in [
        ("lower", l.lower),
        ("upper", l.upper),
        ("effort", l.effort),
        ("velocity", l.velocity),
    ] {
        if v.is_nan() {
            return Err(ModelError::InvalidValue {
                element: el,
                field,
                value: vec![v],
                reason: "is NaN",
            });
        }
    }
    if l.effort < 0.0 || l.velocity < 0.0 {
        return Err(ModelError::InvalidValue {
            element: el,
            field: "effort/velocity",
            value: vec![l.effort, l.velocity],
            reason: "must be non-negative",
        });
    }
    let all_zero = l.lower == 0.0 && l.upper == 0.0 && l.effort == 0.0 && l.velocity == 0.0;
    // Zero effort or velocity means "not given" (as for continuous joints,
    // whose <limit> is optional); never a joint that cannot move.
    let or_inf = |v: f64| if v > 0.0 { v } else { f64::INFINITY };
    match kind {
        JointKind::Continuous => Ok(JointLimits {
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            velocity: or_inf(l.velocity),
            effort: or_inf(l.effort),
        }),
        JointKind::Revolute | JointKind::Prismatic => {
            if all_zero {
                return match options.missing_limits {
                    MissingLimits::Reject => Err(ModelError::MissingLimit {
                        joint: joint.name.clone(),
                        kind: if kind == JointKind::Revolute {
                            "revolute"
                        } else {
                            "prismatic"
                        },
                    }),
                    MissingLimits::Unlimited => Ok(JointLimits::UNLIMITED),
                };
            }
            if l.upper < l.lower {
                return Err(ModelError::InvalidValue {
                    element: el,
                    field: "lower/upper",
                    value: vec![l.lower, l.upper],
                    reason: "upper is below lower",
                });
            }
            // lower == upper (both omitted) leaves the position unbounded.
            let (lower, upper) = if l.lower == l.upper {
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                (l.lower, l.upper)
            };
            Ok(JointLimits {
                lower,
                upper,
                velocity: or_inf(l.velocity),
                effort: or_inf(l.effort),
            })
        }
        JointKind::Root => Ok(JointLimits::UNLIMITED),
    }
}

/// Builds the model: links indexed, the tree checked, then a depth-first
/// walk from the root, children in document order, so that parents get
/// smaller joint indices than their children.
fn build(
    robot: &urdf_rs::Robot,
    base_dir: Option<&Path>,
    options: &LoadOptions,
) -> Result<Model, ModelError> {
    if robot.links.is_empty() {
        return Err(ModelError::NoLinks);
    }
    let link_index = index_links(robot)?;
    let tree = link_tree(robot, &link_index)?;
    let mut model = root_model(robot, tree.root);
    let mut visited = vec![false; robot.links.len()];
    // (link, joint carrying it, link frame in that joint's frame)
    let mut stack: Vec<(usize, usize, Se3)> = vec![(tree.root, 0, Se3::IDENTITY)];
    while let Some((li, jid, link_in_joint)) = stack.pop() {
        visited[li] = true;
        add_link(&mut model, &robot.links[li], jid, &link_in_joint, base_dir)?;
        // Push in reverse so that the first child is handled first.
        for &ji in tree.children_of[li].iter().rev() {
            let j = &robot.joints[ji];
            let (child_jid, child_in_joint) =
                add_joint(&mut model, j, jid, &link_in_joint, options)?;
            stack.push((link_index[j.child.link.as_str()], child_jid, child_in_joint));
        }
    }
    check_reachable(robot, &visited)?;
    Ok(model)
}

/// Link name → index in the document; names must be unique.
fn index_links(robot: &urdf_rs::Robot) -> Result<HashMap<&str, usize>, ModelError> {
    let mut link_index = HashMap::new();
    for (i, l) in robot.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(ModelError::DuplicateName {
                kind: "link",
                name: l.name.clone(),
            });
        }
    }
    Ok(link_index)
}

/// The joints as edges between links, checked to form one tree.
struct LinkTree {
    /// For each link, the joints whose parent it is, in document order.
    children_of: Vec<Vec<usize>>,
    /// The one link that is no joint's child.
    root: usize,
}

/// Connects the links by the joints: unique joint names, existing links,
/// one parent per link and exactly one root (none means a cycle).
fn link_tree(
    robot: &urdf_rs::Robot,
    link_index: &HashMap<&str, usize>,
) -> Result<LinkTree, ModelError> {
    let find_link = |j: &urdf_rs::Joint, role: &'static str, link: &String| {
        link_index
            .get(link.as_str())
            .copied()
            .ok_or_else(|| ModelError::MissingLink {
                joint: j.name.clone(),
                role,
                link: link.clone(),
            })
    };
    let mut joint_names: HashMap<&str, ()> = HashMap::new();
    // For each link, the joint whose child it is.
    let mut parent_joint_of: Vec<Option<usize>> = vec![None; robot.links.len()];
    let mut children_of: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
    for (ji, j) in robot.joints.iter().enumerate() {
        if joint_names.insert(j.name.as_str(), ()).is_some() {
            return Err(ModelError::DuplicateName {
                kind: "joint",
                name: j.name.clone(),
            });
        }
        let parent = find_link(j, "parent", &j.parent.link)?;
        let child = find_link(j, "child", &j.child.link)?;
        if let Some(prev) = parent_joint_of[child] {
            return Err(ModelError::MultipleParents {
                link: j.child.link.clone(),
                first: robot.joints[prev].name.clone(),
                second: j.name.clone(),
            });
        }
        parent_joint_of[child] = Some(ji);
        children_of[parent].push(ji);
    }
    let roots: Vec<usize> = (0..robot.links.len())
        .filter(|&i| parent_joint_of[i].is_none())
        .collect();
    if roots.len() > 1 {
        return Err(ModelError::MultipleRoots {
            roots: roots.iter().map(|&i| robot.links[i].name.clone()).collect(),
        });
    }
    let Some(&root) = roots.first() else {
        // Every link has a parent: the joints close a cycle.
        return Err(ModelError::Loop {
            links: robot.links.iter().map(|l| l.name.clone()).collect(),
        });
    };
    Ok(LinkTree { children_of, root })
}

/// The model before the walk: the universe joint 0 carrying the root link.
fn root_model(robot: &urdf_rs::Robot, root: usize) -> Model {
    Model {
        name: robot.name.clone(),
        joints: vec![Joint {
            name: "universe".to_string(),
            parent: 0,
            placement: Se3::IDENTITY,
            kind: JointKind::Root,
            axis: Vector3::z(),
            idx_v: 0,
            limits: JointLimits::UNLIMITED,
            damping: 0.0,
            friction: 0.0,
            child_link: robot.links[root].name.clone(),
        }],
        inertias: vec![Inertia::ZERO],
        frames: Vec::new(),
        geometries: Vec::new(),
        gravity: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
        root_link: robot.links[root].name.clone(),
    }
}

/// Adds a link carried by joint `jid`: its inertia (summed into the joint's
/// body), its frame and its geometries.
fn add_link(
    model: &mut Model,
    link: &urdf_rs::Link,
    jid: usize,
    link_in_joint: &Se3,
    base_dir: Option<&Path>,
) -> Result<(), ModelError> {
    let inertia = link_inertia(link)?;
    model.inertias[jid] += link_in_joint.act_inertia(&inertia);
    let frame_id = model.frames.len();
    model.frames.push(Frame {
        name: link.name.clone(),
        parent_joint: jid,
        placement: *link_in_joint,
        kind: FrameKind::Link,
    });
    add_geometries(model, link, frame_id, jid, link_in_joint, base_dir)
}

/// Adds URDF joint `j`, whose parent link is carried by joint `jid` at
/// `link_in_joint`. Returns the joint that carries the child link and the
/// child link's frame in it: a fixed joint only adds a frame, so its child
/// rides on `jid`; a moving joint becomes a new model joint.
fn add_joint(
    model: &mut Model,
    j: &urdf_rs::Joint,
    jid: usize,
    link_in_joint: &Se3,
    options: &LoadOptions,
) -> Result<(usize, Se3), ModelError> {
    let el = format!("joint '{}' <origin>", j.name);
    let origin = link_in_joint.mul(&pose(&el, &j.origin)?);
    let Some(kind) = joint_kind(j)? else {
        model.frames.push(Frame {
            name: j.name.clone(),
            parent_joint: jid,
            placement: origin,
            kind: FrameKind::FixedJoint,
        });
        return Ok((jid, origin));
    };
    let axis = joint_axis(j)?;
    let (damping, friction) = joint_dynamics(j)?;
    let new_id = model.joints.len();
    model.joints.push(Joint {
        name: j.name.clone(),
        parent: jid,
        placement: origin,
        kind,
        axis,
        idx_v: new_id - 1,
        limits: limits(j, kind, options)?,
        damping,
        friction,
        child_link: j.child.link.clone(),
    });
    model.inertias.push(Inertia::ZERO);
    model.frames.push(Frame {
        name: j.name.clone(),
        parent_joint: new_id,
        placement: Se3::IDENTITY,
        kind: FrameKind::Joint,
    });
    Ok((new_id, Se3::IDENTITY))
}

/// The joint's kind; `None` for a fixed joint.
fn joint_kind(j: &urdf_rs::Joint) -> Result<Option<JointKind>, ModelError> {
    match j.joint_type {
        urdf_rs::JointType::Fixed => Ok(None),
        urdf_rs::JointType::Revolute => Ok(Some(JointKind::Revolute)),
        urdf_rs::JointType::Continuous => Ok(Some(JointKind::Continuous)),
        urdf_rs::JointType::Prismatic => Ok(Some(JointKind::Prismatic)),
        ref other => Err(ModelError::UnsupportedJoint {
            joint: j.name.clone(),
            kind: format!("{other:?}").to_lowercase(),
        }),
    }
}

/// The joint's unit axis; `<axis>` must be finite and non-zero.
fn joint_axis(j: &urdf_rs::Joint) -> Result<Vector3<f64>, ModelError> {
    let el = format!("joint '{}' <axis>", j.name);
    check_finite(&el, "xyz", &j.axis.xyz.0)?;
    let axis = Vector3::from(j.axis.xyz.0);
    let norm = axis.norm();
    if norm < 1e-9 {
        return Err(ModelError::InvalidValue {
            element: el,
            field: "xyz",
            value: j.axis.xyz.0.to_vec(),
            reason: "must be a non-zero vector",
        });
    }
    Ok(axis / norm)
}

/// The joint's `<dynamics>` (damping, friction); absent: no damping or
/// friction.
fn joint_dynamics(j: &urdf_rs::Joint) -> Result<(f64, f64), ModelError> {
    let (damping, friction) = j
        .dynamics
        .as_ref()
        .map(|d| (d.damping, d.friction))
        .unwrap_or((0.0, 0.0));
    check_finite(
        &format!("joint '{}' <dynamics>", j.name),
        "damping/friction",
        &[damping, friction],
    )?;
    Ok((damping, friction))
}

/// Every link must hang from the root: one the walk did not reach sits on a
/// cycle detached from the tree.
fn check_reachable(robot: &urdf_rs::Robot, visited: &[bool]) -> Result<(), ModelError> {
    let unreachable: Vec<String> = (0..robot.links.len())
        .filter(|&i| !visited[i])
        .map(|i| robot.links[i].name.clone())
        .collect();
    if unreachable.is_empty() {
        Ok(())
    } else {
        Err(ModelError::Loop { links: unreachable })
    }
}

fn add_geometries(
    model: &mut Model,
    link: &urdf_rs::Link,
    frame: usize,
    joint: usize,
    link_in_joint: &Se3,
    base_dir: Option<&Path>,
) -> Result<(), ModelError> {
    let items = link
        .collision
        .iter()
        .map(|c| (GeometryRole::Collision, &c.origin, &c.geometry, None))
        .chain(link.visual.iter().map(|v| {
            let rgba = v
                .material
                .as_ref()
                .and_then(|m| m.color.as_ref())
                .map(|c| c.rgba.0);
            (GeometryRole::Visual, &v.origin, &v.geometry, rgba)
        }));
    for (role, origin, geometry, rgba) in items {
        let el = format!(
            "link '{}' <{}>",
            link.name,
            if role == GeometryRole::Collision {
                "collision"
            } else {
                "visual"
            }
        );
        let origin = pose(&el, origin)?;
        let shape = shape(&el, geometry, base_dir)?;
        model.geometries.push(GeometryObject {
            link: link.name.clone(),
            frame,
            parent_joint: joint,
            placement: link_in_joint.mul(&origin),
            origin,
            shape,
            role,
            rgba,
        });
    }
    Ok(())
}
