//! The dataset builder: shards, meta.json, stats.json and the pairing
//! table, written from logs labelled in parallel.

use super::*;
use learner_node::policy::WRENCH_WINDOW;
use robot_model::descriptions::RobotCatalog;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes shards, meta.json, stats.json and the pairing table.
pub(super) struct Builder {
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
    /// An I/O failure on the dataset's file `name`.
    fn io_err(&self, name: &str, source: std::io::Error) -> DatasetError {
        DatasetError::Io {
            path: self.dir.join(name),
            source,
        }
    }

    pub(super) fn add_episode(&mut self, source: &Path, ep: EpisodeSamples) -> Result<()> {
        if ep.samples.is_empty() {
            self.meta
                .skipped
                .push((source.display().to_string(), "no samples".into()));
            return Ok(());
        }
        if self.meta.samples == 0 {
            (self.meta.width, self.meta.height) = ep.size;
        }
        if ep.size != (self.meta.width, self.meta.height) {
            return Err(DatasetError::ImageSize {
                log: source.to_path_buf(),
                size: ep.size,
                dataset: (self.meta.width, self.meta.height),
            });
        }
        match (&self.meta.camera, ep.camera) {
            (None, c) => self.meta.camera = c,
            (Some(d), Some(c)) if !d.same_camera(&c) => {
                return Err(DatasetError::Camera {
                    log: source.to_path_buf(),
                    log_camera: Box::new(c),
                    dataset: Box::new(*d),
                });
            }
            _ => {}
        }
        let episode = self.meta.episodes.len() as u32;
        self.meta.episodes.push(EpisodeInfo {
            episode,
            source: source.display().to_string(),
            peg: ep.peg,
            policy: ep.policy,
            first_id: self.meta.samples,
            samples: ep.samples.len() as u64,
        });
        for (mut s, tags) in ep.samples.into_iter().zip(ep.tags) {
            s.episode = episode;
            self.stats.balance.add(ep.policy, tags, s.contact);
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
                self.wrench_table
                    .write_all(&x.to_le_bytes())
                    .map_err(|e| self.io_err("wrench.bin", e))?;
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

    pub(super) fn flush_block(&mut self) -> Result<()> {
        if self.pending_n == 0 {
            return Ok(());
        }
        if self.shard.is_none() {
            let name = format!("shard-{:05}.vtds", self.meta.shards.len());
            let err = |e| self.io_err(&name, e);
            let mut f = std::fs::File::create(self.dir.join(&name)).map_err(err)?;
            f.write_all(SHARD_MAGIC).map_err(err)?;
            self.meta.shards.push((name, Vec::new()));
            self.shard = Some((f, SHARD_MAGIC.len() as u64, Vec::new(), 0));
        }
        let name = &self.meta.shards.last().expect("opened").0;
        let err = |e| DatasetError::Io {
            path: self.dir.join(name),
            source: e,
        };
        let z = zstd::bulk::compress(&self.pending, self.cfg.zstd_level).map_err(err)?;
        let (f, offset, blocks, count) = self.shard.as_mut().expect("opened");
        f.write_all(&z).map_err(err)?;
        let first_id = self.meta.samples - self.pending_n as u64;
        blocks.push(BlockIndex {
            offset: *offset,
            length: z.len() as u64,
            samples: self.pending_n,
            first_id,
            crc32: crc32fast::hash(&z),
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

    pub(super) fn close_shard(&mut self) -> Result<()> {
        if let Some((mut f, _, blocks, _)) = self.shard.take() {
            let shard = self.meta.shards.last_mut().expect("opened");
            let err = |source| DatasetError::Io {
                path: self.dir.join(&shard.0),
                source,
            };
            f.write_all(SHARD_MAGIC).map_err(err)?;
            f.sync_all().map_err(err)?;
            shard.1 = blocks;
        }
        Ok(())
    }

    pub(super) fn finish(mut self) -> Result<Meta> {
        self.flush_block()?;
        self.close_shard()?;
        self.wrench_table
            .flush()
            .map_err(|e| self.io_err("wrench.bin", e))?;
        std::fs::write(self.dir.join("contacts.bin"), &self.contacts)
            .map_err(|e| self.io_err("contacts.bin", e))?;
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
        self.write_json("stats.json", &self.stats)?;
        self.write_json("meta.json", &self.meta)?;
        Ok(self.meta)
    }

    /// Writes `value` as pretty JSON into the dataset's file `name`.
    fn write_json(&self, name: &str, value: &impl serde::Serialize) -> Result<()> {
        let path = self.dir.join(name);
        let text = serde_json::to_string_pretty(value).map_err(|source| DatasetError::Json {
            path: path.clone(),
            source,
        })?;
        std::fs::write(&path, text).map_err(|source| DatasetError::Io { path, source })
    }
}

impl Builder {
    /// A builder writing a dataset into `out` (created if absent).
    pub(super) fn new(out: &Path, cfg: &BuildConfig) -> Result<Self> {
        if cfg.block_samples == 0 || cfg.shard_samples == 0 {
            return Err(DatasetError::EmptyBlocks {
                block_samples: cfg.block_samples,
                shard_samples: cfg.shard_samples,
            });
        }
        if !(cfg.flow_mask_min_px.is_finite() && cfg.flow_mask_min_px >= 0.0) {
            return Err(DatasetError::FlowMaskThreshold(cfg.flow_mask_min_px));
        }
        let io_err = |path: PathBuf| move |source| DatasetError::Io { path, source };
        std::fs::create_dir_all(out).map_err(io_err(out.to_path_buf()))?;
        let wrench_path = out.join("wrench.bin");
        let wrench_table = std::fs::File::create(&wrench_path).map_err(io_err(wrench_path))?;
        Ok(Builder {
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
                camera: None,
            },
            stats: stats_new(),
            wrench_table: std::io::BufWriter::new(wrench_table),
            contacts: Vec::new(),
            shard: None,
            pending: Vec::new(),
            pending_n: 0,
            contact_next: 0,
            mask_px: 0,
        })
    }
}

/// The `.mcap` files under `inputs` (files or directories), sorted.
pub fn find_logs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|source| DatasetError::Io {
                    path: p.clone(),
                    source,
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                .collect();
            v.sort();
            out.extend(v);
        } else if p.exists() {
            out.push(p.clone());
        } else {
            return Err(DatasetError::NoInput(p.clone()));
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
    let mut b = Builder::new(out, cfg)?;
    // Robots named by the logs: built-in ones, or files in `robot_dir`
    // (a log is data from elsewhere; it never names a path to read).
    let robots = match &cfg.robot_dir {
        Some(dir) => RobotCatalog::with_dir(dir).map_err(|source| DatasetError::Robot {
            log: dir.clone(),
            robot: "(robot_dir)".into(),
            source: Box::new(source),
        })?,
        None => RobotCatalog::builtin_only(),
    };
    // Workers label logs in parallel; results are added in log order so a
    // build is reproducible.
    let robots = &robots;
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, Result<EpisodeSamples>)>(workers * 2);
    std::thread::scope(|s| -> Result<()> {
        for _ in 0..workers.max(1) {
            let tx = tx.clone();
            let next = &next;
            s.spawn(move || {
                let mut models = Models::new(robots.clone());
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if i >= logs.len() {
                        return;
                    }
                    // A defect that panics on one log must not take the
                    // build down: the log is skipped and reported.
                    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        episode_samples(&logs[i], cfg, &mut models)
                    }))
                    .unwrap_or_else(|panic| {
                        // A model half inserted is not possible (one insert),
                        // but start afresh rather than reason about it.
                        models = Models::new(robots.clone());
                        Err(DatasetError::LabelPanic {
                            log: logs[i].clone(),
                            message: panic_message(panic.as_ref()),
                        })
                    });
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
                // A log that cannot join this dataset is skipped; only
                // the dataset's own I/O ends the build.
                let r = r.and_then(|ep| {
                    let n = ep.samples.len();
                    b.add_episode(path, ep).map(|()| n)
                });
                match r {
                    Ok(n) => on_log(path, Ok(n)),
                    Err(e @ (DatasetError::Io { .. } | DatasetError::Json { .. })) => {
                        return Err(e);
                    }
                    Err(e) => {
                        let text = e.to_string();
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

/// The text of a caught panic.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}
