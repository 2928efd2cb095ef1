//! Self-describing schemas for the raw channels: ROS 2 message definitions
//! (MCAP schema encoding `ros2msg`, message encoding `cdr`), which Foxglove
//! and the official `mcap` readers (`mcap-ros2-support`) decode.
//!
//! Why this encoding: a raw message stays the shared-mem-schema struct's
//! bytes, lossless and read back without conversion. The structs are
//! `#[repr(C)]` with every field at its natural alignment and no padding,
//! and little-endian CDR (XCDR1, the encapsulation ROS 2 uses) lays out
//! primitives at their natural alignment counted from the payload's start,
//! with fixed-size arrays unprefixed. So a CDR message is the 4-byte
//! encapsulation header followed by the struct's bytes. The definitions
//! below are checked field by field against the structs (this module's
//! tests) and decoded by the official reader (learner/tests/interop.rs).
//! Camera frames carry their image as CDR sequences (a `u32` length, then
//! the elements) sized to the image, not to the largest one.

use shared_mem_schema::{HISTOGRAM_BINS, MAX_JOINTS, MAX_MESSAGE_BYTES};

/// The MCAP schema encoding of these definitions.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The MCAP message encoding of the raw channels.
pub const MESSAGE_ENCODING: &str = "cdr";
/// The CDR encapsulation header of a little-endian plain-CDR payload.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The package the message types are named in.
pub const PACKAGE: &str = "vision_touch";

/// A primitive type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prim {
    /// `uint8`.
    U8,
    /// `uint32`.
    U32,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
}

impl Prim {
    fn name(self) -> &'static str {
        match self {
            Prim::U8 => "uint8",
            Prim::U32 => "uint32",
            Prim::U64 => "uint64",
            Prim::F32 => "float32",
            Prim::F64 => "float64",
        }
    }

    /// Size and CDR alignment, bytes.
    pub fn size(self) -> usize {
        match self {
            Prim::U8 => 1,
            Prim::U32 | Prim::F32 => 4,
            Prim::U64 | Prim::F64 => 8,
        }
    }
}

/// A field's type.
#[derive(Debug, Clone, Copy)]
pub enum Ty {
    /// One primitive.
    One(Prim),
    /// A fixed-size array of primitives.
    Array(Prim, usize),
    /// A sequence of primitives (a `u32` length, then the elements).
    Seq(Prim),
    /// A nested message.
    Msg(&'static MsgDef),
}

/// A message definition: its type name and fields, in the struct's order.
#[derive(Debug)]
pub struct MsgDef {
    /// The type's name in [`PACKAGE`].
    pub name: &'static str,
    /// The fields.
    pub fields: &'static [(&'static str, Ty)],
}

use Prim::*;
use Ty::*;

/// `shared_mem_schema::Header`.
pub static HEADER: MsgDef = MsgDef {
    name: "Header",
    fields: &[
        ("schema_version", One(U32)),
        ("flags", One(U32)),
        ("seq", One(U64)),
        ("t_mono_ns", One(U64)),
        ("t_hw_ns", One(U64)),
        ("episode", One(U64)),
    ],
};

/// `shared_mem_schema::SensorFrame`.
pub static SENSOR_FRAME: MsgDef = MsgDef {
    name: "SensorFrame",
    fields: &[
        ("header", Msg(&HEADER)),
        ("step", One(U64)),
        ("action_seq", One(U64)),
        ("n_joints", One(U32)),
        ("mode", One(U32)),
        ("fault_code", One(U32)),
        ("reserved", One(U32)),
        ("q", Array(F64, MAX_JOINTS)),
        ("v", Array(F64, MAX_JOINTS)),
        ("tau_cmd", Array(F64, MAX_JOINTS)),
        ("tau_measured", Array(F64, MAX_JOINTS)),
        ("ee_pos_m", Array(F64, 3)),
        ("ee_quat_xyzw", Array(F64, 4)),
        ("ee_twist", Array(F64, 6)),
        ("wrench", Array(F64, 6)),
        ("tau_sent", Array(F64, MAX_JOINTS)),
    ],
};

/// `shared_mem_schema::PolicyAction`.
pub static POLICY_ACTION: MsgDef = MsgDef {
    name: "PolicyAction",
    fields: &[
        ("header", Msg(&HEADER)),
        ("apply_at_step", One(U64)),
        ("delta_pos_m", Array(F64, 3)),
        ("delta_roll_rad", One(F64)),
    ],
};

/// `shared_mem_schema::LatencyHistogram`.
pub static LATENCY_HISTOGRAM: MsgDef = MsgDef {
    name: "LatencyHistogram",
    fields: &[
        ("count", One(U64)),
        ("overflow", One(U64)),
        ("max_ns", One(U64)),
        ("sum_ns", One(U64)),
        ("bins", Array(U32, HISTOGRAM_BINS)),
    ],
};

