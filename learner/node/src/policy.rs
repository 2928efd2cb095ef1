//! Observations and the scripted policies: the heuristic insertion and the
//! bounded random walk.
//!
//! The heuristic is the "contact-making" half of the paper's
//! data-collection mix and the node's default policy. It knows
//! where the hole is (a calibrated cell, or the simulator's report) and
//! moves above it, aligns the roll, descends to contact, searches on a
//! spiral when it lands on the surface, and inserts.

use crate::proprio::Proprio;
use hw_sim::convert::unit_quaternion;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use shared_mem_schema::SensorFrame;
use stack_common::rng;

/// Readings kept for the policy (the paper's F/T window is 32 samples).
pub const WRENCH_WINDOW: usize = 32;

/// The last [`WRENCH_WINDOW`] wrench readings (fixed buffer).
#[derive(Debug, Clone, PartialEq)]
pub struct WrenchHistory {
    buf: [[f64; 6]; WRENCH_WINDOW],
    next: usize,
    len: usize,
}

impl Default for WrenchHistory {
    fn default() -> Self {
        Self {
            buf: [[0.0; 6]; WRENCH_WINDOW],
            next: 0,
            len: 0,
        }
    }
}

impl WrenchHistory {
    /// Adds the newest reading.
    pub fn push(&mut self, w: [f64; 6]) {
        self.buf[self.next] = w;
        self.next = (self.next + 1) % WRENCH_WINDOW;
        self.len = (self.len + 1).min(WRENCH_WINDOW);
    }

    /// Readings held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Oldest first.
    pub fn ordered(&self) -> impl Iterator<Item = &[f64; 6]> {
        let start = (self.next + WRENCH_WINDOW - self.len) % WRENCH_WINDOW;
        (0..self.len).map(move |i| &self.buf[(start + i) % WRENCH_WINDOW])
    }

    /// The full window, oldest first: exactly [`WRENCH_WINDOW`] readings, a
    /// shorter history repeating its oldest in front (zeros when empty), as
    /// the dataset's first samples of an episode do. What the encoder and
    /// the raw-input observer read.
    pub fn padded(&self) -> impl Iterator<Item = &[f64; 6]> {
        const ZERO: [f64; 6] = [0.0; 6];
        let first = self.ordered().next().unwrap_or(&ZERO);
        std::iter::repeat_n(first, WRENCH_WINDOW - self.len).chain(self.ordered())
    }

    /// Mean force over the newest `n` readings, N.
    pub fn mean_force(&self, n: usize) -> Vector3<f64> {
        let n = n.min(self.len).max(1);
        let skip = self.len.saturating_sub(n);
        let mut f = Vector3::zeros();
        for w in self.ordered().skip(skip) {
            f += Vector3::new(w[0], w[1], w[2]);
        }
        f / n as f64
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        self.len = 0;
        self.next = 0;
    }
}

/// What the policy sees at one 20 Hz step.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Hardware time, ns.
    pub t_hw_ns: u64,
    /// Hardware step of the frame.
    pub step: u64,
    /// Episode.
    pub episode: u64,
    /// End-effector (peg tip) position in the base frame, m.
    pub ee_pos: Vector3<f64>,
    /// End-effector orientation in the base frame.
    pub ee_rot: UnitQuaternion<f64>,
    /// End-effector twist (linear, angular), base frame.
    pub ee_twist: [f64; 6],
    /// The paper's proprioception (the representation's input), roll taken
    /// from the episode's start.
    pub proprio: Proprio,
}

impl Observation {
    /// From a controller sensor frame and the episode's roll reference
    /// ([`crate::proprio::roll_reference`] of its first frame).
    pub fn from_frame(f: &SensorFrame, roll_ref_rad: f64) -> Self {
        let [x, y, z, w] = f.ee_quat_xyzw;
        Self {
            t_hw_ns: f.header.t_hw_ns,
            step: f.step,
            episode: f.header.episode,
            ee_pos: Vector3::from(f.ee_pos_m),
            ee_rot: unit_quaternion([x, y, z, w]),
            ee_twist: f.ee_twist,
            proprio: Proprio::from_frame(f, roll_ref_rad),
        }
    }
}

