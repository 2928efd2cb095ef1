//! `learner repr eval`: a trained model on its run's test split: the
//! appendix table's rows next to the majority-class and zero-flow
//! baselines (with every sensor, and with each one masked at run time),
//! the paper's figure of flow predicted for different candidate actions on
//! the same image, and a PCA picture of z.

use super::checkpoint;
use super::metrics::Row;
use super::run::{evaluate, files, prepare};
use super::{DeviceKind, ReprTrainConfig, Result, Split, TrainError, io_err};
use crate::dataset::{Dataset, Loader, LoaderConfig, Sample};
use crate::models::{Modalities, ModelConfig, Normaliser, ReprNet};
use crate::plot::{Chart, Series};
use burn::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

/// What to evaluate.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// The training run's directory (`config.toml`, `split.json`, `model/`).
    pub run: PathBuf,
    /// The dataset it was trained on.
    pub data: PathBuf,
    /// Where the table and pictures go.
    pub out: PathBuf,
    /// Where the tensors live.
    pub device: DeviceKind,
    /// Samples in the PCA picture (at most).
    pub pca_samples: usize,
    /// Images in the flow picture.
    pub flow_images: usize,
}

/// The evaluation's results.
#[derive(Debug, Clone)]
pub struct ReprEvalReport {
    /// One row per sensor set: its name and the test metrics.
    pub rows: Vec<(String, Row)>,
    /// The table as Markdown.
    pub markdown: String,
}

/// Runs the evaluation and writes `table.md`, `flow_actions.png`,
/// `pca_z_contact.png`, `pca_z_stage.png` and `pca_z_policy.png` (the
/// pictures for predictive models) into `opts.out`.
pub fn eval(opts: &EvalOptions) -> Result<ReprEvalReport> {
    let cfg_path = opts.run.join(files::CONFIG);
    let cfg = ReprTrainConfig::from_file(&cfg_path)?;
    let split_path = opts.run.join(files::SPLIT);
    let text = std::fs::read(&split_path).map_err(io_err(&split_path))?;
    let split: Split = serde_json::from_slice(&text).map_err(|e| TrainError::BadFile {
        path: split_path.clone(),
        what: e.to_string(),
    })?;
    let device = opts.device.device(false).map_err(TrainError::Mismatch)?;
    let (net, meta) = checkpoint::import(&opts.run.join(files::MODEL_DIR), &device)?;
    // The labels are made and the heads read with the run's configuration,
    // the network built from the export's: they must be one model.
    if cfg.model != meta.model {
        return Err(TrainError::Mismatch(format!(
            "{} and the exported model disagree on the model: {:?} against {:?}",
            cfg_path.display(),
            cfg.model,
            meta.model
        )));
    }
    let ds = Dataset::open(&opts.data)?;
    if ds.meta.width != meta.model.image_size {
        return Err(TrainError::Mismatch(format!(
            "the dataset's images are {} px wide; the model takes {}",
            ds.meta.width, meta.model.image_size
        )));
    }
    if split.test.is_empty() {
        return Err(TrainError::Mismatch(format!(
            "{}: the run holds no test episode",
            split_path.display()
        )));
    }
    std::fs::create_dir_all(&opts.out).map_err(io_err(&opts.out))?;
    let m = meta.model.modalities;
    let mut sets = vec![("all sensors".to_string(), m)];
    for (name, off) in [
        ("no RGB", Modalities { rgb: false, ..m }),
        ("no depth", Modalities { depth: false, ..m }),
        (
            "no haptics",
            Modalities {
                haptics: false,
                ..m
            },
        ),
        (
            "no proprio",
            Modalities {
                proprio: false,
                ..m
            },
        ),
    ] {
        if off != m && !off.none() {
            sets.push((format!("{name} (masked at run time)"), off));
        }
    }
    let mut rows = Vec::new();
    for (name, active) in sets {
        let metrics = evaluate(
            &net,
            &cfg,
            &ds,
            &meta.normaliser,
            &split.test,
            &device,
            active,
        )?;
        rows.push((name, metrics.row(meta.epochs, "test")));
    }
    let trained = last_train_row(&opts.run)?;
    let markdown = table(&cfg, &split, &ds, &rows, trained.as_ref());
    let md = opts.out.join("table.md");
    std::fs::write(&md, &markdown).map_err(io_err(&md))?;
    if cfg.model.kind != crate::models::ModelKind::Reconstruction {
        let samples = test_samples(&ds, &split, opts.pca_samples.max(opts.flow_images))?;
        flow_picture(&net, &meta.model, &meta.normaliser, &samples, opts, &device)?;
        let heuristic: std::collections::HashSet<u32> = ds
            .meta
            .episodes
            .iter()
            .filter(|e| e.policy == learner_node::mix::EpisodePolicy::Heuristic)
            .map(|e| e.episode)
            .collect();
        pca_picture(
            &net,
            &meta.model,
            &meta.normaliser,
            &samples,
            &heuristic,
            opts,
            &device,
        )?;
    }
    Ok(ReprEvalReport { rows, markdown })
}

