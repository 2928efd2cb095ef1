//! Foxglove's well-known schemas, JSON-encoded (schema encoding
//! `jsonschema`, message encoding `json`), so that Foxglove shows a log's
//! images, transforms and plots without any extension. Field names and
//! types follow the published schemas (docs.foxglove.dev, "Schemas"):
//! `foxglove.RawImage`, `foxglove.CameraCalibration`,
//! `foxglove.FrameTransforms` and `foxglove.PoseInFrame`; and the JSON
//! schemas of our own JSON channels (`vision_touch.Wrench`, `.Event`,
//! `.Config`), so that every channel describes itself. Byte fields are
//! base64 strings and times are `{"sec", "nsec"}` objects, as Foxglove's
//! JSON encoding wants them.
//!
//! These channels are for people; the lossless raw channels beside them are
//! what training reads.

use base64::Engine;
use serde::Serialize;

/// `foxglove.RawImage`.
pub const RAW_IMAGE: &str = r#"{"title":"foxglove.RawImage","type":"object","required":["timestamp","frame_id","width","height","encoding","step","data"],"properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},
"encoding":{"type":"string"},"step":{"type":"integer"},
"data":{"type":"string","contentEncoding":"base64"}}}"#;

/// `foxglove.CameraCalibration`.
pub const CAMERA_CALIBRATION: &str = r#"{"title":"foxglove.CameraCalibration","type":"object","required":["timestamp","frame_id","width","height","distortion_model","D","K","R","P"],"properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"width":{"type":"integer"},"height":{"type":"integer"},
"distortion_model":{"type":"string"},"D":{"type":"array","items":{"type":"number"}},
"K":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"R":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"P":{"type":"array","items":{"type":"number"},"minItems":12,"maxItems":12}}}"#;

/// `foxglove.FrameTransforms`.
pub const FRAME_TRANSFORMS: &str = r#"{"title":"foxglove.FrameTransforms","type":"object","required":["transforms"],"properties":{
"transforms":{"type":"array","items":{"type":"object","required":["timestamp","parent_frame_id","child_frame_id","translation","rotation"],"properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},
"translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}}"#;

/// `foxglove.PoseInFrame`.
pub const POSE_IN_FRAME: &str = r#"{"title":"foxglove.PoseInFrame","type":"object","required":["timestamp","frame_id","pose"],"properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},"pose":{"type":"object","required":["position","orientation"],"properties":{
"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}"#;

/// The wrist wrench for plots (Foxglove has no wrench schema).
pub const WRENCH: &str = r#"{"title":"vision_touch.Wrench","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_id":{"type":"string"},
"force":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"torque":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"force_norm":{"type":"number"}}}"#;

/// `/events`' messages (`log::events::Event`), one schema for the three
/// kinds, told apart by `event`.
pub const EVENT: &str = r#"{"title":"vision_touch.Event","type":"object","required":["event"],
"description":"An episode event: reset (what it started from), stage (a better stage reached), outcome (how it ended)",
"properties":{
"event":{"enum":["reset","stage","outcome"]},
"episode":{"type":"integer","minimum":0},"seed":{"type":"integer","minimum":0},
"peg":{"enum":["square","triangle","semicircle","hexagon"]},
"policy":{"enum":["heuristic","random","learned","imported"]},
"lockstep":{"type":"boolean"},
"world":{"type":"object","description":"hw-sim's WorldConfig sent with a live reset (docs/hw-sim.md)"},
"hole_pos_m":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3,"description":"hole top centre, base frame, m"},
"hole_quat_xyzw":{"type":"array","items":{"type":"number"},"minItems":4,"maxItems":4},
"hole_depth_m":{"type":"number"},
"stage":{"enum":["failed","touched","inserted","completed"]},
"duration_s":{"type":"number"},"actions":{"type":"integer","minimum":0},
"states":{"type":"integer","minimum":0},"interrupted":{"type":"boolean"}}}"#;

