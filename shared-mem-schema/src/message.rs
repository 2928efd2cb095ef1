//! What every message shares: the [`Header`], the [`Message`] trait (topic,
//! name, bytes), fixed-buffer text, and the layouts the schema version
//! stands for.

use crate::{
    CameraFrame, ControllerCommand, ControllerStatus, EpisodeReport, HardwareState,
    LatencyHistogram, PolicyAction, SCHEMA_VERSION, SensorFrame, SimCommand, TorqueCommand, topics,
};
use crate::{
    HISTOGRAM_BINS, MAX_CONFIG_BYTES, MAX_IMAGE_HEIGHT, MAX_IMAGE_WIDTH, MAX_JOINTS,
    MAX_MESSAGE_BYTES,
};
use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Fields every message starts with.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Pod, Zeroable)]
pub struct Header {
    /// [`SCHEMA_VERSION`] of the sender.
    pub schema_version: u32,
    /// Message-specific flags (see each message).
    pub flags: u32,
    /// Sender's sequence number, +1 per message of this stream.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` at publication, ns (one clock for all processes of
    /// a machine, so latencies between them can be measured).
    pub t_mono_ns: u64,
    /// Hardware (simulated) time of the data, ns.
    pub t_hw_ns: u64,
    /// Episode the data belongs to (hw-sim's reset counter; 0 before any).
    pub episode: u64,
}

impl Header {
    /// A header of this schema version.
    pub fn new(seq: u64, t_mono_ns: u64, t_hw_ns: u64, episode: u64) -> Self {
        Self {
            schema_version: SCHEMA_VERSION,
            flags: 0,
            seq,
            t_mono_ns,
            t_hw_ns,
            episode,
        }
    }
}

/// Copies `text` into a fixed buffer, truncated at a character boundary;
/// returns the bytes used.
pub fn write_text(buf: &mut [u8], text: &str) -> u32 {
    let mut n = text.len().min(buf.len());
    while !text.is_char_boundary(n) {
        n -= 1;
    }
    buf[..n].copy_from_slice(&text.as_bytes()[..n]);
    buf[n..].fill(0);
    n as u32
}

// The derives of `Pod` reject padding; these pin the layouts the schema
// version stands for.
const H: usize = 40;
const J: usize = 8 * MAX_JOINTS;
const _: () = assert!(size_of::<Header>() == H);
const _: () = assert!(size_of::<HardwareState>() == H + 16 + 8 + 3 * J + 48);
const _: () = assert!(size_of::<TorqueCommand>() == H + 16 + 8 + J);
const _: () = assert!(size_of::<SensorFrame>() == H + 16 + 16 + 4 * J + 8 * 19);
const _: () = assert!(size_of::<PolicyAction>() == H + 8 + 32);
const _: () = assert!(
    size_of::<CameraFrame>()
        == H + 8 + 8 + 8 + 16 + 24 + 32 + MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT * 7
);
const _: () = assert!(size_of::<LatencyHistogram>() == 32 + 4 * HISTOGRAM_BINS);
const _: () =
    assert!(size_of::<ControllerStatus>() == H + 144 + 16 + 3 * size_of::<LatencyHistogram>());
const _: () = assert!(size_of::<ControllerCommand>() == H + 8);
const _: () = assert!(size_of::<SimCommand>() == H + 16 + MAX_CONFIG_BYTES);
const _: () = assert!(size_of::<EpisodeReport>() == H + 24 + 24 + 8 * 13 + MAX_MESSAGE_BYTES);

/// A message type with its topic. Messages are plain old data (`bytemuck`):
/// their bytes are what logs store and what travels.
pub trait Message: Pod + ZeroCopySend + core::fmt::Debug {
    /// Its topic (see [`topics`]).
    const TOPIC: &'static str;
    /// Its type name, as written into logs next to [`SCHEMA_VERSION`].
    const NAME: &'static str;
    /// Its header.
    fn header(&self) -> &Header;

    /// A boxed all-zero message, built on the heap (camera frames and
    /// commands are too large for a thread's stack).
    fn boxed_zeroed() -> Box<Self> {
        bytemuck::zeroed_box()
    }

    /// The message's bytes (native endianness).
    fn as_bytes(&self) -> &[u8] {
        bytemuck::bytes_of(self)
    }

    /// A boxed copy of the message whose bytes are `bytes` (any alignment);
    /// `None` when the length differs from the message's size.
    fn read_from(bytes: &[u8]) -> Option<Box<Self>> {
        if bytes.len() != size_of::<Self>() {
            return None;
        }
        let mut b = Self::boxed_zeroed();
        bytemuck::bytes_of_mut(&mut *b).copy_from_slice(bytes);
        Some(b)
    }
}

macro_rules! message {
    ($t:ty, $topic:expr, $name:expr) => {
        impl Message for $t {
            const TOPIC: &'static str = $topic;
            const NAME: &'static str = $name;
            fn header(&self) -> &Header {
                &self.header
            }
        }
    };
}

message!(HardwareState, topics::HARDWARE_STATE, "HardwareState");
message!(TorqueCommand, topics::TORQUE_COMMAND, "TorqueCommand");
message!(SensorFrame, topics::SENSOR, "SensorFrame");
message!(PolicyAction, topics::ACTION, "PolicyAction");
message!(CameraFrame, topics::CAMERA, "CameraFrame");
message!(ControllerStatus, topics::STATUS, "ControllerStatus");
message!(
    ControllerCommand,
    topics::CONTROLLER_COMMAND,
    "ControllerCommand"
);
message!(SimCommand, topics::SIM_COMMAND, "SimCommand");
message!(EpisodeReport, topics::EPISODE, "EpisodeReport");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ControllerMode;

    #[test]
    fn bytes_round_trip() {
        let mut a = PolicyAction::boxed_zeroed();
        a.header = Header::new(7, 1, 2, 3);
        a.delta_pos_m = [0.1, -0.2, 0.3];
        a.delta_roll_rad = -0.0;
        let b = PolicyAction::read_from(a.as_bytes()).unwrap();
        assert_eq!(a.as_bytes(), b.as_bytes());
        assert!(PolicyAction::read_from(&a.as_bytes()[1..]).is_none());
        let cam = CameraFrame::boxed_zeroed();
        assert!(cam.rgb.iter().all(|&x| x == 0));
    }

    #[test]
    fn text_truncates_on_char_boundary() {
        let mut buf = [0xffu8; 5];
        let n = write_text(&mut buf, "ab€d");
        assert_eq!(n, 5);
        let n = write_text(&mut buf, "abcd€");
        assert_eq!(n, 4);
        assert_eq!(&buf, b"abcd\0");
        assert_eq!(ControllerMode::from_u32(3), Some(ControllerMode::Fault));
        assert_eq!(ControllerMode::from_u32(9), None);
    }
}
