//! Configuration of the simulated world and of an episode, TOML-ready:
//! every field has a default; `validate` names the field at fault.

use crate::shapes::{PegShape, hole_outline, inset};
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::{
    ConfigFileError, FieldError, all_finite, at_least, check, ensure, joint_count, non_negative,
    ordered_pair, parse_toml, per_joint, positive, read_toml, within,
};
use std::path::Path;

/// Everything a [`crate::World`] is built from. The same configuration and
/// seed give bit-identical runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldConfig {
    /// A built-in robot (`"iiwa14"`, the paper's simulated robot, or
    /// `"panda"`) or the path of a URDF file.
    pub robot: String,
    /// Physics step, s (1 kHz by default, the controller's rate).
    pub dt_s: f64,
    /// Initial joint positions, rad, one per joint; absent: the robot's
    /// default pose, which holds the peg pointing down above the box.
    pub initial_q: Option<Vec<f64>>,
    /// Viscous joint damping, N·m·s/rad: empty = the URDF's `<dynamics
    /// damping>`, one value = every joint, or one per joint.
    pub joint_damping: Vec<f64>,
    /// Dry joint friction, N·m: same conventions as `joint_damping`.
    pub joint_friction: Vec<f64>,
    /// Saturate commanded torques at the URDF effort limits, as drives do.
    pub clamp_torques: bool,
    /// Solver iterations per step (rapier's substeps). One at 1 kHz passes
    /// every fidelity test (dynamics, F/T, insertion, no pass-through) at
    /// 2.3× the speed of four; see docs/hw-sim.md.
    pub solver_iterations: usize,
    /// rapier's length unit, m: scales its tolerances (contact slop
    /// 0.005 × unit, prediction distance 0.02 × unit, maximum corrective
    /// velocity 3 × unit per s). 1 cm keeps the slop at 0.05 mm, well under
    /// the millimetre clearances of the pegs.
    pub length_unit_m: f64,
    /// Contact recycling, m: a collider pair whose relative pose drifted
    /// less than this since its last full contact update keeps its contact
    /// points instead of recomputing them (rapier's `contact_recycling`).
    /// 10 µm, a fifth of the contact slop, leaves every fidelity test as it
    /// was and makes a jammed peg 20% cheaper (docs/hw-sim.md). 0 turns it
    /// off; rapier's own default (0.05 length units, 0.5 mm here) would
    /// keep contact points across half the pegs' clearance.
    pub contact_recycle_distance_m: f64,
    /// The peg-in-hole task.
    pub task: TaskConfig,
    /// The RGB-D camera.
    pub camera: CameraConfig,
    /// Sensor noise.
    pub noise: NoiseConfig,
    /// Pushes and occlusions.
    pub perturbations: PerturbationConfig,
    /// Episode seed: box placement, noise and random perturbations.
    pub seed: u64,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            robot: "iiwa14".into(),
            dt_s: shared_mem_schema::rates::CONTROL_PERIOD_S,
            initial_q: None,
            joint_damping: Vec::new(),
            joint_friction: Vec::new(),
            clamp_torques: true,
            solver_iterations: 1,
            length_unit_m: 0.01,
            contact_recycle_distance_m: 1.0e-5,
            task: TaskConfig::default(),
            camera: CameraConfig::default(),
            noise: NoiseConfig::default(),
            perturbations: PerturbationConfig::default(),
            seed: 0,
        }
    }
}

