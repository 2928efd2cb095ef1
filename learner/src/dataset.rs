//! The self-supervised dataset: built from MCAP logs, stored as chunked
//! shards, read back by a shuffling, streaming loader. Format: docs/data.md.
//!
//! One sample per 20 Hz step that has an action: the camera frame, the last
//! 32 wrench readings, proprioception and the next action; labels: the flow
//! that action causes and its mask, contact at the next step, the next
//! end-effector position. Pairing negatives (the paper's time-shifted
//! haptics with the opposite contact state) are drawn by the loader from a
//! table of every sample's wrench window kept beside the shards.

use crate::labels::{Calibration, FlowLabeler, in_contact};
use crate::log::{CameraImage, LogReader, topics};
use crate::policy::WRENCH_WINDOW;
use anyhow::{Context, Result, bail, ensure};
use serde::{Deserialize, Serialize};
use shared_mem_schema::{PolicyAction, SensorFrame};
use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Shard file magic (start and end).
pub const SHARD_MAGIC: &[u8; 8] = b"VTDSHRD1";
/// Dataset format version (meta.json).
pub const FORMAT_VERSION: u32 = 1;
/// Proprioception: position (3), orientation quaternion x, y, z, w (4),
/// linear and angular velocity (6).
pub const PROPRIO: usize = 13;

/// How labels are made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BuildConfig {
    /// Contact: mean force change against free space above this, N.
    pub contact_threshold_n: f64,
    /// Readings averaged for the contact test.
    pub contact_window: usize,
    /// Flow mask: rendered robot depth within this of the recorded depth, m.
    pub flow_depth_tol_m: f64,
    /// Samples per compressed block (the loader's unit of reading).
    pub block_samples: usize,
    /// Samples per shard file.
    pub shard_samples: usize,
    /// zstd level.
    pub zstd_level: i32,
}

impl Default for BuildConfig {
    fn default() -> Self {
        Self {
            contact_threshold_n: 3.0,
            contact_window: 4,
            flow_depth_tol_m: 0.01,
            block_samples: 32,
            shard_samples: 4096,
            zstd_level: 3,
        }
    }
}

/// One sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sample {
    /// Episode (dataset-wide number).
    pub episode: u32,
    /// Index within the episode.
    pub index: u32,
    /// Hardware step of the frame.
    pub step: u64,
    /// Contact now.
    pub contact: bool,
    /// Label: contact at the next step.
    pub contact_next: bool,
    /// RGB, H×W×3.
    pub rgb: Vec<u8>,
    /// Depth, m, H×W.
    pub depth: Vec<f32>,
    /// Wrench window, oldest first, 32×6.
    pub wrench: Vec<f32>,
    /// Proprioception ([`PROPRIO`]).
    pub proprio: [f32; PROPRIO],
    /// The next action (Δx, Δy, Δz, Δroll).
    pub action: [f32; 4],
    /// Label: flow, H×W×2, px.
    pub flow: Vec<f32>,
    /// Label: flow mask, H×W.
    pub mask: Vec<u8>,
    /// Label: next end-effector position, m.
    pub ee_next: [f32; 3],
}

fn sample_bytes(w: usize, h: usize) -> usize {
    let n = w * h;
    24 + 3 * n + 4 * n + 4 * WRENCH_WINDOW * 6 + 4 * PROPRIO + 16 + 8 * n + n + 12
}

