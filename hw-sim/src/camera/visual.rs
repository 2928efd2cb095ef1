//! Pictures for people: flow as colour, depth as grey.

use super::*;

/// Colours a flow field (direction as hue, magnitude as saturation up to
/// `max_px`), the usual visualisation.
pub fn flow_to_rgb(frame: &CameraFrame, max_px: f32) -> Vec<u8> {
    let mut out = vec![255u8; frame.flow_px.len() * 3];
    for (i, f) in frame.flow_px.iter().enumerate() {
        if frame.flow_mask[i] != 0 {
            out[3 * i..3 * i + 3].copy_from_slice(&flow_colour(f[0], f[1], max_px));
        }
    }
    out
}

/// The colour of one flow vector (u, v) px: direction as hue, magnitude as
/// saturation up to `max_px` (white: no flow).
pub fn flow_colour(u: f32, v: f32, max_px: f32) -> [u8; 3] {
    let mag = (u.hypot(v) / max_px).min(1.0);
    let hue = (v.atan2(u) / std::f32::consts::TAU).rem_euclid(1.0) * 6.0;
    let x = 1.0 - ((hue % 2.0) - 1.0).abs();
    let (r, g, b) = match hue as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c| (255.0 * (1.0 - mag * (1.0 - c))) as u8)
}

/// Depth as 8-bit grey (near bright, far dark, no return black).
pub fn depth_to_gray(frame: &CameraFrame, near_m: f32, far_m: f32) -> Vec<u8> {
    frame
        .depth_m
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                0
            } else {
                (255.0 * (1.0 - ((d - near_m) / (far_m - near_m)).clamp(0.0, 1.0))) as u8
            }
        })
        .collect()
}
