//! A scripted policy that finds the opening by touch: told roughly where
//! the hole is, it comes down there and, while the box carries the peg,
//! slides along an Archimedean spiral about that point until the peg drops
//! in, pressing lightly. It is memoryless (each action is a function of
//! the current observation only, [`SearchView`]), so a student MLP can
//! imitate it exactly (DAgger, `learner policy distill`'s
//! `[search_teacher]`).
//!
//! Why a spiral and not the wrench's centre of pressure: pressed over the
//! rim, the peg rests on its lowest edge or corner that the box carries
//! (it is not exactly square to the face), so the centre of pressure sits
//! there rather than on the side away from the opening (`touch_probe
//! press`), and a policy stepping against it saw it flip between the ends
//! of the carrying strip with every lateral step (docs/experiments.md "A
//! policy that searches by touch").
//!
//! Why the lead term: the trajectory target accumulates the steps while
//! friction holds the tip back, so the target leads the tip along the
//! spiral's tangent by about the friction over the stiffness; a target
//! leading a tip on a circle of radius r drifts outward by lead/r per unit
//! of step, and the spiral ran away to 5 cm without it. The lateral force
//! measures that lag, and the radial part of the step takes it out.

use super::env::ActionScale;
use super::observe::{ObsView, Observer};
use super::probe::LinearProbe;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;

/// The search's settings (`[search_teacher]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TouchSearchConfig {
    /// Standard deviation of the error of where the hole is believed to
    /// be, per horizontal axis of the hole frame, m (the same per-episode
    /// draw as `observation = { ground_truth_hole_error = … }`: a student
    /// observing that sees the error the teacher acts on).
    pub hole_error_m: f64,
    /// Distance between the spiral's turns, m: below the 2 mm diametral
    /// clearance, so that the opening is not stepped over.
    pub pitch_m: f64,
    /// Lateral step while sliding, m.
    pub slide_m: f64,
    /// Step of the approach and descent, m.
    pub step_m: f64,
    /// The force to press on the top face with, N: low, since friction
    /// (0.3 of it) holds the sliding tip back.
    pub press_n: f64,
    /// The trajectory target's lead over the tip per newton of lateral
    /// force, m/N (the friction's lag; see the module's doc). Tuned, with
    /// `touch_probe search`, for the lateral stiffness of 300 N/m the
    /// controller has by default and with the stiff wrist; another
    /// stiffness needs it tuned again.
    pub lead_m_per_n: f64,
    /// Share of the believed roll error turned each step (0 < g ≤ 1). 1
    /// turns the whole of it, so the roll follows every reading; below 1 a
    /// reading that errs moves the roll by only that share of its error.
    /// Told the roll by a probe of z, 0.1 kept it closer to the hole's than
    /// 1 (docs/experiments.md, "A policy that searches by touch").
    pub roll_gain: f64,
    /// Above the box the search steps towards the believed opening by the
    /// believed offset times `step_m / approach_radius_m` within this
    /// radius of it, and by `step_m` towards it farther out, m. None (the
    /// default): `step_m`, a full step whenever the offset is larger than
    /// one. Why a wider one: a belief read from z jitters by about 3 mm from
    /// frame to frame near the opening, and a step of full length along
    /// that jitter's direction is a label no student on z fits; a
    /// proportional one is a linear function of the belief
    /// (docs/experiments.md, "Where the z student misses").
    pub approach_radius_m: Option<f64>,
    /// Step down above the box while the tip is more than
    /// `descent_until_m` above it, m; `step_m` below that height, so the
    /// box is met at `step_m` (a last fast step may pass the height by up
    /// to `descent_m`). None (the default): `step_m` all the way. Why: from
    /// the start pose the descent takes about 250 of the episode's 500
    /// steps, and the search on the box needs the time; at 1.5 mm per step
    /// all the way the peg met the box hard enough to end most episodes
    /// early with a controller fault (docs/experiments.md, "Where the
    /// student on z lands"). Told by z, the faster descent completed fewer.
    pub descent_m: Option<f64>,
    /// Height above the box below which the descent slows to `step_m`, m.
    pub descent_until_m: f64,
    /// On the box, the radius about the believed opening beyond which the
    /// search turns back towards it, m: from `bound_m` to `bound_m` +
    /// [`BOUND_RAMP_M`] the spiral's step blends into a slide of `slide_m`
    /// straight in, proportionally to the overshoot, so the search orbits
    /// at about that radius. None (the
    /// default): unbounded. Why: a tip that drifted out (a student whose
    /// step is a few tens of degrees off its teacher's, or the friction's
    /// lead) kept spiralling outward, and a teacher's labels out there only
    /// spiralled on, so DAgger taught a drifted student nothing that brought
    /// it back (docs/experiments.md, "Where the student on z lands"). At the
    /// default pitch and slide the spiral reaches about 11 mm in the 250
    /// steps an episode has left on the box, so a bound of 15 mm or more
    /// leaves its own growth alone; one under the belief's error keeps the
    /// search from the opening.
    pub bound_m: Option<f64>,
    /// Tell the search where the hole is by a representation instead of
    /// the truth (`[search_teacher.probe]`): see [`ProbedSearchView`].
    /// `hole_error_m` must then be 0.
    pub probe: Option<BeliefProbeConfig>,
}

