//! What every message shares: the schema version, the [`Header`], the
//! [`Message`] trait (topic, name, bytes) and fixed-buffer text. Each
//! message's module pins its layout (the derives of `Pod` reject padding;
//! the size checks pin what [`SCHEMA_VERSION`] stands for).

use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Version of the message layout. Bump it whenever any message's layout or
/// meaning changes; peers built from different versions refuse to talk.
/// Version 4 appended `tau_sent` to [`crate::SensorFrame`].
pub const SCHEMA_VERSION: u32 = 4;

/// The oldest schema version whose recorded messages this build still reads
/// from logs ([`Message::read_recorded`]): what was recorded stays readable.
/// Live peers must match [`SCHEMA_VERSION`] exactly.
pub const OLDEST_RECORDED_VERSION: u32 = 3;

/// Bytes of a [`Header`]: every message's layout starts with them.
pub(crate) const HEADER_BYTES: usize = 40;
const _: () = assert!(size_of::<Header>() == HEADER_BYTES);

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

/// A message type with its topic. Messages are plain old data (`bytemuck`):
/// their bytes are what logs store and what travels.
pub trait Message: Pod + ZeroCopySend + core::fmt::Debug {
    /// Its topic (see [`crate::topics`]).
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

    /// A message of an older schema version (`version`, from
    /// [`OLDEST_RECORDED_VERSION`] up) whose layout differs from this
    /// build's, brought to this build's layout; `None` where the bytes are
    /// not that version's layout. The default: the layout never changed.
    fn upgrade(_bytes: &[u8], _version: u32) -> Option<Box<Self>> {
        None
    }

    /// A recorded message from its bytes, of this build's schema version or
    /// an older one it still reads (the header keeps the recorded
    /// version). The error says what does not fit.
    fn read_recorded(bytes: &[u8]) -> Result<Box<Self>, String> {
        if bytes.len() < HEADER_BYTES {
            return Err(format!(
                "{} bytes, shorter than the {HEADER_BYTES}-byte header",
                bytes.len()
            ));
        }
        let header: Header = bytemuck::pod_read_unaligned(&bytes[..HEADER_BYTES]);
        let version = header.schema_version;
        if !(OLDEST_RECORDED_VERSION..=SCHEMA_VERSION).contains(&version) {
            return Err(format!(
                "schema version {version}; this build reads versions \
                 {OLDEST_RECORDED_VERSION} to {SCHEMA_VERSION}"
            ));
        }
        let upgraded = if version < SCHEMA_VERSION && bytes.len() != size_of::<Self>() {
            Self::upgrade(bytes, version)
        } else {
            None
        };
        upgraded.or_else(|| Self::read_from(bytes)).ok_or_else(|| {
            format!(
                "{} bytes; {} is {} bytes in schema version {SCHEMA_VERSION}",
                bytes.len(),
                Self::NAME,
                size_of::<Self>()
            )
        })
    }
}

/// Implements [`Message`] for a message type with a `header` field.
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
pub(crate) use message;
