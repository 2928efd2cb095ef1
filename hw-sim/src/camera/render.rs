//! The renderer: screen bounds per primitive, ray casting, shading, depth
//! noise and the ground-truth flow; the frame it fills.

use super::*;
use crate::config::CameraConfig;
use crate::rng::{self, SimRng};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Vector3};
use shared_mem_schema::CameraCalibration;

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
    /// frame, moving or not. Zero elsewhere.
    pub flow_px: Vec<[f32; 2]>,
    /// The robot in motion (the paper's flow mask): 1 where the previous
    /// frame saw the robot or the peg and that point moved at least
    /// [`FLOW_MASK_MIN_PX`] in the image, else 0. All zero in the first
    /// frame of an episode.
    pub flow_mask: Vec<u8>,
}

/// Image-plane displacement from one frame to the next, px, from which a
/// robot or peg pixel counts as moving in [`CameraFrame::flow_mask`].
/// Measured on collected data (docs/paper.md, "Flow mask"):
/// an arm holding still under the controller moves its pixels far less
/// than this, and a tenth of a pixel is below what a flow label resolves
/// (the paper predicts flow at 32×32, a quarter of the image's resolution).
pub const FLOW_MASK_MIN_PX: f32 = 0.1;

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

impl CameraConfig {
    /// The calibration a camera of this configuration reports in its
    /// frames (computed, no camera built).
    pub fn calibration(&self) -> CameraCalibration {
        let (pose, focal_px, principal_px) = self.pinhole();
        CameraCalibration {
            width: self.width,
            height: self.height,
            focal_px,
            principal_px,
            pose_pos_m: pose.translation.vector.into(),
            pose_quat_xyzw: pose.rotation.coords.into(),
        }
    }

    /// The look-at pose (x right, y down, z forward, in the base frame),
    /// the focal length and the principal point, px.
    fn pinhole(&self) -> (Isometry3<f64>, f64, [f64; 2]) {
        let eye = Vector3::from(self.eye_m);
        let forward = (Vector3::from(self.target_m) - eye).normalize();
        let right = forward.cross(&Vector3::z()).normalize();
        let down = forward.cross(&right);
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[right, down, forward]));
        let pose = Isometry3::from_parts(eye.into(), rot.into());
        let focal_px = 0.5 * self.height as f64 / (0.5 * self.vertical_fov_deg.to_radians()).tan();
        let principal = [0.5 * self.width as f64, 0.5 * self.height as f64];
        (pose, focal_px, principal)
    }
}

impl Camera {
    /// A camera over `prims`; `seed` drives its noise.
    pub fn new(config: &CameraConfig, prims: Vec<Primitive>, seed: u64) -> Self {
        let (pose, focal_px, principal) = config.pinhole();
        Self::with_intrinsics(config, pose, focal_px, principal, prims, seed)
    }

    /// A camera of known calibration (as a log records it), seeing up to
    /// `max_depth_m`; the rest of its configuration is the default one.
    pub fn calibrated(
        cal: &CameraCalibration,
        max_depth_m: f64,
        prims: Vec<Primitive>,
        seed: u64,
    ) -> Self {
        let config = CameraConfig {
            width: cal.width,
            height: cal.height,
            max_depth_m,
            ..CameraConfig::default()
        };
        let rotation = crate::convert::unit_quaternion(cal.pose_quat_xyzw);
        let pose = Isometry3::from_parts(Vector3::from(cal.pose_pos_m).into(), rotation);
        Self::with_intrinsics(&config, pose, cal.focal_px, cal.principal_px, prims, seed)
    }

    /// The camera's calibration (image size, intrinsics, pose).
    pub fn calibration(&self) -> CameraCalibration {
        CameraCalibration {
            width: self.config.width,
            height: self.config.height,
            focal_px: self.focal_px,
            principal_px: self.principal_px,
            pose_pos_m: self.pose.translation.vector.into(),
            pose_quat_xyzw: self.pose.rotation.coords.into(),
        }
    }

    /// `pose` is the camera frame (x right, y down, z forward) in the base
    /// frame.
    fn with_intrinsics(
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
            rng: rng::seeded(seed, 4),
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
                    c += rgb_std * rng::normal(&mut self.rng);
                }
                frame.rgb[3 * i + k] = to_level(c);
            }
            let mut depth = t;
            if depth_std > 0.0 {
                depth += depth_std * rng::normal(&mut self.rng);
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
                        let f = [(u - u0) as f32, (v - v0) as f32];
                        frame.flow_px[i] = f;
                        let moved =
                            f[0] * f[0] + f[1] * f[1] >= FLOW_MASK_MIN_PX * FLOW_MASK_MIN_PX;
                        frame.flow_mask[i] = moved as u8;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_configurations_calibration_is_its_cameras() {
        let c = CameraConfig {
            width: 96,
            height: 64,
            vertical_fov_deg: 40.0,
            eye_m: [0.9, -0.24, 0.77],
            target_m: [0.58, 0.0, 0.2],
            ..CameraConfig::default()
        };
        let built = Camera::new(&c, Vec::new(), 0).calibration();
        assert_eq!(c.calibration(), built);
        assert_eq!(built.principal_px, [48.0, 32.0]);
        assert_ne!(CameraConfig::default().calibration(), built);
    }
}
