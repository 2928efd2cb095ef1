//! The paper's staged reward (Sec. "Reward Design") and its four outcome
//! categories (Sec. "Evaluation Metrics").
//!
//! The paper leaves every constant unspecified and prints two terms that do
//! not work as written; docs/rl.md gives each choice and its reason. Stages
//! are tested from the top: completion, insertion, alignment, reaching.
//! Insertion and completion require the tip inside the hole's cross-section
//! (hw-sim's `TaskState::in_hole`), not its height alone, so a peg pushed
//! down beside the box earns reaching reward only.

use hw_sim::{Stage, TaskState};
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;

/// The reward's constants (docs/rl.md, "Reward").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RewardConfig {
    /// Scale of the reaching term, c_r (its maximum, at the hole's opening
    /// with the roll aligned).
    pub c_r: f64,
    /// Scale of the distance inside the reaching term's tanh, λ, 1/m.
    pub lambda_per_m: f64,
    /// Scale of the alignment term, c_a.
    pub c_a: f64,
    /// The alignment region: |s_x|, |s_y|, |s_z| at most these, ε₁, m.
    pub eps1_m: [f64; 3],
    /// The alignment region's roll bound, ε_ψ, rad.
    pub eps_psi_rad: f64,
    /// The step up on entering the hole, c_e: insertion starts at 2 + c_e
    /// where alignment ends at 2 (docs/rl.md, "Reward": why).
    pub c_e: f64,
    /// Scale of the insertion term, c_i (its gain from the opening to the
    /// bottom).
    pub c_i: f64,
    /// Completion: the tip within this of the hole's bottom, ε₂, m.
    pub eps2_m: f64,
}

impl Default for RewardConfig {
    fn default() -> Self {
        Self {
            c_r: 1.0,
            lambda_per_m: 5.0,
            c_a: 1.0,
            eps1_m: [0.005, 0.005, 0.02],
            eps_psi_rad: 0.1,
            c_e: 1.0,
            c_i: 1.5,
            eps2_m: 0.003,
        }
    }
}

/// The largest reward of one step (completion).
pub const MAX_STEP_REWARD: f64 = 5.0;

impl RewardConfig {
    /// Checks that every constant is usable: positive and finite (c_e may
    /// be 0), and the stages ordered (reaching ≤ 1 ≤ alignment ≤ 2 ≤
    /// insertion < 5).
    pub fn validate(&self) -> Result<(), FieldError> {
        let positive = [
            ("reward.c_r", self.c_r),
            ("reward.lambda_per_m", self.lambda_per_m),
            ("reward.c_a", self.c_a),
            ("reward.eps1_m[0]", self.eps1_m[0]),
            ("reward.eps1_m[1]", self.eps1_m[1]),
            ("reward.eps1_m[2]", self.eps1_m[2]),
            ("reward.eps_psi_rad", self.eps_psi_rad),
            ("reward.c_i", self.c_i),
            ("reward.eps2_m", self.eps2_m),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(FieldError::new(name, v, "must be positive and finite"));
            }
        }
        if self.c_r > 1.0 {
            return Err(FieldError::new(
                "reward.c_r",
                self.c_r,
                "at most 1: reaching must not pay more than alignment's base of 1",
            ));
        }
        if self.c_a > 1.0 {
            return Err(FieldError::new(
                "reward.c_a",
                self.c_a,
                "at most 1: alignment must not pay more than insertion's base of 2",
            ));
        }
        if !(self.c_e.is_finite() && self.c_e >= 0.0) {
            return Err(FieldError::new(
                "reward.c_e",
                self.c_e,
                "must be finite and not negative",
            ));
        }
        if self.c_e + self.c_i >= 3.0 {
            return Err(FieldError::new(
                "reward.c_e + reward.c_i",
                format_args!("{} + {}", self.c_e, self.c_i),
                "must be below 3: insertion must pay less than completion's 5 (a configuration \
                 written before c_e existed was trained without the entry step: give it \
                 c_e = 0)",
            ));
        }
        Ok(())
    }
}

/// What the reward needs of the task besides the tip's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RewardGeometry {
    /// Hole depth h_d, m (the target is (0, 0, −h_d)).
    pub hole_depth_m: f64,
    /// The peg's rotational symmetry order k; the wrapped roll s_ψ lies in
    /// (−π/k, π/k].
    pub symmetry: u32,
}

