//! MCAP logs of the live stack (first version: the data issue adds the
//! Foxglove channels, recovery and the reader).
//!
//! One channel per stream. Each message is the shared-mem-schema struct's
//! bytes (`#[repr(C)]`, native little-endian, no padding), so a log is
//! lossless; the schema record names the struct and the schema version.
//! Camera frames are stored compactly: the struct's fixed fields, then the
//! `width × height` RGB bytes, then the `width × height` depth floats.
//! Episode events (reset, stage reached, outcome) and the configuration are
//! JSON. Log time is the hardware time, publish time the monotonic clock.

use mcap::records::MessageHeader;
use shared_mem_schema::{
    CameraFrame, ControllerStatus, EpisodeReport, Message, Pod, PolicyAction, SCHEMA_VERSION,
    SensorFrame,
};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Message encoding of the raw struct channels.
pub const RAW_ENCODING: &str = "vision_touch/repr-c";
/// Message encoding of the compact camera channel.
pub const CAMERA_ENCODING: &str = "vision_touch/camera-compact";

/// A logging failure, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("MCAP log {path}: {source}")]
pub struct LogError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    #[source]
    pub source: mcap::McapError,
}

/// The log's channels.
#[derive(Clone, Copy)]
enum Stream {
    Sensor,
    Action,
    Camera,
    Status,
    Episode,
    Events,
}

struct Channel {
    id: u16,
    seq: u32,
}

/// Writes one episode's streams.
pub struct StackLogger {
    path: PathBuf,
    w: mcap::Writer<BufWriter<File>>,
    sensor: Channel,
    action: Channel,
    camera: Channel,
    status: Channel,
    episode: Channel,
    events: Channel,
}

fn schema_text<T: Message>() -> String {
    format!(
        "shared_mem_schema::{} (schema version {SCHEMA_VERSION}, {} bytes, #[repr(C)], \
         little-endian)",
        T::NAME,
        size_of::<T>()
    )
}

