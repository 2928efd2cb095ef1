//! The shuffling, streaming loader with pairing negatives.

use super::*;
use rand::RngExt;
use rand::seq::SliceRandom;
use stack_common::rng;

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
    /// Episodes to draw from, indexed by dataset-wide episode number
    /// (`None`: all): how training and test splits stay apart.
    pub episodes: Option<std::sync::Arc<Vec<bool>>>,
}

impl Default for LoaderConfig {
    fn default() -> Self {
        Self {
            batch: 64,
            seed: 0,
            shuffle_blocks: 16,
            negative_fraction: 0.5,
            drop_last: false,
            episodes: None,
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
    rng: rng::SimRng,
    _reader: std::thread::JoinHandle<()>,
    done: bool,
}

impl<'a> Loader<'a> {
    /// Starts an epoch.
    pub fn new(ds: &'a Dataset, cfg: LoaderConfig) -> Self {
        let mut rng = rng::seeded(cfg.seed, 31);
        let mut blocks = ds.blocks();
        if let Some(keep) = &cfg.episodes {
            // Blocks holding none of the kept episodes are not even read.
            blocks.retain(|&(s, k)| {
                let b = &ds.meta.shards[s].1[k];
                (b.first_id..b.first_id + b.samples as u64).any(|id| ds.keeps(keep, id))
            });
        }
        blocks.shuffle(&mut rng);
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
            let i = self.rng.random_range(0..self.buffer.len());
            let (id, mut s) = self.buffer.swap_remove(i);
            if let Some(keep) = &self.cfg.episodes
                && !self.ds.keeps(keep, id)
            {
                continue;
            }
            let mut paired = 1;
            if rng::unit(&mut self.rng) < self.cfg.negative_fraction
                && let Some(j) = self.ds.negative_for(id, rng::unit(&mut self.rng))
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
