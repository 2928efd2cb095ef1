//! An opened dataset: its tables and block reads.

use super::*;
use learner_node::policy::WRENCH_WINDOW;
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
        let bad = |what: String| DatasetError::BadMeta {
            path: dir.join("meta.json"),
            what,
        };
        validate_meta(dir, &meta).map_err(bad)?;
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
        validate_stats(&stats).map_err(|what| DatasetError::BadMeta {
            path: dir.join("stats.json"),
            what,
        })?;
        let raw = read("wrench.bin")?;
        let per = meta.wrench_window * 6;
        // Checked: a huge sample count must not wrap to the table's size.
        let need = meta
            .samples
            .checked_mul(per as u64 * 4)
            .ok_or_else(|| bad(format!("samples = {} is absurd", meta.samples)))?;
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

    /// The dataset-wide episode of sample `id`.
    pub fn episode_of(&self, id: u64) -> u32 {
        self.episode_of[id as usize]
    }

    /// Whether sample `id` belongs to an episode `keep` (indexed by episode
    /// number) marks.
    pub fn keeps(&self, keep: &[bool], id: u64) -> bool {
        keep.get(self.episode_of(id) as usize)
            .copied()
            .unwrap_or(false)
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

/// The largest image side a dataset holds, px (the camera's limit).
pub const MAX_IMAGE_SIDE: usize = 4096;
/// The most samples in one block.
pub const MAX_BLOCK_SAMPLES: u32 = 1 << 16;
/// The most bytes one block decompresses to.
pub const MAX_BLOCK_BYTES: u64 = 1 << 30;

/// Checks meta.json against itself and the shard files before anything is
/// indexed or allocated from it; the error names the field.
fn validate_meta(dir: &Path, meta: &Meta) -> std::result::Result<(), String> {
    if meta.wrench_window != WRENCH_WINDOW {
        return Err(format!(
            "wrench_window = {}, this build's samples hold {WRENCH_WINDOW} readings",
            meta.wrench_window
        ));
    }
    let empty = meta.width == 0 || meta.height == 0;
    if meta.width > MAX_IMAGE_SIDE || meta.height > MAX_IMAGE_SIDE || (meta.samples > 0 && empty) {
        return Err(format!(
            "image size {}×{} (each side must be 1..={MAX_IMAGE_SIDE})",
            meta.width, meta.height
        ));
    }
    let block_samples = meta.build.block_samples;
    if !(1..=MAX_BLOCK_SAMPLES as usize).contains(&block_samples) {
        return Err(format!(
            "build.block_samples = {block_samples} (must be 1..={MAX_BLOCK_SAMPLES})"
        ));
    }
    let sample = sample_bytes(meta.width, meta.height) as u64;
    let mut next_id = 0u64;
    for (s, (name, blocks)) in meta.shards.iter().enumerate() {
        // A bare file name: meta.json must not send the reader elsewhere.
        let plain = Path::new(name).components().count() == 1
            && matches!(
                Path::new(name).components().next(),
                Some(std::path::Component::Normal(_))
            );
        if !plain {
            return Err(format!(
                "shards[{s}] = {name:?} is not a file name in the dataset directory"
            ));
        }
        let len = std::fs::metadata(dir.join(name))
            .map_err(|e| format!("shards[{s}] {name}: {e}"))?
            .len();
        for (k, b) in blocks.iter().enumerate() {
            let at = format!("shards[{s}] ({name}) block {k}");
            let end = b.offset.checked_add(b.length);
            if b.offset < SHARD_MAGIC.len() as u64 || end.is_none_or(|e| e > len) {
                return Err(format!(
                    "{at}: bytes {}..+{} lie outside the {len}-byte shard",
                    b.offset, b.length
                ));
            }
            if b.samples == 0 || b.samples as usize > block_samples {
                return Err(format!(
                    "{at}: {} samples (build.block_samples = {block_samples})",
                    b.samples
                ));
            }
            if sample * b.samples as u64 > MAX_BLOCK_BYTES {
                return Err(format!(
                    "{at}: {} samples of {sample} bytes exceed the {MAX_BLOCK_BYTES} bytes a \
                     block may hold",
                    b.samples
                ));
            }
            if b.first_id != next_id {
                return Err(format!(
                    "{at}: first_id = {}, the blocks before it end at sample {next_id}",
                    b.first_id
                ));
            }
            next_id += b.samples as u64;
        }
    }
    if next_id != meta.samples {
        return Err(format!(
            "samples = {}, the blocks hold {next_id}",
            meta.samples
        ));
    }
    // The episodes tile the samples in order: every sample belongs to
    // exactly one (a gap would count as episode 0, an overlap twice).
    let mut next_id = 0u64;
    for (i, e) in meta.episodes.iter().enumerate() {
        if e.episode as usize != i {
            return Err(format!("episodes[{i}].episode = {}", e.episode));
        }
        if e.first_id
            .checked_add(e.samples)
            .is_none_or(|end| end > meta.samples)
        {
            return Err(format!(
                "episodes[{i}]: samples {}..+{} lie outside the {} samples",
                e.first_id, e.samples, meta.samples
            ));
        }
        if e.samples == 0 || e.first_id != next_id {
            return Err(format!(
                "episodes[{i}]: samples {}..+{}, the episodes before it end at sample {next_id} \
                 (episodes must tile the samples)",
                e.first_id, e.samples
            ));
        }
        next_id += e.samples;
    }
    if next_id != meta.samples {
        return Err(format!(
            "the episodes hold {next_id} of the {} samples (episodes must tile the samples)",
            meta.samples
        ));
    }
    Ok(())
}

/// The normalisation constants have the dimensions of what they normalise.
fn validate_stats(stats: &Stats) -> std::result::Result<(), String> {
    for (name, m, dim) in [
        ("wrench", &stats.wrench, 6),
        ("proprio", &stats.proprio, PROPRIO),
        ("action", &stats.action, 4),
        ("depth", &stats.depth, 1),
        ("rgb", &stats.rgb, 3),
        ("ee_delta", &stats.ee_delta, 3),
    ] {
        if m.mean.len() != dim || m.std.len() != dim {
            return Err(format!(
                "{name}: {} means and {} standard deviations, {dim} expected",
                m.mean.len(),
                m.std.len()
            ));
        }
    }
    Ok(())
}

/// Reads and decodes one block of the dataset in `dir` described by `meta`
/// (checked by [`Dataset::open`]).
pub(super) fn read_block(
    dir: &Path,
    meta: &Meta,
    shard: usize,
    block: usize,
) -> Result<Vec<Sample>> {
    let Some(b) = meta.shards.get(shard).and_then(|s| s.1.get(block)) else {
        return Err(DatasetError::BadMeta {
            path: dir.join("meta.json"),
            what: format!("no block {block} in shard {shard}"),
        });
    };
    let name = &meta.shards[shard].0;
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
    let computed = crc32fast::hash(&z);
    if computed != b.crc32 {
        return Err(DatasetError::BlockChecksum {
            path,
            offset: b.offset,
            stored: b.crc32,
            computed,
        });
    }
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
