//! The deployed policy: a small self-contained file the node loads without
//! the training stack, and the action it computes.
//!
//! `policy.json` ([`PolicyFile`]) holds the format and its version, what
//! the policy observes ([`ObservationSpec`]: the ground truth, or a
//! representation whose weights file sits beside it, [`crate::repr::weights`]),
//! the observation normalisation it was trained under ([`NormSpec`]), its
//! network (the Gaussian's mean: tanh hidden layers, a linear output;
//! [`LayerSpec`]), the action scale and the peg it was trained on. The
//! training crate writes it from a training checkpoint (`learner policy
//! export`); the node acts with [`DeployedPolicy::act`]: the mean, clipped
//! to [−1, 1] and scaled, as the RL environment applied it.

use crate::observe::{CameraMismatch, GroundTruth, HoleError, ObsView, Observer};
use crate::policy::Action4;
use crate::repr::{DeployedEncoder, EncoderFile, Representation};
use hw_sim::{PegShape, WorldConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The value of [`PolicyFile::format`].
pub const FORMAT: &str = "learner-node/policy";

/// The format version this node reads and writes.
pub const VERSION: u32 = 1;

/// The file name of a deployed policy in its directory.
pub const POLICY_FILE: &str = "policy.json";

/// The file name of a representation's weights beside it.
pub const ENCODER_FILE: &str = "encoder.bin";

/// The scale of a policy action (docs/rl.md, "Actions").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActionScale {
    /// Position step of an action component of 1 (and the most), m.
    pub max_step_m: f64,
    /// Roll step of an action component of 1 (and the most), rad.
    pub max_roll_rad: f64,
}

impl Default for ActionScale {
    fn default() -> Self {
        Self {
            max_step_m: 0.0015,
            max_roll_rad: 0.05,
        }
    }
}

impl ActionScale {
    /// The controller's action for a policy output: each component clipped
    /// to [−1, 1] (a NaN to 0) and scaled.
    pub fn to_delta(&self, a: &[f64]) -> Action4 {
        let c = |x: f64| if x.is_nan() { 0.0 } else { x.clamp(-1.0, 1.0) };
        [
            c(a[0]) * self.max_step_m,
            c(a[1]) * self.max_step_m,
            c(a[2]) * self.max_step_m,
            c(a[3]) * self.max_roll_rad,
        ]
    }

    /// The policy output that asks for `delta` (clipped): the inverse of
    /// [`ActionScale::to_delta`], for scripted policies run through the env.
    pub fn from_delta(&self, delta: &Action4) -> [f64; 4] {
        [
            (delta[0] / self.max_step_m).clamp(-1.0, 1.0),
            (delta[1] / self.max_step_m).clamp(-1.0, 1.0),
            (delta[2] / self.max_step_m).clamp(-1.0, 1.0),
            (delta[3] / self.max_roll_rad).clamp(-1.0, 1.0),
        ]
    }
}

/// What a deployed policy observes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ObservationSpec {
    /// [`GroundTruth`]: the simulator's task state.
    GroundTruth,
    /// [`HoleError`]: the ground truth with the hole misplaced by this
    /// standard deviation per horizontal axis, m.
    GroundTruthHoleError {
        /// Standard deviation, m.
        std_m: f64,
    },
    /// A representation's z means; its weights file, relative to the
    /// policy file's directory.
    Representation {
        /// The weights file ([`ENCODER_FILE`]).
        encoder: PathBuf,
    },
}

/// The observation normalisation: component i maps to
/// `((o − shift[i]) · scale[i])` clipped to ±clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NormSpec {
    /// The training observations' mean per component.
    pub shift: Vec<f64>,
    /// 1 / (their standard deviation + 1e-8) per component.
    pub scale: Vec<f64>,
    /// The clip.
    pub clip: f64,
}

