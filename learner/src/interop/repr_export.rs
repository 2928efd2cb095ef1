//! `learner repr export`: a trained representation as safetensors for
//! other tools. The tensors are named as the PyTorch twin's `state_dict`
//! ([`crate::models::named`]); a spec beside them (also in the file's
//! metadata) holds the architecture, the input normalisation and what the
//! encoder computes, so a Python user can build the model, load the weights
//! and feed it observations as we do (docs/representation.md).

use super::safetensors::{Tensor, write_with_spec};
use crate::models::named::torch_named;
use crate::models::{ModelConfig, Normaliser, ReprNet};
use std::path::{Path, PathBuf};

/// The weights file `learner repr export` writes.
pub const SAFETENSORS_FILE: &str = "representation.safetensors";
/// Its spec, beside it.
pub const SPEC_FILE: &str = "representation-spec.json";
/// The spec's format line.
pub const FORMAT: &str = "vision-touch representation, safetensors";

/// The spec of a network built for `model` whose parameters are `tensors`,
/// its inputs normalised by `normaliser`; `source` says where it came from.
pub fn spec(
    model: &ModelConfig,
    normaliser: &Normaliser,
    source: &str,
    tensors: &[Tensor],
) -> serde_json::Value {
    serde_json::json!({
        "format": FORMAT,
        "source": source,
        "model": model,
        "normaliser": normaliser,
        "pytorch_twin": "bench-anchors/torch-repr/bench.py: Full(d=model.latent_dim, \
                         side=model.image_size, per_stage=model.depth_convs_per_stage) for \
                         model.kind = full with every modality; load_state_dict(strict=True)",
        "inputs": {
            "rgb": "[B, 3, S, S] float32: (pixel 0..255 - rgb_mean[c]) / rgb_std[c]",
            "depth": "[B, 1, S, S] float32: (depth m - depth_mean) / depth_std for pixels with \
                      a return, 0 where there is none",
            "wrench": "[B, 6, 32] float32: the last 32 wrist readings (newest last), \
                       (w[k] - wrench_mean[k]) / wrench_std[k], components fx fy fz tx ty tz",
            "proprio": "[B, 8] float32: (p - proprio_mean) / proprio_std, the paper's 8 values",
            "action": "[B, 4] float32: (a - action_mean) / action_std (decoders only)",
        },
        "z": "each encoder gives 2d values, a Gaussian (mean: the first d; variance: \
              softplus(the last d) + 1e-4); z's mean is the product of these experts and a \
              standard-normal prior: var = 1 / (1 + sum 1/var_i), mean = var * sum mean_i/var_i. \
              Leaky ReLU slope 0.1 everywhere",
        "tensors": tensors.iter().map(|t| (t.name.clone(), t.shape.clone())).collect::<Vec<_>>(),
    })
}

/// Writes `net` (built for `model`) as [`SAFETENSORS_FILE`] and
/// [`SPEC_FILE`] into `dir`; `source` says where it came from. Returns
/// both paths.
pub fn write_representation(
    net: &ReprNet,
    model: &ModelConfig,
    normaliser: &Normaliser,
    source: &str,
    dir: &Path,
) -> std::io::Result<[PathBuf; 2]> {
    std::fs::create_dir_all(dir)?;
    let tensors: Vec<Tensor> = torch_named(net)
        .into_iter()
        .map(|t| Tensor::f32(t.name, &t.shape, t.values))
        .collect();
    let spec = spec(model, normaliser, source, &tensors);
    write_with_spec(dir, SAFETENSORS_FILE, SPEC_FILE, &tensors, &spec)
}

/// Exports the model `learner repr train` wrote into `model_dir` (a run's
/// `model/`) into `out`.
pub fn export_model_dir(model_dir: &Path, out: &Path) -> anyhow::Result<[PathBuf; 2]> {
    use anyhow::Context;
    let (net, meta) =
        crate::train::checkpoint::import(model_dir, &burn::prelude::Device::flex())
            .with_context(|| format!("loading the representation in {}", model_dir.display()))?;
    let source = format!(
        "{} ({} epochs on {})",
        model_dir.display(),
        meta.epochs,
        meta.dataset
    );
    write_representation(&net, &meta.model, &meta.normaliser, &source, out)
        .with_context(|| format!("writing the safetensors export into {}", out.display()))
}
