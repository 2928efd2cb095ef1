//! The episode events of a log's `/events` channel, one typed value each,
//! written and read with serde (JSON tagged by `"event"`).

use crate::mix::EpisodePolicy;
use hw_sim::{PegShape, Stage, WorldConfig};
use serde::{Deserialize, Serialize};

/// An episode event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// The episode started (boxed: it is by far the largest).
    Reset(Box<Reset>),
    /// A better stage was reached.
    Stage {
        /// The stage.
        stage: Stage,
    },
    /// The episode ended.
    Outcome(EpisodeEnd),
}

/// What an episode started from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reset {
    /// Episode number.
    pub episode: u64,
    /// Its seed.
    pub seed: u64,
    /// The peg.
    pub peg: PegShape,
    /// The policy that acts.
    pub policy: EpisodePolicy,
    /// Live runs: whether the stack ran in lockstep.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lockstep: Option<bool>,
    /// Live runs: the world configuration sent with the reset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<WorldConfig>,
    /// Hole top-centre position in the base frame, m.
    pub hole_pos_m: [f64; 3],
    /// Hole orientation in the base frame, quaternion (x, y, z, w).
    pub hole_quat_xyzw: [f64; 4],
    /// Hole depth, m.
    pub hole_depth_m: f64,
}

/// How an episode ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEnd {
    /// Best stage reached.
    pub stage: Stage,
    /// Live runs: hardware time from the first frame to the end, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// Live runs: actions sent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actions: Option<u64>,
    /// Collection: 20 Hz states written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub states: Option<u64>,
    /// Collection: stopped by a termination request.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<bool>,
}