/// Where a representation-told search's belief comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeliefProbeConfig {
    /// The representation (an exported model directory) whose z means the
    /// probe reads.
    pub representation: std::path::PathBuf,
    /// Episodes per round of fitting (`fit_rounds`); the first round's
    /// search is told the truth.
    #[serde(default = "default_fit_episodes")]
    pub fit_episodes: u64,
    /// The hole error of the first round's search, m: it spreads its states
    /// over the top face around the opening.
    #[serde(default = "default_fit_error")]
    pub fit_hole_error_m: f64,
    /// The probe is fitted on, and used at, states below this height above
    /// the box, m; higher up the search is told the truth.
    #[serde(default = "default_below")]
    pub below_m: f64,
    /// Rounds of fitting (at least 1). The first fits on the search told
    /// the truth with the errors above; each further round runs
    /// `fit_episodes` more episodes of the search told by the probe fitted
    /// so far (the teacher itself) and refits on all states. The probe then
    /// also sees the states its own errors lead the search to, which the
    /// first round's never visit (DAgger for the probe). 1 by default, as
    /// before this setting existed.
    #[serde(default = "default_fit_rounds")]
    pub fit_rounds: u32,
    /// Also tell the search where the hole is on the way down, above
    /// `below_m`, by a second linear probe of z (to the tip's x, y relative
    /// to the hole only; the roll stays the truth's there), fitted on the
    /// same episodes' states above `below_m`, instead of by the truth. A
    /// student on z cannot read the true offset far above the box as
    /// precisely as the direction towards it needs: most of its error was
    /// there (docs/experiments.md, "Where the z student misses"). false by
    /// default, as before this setting existed.
    #[serde(default)]
    pub approach: bool,
}

/// The probes that tell a [`ProbedSearchView`] where the hole is.
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefProbes {
    /// Below `below_m` (and above the opening): z → x, y, roll.
    pub near: LinearProbe,
    /// Above `below_m`, when configured (`approach`): z → x, y.
    pub approach: Option<LinearProbe>,
}

fn default_fit_episodes() -> u64 {
    40
}

fn default_fit_error() -> f64 {
    0.01
}

fn default_below() -> f64 {
    0.03
}

fn default_fit_rounds() -> u32 {
    1
}

impl Default for TouchSearchConfig {
    fn default() -> Self {
        // Chosen with `touch_probe search` over 20 episodes at a 2 mm
        // error (docs/experiments.md "A policy that searches by touch").
        Self {
            hole_error_m: 0.0,
            pitch_m: 0.0015,
            slide_m: 0.001,
            step_m: 0.001,
            press_n: 2.0,
            lead_m_per_n: 0.002,
            roll_gain: 1.0,
            approach_radius_m: None,
            descent_m: None,
            descent_until_m: 0.02,
            bound_m: None,
            probe: None,
        }
    }
}

impl TouchSearchConfig {
    /// The phase of a [`SearchView`] observation: from its height and the
    /// force along the hole's axis.
    pub fn phase(&self, o: &[f64]) -> SearchPhase {
        let z = o[2];
        if z < IN_OPENING_M {
            SearchPhase::InOpening
        } else if o[6] > 0.5 * self.press_n || z < 0.001 {
            SearchPhase::OnBox
        } else {
            SearchPhase::Above
        }
    }

