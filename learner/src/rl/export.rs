//! A trained policy for the robot PC: a training checkpoint's chosen policy
//! converted into the node's deployed format ([`learner_node::deploy`]):
//! its network's layers, its observation normalisation's shift and scale,
//! the action scale, the peg, and for a representation policy the encoder's
//! weights as plain arrays. `learner policy export` writes it;
//! `learner run --policy` and `learner stack --policy` convert a
//! checkpoint.json the same way, so the node only ever reads the deployed
//! format.

use super::gaussian::GaussianPolicy;
use super::observe::ObservationKind;
use super::run::{RunError, read_checkpoint};
use crate::models::Encoder;
use hw_sim::PegShape;
use learner_node::deploy::{
    ActionScale, DeployError, DeployedPolicy, Deployment, ENCODER_FILE, FORMAT, LayerSpec,
    NormSpec, ObservationSpec, PolicyFile, VERSION,
};
use std::path::{Path, PathBuf};

/// Why a checkpoint could not be converted.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The checkpoint could not be read.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The deployed files could not be written or read back.
    #[error(transparent)]
    Deploy(#[from] DeployError),
    /// The representation the policy observes through did not load.
    #[error("{}: the representation {}: {detail}", checkpoint.display(), model.display())]
    Representation {
        /// The checkpoint.
        checkpoint: PathBuf,
        /// The representation's model directory.
        model: PathBuf,
        /// Why.
        detail: String,
    },
    /// A deployed policy was given where a training checkpoint's choice
    /// (`--last`) was asked for.
    #[error("{}: --last picks among a training checkpoint's policies; this is a deployed policy", .0.display())]
    LastOfDeployed(PathBuf),
    /// A policy whose observer the node does not have.
    #[error(
        "a policy on {0} has no deployed format (the node observes the ground truth or a representation's z)"
    )]
    NotDeployable(String),
}

/// The network's layers of `policy` (its flat parameters: per layer the
/// weights, outputs × inputs row-major, then the biases).
pub fn layers(policy: &GaussianPolicy) -> Vec<LayerSpec> {
    let mut off = 0;
    policy
        .sizes
        .windows(2)
        .map(|w| {
            let (inputs, outputs) = (w[0], w[1]);
            let weight = policy.net[off..off + inputs * outputs].to_vec();
            off += inputs * outputs;
            let bias = policy.net[off..off + outputs].to_vec();
            off += outputs;
            LayerSpec {
                inputs,
                outputs,
                weight,
                bias,
            }
        })
        .collect()
}

/// The policy file of `policy` observing `observation` (a representation's
/// weights file is [`ENCODER_FILE`] beside it); refuses an observer the
/// node does not have (the raw-input baseline).
pub fn policy_file(
    policy: &GaussianPolicy,
    observation: &ObservationKind,
    action_scale: ActionScale,
    peg: PegShape,
    source: String,
) -> Result<PolicyFile, ExportError> {
    // Before two observations the normalisation is the identity, unclipped.
    let obs_norm = policy.obs_norm.as_ref().filter(|n| n.count >= 2).map(|n| {
        let (shift, scale) = n.affine();
        NormSpec {
            shift,
            scale,
            clip: n.clip,
        }
    });
    let observation = match observation {
        ObservationKind::GroundTruth => ObservationSpec::GroundTruth,
        ObservationKind::GroundTruthHoleError(std_m) => {
            ObservationSpec::GroundTruthHoleError { std_m: *std_m }
        }
        ObservationKind::Representation(_) => ObservationSpec::Representation {
            encoder: ENCODER_FILE.into(),
        },
        ObservationKind::Raw(spec) => {
            return Err(ExportError::NotDeployable(format!(
                "raw inputs (observation.raw, side {})",
                spec.side
            )));
        }
    };
    Ok(PolicyFile {
        format: FORMAT.into(),
        version: VERSION,
        source,
        observation,
        obs_norm,
        layers: layers(policy),
        action_scale,
        peg,
    })
}