fn fmt(x: f64) -> String {
    if x.is_nan() {
        "n/a".into()
    } else if x != 0.0 && x.abs() < 1e-2 {
        format!("{x:.2e}")
    } else {
        format!("{x:.4}")
    }
}

fn pct(x: f64) -> String {
    if x.is_nan() {
        "n/a".into()
    } else {
        format!("{:.1} %", 100.0 * x)
    }
}

/// The last epoch's training row of the run (as trained: sampled z), from
/// its checkpoint; `None` for a run that finished no epoch.
fn last_train_row(run: &std::path::Path) -> Result<Option<Row>> {
    let path = checkpoint::dir(run).join("state.json");
    let text = std::fs::read(&path).map_err(io_err(&path))?;
    let state: checkpoint::LoopState =
        serde_json::from_slice(&text).map_err(|e| TrainError::BadFile {
            path: path.clone(),
            what: e.to_string(),
        })?;
    Ok(state.rows.into_iter().rev().find(|r| r.split == "train"))
}

fn table(
    cfg: &ReprTrainConfig,
    split: &Split,
    ds: &Dataset,
    test: &[(String, Row)],
    train: Option<&Row>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Model {:?}, d = {}, trained with {}, end-effector target {:?}; test split: {} episodes, {} samples (train: {} episodes).\n",
        cfg.model.kind,
        cfg.model.latent_dim,
        cfg.model.modalities.names(),
        cfg.model.ee_target,
        split.test.len(),
        Split::samples(&ds.meta, &split.test),
        split.train.len()
    );
    let _ = writeln!(
        s,
        "| sensors | flow EPE, px | zero-flow EPE, px | ee MSE (normalised) | contact loss | contact acc | majority contact acc | pairing loss | pairing acc | majority pairing acc |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    let train_row = train.map(|r| {
        (
            format!("train split, epoch {} (as trained)", r.epoch),
            r.clone(),
        )
    });
    let rows: Vec<(String, Row)> = train_row
        .into_iter()
        .chain(
            test.iter()
                .map(|(n, r)| (format!("test split, {n}"), r.clone())),
        )
        .collect();
    for (name, r) in &rows {
        let _ = writeln!(
            s,
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            fmt(r.loss.flow),
            fmt(r.zero_flow_epe),
            fmt(r.loss.ee),
            fmt(r.loss.contact),
            pct(r.contact_acc),
            pct(r.contact_majority_acc),
            fmt(r.loss.pairing),
            pct(r.pairing_acc),
            pct(r.pairing_majority_acc)
        );
    }
    if cfg.model.kind == crate::models::ModelKind::Reconstruction {
        let _ = writeln!(
            s,
            "\n| sensors | RGB MSE | last wrench MSE | proprio MSE |\n|---|---|---|---|"
        );
        for (name, r) in &rows {
            let _ = writeln!(
                s,
                "| {name} | {} | {} | {} |",
                fmt(r.loss.recon_rgb),
                fmt(r.loss.recon_wrench),
                fmt(r.loss.recon_proprio)
            );
        }
    }
    s
}

