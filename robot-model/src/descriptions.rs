//! The robot descriptions shipped with the crate, embedded so that any
//! process can load them without knowing where the repository lies.

use crate::{LoadOptions, Model, ModelError};
use std::path::{Component, Path, PathBuf};

/// The KUKA LBR iiwa 14 (the paper's simulated robot), `urdf/iiwa14.urdf`.
pub const IIWA14_URDF: &str = include_str!("../urdf/iiwa14.urdf");
/// The Franka Emika Panda (the paper's real robot), `urdf/panda.urdf`.
pub const PANDA_URDF: &str = include_str!("../urdf/panda.urdf");
/// The Franka Research 3 with the Franka Hand (the Franka backend's robot),
/// `urdf/fr3.urdf`; end-effector frame `fr3_hand_tcp`.
pub const FR3_URDF: &str = include_str!("../urdf/fr3.urdf");

/// The Panda's "ready" pose (Franka's documented start pose): the peg tip at
/// (0.307, 0, 0.470) m pointing down.
pub const PANDA_READY_Q: [f64; 7] = [
    0.0,
    -std::f64::consts::FRAC_PI_4,
    0.0,
    -3.0 * std::f64::consts::FRAC_PI_4,
    0.0,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_4,
];

/// The FR3's "ready" pose: the same joint angles as the Panda's, inside the
/// FR3's narrower joint limits.
pub const FR3_READY_Q: [f64; 7] = PANDA_READY_Q;

/// A start pose of the iiwa 14 (ours): the peg tip at (0.580, 0, 0.353) m
/// pointing straight down. The three pitch joints sum to π (q2 − q4 + q6);
/// the pose before (q6 = 1.2) left the peg 0.0416 rad off the vertical, so
/// it wedged in the hole part-way down (docs/experiments.md).
pub const IIWA14_HOME_Q: [f64; 7] = [0.0, 0.5, 0.0, -1.4, 0.0, std::f64::consts::PI - 1.9, 0.0];

/// The start pose of a built-in robot, by its URDF robot name.
pub fn home_configuration(robot_name: &str) -> Option<[f64; 7]> {
    match robot_name {
        "panda" => Some(PANDA_READY_Q),
        "iiwa14" => Some(IIWA14_HOME_Q),
        "fr3" => Some(FR3_READY_Q),
        _ => None,
    }
}

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: [&str; 3] = ["iiwa14", "panda", "fr3"];

/// Loads a robot named in a configuration the operator wrote: a built-in
/// name ([`BUILTIN_NAMES`]) or else the path of a URDF file (a regular file
/// of at most [`crate::urdf::MAX_URDF_BYTES`]). A name that comes from a
/// peer or a file someone else wrote goes through a [`RobotCatalog`].
pub fn load(name_or_path: &str) -> Result<Model, ModelError> {
    if BUILTIN_NAMES.contains(&name_or_path) {
        builtin(name_or_path)
    } else {
        Model::from_urdf_file(name_or_path, &LoadOptions::default())
    }
}

/// Loads a built-in description by name (`"iiwa14"`, `"panda"` or `"fr3"`).
pub fn builtin(name: &str) -> Result<Model, ModelError> {
    let text = match name {
        "iiwa14" => IIWA14_URDF,
        "panda" => PANDA_URDF,
        "fr3" => FR3_URDF,
        other => {
            return Err(ModelError::Parse {
                path: None,
                message: format!(
                    "unknown built-in robot '{other}' (known: {})",
                    BUILTIN_NAMES.join(", ")
                ),
            });
        }
    };
    Model::from_urdf_str(text, &LoadOptions::default())
}

/// Where a robot named by input this process does not trust (a peer's
/// message, a log's configuration) may come from: the built-in descriptions
/// and, when one was configured at start-up, the URDF files inside one
/// directory. Nothing else on the file system can be reached through it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RobotCatalog {
    /// The canonical robot directory.
    dir: Option<PathBuf>,
}

impl RobotCatalog {
    /// The built-in robots only.
    pub fn builtin_only() -> Self {
        Self::default()
    }

    /// The built-in robots and the URDF files under `dir` (canonicalised
    /// now: a later change of a symbolic link on the way does not move it).
    pub fn with_dir(dir: &Path) -> Result<Self, ModelError> {
        let io = |source| ModelError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let canonical = dir.canonicalize().map_err(io)?;
        if !canonical.is_dir() {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the robot directory is not a directory",
            )));
        }
        Ok(Self {
            dir: Some(canonical),
        })
    }

    /// The robot directory, canonical.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    /// The file `name` stands for inside the robot directory (`None`: a
    /// built-in robot). `name` must be a relative path that stays inside
    /// the directory once every symbolic link is resolved.
    pub fn resolve(&self, name: &str) -> Result<Option<PathBuf>, ModelError> {
        if BUILTIN_NAMES.contains(&name) {
            return Ok(None);
        }
        let refuse = |why: String| ModelError::Parse {
            path: None,
            message: format!("robot {name:?}: {why}"),
        };
        let Some(dir) = &self.dir else {
            return Err(refuse(format!(
                "not a built-in robot ({}) and no robot directory is configured",
                BUILTIN_NAMES.join(", ")
            )));
        };
        let rel = Path::new(name);
        if name.is_empty() || !rel.components().all(|c| matches!(c, Component::Normal(_))) {
            return Err(refuse(
                "a robot file is named by a plain relative path inside the robot directory \
                 (no leading /, no ..)"
                    .into(),
            ));
        }
        // Not echoed: the reason must not tell a peer what exists outside.
        let full = dir
            .join(rel)
            .canonicalize()
            .map_err(|_| refuse("no such file in the robot directory".into()))?;
        if !full.starts_with(dir) {
            return Err(refuse("leads out of the robot directory".into()));
        }
        Ok(Some(full))
    }

    /// Loads the robot `name`: a built-in one, or a URDF file in the robot
    /// directory (a regular file of at most [`crate::urdf::MAX_URDF_BYTES`]).
    pub fn load(&self, name: &str) -> Result<Model, ModelError> {
        match self.resolve(name)? {
            None => builtin(name),
            Some(path) => Model::from_urdf_file(path, &LoadOptions::default()),
        }
    }
}
