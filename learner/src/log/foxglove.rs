//! Foxglove's well-known schemas, JSON-encoded (schema encoding
//! `jsonschema`, message encoding `json`), so that Foxglove shows a log's
//! images, transforms and plots without any extension. Field names and
//! types follow the published schemas (docs.foxglove.dev, "Schemas"):
//! `foxglove.RawImage`, `foxglove.CameraCalibration`,
//! `foxglove.FrameTransforms` and `foxglove.PoseInFrame`. Byte fields are
//! base64 strings and times are `{"sec", "nsec"}` objects, as Foxglove's
//! JSON encoding wants them.
//!
//! These channels are for people; the lossless raw channels beside them are
//! what training reads.

use std::fmt::Write;

/// `foxglove.RawImage`.
pub const RAW_IMAGE: &str = r#"{"title":"foxglove.RawImage","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},
"encoding":{"type":"string"},"step":{"type":"integer"},
"data":{"type":"string","contentEncoding":"base64"}}}"#;

/// `foxglove.CameraCalibration`.
pub const CAMERA_CALIBRATION: &str = r#"{"title":"foxglove.CameraCalibration","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},
"distortion_model":{"type":"string"},"D":{"type":"array","items":{"type":"number"}},
"K":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"R":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"P":{"type":"array","items":{"type":"number"},"minItems":12,"maxItems":12}}}"#;

/// `foxglove.FrameTransforms`.
pub const FRAME_TRANSFORMS: &str = r#"{"title":"foxglove.FrameTransforms","type":"object","properties":{
"transforms":{"type":"array","items":{"type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},
"translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}}"#;

/// `foxglove.PoseInFrame`.
pub const POSE_IN_FRAME: &str = r#"{"title":"foxglove.PoseInFrame","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"pose":{"type":"object","properties":{
"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}"#;

/// The wrist wrench for plots (Foxglove has no wrench schema).
pub const WRENCH: &str = r#"{"title":"vision_touch.Wrench","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},
"force":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"torque":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"force_norm":{"type":"number"}}}"#;

/// Base frame name in the transforms.
pub const BASE_FRAME: &str = "base";
/// End-effector (peg tip) frame name.
pub const EE_FRAME: &str = "ee";
/// Camera optical frame name (x right, y down, z forward: Foxglove's camera
/// convention too).
pub const CAMERA_FRAME: &str = "camera";
/// F/T sensor frame name.
pub const SENSOR_FRAME: &str = "ft_sensor";

fn time(out: &mut String, t_ns: u64) {
    let _ = write!(
        out,
        r#"{{"sec":{},"nsec":{}}}"#,
        t_ns / 1_000_000_000,
        t_ns % 1_000_000_000
    );
}

/// Writes a finite number (JSON has no NaN or infinity: those become null).
fn num(out: &mut String, x: f64) {
    if x.is_finite() {
        let _ = write!(out, "{x}");
    } else {
        out.push_str("null");
    }
}

