//! MCAP logs: the writer, the reader, crash recovery and Foxglove views.
//!
//! Every stream has its own channel. The raw channels carry each message as
//! the shared-mem-schema struct's bytes (`#[repr(C)]`, native little-endian,
//! no padding) behind a CDR encapsulation header, so a log is lossless and
//! self-describing: the schema is the struct's ROS 2 message definition
//! ([`ros2`]), which Foxglove and the official readers decode, and the reader
//! refuses another schema version. Camera frames carry the struct's fixed
//! fields, then the image's RGB bytes and depth floats as CDR sequences.
//! Episode events (reset, stage reached, outcome; [`Event`]) and the
//! configuration ([`RunConfig`]) are JSON. Beside them, the [`foxglove`] view channels show the images,
//! the transforms, the end-effector pose and the wrench in Foxglove.
//!
//! Log time is the hardware time, publish time the monotonic clock. Files
//! are chunked (1 MiB), zstd-compressed and indexed; the writer closes a
//! chunk at least every [`LogOptions::flush_period_s`] of log time, so a
//! writer killed mid-run leaves every earlier chunk readable, and
//! [`recover`] turns such a file into a valid one. See docs/data.md.

pub mod arm;
pub mod config;
pub mod events;
pub mod foxglove;
pub mod gaps;
mod read;
pub mod ros2;
pub mod scene;
mod walk;
pub mod ws;

pub use config::{RunConfig, RunMode};
pub use events::Event;
pub use gaps::{ChannelGaps, SensorLoss, log_gaps};
pub use read::{
    CameraImage, LogMessage, LogReader, ReadError, RecoverReport, TopicInfo, recover, scan,
};
pub use walk::ScanReport;

use mcap::records::MessageHeader;
use shared_mem_schema::{
    CameraFrame, ControllerStatus, EpisodeReport, Message, PolicyAction, SensorFrame,
};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Message encoding of the raw struct channels in logs written before
/// they were CDR ([`ros2`]); still read.
pub const RAW_ENCODING: &str = "vision_touch/repr-c";
/// Message encoding of the compact camera channel of such older logs.
pub const CAMERA_ENCODING: &str = "vision_touch/camera-compact";
/// The log profile written in the MCAP header.
pub const PROFILE: &str = "vision_touch";

/// Topics of the raw (training) channels.
pub mod topics {
    /// 1 kHz controller sensor frames ([`shared_mem_schema::SensorFrame`]).
    pub const SENSOR: &str = "/controller/sensor";
    /// 20 Hz policy actions ([`shared_mem_schema::PolicyAction`]).
    pub const ACTION: &str = "/policy/action";
    /// Controller status ([`shared_mem_schema::ControllerStatus`]).
    pub const STATUS: &str = "/controller/status";
    /// Simulator episode reports ([`shared_mem_schema::EpisodeReport`]).
    pub const EPISODE: &str = "/sim/episode";
    /// Camera frames (CDR, `ros2::CAMERA_FRAME`).
    pub const CAMERA: &str = "/camera/rgbd";
    /// Episode events, JSON.
    pub const EVENTS: &str = "/events";
    /// The configuration in force, JSON ([`super::RunConfig`]).
    pub const CONFIG: &str = "/config";
    /// Foxglove view: RGB image.
    pub const VIEW_RGB: &str = "/camera/rgb";
    /// Foxglove view: depth image (metres, 32FC1).
    pub const VIEW_DEPTH: &str = "/camera/depth";
    /// Foxglove view: camera intrinsics.
    pub const VIEW_CALIBRATION: &str = "/camera/calibration";
    /// Foxglove view: base → end-effector and base → camera.
    pub const VIEW_TF: &str = "/tf";
    /// Foxglove view: end-effector pose.
    pub const VIEW_EE_POSE: &str = "/ee/pose";
    /// Foxglove view: wrist wrench.
    pub const VIEW_WRENCH: &str = "/ft/wrench";
    /// View: the arm, the peg and the box as `foxglove.SceneUpdate`.
    pub const VIEW_SCENE: &str = "/scene";
}

/// A logging failure, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("MCAP log {path}: {source}")]
pub struct LogError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    #[source]
    pub source: LogFailure,
}

/// Why a log could not be written.
#[derive(Debug, thiserror::Error)]
pub enum LogFailure {
    /// The MCAP writer or the file failed.
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
    /// A message that cannot be stored faithfully was refused (nothing of
    /// it written; the log stays valid).
    #[error("{0}")]
    Refused(String),
}