/// `shared_mem_schema::ControllerStatus`.
pub static CONTROLLER_STATUS: MsgDef = MsgDef {
    name: "ControllerStatus",
    fields: &[
        ("header", Msg(&HEADER)),
        ("cycles", One(U64)),
        ("overruns", One(U64)),
        ("actions_received", One(U64)),
        ("actions_accepted", One(U64)),
        ("actions_rejected", One(U64)),
        ("actions_overflow", One(U64)),
        ("actions_ignored", One(U64)),
        ("action_timeouts", One(U64)),
        ("faults", One(U64)),
        ("hardware_misses", One(U64)),
        ("hardware_states_skipped", One(U64)),
        ("last_action_seq", One(U64)),
        ("actions_too_old", One(U64)),
        ("actions_from_future", One(U64)),
        ("actions_other_episode", One(U64)),
        ("actions_replayed", One(U64)),
        ("resets", One(U64)),
        ("command_seq", One(U64)),
        ("mode", One(U32)),
        ("fault_code", One(U32)),
        ("realtime", One(U32)),
        ("command_result", One(U32)),
        ("wakeup_latency", Msg(&LATENCY_HISTOGRAM)),
        ("compute", Msg(&LATENCY_HISTOGRAM)),
        ("action_latency", Msg(&LATENCY_HISTOGRAM)),
    ],
};

/// `shared_mem_schema::EpisodeReport`.
pub static EPISODE_REPORT: MsgDef = MsgDef {
    name: "EpisodeReport",
    fields: &[
        ("header", Msg(&HEADER)),
        ("command_seq", One(U64)),
        ("seed", One(U64)),
        ("step", One(U64)),
        ("command_result", One(U32)),
        ("peg", One(U32)),
        ("stage_now", One(U32)),
        ("best_stage", One(U32)),
        ("in_contact", One(U32)),
        ("message_len", One(U32)),
        ("s_m", Array(F64, 3)),
        ("s_psi_rad", One(F64)),
        ("hole_pos_m", Array(F64, 3)),
        ("hole_quat_xyzw", Array(F64, 4)),
        ("peg_width_m", One(F64)),
        ("hole_depth_m", One(F64)),
        ("message", Array(U8, MAX_MESSAGE_BYTES)),
    ],
};

/// `shared_mem_schema::CameraCalibration`.
pub static CAMERA_CALIBRATION: MsgDef = MsgDef {
    name: "CameraCalibration",
    fields: &[
        ("width", One(U32)),
        ("height", One(U32)),
        ("focal_px", One(F64)),
        ("principal_px", Array(F64, 2)),
        ("pose_pos_m", Array(F64, 3)),
        ("pose_quat_xyzw", Array(F64, 4)),
    ],
};

/// `shared_mem_schema::CameraFrame` with its image as sequences of the
/// image's size (`width × height × 3` RGB bytes, `width × height` depths).
pub static CAMERA_FRAME: MsgDef = MsgDef {
    name: "CameraFrame",
    fields: &[
        ("header", Msg(&HEADER)),
        ("index", One(U64)),
        ("calibration", Msg(&CAMERA_CALIBRATION)),
        ("rgb", Seq(U8)),
        ("depth_m", Seq(F32)),
    ],
};

impl MsgDef {
    /// The MCAP schema name, `vision_touch/msg/Name`.
    pub fn schema_name(&self) -> String {
        format!("{PACKAGE}/msg/{}", self.name)
    }

    /// The `ros2msg` schema text: this definition's fields, then every
    /// nested definition once after its `MSG:` separator line.
    pub fn schema_text(&self) -> String {
        let mut out = String::new();
        self.write_fields(&mut out);
        let mut nested: Vec<&MsgDef> = Vec::new();
        self.collect_nested(&mut nested);
        for d in nested {
            out.push_str(&"=".repeat(80));
            out.push_str(&format!("\nMSG: {PACKAGE}/{}\n", d.name));
            d.write_fields(&mut out);
        }
        out
    }

    fn write_fields(&self, out: &mut String) {
        for (name, ty) in self.fields {
            let t = match ty {
                One(p) => p.name().to_string(),
                Array(p, n) => format!("{}[{n}]", p.name()),
                Seq(p) => format!("{}[]", p.name()),
                Msg(d) => format!("{PACKAGE}/{}", d.name),
            };
            out.push_str(&format!("{t} {name}\n"));
        }
    }

    fn collect_nested(&self, seen: &mut Vec<&'static MsgDef>) {
        for (_, ty) in self.fields {
            if let Msg(d) = ty {
                if !seen.iter().any(|s| s.name == d.name) {
                    seen.push(d);
                }
                d.collect_nested(seen);
            }
        }
    }

