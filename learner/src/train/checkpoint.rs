//! Checkpoints: the network's weights, Adam's state and where the loop
//! stands, written to a fresh directory and then renamed over the old one,
//! so that a run killed at any moment leaves a complete checkpoint behind.
//! The exported model (`model/`) is what inference loads: weights, the
//! model configuration and the normalisation it was trained with.

use super::metrics::{Metrics, Row};
use super::{Result, TrainError, io_err};
use crate::models::{ModelConfig, Normaliser, ReprNet};
use burn::module::Module;
use burn::optim::ModuleOptimizer;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Where the loop stands.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopState {
    /// Epochs finished.
    pub epoch: u32,
    /// Batches of the current epoch done (resume replays the loader past
    /// them, so the batches that follow are the ones an uninterrupted run
    /// would have drawn).
    pub batches_done: u64,
    /// Optimiser steps in all.
    pub steps: u64,
    /// The current epoch's training metrics so far.
    pub metrics: Metrics,
    /// Rows of the finished epochs.
    pub rows: Vec<Row>,
}

const MODEL: &str = "model.bpk";
const OPTIM: &str = "optim.bpk";
const STATE: &str = "state.json";

/// The checkpoint directory of a run in `out`.
pub fn dir(out: &Path) -> PathBuf {
    out.join("checkpoint")
}

fn record_err(path: &Path) -> impl FnOnce(burn::store::RecordError) -> TrainError + '_ {
    move |e| TrainError::Record {
        path: path.to_path_buf(),
        what: e.to_string(),
    }
}

/// Writes a checkpoint of `net`, `optim` and `state` into `out`.
pub fn save(out: &Path, net: &ReprNet, optim: &ModuleOptimizer, state: &LoopState) -> Result<()> {
    let fresh = out.join("checkpoint.new");
    if fresh.exists() {
        std::fs::remove_dir_all(&fresh).map_err(io_err(&fresh))?;
    }
    std::fs::create_dir_all(&fresh).map_err(io_err(&fresh))?;
    let m = fresh.join(MODEL);
    net.clone().save_file(&m).map_err(record_err(&m))?;
    let o = fresh.join(OPTIM);
    optim.save(&o).map_err(record_err(&o))?;
    let s = fresh.join(STATE);
    let json = serde_json::to_vec_pretty(state).expect("state serialises");
    std::fs::write(&s, json).map_err(io_err(&s))?;
    let target = dir(out);
    let old = out.join("checkpoint.old");
    if target.exists() {
        if old.exists() {
            std::fs::remove_dir_all(&old).map_err(io_err(&old))?;
        }
        std::fs::rename(&target, &old).map_err(io_err(&target))?;
    }
    std::fs::rename(&fresh, &target).map_err(io_err(&fresh))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(io_err(&old))?;
    }
    Ok(())
}

/// The checkpoint in `out`, if there is one: loaded into `net` and
/// `optim` (freshly made for the same configuration). A run killed between
/// the two renames of [`save`] left its last checkpoint as
/// `checkpoint.old`; that one is taken then.
pub fn load(
    out: &Path,
    net: ReprNet,
    optim: ModuleOptimizer,
) -> Result<Option<(ReprNet, ModuleOptimizer, LoopState)>> {
    let mut d = dir(out);
    if !d.exists() {
        d = out.join("checkpoint.old");
        if !d.exists() {
            return Ok(None);
        }
    }
    let s = d.join(STATE);
    let text = std::fs::read(&s).map_err(io_err(&s))?;
    let state: LoopState = serde_json::from_slice(&text).map_err(|e| TrainError::BadFile {
        path: s.clone(),
        what: e.to_string(),
    })?;
    let m = d.join(MODEL);
    let net = net.try_load_file(&m).map_err(record_err(&m))?;
    let o = d.join(OPTIM);
    let optim = optim.load(&o).map_err(record_err(&o))?;
    Ok(Some((net, optim, state)))
}

/// What `model/` holds besides the weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportMeta {
    /// The architecture.
    pub model: ModelConfig,
    /// The normalisation of the inputs.
    pub normaliser: Normaliser,
    /// The dataset it was trained on, for people.
    pub dataset: String,
    /// Epochs trained.
    pub epochs: u32,
    /// The camera of its training images (the dataset's; absent from models
    /// exported before it was kept, or trained on a dataset without it).
    /// The RL environment and the live node refuse another camera.
    #[serde(default)]
    pub camera: Option<shared_mem_schema::CameraCalibration>,
}

const EXPORT_META: &str = "model.json";

/// Writes the model for inference into `dir`.
pub fn export(dir: &Path, net: &ReprNet, meta: &ExportMeta) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let m = dir.join(MODEL);
    net.clone().save_file(&m).map_err(record_err(&m))?;
    let j = dir.join(EXPORT_META);
    let json = serde_json::to_vec_pretty(meta).expect("meta serialises");
    std::fs::write(&j, json).map_err(io_err(&j))
}

/// Reads and checks an exported model's `model.json` in `dir`, without its
/// weights.
pub fn read_meta(dir: &Path) -> Result<ExportMeta> {
    let j = dir.join(EXPORT_META);
    let text = std::fs::read(&j).map_err(io_err(&j))?;
    let bad = |what: String| TrainError::BadFile {
        path: j.clone(),
        what,
    };
    let meta: ExportMeta = serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))?;
    meta.model.validate().map_err(|e| bad(e.to_string()))?;
    meta.normaliser.validate().map_err(bad)?;
    Ok(meta)
}

/// Reads an exported model from `dir` onto `device`.
pub fn import(dir: &Path, device: &burn::prelude::Device) -> Result<(ReprNet, ExportMeta)> {
    let meta = read_meta(dir)?;
    let m = dir.join(MODEL);
    let net = ReprNet::new(&meta.model, device)
        .try_load_file(&m)
        .map_err(record_err(&m))?;
    Ok((net, meta))
}