/// The deployment of `checkpoint`'s best validated or best logged policy,
/// or its last with `last` (as `policy eval` chooses), with its
/// representation's weights when it observes through one.
pub fn from_checkpoint(checkpoint: &Path, last: bool) -> Result<Deployment, ExportError> {
    let c = read_checkpoint(checkpoint)?;
    let chosen = c.chosen_policy(last);
    let source = format!("{chosen} of {}", checkpoint.display());
    let policy = policy_file(
        chosen.policy,
        &c.config.observation,
        c.config.env.action.clone(),
        c.config.env.world.task.peg,
        source,
    )?;
    let encoder = match &c.config.observation {
        ObservationKind::Representation(dir) => Some(
            Encoder::load(dir, &burn::prelude::Device::flex())
                .map_err(|e| ExportError::Representation {
                    checkpoint: checkpoint.to_path_buf(),
                    model: dir.clone(),
                    detail: e.to_string(),
                })?
                .to_file(),
        ),
        _ => None,
    };
    Ok(Deployment { policy, encoder })
}

/// The safetensors file of an exported policy, beside `policy.json`.
pub const SAFETENSORS_FILE: &str = "policy.safetensors";
/// Its observation/action spec, beside it.
pub const SPEC_FILE: &str = "policy-spec.json";

/// Writes `policy`'s network and normalisation as safetensors
/// ([`SAFETENSORS_FILE`]: F64 tensors `layers.{i}.weight` (outputs ×
/// inputs), `layers.{i}.bias`, `obs_norm.shift`, `obs_norm.scale`) and
/// [`SPEC_FILE`], what a user needs to act with them: the observation, the
/// normalisation's clip, the activations, the action's scale. Returns both
/// paths.
pub fn write_safetensors(policy: &PolicyFile, dir: &Path) -> std::io::Result<[PathBuf; 2]> {
    use crate::interop::safetensors::{Tensor, write_with_spec};
    let mut tensors = Vec::new();
    for (i, l) in policy.layers.iter().enumerate() {
        let w = &l.weight;
        tensors.push(Tensor::f64(
            format!("layers.{i}.weight"),
            &[l.outputs, l.inputs],
            w.clone(),
        ));
        tensors.push(Tensor::f64(
            format!("layers.{i}.bias"),
            &[l.outputs],
            l.bias.clone(),
        ));
    }
    if let Some(n) = &policy.obs_norm {
        tensors.push(Tensor::f64(
            "obs_norm.shift",
            &[n.shift.len()],
            n.shift.clone(),
        ));
        tensors.push(Tensor::f64(
            "obs_norm.scale",
            &[n.scale.len()],
            n.scale.clone(),
        ));
    }
    let spec = serde_json::json!({
        "format": "vision-touch policy, safetensors",
        "source": policy.source,
        "observation": policy.observation,
        "observation_dim": policy.layers.first().map_or(0, |l| l.inputs),
        "obs_norm_clip": policy.obs_norm.as_ref().map(|n| n.clip),
        "layers": policy.layers.len(),
        "activation": "tanh after every layer but the last, which is linear",
        "act": "o' = clip((o - obs_norm.shift) * obs_norm.scale, -clip, clip) when obs_norm \
                is present; mean = the MLP of o'; (dx, dy, dz) = clip(mean[0..3], -1, 1) * \
                action_scale.max_step_m in metres, droll = clip(mean[3], -1, 1) * \
                action_scale.max_roll_rad in radians",
        "action_scale": policy.action_scale,
        "peg": policy.peg,
        "tensors": tensors.iter().map(|t| (t.name.clone(), t.shape.clone())).collect::<Vec<_>>(),
    });
    write_with_spec(dir, SAFETENSORS_FILE, SPEC_FILE, &tensors, &spec)
}