impl RewardGeometry {
    /// The largest wrapped roll, π/k, rad.
    pub fn max_roll_rad(&self) -> f64 {
        std::f64::consts::PI / self.symmetry.max(1) as f64
    }
}

/// The stage of the staged reward a state falls in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum RewardStage {
    /// (r): anywhere else.
    Reaching,
    /// (a): just above the opening, roughly aligned.
    Alignment,
    /// (i): the tip in the hole.
    Insertion,
    /// (c): the tip in the hole, within ε₂ of its bottom.
    Completion,
}

/// The reward of one state and its stage.
///
/// - (c) in the hole and `h_d − |s_z| ≤ ε₂`: 5.
/// - (i) in the hole: `2 + c_e + c_i·min(|s_z|, h_d)/h_d`, from 2 + c_e at
///   the opening to 2 + c_e + c_i at the bottom.
/// - (a) `|s| ≤ ε₁` per axis and `|s_ψ| ≤ ε_ψ`:
///   `1 + c_a(1 − ‖s‖/‖ε₁‖)(1 − |s_ψ|/ε_ψ)`.
/// - (r) otherwise: `c_r(1 − tanh(λ‖s‖))(1 − |s_ψ|/(π/k))`.
pub fn reward(cfg: &RewardConfig, geom: &RewardGeometry, task: &TaskState) -> (f64, RewardStage) {
    let s = task.s_m;
    let psi = task.s_psi_rad.abs();
    let h_d = geom.hole_depth_m;
    if task.in_hole {
        let depth = s.z.abs().min(h_d);
        if h_d - depth <= cfg.eps2_m {
            return (MAX_STEP_REWARD, RewardStage::Completion);
        }
        return (
            2.0 + cfg.c_e + cfg.c_i * depth / h_d,
            RewardStage::Insertion,
        );
    }
    let e = cfg.eps1_m;
    if s.x.abs() <= e[0] && s.y.abs() <= e[1] && s.z.abs() <= e[2] && psi <= cfg.eps_psi_rad {
        let e_norm = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
        let r = 1.0 + cfg.c_a * (1.0 - s.norm() / e_norm) * (1.0 - psi / cfg.eps_psi_rad);
        return (r, RewardStage::Alignment);
    }
    let roll = (1.0 - psi / geom.max_roll_rad()).max(0.0);
    let r = cfg.c_r * (1.0 - (cfg.lambda_per_m * s.norm()).tanh()) * roll;
    (r, RewardStage::Reaching)
}

/// The paper's four outcome categories of an episode (the best stage the
/// simulator saw in it, at 1 kHz).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Outcome {
    /// The peg fails to reach the box.
    Failed,
    /// The peg only makes contact with the box.
    TouchedBox,
    /// The peg goes into the hole but does not reach the bottom.
    InsertedIntoHole,
    /// The peg reaches the bottom of the hole.
    CompletedInsertion,
}

impl Outcome {
    /// All four, from failed to completed.
    pub const ALL: [Outcome; 4] = [
        Outcome::Failed,
        Outcome::TouchedBox,
        Outcome::InsertedIntoHole,
        Outcome::CompletedInsertion,
    ];

    /// The category of an episode whose best stage was `stage`.
    pub fn from_stage(stage: Stage) -> Self {
        match stage {
            Stage::Failed => Outcome::Failed,
            Stage::Touched => Outcome::TouchedBox,
            Stage::Inserted => Outcome::InsertedIntoHole,
            Stage::Completed => Outcome::CompletedInsertion,
        }
    }

    /// The paper's name of the category.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Failed => "failed",
            Outcome::TouchedBox => "touched the box",
            Outcome::InsertedIntoHole => "inserted into hole",
            Outcome::CompletedInsertion => "completed insertion",
        }
    }

    /// Index in [`Outcome::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// An episode's reward normalised by the highest attainable one, as the
