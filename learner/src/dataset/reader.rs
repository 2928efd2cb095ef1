//! An opened dataset: its tables and block reads.

use super::*;
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
            let path = dir.join(name);
            std::fs::read(&path).map_err(|source| DatasetError::Io { path, source })
        };
        let parse_err = |name: &str| {
            let path = dir.join(name);
            move |source| DatasetError::Json { path, source }
        };
        let meta: Meta =
            serde_json::from_slice(&read("meta.json")?).map_err(parse_err("meta.json"))?;
        if meta.format_version != FORMAT_VERSION {
            return Err(DatasetError::FormatVersion {
                dir: dir.to_path_buf(),
                found: meta.format_version,
                expected: FORMAT_VERSION,
            });
        }
        // Shards copied in from another version would decode as garbage.
        for (name, _) in &meta.shards {
            let path = dir.join(name);
            let mut head = [0u8; 8];
            std::fs::File::open(&path)
                .and_then(|mut f| f.read_exact(&mut head))
                .map_err(|source| DatasetError::Io {
                    path: path.clone(),
                    source,
                })?;
            if &head != SHARD_MAGIC {
                return Err(DatasetError::ShardMagic {
                    path,
                    found: String::from_utf8_lossy(&head).into_owned(),
                    expected: String::from_utf8_lossy(SHARD_MAGIC).into_owned(),
                    version: FORMAT_VERSION,
                });
            }
        }
        let stats: Stats =
            serde_json::from_slice(&read("stats.json")?).map_err(parse_err("stats.json"))?;
        let raw = read("wrench.bin")?;
        let per = meta.wrench_window * 6;
        let need = meta.samples * per as u64 * 4;
        if raw.len() as u64 != need {
            return Err(DatasetError::WrenchTable {
                path: dir.join("wrench.bin"),
                bytes: raw.len() as u64,
                samples: meta.samples,
                need,
            });
        }
        let wrench = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4")))
            .collect();
        let contacts = read("contacts.bin")?;
        if contacts.len() as u64 != meta.samples {
            return Err(DatasetError::ContactTable {
                path: dir.join("contacts.bin"),
                entries: contacts.len() as u64,
                samples: meta.samples,
            });
        }
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
    let io_err = |source| DatasetError::Io {
        path: path.clone(),
        source,
    };
    let mut f = std::fs::File::open(&path).map_err(io_err)?;
    let mut z = vec![0u8; b.length as usize];
    f.seek(SeekFrom::Start(b.offset)).map_err(io_err)?;
    f.read_exact(&mut z)
        .map_err(|source| DatasetError::BlockCut {
            path: path.clone(),
            offset: b.offset,
            source,
        })?;
    let (w, h) = (meta.width, meta.height);
    let size = sample_bytes(w, h);
    let mut plain = vec![0u8; size * b.samples as usize];
    let n = zstd::bulk::decompress_to_buffer(&z, &mut plain).map_err(|source| {
        DatasetError::BlockDecompress {
            path: path.clone(),
            offset: b.offset,
            source,
        }
    })?;
    if n != plain.len() {
        return Err(DatasetError::BlockSize {
            path,
            offset: b.offset,
            got: n,
            expected: plain.len(),
        });
    }
    Ok(plain
        .chunks_exact(size)
        .map(|c| Sample::decode(c, w, h))
        .collect())
}
