//! Reinforcement learning on the fast path (issue 18): the environment
//! ([`env`], [`vec`]), what the policy observes ([`observe`], the frozen
//! representation in [`represent`]), the paper's
//! staged reward and outcome categories ([`reward`]), the Gaussian policy
//! with its observation normalisation ([`obs_norm`]), the value baselines
//! ([`gaussian`], [`value`], on the small differentiable network of
//! [`mlp`]), TRPO ([`trpo`]) and PPO ([`ppo`]), and the training loop
//! ([`train`]), DAgger from a privileged teacher ([`distill`]), and the
//! scripted touch search such a teacher can be ([`search`], told where the
//! hole is through a linear probe of z: [`probe`]).
//! docs/rl.md gives every
//! constant and setting with its source or reason.

pub mod adam;
pub mod curve;
pub mod distill;
pub mod env;
pub mod export;
pub mod gaussian;
pub mod mlp;
pub mod obs_norm;
pub mod observe;
pub mod package;
pub mod ppo;
pub mod probe;
pub mod raw;
pub mod represent;
pub mod reward;
pub mod run;
pub mod run_config;
pub mod search;
pub mod train;
pub mod trpo;
pub mod value;
pub mod vec;

pub use env::{ActionScale, RlEnv, RlEnvConfig, RlEnvError, StepOutcome, TrainingAids};
pub use gaussian::{GaussianPolicy, LinearBaseline};
pub use obs_norm::ObsNorm;
pub use observe::{GroundTruth, ObsView, ObservationKind, Observer};
pub use ppo::PpoConfig;
pub use represent::Representation;
pub use reward::{Outcome, RewardConfig, RewardStage};
pub use train::{Algorithm, EpisodeStats, IterationStats, PolicyConfig, Trainer, TrainerState};
pub use trpo::TrpoConfig;
pub use value::{Baseline, BaselineKind, ValueConfig, ValueNet};
pub use vec::{BatchEnv, VecEnv};
