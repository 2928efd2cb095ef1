//! Ray geometry: the primitives the camera sees and their exact ray
//! intersections.

use nalgebra::{Isometry3, Vector3};

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
    pub(super) fn cover(&self) -> Vec<(Vector3<f64>, f64)> {
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
    pub(super) fn intersect(
        &self,
        o: &Vector3<f64>,
        d: &Vector3<f64>,
    ) -> Option<(f64, Vector3<f64>)> {
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