fn put_f32s(out: &mut Vec<u8>, xs: &[f32]) {
    for x in xs {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

fn get_f32s(buf: &[u8], at: &mut usize, out: &mut [f32]) {
    for x in out.iter_mut() {
        *x = f32::from_le_bytes(buf[*at..*at + 4].try_into().expect("4 bytes"));
        *at += 4;
    }
}

impl Sample {
    fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.episode.to_le_bytes());
        out.extend_from_slice(&self.index.to_le_bytes());
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&[
            self.contact as u8,
            self.contact_next as u8,
            0,
            0,
            0,
            0,
            0,
            0,
        ]);
        out.extend_from_slice(&self.rgb);
        put_f32s(out, &self.depth);
        put_f32s(out, &self.wrench);
        put_f32s(out, &self.proprio);
        put_f32s(out, &self.action);
        put_f32s(out, &self.flow);
        out.extend_from_slice(&self.mask);
        put_f32s(out, &self.ee_next);
    }

    fn decode(buf: &[u8], w: usize, h: usize) -> Self {
        let n = w * h;
        let u32_at = |a: usize| u32::from_le_bytes(buf[a..a + 4].try_into().expect("4"));
        let mut s = Sample {
            episode: u32_at(0),
            index: u32_at(4),
            step: u64::from_le_bytes(buf[8..16].try_into().expect("8")),
            contact: buf[16] != 0,
            contact_next: buf[17] != 0,
            rgb: buf[24..24 + 3 * n].to_vec(),
            depth: vec![0.0; n],
            wrench: vec![0.0; WRENCH_WINDOW * 6],
            flow: vec![0.0; 2 * n],
            ..Default::default()
        };
        let mut at = 24 + 3 * n;
        get_f32s(buf, &mut at, &mut s.depth);
        get_f32s(buf, &mut at, &mut s.wrench);
        get_f32s(buf, &mut at, &mut s.proprio);
        get_f32s(buf, &mut at, &mut s.action);
        get_f32s(buf, &mut at, &mut s.flow);
        s.mask = buf[at..at + n].to_vec();
        at += n;
        get_f32s(buf, &mut at, &mut s.ee_next);
        s
    }
}

/// Where a block is in its shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockIndex {
    /// Byte offset.
    pub offset: u64,
    /// Compressed length.
    pub length: u64,
    /// Samples in it.
    pub samples: u32,
    /// Dataset-wide id of its first sample.
    pub first_id: u64,
}

/// An episode's samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Dataset-wide number.
    pub episode: u32,
    /// The log it came from.
    pub source: String,
    /// Peg.
    pub peg: String,
    /// Policy that collected it.
    pub policy: String,
    /// Id of its first sample (its samples are consecutive).
    pub first_id: u64,
    /// Samples.
    pub samples: u64,
}

/// meta.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Wrench readings per sample.
    pub wrench_window: usize,
    /// Samples.
    pub samples: u64,
    /// Shard files and their blocks.
    pub shards: Vec<(String, Vec<BlockIndex>)>,
    /// Episodes.
    pub episodes: Vec<EpisodeInfo>,
    /// Logs skipped, with the reason.
    pub skipped: Vec<(String, String)>,
    /// How the labels were made.
    pub build: BuildConfig,
}

/// Running mean and variance (Welford), per component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Moments {
    /// Count.
    pub n: u64,
    /// Mean.
    pub mean: Vec<f64>,
    m2: Vec<f64>,
    /// Standard deviation (filled by [`Moments::finish`]).
    pub std: Vec<f64>,
}

impl Moments {
    fn new(dim: usize) -> Self {
        Self {
            n: 0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
            std: vec![0.0; dim],
        }
    }

    fn add(&mut self, x: &[f32]) {
        self.n += 1;
        for (k, &v) in x.iter().enumerate() {
            let d = v as f64 - self.mean[k];
            self.mean[k] += d / self.n as f64;
            self.m2[k] += d * (v as f64 - self.mean[k]);
        }
    }

    fn finish(&mut self) {
        let n = self.n.max(2) as f64 - 1.0;
        self.std = self.m2.iter().map(|m| (m / n).sqrt().max(1e-6)).collect();
    }
}

/// stats.json: normalisation constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Wrench components (fx, fy, fz, tx, ty, tz).
    pub wrench: Moments,
    /// Proprioception.
    pub proprio: Moments,
    /// Actions.
    pub action: Moments,
    /// Depth of pixels with a return, m.
    pub depth: Moments,
    /// RGB channels, 0..255.
    pub rgb: Moments,
    /// Next position minus current position, m.
    pub ee_delta: Moments,
    /// Share of samples in contact at the next step.
    pub contact_next_ratio: f64,
    /// Share of flow-mask pixels.
    pub mask_ratio: f64,
}

fn stats_new() -> Stats {
    Stats {
        wrench: Moments::new(6),
        proprio: Moments::new(PROPRIO),
        action: Moments::new(4),
        depth: Moments::new(1),
        rgb: Moments::new(3),
        ee_delta: Moments::new(3),
        contact_next_ratio: 0.0,
        mask_ratio: 0.0,
    }
}

/// The samples of one log.
pub struct EpisodeSamples {
    /// Peg.
    pub peg: String,
    /// Policy.
    pub policy: String,
    /// Samples in order.
    pub samples: Vec<Sample>,
    /// Image size.
    pub size: (usize, usize),
}

