//! A rendered frame and the calibration as the stack's camera message.

use super::*;

/// Copies a rendered frame and the camera's calibration into the stack's
/// message (everything but the header). Frames larger than the message's
/// maximum are cut to it; hw-sim refuses such camera sizes before.
pub fn fill_message(
    camera: &Camera,
    frame: &CameraFrame,
    msg: &mut shared_mem_schema::CameraFrame,
) {
    let w = (frame.width as usize).min(shared_mem_schema::MAX_IMAGE_WIDTH);
    let h = (frame.height as usize).min(shared_mem_schema::MAX_IMAGE_HEIGHT);
    msg.index = frame.index;
    msg.calibration = camera.calibration();
    msg.calibration.width = w as u32;
    msg.calibration.height = h as u32;
    let stride = frame.width as usize;
    for v in 0..h {
        let (src, dst) = (v * stride, v * w);
        msg.rgb[3 * dst..3 * (dst + w)].copy_from_slice(&frame.rgb[3 * src..3 * (src + w)]);
        msg.depth_m[dst..dst + w].copy_from_slice(&frame.depth_m[src..src + w]);
    }
}
