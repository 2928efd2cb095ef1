//! The fixed RGB-D camera: an exact ray caster over the collision geometry
//! (the shapes the physics uses, intersected analytically), and the
//! ground-truth optical flow between consecutive frames.
//!
//! Rays are only cast where a primitive can appear: each primitive's
//! bounding sphere is projected to a screen rectangle, and only the pixels
//! inside it test that primitive. Ray directions are `(x, y, 1)` in the
//! camera frame, so a hit's ray parameter is its depth.

use crate::config::CameraConfig;
use crate::rng::SimRng;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Vector3};

/// What a pixel sees (the segmentation channel).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Class {
    /// Nothing within range.
    None = 0,
    /// The floor.
    Ground = 1,
    /// The box with the hole.
    Box = 2,
    /// A link of the robot.
    Robot = 3,
    /// The peg.
    Peg = 4,
}

/// The body a primitive moves with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyRef {
    /// Never moves (the floor).
    Static,
    /// The body moved by robot-model joint `j` (0: the base).
    Link(usize),
    /// The box (its hole frame).
    Box,
}

/// Analytic shapes in a primitive's own frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    /// Segment from z = −half_length to +half_length, swept by a sphere.
    Capsule {
        /// Half length of the segment.
        half_length: f64,
        /// Radius.
        radius: f64,
    },
    /// Flat-capped cylinder along z.
    Cylinder {
        /// Half length.
        half_length: f64,
        /// Radius.
        radius: f64,
    },
    /// Sphere at the origin.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// Axis-aligned box at the origin.
    Cuboid {
        /// Half extents.
        half: Vector3<f64>,
    },
    /// Convex polyhedron `n·x ≤ c` for each plane.
    Convex {
        /// Outward unit normals and offsets.
        planes: Vec<(Vector3<f64>, f64)>,
        /// Its corner points (for bounds).
        points: Vec<Vector3<f64>>,
    },
}

impl Geometry {
    /// Spheres (centre, radius; radius 0 for a point) in the primitive
    /// frame whose convex hull contains the shape: the renderer projects
    /// them to bound the pixels that can see it. Corners for polyhedra and
    /// end spheres for capsules and cylinders bound far tighter on screen
    /// than one bounding sphere does for the long, thin links and wall
    /// pieces.
    fn cover(&self) -> Vec<(Vector3<f64>, f64)> {
        let ends = |h: f64, r: f64| {
            vec![
                (Vector3::new(0.0, 0.0, -h), r),
                (Vector3::new(0.0, 0.0, h), r),
            ]
        };
        match self {
            Geometry::Capsule {
                half_length,
                radius,
            }
            | Geometry::Cylinder {
                half_length,
                radius,
            } => ends(*half_length, *radius),
            Geometry::Sphere { radius } => vec![(Vector3::zeros(), *radius)],
            Geometry::Cuboid { half } => (0..8)
                .map(|k| {
                    let s = |bit: usize| if k & bit == 0 { -1.0 } else { 1.0 };
                    (
                        Vector3::new(s(1) * half.x, s(2) * half.y, s(4) * half.z),
                        0.0,
                    )
                })
                .collect(),
            Geometry::Convex { points, .. } => points.iter().map(|p| (*p, 0.0)).collect(),
        }
    }

    /// First hit of the ray `o + t d` with t > 0: (t, outward normal).
    fn intersect(&self, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        match self {
            Geometry::Sphere { radius } => ray_sphere(o, d, &Vector3::zeros(), *radius),
            Geometry::Capsule {
                half_length,
                radius,
            } => ray_capsule(o, d, *half_length, *radius),
            Geometry::Cylinder {
                half_length,
                radius,
            } => ray_cylinder(o, d, *half_length, *radius),
            Geometry::Cuboid { half } => ray_cuboid(o, d, half),
            Geometry::Convex { planes, .. } => ray_convex(o, d, planes),
        }
    }
}

