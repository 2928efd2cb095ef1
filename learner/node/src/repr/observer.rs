//! The frozen representation as the policy's observation (paper, "Policy
//! Learning": the policy takes the mean of the learned representation): a
//! trained model's z means of the camera frame, the wrench window and the
//! proprioception of every environment, encoded as one batch.

use super::inputs::{InputError, ObservationRef};
use crate::observe::{ObsView, Observer};
use crate::policy::WRENCH_WINDOW;
use crate::proprio::PROPRIO;
use shared_mem_schema::CameraCalibration;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// A trained representation that gives z means: the deployed one
/// ([`super::DeployedEncoder`]) or the training crate's.
pub trait ZEncoder: Send {
    /// Latent size d.
    fn dim(&self) -> usize;
    /// The camera of its training images, when known.
    fn camera(&self) -> Option<CameraCalibration>;
    /// The z means of `obs`, `obs.len()` × d values, row after row; refuses
    /// an observation of another size than the model's or not finite.
    fn encode(&self, obs: &[ObservationRef<'_>]) -> Result<Vec<f32>, InputError>;
}

/// z means of a trained representation, encoded a batch at a time.
pub struct Representation {
    encoder: Mutex<Box<dyn ZEncoder>>,
    dim: usize,
    camera: Option<CameraCalibration>,
    rejected: AtomicU64,
}

impl Representation {
    /// Around an encoder.
    pub fn new(encoder: Box<dyn ZEncoder>) -> Self {
        Self {
            dim: encoder.dim(),
            camera: encoder.camera(),
            encoder: Mutex::new(encoder),
            rejected: AtomicU64::new(0),
        }
    }

    /// Batches it refused (a camera frame of another size or another
    /// camera than the model's, a value that is not finite): their
    /// observations were written as zeros.
    pub fn rejected(&self) -> u64 {
        self.rejected.load(Ordering::Relaxed)
    }
}

/// The 32×6 wrench window of a view as the encoder takes it
/// ([`crate::policy::WrenchHistory::padded`]).
fn window(v: &ObsView<'_>) -> Vec<f32> {
    let mut out = Vec::with_capacity(WRENCH_WINDOW * 6);
    for r in v.wrench.padded() {
        out.extend(r.iter().map(|&x| x as f32));
    }
    out
}

impl Observer for Representation {
    fn dim(&self) -> usize {
        self.dim
    }

    fn rejected(&self) -> u64 {
        Representation::rejected(self)
    }

    fn needs_camera(&self) -> bool {
        true
    }

    fn camera(&self) -> Option<CameraCalibration> {
        self.camera
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let windows: Vec<Vec<f32>> = views.iter().map(window).collect();
        let proprios: Vec<[f32; PROPRIO]> =
            views.iter().map(|v| v.obs.proprio.to_array()).collect();
        let mut obs = Vec::with_capacity(views.len());
        for (i, v) in views.iter().enumerate() {
            let Some(cam) = v.camera else {
                break;
            };
            // Another camera's frame is refused like a frame of another
            // size (the environment and the live node check the world's
            // camera before the first step; this catches a frame that
            // still differs).
            if self
                .camera
                .is_some_and(|c| !c.same_camera(&cam.calibration))
            {
                break;
            }
            let (w, h) = (
                cam.calibration.width as usize,
                cam.calibration.height as usize,
            );
            obs.push(ObservationRef {
                rgb: &cam.rgb[..(3 * w * h).min(cam.rgb.len())],
                depth: &cam.depth_m[..(w * h).min(cam.depth_m.len())],
                wrench: &windows[i],
                proprio: &proprios[i],
            });
        }
        let z = if obs.len() == views.len() {
            let enc = self.encoder.lock().unwrap_or_else(|e| e.into_inner());
            enc.encode(&obs).ok()
        } else {
            None
        };
        match z {
            Some(z) if z.len() == out.len() => {
                for (o, x) in out.iter_mut().zip(z) {
                    *o = x as f64;
                }
            }
            _ => {
                // `encode` checks sizes (a frame of another size than the
                // model's) and finiteness; the policy gets zeros and the
                // count says so.
                self.rejected.fetch_add(1, Ordering::Relaxed);
                out.fill(0.0);
            }
        }
    }
}