fn xyz(out: &mut String, v: &[f64]) {
    out.push_str(r#"{"x":"#);
    num(out, v[0]);
    out.push_str(r#","y":"#);
    num(out, v[1]);
    out.push_str(r#","z":"#);
    num(out, v[2]);
    out.push('}');
}

fn quat(out: &mut String, q: &[f64; 4]) {
    out.push_str(r#"{"x":"#);
    num(out, q[0]);
    out.push_str(r#","y":"#);
    num(out, q[1]);
    out.push_str(r#","z":"#);
    num(out, q[2]);
    out.push_str(r#","w":"#);
    num(out, q[3]);
    out.push('}');
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 (RFC 4648, padded).
pub fn base64_into(out: &mut String, bytes: &[u8]) {
    out.reserve(bytes.len().div_ceil(3) * 4);
    let mut chunks = bytes.chunks_exact(3);
    for c in &mut chunks {
        let n = (c[0] as u32) << 16 | (c[1] as u32) << 8 | c[2] as u32;
        for shift in [18, 12, 6, 0] {
            out.push(B64[(n >> shift & 63) as usize] as char);
        }
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let n = (rest[0] as u32) << 16 | rest.get(1).map_or(0, |&b| (b as u32) << 8);
        out.push(B64[(n >> 18 & 63) as usize] as char);
        out.push(B64[(n >> 12 & 63) as usize] as char);
        out.push(if rest.len() == 2 {
            B64[(n >> 6 & 63) as usize] as char
        } else {
            '='
        });
        out.push('=');
    }
}

/// A `foxglove.RawImage`: `encoding` is `rgb8` or `32FC1`, `step` the bytes
/// per row.
pub fn raw_image(
    out: &mut String,
    t_ns: u64,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) {
    out.clear();
    out.push_str(r#"{"timestamp":"#);
    time(out, t_ns);
    let _ = write!(
        out,
        r#","frame_id":"{CAMERA_FRAME}","width":{width},"height":{height},"encoding":"{encoding}","step":{step},"data":""#
    );
    base64_into(out, data);
    out.push_str("\"}");
}

/// A `foxglove.CameraCalibration` of an undistorted pinhole camera.
pub fn camera_calibration(
    out: &mut String,
    t_ns: u64,
    width: u32,
    height: u32,
    focal_px: f64,
    principal_px: [f64; 2],
) {
    let (f, cx, cy) = (focal_px, principal_px[0], principal_px[1]);
    out.clear();
    out.push_str(r#"{"timestamp":"#);
    time(out, t_ns);
    let _ = write!(
        out,
        r#","frame_id":"{CAMERA_FRAME}","width":{width},"height":{height},"distortion_model":"plumb_bob","D":[0,0,0,0,0],"K":[{f},0,{cx},0,{f},{cy},0,0,1],"R":[1,0,0,0,1,0,0,0,1],"P":[{f},0,{cx},0,0,{f},{cy},0,0,0,1,0]}}"#
    );
}

/// One transform of a `foxglove.FrameTransforms`.
pub struct Transform<'a> {
    /// Parent frame.
    pub parent: &'a str,
    /// Child frame.
    pub child: &'a str,
    /// Child origin in the parent, m.
    pub translation: [f64; 3],
    /// Child orientation in the parent (x, y, z, w).
    pub rotation_xyzw: [f64; 4],
}

/// A `foxglove.FrameTransforms`.
pub fn frame_transforms(out: &mut String, t_ns: u64, transforms: &[Transform]) {
    out.clear();
    out.push_str(r#"{"transforms":["#);
    for (i, tf) in transforms.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str(r#"{"timestamp":"#);
        time(out, t_ns);
        let _ = write!(
            out,
            r#","parent_frame_id":"{}","child_frame_id":"{}","translation":"#,
            tf.parent, tf.child
        );
        xyz(out, &tf.translation);
        out.push_str(r#","rotation":"#);
        quat(out, &tf.rotation_xyzw);
        out.push('}');
    }
    out.push_str("]}");
}

/// A `foxglove.PoseInFrame`.
pub fn pose_in_frame(out: &mut String, t_ns: u64, frame: &str, pos: &[f64; 3], q: &[f64; 4]) {
    out.clear();
    out.push_str(r#"{"timestamp":"#);
    time(out, t_ns);
    let _ = write!(out, r#","frame_id":"{frame}","pose":{{"position":"#);
    xyz(out, pos);
    out.push_str(r#","orientation":"#);
    quat(out, q);
    out.push_str("}}");
}

/// A `vision_touch.Wrench` (force N, torque N m).
pub fn wrench(out: &mut String, t_ns: u64, w: &[f64; 6]) {
    out.clear();
    out.push_str(r#"{"timestamp":"#);
    time(out, t_ns);
    let _ = write!(out, r#","frame_id":"{SENSOR_FRAME}","force":"#);
    xyz(out, &w[..3]);
    out.push_str(r#","torque":"#);
    xyz(out, &w[3..]);
    out.push_str(r#","force_norm":"#);
    num(out, (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt());
    out.push('}');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_rfc_vectors() {
        // RFC 4648, section 10.
        for (plain, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            let mut s = String::new();
            base64_into(&mut s, plain.as_bytes());
            assert_eq!(s, enc);
        }
    }

    #[test]
    fn messages_are_valid_json_with_the_schema_fields() {
        let mut s = String::new();
        raw_image(&mut s, 1_500_000_000, 2, 1, "rgb8", 6, &[1, 2, 3, 4, 5, 6]);
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["timestamp"]["sec"], 1);
        assert_eq!(v["timestamp"]["nsec"], 500_000_000);
        assert_eq!(v["data"], "AQIDBAUG");
        assert_eq!(v["step"], 6);
        camera_calibration(&mut s, 0, 128, 128, 154.5, [64.0, 64.0]);
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["K"].as_array().unwrap().len(), 9);
        assert_eq!(v["P"].as_array().unwrap().len(), 12);
        frame_transforms(
            &mut s,
            7,
            &[Transform {
                parent: BASE_FRAME,
                child: EE_FRAME,
                translation: [0.5, 0.0, f64::NAN],
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            }],
        );
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["transforms"][0]["child_frame_id"], "ee");
        assert!(v["transforms"][0]["translation"]["z"].is_null());
        pose_in_frame(
            &mut s,
            7,
            BASE_FRAME,
            &[1.0, 2.0, 3.0],
            &[0.0, 0.0, 0.0, 1.0],
        );
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["pose"]["position"]["y"], 2.0);
        wrench(&mut s, 7, &[3.0, 4.0, 0.0, 0.1, 0.2, 0.3]);
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["force_norm"], 5.0);
        for schema in [
            RAW_IMAGE,
            CAMERA_CALIBRATION,
            FRAME_TRANSFORMS,
            POSE_IN_FRAME,
            WRENCH,
        ] {
            serde_json::from_str::<serde_json::Value>(schema).unwrap();
        }
    }
}