/// Models by robot name, loaded once.
#[derive(Default)]
pub struct Models(HashMap<String, robot_model::Model>);

impl Models {
    fn get(&mut self, robot: &str) -> Result<robot_model::Model> {
        if let Some(m) = self.0.get(robot) {
            return Ok(m.clone());
        }
        let m = robot_model::descriptions::load(robot)?;
        self.0.insert(robot.into(), m.clone());
        Ok(m)
    }
}

/// Turns one log into samples with labels.
pub fn episode_samples(
    path: &Path,
    cfg: &BuildConfig,
    models: &mut Models,
) -> Result<EpisodeSamples> {
    let r = LogReader::open(path)?;
    let config = r
        .read_json(topics::CONFIG, None)?
        .into_iter()
        .next()
        .with_context(|| format!("{}: no configuration message on /config", path.display()))?
        .1;
    let world: hw_sim::WorldConfig = serde_json::from_value(config["world"].clone())
        .with_context(|| format!("{}: the /config world does not parse", path.display()))?;
    let model = models.get(&world.robot)?;
    let frames: Vec<SensorFrame> = r.read_raw(topics::SENSOR, None)?;
    let actions: Vec<PolicyAction> = r.read_raw(topics::ACTION, None)?;
    let cams: Vec<CameraImage> = r.read_camera(None)?;
    ensure!(!frames.is_empty(), "{}: no sensor frames", path.display());
    let by_time: HashMap<u64, usize> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| (f.header.t_hw_ns, i))
        .collect();
    let by_seq: HashMap<u64, &PolicyAction> = actions.iter().map(|a| (a.header.seq, a)).collect();
    let force = |i: usize| {
        let w = &frames[i].wrench;
        [w[0], w[1], w[2]]
    };
    // Free space: the episode starts away from the box.
    let first: Vec<[f64; 3]> = (0..frames.len().min(WRENCH_WINDOW)).map(force).collect();
    let mut free = [0.0; 3];
    for f in &first {
        for k in 0..3 {
            free[k] += f[k] / first.len() as f64;
        }
    }
    let contact_at = |i: usize| {
        let lo = (i + 1).saturating_sub(cfg.contact_window);
        let fs: Vec<[f64; 3]> = (lo..=i).map(force).collect();
        in_contact(&fs, &free, cfg.contact_threshold_n)
    };
    let mut labeler: Option<FlowLabeler> = None;
    let mut out = Vec::new();
    let nq = frames[0].n_joints as usize;
    let mut size = (0, 0);
    for pair in cams.windows(2) {
        let (c0, c1) = (&pair[0], &pair[1]);
        let (Some(&i0), Some(&i1)) = (
            by_time.get(&c0.header.t_hw_ns),
            by_time.get(&c1.header.t_hw_ns),
        ) else {
            continue; // a frame without its sensor frame (a lost message)
        };
        if i1 <= i0 || i0 == 0 {
            continue;
        }
        // The action taken in this interval: newest applied by its end, if
        // it was not already in force at its start.
        let (a_prev, a_new) = (frames[i0 - 1].action_seq, frames[i1 - 1].action_seq);
        if a_new == a_prev {
            continue;
        }
        let Some(a) = by_seq.get(&a_new) else {
            continue;
        };
        if labeler.is_none() {
            let cal = Calibration {
                width: c0.width,
                height: c0.height,
                focal_px: c0.focal_px,
                principal_px: c0.principal_px,
                pos_m: c0.pose_pos_m,
                quat_xyzw: c0.pose_quat_xyzw,
            };
            labeler = Some(FlowLabeler::new(model.clone(), &world.task, &cal)?);
            size = (c0.width as usize, c0.height as usize);
        }
        ensure!(
            (c0.width as usize, c0.height as usize) == size,
            "{}: the image size changes within the episode",
            path.display()
        );
        let l = labeler.as_mut().expect("made");
        l.label(
            &frames[i0].q[..nq],
            &frames[i1].q[..nq],
            &c0.depth_m,
            cfg.flow_depth_tol_m,
        );
        let f0 = &frames[i0];
        let mut wrench = Vec::with_capacity(WRENCH_WINDOW * 6);
        for k in 0..WRENCH_WINDOW {
            let i = (i0 + k + 1).saturating_sub(WRENCH_WINDOW);
            wrench.extend(frames[i].wrench.iter().map(|&x| x as f32));
        }
        let mut proprio = [0f32; PROPRIO];
        for (k, x) in f0
            .ee_pos_m
            .iter()
            .chain(&f0.ee_quat_xyzw)
            .chain(&f0.ee_twist)
            .enumerate()
        {
            proprio[k] = *x as f32;
        }
        let ee1 = frames[i1].ee_pos_m;
        out.push(Sample {
            episode: 0,
            index: out.len() as u32,
            step: f0.step,
            contact: contact_at(i0),
            contact_next: contact_at(i1),
            rgb: c0.rgb.clone(),
            depth: c0.depth_m.clone(),
            wrench,
            proprio,
            action: a.delta().map(|x| x as f32),
            flow: l.flow_px.iter().flat_map(|f| [f[0], f[1]]).collect(),
            mask: l.mask.clone(),
            ee_next: [ee1[0] as f32, ee1[1] as f32, ee1[2] as f32],
        });
    }
    let str_of = |v: &serde_json::Value| v.as_str().unwrap_or("unknown").to_string();
    Ok(EpisodeSamples {
        peg: world.task.peg.name().into(),
        policy: str_of(&config["policy"]),
        samples: out,
        size,
    })
}