/// Where the task is (calibration; the simulator reports it).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskGeometry {
    /// Hole frame (centre of the opening, z up) in the base frame.
    pub hole_pose: Isometry3<f64>,
    /// Rotational symmetry order of the peg (4 square, 3 triangle, 1
    /// semicircle, 6 hexagon).
    pub symmetry: u32,
    /// Hole depth, m.
    pub depth_m: f64,
}

/// A policy action: (Δx, Δy, Δz) in the base frame, m, and Δroll, rad.
pub type Action4 = [f64; 4];

/// Tuning of the heuristic.
#[derive(Debug, Clone, PartialEq)]
pub struct HeuristicConfig {
    /// Approach height of the tip above the hole's opening, m.
    pub above_m: f64,
    /// Largest position step per action while approaching, m.
    pub approach_step_m: f64,
    /// Position tolerance to start descending, m.
    pub align_tol_m: f64,
    /// Roll tolerance to start descending, rad.
    pub roll_tol_rad: f64,
    /// Largest roll step per action, rad.
    pub roll_step_rad: f64,
    /// Downward step per action while descending and inserting, m.
    pub descend_step_m: f64,
    /// Downward step per action just above a surface (the box's top face,
    /// the hole's bottom), m: the speed at which the tip may meet it. A
    /// rigid contact stops the arm within one 1 ms physics step, so the
    /// wrist reads an impact force of about the arm's effective mass times
    /// this speed per millisecond (121 N at 3.5 cm/s measured; 0.5 mm per
    /// 50 ms is 1 cm/s).
    pub contact_step_m: f64,
    /// Force change (against the free-space reading) that means contact, N.
    pub contact_force_n: f64,
    /// Pressing harder than this backs off instead of pushing on (the
    /// controller faults at its `safety.max_force_n`), N.
    pub max_press_force_n: f64,
    /// Within this of the hole's bottom the insertion is done and the
    /// policy rests there, m.
    pub bottom_tol_m: f64,
    /// Resting on the bottom, it presses down until the wrist reads this
    /// much (above `contact_force_n`, well below the fault), N.
    pub rest_press_force_n: f64,
    /// Spiral search: growth of the radius per action, m.
    pub search_growth_m: f64,
    /// Spiral search: largest radius, m.
    pub search_max_m: f64,
}

impl Default for HeuristicConfig {
    fn default() -> Self {
        Self {
            above_m: 0.015,
            approach_step_m: 0.008,
            align_tol_m: 0.0015,
            roll_tol_rad: 0.03,
            roll_step_rad: 0.05,
            descend_step_m: 0.004,
            contact_step_m: 0.0005,
            contact_force_n: 4.0,
            max_press_force_n: 15.0,
            bottom_tol_m: 0.002,
            rest_press_force_n: 8.0,
            search_growth_m: 0.0002,
            search_max_m: 0.004,
        }
    }
}

/// Phase of the heuristic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// Moving above the hole and aligning the roll.
    Approach,
    /// Going down onto the hole.
    Descend,
    /// Landed on the surface: spiralling around the hole centre.
    Search {
        /// Actions spent searching.
        k: u32,
    },
    /// The tip is in the hole: pushing to the bottom.
    Insert,
}

/// The scripted insertion policy.
#[derive(Debug, Clone)]
pub struct HeuristicPolicy {
    /// Tuning.
    pub cfg: HeuristicConfig,
    phase: Phase,
    free_force: Option<Vector3<f64>>,
    stuck: u32,
}

/// The tip relative to the hole: position in the hole frame and roll
/// wrapped by the peg's symmetry (as the simulator's s and s_ψ).
pub fn relative_to_hole(
    ee_pos: &Vector3<f64>,
    ee_rot: &UnitQuaternion<f64>,
    task: &TaskGeometry,
) -> (Vector3<f64>, f64) {
    let rel = task.hole_pose.inverse() * Isometry3::from_parts((*ee_pos).into(), *ee_rot);
    let x = rel.rotation * Vector3::x();
    let period = std::f64::consts::TAU / task.symmetry.max(1) as f64;
    let mut psi = x.y.atan2(x.x).rem_euclid(period);
    if psi > 0.5 * period {
        psi -= period;
    }
    (rel.translation.vector, psi)
}

fn clamp_norm(v: Vector3<f64>, max: f64) -> Vector3<f64> {
    let n = v.norm();
    if n > max { v * (max / n) } else { v }
}

