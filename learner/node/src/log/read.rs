//! Reading logs: the indexed reader, a structural scan that names the byte
//! offset of the first problem, and crash recovery.
//!
//! The top-level records are walked ([`super::walk`]) rather than read
//! through the mcap crate's streaming reader, so that every error can say
//! where in the file it is; the mcap crate still parses each record and
//! decompresses chunks.

use super::walk::{OP_CHUNK, Salvage, ScanReport, check_summary_crc, chunk_records, walk_all};
use super::{CAMERA_ENCODING, RAW_ENCODING, ros2, topics};
use mcap::records::Record;
use shared_mem_schema::{
    CameraCalibration, CameraFrame, Header, Message, OLDEST_RECORDED_VERSION, SCHEMA_VERSION,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A reading failure, naming the file and, for damaged files, the byte
/// offset of the problem.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{path}: not an MCAP file (no MCAP magic at byte offset 0)")]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// The file ends before its summary: its writer stopped (killed, or
    /// still running).
    #[error(
        "{path}: incomplete log: it ends at byte offset {offset} inside or before its summary \
         ({what}); `learner log recover {path}` writes a valid copy of the {readable} bytes \
         before the damage"
    )]
    Incomplete {
        /// The file.
        path: PathBuf,
        /// Where the damage starts.
        offset: u64,
        /// Bytes readable before it.
        readable: u64,
        /// What was found there.
        what: String,
    },
    /// A record is damaged.
    #[error("{path}: corrupted at byte offset {offset}: {what}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Where the damaged record starts.
        offset: u64,
        /// What is wrong.
        what: String,
    },
    /// A message does not match what its channel promises.
    #[error("{path}: channel {topic}: {what}")]
    Content {
        /// The file.
        path: PathBuf,
        /// The channel.
        topic: String,
        /// What is wrong.
        what: String,
    },
}

/// One message read back.
#[derive(Debug, Clone, PartialEq)]
pub struct LogMessage {
    /// Its channel's topic.
    pub topic: Arc<str>,
    /// Sequence number within the channel.
    pub sequence: u32,
    /// Log time (hardware time), ns.
    pub log_time: u64,
    /// Publish time (monotonic clock), ns.
    pub publish_time: u64,
    /// The payload.
    pub data: Vec<u8>,
}

/// A channel of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// Topic.
    pub topic: String,
    /// Schema name.
    pub schema: String,
    /// Message encoding.
    pub encoding: String,
    /// Messages on it.
    pub messages: u64,
}

/// A camera frame decoded from the raw camera channel.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraImage {
    /// The message header.
    pub header: Header,
    /// Frame counter.
    pub index: u64,
    /// Image size, intrinsics and pose.
    pub calibration: CameraCalibration,
    /// RGB, row-major.
    pub rgb: Vec<u8>,
    /// Depth, m, row-major (0: no return).
    pub depth_m: Vec<f32>,
}