/// Writes shards, meta.json, stats.json and the pairing table.
struct Builder {
    dir: PathBuf,
    cfg: BuildConfig,
    meta: Meta,
    stats: Stats,
    wrench_table: std::io::BufWriter<std::fs::File>,
    contacts: Vec<u8>,
    shard: Option<(std::fs::File, u64, Vec<BlockIndex>, usize)>,
    pending: Vec<u8>,
    pending_n: u32,
    contact_next: u64,
    mask_px: u64,
}

impl Builder {
    fn add_episode(&mut self, source: &Path, ep: EpisodeSamples) -> Result<()> {
        if ep.samples.is_empty() {
            self.meta
                .skipped
                .push((source.display().to_string(), "no samples".into()));
            return Ok(());
        }
        if self.meta.samples == 0 {
            (self.meta.width, self.meta.height) = ep.size;
        }
        ensure!(
            ep.size == (self.meta.width, self.meta.height),
            "{}: images of {:?}, the dataset's are {}×{}",
            source.display(),
            ep.size,
            self.meta.width,
            self.meta.height
        );
        let episode = self.meta.episodes.len() as u32;
        self.meta.episodes.push(EpisodeInfo {
            episode,
            source: source.display().to_string(),
            peg: ep.peg,
            policy: ep.policy,
            first_id: self.meta.samples,
            samples: ep.samples.len() as u64,
        });
        for mut s in ep.samples {
            s.episode = episode;
            for row in s.wrench.chunks_exact(6) {
                self.stats.wrench.add(row);
            }
            self.stats.proprio.add(&s.proprio);
            self.stats.action.add(&s.action);
            for (k, d) in s.depth.iter().enumerate() {
                if *d > 0.0 && k % 7 == 0 {
                    self.stats.depth.add(&[*d]);
                }
            }
            for px in s.rgb.chunks_exact(3).step_by(7) {
                self.stats
                    .rgb
                    .add(&[px[0] as f32, px[1] as f32, px[2] as f32]);
            }
            let d: Vec<f32> = (0..3).map(|k| s.ee_next[k] - s.proprio[k]).collect();
            self.stats.ee_delta.add(&d);
            self.contact_next += s.contact_next as u64;
            self.mask_px += s.mask.iter().map(|&m| m as u64).sum::<u64>();
            for x in &s.wrench {
                self.wrench_table.write_all(&x.to_le_bytes())?;
            }
            self.contacts.push(s.contact as u8);
            s.encode(&mut self.pending);
            self.pending_n += 1;
            self.meta.samples += 1;
            if self.pending_n as usize >= self.cfg.block_samples {
                self.flush_block()?;
            }
        }
        Ok(())
    }