/// The peg, its box and where the box goes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TaskConfig {
    /// Build the peg and the box at all (off: the bare arm, for dynamics
    /// checks).
    pub enabled: bool,
    /// Peg cross-section.
    pub peg: PegShape,
    /// Peg width, m (side, diameter or across flats; see [`PegShape`]).
    pub peg_width_m: f64,
    /// Peg length from the sensor face, m; 0: up to the URDF's `peg_tip`
    /// frame.
    pub peg_length_m: f64,
    /// Peg density, kg/m³ (3D-printed PLA at partial infill ≈ 1000).
    pub peg_density_kg_m3: f64,
    /// Clearance on the diameter, m: the hole is the peg's outline offset
    /// by half of it (2 mm, the paper's real pegs).
    pub clearance_m: f64,
    /// Hole depth, m.
    pub hole_depth_m: f64,
    /// Box side, m.
    pub box_side_m: f64,
    /// Box height, m (it stands on the floor).
    pub box_height_m: f64,
    /// Coulomb friction between the peg and the box.
    pub friction: f64,
    /// Centre of the box placement region in the base x-y plane, m; absent:
    /// under the peg tip at the initial pose.
    pub box_center_xy_m: Option<[f64; 2]>,
    /// Half-widths of the placement region around the centre, m.
    pub box_xy_range_m: [f64; 2],
    /// Half-range of the box yaw, rad, about the yaw at which the hole fits
    /// the peg at the initial pose (so the peg starts within this roll of
    /// alignment).
    pub box_yaw_range_rad: f64,
    /// How far the tip must be below the top face to count as inserted, m.
    pub inserted_depth_m: f64,
    /// How close to the hole's bottom the tip must come to count as a
    /// completed insertion, m.
    pub completed_tolerance_m: f64,
    /// How far inside the hole's outline (in the hole frame's x-y plane) the
    /// tip must be for inserted and completed, m. The tip is on the peg's
    /// axis, so a peg in the hole has it far inside (6.3 mm for the 30 mm
    /// semicircle, the least of the four pegs); the margin keeps a tip
    /// grazing the outline from counting. Must be less than the distance
    /// from the hole's centre to its nearest edge.
    pub in_hole_margin_m: f64,
}

impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            peg: PegShape::Square,
            peg_width_m: 0.03,
            peg_length_m: 0.0,
            peg_density_kg_m3: 1000.0,
            clearance_m: 0.002,
            hole_depth_m: 0.04,
            box_side_m: 0.16,
            box_height_m: 0.10,
            friction: 0.3,
            box_center_xy_m: None,
            box_xy_range_m: [0.04, 0.04],
            box_yaw_range_rad: 0.26,
            inserted_depth_m: 0.003,
            completed_tolerance_m: 0.003,
            in_hole_margin_m: 0.001,
        }
    }
}

/// A fixed pinhole camera (OpenCV convention: x right, y down, z forward).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Vertical field of view, degrees (square pixels, centred principal
    /// point).
    pub vertical_fov_deg: f64,
    /// Camera position in the base frame, m.
    pub eye_m: [f64; 3],
    /// The point it looks at, m.
    pub target_m: [f64; 3],
    /// Physics steps between frames (50 at 1 kHz: 20 Hz, the policy rate).
    pub period_steps: u32,
    /// Depth beyond which a pixel reads 0 (no return), m.
    pub max_depth_m: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width: 128,
            height: 128,
            vertical_fov_deg: 45.0,
            eye_m: [1.45, -0.75, 0.85],
            target_m: [0.45, 0.0, 0.2],
            period_steps: shared_mem_schema::rates::ACTION_PERIOD_STEPS as u32,
            max_depth_m: 4.0,
        }
    }
}

/// Gaussian noise per channel (standard deviations) and a constant F/T bias.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseConfig {
    /// Joint position, rad.
    pub q_std_rad: f64,
    /// Joint velocity, rad/s.
    pub v_std_rad_s: f64,
    /// F/T force, N.
    pub force_std_n: f64,
    /// F/T moment, N·m.
    pub torque_std_nm: f64,
    /// F/T bias added to every reading (fx, fy, fz, mx, my, mz).
    pub ft_bias: [f64; 6],
    /// Cut-off of the F/T sensor's first-order low-pass filter, Hz; 0: no
    /// filter. Rigid contact delivers an impact's impulse within one step,
    /// which reads as a one-sample spike of hundreds of newtons; a real
    /// sensor's compliance and filter spread it (the paper's OptoForce
    /// sensor offers 15–500 Hz filters; 150 Hz here).
    pub ft_filter_hz: f64,
    /// Depth, m.
    pub depth_std_m: f64,
    /// RGB, in 8-bit levels.
    pub rgb_std: f64,
    /// Per-episode range `[lo, hi]` of a factor on every standard deviation
    /// above (not the bias or the filter): each reset draws it uniformly
    /// (stream 8), so that one run sees sensors from `lo` to `hi` times as
    /// noisy, for a policy that must hold across noise levels. `[1, 1]`:
    /// the deviations as given, and no draw.
    pub episode_scale: [f64; 2],
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            q_std_rad: 0.0,
            v_std_rad_s: 0.0,
            force_std_n: 0.0,
            torque_std_nm: 0.0,
            ft_bias: [0.0; 6],
            ft_filter_hz: 150.0,
            depth_std_m: 0.0,
            rgb_std: 0.0,
            episode_scale: [1.0, 1.0],
        }
    }
}

