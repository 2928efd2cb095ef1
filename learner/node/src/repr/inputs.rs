//! From observations to the model's input arrays: channel-first,
//! normalised with the dataset's statistics as the model was trained. Plain
//! `f32` vectors, no tensors: the same arrays feed training, evaluation and
//! inference, and can be checked without a backend.

use crate::policy::WRENCH_WINDOW;
use crate::proprio::PROPRIO;
use serde::{Deserialize, Serialize};

/// Mean and standard deviation of every input, taken from a dataset's
/// statistics and exported with a trained model, so that inference
/// normalises exactly as training did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normaliser {
    /// RGB channel means, 0..255.
    pub rgb_mean: [f32; 3],
    /// RGB channel standard deviations, 0..255.
    pub rgb_std: [f32; 3],
    /// Depth of pixels with a return, m.
    pub depth_mean: f32,
    /// Its standard deviation, m.
    pub depth_std: f32,
    /// Wrench components (fx, fy, fz, tx, ty, tz).
    pub wrench_mean: [f32; 6],
    /// Their standard deviations.
    pub wrench_std: [f32; 6],
    /// Proprioception.
    pub proprio_mean: [f32; PROPRIO],
    /// Its standard deviations.
    pub proprio_std: [f32; PROPRIO],
    /// Actions.
    pub action_mean: [f32; 4],
    /// Their standard deviations.
    pub action_std: [f32; 4],
    /// Next end-effector position minus the current one, m.
    pub ee_delta_mean: [f32; 3],
    /// Its standard deviations, m.
    pub ee_delta_std: [f32; 3],
}

impl Normaliser {
    /// Means 0 and deviations 1: inputs pass unchanged. For benchmarks and
    /// tests of a model that no dataset has normalised.
    pub fn identity() -> Self {
        Self {
            rgb_mean: [0.0; 3],
            rgb_std: [1.0; 3],
            depth_mean: 0.0,
            depth_std: 1.0,
            wrench_mean: [0.0; 6],
            wrench_std: [1.0; 6],
            proprio_mean: [0.0; PROPRIO],
            proprio_std: [1.0; PROPRIO],
            action_mean: [0.0; 4],
            action_std: [1.0; 4],
            ee_delta_mean: [0.0; 3],
            ee_delta_std: [1.0; 3],
        }
    }

    /// Checks every constant is finite and every deviation positive,
    /// naming the input at fault.
    pub fn validate(&self) -> Result<(), String> {
        let groups: [(&str, &[f32], &[f32]); 6] = [
            ("rgb", &self.rgb_mean, &self.rgb_std),
            (
                "depth",
                std::slice::from_ref(&self.depth_mean),
                std::slice::from_ref(&self.depth_std),
            ),
            ("wrench", &self.wrench_mean, &self.wrench_std),
            ("proprio", &self.proprio_mean, &self.proprio_std),
            ("action", &self.action_mean, &self.action_std),
            ("ee_delta", &self.ee_delta_mean, &self.ee_delta_std),
        ];
        for (name, means, stds) in groups {
            if means.iter().any(|x| !x.is_finite()) {
                return Err(format!("normaliser: a mean of {name} is not finite"));
            }
            if stds.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
                return Err(format!(
                    "normaliser: a standard deviation of {name} is not finite and positive"
                ));
            }
        }
        Ok(())
    }
}

/// One observation as the encoders take it (borrowed, so the live node and
/// the RL environment need not copy it into a dataset sample).
#[derive(Debug, Clone, Copy)]
pub struct ObservationRef<'a> {
    /// RGB, H×W×3.
    pub rgb: &'a [u8],
    /// Depth, m, H×W (0: no return).
    pub depth: &'a [f32],
    /// Wrench window, oldest first, 32×6.
    pub wrench: &'a [f32],
    /// Proprioception.
    pub proprio: &'a [f32; PROPRIO],
}

/// A batch of normalised inputs, channel-first, sample-major.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InputArrays {
    /// Samples.
    pub batch: usize,
    /// Image side, px.
    pub side: usize,
    /// B×3×S×S.
    pub rgb: Vec<f32>,
    /// B×1×S×S (a pixel without a return is 0, the mean).
    pub depth: Vec<f32>,
    /// B×6×32 (channels: the wrench components; time oldest first).
    pub wrench: Vec<f32>,
    /// B×8.
    pub proprio: Vec<f32>,
}

/// Errors of a sample that does not fit the model.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum InputError {
    /// An image of another size.
    #[error("observation {index}: {what} has {got} values, the model takes {want}")]
    Size {
        /// Position in the batch.
        index: usize,
        /// Which array.
        what: &'static str,
        /// Values given.
        got: usize,
        /// Values expected.
        want: usize,
    },
    /// A NaN or infinite input.
    #[error("observation {index}: {what} holds a value that is not finite")]
    NotFinite {
        /// Position in the batch.
        index: usize,
        /// Which array.
        what: &'static str,
    },
}

impl Normaliser {
    /// The normalised inputs of `obs`, each `side`×`side`.
    pub fn inputs(
        &self,
        obs: &[ObservationRef<'_>],
        side: usize,
    ) -> Result<InputArrays, InputError> {
        let n = side * side;
        let b = obs.len();
        let mut out = InputArrays {
            batch: b,
            side,
            rgb: Vec::with_capacity(b * 3 * n),
            depth: Vec::with_capacity(b * n),
            wrench: Vec::with_capacity(b * 6 * WRENCH_WINDOW),
            proprio: Vec::with_capacity(b * PROPRIO),
        };
        for (index, o) in obs.iter().enumerate() {
            let check = |what, got: usize, want| {
                if got == want {
                    Ok(())
                } else {
                    Err(InputError::Size {
                        index,
                        what,
                        got,
                        want,
                    })
                }
            };
            check("rgb", o.rgb.len(), 3 * n)?;
            check("depth", o.depth.len(), n)?;
            check("wrench", o.wrench.len(), 6 * WRENCH_WINDOW)?;
            let finite = |what, xs: &[f32]| {
                if xs.iter().all(|x| x.is_finite()) {
                    Ok(())
                } else {
                    Err(InputError::NotFinite { index, what })
                }
            };
            finite("depth", o.depth)?;
            finite("wrench", o.wrench)?;
            finite("proprio", o.proprio)?;
            for c in 0..3 {
                let (m, s) = (self.rgb_mean[c], self.rgb_std[c]);
                out.rgb
                    .extend(o.rgb[c..].iter().step_by(3).map(|&v| (v as f32 - m) / s));
            }
            out.depth.extend(o.depth.iter().map(|&d| {
                if d > 0.0 {
                    (d - self.depth_mean) / self.depth_std
                } else {
                    0.0
                }
            }));
            for c in 0..6 {
                let (m, s) = (self.wrench_mean[c], self.wrench_std[c]);
                out.wrench
                    .extend(o.wrench[c..].iter().step_by(6).map(|&v| (v - m) / s));
            }
            out.proprio.extend(
                o.proprio
                    .iter()
                    .zip(self.proprio_mean.iter().zip(&self.proprio_std))
                    .map(|(&v, (m, s))| (v - m) / s),
            );
        }
        Ok(out)
    }
}