    /// Refuses settings the search cannot run with, naming the field.
    pub fn validate(&self) -> Result<(), FieldError> {
        let f = |name: &str| format!("search_teacher.{name}");
        if !(self.hole_error_m.is_finite() && self.hole_error_m >= 0.0) {
            return Err(FieldError::new(
                f("hole_error_m"),
                self.hole_error_m,
                "must be finite and not negative",
            ));
        }
        for (name, v) in [
            ("pitch_m", self.pitch_m),
            ("slide_m", self.slide_m),
            ("step_m", self.step_m),
            ("press_n", self.press_n),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(FieldError::new(f(name), v, "must be positive and finite"));
            }
        }
        for (name, v) in [
            ("lead_m_per_n", self.lead_m_per_n),
            ("descent_until_m", self.descent_until_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(FieldError::new(
                    f(name),
                    v,
                    "must be finite and not negative",
                ));
            }
        }
        for (name, v) in [("descent_m", self.descent_m), ("bound_m", self.bound_m)] {
            if let Some(v) = v
                && !(v.is_finite() && v > 0.0)
            {
                return Err(FieldError::new(f(name), v, "must be positive and finite"));
            }
        }
        if let Some(r) = self.approach_radius_m
            && !(r.is_finite() && r >= self.step_m)
        {
            return Err(FieldError::new(
                f("approach_radius_m"),
                r,
                "must be finite and at least step_m",
            ));
        }
        if !(self.roll_gain.is_finite() && self.roll_gain > 0.0 && self.roll_gain <= 1.0) {
            return Err(FieldError::new(
                f("roll_gain"),
                self.roll_gain,
                "must lie in (0, 1]",
            ));
        }
        if let Some(p) = &self.probe {
            if self.hole_error_m != 0.0 {
                return Err(FieldError::new(
                    f("hole_error_m"),
                    self.hole_error_m,
                    "must be 0 with [search_teacher.probe]: the probe says where the hole is",
                ));
            }
            if !(p.below_m.is_finite() && p.below_m > 0.0) {
                return Err(FieldError::new(
                    f("probe.below_m"),
                    p.below_m,
                    "must be positive and finite (the probe is read below it)",
                ));
            }
            if p.fit_episodes == 0 {
                return Err(FieldError::new(
                    f("probe.fit_episodes"),
                    0,
                    "must be at least 1",
                ));
            }
            if p.fit_rounds == 0 {
                return Err(FieldError::new(
                    f("probe.fit_rounds"),
                    0,
                    "must be at least 1",
                ));
            }
            if p.fit_episodes.saturating_mul(u64::from(p.fit_rounds)) > 1_000_000 {
                return Err(FieldError::new(
                    f("probe.fit_rounds"),
                    p.fit_rounds,
                    "fit_episodes × fit_rounds must be at most 1 000 000 (the fitting \
                     episodes' seeds stay apart from DAgger's and evaluation's)",
                ));
            }
            if !(p.fit_hole_error_m.is_finite() && p.fit_hole_error_m >= 0.0) {
                return Err(FieldError::new(
                    f("probe.fit_hole_error_m"),
                    p.fit_hole_error_m,
                    "must be finite and not negative",
                ));
            }
        }
        Ok(())
    }
}

/// What [`TouchSearch`] acts on, [`SEARCH_VIEW_DIM`] values, SI units:
/// where the tip is believed to be relative to the hole (hole frame x, y,
/// with [`super::observe::HoleError`]'s per-episode error), its true height
/// above the opening, its roll relative to the hole (wrapped by the peg's
/// symmetry), the mean wrench's force of the newest 8 readings less the
/// free-space reading, in the hole frame (N, x, y, z; z positive when the
/// box pushes the peg up), and the hole's yaw in the base frame (rad).
#[derive(Debug, Clone, Copy)]
pub struct SearchView {
    /// The believed hole position's error, as [`super::observe::HoleError`].
    pub std_m: f64,
}

/// Length of a [`SearchView`] observation.
pub const SEARCH_VIEW_DIM: usize = 8;

/// Height above the box below which the tip is in the opening and the
/// search goes straight down, m.
pub const IN_OPENING_M: f64 = -0.002;

/// Width of the band beyond [`TouchSearchConfig::bound_m`] over which the
/// search's step turns from the spiral's to straight in, m: a label that
/// changes continuously with the belief is one a student can fit.
pub const BOUND_RAMP_M: f64 = 0.005;