/// paper reports it: the sum over the episode divided by 5 per step of the
/// full episode length (a terminated episode earns nothing for the steps it
/// did not run).
pub fn normalised_return(sum: f64, max_steps: u32) -> f64 {
    sum / (MAX_STEP_REWARD * max_steps.max(1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn state(s: [f64; 3], psi: f64, in_hole: bool) -> TaskState {
        TaskState {
            s_m: Vector3::from(s),
            s_psi_rad: psi,
            in_contact: false,
            in_hole,
            stage_now: Stage::Failed,
            best_stage: Stage::Failed,
        }
    }

    const GEOM: RewardGeometry = RewardGeometry {
        hole_depth_m: 0.04,
        symmetry: 4,
    };

    fn r(s: [f64; 3], psi: f64, in_hole: bool) -> (f64, RewardStage) {
        reward(&RewardConfig::default(), &GEOM, &state(s, psi, in_hole))
    }

    #[test]
    fn reaching_by_hand() {
        // ‖s‖ = 0.1 m, λ = 5: 1 − tanh(0.5) = 0.537883; roll π/16 of π/4
        // leaves 0.75.
        let (v, st) = r([0.06, 0.0, 0.08], std::f64::consts::PI / 16.0, false);
        assert_eq!(st, RewardStage::Reaching);
        assert!((v - 0.537_882_842_739_990 * 0.75).abs() < 1e-12, "{v}");
        // Rolled the most a square can be: nothing.
        let (v, _) = r([0.0, 0.0, 0.05], -std::f64::consts::FRAC_PI_4, false);
        assert_eq!(v, 0.0);
    }

    #[test]
    fn alignment_by_hand() {
        // ‖ε₁‖ = √(0.005² + 0.005² + 0.02²) = 0.0212132; ‖s‖ = 0.005:
        // 1 + (1 − 0.235702)(1 − 0.05/0.1) = 1.382149.
        let (v, st) = r([0.003, 0.0, 0.004], 0.05, false);
        assert_eq!(st, RewardStage::Alignment);
        assert!((v - 1.382_148_869_802_612).abs() < 1e-12, "{v}");
        // Aligned at the opening: 2, alignment's best.
        assert_eq!(
            r([0.0, 0.0, 0.0], 0.0, false),
            (2.0, RewardStage::Alignment)
        );
        // Outside ε₁ on one axis, or rolled past ε_ψ: reaching.
        assert_eq!(r([0.006, 0.0, 0.004], 0.0, false).1, RewardStage::Reaching);
        assert_eq!(r([0.0, 0.0, 0.004], 0.11, false).1, RewardStage::Reaching);
    }

    #[test]
    fn insertion_and_completion_by_hand() {
        // 1 cm into a 4 cm hole: 2 + 1 + 1.5·0.25 = 3.375.
        let (v, st) = r([0.0005, 0.0, -0.01], 0.0, true);
        assert_eq!(st, RewardStage::Insertion);
        assert!((v - 3.375).abs() < 1e-12);
        // 3.6 cm: 0.4 cm short of the bottom, above ε₂ = 3 mm: 4.35.
        let (v, st) = r([0.0, 0.0, -0.036], 0.0, true);
        assert_eq!(st, RewardStage::Insertion);
        assert!((v - 4.35).abs() < 1e-12);
        // Just in: a step up from alignment's best, 2, to 3.
        let (v, st) = r([0.0, 0.0, -0.0001], 0.0, true);
        assert_eq!(st, RewardStage::Insertion);
        assert!((v - 3.00375).abs() < 1e-12, "{v}");
        // 3.8 cm: within ε₂.
        assert_eq!(
            r([0.0, 0.0, -0.038], 0.0, true),
            (5.0, RewardStage::Completion)
        );
    }

    #[test]
    fn pushed_down_beside_the_box_is_not_insertion() {
        // The tip 4 cm below the top face but 9 cm off the hole's axis,
        // beside the box: hw-sim reports it out of the hole.
        let (v, st) = r([0.09, 0.0, -0.04], 0.0, false);
        assert_eq!(st, RewardStage::Reaching);
        assert!(v < 1.0, "{v}");
        // Just below the opening but on the outline (not in by the margin):
        // alignment at most, never insertion.
        let (v, st) = r([0.0045, 0.0, -0.004], 0.0, false);
        assert_eq!(st, RewardStage::Alignment);
        assert!(v < 2.0);
    }

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        RewardConfig::default().validate().unwrap();
        let bad = RewardConfig {
            lambda_per_m: -1.0,
            ..Default::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("reward.lambda_per_m"), "{e}");
        let bad = RewardConfig {
            c_i: 2.5,
            ..Default::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(
            e.contains("reward.c_e + reward.c_i") && e.contains("c_e = 0"),
            "{e}"
        );
        let bad = RewardConfig {
            c_e: -0.5,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("c_e"));
    }

    #[test]
    fn stages_map_to_outcomes_and_normalise() {
        let got: Vec<_> = Stage::ALL.into_iter().map(Outcome::from_stage).collect();
        assert_eq!(got, Outcome::ALL);
        assert_eq!(normalised_return(1250.0, 500), 0.5);
    }
}