/// Whether `path` is a deployed policy file (rather than a training
/// checkpoint).
pub fn is_deployed(path: &Path) -> Result<bool, ExportError> {
    let text = std::fs::read_to_string(path).map_err(|source| RunError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(PolicyFile::is_deployed(&text))
}

/// The policy the node acts with for `--policy path`: a deployed policy as
/// it is, a training checkpoint converted (its last policy with `last`).
pub fn load_for_node(path: &Path, last: bool) -> Result<DeployedPolicy, ExportError> {
    if is_deployed(path)? {
        if last {
            return Err(ExportError::LastOfDeployed(path.to_path_buf()));
        }
        return Ok(DeployedPolicy::load(path)?);
    }
    Ok(DeployedPolicy::new(from_checkpoint(path, last)?, path)?)
}

/// The deployed policy file for `--policy path` of a process the stack
/// starts: `path` itself when deployed, else the checkpoint converted into
/// `dir` (returns the written policy file).
pub fn file_for_node(path: &Path, last: bool, dir: &Path) -> Result<PathBuf, ExportError> {
    if is_deployed(path)? {
        if last {
            return Err(ExportError::LastOfDeployed(path.to_path_buf()));
        }
        return Ok(path.to_path_buf());
    }
    Ok(from_checkpoint(path, last)?.write(dir)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rl::observe::{GroundTruth, ObsView, Observer};
    use crate::rl::{ObsNorm, RlEnv};

    /// The deployed file's policy against the training policy, on the
    /// states of an episode: the same normalised mean, clipped and scaled.
    #[test]
    fn a_deployed_policy_acts_as_its_training_policy_on_its_normalised_observation() {
        let mut env = RlEnv::new(&Default::default()).unwrap();
        env.reset(5, false).unwrap();
        let mut rng = stack_common::rng::seeded(1, 0);
        let mut policy = GaussianPolicy::new(GroundTruth.dim(), &[8, 6], 4, 0.0, &mut rng);
        // Statistics far from the identity: every component shifted and
        // spread around values unlike these observations.
        let mut norm = ObsNorm::new(GroundTruth.dim(), 5.0);
        let seen: Vec<f64> = (0..4 * GroundTruth.dim())
            .map(|k| 0.3 * (k % 7) as f64 - 0.8)
            .collect();
        norm.update(&seen);
        policy.obs_norm = Some(norm.clone());
        for w in &mut policy.net {
            // The output layer starts small (pytorch-trpo's init): scaled up so
            // that some means fall beyond ±1 and the clip is tested.
            *w *= 10.0;
        }
        let scale = ActionScale::default();
        let file = policy_file(
            &policy,
            &ObservationKind::GroundTruth,
            scale.clone(),
            PegShape::Square,
            "test".into(),
        )
        .unwrap();
        let dir = test_support::scratch_dir("deploy-ground-truth");
        let path = Deployment {
            policy: file,
            encoder: None,
        }
        .write(dir.path())
        .unwrap();
        let p = DeployedPolicy::load(&path).unwrap();
        let mut clipped = 0;
        for step in 0..20 {
            let a = [0.3, -0.2, -0.5 + 0.05 * step as f64, 0.1];
            env.step(&a, false).unwrap();
            let view = env.view().unwrap();
            let mut obs = vec![0.0; GroundTruth.dim()];
            GroundTruth.observe(std::slice::from_ref(&view), &mut obs);
            let acted = p.act(&view);
            let trained = scale.to_delta(&policy.net_means(&norm.apply(&obs)));
            for (x, y) in acted.iter().zip(&trained) {
                assert!((x - y).abs() <= 1e-9, "{acted:?} against {trained:?}");
            }
            // The normalisation matters (before the clip, which may hide it).
            assert_ne!(policy.net_means(&norm.apply(&obs)), policy.net_means(&obs));
            clipped += policy.means(&obs).iter().filter(|m| m.abs() > 1.0).count();
        }
        assert!(clipped > 0, "some means beyond ±1 tested the clip");
        // A normaliser of another size than the network's input is refused,
        // the field and both sizes named.
        policy.obs_norm = Some({
            let mut n = ObsNorm::new(3, 5.0);
            n.update(&[0.0, 1.0, 2.0, 1.0, 0.0, 3.0]);
            n
        });
        let bad = Deployment {
            policy: policy_file(
                &policy,
                &ObservationKind::GroundTruth,
                scale,
                PegShape::Square,
                "test".into(),
            )
            .unwrap(),
            encoder: None,
        };
        let e = DeployedPolicy::new(bad, &path).unwrap_err().to_string();
        assert!(
            e.contains("obs_norm.shift has 3 values, expected 18"),
            "{e}"
        );
    }

    /// A representation policy deployed: an untrained Full Model's weights
    /// file read back by the node, its z means on the node's CPU path
    /// against burn's own encoding of the same network, and the policy's
    /// actions on them.
    #[test]
    fn a_deployed_representation_policy_acts_as_burns_encoding_of_its_model() {
        use crate::models::{ModelConfig, Normaliser, ReprNet, init};
        use learner_node::repr::Representation;
        let model = ModelConfig {
            latent_dim: 16,
            depth_convs_per_stage: 1,
            ..ModelConfig::default()
        };
        let dev = burn::prelude::Device::flex();
        let net = init::seeded(ReprNet::new(&model, &dev), 5);
        let mut normaliser = Normaliser::identity();
        normaliser.rgb_mean = [120.0, 110.0, 100.0];
        normaliser.rgb_std = [60.0, 50.0, 40.0];
        normaliser.depth_mean = 0.4;
        normaliser.depth_std = 0.1;
        normaliser.wrench_std = [5.0, 5.0, 5.0, 0.5, 0.5, 0.5];
        let enc = Encoder::new(net, model.clone(), normaliser, &dev);
        let file = enc.to_file();
        let reference = Representation::new(Box::new(enc.with_fast_path(false)));
        let mut rng = stack_common::rng::seeded(9, 0);
        let mut policy = GaussianPolicy::new(16, &[8], 4, 0.0, &mut rng);
        for w in &mut policy.net {
            *w *= 10.0; // actions that follow z
        }
        let scale = ActionScale::default();
        let dir = test_support::scratch_dir("deploy-representation");
        let path = Deployment {
            policy: policy_file(
                &policy,
                &ObservationKind::Representation("model".into()),
                scale.clone(),
                PegShape::Square,
                "test".into(),
            )
            .unwrap(),
            encoder: Some(file),
        }
        .write(dir.path())
        .unwrap();
        assert!(dir.path().join(ENCODER_FILE).is_file());
        let p = DeployedPolicy::load(&path).unwrap();
        assert!(p.needs_camera());
        let mut env = RlEnv::new(&Default::default()).unwrap();
        env.reset(3, false).unwrap();
        use shared_mem_schema::Message;
        let mut cam = shared_mem_schema::CameraFrame::boxed_zeroed();
        cam.calibration = hw_sim::config::CameraConfig::default().calibration();
        let (w, h) = (
            cam.calibration.width as usize,
            cam.calibration.height as usize,
        );
        assert_eq!(w, model.image_size);
        let mut moved = 0.0f64;
        let mut first: Option<[f64; 4]> = None;
        for step in 0..3 {
            env.step(&[0.5, -0.3, -0.4, 0.2], false).unwrap();
            for (i, v) in cam.rgb[..3 * w * h].iter_mut().enumerate() {
                *v = ((i * 7 + 31 * step) % 256) as u8;
            }
            for (i, v) in cam.depth_m[..w * h].iter_mut().enumerate() {
                *v = if i % 11 == 0 {
                    0.0
                } else {
                    0.3 + 0.001 * ((i + step) % 97) as f32
                };
            }
            let view = env.view().unwrap();
            let view = ObsView {
                camera: Some(&cam),
                ..view
            };
            let mut z = vec![0.0; 16];
            reference.observe(std::slice::from_ref(&view), &mut z);
            assert_eq!(reference.rejected(), 0);
            let want = scale.to_delta(&policy.means(&z));
            let got = p.act(&view);
            assert_eq!(p.rejected(), 0);
            let unit = [
                scale.max_step_m,
                scale.max_step_m,
                scale.max_step_m,
                scale.max_roll_rad,
            ];
            for k in 0..4 {
                let (a, b) = (got[k] / unit[k], want[k] / unit[k]);
                assert!((a - b).abs() <= 1e-5, "component {k}: {a} against {b}");
            }
            if let Some(f) = first {
                moved = moved.max((got[0] - f[0]).abs());
            }
            first.get_or_insert(got);
        }
        assert!(moved > 0.0, "the actions follow the scene");
    }
}