/// One push on the arm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Push {
    /// Start, s of simulated time.
    pub start_s: f64,
    /// Duration, s; 0: an impulse (then `force_n` is in N·s).
    pub duration_s: f64,
    /// Joint index (1-based, as robot-model numbers them) of the link pushed.
    pub link: usize,
    /// Force (or impulse) in the base frame, applied at the link's origin.
    pub force_n: [f64; 3],
}

impl Default for Push {
    fn default() -> Self {
        Self {
            start_s: 0.0,
            duration_s: 0.1,
            link: 7,
            force_n: [0.0; 3],
        }
    }
}

/// A camera occlusion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Occlusion {
    /// Start, s of simulated time.
    pub start_s: f64,
    /// End, s.
    pub end_s: f64,
    /// Patch `[x, y, width, height]` in pixels; absent: the whole image.
    pub rect: Option<[u32; 4]>,
}

impl Default for Occlusion {
    fn default() -> Self {
        Self {
            start_s: 0.0,
            end_s: f64::INFINITY,
            rect: None,
        }
    }
}

/// Perturbations of an episode: explicit ones, plus random ones drawn from
/// the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerturbationConfig {
    /// Explicit pushes.
    pub pushes: Vec<Push>,
    /// Explicit occlusions.
    pub occlusions: Vec<Occlusion>,
    /// Number of random pushes on the last link.
    pub random_pushes: u32,
    /// Their force magnitude range, N (horizontal direction uniform).
    pub random_push_force_n: [f64; 2],
    /// Their duration, s.
    pub random_push_duration_s: f64,
    /// Number of random square occlusion patches.
    pub random_occlusions: u32,
    /// Their side, px.
    pub random_occlusion_side_px: u32,
    /// Their duration, s.
    pub random_occlusion_duration_s: f64,
    /// Random perturbations start within this window, s.
    pub random_window_s: [f64; 2],
}

impl Default for PerturbationConfig {
    fn default() -> Self {
        Self {
            pushes: Vec::new(),
            occlusions: Vec::new(),
            random_pushes: 0,
            random_push_force_n: [5.0, 20.0],
            random_push_duration_s: 0.2,
            random_occlusions: 0,
            random_occlusion_side_px: 32,
            random_occlusion_duration_s: 1.0,
            random_window_s: [1.0, 20.0],
        }
    }
}

impl WorldConfig {
    /// Checks every value that does not need the robot; `nv` is the robot's
    /// number of joints. Steps in field order, so the first bad field of the
    /// document is the one reported.
    pub fn validate(&self, nv: usize) -> Result<(), FieldError> {
        self.validate_arm(nv)?;
        self.task.validate()?;
        self.camera.validate()?;
        self.noise.validate()?;
        self.perturbations.validate(nv)
    }

    /// The arm and the physics: step, initial pose, joint dynamics, solver.
    fn validate_arm(&self, nv: usize) -> Result<(), FieldError> {
        positive("dt_s", self.dt_s)?;
        if let Some(q) = &self.initial_q {
            joint_count("initial_q", q.len(), nv)?;
            all_finite("initial_q", q)?;
        }
        per_joint("joint_damping", &self.joint_damping, nv)?;
        per_joint("joint_friction", &self.joint_friction, nv)?;
        // Bounded: a reset command must not be able to stall the simulator.
        within("solver_iterations", self.solver_iterations, 1..=100)?;
        positive("length_unit_m", self.length_unit_m)?;
        non_negative(
            "contact_recycle_distance_m",
            self.contact_recycle_distance_m,
        )
    }