    fn flush_block(&mut self) -> Result<()> {
        if self.pending_n == 0 {
            return Ok(());
        }
        if self.shard.is_none() {
            let name = format!("shard-{:05}.vtds", self.meta.shards.len());
            let mut f = std::fs::File::create(self.dir.join(&name))
                .with_context(|| format!("creating {name}"))?;
            f.write_all(SHARD_MAGIC)?;
            self.meta.shards.push((name, Vec::new()));
            self.shard = Some((f, SHARD_MAGIC.len() as u64, Vec::new(), 0));
        }
        let (f, offset, blocks, count) = self.shard.as_mut().expect("opened");
        let z = zstd::bulk::compress(&self.pending, self.cfg.zstd_level)?;
        f.write_all(&z)?;
        let first_id = self.meta.samples - self.pending_n as u64;
        blocks.push(BlockIndex {
            offset: *offset,
            length: z.len() as u64,
            samples: self.pending_n,
            first_id,
        });
        *offset += z.len() as u64;
        *count += self.pending_n as usize;
        self.pending.clear();
        self.pending_n = 0;
        if *count >= self.cfg.shard_samples {
            self.close_shard()?;
        }
        Ok(())
    }

    fn close_shard(&mut self) -> Result<()> {
        if let Some((mut f, _, blocks, _)) = self.shard.take() {
            f.write_all(SHARD_MAGIC)?;
            f.sync_all()?;
            self.meta.shards.last_mut().expect("opened").1 = blocks;
        }
        Ok(())
    }

    fn finish(mut self) -> Result<Meta> {
        self.flush_block()?;
        self.close_shard()?;
        self.wrench_table.flush()?;
        std::fs::write(self.dir.join("contacts.bin"), &self.contacts)?;
        let n = self.meta.samples.max(1) as f64;
        self.stats.contact_next_ratio = self.contact_next as f64 / n;
        self.stats.mask_ratio =
            self.mask_px as f64 / (n * (self.meta.width * self.meta.height).max(1) as f64);
        for m in [
            &mut self.stats.wrench,
            &mut self.stats.proprio,
            &mut self.stats.action,
            &mut self.stats.depth,
            &mut self.stats.rgb,
            &mut self.stats.ee_delta,
        ] {
            m.finish();
        }
        std::fs::write(
            self.dir.join("stats.json"),
            serde_json::to_string_pretty(&self.stats)?,
        )?;
        std::fs::write(
            self.dir.join("meta.json"),
            serde_json::to_string_pretty(&self.meta)?,
        )?;
        Ok(self.meta)
    }
}

/// The `.mcap` files under `inputs` (files or directories), sorted.
pub fn find_logs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("reading {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                .collect();
            v.sort();
            out.extend(v);
        } else if p.exists() {
            out.push(p.clone());
        } else {
            bail!("{}: no such file or directory", p.display());
        }
    }
    Ok(out)
}

/// Builds a dataset in `out` from logs; `workers` threads label episodes.
/// Logs that cannot be read are skipped and listed in meta.json (and
/// reported through `on_log`); nothing is written into the inputs.
pub fn build(
    logs: &[PathBuf],
    out: &Path,
    cfg: &BuildConfig,
    workers: usize,
    mut on_log: impl FnMut(&Path, Result<usize, String>),
) -> Result<Meta> {
    ensure!(
        cfg.block_samples > 0 && cfg.shard_samples > 0,
        "block and shard sizes must be > 0"
    );
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut b = Builder {
        dir: out.to_path_buf(),
        cfg: cfg.clone(),
        meta: Meta {
            format_version: FORMAT_VERSION,
            width: 0,
            height: 0,
            wrench_window: WRENCH_WINDOW,
            samples: 0,
            shards: Vec::new(),
            episodes: Vec::new(),
            skipped: Vec::new(),
            build: cfg.clone(),
        },
        stats: stats_new(),
        wrench_table: std::io::BufWriter::new(std::fs::File::create(out.join("wrench.bin"))?),
        contacts: Vec::new(),
        shard: None,
        pending: Vec::new(),
        pending_n: 0,
        contact_next: 0,
        mask_px: 0,
    };
    // Workers label logs in parallel; results are added in log order so a
    // build is reproducible.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, Result<EpisodeSamples>)>(workers * 2);
    std::thread::scope(|s| -> Result<()> {
        for _ in 0..workers.max(1) {
            let tx = tx.clone();
            let next = &next;
            s.spawn(move || {
                let mut models = Models::default();
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if i >= logs.len() {
                        return;
                    }
                    let r = episode_samples(&logs[i], cfg, &mut models);
                    if tx.send((i, r)).is_err() {
                        return;
                    }
                }
            });
        }
        drop(tx);
        let mut held: std::collections::BTreeMap<usize, Result<EpisodeSamples>> =
            Default::default();
        let mut want = 0;
        for (i, r) in rx {
            held.insert(i, r);
            while let Some(r) = held.remove(&want) {
                let path = &logs[want];
                match r {
                    Ok(ep) => {
                        let n = ep.samples.len();
                        b.add_episode(path, ep)?;
                        on_log(path, Ok(n));
                    }
                    Err(e) => {
                        let text = format!("{e:#}");
                        b.meta
                            .skipped
                            .push((path.display().to_string(), text.clone()));
                        on_log(path, Err(text));
                    }
                }
                want += 1;
            }
        }
        Ok(())
    })?;
    b.finish()
}