impl CameraImage {
    /// Decodes a camera message of the `cdr` channel (docs/data.md): the
    /// encapsulation header, the frame's head, then the RGB bytes and the
    /// depths as CDR sequences.
    pub fn decode_cdr(data: &[u8]) -> Result<Self, String> {
        let Some(body) = data.strip_prefix(&ros2::CDR_LE) else {
            return Err("camera message without a little-endian plain-CDR header".into());
        };
        let (mut image, n) = Self::decode_head(body)?;
        let head_len = std::mem::offset_of!(CameraFrame, rgb);
        let u32_at = |o: usize| {
            body.get(o..o + 4)
                .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize)
        };
        let rgb_at = head_len + 4;
        let depth_len_at = (rgb_at + 3 * n).next_multiple_of(4);
        let depth_at = depth_len_at + 4;
        let expected = depth_at + 4 * n;
        if u32_at(head_len) != Some(3 * n)
            || u32_at(depth_len_at) != Some(n)
            || body.len() != expected
        {
            return Err(format!(
                "camera message of {} bytes does not hold a {}×{} image ({} expected, with \
                 sequences of {} and {n})",
                data.len(),
                image.calibration.width,
                image.calibration.height,
                expected + 4,
                3 * n
            ));
        }
        image.rgb = body[rgb_at..rgb_at + 3 * n].to_vec();
        image.depth_m = f32s(&body[depth_at..]);
        Ok(image)
    }

    /// Decodes a message of the compact camera channel older logs have.
    pub fn decode(data: &[u8]) -> Result<Self, String> {
        let (mut image, n) = Self::decode_head(data)?;
        let head_len = std::mem::offset_of!(CameraFrame, rgb);
        if data.len() != head_len + 7 * n {
            return Err(format!(
                "camera message of {} bytes does not hold a {}×{} image ({} expected)",
                data.len(),
                image.calibration.width,
                image.calibration.height,
                head_len + 7 * n
            ));
        }
        image.rgb = data[head_len..head_len + 3 * n].to_vec();
        image.depth_m = f32s(&data[head_len + 3 * n..]);
        Ok(image)
    }

    /// The frame's head (up to its pixels; no pixels yet) and its pixel
    /// count, the image's size checked against the largest a frame holds.
    fn decode_head(data: &[u8]) -> Result<(Self, usize), String> {
        let head_len = std::mem::offset_of!(CameraFrame, rgb);
        if data.len() < head_len {
            return Err(format!(
                "camera message of {} bytes, shorter than its {head_len}-byte head",
                data.len()
            ));
        }
        let header: Header = bytemuck::pod_read_unaligned(&data[..size_of::<Header>()]);
        // The camera frame's layout is unchanged since the oldest version
        // read.
        if !(OLDEST_RECORDED_VERSION..=SCHEMA_VERSION).contains(&header.schema_version) {
            return Err(format!(
                "camera frame of schema version {}, this build reads versions \
                 {OLDEST_RECORDED_VERSION} to {SCHEMA_VERSION}",
                header.schema_version
            ));
        }
        let u64_at = |o: usize| u64::from_le_bytes(data[o..o + 8].try_into().expect("8 bytes"));
        let u32_at = |o: usize| u32::from_le_bytes(data[o..o + 4].try_into().expect("4 bytes"));
        let f64_at = |o: usize| f64::from_le_bytes(data[o..o + 8].try_into().expect("8 bytes"));
        let f64s = |o: usize, out: &mut [f64]| {
            for (i, x) in out.iter_mut().enumerate() {
                *x = f64_at(o + 8 * i);
            }
        };
        use std::mem::offset_of;
        let at = |field: usize| offset_of!(CameraFrame, calibration) + field;
        let mut calibration = CameraCalibration {
            width: u32_at(at(offset_of!(CameraCalibration, width))),
            height: u32_at(at(offset_of!(CameraCalibration, height))),
            focal_px: f64_at(at(offset_of!(CameraCalibration, focal_px))),
            ..CameraCalibration::default()
        };
        f64s(
            at(offset_of!(CameraCalibration, principal_px)),
            &mut calibration.principal_px,
        );
        f64s(
            at(offset_of!(CameraCalibration, pose_pos_m)),
            &mut calibration.pose_pos_m,
        );
        f64s(
            at(offset_of!(CameraCalibration, pose_quat_xyzw)),
            &mut calibration.pose_quat_xyzw,
        );
        let (width, height) = (calibration.width, calibration.height);
        if width as usize > shared_mem_schema::MAX_IMAGE_WIDTH
            || height as usize > shared_mem_schema::MAX_IMAGE_HEIGHT
        {
            return Err(format!(
                "camera frame claims a {width}×{height} image, larger than the {}×{} a frame holds",
                shared_mem_schema::MAX_IMAGE_WIDTH,
                shared_mem_schema::MAX_IMAGE_HEIGHT
            ));
        }
        let image = Self {
            header,
            index: u64_at(offset_of!(CameraFrame, index)),
            calibration,
            rgb: Vec::new(),
            depth_m: Vec::new(),
        };
        Ok((image, width as usize * height as usize))
    }
}

/// Little-endian `f32`s.
fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect()
}

/// Scans a whole file: every record parsed, every chunk decompressed.
pub fn scan(path: &Path) -> Result<ScanReport, ReadError> {
    let buf = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !buf.starts_with(mcap::MAGIC) {
        return Err(ReadError::NotMcap {
            path: path.to_path_buf(),
        });
    }
    Ok(walk_all(&buf, None))
}