fn ray_sphere(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    c: &Vector3<f64>,
    r: f64,
) -> Option<(f64, Vector3<f64>)> {
    let oc = o - c;
    let a = d.norm_squared();
    let b = oc.dot(d);
    let cc = oc.norm_squared() - r * r;
    let disc = b * b - a * cc;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / a;
    (t > 0.0).then(|| (t, (oc + d * t) / r))
}

fn ray_capsule(o: &Vector3<f64>, d: &Vector3<f64>, h: f64, r: f64) -> Option<(f64, Vector3<f64>)> {
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-18 {
        let b = o.x * d.x + o.y * d.y;
        let c = o.x * o.x + o.y * o.y - r * r;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None; // misses the infinite cylinder, hence the capsule
        }
        let t = (-b - disc.sqrt()) / a;
        let z = o.z + t * d.z;
        if t > 0.0 && z.abs() <= h {
            let p = o + d * t;
            return Some((t, Vector3::new(p.x / r, p.y / r, 0.0)));
        }
    }
    // Otherwise the first hit, if any, is on a cap: the nearer sphere hit
    // that lies beyond its end of the segment.
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for sign in [-1.0, 1.0] {
        let c = Vector3::new(0.0, 0.0, sign * h);
        if let Some((t, n)) = ray_sphere(o, d, &c, r)
            && n.z * sign >= 0.0
            && best.is_none_or(|b| t < b.0)
        {
            best = Some((t, n));
        }
    }
    best
}

fn ray_cylinder(o: &Vector3<f64>, d: &Vector3<f64>, h: f64, r: f64) -> Option<(f64, Vector3<f64>)> {
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-18 {
        let b = o.x * d.x + o.y * d.y;
        let c = o.x * o.x + o.y * o.y - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let p = o + d * t;
            if t > 0.0 && p.z.abs() <= h {
                best = Some((t, Vector3::new(p.x / r, p.y / r, 0.0)));
            }
        }
    }
    if d.z.abs() > 1e-18 {
        for sign in [-1.0, 1.0] {
            let t = (sign * h - o.z) / d.z;
            let p = o + d * t;
            if t > 0.0 && p.x * p.x + p.y * p.y <= r * r && best.is_none_or(|b| t < b.0) {
                best = Some((t, Vector3::new(0.0, 0.0, sign)));
            }
        }
    }
    best
}

fn ray_cuboid(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    half: &Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut axis = 0;
    let mut sign = 1.0;
    for i in 0..3 {
        if d[i].abs() < 1e-18 {
            if o[i].abs() > half[i] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[i];
        let (a, b) = ((-half[i] - o[i]) * inv, (half[i] - o[i]) * inv);
        let (near, far, s) = if a < b { (a, b, -1.0) } else { (b, a, 1.0) };
        if near > t0 {
            t0 = near;
            axis = i;
            sign = s;
        }
        t1 = t1.min(far);
    }
    if t0 > t1 || t0 <= 0.0 {
        return None;
    }
    let mut n = Vector3::zeros();
    n[axis] = sign;
    Some((t0, n))
}

fn ray_convex(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    planes: &[(Vector3<f64>, f64)],
) -> Option<(f64, Vector3<f64>)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut normal = Vector3::zeros();
    for (n, c) in planes {
        let denom = n.dot(d);
        let dist = c - n.dot(o);
        if denom.abs() < 1e-18 {
            if dist < 0.0 {
                return None;
            }
            continue;
        }
        let t = dist / denom;
        if denom < 0.0 {
            if t > t0 {
                t0 = t;
                normal = *n;
            }
        } else {
            t1 = t1.min(t);
        }
        if t0 > t1 {
            return None;
        }
    }
    (t0 > 0.0 && t0 <= t1).then_some((t0, normal))
}

/// One renderable primitive.
#[derive(Clone, Debug)]
pub struct Primitive {
    /// The body it moves with.
    pub body: BodyRef,
    /// Its pose in the body frame.
    pub local: Isometry3<f64>,
    /// Its shape.
    pub geometry: Geometry,
    /// What it is.
    pub class: Class,
    /// Base colour, linear 0..1.
    pub color: [f64; 3],
}