/// An opened dataset.
pub struct Dataset {
    dir: PathBuf,
    /// meta.json.
    pub meta: Meta,
    /// stats.json.
    pub stats: Stats,
    wrench: Vec<f32>,
    contacts: Vec<u8>,
    episode_of: Vec<u32>,
    /// Per episode: ids of samples in contact and out of contact.
    by_contact: Vec<[Vec<u64>; 2]>,
}

impl Dataset {
    /// Opens a dataset directory; checks the format version and the tables.
    pub fn open(dir: &Path) -> Result<Self> {
        let read = |name: &str| {
            std::fs::read(dir.join(name))
                .with_context(|| format!("dataset {}: reading {name}", dir.display()))
        };
        let meta: Meta = serde_json::from_slice(&read("meta.json")?)
            .with_context(|| format!("dataset {}: meta.json does not parse", dir.display()))?;
        ensure!(
            meta.format_version == FORMAT_VERSION,
            "dataset {}: format version {}, this build reads version {FORMAT_VERSION}",
            dir.display(),
            meta.format_version
        );
        let stats: Stats = serde_json::from_slice(&read("stats.json")?)
            .with_context(|| format!("dataset {}: stats.json does not parse", dir.display()))?;
        let raw = read("wrench.bin")?;
        let per = meta.wrench_window * 6;
        ensure!(
            raw.len() as u64 == meta.samples * per as u64 * 4,
            "dataset {}: wrench.bin holds {} bytes, {} samples need {}",
            dir.display(),
            raw.len(),
            meta.samples,
            meta.samples * per as u64 * 4
        );
        let wrench = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4")))
            .collect();
        let contacts = read("contacts.bin")?;
        ensure!(
            contacts.len() as u64 == meta.samples,
            "dataset {}: contacts.bin holds {} entries for {} samples",
            dir.display(),
            contacts.len(),
            meta.samples
        );
        let mut episode_of = vec![0u32; meta.samples as usize];
        let mut by_contact = Vec::new();
        for e in &meta.episodes {
            let mut sets = [Vec::new(), Vec::new()];
            for id in e.first_id..e.first_id + e.samples {
                episode_of[id as usize] = e.episode;
                sets[contacts[id as usize] as usize & 1].push(id);
            }
            by_contact.push(sets);
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            stats,
            wrench,
            contacts,
            episode_of,
            by_contact,
        })
    }

    /// Samples.
    pub fn len(&self) -> u64 {
        self.meta.samples
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.meta.samples == 0
    }

    /// Every block: (shard, block).
    pub fn blocks(&self) -> Vec<(usize, usize)> {
        self.meta
            .shards
            .iter()
            .enumerate()
            .flat_map(|(s, (_, b))| (0..b.len()).map(move |k| (s, k)))
            .collect()
    }

    /// Reads and decodes one block.
    pub fn read_block(&self, shard: usize, block: usize) -> Result<Vec<Sample>> {
        read_block(&self.dir, &self.meta, shard, block)
    }

    /// The wrench window of sample `id` (the pairing table).
    pub fn wrench_of(&self, id: u64) -> &[f32] {
        let per = self.meta.wrench_window * 6;
        &self.wrench[id as usize * per..(id as usize + 1) * per]
    }

    /// A time-shifted negative for sample `id`: another sample of its
    /// episode whose contact state is the opposite, drawn with `r` in
    /// [0, 1); `None` when its episode has none.
    pub fn negative_for(&self, id: u64, r: f64) -> Option<u64> {
        let e = self.episode_of[id as usize] as usize;
        let c = self.contacts[id as usize] as usize & 1;
        let pool = &self.by_contact[e][1 - c];
        (!pool.is_empty()).then(|| pool[((r * pool.len() as f64) as usize).min(pool.len() - 1)])
    }

    /// Share of samples with a negative available (the pairing ratio).
    pub fn pairing_ratio(&self) -> f64 {
        let with: u64 = self
            .by_contact
            .iter()
            .filter(|s| !s[0].is_empty() && !s[1].is_empty())
            .map(|s| (s[0].len() + s[1].len()) as u64)
            .sum();
        with as f64 / self.len().max(1) as f64
    }

    /// Share of samples in contact now.
    pub fn contact_ratio(&self) -> f64 {
        self.contacts.iter().map(|&c| c as u64).sum::<u64>() as f64 / self.len().max(1) as f64
    }
}