/// `/config`'s messages (`log::config::RunConfig`).
pub const CONFIG: &str = r#"{"title":"vision_touch.Config","type":"object",
"required":["mode","world","robot","policy","episode","seed"],
"description":"The configuration one episode ran with",
"properties":{
"mode":{"enum":["live","fast"]},
"world":{"type":"object","description":"hw-sim's WorldConfig (docs/hw-sim.md)"},
"robot":{"type":"string","description":"robot description: a built-in name or a URDF path"},
"policy":{"enum":["heuristic","random","learned","imported"]},
"episode":{"type":"integer","minimum":0},"seed":{"type":"integer","minimum":0},
"lockstep":{"type":"boolean"},"namespace":{"type":"string"},
"controller":{"type":"object","description":"rt-controller's ControllerConfig (fast mode)"}}}"#;

/// Base frame name in the transforms.
pub const BASE_FRAME: &str = "base";
/// End-effector (peg tip) frame name.
pub const EE_FRAME: &str = "ee";
/// Camera optical frame name (x right, y down, z forward: Foxglove's camera
/// convention too).
pub const CAMERA_FRAME: &str = "camera";
/// F/T sensor frame name.
pub const SENSOR_FRAME: &str = "ft_sensor";

/// A time as Foxglove's JSON encoding wants it.
#[derive(Serialize)]
pub(crate) struct Time {
    sec: u64,
    nsec: u64,
}

impl Time {
    pub(crate) fn of(t_ns: u64) -> Self {
        Self {
            sec: t_ns / 1_000_000_000,
            nsec: t_ns % 1_000_000_000,
        }
    }
}

/// A vector as Foxglove's JSON encoding wants it.
#[derive(Serialize)]
pub(crate) struct Xyz {
    x: f64,
    y: f64,
    z: f64,
}

impl Xyz {
    pub(crate) fn of(v: &[f64]) -> Self {
        Self {
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }
}

/// A rotation (quaternion) as Foxglove's JSON encoding wants it.
#[derive(Serialize)]
pub(crate) struct Quat {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

impl Quat {
    pub(crate) fn of(q: &[f64; 4]) -> Self {
        let [x, y, z, w] = *q;
        Self { x, y, z, w }
    }
}

/// An isometry's translation and its rotation `[x, y, z, w]`.
pub(crate) fn parts(iso: &nalgebra::Isometry3<f64>) -> ([f64; 3], [f64; 4]) {
    let t = iso.translation.vector;
    let r = iso.rotation;
    ([t.x, t.y, t.z], [r.i, r.j, r.k, r.w])
}

/// Serialises `msg` into `out` (cleared first). Non-finite numbers become
/// `null`, as JSON has no NaN.
fn to_json(out: &mut Vec<u8>, msg: &impl Serialize) {
    out.clear();
    serde_json::to_writer(&mut *out, msg).expect("view messages serialise");
}

/// A `foxglove.RawImage`: `encoding` is `rgb8` or `32FC1`, `step` the bytes
/// per row; `data` is sent base64-encoded.
pub fn raw_image(
    out: &mut Vec<u8>,
    t_ns: u64,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) {
    #[derive(Serialize)]
    struct RawImage<'a> {
        timestamp: Time,
        frame_id: &'a str,
        width: u32,
        height: u32,
        encoding: &'a str,
        step: u32,
        data: String,
    }
    let msg = RawImage {
        timestamp: Time::of(t_ns),
        frame_id: CAMERA_FRAME,
        width,
        height,
        encoding,
        step,
        data: base64::engine::general_purpose::STANDARD.encode(data),
    };
    to_json(out, &msg);
}

/// A `foxglove.CameraCalibration` of an undistorted pinhole camera.
pub fn camera_calibration(
    out: &mut Vec<u8>,
    t_ns: u64,
    width: u32,
    height: u32,
    focal_px: f64,
    principal_px: [f64; 2],
) {
    #[derive(Serialize)]
    #[allow(non_snake_case)] // the schema's field names
    struct CameraCalibration<'a> {
        timestamp: Time,
        frame_id: &'a str,
        width: u32,
        height: u32,
        distortion_model: &'a str,
        D: [f64; 5],
        K: [f64; 9],
        R: [f64; 9],
        P: [f64; 12],
    }
    let (f, cx, cy) = (focal_px, principal_px[0], principal_px[1]);
    let msg = CameraCalibration {
        timestamp: Time::of(t_ns),
        frame_id: CAMERA_FRAME,
        width,
        height,
        distortion_model: "plumb_bob",
        D: [0.0; 5],
        K: [f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0],
        R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P: [f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    };
    to_json(out, &msg);
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
pub fn frame_transforms(out: &mut Vec<u8>, t_ns: u64, transforms: &[Transform]) {
    #[derive(Serialize)]
    struct FrameTransform<'a> {
        timestamp: Time,
        parent_frame_id: &'a str,
        child_frame_id: &'a str,
        translation: Xyz,
        rotation: Quat,
    }
    #[derive(Serialize)]
    struct FrameTransforms<'a> {
        transforms: Vec<FrameTransform<'a>>,
    }
    let msg = FrameTransforms {
        transforms: transforms
            .iter()
            .map(|tf| FrameTransform {
                timestamp: Time::of(t_ns),
                parent_frame_id: tf.parent,
                child_frame_id: tf.child,
                translation: Xyz::of(&tf.translation),
                rotation: Quat::of(&tf.rotation_xyzw),
            })
            .collect(),
    };
    to_json(out, &msg);
}