/// One rendered frame: RGB, depth, segmentation and the ground-truth flow
/// from the previous frame to this one.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraFrame {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Simulated time of the frame, s.
    pub t_s: f64,
    /// Frames since the reset (0 is the first).
    pub index: u64,
    /// RGB, row-major, 3 bytes per pixel.
    pub rgb: Vec<u8>,
    /// Depth along the optical axis, m; 0 where nothing is within range or
    /// the view is occluded.
    pub depth_m: Vec<f32>,
    /// [`Class`] per pixel.
    pub class: Vec<u8>,
    /// Forward flow on the previous frame's pixel grid, px: where each pixel
    /// of the previous frame that saw the robot or the peg went in this
    /// frame. Zero elsewhere.
    pub flow_px: Vec<[f32; 2]>,
    /// 1 where `flow_px` is defined (the previous frame saw the robot or the
    /// peg there), else 0. All zero in the first frame of an episode.
    pub flow_mask: Vec<u8>,
}

/// Poses of the bodies at render time.
pub struct BodyPoses<'a> {
    /// Per robot-model joint (0: the base).
    pub links: &'a [Isometry3<f64>],
    /// The box's hole frame, if there is a box.
    pub box_pose: Option<Isometry3<f64>>,
}

impl BodyPoses<'_> {
    fn get(&self, b: BodyRef) -> Isometry3<f64> {
        match b {
            BodyRef::Static => Isometry3::identity(),
            BodyRef::Link(j) => self.links[j],
            BodyRef::Box => self.box_pose.unwrap_or_else(Isometry3::identity),
        }
    }
}

/// One instant as the camera sees it: body poses, time, occlusions and
/// noise levels (see [`crate::World::camera_shot`]).
#[derive(Clone, Debug)]
pub struct CameraShot {
    /// Per robot-model joint (0: the base).
    pub links: Vec<Isometry3<f64>>,
    /// The box's hole frame, if there is a box.
    pub box_pose: Option<Isometry3<f64>>,
    /// Simulated time, s.
    pub t_s: f64,
    /// Occluding rectangles `[x, y, w, h]` (`None`: the whole image).
    pub occlusions: Vec<Option<[u32; 4]>>,
    /// (depth σ in m, RGB σ in levels).
    pub noise: (f64, f64),
}

/// The renderer and its state between frames.
#[derive(Clone)]
pub struct Camera {
    config: CameraConfig,
    /// Camera frame → base frame (x right, y down, z forward).
    pub pose: Isometry3<f64>,
    /// Focal length, px.
    pub focal_px: f64,
    /// Principal point (u, v), px.
    pub principal_px: [f64; 2],
    prims: Vec<Primitive>,
    /// Per primitive: its covering spheres ([`Geometry::cover`]).
    covers: Vec<Vec<(Vector3<f64>, f64)>>,
    dirs: Vec<Vector3<f64>>,
    /// The nearest hits of the frame being rendered.
    layer: Layer,
    /// The floor's and the box's hits, for the box pose they were cast at.
    still: Option<Layer>,
    /// The still layer shaded without noise, as a frame holds it.
    still_rgb: Vec<u8>,
    still_depth: Vec<f32>,
    still_class: Vec<u8>,
    /// Where `cur` and `prev` hold points (outside: `None`).
    cur_rect: Rect,
    prev_rect: Rect,
    /// Shade every pixel every frame (a test's reference for the fast path).
    exhaustive: bool,
    /// Per pixel of the last frame: the body and the hit point in its frame.
    prev: Vec<Option<(BodyRef, Vector3<f64>)>>,
    cur: Vec<Option<(BodyRef, Vector3<f64>)>>,
    has_prev: bool,
    frames: u64,
    rng: SimRng,
}

const NO_HIT: u32 = u32::MAX;

/// A pixel rectangle `[u0, u1) × [v0, v1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rect {
    u0: usize,
    u1: usize,
    v0: usize,
    v1: usize,
}

impl Rect {
    const EMPTY: Rect = Rect {
        u0: usize::MAX,
        u1: 0,
        v0: usize::MAX,
        v1: 0,
    };

