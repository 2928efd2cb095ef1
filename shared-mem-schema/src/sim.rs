//! The simulator's episode control: commands, reports and the task's stages.

use crate::message::{HEADER_BYTES as H, Header, Message, message};
use crate::topics;
use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Capacity of [`SimCommand::config_toml`], bytes.
pub const MAX_CONFIG_BYTES: usize = 16 * 1024;
/// Capacity of [`EpisodeReport::message`], bytes.
pub const MAX_MESSAGE_BYTES: usize = 256;

/// The episode stages of the paper's evaluation (Sec. "Evaluation
/// metrics"), ordered: a later stage implies the earlier ones were reached.
/// On the wire as [`Stage::code`], in text (logs, events) as
/// [`Stage::name`].
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
#[repr(u32)]
pub enum Stage {
    /// The peg never touched the box.
    #[default]
    Failed = 0,
    /// The peg touched the box.
    Touched = 1,
    /// The peg's tip went into the hole.
    Inserted = 2,
    /// The peg's tip reached the hole's bottom.
    Completed = 3,
}

impl Stage {
    /// All stages, in order.
    pub const ALL: [Stage; 4] = [
        Stage::Failed,
        Stage::Touched,
        Stage::Inserted,
        Stage::Completed,
    ];

    /// The wire code.
    pub fn code(self) -> u32 {
        self as u32
    }

    /// The stage of a wire code; an unknown code reads as failed.
    pub fn from_code(code: u32) -> Self {
        Self::ALL
            .get(code as usize)
            .copied()
            .unwrap_or(Stage::Failed)
    }

    /// Lower-case name: failed, touched, inserted or completed.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Failed => "failed",
            Stage::Touched => "touched",
            Stage::Inserted => "inserted",
            Stage::Completed => "completed",
        }
    }
}

impl core::fmt::Display for Stage {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Learner → hw-sim: episode control.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct SimCommand {
    /// Header (`seq` is the request id echoed in [`EpisodeReport`]).
    pub header: Header,
    /// What to do ([`SimCommand::RESET`], [`SimCommand::SHUTDOWN`]).
    pub command: u32,
    /// Used bytes of `config_toml`.
    pub config_len: u32,
    /// Seed of the new episode.
    pub seed: u64,
    /// TOML of the simulator's world configuration (UTF-8); empty: keep the
    /// current configuration.
    pub config_toml: [u8; MAX_CONFIG_BYTES],
}

impl SimCommand {
    /// Start a new episode (new box pose, arm at its start pose).
    pub const RESET: u32 = 1;
    /// Stop the simulator process.
    pub const SHUTDOWN: u32 = 2;
}

/// hw-sim → learner: the episode and task state, at 20 Hz and after each
/// command (the simulator's ground truth; a real cell has none of it).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct EpisodeReport {
    /// Header (`episode`: the current episode).
    pub header: Header,
    /// `seq` of the last command handled (0: none).
    pub command_seq: u64,
    /// Seed of the current episode.
    pub seed: u64,
    /// Hardware step of the report.
    pub step: u64,
    /// Result of the last command: [`EpisodeReport::OK`] or
    /// [`EpisodeReport::REJECTED`] (reason in `message`).
    pub command_result: u32,
    /// Peg: 0 none, 1 square, 2 triangle, 3 semicircle, 4 hexagon.
    pub peg: u32,
    /// Stage now, [`Stage::code`]: 0 failed (not touched), 1 touched, 2
    /// inserted, 3 completed.
    pub stage_now: u32,
    /// Best stage reached this episode (same codes).
    pub best_stage: u32,
    /// 1 when the peg touches the box.
    pub in_contact: u32,
    /// Used bytes of `message`.
    pub message_len: u32,
    /// Peg tip relative to the hole's top centre, hole frame, m.
    pub s_m: [f64; 3],
    /// Peg roll relative to the hole, wrapped by its symmetry, rad.
    pub s_psi_rad: f64,
    /// Hole top-centre position in the base frame, m.
    pub hole_pos_m: [f64; 3],
    /// Hole orientation in the base frame, quaternion (x, y, z, w).
    pub hole_quat_xyzw: [f64; 4],
    /// Peg width (outline scale), m.
    pub peg_width_m: f64,
    /// Hole depth, m.
    pub hole_depth_m: f64,
    /// UTF-8 text: the reason a command was rejected.
    pub message: [u8; MAX_MESSAGE_BYTES],
}

