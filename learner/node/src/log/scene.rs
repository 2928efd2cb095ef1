//! The log's `/scene` channel: `foxglove.SceneUpdate` messages (JSON) that
//! draw the arm, the peg and the box in Foxglove's 3D panel with no URDF
//! or mesh to load. Each entity is frame-locked to a frame `/tf` moves (a
//! link, the peg tip, the base), so one update per episode suffices: the
//! arm's links are its URDF visuals (boxes, cylinders, spheres; a capsule
//! as a cylinder and two spheres), the peg a box from the wrist sensor to
//! the tip, the box four walls around a square opening of the peg's width
//! plus clearance, and the hole's floor. The drawing is for people; the
//! simulator's true shapes (a triangle's hole, for one) are its own.

use super::foxglove::{BASE_FRAME, Quat, Time, Xyz, parts};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use robot_model::{GeometryRole, Model, Shape};
use serde::Serialize;

/// `foxglove.SceneUpdate`, the parts written here (published schema:
/// docs.foxglove.dev, "SceneUpdate").
pub const SCENE_UPDATE: &str = r##"{"title":"foxglove.SceneUpdate","type":"object","required":["deletions","entities"],"properties":{
"deletions":{"type":"array","items":{"type":"object","required":["timestamp","type","id"]}},
"entities":{"type":"array","items":{"type":"object","required":["timestamp","frame_id","id","lifetime","frame_locked","metadata","arrows","cubes","spheres","cylinders","lines","triangles","texts","models"],"properties":{
"timestamp":{"$ref":"#/$defs/time"},"frame_id":{"type":"string"},"id":{"type":"string"},
"lifetime":{"$ref":"#/$defs/time"},"frame_locked":{"type":"boolean"},
"metadata":{"type":"array","items":{"type":"object","properties":{"key":{"type":"string"},"value":{"type":"string"}}}},
"arrows":{"type":"array"},"lines":{"type":"array"},"triangles":{"type":"array"},"texts":{"type":"array"},"models":{"type":"array"},
"cubes":{"type":"array","items":{"$ref":"#/$defs/primitive"}},
"spheres":{"type":"array","items":{"$ref":"#/$defs/primitive"}},
"cylinders":{"type":"array","items":{"allOf":[{"$ref":"#/$defs/primitive"},{"type":"object","properties":{
"bottom_scale":{"type":"number"},"top_scale":{"type":"number"}}}]}}}}}},
"$defs":{
"time":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"xyz":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"primitive":{"type":"object","required":["pose","size","color"],"properties":{
"pose":{"type":"object","properties":{"position":{"$ref":"#/$defs/xyz"},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}},
"size":{"$ref":"#/$defs/xyz"},
"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}}}}}"##;

#[derive(Serialize)]
struct Pose {
    position: Xyz,
    orientation: Quat,
}

impl Pose {
    fn of(iso: &Isometry3<f64>) -> Self {
        let (t, r) = parts(iso);
        Self {
            position: Xyz::of(&t),
            orientation: Quat::of(&r),
        }
    }
}

#[derive(Serialize)]
struct Rgba {
    r: f64,
    g: f64,
    b: f64,
    a: f64,
}

impl Rgba {
    fn of(c: [f64; 4]) -> Self {
        Self {
            r: c[0],
            g: c[1],
            b: c[2],
            a: c[3],
        }
    }
}

#[derive(Serialize)]
struct Primitive {
    pose: Pose,
    size: Xyz,
    color: Rgba,
    #[serde(skip_serializing_if = "Option::is_none")]
    bottom_scale: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    top_scale: Option<f64>,
}

fn primitive(pose: &Isometry3<f64>, size: [f64; 3], color: [f64; 4]) -> Primitive {
    Primitive {
        pose: Pose::of(pose),
        size: Xyz::of(&size),
        color: Rgba::of(color),
        bottom_scale: None,
        top_scale: None,
    }
}

/// One entity: primitives in one frame.
#[derive(Serialize)]
pub struct Entity {
    timestamp: Time,
    frame_id: String,
    id: String,
    lifetime: Time,
    frame_locked: bool,
    metadata: Vec<()>,
    // Foxglove's schema requires every primitive list, these always empty.
    arrows: [(); 0],
    cubes: Vec<Primitive>,
    spheres: Vec<Primitive>,
    cylinders: Vec<Primitive>,
    lines: [(); 0],
    triangles: [(); 0],
    texts: [(); 0],
    models: [(); 0],
}

impl Entity {
    fn new(t_ns: u64, frame: &str, id: &str) -> Self {
        Self {
            timestamp: Time::of(t_ns),
            frame_id: frame.to_string(),
            id: id.to_string(),
            lifetime: Time::of(0),
            frame_locked: true,
            metadata: Vec::new(),
            arrows: [],
            cubes: Vec::new(),
            spheres: Vec::new(),
            cylinders: Vec::new(),
            lines: [],
            triangles: [],
            texts: [],
            models: [],
        }
    }

    /// Primitives in it.
    pub fn len(&self) -> usize {
        self.cubes.len() + self.spheres.len() + self.cylinders.len()
    }

    /// Whether it has none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

const GREY: [f64; 4] = [0.6, 0.6, 0.6, 1.0];

/// The arm's visuals, one entity per link with any, each in its link's
/// frame (`/tf` names the links).
pub fn arm(model: &Model, t_ns: u64) -> Vec<Entity> {
    let mut out: Vec<Entity> = Vec::new();
    for g in model
        .geometries
        .iter()
        .filter(|g| g.role == GeometryRole::Visual)
    {
        // One entity per link, wherever its visuals stand in the list.
        let k = match out.iter().position(|e| e.frame_id == g.link) {
            Some(k) => k,
            None => {
                out.push(Entity::new(t_ns, &g.link, &format!("arm/{}", g.link)));
                out.len() - 1
            }
        };
        let e = &mut out[k];
        let pose = g.origin.to_isometry();
        let color = g.rgba.unwrap_or(GREY);
        match &g.shape {
            Shape::Box { size } => e.cubes.push(primitive(&pose, *size, color)),
            Shape::Sphere { radius } => e.spheres.push(primitive(&pose, [2.0 * radius; 3], color)),
            Shape::Cylinder { radius, length } => {
                e.cylinders.push(cylinder(&pose, *radius, *length, color))
            }
            Shape::Capsule { radius, length } => {
                e.cylinders.push(cylinder(&pose, *radius, *length, color));
                for s in [-0.5, 0.5] {
                    let cap = pose * Translation3::new(0.0, 0.0, s * length);
                    e.spheres.push(primitive(&cap, [2.0 * radius; 3], color));
                }
            }
            // Meshes are files the log does not carry.
            Shape::Mesh { .. } => {}
        }
    }
    out.retain(|e| !e.is_empty());
    out
}

fn cylinder(pose: &Isometry3<f64>, radius: f64, length: f64, color: [f64; 4]) -> Primitive {
    Primitive {
        bottom_scale: Some(1.0),
        top_scale: Some(1.0),
        ..primitive(pose, [2.0 * radius, 2.0 * radius, length], color)
    }
}

/// The peg: a box of side `width` from the tip (frame `tip_frame`) to the
/// point `to_sensor` (the wrist sensor's origin in the tip's frame).
pub fn peg(t_ns: u64, tip_frame: &str, to_sensor: Vector3<f64>, width: f64) -> Entity {
    let mut e = Entity::new(t_ns, tip_frame, "peg");
    let len = to_sensor.norm();
    let rot = UnitQuaternion::rotation_between(&Vector3::z(), &to_sensor).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    let pose = Isometry3::from_parts(Translation3::from(to_sensor / 2.0), rot);
    e.cubes
        .push(primitive(&pose, [width, width, len], [0.2, 0.5, 0.9, 1.0]));
    e
}

/// The box around its hole: the hole frame `hole` (top centre, z up) in the
/// base frame, a square opening of side `opening`, `depth` deep, in a box
/// of side `side` and height `height`.
pub fn box_with_hole(
    t_ns: u64,
    hole: &Isometry3<f64>,
    opening: f64,
    depth: f64,
    side: f64,
    height: f64,
) -> Entity {
    let mut e = Entity::new(t_ns, BASE_FRAME, "box");
    let wood = [0.75, 0.6, 0.4, 1.0];
    let wall = ((side - opening) / 2.0).max(0.0);
    let off = opening / 2.0 + wall / 2.0;
    let z = -height / 2.0;
    let at = |x: f64, y: f64, z: f64| hole * Translation3::new(x, y, z);
    for s in [-1.0, 1.0] {
        e.cubes
            .push(primitive(&at(s * off, 0.0, z), [wall, side, height], wood));
        e.cubes.push(primitive(
            &at(0.0, s * off, z),
            [opening, wall, height],
            wood,
        ));
    }
    let floor = (height - depth).max(0.0);
    e.cubes.push(primitive(
        &at(0.0, 0.0, -depth - floor / 2.0),
        [opening, opening, floor],
        wood,
    ));
    e
}

/// A `foxglove.SceneUpdate` of `entities` (replacing those of the same
/// ids), serialised into `out`.
pub fn scene_update(out: &mut Vec<u8>, entities: &[Entity]) {
    #[derive(Serialize)]
    struct SceneUpdate<'a> {
        deletions: Vec<()>,
        entities: &'a [Entity],
    }
    out.clear();
    serde_json::to_writer(
        &mut *out,
        &SceneUpdate {
            deletions: Vec::new(),
            entities,
        },
    )
    .expect("scene updates serialise");
}