    fn full(w: usize, h: usize) -> Rect {
        Rect {
            u0: 0,
            u1: w,
            v0: 0,
            v1: h,
        }
    }

    fn is_empty(&self) -> bool {
        self.u0 >= self.u1 || self.v0 >= self.v1
    }

    fn union(self, o: Rect) -> Rect {
        if o.is_empty() {
            return self;
        }
        if self.is_empty() {
            return o;
        }
        Rect {
            u0: self.u0.min(o.u0),
            u1: self.u1.max(o.u1),
            v0: self.v0.min(o.v0),
            v1: self.v1.max(o.v1),
        }
    }

    /// Its rows as index ranges of a row-major image `w` wide.
    fn rows(self, w: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
        let (u0, u1) = (self.u0, self.u1.max(self.u0));
        let v1 = if self.is_empty() { self.v0 } else { self.v1 };
        (self.v0..v1).map(move |v| v * w + u0..v * w + u1)
    }

    /// Its pixel indices, row by row.
    fn pixels(self, w: usize) -> impl Iterator<Item = usize> {
        self.rows(w).flatten()
    }
}

/// Lambert shading with an ambient floor, 0.35..1.
fn lambert(normal: &Vector3<f64>, light: &Vector3<f64>) -> f64 {
    0.35 + 0.65 * normal.dot(light).max(0.0)
}

/// A colour value to an 8-bit level, rounding half up (`f64::round` is a
/// libm call on this ISA baseline, 10% of a frame).
fn to_level(c: f64) -> u8 {
    (c.clamp(0.0, 255.0) + 0.5) as u8
}

/// Nearest hit per pixel: ray parameter (depth along the optical axis, since
/// the directions have z = 1), primitive index and world normal.
#[derive(Clone)]
struct Layer {
    t: Vec<f64>,
    hit: Vec<u32>,
    normal: Vec<Vector3<f64>>,
    /// The box pose the layer was cast at (the still layer only).
    box_pose: Option<Isometry3<f64>>,
}

impl Layer {
    fn new(n: usize) -> Self {
        Self {
            t: vec![f64::INFINITY; n],
            hit: vec![NO_HIT; n],
            normal: vec![Vector3::zeros(); n],
            box_pose: None,
        }
    }

    fn clear(&mut self) {
        self.t.fill(f64::INFINITY);
        self.hit.fill(NO_HIT);
    }
}
const LIGHT: [f64; 3] = [0.35, -0.45, 0.82];