impl HeuristicPolicy {
    /// A policy at the start of an episode.
    pub fn new(cfg: HeuristicConfig) -> Self {
        Self {
            cfg,
            phase: Phase::Approach,
            free_force: None,
            stuck: 0,
        }
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Starts over (new episode).
    pub fn reset(&mut self) {
        *self = Self::new(self.cfg.clone());
    }

    /// The next action.
    pub fn act(
        &mut self,
        obs: &Observation,
        wrench: &WrenchHistory,
        task: &TaskGeometry,
    ) -> Action4 {
        let c = self.cfg.clone();
        let (s, psi) = relative_to_hole(&obs.ee_pos, &obs.ee_rot, task);
        let force = wrench.mean_force(8);
        let free = *self.free_force.get_or_insert(force);
        let pressing = (force - free).norm();
        let contact = pressing > c.contact_force_n;
        let roll = (-psi).clamp(-c.roll_step_rad, c.roll_step_rad);
        let to_base = |d: Vector3<f64>| task.hole_pose.rotation * d;
        let inserted = s.z < -0.003;
        let at_bottom = self.phase == Phase::Insert && task.depth_m + s.z < c.bottom_tol_m;
        let step_hole = match self.phase {
            Phase::Approach => {
                let goal = Vector3::new(0.0, 0.0, c.above_m);
                let d = goal - s;
                if d.norm() < c.align_tol_m && psi.abs() < c.roll_tol_rad {
                    self.phase = Phase::Descend;
                }
                clamp_norm(d, c.approach_step_m)
            }
            Phase::Descend | Phase::Insert => {
                if inserted {
                    self.phase = Phase::Insert;
                }
                let on_surface = contact && !inserted && s.z > -0.001;
                self.stuck = if on_surface { self.stuck + 1 } else { 0 };
                if self.stuck >= 3 && self.phase == Phase::Descend {
                    self.phase = Phase::Search { k: 0 };
                }
                let gain = if self.phase == Phase::Insert {
                    0.5
                } else {
                    1.0
                };
                let to_bottom = task.depth_m + s.z;
                if at_bottom {
                    // At the bottom: the task is done. Pushing on (down, or
                    // sideways against the walls) only winds the contact
                    // force up until the controller faults; rest on the
                    // bottom with a light press instead.
                    let dz = if pressing < c.rest_press_force_n {
                        0.0005
                    } else {
                        0.0
                    };
                    Vector3::new(0.0, 0.0, -dz)
                } else {
                    let xy = clamp_norm(Vector3::new(-s.x, -s.y, 0.0) * gain, 0.002);
                    // Slow down towards the box's top and towards the
                    // bottom: a rigid surface met at full speed is an
                    // impact spike on the wrist sensor that the controller
                    // faults on (266 N at 8 cm/s measured). Aligned over
                    // the opening too: the tip is within the clearance of
                    // the rim, and a little noise puts it on it.
                    let to_surface = if s.z > 0.0 { s.z } else { to_bottom };
                    let dz = (0.25 * to_surface).clamp(c.contact_step_m, c.descend_step_m);
                    xy + Vector3::new(0.0, 0.0, -dz)
                }
            }
            Phase::Search { k } => {
                if inserted {
                    self.phase = Phase::Insert;
                    Vector3::new(0.0, 0.0, -c.descend_step_m)
                } else {
                    self.phase = Phase::Search { k: k + 1 };
                    let r = (c.search_growth_m * k as f64).min(c.search_max_m);
                    let a = 2.4 * k as f64;
                    let goal = Vector3::new(r * a.cos(), r * a.sin(), -0.002);
                    let mut d = goal - s;
                    // Keep pressing lightly: never lift more than 1 mm.
                    d.z = d.z.min(0.001);
                    clamp_norm(d, 0.003)
                }
            }
        };
        let mut step_hole = step_hole;
        if pressing > c.max_press_force_n {
            // Too hard: ease off upward, whatever the phase.
            step_hole.z = step_hole.z.max(0.001);
        }
        let d = to_base(step_hole);
        [d.x, d.y, d.z, if at_bottom { 0.0 } else { roll }]
    }
}

/// Tuning of the random exploration policy.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomConfig {
    /// Largest position step per axis per action, m.
    pub max_step_m: f64,
    /// Largest roll step per action, rad.
    pub max_roll_rad: f64,
    /// Half extent (x, y) of the region around the hole it wanders in, m.
    pub region_half_m: f64,
    /// Height range of the tip above the hole's opening (min, max), m;
    /// the minimum is below the opening so that it touches the box.
    pub region_z_m: (f64, f64),
}