impl StackLogger {
    /// Creates `path` (zstd-compressed, chunked, indexed).
    pub fn create(path: &Path) -> Result<Self, LogError> {
        let err = |source| LogError {
            path: path.to_path_buf(),
            source,
        };
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| err(e.into()))?;
        }
        let file = File::create(path).map_err(|e| err(e.into()))?;
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(1 << 20))
            .profile("vision_touch")
            .create(BufWriter::new(file))
            .map_err(err)?;
        let meta = BTreeMap::new();
        let raw = |w: &mut mcap::Writer<_>, name: &str, text: String, topic: &str| {
            let sid = w.add_schema(name, RAW_ENCODING, text.as_bytes())?;
            let id = w.add_channel(sid, topic, RAW_ENCODING, &meta)?;
            Ok::<_, mcap::McapError>(Channel { id, seq: 0 })
        };
        let sensor = raw(
            &mut w,
            "SensorFrame",
            schema_text::<SensorFrame>(),
            "/controller/sensor",
        )
        .map_err(err)?;
        let action = raw(
            &mut w,
            "PolicyAction",
            schema_text::<PolicyAction>(),
            "/policy/action",
        )
        .map_err(err)?;
        let status = raw(
            &mut w,
            "ControllerStatus",
            schema_text::<ControllerStatus>(),
            "/controller/status",
        )
        .map_err(err)?;
        let episode = raw(
            &mut w,
            "EpisodeReport",
            schema_text::<EpisodeReport>(),
            "/sim/episode",
        )
        .map_err(err)?;
        let cam_sid = w
            .add_schema(
                "CameraFrameCompact",
                CAMERA_ENCODING,
                format!(
                    "shared_mem_schema::CameraFrame (schema version {SCHEMA_VERSION}): its first \
                     {} bytes, then width*height*3 RGB bytes, then width*height f32 depths",
                    std::mem::offset_of!(CameraFrame, rgb)
                )
                .as_bytes(),
            )
            .map_err(err)?;
        let camera = Channel {
            id: w
                .add_channel(cam_sid, "/camera/rgbd", CAMERA_ENCODING, &meta)
                .map_err(err)?,
            seq: 0,
        };
        let ev_sid = w
            .add_schema("Event", "jsonschema", br#"{"type":"object"}"#)
            .map_err(err)?;
        let events = Channel {
            id: w
                .add_channel(ev_sid, "/events", "json", &meta)
                .map_err(err)?,
            seq: 0,
        };
        Ok(Self {
            path: path.to_path_buf(),
            w,
            sensor,
            action,
            camera,
            status,
            episode,
            events,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write(
        &mut self,
        stream: Stream,
        log_ns: u64,
        pub_ns: u64,
        data: &[u8],
    ) -> Result<(), LogError> {
        let ch = match stream {
            Stream::Sensor => &mut self.sensor,
            Stream::Action => &mut self.action,
            Stream::Camera => &mut self.camera,
            Stream::Status => &mut self.status,
            Stream::Episode => &mut self.episode,
            Stream::Events => &mut self.events,
        };
        ch.seq = ch.seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id: ch.id,
            sequence: ch.seq,
            log_time: log_ns,
            publish_time: pub_ns,
        };
        self.w
            .write_to_known_channel(&header, data)
            .map_err(|source| LogError {
                path: self.path.clone(),
                source,
            })
    }

    /// A raw struct message, stamped with its own header's times.
    fn raw<T: Message>(&mut self, stream: Stream, m: &T) -> Result<(), LogError> {
        let h = m.header();
        self.write(stream, h.t_hw_ns, h.t_mono_ns, m.as_bytes())
    }

    /// Logs a sensor frame.
    pub fn sensor(&mut self, m: &SensorFrame) -> Result<(), LogError> {
        self.raw(Stream::Sensor, m)
    }

    /// Logs an action (`t_hw_ns`: the observation's hardware time).
    pub fn action(&mut self, m: &PolicyAction) -> Result<(), LogError> {
        self.raw(Stream::Action, m)
    }

    /// Logs a controller status.
    pub fn status(&mut self, m: &ControllerStatus) -> Result<(), LogError> {
        self.raw(Stream::Status, m)
    }

    /// Logs an episode report.
    pub fn episode(&mut self, m: &EpisodeReport) -> Result<(), LogError> {
        self.raw(Stream::Episode, m)
    }

    /// Logs a camera frame (compact).
    pub fn camera(&mut self, m: &CameraFrame) -> Result<(), LogError> {
        let n = (m.width as usize).min(shared_mem_schema::MAX_IMAGE_WIDTH)
            * (m.height as usize).min(shared_mem_schema::MAX_IMAGE_HEIGHT);
        let head = &m.as_bytes()[..std::mem::offset_of!(CameraFrame, rgb)];
        let mut buf = Vec::with_capacity(head.len() + n * 7);
        buf.extend_from_slice(head);
        buf.extend_from_slice(&m.rgb[..n * 3]);
        for d in &m.depth_m[..n] {
            buf.extend_from_slice(&d.to_le_bytes());
        }
        self.write(Stream::Camera, m.header.t_hw_ns, m.header.t_mono_ns, &buf)
    }

    /// Logs an event (JSON object) at hardware time `t_hw_ns`.
    pub fn event(&mut self, t_hw_ns: u64, json: &serde_json::Value) -> Result<(), LogError> {
        let text = json.to_string();
        let now = shared_mem_schema::process::mono_now_ns();
        self.write(Stream::Events, t_hw_ns, now, text.as_bytes())
    }

    /// Writes the summary and index; the file is complete after this.
    pub fn finish(mut self) -> Result<PathBuf, LogError> {
        self.w.finish().map_err(|source| LogError {
            path: self.path.clone(),
            source,
        })?;
        Ok(self.path)
    }
}
