//! The raw-input baseline's observer (issue 51 item 4: how much the
//! representation saves a learner against learning from its inputs). It
//! reads what the representation's encoders read, without an encoder: the
//! camera frame average-pooled to `side`×`side` (RGB / 255, then depth in
//! metres, a pixel without a return 0), the 32×6 wrench window (force /
//! 10 N, moment / 1 N·m, oldest first, as the encoder's window pads it)
//! and the proprioception, flattened. Nothing privileged: no task state,
//! no hole pose. Training and evaluation only: the node has no deployed
//! format for it (`policy export` refuses it by name).

use super::observe::{ObsView, Observer};
use learner_node::policy::WRENCH_WINDOW;
use learner_node::proprio::PROPRIO;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};

/// `observation = { raw = { side = 16 } }`: the pooled image's side, px.
/// A side above the camera's repeats its pixels (every cell holds at
/// least one), so no frame size leaves the image blank.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSpec {
    /// Side of the pooled image, px (1 to [`MAX_SIDE`]).
    pub side: usize,
}

/// The largest pooled side accepted: the largest side of a camera frame
/// on shared memory (256 px).
pub const MAX_SIDE: usize = 256;

/// Force scale of the wrench window, N (moments are in N·m as read).
const FORCE_SCALE_N: f64 = 10.0;

/// The raw-input observer of [`RawSpec`].
#[derive(Debug)]
pub struct RawObserver {
    side: usize,
    rejected: AtomicU64,
}

impl RawObserver {
    /// The observer of `spec`; refuses a side of 0 or over [`MAX_SIDE`].
    pub fn new(spec: RawSpec) -> Result<Self, shared_mem_schema::config::FieldError> {
        if spec.side == 0 || spec.side > MAX_SIDE {
            return Err(shared_mem_schema::config::FieldError::new(
                "observation.raw.side",
                spec.side,
                format!("must be a pooled image side from 1 to {MAX_SIDE} px"),
            ));
        }
        Ok(Self {
            side: spec.side,
            rejected: AtomicU64::new(0),
        })
    }

    /// Values of the image part: RGB and depth, `side`² each channel.
    fn image_len(&self) -> usize {
        4 * self.side * self.side
    }

    /// The pooled image of `cam` into `out` (channel-first: R, G, B,
    /// depth); `false` (and `out` untouched) for an empty frame or one
    /// shorter than its calibration says.
    fn pool(&self, cam: &shared_mem_schema::CameraFrame, out: &mut [f64]) -> bool {
        let (w, h) = (
            cam.calibration.width as usize,
            cam.calibration.height as usize,
        );
        let s = self.side;
        if w == 0 || h == 0 || cam.rgb.len() < 3 * w * h || cam.depth_m.len() < w * h {
            return false;
        }
        let plane = s * s;
        for r in 0..s {
            // Pixel row y falls in cell row ⌊y·s/h⌋; a cell no pixel falls
            // in (s > h) takes its nearest.
            let y0 = (r * h).div_ceil(s).min(h - 1);
            let y1 = ((r + 1) * h).div_ceil(s).clamp(y0 + 1, h);
            for c in 0..s {
                let x0 = (c * w).div_ceil(s).min(w - 1);
                let x1 = ((c + 1) * w).div_ceil(s).clamp(x0 + 1, w);
                let mut acc = [0.0f64; 4];
                for y in y0..y1 {
                    for x in x0..x1 {
                        let p = y * w + x;
                        for (k, a) in acc.iter_mut().take(3).enumerate() {
                            *a += f64::from(cam.rgb[3 * p + k]) / 255.0;
                        }
                        let d = f64::from(cam.depth_m[p]);
                        acc[3] += if d.is_finite() && d > 0.0 { d } else { 0.0 };
                    }
                }
                let n = ((y1 - y0) * (x1 - x0)) as f64;
                for (k, a) in acc.iter().enumerate() {
                    out[k * plane + r * s + c] = a / n;
                }
            }
        }
        true
    }
}

impl Observer for RawObserver {
    fn dim(&self) -> usize {
        self.image_len() + 6 * WRENCH_WINDOW + PROPRIO
    }

    fn needs_camera(&self) -> bool {
        true
    }

    fn rejected(&self) -> u64 {
        self.rejected.load(Ordering::Relaxed)
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let dim = self.dim();
        let img = self.image_len();
        for (v, o) in views.iter().zip(out.chunks_exact_mut(dim)) {
            let (image, rest) = o.split_at_mut(img);
            let (wrench, proprio) = rest.split_at_mut(6 * WRENCH_WINDOW);
            let mut bad = !v.camera.is_some_and(|cam| self.pool(cam, image));
            if bad {
                image.fill(0.0);
            }
            for (r, slot) in v.wrench.padded().zip(wrench.chunks_exact_mut(6)) {
                for (k, (x, y)) in r.iter().zip(slot.iter_mut()).enumerate() {
                    *y = if k < 3 { x / FORCE_SCALE_N } else { *x };
                }
            }
            for (x, y) in v.obs.proprio.to_array().iter().zip(proprio.iter_mut()) {
                *y = f64::from(*x);
            }
            // A value that is not finite reaches no policy: zero, counted.
            for x in o.iter_mut().filter(|x| !x.is_finite()) {
                *x = 0.0;
                bad = true;
            }
            if bad {
                self.rejected.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}