/// Reads and decodes one block of the dataset in `dir` described by `meta`.
fn read_block(dir: &Path, meta: &Meta, shard: usize, block: usize) -> Result<Vec<Sample>> {
    let (name, blocks) = &meta.shards[shard];
    let b = &blocks[block];
    let path = dir.join(name);
    let mut f =
        std::fs::File::open(&path).with_context(|| format!("dataset shard {}", path.display()))?;
    let mut z = vec![0u8; b.length as usize];
    f.seek(SeekFrom::Start(b.offset))?;
    f.read_exact(&mut z).with_context(|| {
        format!(
            "dataset shard {}: block at byte offset {} is cut short",
            path.display(),
            b.offset
        )
    })?;
    let (w, h) = (meta.width, meta.height);
    let size = sample_bytes(w, h);
    let mut plain = vec![0u8; size * b.samples as usize];
    let n = zstd::bulk::decompress_to_buffer(&z, &mut plain).map_err(|e| {
        anyhow::anyhow!(
            "dataset shard {}: block at byte offset {}: {e}",
            path.display(),
            b.offset
        )
    })?;
    ensure!(
        n == plain.len(),
        "dataset shard {}: block at byte offset {} holds {n} bytes, expected {}",
        path.display(),
        b.offset,
        plain.len()
    );
    Ok(plain
        .chunks_exact(size)
        .map(|c| Sample::decode(c, w, h))
        .collect())
}

/// A batch, flattened row-major, sample-major.
#[derive(Debug, Clone, Default)]
pub struct Batch {
    /// Samples in it.
    pub len: usize,
    /// Their dataset ids.
    pub ids: Vec<u64>,
    /// The samples (with the haptics of negatives swapped in).
    pub samples: Vec<Sample>,
    /// Pairing label: 1 aligned, 0 time-shifted haptics.
    pub paired: Vec<u8>,
}

/// Loader settings.
#[derive(Debug, Clone)]
pub struct LoaderConfig {
    /// Samples per batch.
    pub batch: usize,
    /// Shuffle seed.
    pub seed: u64,
    /// Blocks held for shuffling samples across blocks and shards.
    pub shuffle_blocks: usize,
    /// Share of samples given time-shifted haptics.
    pub negative_fraction: f64,
    /// Drop a last, short batch.
    pub drop_last: bool,
}

impl Default for LoaderConfig {
    fn default() -> Self {
        Self {
            batch: 64,
            seed: 0,
            shuffle_blocks: 16,
            negative_fraction: 0.5,
            drop_last: false,
        }
    }
}

/// One epoch of shuffled batches, read ahead on a thread; holds at most
/// `shuffle_blocks` + a few blocks in memory.
pub struct Loader<'a> {
    ds: &'a Dataset,
    cfg: LoaderConfig,
    rx: std::sync::mpsc::Receiver<Result<Vec<(u64, Sample)>>>,
    buffer: Vec<(u64, Sample)>,
    rng: hw_sim::rng::SimRng,
    _reader: std::thread::JoinHandle<()>,
    done: bool,
}

impl<'a> Loader<'a> {
    /// Starts an epoch.
    pub fn new(ds: &'a Dataset, cfg: LoaderConfig) -> Self {
        let mut rng = hw_sim::rng::SimRng::new(cfg.seed, 31);
        let mut blocks = ds.blocks();
        for i in (1..blocks.len()).rev() {
            let j = (rng.unit() * (i + 1) as f64) as usize;
            blocks.swap(i, j.min(i));
        }
        let (tx, rx) = std::sync::mpsc::sync_channel(4);
        let dir = ds.dir.clone();
        let meta = ds.meta.clone();
        // Only the block index travels to the reader: reopening the
        // dataset there would load its pairing table a second time.
        let reader = std::thread::spawn(move || {
            for (s, k) in blocks {
                let first = meta.shards[s].1[k].first_id;
                let r = read_block(&dir, &meta, s, k).map(|v| {
                    v.into_iter()
                        .enumerate()
                        .map(|(i, x)| (first + i as u64, x))
                        .collect()
                });
                let stop = r.is_err();
                if tx.send(r).is_err() || stop {
                    return;
                }
            }
        });
        Self {
            ds,
            cfg,
            rx,
            buffer: Vec::new(),
            rng,
            _reader: reader,
            done: false,
        }
    }
}