/// Readings averaged for the force (as the ground truth does).
const FORCE_MEAN_READINGS: usize = 8;

impl Observer for SearchView {
    fn dim(&self) -> usize {
        SEARCH_VIEW_DIM
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let error = super::observe::HoleError { std_m: self.std_m };
        for (v, o) in views.iter().zip(out.chunks_exact_mut(SEARCH_VIEW_DIM)) {
            let [ex, ey] = error.error(v.hole_pose);
            let n = FORCE_MEAN_READINGS.min(v.wrench.len()).max(1);
            let mut f = Vector3::zeros();
            for r in v.wrench.ordered().skip(v.wrench.len().saturating_sub(n)) {
                for i in 0..3 {
                    f[i] += (r[i] - v.free_wrench[i]) / n as f64;
                }
            }
            // The sensor frame is the end effector's; the wrench is what
            // the peg exerts on the flange, which is what the box exerts on
            // the peg (quasi-static).
            let f = v.hole_pose.rotation.inverse() * (v.obs.ee_rot * f);
            let x_axis = v.hole_pose.rotation * Vector3::x();
            o.copy_from_slice(&[
                v.task.s_m.x + ex,
                v.task.s_m.y + ey,
                v.task.s_m.z,
                v.task.s_psi_rad,
                f.x,
                f.y,
                f.z,
                x_axis.y.atan2(x_axis.x),
            ]);
        }
    }
}

/// The scripted search (see the module's doc): acts on [`SearchView`]
/// observations, giving policy outputs for the environment's action scale.
#[derive(Debug, Clone)]
pub struct TouchSearch {
    /// Its settings.
    pub cfg: TouchSearchConfig,
    /// The environment's action scale.
    pub scale: ActionScale,
}

/// Which of its three behaviours the search is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchPhase {
    /// In the opening: straight down.
    InOpening,
    /// On the top face (the box carries the peg, or the tip is within
    /// 1 mm of it): the spiral.
    OnBox,
    /// Above the box: towards the believed opening and down.
    Above,
}

impl TouchSearch {
    /// The step (hole frame x, y, z, m) for one observation.
    pub fn step(&self, o: &[f64]) -> Vector3<f64> {
        let c = &self.cfg;
        let (bx, by) = (o[0], o[1]);
        let f = Vector3::new(o[4], o[5], o[6]);
        let phase = c.phase(o);
        if phase == SearchPhase::InOpening {
            return Vector3::new(0.0, 0.0, -c.step_m);
        }
        if phase == SearchPhase::OnBox {
            let r = r2(bx, by);
            let (rx, ry) = if r > 1e-4 {
                (bx / r, by / r)
            } else {
                (1.0, 0.0)
            };
            // Radial part per unit of tangential step: the pitch's growth
            // p/(2π r), less what a chord of length L adds by itself, L/(2r),
            // less the lead's drift.
            let fxy = r2(f.x, f.y);
            let k = ((c.pitch_m / std::f64::consts::TAU - 0.5 * c.slide_m - c.lead_m_per_n * fxy)
                / r.max(1e-4))
            .clamp(-1.0, 1.0);
            let dz = if f.z > 2.0 * c.press_n {
                0.2 * c.step_m
            } else if f.z > c.press_n {
                0.0
            } else if f.z > 0.5 * c.press_n {
                -0.2 * c.step_m
            } else {
                -c.step_m
            };
            let mut lat = [(-ry + k * rx) * c.slide_m, (rx + k * ry) * c.slide_m];
            if let Some(bound) = c.bound_m {
                let w = ((r - bound) / BOUND_RAMP_M).clamp(0.0, 1.0);
                lat = [
                    (1.0 - w) * lat[0] - w * rx * c.slide_m,
                    (1.0 - w) * lat[1] - w * ry * c.slide_m,
                ];
            }
            return Vector3::new(lat[0], lat[1], dz);
        }
        // Above the box: towards the believed opening and down at once.
        // Not first centring and then descending: a student reading the
        // belief from a representation cannot resolve the 1 mm such a gate
        // needs far above the box, and hovered there waiting. From the start
        // pose the box is 5-6 lateral centimetres and 25 vertical ones away,
        // so the tip is over the opening long before it reaches the top.
        let lateral = r2(bx, by);
        let mut d = Vector3::new(-bx, -by, 0.0);
        let radius = c.approach_radius_m.unwrap_or(c.step_m);
        d *= c.step_m / lateral.max(radius);
        d.z = match c.descent_m {
            Some(fast) if o[2] > c.descent_until_m => -fast,
            _ => -c.step_m,
        };
        d
    }

