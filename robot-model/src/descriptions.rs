//! The robot descriptions shipped with the crate, embedded so that any
//! process can load them without knowing where the repository lies.

use crate::{LoadOptions, Model, ModelError};

/// The KUKA LBR iiwa 14 (the paper's simulated robot), `urdf/iiwa14.urdf`.
pub const IIWA14_URDF: &str = include_str!("../urdf/iiwa14.urdf");
/// The Franka Emika Panda (the paper's real robot), `urdf/panda.urdf`.
pub const PANDA_URDF: &str = include_str!("../urdf/panda.urdf");

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

/// A start pose of the iiwa 14 (ours): the peg tip at (0.590, 0, 0.353) m
/// pointing down.
pub const IIWA14_HOME_Q: [f64; 7] = [0.0, 0.5, 0.0, -1.4, 0.0, 1.2, 0.0];

/// The start pose of a built-in robot, by its URDF robot name.
pub fn home_configuration(robot_name: &str) -> Option<[f64; 7]> {
    match robot_name {
        "panda" => Some(PANDA_READY_Q),
        "iiwa14" => Some(IIWA14_HOME_Q),
        _ => None,
    }
}

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: [&str; 2] = ["iiwa14", "panda"];

/// Loads a robot named in a configuration: a built-in name
/// ([`BUILTIN_NAMES`]) or else the path of a URDF file.
pub fn load(name_or_path: &str) -> Result<Model, ModelError> {
    if BUILTIN_NAMES.contains(&name_or_path) {
        builtin(name_or_path)
    } else {
        Model::from_urdf_file(name_or_path, &LoadOptions::default())
    }
}

/// Loads a built-in description by name (`"iiwa14"` or `"panda"`).
pub fn builtin(name: &str) -> Result<Model, ModelError> {
    let text = match name {
        "iiwa14" => IIWA14_URDF,
        "panda" => PANDA_URDF,
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
