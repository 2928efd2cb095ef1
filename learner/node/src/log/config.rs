//! The configuration record of a log's `/config` channel: what an episode
//! ran with, one typed value written by the live node and by fast-mode
//! collection, read back by the dataset labeler (JSON through serde).

use crate::mix::EpisodePolicy;
use hw_sim::WorldConfig;
use rt_controller::ControllerConfig;
use serde::{Deserialize, Serialize};

/// Which path ran the episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunMode {
    /// The live policy node against the process stack (`learner run`).
    Live,
    /// In-process lockstep collection (`learner collect`).
    Fast,
}

/// The configuration in force for one episode. Fields only one writer
/// knows are optional, so logs of either path (and of older builds) read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    /// Which path ran it.
    pub mode: RunMode,
    /// The world configuration.
    pub world: WorldConfig,
    /// The robot description: the world's, repeated at the top so that a
    /// person reading the log finds it at once.
    pub robot: String,
    /// The policy that acted.
    pub policy: EpisodePolicy,
    /// Episode number.
    pub episode: u64,
    /// Its seed.
    pub seed: u64,
    /// Live runs: whether the stack ran in lockstep.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lockstep: Option<bool>,
    /// Live runs: the service namespace.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub namespace: Option<String>,
    /// Fast mode: the control law (the live node does not see the
    /// daemon's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller: Option<ControllerConfig>,
}

impl RunConfig {
    /// The record of an episode in `world` with `policy`; the
    /// mode-specific fields are left empty.
    pub fn new(
        mode: RunMode,
        world: WorldConfig,
        policy: EpisodePolicy,
        episode: u64,
        seed: u64,
    ) -> Self {
        Self {
            mode,
            robot: world.robot.clone(),
            world,
            policy,
            episode,
            seed,
            lockstep: None,
            namespace: None,
            controller: None,
        }
    }
}