    /// Policy outputs (x, y, z, roll, base frame, scaled) for a batch of
    /// [`SearchView`] observations.
    pub fn means(&self, obs: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(obs.len() / SEARCH_VIEW_DIM * 4);
        for o in obs.chunks_exact(SEARCH_VIEW_DIM) {
            let d = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), o[7]) * self.step(o);
            out.extend_from_slice(&self.scale.from_delta(&[
                d.x,
                d.y,
                d.z,
                -self.cfg.roll_gain * o[3],
            ]));
        }
        out
    }
}

/// [`SearchView`] told where the hole is by a representation: below
/// `below_m` above the box (and above the opening, where the belief is not
/// read) the believed offset (x, y) and the peg's roll relative to the hole
/// are a linear probe's reading of the representation's z means, higher up
/// the truth (the probe is fitted near
/// the box; far above it the approach needs no precision). Height, force
/// and the hole's yaw stay the truth's.
///
/// What it is for: a teacher whose belief is a function of what a student
/// on z sees, so that DAgger's labels are ones the student can learn (a
/// teacher told the truth with an independent error gives labels that
/// differ from episode to episode for the same z).
pub struct ProbedSearchView {
    /// The representation's observer.
    pub repr: std::sync::Arc<dyn Observer>,
    /// z means → (x, y) of the tip relative to the hole (hole frame, m)
    /// and the peg's roll relative to the hole (rad, wrapped by the
    /// symmetry) near the box; z means → (x, y) above it, if given.
    pub probes: BeliefProbes,
    /// Height above the box below which the near probe is read (and above
    /// which the approach probe is), m.
    pub below_m: f64,
}

impl Observer for ProbedSearchView {
    fn dim(&self) -> usize {
        SEARCH_VIEW_DIM
    }

    fn needs_camera(&self) -> bool {
        self.repr.needs_camera()
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let zd = self.repr.dim();
        let mut z = vec![0.0; views.len() * zd];
        self.repr.observe(views, &mut z);
        SearchView { std_m: 0.0 }.observe(views, out);
        for (o, z) in out
            .chunks_exact_mut(SEARCH_VIEW_DIM)
            .zip(z.chunks_exact(zd))
        {
            tell_by_probes(&self.probes, self.below_m, z, o);
        }
    }

    fn rejected(&self) -> u64 {
        self.repr.rejected()
    }

    fn camera(&self) -> Option<shared_mem_schema::CameraCalibration> {
        self.repr.camera()
    }
}

/// Whether the search's belief is read from a probe at this height above
/// the box: below `below_m` and above the opening (in it, the search goes
/// straight down whatever it believes).
fn reads_belief(height_m: f64, below_m: f64) -> bool {
    (IN_OPENING_M..below_m).contains(&height_m)
}

/// Whether an approach probe, where there is one, is read at this height
/// above the box: from `below_m` up.
fn reads_approach(height_m: f64, below_m: f64) -> bool {
    height_m >= below_m
}

/// Replaces a [`SearchView`] observation's belief with the probes'
/// reading of `z` where they are read: near the box the offset and roll
/// (the near probe), above `below_m` the offset (the approach probe, if
/// any); in the opening, and above without an approach probe, the
/// observation is left as it is.
fn tell_by_probes(probes: &BeliefProbes, below_m: f64, z: &[f64], o: &mut [f64]) {
    let mut b = [0.0; 3];
    if reads_belief(o[2], below_m) {
        probes.near.predict_into(z, &mut b);
        (o[0], o[1], o[3]) = (b[0], b[1], b[2]);
    } else if let Some(a) = &probes.approach
        && reads_approach(o[2], below_m)
    {
        a.predict_into(z, &mut b[..2]);
        (o[0], o[1]) = (b[0], b[1]);
    }
}