/// A `foxglove.PoseInFrame`.
pub fn pose_in_frame(out: &mut Vec<u8>, t_ns: u64, frame: &str, pos: &[f64; 3], q: &[f64; 4]) {
    #[derive(Serialize)]
    struct Pose {
        position: Xyz,
        orientation: Quat,
    }
    #[derive(Serialize)]
    struct PoseInFrame<'a> {
        timestamp: Time,
        frame_id: &'a str,
        pose: Pose,
    }
    let msg = PoseInFrame {
        timestamp: Time::of(t_ns),
        frame_id: frame,
        pose: Pose {
            position: Xyz::of(pos),
            orientation: Quat::of(q),
        },
    };
    to_json(out, &msg);
}

/// A `vision_touch.Wrench` (force N, torque N m).
pub fn wrench(out: &mut Vec<u8>, t_ns: u64, w: &[f64; 6]) {
    #[derive(Serialize)]
    struct Wrench<'a> {
        timestamp: Time,
        frame_id: &'a str,
        force: Xyz,
        torque: Xyz,
        force_norm: f64,
    }
    let msg = Wrench {
        timestamp: Time::of(t_ns),
        frame_id: SENSOR_FRAME,
        force: Xyz::of(&w[..3]),
        torque: Xyz::of(&w[3..]),
        force_norm: (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt(),
    };
    to_json(out, &msg);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_valid_json_with_the_schema_fields() {
        let mut s = Vec::new();
        raw_image(&mut s, 1_500_000_000, 2, 1, "rgb8", 6, &[1, 2, 3, 4, 5, 6]);
        let v: serde_json::Value = serde_json::from_slice(&s).unwrap();
        assert_eq!(v["timestamp"]["sec"], 1);
        assert_eq!(v["timestamp"]["nsec"], 500_000_000);
        assert_eq!(v["data"], "AQIDBAUG");
        assert_eq!(v["step"], 6);
        camera_calibration(&mut s, 0, 128, 128, 154.5, [64.0, 64.0]);
        let v: serde_json::Value = serde_json::from_slice(&s).unwrap();
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
        let v: serde_json::Value = serde_json::from_slice(&s).unwrap();
        assert_eq!(v["transforms"][0]["child_frame_id"], "ee");
        assert!(v["transforms"][0]["translation"]["z"].is_null());
        pose_in_frame(
            &mut s,
            7,
            BASE_FRAME,
            &[1.0, 2.0, 3.0],
            &[0.0, 0.0, 0.0, 1.0],
        );
        let v: serde_json::Value = serde_json::from_slice(&s).unwrap();
        assert_eq!(v["pose"]["position"]["y"], 2.0);
        wrench(&mut s, 7, &[3.0, 4.0, 0.0, 0.1, 0.2, 0.3]);
        let v: serde_json::Value = serde_json::from_slice(&s).unwrap();
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