/// What [`recover`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct RecoverReport {
    /// Messages written to the new file.
    pub messages: u64,
    /// Channels written.
    pub channels: usize,
    /// Of those, channels whose schema record was lost (written without a
    /// schema, their messages kept).
    pub channels_without_schema: usize,
    /// Bytes of the input kept (intact records).
    pub readable_bytes: u64,
    /// Where the damage began and what it was, if anywhere.
    pub damage: Option<(u64, String)>,
}

/// Writes a valid copy of everything intact in `input` (schemas, channels
/// and every message before the first damaged record) to `output`. The
/// input is never modified; `output` must be another file.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, ReadError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReadError::Io { path, source }
    };
    if input.canonicalize().ok() == output.canonicalize().ok() && output.exists() {
        return Err(ReadError::Io {
            path: output.to_path_buf(),
            source: std::io::Error::other("the recovered copy must not overwrite its input"),
        });
    }
    let buf = std::fs::read(input).map_err(io(input))?;
    if !buf.starts_with(mcap::MAGIC) {
        return Err(ReadError::NotMcap {
            path: input.to_path_buf(),
        });
    }
    let mut salvage = Salvage::default();
    let rep = walk_all(&buf, Some(&mut salvage));
    let err = |e: mcap::McapError| ReadError::Io {
        path: output.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    };
    let file = std::fs::File::create(output).map_err(io(output))?;
    let profile = if salvage.profile.is_empty() {
        super::PROFILE.to_string()
    } else {
        salvage.profile.clone()
    };
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile(profile)
        .create(std::io::BufWriter::new(file))
        .map_err(err)?;
    for (id, (name, enc, data)) in &salvage.schemas {
        w.add_schema_with_id(*id, name, enc, data).map_err(err)?;
    }
    let (mut channels, mut without_schema) = (0, 0);
    for c in salvage.channels.values() {
        // A channel whose schema record is lost keeps its messages: it is
        // written without a schema (its message encoding still says how to
        // read them).
        let schema_id = if c.schema_id != 0 && !salvage.schemas.contains_key(&c.schema_id) {
            without_schema += 1;
            0
        } else {
            c.schema_id
        };
        w.add_channel_with_id(c.id, schema_id, &c.topic, &c.message_encoding, &c.metadata)
            .map_err(err)?;
        channels += 1;
    }
    let mut messages = 0;
    for (h, data) in &salvage.messages {
        if !salvage.channels.contains_key(&h.channel_id) {
            continue;
        }
        w.write_to_known_channel(h, data).map_err(err)?;
        messages += 1;
    }
    w.finish().map_err(err)?;
    Ok(RecoverReport {
        messages,
        channels,
        channels_without_schema: without_schema,
        readable_bytes: rep.readable_bytes,
        damage: rep.problem,
    })
}

/// A complete, indexed log held in memory.
pub struct LogReader {
    path: PathBuf,
    buf: Vec<u8>,
    summary: mcap::Summary,
    topics: HashMap<u16, Arc<str>>,
}

impl LogReader {
    /// Opens a complete log. A truncated or damaged file is an error naming
    /// the byte offset where the damage starts.
    pub fn open(path: &Path) -> Result<Self, ReadError> {
        let buf = std::fs::read(path).map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(path, buf)
    }