/// How a log is written.
#[derive(Debug, Clone, PartialEq)]
pub struct LogOptions {
    /// Write the Foxglove view channels.
    pub foxglove: bool,
    /// Rate of the view channels fed by 1 kHz frames (pose, wrench,
    /// transforms), Hz; at least every frame's rate means every frame.
    pub view_rate_hz: f64,
    /// Longest stretch of log time between closed chunks, s.
    pub flush_period_s: f64,
    /// Chunk size before compression, bytes.
    pub chunk_bytes: u64,
}

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            foxglove: true,
            view_rate_hz: 1000.0,
            flush_period_s: 1.0,
            chunk_bytes: 1 << 20,
        }
    }
}

/// The log's channels.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stream {
    Sensor,
    Action,
    Camera,
    Status,
    Episode,
    Events,
    Config,
    Rgb,
    Depth,
    Calibration,
    Tf,
    EePose,
    Wrench,
    Scene,
}

const STREAMS: usize = 14;

/// Whether every value is a number (not NaN or infinite).
fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Writes one log (an episode of the live stack, or a collection shard).
pub struct LogWriter {
    path: PathBuf,
    w: mcap::Writer<BufWriter<File>>,
    opts: LogOptions,
    ids: [u16; STREAMS],
    seqs: [u32; STREAMS],
    last_flush_ns: u64,
    last_view_ns: Option<u64>,
    json: Vec<u8>,
    buf: Vec<u8>,
    /// The arm whose links the views place (the robot `/config` names;
    /// `Err`: that robot did not load, said once, and the views go on
    /// without the links).
    arm: Option<Result<arm::ArmFrames, String>>,
    /// The task of the last `/config`, whose box the reset draws.
    task: Option<hw_sim::config::TaskConfig>,
    /// The live view every written message also goes to.
    live: Option<std::sync::Arc<ws::Hub>>,
}

/// One channel of a log: its stream, schema and encodings.
struct ChannelSpec {
    stream: Stream,
    schema_name: String,
    schema_encoding: &'static str,
    schema: String,
    topic: &'static str,
    message_encoding: &'static str,
}

/// The channels a log with `opts` has: the raw streams (struct bytes), the
/// camera frames, the JSON events and configuration, and (unless
/// turned off) the Foxglove views.
fn channel_specs(opts: &LogOptions) -> Vec<ChannelSpec> {
    let raw = |stream, def: &ros2::MsgDef, topic| ChannelSpec {
        stream,
        schema_name: def.schema_name(),
        schema_encoding: ros2::SCHEMA_ENCODING,
        schema: def.schema_text(),
        topic,
        message_encoding: ros2::MESSAGE_ENCODING,
    };
    let json = |stream, schema_name: &str, schema: &str, topic| ChannelSpec {
        stream,
        schema_name: schema_name.to_string(),
        schema_encoding: "jsonschema",
        schema: schema.to_string(),
        topic,
        message_encoding: "json",
    };
    let mut specs = vec![
        raw(Stream::Sensor, &ros2::SENSOR_FRAME, topics::SENSOR),
        raw(Stream::Action, &ros2::POLICY_ACTION, topics::ACTION),
        raw(Stream::Status, &ros2::CONTROLLER_STATUS, topics::STATUS),
        raw(Stream::Episode, &ros2::EPISODE_REPORT, topics::EPISODE),
        raw(Stream::Camera, &ros2::CAMERA_FRAME, topics::CAMERA),
        json(
            Stream::Events,
            "vision_touch.Event",
            foxglove::EVENT,
            topics::EVENTS,
        ),
        json(
            Stream::Config,
            "vision_touch.Config",
            foxglove::CONFIG,
            topics::CONFIG,
        ),
    ];
    if opts.foxglove {
        specs.extend([
            json(
                Stream::Rgb,
                "foxglove.RawImage",
                foxglove::RAW_IMAGE,
                topics::VIEW_RGB,
            ),
            json(
                Stream::Depth,
                "foxglove.RawImage",
                foxglove::RAW_IMAGE,
                topics::VIEW_DEPTH,
            ),
            json(
                Stream::Calibration,
                "foxglove.CameraCalibration",
                foxglove::CAMERA_CALIBRATION,
                topics::VIEW_CALIBRATION,
            ),
            json(
                Stream::Tf,
                "foxglove.FrameTransforms",
                foxglove::FRAME_TRANSFORMS,
                topics::VIEW_TF,
            ),
            json(
                Stream::EePose,
                "foxglove.PoseInFrame",
                foxglove::POSE_IN_FRAME,
                topics::VIEW_EE_POSE,
            ),
            json(
                Stream::Wrench,
                "vision_touch.Wrench",
                foxglove::WRENCH,
                topics::VIEW_WRENCH,
            ),
            json(
                Stream::Scene,
                "foxglove.SceneUpdate",
                scene::SCENE_UPDATE,
                topics::VIEW_SCENE,
            ),
        ]);
    }
    specs
}