/// Up to `n` aligned test samples, the most moving first half of them
/// (the flow picture wants the robot in motion).
fn test_samples(ds: &Dataset, split: &Split, n: usize) -> Result<Vec<Sample>> {
    let loader = Loader::new(
        ds,
        LoaderConfig {
            batch: 64,
            seed: 11,
            negative_fraction: 0.0,
            episodes: Some(Arc::new(Split::table(&split.test))),
            ..LoaderConfig::default()
        },
    );
    let mut out = Vec::new();
    for b in loader {
        out.extend(b?.samples);
        if out.len() >= n {
            break;
        }
    }
    out.truncate(n);
    Ok(out)
}

/// Candidate actions of the flow picture: Δx, Δy, Δz in m (5 mm), Δroll.
const CANDIDATES: [(&str, [f32; 4]); 5] = [
    ("+x", [0.005, 0.0, 0.0, 0.0]),
    ("-x", [-0.005, 0.0, 0.0, 0.0]),
    ("+y", [0.0, 0.005, 0.0, 0.0]),
    ("-y", [0.0, -0.005, 0.0, 0.0]),
    ("down", [0.0, 0.0, -0.005, 0.0]),
];

/// The paper's figure: for each of a few test images (rows), the image, the
/// true flow of the action taken, the flow predicted for it, and the flow
/// predicted for each candidate action (columns).
fn flow_picture(
    net: &ReprNet,
    model: &ModelConfig,
    norm: &Normaliser,
    samples: &[Sample],
    opts: &EvalOptions,
    device: &Device,
) -> Result<()> {
    let s = model.image_size;
    // The samples whose robot moves most.
    let mut order: Vec<usize> = (0..samples.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(samples[i].mask.iter().filter(|&&m| m != 0).count()));
    order.truncate(opts.flow_images.max(1));
    let cols = 3 + CANDIDATES.len();
    let (w, h) = (cols * s, order.len() * s);
    let mut px = vec![255u8; w * h * 3];
    let mut put = |row: usize, col: usize, tile: &[u8]| {
        for y in 0..s {
            let dst = ((row * s + y) * w + col * s) * 3;
            px[dst..dst + 3 * s].copy_from_slice(&tile[y * s * 3..(y + 1) * s * 3]);
        }
    };
    let max_px = 2.0;
    let colour = |u: &[f32], v: &[f32]| -> Vec<u8> {
        u.iter()
            .zip(v)
            .flat_map(|(&a, &b)| hw_sim::camera::flow_colour(a, b, max_px))
            .collect()
    };
    let n = s * s;
    for (row, &i) in order.iter().enumerate() {
        let smp = &samples[i];
        put(row, 0, &smp.rgb);
        let (u, v): (Vec<f32>, Vec<f32>) = smp.flow.chunks_exact(2).map(|f| (f[0], f[1])).unzip();
        put(row, 1, &colour(&u, &v));
        let mut actions = vec![smp.action];
        actions.extend(CANDIDATES.iter().map(|c| c.1));
        let k = actions.len();
        let batch = crate::dataset::Batch {
            len: k,
            ids: vec![0; k],
            samples: actions
                .iter()
                .map(|a| Sample {
                    action: *a,
                    ..smp.clone()
                })
                .collect(),
            paired: vec![1; k],
        };
        let p = prepare(&batch, norm, s, model.ee_target, false, device)?;
        let out = net.forward(model, &p.x, p.y.action.clone(), None, model.modalities);
        let flow = out.flow.expect("a predictive model").flow;
        let f: Vec<f32> = flow.try_into_vec_as::<f32>().expect("f32");
        for (j, chunk) in f.chunks_exact(2 * n).enumerate() {
            put(row, 2 + j, &colour(&chunk[..n], &chunk[n..]));
        }
    }
    let path = opts.out.join("flow_actions.png");
    stack_common::png::write(&path, w as u32, h as u32, 3, &px).map_err(|e| {
        TrainError::Record {
            path: path.clone(),
            what: e.to_string(),
        }
    })?;
    Ok(())
}