    /// Parses a TOML document (unknown fields are errors, so a typo is not
    /// silently ignored).
    pub fn from_toml(text: &str) -> Result<Self, ConfigFileError> {
        parse_toml(text, Path::new("(text)"))
    }

    /// Reads and parses a configuration file (validated against the robot
    /// when a world is built from it).
    pub fn from_file(path: &Path) -> Result<Self, ConfigFileError> {
        read_toml(path)
    }
}

impl TaskConfig {
    /// The peg and box dimensions, their consistency and the placement.
    fn validate(&self) -> Result<(), FieldError> {
        positive("task.peg_width_m", self.peg_width_m)?;
        non_negative("task.peg_length_m", self.peg_length_m)?;
        positive("task.peg_density_kg_m3", self.peg_density_kg_m3)?;
        non_negative("task.clearance_m", self.clearance_m)?;
        positive("task.hole_depth_m", self.hole_depth_m)?;
        positive("task.box_side_m", self.box_side_m)?;
        positive("task.box_height_m", self.box_height_m)?;
        non_negative("task.friction", self.friction)?;
        check(
            "task.hole_depth_m",
            self.hole_depth_m,
            self.hole_depth_m < self.box_height_m,
            "must be less than task.box_height_m",
        )?;
        check(
            "task.box_side_m",
            self.box_side_m,
            self.box_side_m >= 2.0 * self.peg_width_m + self.clearance_m,
            "must be at least twice task.peg_width_m plus task.clearance_m",
        )?;
        all_finite("task.box_xy_range_m", &self.box_xy_range_m)?;
        if let Some(c) = &self.box_center_xy_m {
            all_finite("task.box_center_xy_m", c)?;
        }
        non_negative("task.box_yaw_range_rad", self.box_yaw_range_rad)?;
        non_negative("task.inserted_depth_m", self.inserted_depth_m)?;
        non_negative("task.completed_tolerance_m", self.completed_tolerance_m)?;
        non_negative("task.in_hole_margin_m", self.in_hole_margin_m)?;
        // The hole's outline as the box builds it (mirroring, which the
        // box applies, does not change distances from the centre).
        let hole = hole_outline(&self.peg.outline(self.peg_width_m), self.clearance_m);
        let reach = inset(&hole, [0.0, 0.0]);
        check(
            "task.in_hole_margin_m",
            self.in_hole_margin_m,
            self.in_hole_margin_m < reach,
            &format!(
                "must be less than {:.2} mm, the distance from the hole's centre to its \
                 nearest edge (no tip would count as in the hole)",
                1e3 * reach
            ),
        )
    }
}

impl CameraConfig {
    /// Image size, field of view, a usable view direction, rate and range.
    pub fn validate(&self) -> Result<(), FieldError> {
        within("camera.width", self.width, 1..=4096)?;
        within("camera.height", self.height, 1..=4096)?;
        let fov = self.vertical_fov_deg;
        check(
            "camera.vertical_fov_deg",
            fov,
            fov > 1.0 && fov < 170.0,
            "must be in (1, 170) degrees",
        )?;
        let dir: Vec<f64> = (0..3).map(|i| self.target_m[i] - self.eye_m[i]).collect();
        let target = format!("{:?}", self.target_m);
        ensure(
            dir.iter().all(|d| d.is_finite()) && dir.iter().any(|d| d.abs() >= 1e-9),
            "camera.target_m",
            &target,
            "must be finite and differ from camera.eye_m",
        )?;
        // The look-at frame takes +z as up, undefined along a vertical view.
        ensure(
            dir[0].abs() >= 1e-9 || dir[1].abs() >= 1e-9,
            "camera.target_m",
            &target,
            "the view must not be vertical (up is +z)",
        )?;
        at_least("camera.period_steps", self.period_steps, 1)?;
        positive("camera.max_depth_m", self.max_depth_m)
    }
}

