//! # shared-mem-schema
//!
//! Owns every message that crosses a process boundary in the stack: the 1 kHz
//! sensor frame, the 20 Hz policy action, the hardware state and torque
//! command, the camera frame and the controller status, as fixed-size
//! `#[repr(C)]` structs usable zero-copy over iceoryx2, together with the
//! service names and the schema version that two processes compare before
//! they talk.
//!
//! It must not contain logic beyond plain constructors and must not depend on
//! any other crate of this workspace.
//!
//! The messages arrive with the real-time stack; for now the crate holds the
//! schema version that every later message will carry.

/// Version of the message layout. Bump it whenever any message's layout or
/// meaning changes; peers built from different versions refuse to talk.
pub const SCHEMA_VERSION: u32 = 1;
