//! What a peer's reset command may ask for. The world configuration in a
//! `SimCommand` comes from any process that can open the command topic, so
//! it is admitted against what hw-sim was started with: its robot must be a
//! built-in one or a URDF file in the robot directory configured at start
//! (never an arbitrary path), and it may tighten a safety setting but never
//! relax it.

use crate::{SimError, World, WorldConfig};
use robot_model::descriptions::RobotCatalog;
use shared_mem_schema::config::ConfigFileError;

/// Why a reset's configuration was refused (the running world is kept).
#[derive(Debug, thiserror::Error)]
pub enum ResetError {
    /// The configuration is not text.
    #[error("the configuration is not UTF-8")]
    NotUtf8,
    /// The TOML does not parse (or names an unknown field).
    #[error(transparent)]
    Parse(#[from] ConfigFileError),
    /// The command would relax a safety setting of the start-up
    /// configuration.
    #[error(
        "`{field}` = {asked}: a reset command may not relax a safety setting (hw-sim was started \
         with {field} = {start})"
    )]
    Relaxes {
        /// The field.
        field: &'static str,
        /// What the command asked for.
        asked: String,
        /// The start-up value.
        start: String,
    },
    /// The robot is not allowed, does not load, or the world cannot be
    /// built from the configuration.
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// The start-up configuration and the robots a reset may name.
#[derive(Debug, Clone)]
pub struct ResetPolicy {
    start: WorldConfig,
    robots: RobotCatalog,
}

impl ResetPolicy {
    /// Resets are judged against `start`, the configuration hw-sim was
    /// started with; their robots come from `robots`.
    pub fn new(start: WorldConfig, robots: RobotCatalog) -> Self {
        Self { start, robots }
    }

    /// The configuration `toml` (a command's bytes) asks for, with `seed`,
    /// if it is admissible; not yet built.
    pub fn admit(&self, toml: &[u8], seed: u64) -> Result<WorldConfig, ResetError> {
        let text = std::str::from_utf8(toml).map_err(|_| ResetError::NotUtf8)?;
        let mut config = WorldConfig::from_toml(text)?;
        config.seed = seed;
        // The simulated drives' torque saturation is the one safety setting
        // of the world (the command timeouts are command-line options,
        // which no message reaches).
        if self.start.clamp_torques && !config.clamp_torques {
            return Err(ResetError::Relaxes {
                field: "clamp_torques",
                asked: "false".into(),
                start: "true".into(),
            });
        }
        // Refuse a robot outside the catalog before anything is built.
        self.robots.resolve(&config.robot).map_err(SimError::from)?;
        Ok(config)
    }

    /// The world a reset command asks for (built aside, so that a refused
    /// one leaves the running world untouched).
    pub fn world(&self, toml: &[u8], seed: u64) -> Result<World, ResetError> {
        let config = self.admit(toml, seed)?;
        let model = self.robots.load(&config.robot).map_err(SimError::from)?;
        Ok(World::with_model(model, config)?)
    }
}
