//! Peg and box-with-hole geometry: convex prisms that both the physics (as
//! convex hulls) and the renderer (as plane sets) use, so that what is seen
//! is exactly what collides.

use serde::{Deserialize, Serialize};

/// The four pegs of the paper (Fig. "peg types").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum PegShape {
    /// Square cross-section; `width` is the side.
    #[default]
    Square,
    /// Equilateral triangle; `width` is the side.
    Triangle,
    /// Half disk; `width` is the diameter.
    Semicircle,
    /// Regular hexagon; `width` is the distance across flats.
    Hexagon,
}

impl PegShape {
    /// All four, in the paper's order.
    pub const ALL: [PegShape; 4] = [
        PegShape::Square,
        PegShape::Triangle,
        PegShape::Semicircle,
        PegShape::Hexagon,
    ];

    /// Rotational symmetry order about the peg axis: the roll error wraps
    /// with period 2π / order.
    pub fn symmetry_order(self) -> u32 {
        match self {
            PegShape::Square => 4,
            PegShape::Triangle => 3,
            PegShape::Semicircle => 1,
            PegShape::Hexagon => 6,
        }
    }

    /// Lower-case name as used in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            PegShape::Square => "square",
            PegShape::Triangle => "triangle",
            PegShape::Semicircle => "semicircle",
            PegShape::Hexagon => "hexagon",
        }
    }

    /// The cross-section, counter-clockwise, with its area centroid at the
    /// origin (the peg axis passes through the centroid).
    pub fn outline(self, width: f64) -> Vec<[f64; 2]> {
        let mut pts: Vec<[f64; 2]> = match self {
            PegShape::Square => {
                let h = 0.5 * width;
                vec![[-h, -h], [h, -h], [h, h], [-h, h]]
            }
            PegShape::Triangle => regular(3, width / 3f64.sqrt(), std::f64::consts::FRAC_PI_2),
            PegShape::Hexagon => regular(6, width / 3f64.sqrt(), 0.0),
            PegShape::Semicircle => {
                // The arc as a polygon with vertices on the circle: 12 segments
                // keep the chord sag at 0.13 mm for a 30 mm peg (an eighth of
                // the 1 mm radial clearance) with half the wall pieces of 24.
                let r = 0.5 * width;
                let n = 12;
                (0..=n)
                    .map(|k| {
                        let a = std::f64::consts::PI * k as f64 / n as f64;
                        [r * a.cos(), r * a.sin()]
                    })
                    .collect()
            }
        };
        let c = centroid(&pts);
        for p in &mut pts {
            p[0] -= c[0];
            p[1] -= c[1];
        }
        pts
    }
}

fn regular(n: usize, circumradius: f64, phase: f64) -> Vec<[f64; 2]> {
    (0..n)
        .map(|k| {
            let a = phase + std::f64::consts::TAU * k as f64 / n as f64;
            [circumradius * a.cos(), circumradius * a.sin()]
        })
        .collect()
}

/// Area centroid of a simple polygon.
pub fn centroid(poly: &[[f64; 2]]) -> [f64; 2] {
    let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..poly.len() {
        let p = poly[i];
        let q = poly[(i + 1) % poly.len()];
        let cr = p[0] * q[1] - q[0] * p[1];
        a += cr;
        cx += (p[0] + q[0]) * cr;
        cy += (p[1] + q[1]) * cr;
    }
    [cx / (3.0 * a), cy / (3.0 * a)]
}

/// Signed area (positive for counter-clockwise).
pub fn area(poly: &[[f64; 2]]) -> f64 {
    let mut a = 0.0;
    for i in 0..poly.len() {
        let p = poly[i];
        let q = poly[(i + 1) % poly.len()];
        a += p[0] * q[1] - q[0] * p[1];
    }
    0.5 * a
}

/// Offsets a convex counter-clockwise polygon outwards by `d` (each edge
/// moves `d` along its outward normal; corners are mitred).
pub fn offset_convex(poly: &[[f64; 2]], d: f64) -> Vec<[f64; 2]> {
    let n = poly.len();
    let lines: Vec<([f64; 2], f64)> = (0..n)
        .map(|i| {
            let a = poly[i];
            let b = poly[(i + 1) % n];
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = (dx * dx + dy * dy).sqrt();
            let nrm = [dy / len, -dx / len];
            (nrm, nrm[0] * a[0] + nrm[1] * a[1] + d)
        })
        .collect();
    (0..n)
        .map(|i| {
            let (n1, c1) = lines[(i + n - 1) % n];
            let (n2, c2) = lines[i];
            let det = n1[0] * n2[1] - n1[1] * n2[0];
            [
                (c1 * n2[1] - c2 * n1[1]) / det,
                (n1[0] * c2 - n2[0] * c1) / det,
            ]
        })
        .collect()
}

/// The outline of the hole for a peg of outline `peg`: the peg's grown by
/// half the diametral `clearance` on every side.
pub fn hole_outline(peg: &[[f64; 2]], clearance: f64) -> Vec<[f64; 2]> {
    offset_convex(peg, 0.5 * clearance)
}