/// Fits a [`ProbedSearchView`]'s probe. The first round: `cfg.fit_episodes`
/// episodes (seeds from `first_seed`) of the search `search` (its settings,
/// told the truth with a `cfg.fit_hole_error_m` error instead of by a
/// probe), in
/// `env_cfg`'s world, each state where the probe is read (below
/// `cfg.below_m` above the box and not in the opening) giving a row: the z
/// means; the tip's true x, y relative to the hole and the peg's roll
/// relative to it; with `cfg.approach`, each state above `cfg.below_m`
/// gives a row of the approach probe (the z means; x, y). Each further
/// round (`cfg.fit_rounds`) runs as many episodes (the next seeds) of the
/// search told by the probes fitted on the rows so far, as the teacher is,
/// and adds their rows. `progress` is called after each episode with the
/// episodes and rows (both probes') so far.
pub fn fit_belief_probe(
    env_cfg: &super::RlEnvConfig,
    repr: &dyn Observer,
    search: &TouchSearchConfig,
    cfg: &BeliefProbeConfig,
    first_seed: u64,
    progress: &mut dyn FnMut(u64, usize),
) -> Result<BeliefProbes, super::RlEnvError> {
    let mut env = super::RlEnv::new(env_cfg)?;
    super::observe::check_camera(&env_cfg.world.camera, repr)?;
    let search = TouchSearch {
        cfg: TouchSearchConfig {
            hole_error_m: cfg.fit_hole_error_m,
            probe: None,
            ..search.clone()
        },
        scale: env_cfg.action.clone(),
    };
    let camera = repr.needs_camera();
    let fit = |xs: &[Vec<f64>], ys: &[Vec<f64>], field: &str, where_: &str| {
        if xs.is_empty() {
            return Err(super::RlEnvError::from(FieldError::new(
                field,
                cfg.below_m,
                format!("no state of the fitting episodes came {where_} it"),
            )));
        }
        LinearProbe::fit(xs, ys, 1e-3).map_err(|e| super::RlEnvError::Representation(e.to_string()))
    };
    // Near the box: z → x, y, roll; on the way down (`approach`): z → x, y.
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let (mut xa, mut ya) = (Vec::new(), Vec::new());
    let fit_all = |xs: &[Vec<f64>], ys: &[Vec<f64>], xa: &[Vec<f64>], ya: &[Vec<f64>]| {
        Ok::<_, super::RlEnvError>(BeliefProbes {
            near: fit(xs, ys, "search_teacher.probe.below_m", "below")?,
            approach: if cfg.approach {
                Some(fit(xa, ya, "search_teacher.probe.approach", "above")?)
            } else {
                None
            },
        })
    };
    let mut probes: Option<BeliefProbes> = None;
    let mut z = vec![0.0; repr.dim()];
    for round in 0..u64::from(cfg.fit_rounds.max(1)) {
        if round > 0 {
            probes = Some(fit_all(&xs, &ys, &xa, &ya)?);
        }
        // The first round's search is told the truth with its errors; the
        // later rounds' by the probes, as the teacher is.
        let view = SearchView {
            std_m: if round == 0 {
                cfg.fit_hole_error_m
            } else {
                0.0
            },
        };
        for ep in 0..cfg.fit_episodes {
            let seed = first_seed + round * cfg.fit_episodes + ep;
            env.reset(seed, camera)?;
            loop {
                let v = env.view().expect("reset gives a view");
                let s = v.task.s_m;
                let mut o = [0.0; SEARCH_VIEW_DIM];
                view.observe(std::slice::from_ref(&v), &mut o);
                let near = reads_belief(s.z, cfg.below_m);
                let above = cfg.approach && reads_approach(s.z, cfg.below_m);
                if near || above {
                    repr.observe(std::slice::from_ref(&v), &mut z);
                    if near {
                        xs.push(z.clone());
                        ys.push(vec![s.x, s.y, v.task.s_psi_rad]);
                    } else {
                        xa.push(z.clone());
                        ya.push(vec![s.x, s.y]);
                    }
                    if let Some(p) = &probes {
                        tell_by_probes(p, cfg.below_m, &z, &mut o);
                    }
                }
                if env.step(&search.means(&o), camera)?.done() {
                    break;
                }
            }
            progress(round * cfg.fit_episodes + ep + 1, xs.len() + xa.len());
        }
    }
    fit_all(&xs, &ys, &xa, &ya)
}

/// The length of the horizontal vector (x, y).
fn r2(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}