impl Camera {
    /// A camera over `prims`; `seed` drives its noise.
    pub fn new(config: &CameraConfig, prims: Vec<Primitive>, seed: u64) -> Self {
        let eye = Vector3::from(config.eye_m);
        let forward = (Vector3::from(config.target_m) - eye).normalize();
        let right = forward.cross(&Vector3::z()).normalize();
        let down = forward.cross(&right);
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[right, down, forward]));
        let pose = Isometry3::from_parts(eye.into(), rot.into());
        let focal_px =
            0.5 * config.height as f64 / (0.5 * config.vertical_fov_deg.to_radians()).tan();
        let principal = [0.5 * config.width as f64, 0.5 * config.height as f64];
        Self::calibrated(config, pose, focal_px, principal, prims, seed)
    }

    /// A camera of known calibration (as a log records it): `pose` is the
    /// camera frame (x right, y down, z forward) in the base frame; of
    /// `config`, only the image size and the depth range are used.
    pub fn calibrated(
        config: &CameraConfig,
        pose: Isometry3<f64>,
        focal_px: f64,
        principal_px: [f64; 2],
        prims: Vec<Primitive>,
        seed: u64,
    ) -> Self {
        let (w, h) = (config.width as usize, config.height as usize);
        let [cx, cy] = principal_px;
        let mut dirs = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                dirs.push(Vector3::new(
                    (u as f64 + 0.5 - cx) / focal_px,
                    (v as f64 + 0.5 - cy) / focal_px,
                    1.0,
                ));
            }
        }
        let n = w * h;
        Self {
            config: config.clone(),
            pose,
            focal_px,
            principal_px,
            covers: prims.iter().map(|p| p.geometry.cover()).collect(),
            prims,
            dirs,
            layer: Layer::new(n),
            still: None,
            still_rgb: Vec::new(),
            still_depth: Vec::new(),
            still_class: Vec::new(),
            cur_rect: Rect::EMPTY,
            prev_rect: Rect::EMPTY,
            exhaustive: false,
            prev: vec![None; n],
            cur: vec![None; n],
            has_prev: false,
            frames: 0,
            rng: SimRng::new(seed, 4),
        }
    }

    /// The primitives it draws.
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// Projects a base-frame point to pixel coordinates (u right, v down;
    /// pixel centres at half-integers) and its depth.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64, f64)> {
        let c = self.pose.inverse_transform_point(&Point3::from(*p));
        (c.z > 1e-9).then(|| {
            (
                self.principal_px[0] + self.focal_px * c.x / c.z,
                self.principal_px[1] + self.focal_px * c.y / c.z,
                c.z,
            )
        })
    }

    /// Renders a [`CameraShot`] into `frame` (see [`Camera::render`]).
    pub fn render_shot(&mut self, shot: &CameraShot, frame: &mut CameraFrame) {
        let poses = BodyPoses {
            links: &shot.links,
            box_pose: shot.box_pose,
        };
        self.render(&poses, shot.t_s, &shot.occlusions, shot.noise, frame);
    }

    /// The pixels that can see primitive `pi` at pose `world`: the union of
    /// its covering spheres' projected bounds, or the whole image if any
    /// reaches behind the eye.
    fn screen_rect(&self, pi: usize, world: &Isometry3<f64>) -> Rect {
        let (w, h) = (self.config.width as usize, self.config.height as usize);
        let ([cx, cy], f) = (self.principal_px, self.focal_px);
        let mut rect = Rect::EMPTY;
        for (bc, br) in &self.covers[pi] {
            let c = self
                .pose
                .inverse_transform_point(&(world * Point3::from(*bc)));
            if c.z - br <= 1e-3 {
                return Rect::full(w, h);
            }
            let (zn, zf) = (c.z - br, c.z + br);
            let lo = |a: f64| (a / zn).min(a / zf);
            let hi = |a: f64| (a / zn).max(a / zf);
            let clampi = |x: f64, m: usize| x.floor().clamp(0.0, m as f64) as usize;
            rect = rect.union(Rect {
                u0: clampi(cx + f * lo(c.x - br), w),
                u1: clampi(cx + f * hi(c.x + br) + 1.0, w),
                v0: clampi(cy + f * lo(c.y - br), h),
                v1: clampi(cy + f * hi(c.y + br) + 1.0, h),
            });
        }
        rect
    }

    /// The union of the screen rectangles of the primitives `skip` keeps.
    fn region(&self, poses: &BodyPoses, skip: impl Fn(BodyRef) -> bool) -> Rect {
        self.prims
            .iter()
            .enumerate()
            .filter(|(_, p)| !skip(p.body))
            .fold(Rect::EMPTY, |r, (pi, p)| {
                r.union(self.screen_rect(pi, &(poses.get(p.body) * p.local)))
            })
    }

    /// Casts the camera's rays at every primitive whose body `skip` does
    /// not exclude, keeping the nearest hit per pixel in `layer`.
    fn cast(&self, poses: &BodyPoses, skip: impl Fn(BodyRef) -> bool, layer: &mut Layer) {
        let w = self.config.width as usize;
        let cam_rot = self.pose.rotation.to_rotation_matrix().into_inner();
        let eye = self.pose.translation.vector;
        for (pi, prim) in self.prims.iter().enumerate() {
            if skip(prim.body) {
                continue;
            }
            let world = poses.get(prim.body) * prim.local;
            let rect = self.screen_rect(pi, &world);
            if rect.is_empty() {
                continue;
            }
            // Ray in the primitive frame: origin once, directions through a
            // fixed 3×3 map of the camera-frame direction.
            let inv = world.inverse();
            let o = inv.transform_point(&Point3::from(eye)).coords;
            let m = inv.rotation.to_rotation_matrix().into_inner() * cam_rot;
            for i in rect.pixels(w) {
                let d = m * self.dirs[i];
                if let Some((t, nrm)) = prim.geometry.intersect(&o, &d)
                    && t < layer.t[i]
                {
                    layer.t[i] = t;
                    layer.hit[i] = pi as u32;
                    layer.normal[i] = world.rotation * nrm;
                }
            }
        }
    }

    /// Renders `poses` into `frame` (buffers are reused), with the flow from
    /// the previous render. `occlusions` are `[x, y, w, h]` rectangles
    /// (`None`: the whole image). `noise` is (depth σ in m, RGB σ in levels).
    pub fn render(
        &mut self,
        poses: &BodyPoses,
        t_s: f64,
        occlusions: &[Option<[u32; 4]>],
        noise: (f64, f64),
        frame: &mut CameraFrame,
    ) {
        let (w, h) = (self.config.width as usize, self.config.height as usize);
        let n = w * h;
        let moving = |b: BodyRef| !matches!(b, BodyRef::Static | BodyRef::Box);
        // The floor and the box do not move within an episode: their hits are
        // cast and shaded once per box pose, and a frame casts rays only at
        // the arm and the peg.
        let fresh = self
            .still
            .as_ref()
            .is_none_or(|l| l.box_pose != poses.box_pose);
        if fresh {
            let mut layer = self.still.take().unwrap_or_else(|| Layer::new(n));
            layer.clear();
            layer.box_pose = poses.box_pose;
            self.cast(poses, moving, &mut layer);
            let light = Vector3::from(LIGHT).normalize();
            self.still_rgb.resize(3 * n, 0);
            self.still_depth.resize(n, 0.0);
            self.still_class.resize(n, 0);
            for i in 0..n {
                let (hit, t) = (layer.hit[i], layer.t[i]);
                let (rgb, depth, class) = if hit == NO_HIT || t > self.config.max_depth_m {
                    ([0; 3], 0.0, Class::None as u8)
                } else {
                    let prim = &self.prims[hit as usize];
                    let shade = lambert(&layer.normal[i], &light);
                    let rgb = prim.color.map(|c| to_level(255.0 * c * shade));
                    (rgb, t as f32, prim.class as u8)
                };
                self.still_rgb[3 * i..3 * i + 3].copy_from_slice(&rgb);
                self.still_depth[i] = depth;
                self.still_class[i] = class;
            }
            self.still = Some(layer);
        }
        let (depth_std, rgb_std) = noise;
        // Without noise only the pixels that can see the arm or the peg
        // differ from the shaded still scene; with noise every pixel draws.
        let fast = depth_std <= 0.0 && rgb_std <= 0.0 && !self.exhaustive;
        let region = if fast {
            self.region(poses, |b| !moving(b))
        } else {
            Rect::full(w, h)
        };
        let mut layer = std::mem::replace(&mut self.layer, Layer::new(0));
        let still = self.still.as_ref().expect("cast above");
        for row in region.rows(w) {
            layer.t[row.clone()].copy_from_slice(&still.t[row.clone()]);
            layer.hit[row.clone()].copy_from_slice(&still.hit[row.clone()]);
            layer.normal[row.clone()].copy_from_slice(&still.normal[row]);
        }
        self.cast(poses, |b| !moving(b), &mut layer);
        self.layer = layer;
        let still = self.still.as_ref().expect("cast above");
        let cam_rot = self.pose.rotation.to_rotation_matrix().into_inner();
        let eye = self.pose.translation.vector;

        frame.width = w as u32;
        frame.height = h as u32;
        frame.t_s = t_s;
        frame.index = self.frames;
        frame.rgb.resize(3 * n, 0);
        frame.depth_m.resize(n, 0.0);
        frame.class.resize(n, 0);
        frame.flow_px.resize(n, [0.0; 2]);
        frame.flow_mask.resize(n, 0);
        let light = Vector3::from(LIGHT).normalize();
        // `cur` holds points only inside the region it was last filled over.
        for i in self.cur_rect.pixels(w) {
            self.cur[i] = None;
        }
        if fast {
            frame.rgb.copy_from_slice(&self.still_rgb);
            frame.depth_m.copy_from_slice(&self.still_depth);
            frame.class.copy_from_slice(&self.still_class);
        }
        for i in region.pixels(w) {
            let hit = self.layer.hit[i];
            let t = self.layer.t[i];
            if fast && hit == still.hit[i] {
                continue; // the still scene, already in the frame
            }
            if hit == NO_HIT || t > self.config.max_depth_m {
                frame.rgb[3 * i..3 * i + 3].fill(0);
                frame.depth_m[i] = 0.0;
                frame.class[i] = Class::None as u8;
                continue;
            }
            let prim = &self.prims[hit as usize];
            let shade = lambert(&self.layer.normal[i], &light);
            for k in 0..3 {
                let mut c = 255.0 * prim.color[k] * shade;
                if rgb_std > 0.0 {
                    c += rgb_std * self.rng.normal();
                }
                frame.rgb[3 * i + k] = to_level(c);
            }
            let mut depth = t;
            if depth_std > 0.0 {
                depth += depth_std * self.rng.normal();
            }
            frame.depth_m[i] = depth as f32;
            frame.class[i] = prim.class as u8;
            if matches!(prim.class, Class::Robot | Class::Peg) {
                let world_pt = eye + cam_rot * self.dirs[i] * t;
                let local = poses
                    .get(prim.body)
                    .inverse_transform_point(&Point3::from(world_pt));
                self.cur[i] = Some((prim.body, local.coords));
            }
        }
        self.cur_rect = region;

        // Flow: each point seen on a moving body in the previous frame,
        // carried with its body to now and projected.
        frame.flow_px.fill([0.0, 0.0]);
        frame.flow_mask.fill(0);
        if self.has_prev {
            for i in self.prev_rect.pixels(w) {
                if let Some((body, local)) = self.prev[i] {
                    let p = poses.get(body) * Point3::from(local);
                    if let Some((u, v, _)) = self.project(&p.coords) {
                        let (u0, v0) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                        frame.flow_px[i] = [(u - u0) as f32, (v - v0) as f32];
                        frame.flow_mask[i] = 1;
                    }
                }
            }
        }
        std::mem::swap(&mut self.prev_rect, &mut self.cur_rect);
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.has_prev = true;
        self.frames += 1;

        for rect in occlusions {
            let [x, y, rw, rh] = rect.unwrap_or([0, 0, w as u32, h as u32]);
            for v in (y as usize).min(h)..((y + rh) as usize).min(h) {
                for u in (x as usize).min(w)..((x + rw) as usize).min(w) {
                    let i = v * w + u;
                    frame.rgb[3 * i..3 * i + 3].fill(40);
                    frame.depth_m[i] = 0.0;
                }
            }
        }
    }

    /// Forgets the previous frame (the next render has no flow).
    pub fn reset(&mut self) {
        self.has_prev = false;
        self.frames = 0;
        self.still = None;
    }

    /// Shades every pixel of every frame instead of only those that can see
    /// the arm or the peg: the reference the fast path is tested against.
    #[doc(hidden)]
    pub fn set_exhaustive(&mut self, on: bool) {
        self.exhaustive = on;
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

/// The peg as a camera primitive.
pub fn peg_primitive(peg: &crate::world::PegInfo) -> Primitive {
    Primitive {
        body: BodyRef::Link(peg.link),
        local: peg.sensor_in_link,
        geometry: prism_geometry(&peg.prism),
        class: Class::Peg,
        color: [0.85, 0.22, 0.15],
    }
}

/// Copies a rendered frame and the camera's calibration into the stack's
/// message (everything but the header). Frames larger than the message's
/// maximum are cut to it; hw-sim refuses such camera sizes before.
pub fn fill_message(
    camera: &Camera,
    frame: &CameraFrame,
    msg: &mut shared_mem_schema::CameraFrame,
) {
    let w = (frame.width as usize).min(shared_mem_schema::MAX_IMAGE_WIDTH);
    let h = (frame.height as usize).min(shared_mem_schema::MAX_IMAGE_HEIGHT);
    msg.index = frame.index;
    msg.width = w as u32;
    msg.height = h as u32;
    msg.focal_px = camera.focal_px;
    msg.principal_px = camera.principal_px;
    msg.pose_pos_m = camera.pose.translation.vector.into();
    msg.pose_quat_xyzw = camera.pose.rotation.coords.into();
    let stride = frame.width as usize;
    for v in 0..h {
        let (src, dst) = (v * stride, v * w);
        msg.rgb[3 * dst..3 * (dst + w)].copy_from_slice(&frame.rgb[3 * src..3 * (src + w)]);
        msg.depth_m[dst..dst + w].copy_from_slice(&frame.depth_m[src..src + w]);
    }
}

/// Colours a flow field (direction as hue, magnitude as saturation up to
/// `max_px`), the usual visualisation.
pub fn flow_to_rgb(frame: &CameraFrame, max_px: f32) -> Vec<u8> {
    let mut out = vec![255u8; frame.flow_px.len() * 3];
    for (i, f) in frame.flow_px.iter().enumerate() {
        if frame.flow_mask[i] == 0 {
            continue;
        }
        let mag = (f[0].hypot(f[1]) / max_px).min(1.0);
        let hue = (f[1].atan2(f[0]) / std::f32::consts::TAU).rem_euclid(1.0) * 6.0;
        let x = 1.0 - ((hue % 2.0) - 1.0).abs();
        let (r, g, b) = match hue as u32 {
            0 => (1.0, x, 0.0),
            1 => (x, 1.0, 0.0),
            2 => (0.0, 1.0, x),
            3 => (0.0, x, 1.0),
            4 => (x, 0.0, 1.0),
            _ => (1.0, 0.0, x),
        };
        for (k, c) in [r, g, b].into_iter().enumerate() {
            out[3 * i + k] = (255.0 * (1.0 - mag * (1.0 - c))) as u8;
        }
    }
    out
}

/// Depth as 8-bit grey (near bright, far dark, no return black).
pub fn depth_to_gray(frame: &CameraFrame, near_m: f32, far_m: f32) -> Vec<u8> {
    frame
        .depth_m
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                0
            } else {
                (255.0 * (1.0 - ((d - near_m) / (far_m - near_m)).clamp(0.0, 1.0))) as u8
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_intersections_hit_where_expected() {
        let o = Vector3::new(0.0, 0.0, 5.0);
        let d = Vector3::new(0.0, 0.0, -1.0);
        let cap = ray_capsule(&o, &d, 1.0, 0.5).unwrap();
        assert!((cap.0 - 3.5).abs() < 1e-12 && (cap.1.z - 1.0).abs() < 1e-12);
        let side = ray_capsule(
            &Vector3::new(5.0, 0.0, 0.3),
            &Vector3::new(-1.0, 0.0, 0.0),
            1.0,
            0.5,
        )
        .unwrap();
        assert!((side.0 - 4.5).abs() < 1e-12);
        let cyl = ray_cylinder(&o, &d, 1.0, 0.5).unwrap();
        assert!((cyl.0 - 4.0).abs() < 1e-12);
        let cube = ray_cuboid(&o, &d, &Vector3::new(1.0, 1.0, 2.0)).unwrap();
        assert!((cube.0 - 3.0).abs() < 1e-12 && cube.1.z == 1.0);
        let planes = crate::shapes::ConvexPrism {
            polygon: vec![[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]],
            z0: -2.0,
            z1: 2.0,
        }
        .planes()
        .into_iter()
        .map(|(n, c)| (Vector3::from(n), c))
        .collect::<Vec<_>>();
        let conv = ray_convex(&o, &d, &planes).unwrap();
        assert!((conv.0 - 3.0).abs() < 1e-12 && conv.1.z == 1.0);
        assert!(ray_convex(&Vector3::new(3.0, 0.0, 5.0), &d, &planes).is_none());
    }
}