impl Default for RandomConfig {
    fn default() -> Self {
        Self {
            max_step_m: 0.006,
            max_roll_rad: 0.05,
            region_half_m: 0.04,
            region_z_m: (-0.01, 0.06),
        }
    }
}

/// The random half of the paper's data-collection mix: uniform random
/// steps, turned inwards when the tip is outside a region around the box,
/// so that the walk keeps coming back to (and touching) the box.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    /// Tuning.
    pub cfg: RandomConfig,
    rng: rng::SimRng,
}

impl RandomPolicy {
    /// A policy drawing from `seed`.
    pub fn new(cfg: RandomConfig, seed: u64) -> Self {
        Self {
            cfg,
            rng: rng::seeded(seed, 17),
        }
    }

    /// The next action.
    pub fn act(&mut self, obs: &Observation, task: &TaskGeometry) -> Action4 {
        let c = &self.cfg;
        let (s, _) = relative_to_hole(&obs.ee_pos, &obs.ee_rot, task);
        let lo = [-c.region_half_m, -c.region_half_m, c.region_z_m.0];
        let hi = [c.region_half_m, c.region_half_m, c.region_z_m.1];
        let mut d = Vector3::zeros();
        for k in 0..3 {
            let x = rng::uniform(&mut self.rng, -c.max_step_m, c.max_step_m);
            d[k] = if s[k] < lo[k] {
                x.abs()
            } else if s[k] > hi[k] {
                -x.abs()
            } else {
                x
            };
        }
        let d = task.hole_pose.rotation * d;
        let roll = rng::uniform(&mut self.rng, -c.max_roll_rad, c.max_roll_rad);
        [d.x, d.y, d.z, roll]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_keeps_the_newest_in_order() {
        let mut h = WrenchHistory::default();
        for i in 0..40 {
            h.push([i as f64, 0.0, 0.0, 0.0, 0.0, 0.0]);
        }
        assert_eq!(h.len(), 32);
        let xs: Vec<f64> = h.ordered().map(|w| w[0]).collect();
        assert_eq!(xs.first(), Some(&8.0));
        assert_eq!(xs.last(), Some(&39.0));
        assert_eq!(h.mean_force(2).x, 38.5);
    }

    #[test]
    fn random_walk_turns_back_into_its_region() {
        let task = TaskGeometry {
            hole_pose: Isometry3::translation(0.5, 0.0, 0.1),
            symmetry: 4,
            depth_m: 0.04,
        };
        let mut p = RandomPolicy::new(RandomConfig::default(), 3);
        let mut obs = Observation {
            t_hw_ns: 0,
            step: 0,
            episode: 0,
            ee_pos: Vector3::new(0.7, -0.2, 0.4),
            ee_rot: UnitQuaternion::identity(),
            ee_twist: [0.0; 6],
            proprio: Proprio::new(
                &Vector3::zeros(),
                &UnitQuaternion::identity(),
                &[0.0; 6],
                0.0,
            ),
        };
        // Far outside on every axis: every step points back.
        for _ in 0..50 {
            let a = p.act(&obs, &task);
            assert!(a[0] <= 0.0 && a[1] >= 0.0 && a[2] <= 0.0, "{a:?}");
            assert!(a[3].abs() <= 0.05);
        }
        // Inside: both signs occur.
        obs.ee_pos = Vector3::new(0.5, 0.0, 0.12);
        let xs: Vec<f64> = (0..50).map(|_| p.act(&obs, &task)[0]).collect();
        assert!(xs.iter().any(|&x| x > 0.0) && xs.iter().any(|&x| x < 0.0));
    }

    #[test]
    fn roll_is_wrapped_by_symmetry() {
        let task = TaskGeometry {
            hole_pose: Isometry3::identity(),
            symmetry: 4,
            depth_m: 0.04,
        };
        let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.5);
        let (_, psi) = relative_to_hole(&Vector3::zeros(), &rot, &task);
        assert!((psi - (1.5 - std::f64::consts::FRAC_PI_2)).abs() < 1e-12);
    }
}