impl EpisodeReport {
    /// The command was carried out.
    pub const OK: u32 = 0;
    /// The command was refused; `message` says why.
    pub const REJECTED: u32 = 1;

    /// The stage reached at this step.
    pub fn stage_now(&self) -> Stage {
        Stage::from_code(self.stage_now)
    }

    /// The best stage reached this episode so far.
    pub fn best_stage(&self) -> Stage {
        Stage::from_code(self.best_stage)
    }

    /// The message text (lossy UTF-8).
    pub fn message_text(&self) -> String {
        let n = (self.message_len as usize).min(MAX_MESSAGE_BYTES);
        String::from_utf8_lossy(&self.message[..n]).into_owned()
    }

    /// What is wrong with the task's geometry this report carries, if
    /// anything: a hole pose or size that is not finite, a hole beyond 10 m, a rotation that is
    /// not a unit quaternion, a depth or peg width not above zero. The
    /// simulator is a peer like any other: a receiver whose world has a task
    /// checks before it places the box, rewards, or records the episode by
    /// these values (a world without one reports zeros).
    pub fn task_problem(&self) -> Option<String> {
        let p = self.hole_pos_m;
        if p.iter().any(|v| !v.is_finite()) {
            return Some(format!("hole_pos_m {p:?} is not finite"));
        }
        // No arm reaches 10 m: a box there is a corrupt report.
        if p.iter().map(|v| v * v).sum::<f64>() > 100.0 {
            return Some(format!("hole_pos_m {p:?} is beyond 10 m of the base"));
        }
        let q = self.hole_quat_xyzw;
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        // f32-rounded unit quaternions are within 1e-6; 1e-3 allows any
        // honest conversion and nothing degenerate.
        if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
            return Some(format!(
                "hole_quat_xyzw {q:?} is not a unit quaternion (norm {norm})"
            ));
        }
        for (name, v) in [
            ("hole_depth_m", self.hole_depth_m),
            ("peg_width_m", self.peg_width_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Some(format!("{name} {v} is not a positive finite length"));
            }
        }
        None
    }
}

message!(SimCommand, topics::SIM_COMMAND, "SimCommand");
message!(EpisodeReport, topics::EPISODE, "EpisodeReport");

// Layouts (`Pod` rejects padding; these pin the sizes).
const _: () = assert!(size_of::<SimCommand>() == H + 16 + MAX_CONFIG_BYTES);
const _: () = assert!(size_of::<EpisodeReport>() == H + 24 + 24 + 8 * 13 + MAX_MESSAGE_BYTES);

#[cfg(test)]
mod tests {
    use super::*;

    fn sound() -> EpisodeReport {
        let mut r = EpisodeReport::zeroed();
        r.hole_pos_m = [0.6, 0.0, 0.1];
        r.hole_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
        r.hole_depth_m = 0.04;
        r.peg_width_m = 0.03;
        r
    }

    #[test]
    fn a_reports_task_geometry_is_checked_field_by_field() {
        assert_eq!(sound().task_problem(), None);
        let mut r = sound();
        r.hole_pos_m[1] = f64::NAN;
        assert!(r.task_problem().unwrap().contains("hole_pos_m"));
        let mut r = sound();
        r.hole_pos_m[0] = 1e300;
        assert!(r.task_problem().unwrap().contains("beyond 10 m"));
        let mut r = sound();
        r.hole_quat_xyzw = [0.0; 4];
        assert!(r.task_problem().unwrap().contains("not a unit quaternion"));
        let mut r = sound();
        r.hole_quat_xyzw[0] = f64::INFINITY;
        assert!(r.task_problem().unwrap().contains("hole_quat_xyzw"));
        let mut r = sound();
        r.hole_depth_m = 0.0;
        assert!(r.task_problem().unwrap().contains("hole_depth_m"));
        let mut r = sound();
        r.peg_width_m = f64::NAN;
        assert!(r.task_problem().unwrap().contains("peg_width_m"));
    }
}
