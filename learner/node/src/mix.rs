//! The policy mix of data collection (paper, "Experiments": "We roll out a
//! random policy as well as a heuristic policy while collecting the data"):
//! which policy an episode runs, drawn from its seed, and that policy's
//! actions. Fast collection (the learner's `collect`) and the live node's
//! collection mode share it; the episode's [`EpisodePolicy`] is recorded in
//! its log.

use crate::policy::{
    Action4, HeuristicConfig, HeuristicPolicy, Observation, Phase, RandomConfig, RandomPolicy,
    TaskGeometry, WrenchHistory,
};
use stack_common::rng;

/// The policy mix.
#[derive(Debug, Clone, PartialEq)]
pub struct Mix {
    /// Share of episodes run by the heuristic (the rest: random).
    pub heuristic_fraction: f64,
    /// Gaussian noise added to the heuristic's position steps, m (σ).
    pub heuristic_noise_m: f64,
    /// The random policy's tuning.
    pub random: RandomConfig,
    /// An episode that completed the insertion ends this many actions
    /// later (none: it runs its full length). A peg resting at the bottom
    /// changes nothing from one state to the next; the states it would take
    /// go to new episodes instead (new box poses, approaches and contacts).
    pub end_after_completion: Option<u32>,
}

impl Default for Mix {
    fn default() -> Self {
        Self {
            heuristic_fraction: 0.5,
            heuristic_noise_m: 0.001,
            random: RandomConfig::default(),
            end_after_completion: Some(10),
        }
    }
}

/// Which policy an episode runs (serde: its [`EpisodePolicy::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EpisodePolicy {
    /// The scripted insertion.
    Heuristic,
    /// The bounded random walk.
    Random,
    /// A trained policy (`learner run --policy`).
    Learned,
    /// Recorded elsewhere and imported (`learner dataset import`): the
    /// policy that acted is not known.
    Imported,
}

impl EpisodePolicy {
    /// Name used in logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Heuristic => "heuristic",
            Self::Random => "random",
            Self::Learned => "learned",
            Self::Imported => "imported",
        }
    }
}

/// The mixed policy of one episode.
pub struct MixedPolicy {
    kind: EpisodePolicy,
    heuristic: HeuristicPolicy,
    random: RandomPolicy,
    noise_m: f64,
    rng: rng::SimRng,
}

impl MixedPolicy {
    /// Draws the episode's policy from `seed`.
    pub fn new(mix: &Mix, seed: u64) -> Self {
        let mut rng = rng::seeded(seed, 23);
        let kind = if rng::unit(&mut rng) < mix.heuristic_fraction {
            EpisodePolicy::Heuristic
        } else {
            EpisodePolicy::Random
        };
        Self {
            kind,
            heuristic: HeuristicPolicy::new(HeuristicConfig::default()),
            random: RandomPolicy::new(mix.random.clone(), seed),
            noise_m: mix.heuristic_noise_m,
            rng,
        }
    }

    /// The policy drawn.
    pub fn kind(&self) -> EpisodePolicy {
        self.kind
    }

    /// The next action.
    pub fn act(
        &mut self,
        obs: &Observation,
        wrench: &WrenchHistory,
        task: &TaskGeometry,
    ) -> Action4 {
        match self.kind {
            EpisodePolicy::Heuristic => {
                let mut a = self.heuristic.act(obs, wrench, task);
                // In the hole (and resting on its bottom) the walls hold
                // the tip: noise would only wind the target into them
                // until the force faults the controller (10 of 59
                // episodes in the hole, 2 at the bottom, measured).
                if self.heuristic.phase() == Phase::Insert {
                    return a;
                }
                let down = a[2].min(0.0);
                for x in &mut a[..3] {
                    *x += self.noise_m * rng::normal(&mut self.rng);
                }
                // Noise may slow a descent or move it sideways, never
                // speed it up downwards: the heuristic's own speed near a
                // surface is what keeps the first contact below the
                // overload (1 mm of noise per action is 2 cm/s).
                a[2] = a[2].max(down);
                a
            }
            // A mix draws only the two above.
            EpisodePolicy::Random | EpisodePolicy::Learned | EpisodePolicy::Imported => {
                self.random.act(obs, task)
            }
        }
    }
}