/// One layer of the mean's network: `y = W·x + b`, tanh on every layer but
/// the last.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerSpec {
    /// Inputs.
    pub inputs: usize,
    /// Outputs.
    pub outputs: usize,
    /// W, `outputs × inputs`, row-major.
    pub weight: Vec<f64>,
    /// b, `outputs`.
    pub bias: Vec<f64>,
}

/// The contents of `policy.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyFile {
    /// [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// Where it came from, for people (e.g. the checkpoint and which of its
    /// policies).
    #[serde(default)]
    pub source: String,
    /// What it observes.
    pub observation: ObservationSpec,
    /// The observation normalisation (`None`: the network sees the
    /// observations as they are).
    pub obs_norm: Option<NormSpec>,
    /// The network, input layer first.
    pub layers: Vec<LayerSpec>,
    /// The action's scale.
    pub action_scale: ActionScale,
    /// The peg it was trained on.
    pub peg: PegShape,
}

/// Why a deployed policy does not load; names the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Not JSON of this format.
    #[error("{}: {detail}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// A field of another size than the others ask for.
    #[error("{}: {field} has {found} values, expected {expected}", path.display())]
    Size {
        /// The file.
        path: PathBuf,
        /// The field.
        field: String,
        /// What the other fields ask for.
        expected: usize,
        /// What the file holds.
        found: usize,
    },
    /// The representation's weights file.
    #[error(transparent)]
    Encoder(#[from] crate::repr::weights::FileError),
    /// A world whose camera is not the representation's.
    #[error(transparent)]
    Camera(#[from] CameraMismatch),
}

/// A deployed policy with its encoder's contents, in memory (what the
/// files hold, before the node builds its observer).
#[derive(Debug, Clone, PartialEq)]
pub struct Deployment {
    /// policy.json.
    pub policy: PolicyFile,
    /// The representation's weights, for [`ObservationSpec::Representation`].
    pub encoder: Option<EncoderFile>,
}

impl Deployment {
    /// Writes `dir`/[`POLICY_FILE`] and, with a representation, its
    /// weights file beside it; returns the policy file's path.
    pub fn write(&self, dir: &Path) -> Result<PathBuf, DeployError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| DeployError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let mut policy = self.policy.clone();
        if let Some(e) = &self.encoder {
            let name = PathBuf::from(ENCODER_FILE);
            e.write(&dir.join(&name))?;
            policy.observation = ObservationSpec::Representation { encoder: name };
        }
        let path = dir.join(POLICY_FILE);
        let text = serde_json::to_string_pretty(&policy).expect("a policy serialises");
        std::fs::write(&path, text).map_err(io(&path))?;
        Ok(path)
    }

    /// Reads a policy file and, with a representation, its weights file.
    pub fn read(path: &Path) -> Result<Self, DeployError> {
        let text = std::fs::read_to_string(path).map_err(|source| DeployError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let policy = PolicyFile::parse(&text).map_err(|detail| DeployError::Format {
            path: path.to_path_buf(),
            detail,
        })?;
        let encoder = match &policy.observation {
            ObservationSpec::Representation { encoder } => {
                let dir = path.parent().unwrap_or(Path::new("."));
                Some(EncoderFile::read(&dir.join(encoder))?)
            }
            _ => None,
        };
        Ok(Self { policy, encoder })
    }
}

impl PolicyFile {
    /// Whether `text` claims to be a deployed policy (its `format` field
    /// says so), before anything else is checked.
    pub fn is_deployed(text: &str) -> bool {
        #[derive(Deserialize)]
        struct Probe {
            format: Option<String>,
        }
        serde_json::from_str::<Probe>(text).is_ok_and(|p| p.format.as_deref() == Some(FORMAT))
    }

    /// Parses `text`, checking the format and version first.
    pub fn parse(text: &str) -> Result<Self, String> {
        #[derive(Deserialize)]
        struct Probe {
            format: Option<String>,
            version: Option<u32>,
        }
        let probe: Probe = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
        match (probe.format.as_deref(), probe.version) {
            (Some(FORMAT), Some(VERSION)) => {}
            (Some(FORMAT), v) => {
                return Err(format!(
                    "format version {v:?}; this node reads version {VERSION}"
                ));
            }
            (f, _) => {
                return Err(format!(
                    "format {f:?} is not {FORMAT:?}: not a deployed policy (a training \
                     checkpoint is converted by `learner policy export`)"
                ));
            }
        }
        serde_json::from_str(text).map_err(|e| e.to_string())
    }
}

/// A deployed policy, ready to act.
pub struct DeployedPolicy {
    layers: Vec<LayerSpec>,
    norm: Option<NormSpec>,
    observer: Arc<dyn Observer>,
    scale: ActionScale,
    peg: PegShape,
    source: String,
}

impl std::fmt::Debug for DeployedPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeployedPolicy")
            .field("source", &self.source)
            .field("observation_dim", &self.observer.dim())
            .field("layers", &self.layers.len())
            .field("scale", &self.scale)
            .field("peg", &self.peg)
            .finish()
    }
}