impl NoiseConfig {
    /// Standard deviations and the filter cut-off are >= 0; the bias finite.
    fn validate(&self) -> Result<(), FieldError> {
        for (f, v) in [
            ("noise.q_std_rad", self.q_std_rad),
            ("noise.v_std_rad_s", self.v_std_rad_s),
            ("noise.force_std_n", self.force_std_n),
            ("noise.torque_std_nm", self.torque_std_nm),
            ("noise.depth_std_m", self.depth_std_m),
            ("noise.rgb_std", self.rgb_std),
            ("noise.ft_filter_hz", self.ft_filter_hz),
        ] {
            non_negative(f, v)?;
        }
        ordered_pair("noise.episode_scale", self.episode_scale)?;
        all_finite("noise.ft_bias", &self.ft_bias)
    }
}

impl PerturbationConfig {
    /// Explicit pushes (on one of the `nv` links) and occlusions, then the
    /// ranges random ones are drawn from.
    fn validate(&self, nv: usize) -> Result<(), FieldError> {
        for (i, push) in self.pushes.iter().enumerate() {
            let f = format!("perturbations.pushes[{i}]");
            non_negative(&format!("{f}.start_s"), push.start_s)?;
            non_negative(&format!("{f}.duration_s"), push.duration_s)?;
            within(&format!("{f}.link"), push.link, 1..=nv)?;
            all_finite(&format!("{f}.force_n"), &push.force_n)?;
        }
        for (i, o) in self.occlusions.iter().enumerate() {
            // An infinite end (the default) is allowed: occluded to the end.
            ensure(
                !o.start_s.is_nan() && o.end_s >= o.start_s,
                &format!("perturbations.occlusions[{i}].end_s"),
                o.end_s,
                format!("must not be before start_s ({})", o.start_s),
            )?;
        }
        // Bounded: each is drawn and kept for the episode.
        within("perturbations.random_pushes", self.random_pushes, 0..=1000)?;
        within(
            "perturbations.random_occlusions",
            self.random_occlusions,
            0..=1000,
        )?;
        ordered_pair(
            "perturbations.random_push_force_n",
            self.random_push_force_n,
        )?;
        non_negative(
            "perturbations.random_push_duration_s",
            self.random_push_duration_s,
        )?;
        non_negative(
            "perturbations.random_occlusion_duration_s",
            self.random_occlusion_duration_s,
        )?;
        ordered_pair("perturbations.random_window_s", self.random_window_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_field_at_fault() {
        let c = WorldConfig::default();
        c.validate(7).unwrap();
        let mut bad = c.clone();
        bad.initial_q = Some(vec![0.0; 6]);
        assert_eq!(bad.validate(7).unwrap_err().field, "initial_q");
        let mut bad = c.clone();
        bad.camera.height = 0;
        assert_eq!(bad.validate(7).unwrap_err().field, "camera.height");
        let mut bad = c.clone();
        bad.perturbations.random_window_s = [2.0, 1.0];
        let e = bad.validate(7).unwrap_err();
        assert_eq!(e.field, "perturbations.random_window_s", "{e}");
        let mut bad = c;
        bad.joint_damping = vec![1.0; 3];
        assert_eq!(bad.validate(7).unwrap_err().field, "joint_damping");
    }

    #[test]
    fn the_in_hole_margin_must_leave_room_in_the_hole() {
        let mut c = WorldConfig::default();
        c.task.peg = PegShape::Semicircle;
        // The hole's centre is 6.3 + 1 mm from its flat side.
        c.task.in_hole_margin_m = 0.007;
        c.validate(7).unwrap();
        c.task.in_hole_margin_m = 0.008;
        let e = c.validate(7).unwrap_err();
        assert_eq!(e.field, "task.in_hole_margin_m", "{e}");
        assert!(e.to_string().contains("7.33 mm"), "{e}");
        c.task.in_hole_margin_m = -0.001;
        assert_eq!(c.validate(7).unwrap_err().field, "task.in_hole_margin_m");
    }

    #[test]
    fn initial_q_is_absent_by_default_and_round_trips() {
        let c = WorldConfig::from_toml("initial_q = [0.0, 0.5]\n").unwrap();
        assert_eq!(c.initial_q, Some(vec![0.0, 0.5]));
        let d = WorldConfig::default();
        assert_eq!(d.initial_q, None);
        let back = WorldConfig::from_toml(&toml::to_string(&d).unwrap()).unwrap();
        assert_eq!(back, d);
    }
}
