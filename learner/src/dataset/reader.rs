//! An opened dataset: its tables and block reads.

use super::*;
use anyhow::{Context, Result, ensure};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// An opened dataset.
pub struct Dataset {
    pub(super) dir: PathBuf,
    /// meta.json.
    pub meta: Meta,
    /// stats.json.
    pub stats: Stats,
    pub(super) wrench: Vec<f32>,
    pub(super) contacts: Vec<u8>,
    pub(super) episode_of: Vec<u32>,
    /// Per episode: ids of samples in contact and out of contact.
    pub(super) by_contact: Vec<[Vec<u64>; 2]>,
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
pub(super) fn read_block(
    dir: &Path,
    meta: &Meta,
    shard: usize,
    block: usize,
) -> Result<Vec<Sample>> {
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