impl Iterator for Loader<'_> {
    type Item = Result<Batch>;

    fn next(&mut self) -> Option<Result<Batch>> {
        let want = self.cfg.shuffle_blocks.max(1) * self.ds.meta.build.block_samples;
        let mut batch = Batch::default();
        while batch.len < self.cfg.batch {
            while !self.done && self.buffer.len() < want {
                match self.rx.recv() {
                    Ok(Ok(v)) => self.buffer.extend(v),
                    Ok(Err(e)) => {
                        self.done = true;
                        return Some(Err(e));
                    }
                    Err(_) => self.done = true,
                }
            }
            if self.buffer.is_empty() {
                break;
            }
            let i =
                ((self.rng.unit() * self.buffer.len() as f64) as usize).min(self.buffer.len() - 1);
            let (id, mut s) = self.buffer.swap_remove(i);
            let mut paired = 1;
            if self.rng.unit() < self.cfg.negative_fraction
                && let Some(j) = self.ds.negative_for(id, self.rng.unit())
            {
                s.wrench.copy_from_slice(self.ds.wrench_of(j));
                paired = 0;
            }
            batch.ids.push(id);
            batch.samples.push(s);
            batch.paired.push(paired);
            batch.len += 1;
        }
        if batch.len == 0 || (self.cfg.drop_last && batch.len < self.cfg.batch) {
            return None;
        }
        Some(Ok(batch))
    }
}

/// A contact sheet: for `n` samples, a row of RGB, depth, flow and mask.
pub fn contact_sheet(ds: &Dataset, n: usize, path: &Path) -> Result<()> {
    let (w, h) = (ds.meta.width, ds.meta.height);
    let ids: Vec<u64> = (0..n as u64)
        .map(|k| k * ds.len() / n.max(1) as u64)
        .filter(|&id| id < ds.len())
        .collect();
    let cols = 4;
    let (sw, sh) = (cols * w, ids.len() * h);
    let mut img = vec![255u8; sw * sh * 3];
    for (row, &id) in ids.iter().enumerate() {
        let (shard, block) = locate(ds, id)?;
        let samples = ds.read_block(shard, block)?;
        let first = ds.meta.shards[shard].1[block].first_id;
        let s = &samples[(id - first) as usize];
        let mut frame = hw_sim::CameraFrame {
            width: w as u32,
            height: h as u32,
            depth_m: s.depth.clone(),
            flow_px: s.flow.chunks_exact(2).map(|f| [f[0], f[1]]).collect(),
            flow_mask: s.mask.clone(),
            ..Default::default()
        };
        frame.rgb = s.rgb.clone();
        let depth = hw_sim::camera::depth_to_gray(&frame, 0.3, 2.5);
        let flow = hw_sim::camera::flow_to_rgb(&frame, 2.0);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let d = depth[i];
                let m = if s.mask[i] == 1 { 255 } else { 0 };
                let tiles = [
                    [s.rgb[3 * i], s.rgb[3 * i + 1], s.rgb[3 * i + 2]],
                    [d, d, d],
                    [flow[3 * i], flow[3 * i + 1], flow[3 * i + 2]],
                    [m, m, if s.contact_next { 0 } else { m }],
                ];
                for (c, px) in tiles.iter().enumerate() {
                    let o = ((row * h + y) * sw + c * w + x) * 3;
                    img[o..o + 3].copy_from_slice(px);
                }
            }
        }
    }
    hw_sim::png::write(path, sw as u32, sh as u32, 3, &img)
        .with_context(|| format!("writing {}", path.display()))
}

fn locate(ds: &Dataset, id: u64) -> Result<(usize, usize)> {
    for (s, (_, blocks)) in ds.meta.shards.iter().enumerate() {
        for (k, b) in blocks.iter().enumerate() {
            if id >= b.first_id && id < b.first_id + b.samples as u64 {
                return Ok((s, k));
            }
        }
    }
    bail!("sample {id} is in no block")
}
