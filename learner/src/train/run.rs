//! The training loop of `learner repr train`.

use super::checkpoint::{self, ExportMeta, LoopState};
use super::metrics::{CSV_HEADER, Metrics, Row, write_curves};
use super::{DeviceKind, ReprTrainConfig, Result, Split, TrainError, io_err};
use crate::dataset::{Batch, Dataset, Loader, LoaderConfig};
use crate::models::losses::{LabelTensors, losses};
use crate::models::net::tensor;
use crate::models::{
    EeTarget, InputTensors, Modalities, ModelKind, Normaliser, ObservationRef, ReprNet,
};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use learner_node::policy::WRENCH_WINDOW;
use stack_common::rng;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// How a run is started.
#[derive(Debug, Clone, Default)]
pub struct TrainOptions {
    /// Continue from the checkpoint in the output directory.
    pub resume: bool,
    /// Where the tensors live.
    pub device: DeviceKind,
    /// Stop (with a checkpoint) after this many optimiser steps of this
    /// invocation: an interruption at a known point, for tests.
    pub stop_after_steps: Option<u64>,
    /// Show a progress bar.
    pub progress: bool,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct TrainSummary {
    /// Every epoch's train and test rows.
    pub rows: Vec<Row>,
    /// Optimiser steps in all (earlier invocations included).
    pub steps: u64,
    /// Whether it ran to its last epoch (false: stopped, checkpointed).
    pub finished: bool,
    /// Training samples per second of this invocation.
    pub samples_per_s: f64,
    /// The exported model's directory (when finished).
    pub model_dir: PathBuf,
}

/// Names of the files a run writes in its output directory.
pub mod files {
    /// The effective configuration.
    pub const CONFIG: &str = "config.toml";
    /// The split by episode.
    pub const SPLIT: &str = "split.json";
    /// Per-epoch metrics.
    pub const METRICS: &str = "metrics.csv";
    /// The exported model.
    pub const MODEL_DIR: &str = "model";
}

/// The network, its optimiser and the loop's state, fresh or resumed.
type Trainee = (ReprNet, ModuleOptimizer, LoopState);

fn start(cfg: &ReprTrainConfig, out: &Path, resume: bool, device: &Device) -> Result<Trainee> {
    let net = crate::models::init::seeded(ReprNet::new(&cfg.model, device), cfg.train.seed);
    let optim = AdamConfig::new()
        .with_beta_1(cfg.train.beta1 as f32)
        .with_beta_2(cfg.train.beta2 as f32)
        // PyTorch's and the paper's Adam (burn's default is 1e-5).
        .with_epsilon(1e-8)
        .init();
    let cfg_path = out.join(files::CONFIG);
    let text = toml::to_string(cfg).expect("the configuration serialises");
    if resume {
        // The same run, but for its length: a resume may extend it.
        let mut before = ReprTrainConfig::from_file(&cfg_path)?;
        before.train.epochs = cfg.train.epochs;
        if &before != cfg {
            return Err(TrainError::BadFile {
                path: cfg_path,
                what: "the run was started with another configuration; resume it with that one \
                       (only train.epochs may change) or train into a new directory"
                    .into(),
            });
        }
        std::fs::write(&cfg_path, text).map_err(io_err(&cfg_path))?;
        if let Some(t) = checkpoint::load(out, net, optim)? {
            return Ok(t);
        }
        return Err(TrainError::BadFile {
            path: checkpoint::dir(out),
            what: "no checkpoint to resume from".into(),
        });
    }
    if checkpoint::dir(out).exists() || out.join("checkpoint.old").exists() {
        return Err(TrainError::BadFile {
            path: checkpoint::dir(out),
            what: "a run is already here: pass --resume to continue it, or choose another --out"
                .into(),
        });
    }
    std::fs::write(&cfg_path, text).map_err(io_err(&cfg_path))?;
    Ok((net, optim, LoopState::default()))
}

/// Checks the dataset against the model.
fn check_dataset(cfg: &ReprTrainConfig, ds: &Dataset) -> Result<()> {
    let m = &ds.meta;
    let s = cfg.model.image_size;
    if m.width != s || m.height != s {
        return Err(TrainError::Mismatch(format!(
            "the dataset's images are {}×{} px; model.image_size is {s}",
            m.width, m.height
        )));
    }
    if m.wrench_window != WRENCH_WINDOW {
        return Err(TrainError::Mismatch(format!(
            "the dataset's wrench window is {} readings; the model takes {WRENCH_WINDOW}",
            m.wrench_window
        )));
    }
    Ok(())
}

/// One batch prepared for the network.
pub(crate) struct Prepared {
    pub x: InputTensors,
    pub y: LabelTensors,
    pub paired: Vec<f32>,
    pub contact_next: Vec<f32>,
    pub zero_flow_epe: Vec<f32>,
}

/// Normalises `b` and uploads it to `device` (with the end-effector target
/// `ee`, and the RGB reconstruction target when `with_rgb01`).
pub(crate) fn prepare(
    b: &Batch,
    norm: &Normaliser,
    side: usize,
    ee: EeTarget,
    with_rgb01: bool,
    device: &Device,
) -> Result<Prepared> {
    let obs: Vec<ObservationRef<'_>> = b.samples.iter().map(ObservationRef::from).collect();
    let inputs = norm.inputs(&obs, side)?;
    let labels = crate::models::inputs::labels(norm, &b.samples, &b.paired, side, ee, with_rgb01);
    let n = side * side;
    let zero_flow_epe = labels
        .flow
        .chunks_exact(2 * n)
        .map(|f| {
            let (u, v) = f.split_at(n);
            u.iter()
                .zip(v)
                .map(|(a, b)| (a * a + b * b).sqrt())
                .sum::<f32>()
                / n as f32
        })
        .collect();
    Ok(Prepared {
        x: InputTensors::new(&inputs, device),
        y: LabelTensors::new(&labels, side, device),
        paired: labels.paired,
        contact_next: labels.contact_next,
        zero_flow_epe,
    })
}

/// Standard-normal noise for the reparameterised sample of step `step`,
/// from our own seeded generator (so a resumed run draws what the
/// uninterrupted one would have).
fn noise(seed: u64, step: u64, b: usize, d: usize, device: &Device) -> Tensor<2> {
    let mut r = rng::seeded(seed, 1_000_000 + step);
    let v = (0..b * d).map(|_| rng::normal(&mut r) as f32).collect();
    tensor(v, [b, d], device)
}

/// One pass of `net` (validation mode, z = the mean) over the episodes
/// `episodes` of `ds`.
pub fn evaluate(
    net: &ReprNet,
    cfg: &ReprTrainConfig,
    ds: &Dataset,
    norm: &Normaliser,
    episodes: &[u32],
    device: &Device,
    active: Modalities,
) -> Result<Metrics> {
    let net = net.valid();
    let device = device.clone().inner();
    let loader = Loader::new(
        ds,
        LoaderConfig {
            batch: cfg.train.batch,
            seed: cfg.train.seed ^ 0x7e57,
            shuffle_blocks: cfg.train.shuffle_blocks,
            negative_fraction: cfg.negatives(),
            drop_last: false,
            episodes: Some(Arc::new(Split::table(episodes))),
        },
    );
    let mut m = Metrics::default();
    let recon = cfg.model.kind == ModelKind::Reconstruction;
    for (k, b) in loader.enumerate() {
        if cfg.train.max_test_batches > 0 && k as u64 >= cfg.train.max_test_batches {
            break;
        }
        let p = prepare(
            &b?,
            norm,
            cfg.model.image_size,
            cfg.model.ee_target,
            recon,
            &device,
        )?;
        let out = net.forward(&cfg.model, &p.x, p.y.action.clone(), None, active);
        let l = losses(&out, &p.y, &p.x.proprio, &cfg.loss_weights());
        m.add(&l, &out, &p.paired, &p.contact_next, &p.zero_flow_epe);
    }
    Ok(m)
}

/// Trains `cfg` on the dataset in `data`, writing into `out`; `stop` is
/// asked after every step (true: checkpoint and return, e.g. on Ctrl-C).
pub fn train(
    cfg: &ReprTrainConfig,
    data: &Path,
    out: &Path,
    opts: &TrainOptions,
    stop: &dyn Fn() -> bool,
) -> Result<TrainSummary> {
    cfg.validate().map_err(|e| TrainError::BadFile {
        path: out.join(files::CONFIG),
        what: e.to_string(),
    })?;
    let ds = Dataset::open(data)?;
    check_dataset(cfg, &ds)?;
    std::fs::create_dir_all(out).map_err(io_err(out))?;
    let device = opts.device.device(true).map_err(TrainError::Mismatch)?;
    let t = &cfg.train;
    let norm = crate::models::inputs::normaliser_from_stats(&ds.stats);
    norm.validate()
        .map_err(|what| TrainError::Mismatch(format!("{}: {what}", data.display())))?;
    let (mut net, mut optim, mut state) = start(cfg, out, opts.resume, &device)?;
    crate::interop::record_start(out, cfg).map_err(io_err(out))?;
    let mut tb = crate::interop::ScalarLog::create(out).map_err(io_err(out))?;
    let split_path = out.join(files::SPLIT);
    let split = if opts.resume {
        // The run's own split: a dataset grown since must not move
        // episodes the model has trained on into the test split.
        Split::read(&split_path, &ds.meta)?
    } else {
        let split = Split::by_episode(&ds.meta, t.test_fraction, t.seed);
        let json = serde_json::to_vec_pretty(&split).expect("split serialises");
        std::fs::write(&split_path, json).map_err(io_err(&split_path))?;
        split
    };
    if split.train.is_empty() {
        return Err(TrainError::Mismatch(format!(
            "{}: no episode left for training",
            data.display()
        )));
    }

    let train_table = Arc::new(Split::table(&split.train));
    let train_samples = Split::samples(&ds.meta, &split.train);
    let mut per_epoch = train_samples.div_ceil(t.batch as u64);
    if t.max_batches_per_epoch > 0 {
        per_epoch = per_epoch.min(t.max_batches_per_epoch);
    }
    let total = per_epoch * t.epochs as u64;
    let bar = opts
        .progress
        .then(|| learner_node::progress::Progress::new(total, "batches"));
    let variational = cfg.model.kind != ModelKind::Deterministic;
    let recon = cfg.model.kind == ModelKind::Reconstruction;
    let side = cfg.model.image_size;
    let (mut steps_here, mut samples_here) = (0u64, 0u64);
    let started = Instant::now();
    let lr = t.lr;
    let weights = cfg.loss_weights();

    while state.epoch < t.epochs {
        let epoch = state.epoch;
        let loader = Loader::new(
            &ds,
            LoaderConfig {
                batch: t.batch,
                seed: t.seed.wrapping_mul(1000).wrapping_add(epoch as u64),
                shuffle_blocks: t.shuffle_blocks,
                negative_fraction: cfg.negatives(),
                drop_last: false,
                episodes: Some(train_table.clone()),
            },
        );
        for (k, b) in loader.enumerate() {
            let k = k as u64;
            if k >= per_epoch {
                break;
            }
            if k < state.batches_done {
                // Drawn again only so that the loader's order continues
                // exactly where the interrupted run stood.
                continue;
            }
            let p = prepare(&b?, &norm, side, cfg.model.ee_target, recon, &device)?;
            let eps = variational.then(|| {
                noise(
                    t.seed,
                    state.steps,
                    p.paired.len(),
                    cfg.model.latent_dim,
                    &device,
                )
            });
            let pred = net.forward(&cfg.model, &p.x, p.y.action.clone(), eps, Modalities::ALL);
            let l = losses(&pred, &p.y, &p.x.proprio, &weights);
            let total_loss = f64::from(l.total.clone().into_scalar::<f32>());
            if !total_loss.is_finite() {
                return Err(TrainError::NotFinite {
                    epoch: epoch + 1,
                    batch: k,
                    value: total_loss,
                });
            }
            state
                .metrics
                .add(&l, &pred, &p.paired, &p.contact_next, &p.zero_flow_epe);
            let grads = GradientsParams::from_grads(l.total.backward(), &net);
            net = optim.step(lr, net, grads);
            state.batches_done = k + 1;
            state.steps += 1;
            steps_here += 1;
            samples_here += p.paired.len() as u64;
            if let Some(bar) = &bar {
                let done = epoch as u64 * per_epoch + state.batches_done;
                let rate = samples_here as f64 / started.elapsed().as_secs_f64().max(1e-9);
                bar.update(
                    done,
                    format!(
                        "epoch {}/{} loss {:.4} {:.1} samples/s",
                        epoch + 1,
                        t.epochs,
                        total_loss,
                        rate
                    ),
                );
            }
            let interrupted = stop() || opts.stop_after_steps.is_some_and(|s| steps_here >= s);
            if interrupted || state.steps % t.checkpoint_every == 0 {
                checkpoint::save(out, &net, &optim, &state)?;
            }
            if interrupted {
                if let Some(bar) = &bar {
                    bar.finish();
                }
                return Ok(TrainSummary {
                    rows: state.rows,
                    steps: state.steps,
                    finished: false,
                    samples_per_s: samples_here as f64 / started.elapsed().as_secs_f64().max(1e-9),
                    model_dir: out.join(files::MODEL_DIR),
                });
            }
        }
        state.rows.push(state.metrics.row(epoch + 1, "train"));
        if !split.test.is_empty() {
            let test = evaluate(&net, cfg, &ds, &norm, &split.test, &device, Modalities::ALL)?;
            state.rows.push(test.row(epoch + 1, "test"));
        }
        for r in state.rows.iter().filter(|r| r.epoch == epoch + 1) {
            tb.scalars(u64::from(r.epoch), &r.scalars())
                .map_err(io_err(out))?;
        }
        state.epoch += 1;
        state.batches_done = 0;
        state.metrics = Metrics::default();
        write_metrics(out, &state.rows)?;
        checkpoint::save(out, &net, &optim, &state)?;
    }
    if let Some(bar) = &bar {
        bar.finish();
    }
    let model_dir = out.join(files::MODEL_DIR);
    checkpoint::export(
        &model_dir,
        &net,
        &ExportMeta {
            model: cfg.model.clone(),
            normaliser: norm,
            dataset: data.display().to_string(),
            epochs: state.epoch,
            camera: ds.meta.camera,
        },
    )?;
    Ok(TrainSummary {
        rows: state.rows,
        steps: state.steps,
        finished: true,
        samples_per_s: samples_here as f64 / started.elapsed().as_secs_f64().max(1e-9),
        model_dir,
    })
}

/// Writes metrics.csv and the learning curves.
fn write_metrics(out: &Path, rows: &[Row]) -> Result<()> {
    let mut csv = String::from(CSV_HEADER);
    csv.push('\n');
    for r in rows {
        csv.push_str(&r.csv());
        csv.push('\n');
    }
    let p = out.join(files::METRICS);
    std::fs::write(&p, csv).map_err(io_err(&p))?;
    write_curves(rows, out, "representation")?;
    Ok(())
}