    /// Reads a log already in memory (`path` names it in errors).
    pub fn from_bytes(path: &Path, buf: Vec<u8>) -> Result<Self, ReadError> {
        let path = path.to_path_buf();
        if !buf.starts_with(mcap::MAGIC) {
            return Err(ReadError::NotMcap { path });
        }
        let summary = if buf.len() >= 2 * mcap::MAGIC.len() && buf.ends_with(mcap::MAGIC) {
            mcap::Summary::read(&buf).ok().flatten()
        } else {
            None
        };
        let Some(summary) = summary else {
            let rep = walk_all(&buf, None);
            let (offset, what) = rep
                .problem
                .unwrap_or((buf.len() as u64, "no summary".into()));
            return Err(if rep.complete {
                ReadError::Corrupt { path, offset, what }
            } else {
                ReadError::Incomplete {
                    path,
                    offset,
                    readable: rep.readable_bytes,
                    what,
                }
            });
        };
        if let Err((offset, what)) = check_summary_crc(&buf) {
            return Err(ReadError::Corrupt { path, offset, what });
        }
        for ci in &summary.chunk_indexes {
            let end = ci.chunk_start_offset.checked_add(ci.chunk_length);
            if end.is_none_or(|e| e > buf.len() as u64) || ci.chunk_length < 9 {
                return Err(ReadError::Corrupt {
                    path,
                    offset: ci.chunk_start_offset,
                    what: "a chunk index points outside the file".into(),
                });
            }
        }
        // Two indexes of one chunk (or of overlapping bytes) would read its
        // messages twice.
        let mut spans: Vec<(u64, u64)> = summary
            .chunk_indexes
            .iter()
            .map(|ci| (ci.chunk_start_offset, ci.chunk_length))
            .collect();
        spans.sort_unstable();
        if let Some(w) = spans.windows(2).find(|w| w[0].0 + w[0].1 > w[1].0) {
            return Err(ReadError::Corrupt {
                path,
                offset: w[1].0,
                what: format!(
                    "two chunk indexes cover this chunk (the one at {} runs {} bytes)",
                    w[0].0, w[0].1
                ),
            });
        }
        let topics = summary
            .channels
            .iter()
            .map(|(id, c)| (*id, Arc::from(c.topic.as_str())))
            .collect();
        Ok(Self {
            path,
            buf,
            summary,
            topics,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Size of the file, bytes.
    pub fn len_bytes(&self) -> u64 {
        self.buf.len() as u64
    }

    /// The channels, with their message counts.
    pub fn topics(&self) -> Vec<TopicInfo> {
        let counts = self
            .summary
            .stats
            .as_ref()
            .map(|s| s.channel_message_counts.clone())
            .unwrap_or_default();
        let mut out: Vec<TopicInfo> = self
            .summary
            .channels
            .iter()
            .map(|(id, c)| TopicInfo {
                topic: c.topic.clone(),
                schema: c
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                encoding: c.message_encoding.clone(),
                messages: counts.get(id).copied().unwrap_or(0),
            })
            .collect();
        out.sort_by(|a, b| a.topic.cmp(&b.topic));
        out
    }

    /// Log-time span of the messages, ns.
    pub fn time_span(&self) -> Option<(u64, u64)> {
        let s = self.summary.stats.as_ref()?;
        (s.message_count > 0).then_some((s.message_start_time, s.message_end_time))
    }

    /// Messages of `topics` (all when empty) with log time in
    /// `[start, end)` (everything when `None`), in log-time order. Only the
    /// chunks whose index says they hold such messages are decompressed.
    pub fn read(
        &self,
        topics: &[&str],
        range: Option<(u64, u64)>,
    ) -> Result<Vec<LogMessage>, ReadError> {
        let wanted: HashMap<u16, Arc<str>> = self
            .topics
            .iter()
            .filter(|(_, t)| topics.is_empty() || topics.contains(&&***t))
            .map(|(id, t)| (*id, t.clone()))
            .collect();
        let (lo, hi) = range.unwrap_or((0, u64::MAX));
        let mut out = Vec::new();
        for ci in &self.summary.chunk_indexes {
            if ci.message_end_time < lo || ci.message_start_time >= hi {
                continue;
            }
            if !ci.message_index_offsets.is_empty()
                && !ci
                    .message_index_offsets
                    .keys()
                    .any(|id| wanted.contains_key(id))
            {
                continue;
            }
            let start = ci.chunk_start_offset as usize;
            let end = start + ci.chunk_length as usize;
            let corrupt = |what: String| ReadError::Corrupt {
                path: self.path.clone(),
                offset: ci.chunk_start_offset,
                what,
            };
            if self.buf[start] != OP_CHUNK {
                return Err(corrupt(
                    "the chunk index points at a record that is not a chunk".into(),
                ));
            }
            for r in chunk_records(&self.buf[start + 9..end]).map_err(corrupt)? {
                if let Record::Message { header, data } = r
                    && let Some(topic) = wanted.get(&header.channel_id)
                    && header.log_time >= lo
                    && header.log_time < hi
                {
                    out.push(LogMessage {
                        topic: topic.clone(),
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: data.into_owned(),
                    });
                }
            }
        }
        out.sort_by_key(|m| m.log_time);
        Ok(out)
    }

    fn content_err(&self, topic: &str, what: String) -> ReadError {
        ReadError::Content {
            path: self.path.clone(),
            topic: topic.to_string(),
            what,
        }
    }

    fn check_encoding(&self, topic: &str, encoding: &str) -> Result<(), ReadError> {
        self.channel_encoding(topic, &[encoding]).map(|_| ())
    }

    /// The message encoding of `topic`'s channel, one of `accepted`.
    fn channel_encoding(&self, topic: &str, accepted: &[&str]) -> Result<String, ReadError> {
        match self.summary.channels.values().find(|c| c.topic == topic) {
            Some(c) if accepted.contains(&c.message_encoding.as_str()) => {
                Ok(c.message_encoding.clone())
            }
            Some(c) => Err(self.content_err(
                topic,
                format!(
                    "encoding {:?}, expected one of {accepted:?}",
                    c.message_encoding
                ),
            )),
            None => Err(self.content_err(topic, "no such channel in this log".into())),
        }
    }

    /// The raw struct messages of `T`'s channel at `topic`, checked: size
    /// and schema version must be this build's or an older one it reads
    /// ([`Message::read_recorded`]).
    pub fn read_raw<T: Message>(
        &self,
        topic: &str,
        range: Option<(u64, u64)>,
    ) -> Result<Vec<T>, ReadError> {
        let cdr = self.channel_encoding(topic, &[RAW_ENCODING, ros2::MESSAGE_ENCODING])?
            == ros2::MESSAGE_ENCODING;
        let mut out = Vec::new();
        for m in self.read(&[topic], range)? {
            let bytes = if cdr {
                m.data.strip_prefix(&ros2::CDR_LE).ok_or_else(|| {
                    self.content_err(
                        topic,
                        format!(
                            "message {} has no little-endian plain-CDR header",
                            m.sequence
                        ),
                    )
                })?
            } else {
                &m.data[..]
            };
            let v = T::read_recorded(bytes).map_err(|what| {
                self.content_err(topic, format!("message {}: {what}", m.sequence))
            })?;
            out.push(*v);
        }
        Ok(out)
    }

    /// The camera frames in `range`.
    pub fn read_camera(&self, range: Option<(u64, u64)>) -> Result<Vec<CameraImage>, ReadError> {
        let cdr = self
            .channel_encoding(topics::CAMERA, &[CAMERA_ENCODING, ros2::MESSAGE_ENCODING])?
            == ros2::MESSAGE_ENCODING;
        self.read(&[topics::CAMERA], range)?
            .iter()
            .map(|m| {
                let image = if cdr {
                    CameraImage::decode_cdr(&m.data)
                } else {
                    CameraImage::decode(&m.data)
                };
                image.map_err(|what| {
                    self.content_err(topics::CAMERA, format!("message {}: {what}", m.sequence))
                })
            })
            .collect()
    }

    /// The episode events of `/events`, typed.
    pub fn read_events(
        &self,
        range: Option<(u64, u64)>,
    ) -> Result<Vec<(u64, super::Event)>, ReadError> {
        self.read_serde(super::topics::EVENTS, range)
    }

    /// The configuration records of `/config`, typed.
    pub fn read_config(
        &self,
        range: Option<(u64, u64)>,
    ) -> Result<Vec<(u64, super::RunConfig)>, ReadError> {
        self.read_serde(super::topics::CONFIG, range)
    }

    /// The JSON messages of `topic` (events, configuration, views) with
    /// their log times.
    pub fn read_json(
        &self,
        topic: &str,
        range: Option<(u64, u64)>,
    ) -> Result<Vec<(u64, serde_json::Value)>, ReadError> {
        self.read_serde(topic, range)
    }

    /// The JSON messages of `topic` decoded as `T`, with their log times.
    fn read_serde<T: serde::de::DeserializeOwned>(
        &self,
        topic: &str,
        range: Option<(u64, u64)>,
    ) -> Result<Vec<(u64, T)>, ReadError> {
        self.check_encoding(topic, "json")?;
        self.read(&[topic], range)?
            .iter()
            .map(|m| {
                serde_json::from_slice(&m.data)
                    .map(|v| (m.log_time, v))
                    .map_err(|e| self.content_err(topic, format!("message {}: {e}", m.sequence)))
            })
            .collect()
    }
}