impl LogWriter {
    /// Creates `path` with the default options.
    pub fn create(path: &Path) -> Result<Self, LogError> {
        Self::create_with(path, LogOptions::default())
    }

    /// Creates `path` (zstd-compressed, chunked, indexed): opens the file,
    /// registers every channel of [`channel_specs`] and flushes them.
    pub fn create_with(path: &Path, opts: LogOptions) -> Result<Self, LogError> {
        let err = |source: mcap::McapError| LogError {
            path: path.to_path_buf(),
            source: source.into(),
        };
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| err(e.into()))?;
        }
        let file = File::create(path).map_err(|e| err(e.into()))?;
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(opts.chunk_bytes))
            .profile(PROFILE)
            .create(BufWriter::new(file))
            .map_err(err)?;
        let meta = BTreeMap::new();
        let mut ids = [0u16; STREAMS];
        for c in channel_specs(&opts) {
            let sid = w
                .add_schema(&c.schema_name, c.schema_encoding, c.schema.as_bytes())
                .map_err(err)?;
            ids[c.stream as usize] = w
                .add_channel(sid, c.topic, c.message_encoding, &meta)
                .map_err(err)?;
        }
        // The schemas and channels go to disk at once, in a chunk of their
        // own: a file killed before its first full chunk still names them.
        w.flush().map_err(err)?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
            opts,
            ids,
            seqs: [0; STREAMS],
            last_flush_ns: 0,
            last_view_ns: None,
            json: Vec::new(),
            buf: Vec::new(),
            arm: None,
            task: None,
            live: None,
        })
    }

    /// Also hands every message written from now on to `hub` (a
    /// [`ws::LiveServer`]'s, serving the same channels; it never blocks).
    pub fn serve_live(&mut self, hub: std::sync::Arc<ws::Hub>) {
        self.live = Some(hub);
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn err(&self, source: mcap::McapError) -> LogError {
        LogError {
            path: self.path.clone(),
            source: source.into(),
        }
    }

    fn write(&mut self, s: Stream, log_ns: u64, pub_ns: u64, data: &[u8]) -> Result<(), LogError> {
        let seq = &mut self.seqs[s as usize];
        *seq = seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id: self.ids[s as usize],
            sequence: *seq,
            log_time: log_ns,
            publish_time: pub_ns,
        };
        self.w
            .write_to_known_channel(&header, data)
            .map_err(|e| self.err(e))?;
        if let Some(live) = &self.live {
            live.publish(s, log_ns, data);
        }
        let period_ns = (self.opts.flush_period_s * 1e9) as u64;
        if log_ns.abs_diff(self.last_flush_ns) >= period_ns {
            self.last_flush_ns = log_ns;
            self.w.flush().map_err(|e| self.err(e))?;
        }
        Ok(())
    }

    /// The JSON view message held in `self.json`.
    fn write_json(&mut self, s: Stream, log_ns: u64, pub_ns: u64) -> Result<(), LogError> {
        let json = std::mem::take(&mut self.json);
        let r = self.write(s, log_ns, pub_ns, &json);
        self.json = json;
        r
    }

    /// A raw struct message (CDR: the encapsulation header, then the
    /// struct's bytes; `ros2`), stamped with its own header's times.
    fn raw<T: Message>(&mut self, s: Stream, m: &T) -> Result<(), LogError> {
        let h = m.header();
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        buf.extend_from_slice(&ros2::CDR_LE);
        buf.extend_from_slice(m.as_bytes());
        let r = self.write(s, h.t_hw_ns, h.t_mono_ns, &buf);
        self.buf = buf;
        r
    }

    /// Logs a sensor frame (and its view messages when one is due).
    pub fn sensor(&mut self, m: &SensorFrame) -> Result<(), LogError> {
        self.raw(Stream::Sensor, m)?;
        if !self.opts.foxglove {
            return Ok(());
        }
        // A view holds numbers only (JSON has no NaN, and Foxglove's schemas
        // refuse null): a frame with a non-finite pose or wrench stays in
        // its raw channel alone.
        if !(finite(&m.ee_pos_m) && finite(&m.ee_quat_xyzw) && finite(&m.wrench)) {
            return Ok(());
        }
        let (t, p) = (m.header.t_hw_ns, m.header.t_mono_ns);
        let period_ns = (1e9 / self.opts.view_rate_hz.max(1e-3)) as u64;
        if self
            .last_view_ns
            .is_some_and(|last| t < last + period_ns && t >= last)
        {
            return Ok(());
        }
        self.last_view_ns = Some(t);
        foxglove::pose_in_frame(
            &mut self.json,
            t,
            foxglove::BASE_FRAME,
            &m.ee_pos_m,
            &m.ee_quat_xyzw,
        );
        self.write_json(Stream::EePose, t, p)?;
        foxglove::wrench(&mut self.json, t, &m.wrench);
        self.write_json(Stream::Wrench, t, p)?;
        let mut tfs = vec![foxglove::Transform {
            parent: foxglove::BASE_FRAME,
            child: foxglove::EE_FRAME,
            translation: m.ee_pos_m,
            rotation_xyzw: m.ee_quat_xyzw,
        }];
        let q = &m.q[..(m.n_joints as usize).min(m.q.len())];
        if let Some(Ok(arm)) = &mut self.arm
            && finite(q)
            && let Some(links) = arm.transforms(q)
        {
            tfs.extend(links);
        }
        foxglove::frame_transforms(&mut self.json, t, &tfs);
        self.write_json(Stream::Tf, t, p)
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

    /// Logs a camera frame: raw (CDR), and the view images and calibration.
    /// A frame claiming a larger image than a message holds is refused
    /// (nothing written): stored, its size would disagree with its pixels
    /// and the reader would refuse the whole camera channel.
    pub fn camera(&mut self, m: &CameraFrame) -> Result<(), LogError> {
        let (w, h) = (m.calibration.width as usize, m.calibration.height as usize);
        if w > shared_mem_schema::MAX_IMAGE_WIDTH || h > shared_mem_schema::MAX_IMAGE_HEIGHT {
            return Err(LogError {
                path: self.path.clone(),
                source: LogFailure::Refused(format!(
                    "camera frame {} claims a {w}×{h} image, larger than the {}×{} a message \
                     holds; not logged",
                    m.index,
                    shared_mem_schema::MAX_IMAGE_WIDTH,
                    shared_mem_schema::MAX_IMAGE_HEIGHT
                )),
            });
        }
        let n = w * h;
        let head = &m.as_bytes()[..std::mem::offset_of!(CameraFrame, rgb)];
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        // CDR (`ros2::CAMERA_FRAME`): the head, then the pixels as
        // sequences; offsets count from after the encapsulation header.
        buf.extend_from_slice(&ros2::CDR_LE);
        buf.extend_from_slice(head);
        buf.extend_from_slice(&(3 * n as u32).to_le_bytes());
        buf.extend_from_slice(&m.rgb[..n * 3]);
        buf.resize(4 + (buf.len() - 4).next_multiple_of(4), 0);
        buf.extend_from_slice(&(n as u32).to_le_bytes());
        let depth_at = buf.len();
        for d in &m.depth_m[..n] {
            buf.extend_from_slice(&d.to_le_bytes());
        }
        let (t, p) = (m.header.t_hw_ns, m.header.t_mono_ns);
        let r = self.write(Stream::Camera, t, p, &buf);
        let cal = &m.calibration;
        let placed = cal.focal_px.is_finite()
            && finite(&cal.principal_px)
            && finite(&cal.pose_pos_m)
            && finite(&cal.pose_quat_xyzw);
        // Images are bytes whatever they hold; a non-finite calibration
        // stays in the raw channel alone (as a sensor frame's pose).
        if r.is_ok() && self.opts.foxglove {
            let depth = &buf[depth_at..];
            let rgb = &m.rgb[..n * 3];
            foxglove::raw_image(
                &mut self.json,
                t,
                w as u32,
                h as u32,
                "rgb8",
                3 * w as u32,
                rgb,
            );
            self.write_json(Stream::Rgb, t, p)?;
            foxglove::raw_image(
                &mut self.json,
                t,
                w as u32,
                h as u32,
                "32FC1",
                4 * w as u32,
                depth,
            );
            self.write_json(Stream::Depth, t, p)?;
        }
        if r.is_ok() && self.opts.foxglove && placed {
            foxglove::camera_calibration(
                &mut self.json,
                t,
                w as u32,
                h as u32,
                m.calibration.focal_px,
                m.calibration.principal_px,
            );
            self.write_json(Stream::Calibration, t, p)?;
            foxglove::frame_transforms(
                &mut self.json,
                t,
                &[foxglove::Transform {
                    parent: foxglove::BASE_FRAME,
                    child: foxglove::CAMERA_FRAME,
                    translation: m.calibration.pose_pos_m,
                    rotation_xyzw: m.calibration.pose_quat_xyzw,
                }],
            );
            self.write_json(Stream::Tf, t, p)?;
        }
        self.buf = buf;
        r
    }

    /// Logs an event (JSON object) at hardware time `t_hw_ns`.
    pub fn event(&mut self, t_hw_ns: u64, event: &Event) -> Result<(), LogError> {
        let text = serde_json::to_string(event).expect("events serialise");
        let now = shared_mem_schema::process::mono_now_ns();
        self.write(Stream::Events, t_hw_ns, now, text.as_bytes())?;
        // The box where this episode put it.
        if let (true, Event::Reset(r)) = (self.opts.foxglove, event) {
            let task = r.world.as_ref().map(|w| &w.task).or(self.task.as_ref());
            let hole_finite =
                finite(&r.hole_pos_m) && finite(&r.hole_quat_xyzw) && r.hole_depth_m.is_finite();
            if let Some(task) = task.filter(|t| t.enabled && hole_finite) {
                let hole = nalgebra::Isometry3::from_parts(
                    nalgebra::Translation3::from(nalgebra::Vector3::from(r.hole_pos_m)),
                    hw_sim::convert::unit_quaternion(r.hole_quat_xyzw),
                );
                let b = scene::box_with_hole(
                    t_hw_ns,
                    &hole,
                    task.peg_width_m + task.clearance_m,
                    r.hole_depth_m,
                    task.box_side_m,
                    task.box_height_m,
                );
                scene::scene_update(&mut self.json, &[b]);
                self.write_json(Stream::Scene, t_hw_ns, now)?;
            }
        }
        Ok(())
    }

    /// Logs the configuration in force at `t_hw_ns`.
    pub fn config(&mut self, t_hw_ns: u64, config: &RunConfig) -> Result<(), LogError> {
        let now = shared_mem_schema::process::mono_now_ns();
        // The configuration first: it opens an episode's messages for the
        // live view's late viewers ([`ws`]), the scene below among them.
        let text = serde_json::to_string(config).expect("configurations serialise");
        self.write(Stream::Config, t_hw_ns, now, text.as_bytes())?;
        if self.opts.foxglove {
            self.load_arm(&config.robot);
            self.task = Some(config.world.task.clone());
            // The arm's links and the peg, drawn in the frames /tf moves.
            if let Some(Ok(arm)) = &self.arm {
                let mut entities = scene::arm(arm.model(), t_hw_ns);
                if config.world.task.enabled
                    && let Some(v) = arm.tip_to_sensor()
                {
                    entities.push(scene::peg(
                        t_hw_ns,
                        "peg_tip",
                        v,
                        config.world.task.peg_width_m,
                    ));
                }
                scene::scene_update(&mut self.json, &entities);
                self.write_json(Stream::Scene, t_hw_ns, now)?;
            }
        }
        Ok(())
    }

    /// Makes `robot` the arm the views place, loading it unless it is the
    /// one already loaded (or already failed).
    fn load_arm(&mut self, robot: &str) {
        let same = match &self.arm {
            Some(Ok(a)) => a.robot == robot,
            Some(Err(r)) => r == robot,
            None => false,
        };
        if !same {
            self.arm = Some(arm::ArmFrames::load(robot).map_err(|e| {
                eprintln!(
                    "learner: {}: the robot {robot:?} did not load ({e}); the views go on \
                     without the arm's links",
                    self.path.display()
                );
                robot.to_string()
            }));
        }
    }

    /// Writes the summary and index; the file is complete after this.
    pub fn finish(mut self) -> Result<PathBuf, LogError> {
        self.w.finish().map_err(|e| self.err(e))?;
        Ok(self.path)
    }
}
