//! The robot descriptions shipped with the crate, embedded so that any
//! process can load them without knowing where the repository lies.

use crate::{LoadOptions, Model, ModelError};

/// The KUKA LBR iiwa 14 (the paper's simulated robot), `urdf/iiwa14.urdf`.
pub const IIWA14_URDF: &str = include_str!("../urdf/iiwa14.urdf");
/// The Franka Emika Panda (the paper's real robot), `urdf/panda.urdf`.
pub const PANDA_URDF: &str = include_str!("../urdf/panda.urdf");

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: [&str; 2] = ["iiwa14", "panda"];

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