/// How far `p` lies inside a convex counter-clockwise polygon: the least
/// distance from `p` to the lines through its edges. Inside, that is the
/// distance to the outline; outside, it is negative (its size is then only a
/// lower bound of the distance).
pub fn inset(poly: &[[f64; 2]], p: [f64; 2]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let a = poly[i];
            let b = poly[(i + 1) % n];
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            // Outward normal (dy, −dx) / len, as in `offset_convex`.
            (dy * (a[0] - p[0]) - dx * (a[1] - p[1])) / dx.hypot(dy)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Keeps the part of a convex polygon where `n·x ≤ c` (Sutherland–Hodgman).
fn clip(poly: &[[f64; 2]], n: [f64; 2], c: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    let side = |p: [f64; 2]| n[0] * p[0] + n[1] * p[1] - c;
    for i in 0..poly.len() {
        let p = poly[i];
        let q = poly[(i + 1) % poly.len()];
        let (sp, sq) = (side(p), side(q));
        if sp <= 0.0 {
            out.push(p);
        }
        if (sp < 0.0 && sq > 0.0) || (sp > 0.0 && sq < 0.0) {
            let t = sp / (sp - sq);
            out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
    }
    out
}

/// A convex polygon (counter-clockwise, in a body frame's x-y plane)
/// extruded along z from `z0` to `z1`.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexPrism {
    /// The cross-section.
    pub polygon: Vec<[f64; 2]>,
    /// Bottom face height.
    pub z0: f64,
    /// Top face height.
    pub z1: f64,
}

impl ConvexPrism {
    /// Its corner points (for a convex-hull collider).
    pub fn points(&self) -> Vec<[f64; 3]> {
        let mut pts = Vec::with_capacity(2 * self.polygon.len());
        for z in [self.z0, self.z1] {
            pts.extend(self.polygon.iter().map(|p| [p[0], p[1], z]));
        }
        pts
    }

    /// Its bounding planes `n·x ≤ c`, outward normals of unit length.
    pub fn planes(&self) -> Vec<([f64; 3], f64)> {
        let n = self.polygon.len();
        let mut planes = Vec::with_capacity(n + 2);
        for i in 0..n {
            let a = self.polygon[i];
            let b = self.polygon[(i + 1) % n];
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = (dx * dx + dy * dy).sqrt();
            let nrm = [dy / len, -dx / len, 0.0];
            planes.push((nrm, nrm[0] * a[0] + nrm[1] * a[1]));
        }
        planes.push(([0.0, 0.0, 1.0], self.z1));
        planes.push(([0.0, 0.0, -1.0], -self.z0));
        planes
    }

    /// Volume.
    pub fn volume(&self) -> f64 {
        area(&self.polygon) * (self.z1 - self.z0)
    }
}

/// The box with its hole, in the hole frame: origin at the centre of the
/// hole's opening on the top face, z up, the hole's outline matching the
/// peg's outline at zero relative roll. The box spans z ∈ [−height, 0].
#[derive(Clone, Debug)]
pub struct BoxWithHole {
    /// The hole's outline (the peg's, offset by half the clearance).
    pub hole: Vec<[f64; 2]>,
    /// Convex pieces: the slab under the hole, then one wall piece per hole
    /// edge.
    pub pieces: Vec<ConvexPrism>,
    /// Box height, m.
    pub height: f64,
    /// Hole depth, m.
    pub depth: f64,
    /// Half of the outer side length, m.
    pub half_side: f64,
}

impl BoxWithHole {
    /// How far the point `xy` of the hole frame lies inside the hole's
    /// outline (negative outside; see [`inset`]).
    pub fn hole_inset(&self, xy: [f64; 2]) -> f64 {
        inset(&self.hole, xy)
    }

    /// Builds the box around the hole for `peg` (its outline) with the given
    /// diametral clearance.
    ///
    /// The walls are the square minus the hole, cut into convex pieces: for
    /// each hole edge, the square's part inside the wedge from the hole's
    /// centroid through the edge's end points and outside the edge. Each is
    /// an intersection of convex sets, hence convex, and together they tile
    /// the square minus the hole.
    pub fn new(peg: &[[f64; 2]], clearance: f64, side: f64, height: f64, depth: f64) -> Self {
        let hole = hole_outline(peg, clearance);
        let h = 0.5 * side;
        let square = vec![[-h, -h], [h, -h], [h, h], [-h, h]];
        let c = centroid(&hole);
        let mut pieces = vec![ConvexPrism {
            polygon: square.clone(),
            z0: -height,
            z1: -depth,
        }];
        let n = hole.len();
        for i in 0..n {
            let a = hole[i];
            let b = hole[(i + 1) % n];
            // Left of the ray c→a: cross(a − c, x − c) ≥ 0 ⇔ n·x ≤ n·c with
            // n = (ay − cy, −(ax − cx)).
            let na = [a[1] - c[1], -(a[0] - c[0])];
            let nb = [-(b[1] - c[1]), b[0] - c[0]];
            let ne = [-(b[1] - a[1]), b[0] - a[0]];
            let mut poly = clip(&square, na, na[0] * c[0] + na[1] * c[1]);
            poly = clip(&poly, nb, nb[0] * c[0] + nb[1] * c[1]);
            poly = clip(&poly, ne, ne[0] * a[0] + ne[1] * a[1]);
            poly.dedup_by(|p, q| (p[0] - q[0]).hypot(p[1] - q[1]) < 1e-12);
            if poly.len() >= 3 && area(&poly) > 1e-12 {
                pieces.push(ConvexPrism {
                    polygon: poly,
                    z0: -depth,
                    z1: 0.0,
                });
            }
        }
        Self {
            hole,
            pieces,
            height,
            depth,
            half_side: h,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outlines_are_ccw_centred_and_sized() {
        for shape in PegShape::ALL {
            let p = shape.outline(0.03);
            assert!(area(&p) > 0.0, "{shape:?} not counter-clockwise");
            let c = centroid(&p);
            assert!(c[0].abs() < 1e-12 && c[1].abs() < 1e-12, "{shape:?} {c:?}");
        }
        assert!((area(&PegShape::Square.outline(0.03)) - 9e-4).abs() < 1e-15);
        let hex = PegShape::Hexagon.outline(0.03);
        assert!((area(&hex) - 3f64.sqrt() / 2.0 * 9e-4).abs() < 1e-12);
    }

    #[test]
    fn offset_moves_every_edge_by_the_distance() {
        for shape in PegShape::ALL {
            let p = shape.outline(0.03);
            let o = offset_convex(&p, 0.001);
            let pp = ConvexPrism {
                polygon: p,
                z0: 0.0,
                z1: 1.0,
            }
            .planes();
            let op = ConvexPrism {
                polygon: o,
                z0: 0.0,
                z1: 1.0,
            }
            .planes();
            for (a, b) in pp.iter().zip(&op).take(pp.len() - 2) {
                assert!((a.0[0] - b.0[0]).abs() < 1e-12 && (a.0[1] - b.0[1]).abs() < 1e-12);
                assert!((b.1 - a.1 - 0.001).abs() < 1e-12, "{shape:?}");
            }
        }
    }

    #[test]
    fn inset_is_the_distance_inside_and_negative_outside() {
        let sq = PegShape::Square.outline(0.03);
        assert!((inset(&sq, [0.0, 0.0]) - 0.015).abs() < 1e-15);
        assert!((inset(&sq, [0.01, -0.004]) - 0.005).abs() < 1e-15);
        assert!(inset(&sq, [0.02, 0.0]) < 0.0);
        assert!(inset(&sq, [0.0, 0.1]) < -0.08);
        for shape in PegShape::ALL {
            let p = shape.outline(0.03);
            // Every vertex is on the outline, and a point just beyond it
            // (away from the centroid) is outside.
            for v in &p {
                assert!(inset(&p, *v).abs() < 1e-12, "{shape:?}");
                assert!(inset(&p, [1.01 * v[0], 1.01 * v[1]]) < 0.0, "{shape:?}");
            }
            // The offset outline is `d` farther from the centroid everywhere.
            let o = offset_convex(&p, 0.001);
            assert!((inset(&o, [0.0, 0.0]) - inset(&p, [0.0, 0.0]) - 0.001).abs() < 1e-12);
        }
        // The semicircle's centroid is about 4r/3π from its flat side (less
        // the 12-segment arc's effect, well under 0.1 mm).
        let semi = PegShape::Semicircle.outline(0.03);
        let expect = 4.0 * 0.015 / (3.0 * std::f64::consts::PI);
        assert!((inset(&semi, [0.0, 0.0]) - expect).abs() < 1e-4);
    }

    #[test]
    fn box_pieces_tile_the_square_minus_the_hole() {
        for shape in PegShape::ALL {
            let peg = shape.outline(0.03);
            let b = BoxWithHole::new(&peg, 0.002, 0.16, 0.1, 0.04);
            let walls: f64 = b.pieces[1..].iter().map(|p| area(&p.polygon)).sum();
            let expect = 0.16 * 0.16 - area(&b.hole);
            assert!(
                (walls - expect).abs() < 1e-12,
                "{shape:?}: {walls} vs {expect}"
            );
            for piece in &b.pieces {
                // Convex and counter-clockwise: every turn is a left turn.
                let p = &piece.polygon;
                for i in 0..p.len() {
                    let (a, b2, c) = (p[i], p[(i + 1) % p.len()], p[(i + 2) % p.len()]);
                    let cr = (b2[0] - a[0]) * (c[1] - b2[1]) - (b2[1] - a[1]) * (c[0] - b2[0]);
                    assert!(cr > -1e-15, "{shape:?}: reflex corner");
                }
            }
        }
    }
}