/// The z means of `samples` projected on their two principal components
/// (faer's symmetric eigendecomposition of the covariance), coloured by
/// contact at the sample's own step, by the stage its episode had reached,
/// and by the episode's policy.
fn pca_picture(
    net: &ReprNet,
    model: &ModelConfig,
    norm: &Normaliser,
    samples: &[Sample],
    heuristic: &std::collections::HashSet<u32>,
    opts: &EvalOptions,
    device: &Device,
) -> Result<()> {
    let encoder = crate::models::Encoder::new(net.clone(), model.clone(), norm.clone(), device);
    let d = model.latent_dim;
    let mut z = Vec::with_capacity(samples.len() * d);
    for chunk in samples.chunks(64) {
        let obs: Vec<_> = chunk
            .iter()
            .map(crate::models::ObservationRef::from)
            .collect();
        z.extend(encoder.encode(&obs)?);
    }
    let proj = pca2(&z, d);
    let series = |keep: &dyn Fn(&Sample) -> bool| -> Vec<(f64, f64)> {
        samples
            .iter()
            .zip(&proj)
            .filter(|(s, _)| keep(s))
            .map(|(_, p)| *p)
            .collect()
    };
    let chart = Chart::new("z means, first two principal components", "PC 1", "PC 2")
        .with(Series::points("no contact", series(&|s| !s.contact)))
        .with(Series::points("contact", series(&|s| s.contact)));
    chart.write_png(opts.out.join("pca_z_contact.png"))?;
    let mut chart = Chart::new("z means by the stage reached", "PC 1", "PC 2");
    for st in shared_mem_schema::Stage::ALL {
        let pts = series(&|s| s.stage == st);
        if !pts.is_empty() {
            chart = chart.with(Series::points(st.name(), pts));
        }
    }
    chart.write_png(opts.out.join("pca_z_stage.png"))?;
    let chart = Chart::new("z means by the episode's policy", "PC 1", "PC 2")
        .with(Series::points(
            "random",
            series(&|s| !heuristic.contains(&s.episode)),
        ))
        .with(Series::points(
            "heuristic",
            series(&|s| heuristic.contains(&s.episode)),
        ));
    chart.write_png(opts.out.join("pca_z_policy.png"))?;
    Ok(())
}

/// Projections of the rows of `z` (n × d, row-major) on their first two
/// principal components.
pub fn pca2(z: &[f32], d: usize) -> Vec<(f64, f64)> {
    let n = z.len() / d.max(1);
    if n == 0 || d == 0 {
        return Vec::new();
    }
    let mut mean = vec![0.0f64; d];
    for row in z.chunks_exact(d) {
        for (m, &x) in mean.iter_mut().zip(row) {
            *m += x as f64 / n as f64;
        }
    }
    let centred = faer::Mat::<f64>::from_fn(n, d, |i, j| z[i * d + j] as f64 - mean[j]);
    let cov = centred.transpose() * &centred;
    let Ok(eig) = cov.self_adjoint_eigen(faer::Side::Lower) else {
        return vec![(0.0, 0.0); n];
    };
    // Eigenvalues ascending: the last two columns are the principal axes.
    let u = eig.U();
    let (a, b) = (d - 1, d.saturating_sub(2));
    (0..n)
        .map(|i| {
            let mut p = (0.0, 0.0);
            for j in 0..d {
                p.0 += centred[(i, j)] * u[(j, a)];
                p.1 += centred[(i, j)] * u[(j, b)];
            }
            p
        })
        .collect()
}