    /// The CDR offset (from the payload's start, after the encapsulation
    /// header) of every top-level field before the first sequence when
    /// this message starts at `start`, and the offset after them (for a
    /// message without sequences, its end).
    pub fn fixed_layout(&self, start: usize) -> (Vec<(&'static str, usize)>, usize) {
        let mut at = start;
        let mut out = Vec::new();
        for (name, ty) in self.fields {
            let end = match ty {
                One(p) => at.next_multiple_of(p.size()) + p.size(),
                Array(p, n) => at.next_multiple_of(p.size()) + p.size() * n,
                Msg(d) => d.fixed_layout(at).1,
                Seq(_) => break,
            };
            if let One(p) | Array(p, _) = ty {
                at = at.next_multiple_of(p.size());
            }
            out.push((*name, at));
            at = end;
        }
        (out, at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_mem_schema::{
        CameraCalibration, CameraFrame, ControllerStatus, EpisodeReport, Header, LatencyHistogram,
        PolicyAction, SensorFrame,
    };
    use std::mem::{offset_of, size_of};

    /// Every field of `def` lies where the struct has it, and the sizes
    /// agree: the struct's bytes are the CDR payload.
    macro_rules! same_layout {
        ($def:expr, $ty:ty, [$($field:ident),* $(,)?]) => {{
            let (fields, end) = $def.fixed_layout(0);
            let ours: Vec<(&str, usize)> = vec![$((stringify!($field), offset_of!($ty, $field))),*];
            assert_eq!(fields, ours, "{}", $def.name);
            assert_eq!(end, size_of::<$ty>(), "{}: size", $def.name);
        }};
    }

    #[test]
    fn every_definition_matches_its_struct_field_by_field() {
        same_layout!(
            HEADER,
            Header,
            [schema_version, flags, seq, t_mono_ns, t_hw_ns, episode]
        );
        same_layout!(
            SENSOR_FRAME,
            SensorFrame,
            [
                header,
                step,
                action_seq,
                n_joints,
                mode,
                fault_code,
                reserved,
                q,
                v,
                tau_cmd,
                tau_measured,
                ee_pos_m,
                ee_quat_xyzw,
                ee_twist,
                wrench,
                tau_sent
            ]
        );
        same_layout!(
            POLICY_ACTION,
            PolicyAction,
            [header, apply_at_step, delta_pos_m, delta_roll_rad]
        );
        same_layout!(
            LATENCY_HISTOGRAM,
            LatencyHistogram,
            [count, overflow, max_ns, sum_ns, bins]
        );
        same_layout!(
            CONTROLLER_STATUS,
            ControllerStatus,
            [
                header,
                cycles,
                overruns,
                actions_received,
                actions_accepted,
                actions_rejected,
                actions_overflow,
                actions_ignored,
                action_timeouts,
                faults,
                hardware_misses,
                hardware_states_skipped,
                last_action_seq,
                actions_too_old,
                actions_from_future,
                actions_other_episode,
                actions_replayed,
                resets,
                command_seq,
                mode,
                fault_code,
                realtime,
                command_result,
                wakeup_latency,
                compute,
                action_latency
            ]
        );
        same_layout!(
            EPISODE_REPORT,
            EpisodeReport,
            [
                header,
                command_seq,
                seed,
                step,
                command_result,
                peg,
                stage_now,
                best_stage,
                in_contact,
                message_len,
                s_m,
                s_psi_rad,
                hole_pos_m,
                hole_quat_xyzw,
                peg_width_m,
                hole_depth_m,
                message
            ]
        );
        same_layout!(
            CAMERA_CALIBRATION,
            CameraCalibration,
            [
                width,
                height,
                focal_px,
                principal_px,
                pose_pos_m,
                pose_quat_xyzw
            ]
        );
        // The camera frame's fixed head is the struct's up to its pixels.
        let (head, end) = CAMERA_FRAME.fixed_layout(0);
        let ours = [
            ("header", offset_of!(CameraFrame, header)),
            ("index", offset_of!(CameraFrame, index)),
            ("calibration", offset_of!(CameraFrame, calibration)),
        ];
        assert_eq!(head, ours);
        assert_eq!(end, offset_of!(CameraFrame, rgb));
    }

    #[test]
    fn schema_text_names_each_nested_type_once() {
        let text = CONTROLLER_STATUS.schema_text();
        assert!(text.starts_with("vision_touch/Header header\nuint64 cycles\n"));
        assert_eq!(
            text.matches("MSG: vision_touch/LatencyHistogram").count(),
            1
        );
        assert_eq!(text.matches("MSG: vision_touch/Header").count(), 1);
        assert!(text.contains("uint32[2000] bins\n"));
        assert!(
            CAMERA_FRAME
                .schema_text()
                .contains("uint8[] rgb\nfloat32[] depth_m\n")
        );
        assert_eq!(SENSOR_FRAME.schema_name(), "vision_touch/msg/SensorFrame");
    }
}