impl DeployedPolicy {
    /// Loads a policy file (and its encoder's weights file).
    pub fn load(path: &Path) -> Result<Self, DeployError> {
        Self::new(Deployment::read(path)?, path)
    }

    /// From a deployment in memory; `path` names it in errors. Every size
    /// is checked: the network's layers against each other, its input
    /// against the observer's output and the normalisation, its output
    /// against the controller's 4 action components.
    pub fn new(d: Deployment, path: &Path) -> Result<Self, DeployError> {
        let p = d.policy;
        let size = |field: String, expected: usize, found: usize| {
            if expected == found {
                Ok(())
            } else {
                Err(DeployError::Size {
                    path: path.to_path_buf(),
                    field,
                    expected,
                    found,
                })
            }
        };
        let observer: Arc<dyn Observer> = match (&p.observation, d.encoder) {
            (ObservationSpec::GroundTruth, _) => Arc::new(GroundTruth),
            (ObservationSpec::GroundTruthHoleError { std_m }, _) => {
                if !(std_m.is_finite() && *std_m >= 0.0) {
                    return Err(DeployError::Format {
                        path: path.to_path_buf(),
                        detail: format!(
                            "observation.ground_truth_hole_error.std_m {std_m}: must be 0 or more"
                        ),
                    });
                }
                Arc::new(HoleError { std_m: *std_m })
            }
            (ObservationSpec::Representation { encoder }, Some(e)) => {
                let e = DeployedEncoder::new(e).map_err(|e| crate::repr::weights::FileError {
                    path: encoder.clone(),
                    kind: e.into(),
                })?;
                Arc::new(Representation::new(Box::new(e)))
            }
            (ObservationSpec::Representation { encoder }, None) => {
                return Err(DeployError::Format {
                    path: path.to_path_buf(),
                    detail: format!("the encoder {} is not loaded", encoder.display()),
                });
            }
        };
        if p.layers.is_empty() {
            size("layers".into(), 1, 0)?;
        }
        let mut n = observer.dim();
        for (i, l) in p.layers.iter().enumerate() {
            size(format!("layers[{i}].inputs"), n, l.inputs)?;
            // A damaged file's sizes may not even multiply.
            let weights = l
                .inputs
                .checked_mul(l.outputs)
                .ok_or_else(|| DeployError::Format {
                    path: path.to_path_buf(),
                    detail: format!(
                        "layers[{i}]: {} inputs × {} outputs is more weights than can exist",
                        l.inputs, l.outputs
                    ),
                })?;
            size(format!("layers[{i}].weight"), weights, l.weight.len())?;
            size(format!("layers[{i}].bias"), l.outputs, l.bias.len())?;
            n = l.outputs;
        }
        size(format!("layers[{}].outputs", p.layers.len() - 1), 4, n)?;
        if let Some(norm) = &p.obs_norm {
            size("obs_norm.shift".into(), observer.dim(), norm.shift.len())?;
            size("obs_norm.scale".into(), observer.dim(), norm.scale.len())?;
        }
        // `f64::clamp` panics on a negative or NaN bound.
        let mut positive = vec![
            ("action_scale.max_step_m", p.action_scale.max_step_m),
            ("action_scale.max_roll_rad", p.action_scale.max_roll_rad),
        ];
        if let Some(norm) = &p.obs_norm {
            positive.push(("obs_norm.clip", norm.clip));
        }
        if let Some((field, v)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return Err(DeployError::Format {
                path: path.to_path_buf(),
                detail: format!("{field} is {v}: must be a positive number"),
            });
        }
        // JSON cannot spell NaN, but a deployment built in memory (from a
        // checkpoint) can hold one: it would turn every action into 0.
        let mut fields: Vec<(String, &[f64])> = Vec::new();
        for (i, l) in p.layers.iter().enumerate() {
            fields.push((format!("layers[{i}].weight"), &l.weight));
            fields.push((format!("layers[{i}].bias"), &l.bias));
        }
        if let Some(norm) = &p.obs_norm {
            fields.push(("obs_norm.shift".into(), &norm.shift));
            fields.push(("obs_norm.scale".into(), &norm.scale));
        }
        for (field, values) in fields {
            if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                return Err(DeployError::Format {
                    path: path.to_path_buf(),
                    detail: format!("{field}[{k}] is {}, not a finite number", values[k]),
                });
            }
        }
        Ok(Self {
            layers: p.layers,
            norm: p.obs_norm,
            observer,
            scale: p.action_scale,
            peg: p.peg,
            source: p.source,
        })
    }

    /// Where it came from (the file's `source`).
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Refuses a world whose camera is not the one the policy's
    /// representation was trained with (its z would describe another
    /// scene).
    pub fn check_world(&self, world: &WorldConfig) -> Result<(), DeployError> {
        Ok(crate::observe::check_calibration(
            &world.camera,
            self.observer.camera(),
        )?)
    }

    /// Whether the observer reads the camera.
    pub fn needs_camera(&self) -> bool {
        self.observer.needs_camera()
    }

    /// Observations the observer could not make and gave as zeros so far
    /// (a camera frame missing or of another size, a value not finite).
    pub fn rejected(&self) -> u64 {
        self.observer.rejected()
    }

    /// The peg it was trained on.
    pub fn trained_peg(&self) -> PegShape {
        self.peg
    }

    /// The network's mean for one observation (before the action's clip
    /// and scale).
    pub fn means(&self, obs: &[f64]) -> Vec<f64> {
        let mut x: Vec<f64> = match &self.norm {
            Some(n) => obs
                .iter()
                .zip(n.shift.iter().zip(&n.scale))
                .map(|(o, (m, s))| ((o - m) * s).clamp(-n.clip, n.clip))
                .collect(),
            None => obs.to_vec(),
        };
        let last = self.layers.len() - 1;
        for (l, layer) in self.layers.iter().enumerate() {
            x = (0..layer.outputs)
                .map(|k| {
                    let row = &layer.weight[k * layer.inputs..][..layer.inputs];
                    let mut acc = layer.bias[k];
                    for (w, v) in row.iter().zip(&x) {
                        acc += w * v;
                    }
                    if l < last { acc.tanh() } else { acc }
                })
                .collect();
        }
        x
    }

    /// The action for one state: the mean, clipped to [−1, 1] and scaled.
    pub fn act(&self, view: &ObsView<'_>) -> Action4 {
        let mut obs = vec![0.0; self.observer.dim()];
        self.observer.observe(std::slice::from_ref(view), &mut obs);
        self.scale.to_delta(&self.means(&obs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::repr::fast::{Dense, EncoderWeights};
    use crate::repr::{Modalities, Normaliser};

    fn layer(inputs: usize, outputs: usize) -> LayerSpec {
        LayerSpec {
            inputs,
            outputs,
            weight: (0..inputs * outputs).map(|k| 0.01 * k as f64).collect(),
            bias: vec![0.1; outputs],
        }
    }

    fn ground_truth_policy() -> PolicyFile {
        PolicyFile {
            format: FORMAT.into(),
            version: VERSION,
            source: "test".into(),
            observation: ObservationSpec::GroundTruth,
            obs_norm: None,
            layers: vec![layer(18, 8), layer(8, 4)],
            action_scale: ActionScale::default(),
            peg: PegShape::Square,
        }
    }

    /// A representation of proprioception alone, d = 2.
    fn proprio_encoder() -> EncoderFile {
        EncoderFile {
            weights: EncoderWeights {
                latent_dim: 2,
                image_side: 4,
                leaky_slope: 0.1,
                min_variance: 1e-4,
                rgb: None,
                depth: None,
                haptics: None,
                proprio: Some(vec![Dense {
                    w: (0..32).map(|k| 0.05 * k as f32 - 0.7).collect(),
                    b: vec![0.1, -0.1, 0.2, 0.0],
                    n_in: 8,
                    n_out: 4,
                }]),
                concat: None,
            },
            modalities: Modalities::ALL,
            normaliser: Normaliser::identity(),
            camera: None,
        }
    }

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_malformed_policy_file_is_refused_naming_the_file_and_the_field() {
        let dir = test_support::scratch_dir("deploy-malformed");
        let good = Deployment {
            policy: ground_truth_policy(),
            encoder: None,
        }
        .write(dir.path())
        .unwrap();
        let p = DeployedPolicy::load(&good).unwrap();
        assert_eq!(p.means(&[0.5; 18]).len(), 4);
        // A weight of another size than its layer's.
        let mut f = ground_truth_policy();
        f.layers[1].weight.pop();
        let bad = write(
            dir.path(),
            "short.json",
            &serde_json::to_string(&f).unwrap(),
        );
        let e = DeployedPolicy::load(&bad).unwrap_err().to_string();
        assert!(e.contains("short.json"), "{e}");
        assert!(
            e.contains("layers[1].weight has 31 values, expected 32"),
            "{e}"
        );
        // A network whose input is not the observation's.
        let mut f = ground_truth_policy();
        f.layers[0] = layer(17, 8);
        let bad = write(
            dir.path(),
            "input.json",
            &serde_json::to_string(&f).unwrap(),
        );
        let e = DeployedPolicy::load(&bad).unwrap_err().to_string();
        assert!(
            e.contains("layers[0].inputs has 17 values, expected 18"),
            "{e}"
        );
        // Not four actions.
        let mut f = ground_truth_policy();
        f.layers[1] = layer(8, 3);
        let bad = write(
            dir.path(),
            "actions.json",
            &serde_json::to_string(&f).unwrap(),
        );
        let e = DeployedPolicy::load(&bad).unwrap_err().to_string();
        assert!(
            e.contains("layers[1].outputs has 3 values, expected 4"),
            "{e}"
        );
        // Sizes whose product overflows (found by fuzz_readers.rs): refused,
        // not a panic.
        let mut f = ground_truth_policy();
        f.layers[0].outputs = usize::MAX / 4;
        let bad = write(dir.path(), "huge.json", &serde_json::to_string(&f).unwrap());
        let e = DeployedPolicy::load(&bad).unwrap_err().to_string();
        assert!(
            e.contains("huge.json") && e.contains("more weights than can exist"),
            "{e}"
        );
        // Cut short, another format, another version.
        let text = std::fs::read_to_string(&good).unwrap();
        let cut = write(dir.path(), "cut.json", &text[..text.len() / 2]);
        let e = DeployedPolicy::load(&cut).unwrap_err().to_string();
        assert!(e.contains("cut.json") && e.contains("not JSON"), "{e}");
        let other = write(dir.path(), "ckpt.json", r#"{"config": {}, "state": {}}"#);
        let e = DeployedPolicy::load(&other).unwrap_err().to_string();
        assert!(e.contains("not a deployed policy"), "{e}");
        assert!(!PolicyFile::is_deployed(r#"{"config": {}}"#));
        assert!(PolicyFile::is_deployed(&text));
        let v2 = write(
            dir.path(),
            "v2.json",
            &text.replace("\"version\": 1", "\"version\": 2"),
        );
        let e = DeployedPolicy::load(&v2).unwrap_err().to_string();
        assert!(e.contains("version Some(2)"), "{e}");
        // A field this version does not know.
        let extra = write(
            dir.path(),
            "extra.json",
            &text.replacen('{', "{\"temperature\": 1,", 1),
        );
        let e = DeployedPolicy::load(&extra).unwrap_err().to_string();
        assert!(e.contains("temperature"), "{e}");
        // A value that is not a number, from a checkpoint in memory.
        let mut f = ground_truth_policy();
        f.layers[1].bias[2] = f64::NAN;
        let d = Deployment {
            policy: f,
            encoder: None,
        };
        let Err(e) = DeployedPolicy::new(d, Path::new("nan.json")) else {
            panic!("a NaN bias was accepted");
        };
        let e = e.to_string();
        assert!(
            e.contains("nan.json") && e.contains("layers[1].bias[2] is NaN"),
            "{e}"
        );
        // A negative clip would make the first action panic in `clamp`.
        let mut f = ground_truth_policy();
        f.obs_norm = Some(NormSpec {
            shift: vec![0.0; 18],
            scale: vec![1.0; 18],
            clip: -1.0,
        });
        let bad = write(dir.path(), "clip.json", &serde_json::to_string(&f).unwrap());
        let e = DeployedPolicy::load(&bad).unwrap_err().to_string();
        assert!(
            e.contains("obs_norm.clip is -1: must be a positive number"),
            "{e}"
        );
    }

    #[test]
    fn an_encoder_file_round_trips_and_a_truncated_or_misshapen_one_is_refused() {
        let dir = test_support::scratch_dir("deploy-encoder");
        let mut policy = ground_truth_policy();
        policy.layers[0] = layer(2, 8);
        let d = Deployment {
            policy,
            encoder: Some(proprio_encoder()),
        };
        let path = d.write(dir.path()).unwrap();
        let back = Deployment::read(&path).unwrap();
        assert_eq!(back.encoder, d.encoder, "bit-exact");
        let p = DeployedPolicy::new(back, &path).unwrap();
        assert!(p.needs_camera());
        // Truncated: the file and both sizes named.
        let enc = dir.path().join(ENCODER_FILE);
        let bytes = std::fs::read(&enc).unwrap();
        std::fs::write(&enc, &bytes[..bytes.len() - 6]).unwrap();
        let e = DeployedPolicy::load(&path).unwrap_err().to_string();
        assert!(e.contains(ENCODER_FILE), "{e}");
        assert!(
            e.contains("the header's arrays take 144 bytes of values, the file holds 138"),
            "{e}"
        );
        // A layer of another input size than proprioception's 8 values.
        let mut bad = proprio_encoder();
        let l = &mut bad.weights.proprio.as_mut().unwrap()[0];
        l.n_in = 7;
        l.w.truncate(28);
        bad.write(&enc).unwrap();
        let e = DeployedPolicy::load(&path).unwrap_err().to_string();
        assert!(
            e.contains("proprio.layer0.weight: shape [7, 4], expected [8, 4]"),
            "{e}"
        );
        // Not a weights file at all.
        std::fs::write(&enc, b"{\"weights\": []}").unwrap();
        let e = DeployedPolicy::load(&path).unwrap_err().to_string();
        assert!(e.contains("not an encoder weights file"), "{e}");
    }
}
