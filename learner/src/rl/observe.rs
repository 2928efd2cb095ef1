//! Which observer a training run, an evaluation or a distillation uses
//! ([`ObservationKind`]). The observers deployed policies act through
//! ([`GroundTruth`], [`HoleError`], the representation's z means) and the
//! view every observer reads ([`ObsView`]) are the node's
//! ([`learner_node::observe`]); the raw-input baseline's is training-only
//! ([`super::raw`]).

pub use learner_node::observe::{GROUND_TRUTH_DIM, GroundTruth, HoleError, ObsView, Observer};
use serde::{Deserialize, Serialize};

/// Refuses a world camera (`camera`, the world's `[camera]`) that is not
/// the one `observer` was trained for.
pub fn check_camera(
    camera: &hw_sim::config::CameraConfig,
    observer: &dyn Observer,
) -> Result<(), super::env::RlEnvError> {
    check_calibration(camera, observer.camera())
}

/// Refuses a world camera (`camera`) that is not `trained` (the camera a
/// representation, or the dataset it learns from, was made through; `None`:
/// any camera).
pub fn check_calibration(
    camera: &hw_sim::config::CameraConfig,
    trained: Option<shared_mem_schema::CameraCalibration>,
) -> Result<(), super::env::RlEnvError> {
    use learner_node::observe::CameraMismatch;
    learner_node::observe::check_calibration(camera, trained).map_err(|e| match e {
        CameraMismatch::Invalid(f) => f.into(),
        CameraMismatch::Other { world, model } => super::env::RlEnvError::Camera { world, model },
    })
}

/// Which observer a configuration asks for: `observation = "ground_truth"`,
/// `{ representation = "runs/full/model" }`, `{ ground_truth_hole_error =
/// 0.006 }` or `{ raw = { side = 16 } }`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationKind {
    /// [`GroundTruth`].
    #[default]
    GroundTruth,
    /// The z means of the representation exported into this directory by
    /// `learner repr train` (its `model/`).
    Representation(std::path::PathBuf),
    /// [`GroundTruth`] with the hole believed displaced by a per-episode
    /// error of this standard deviation per horizontal axis, m
    /// (`observation = { ground_truth_hole_error = 0.003 }`):
    /// [`HoleError`].
    GroundTruthHoleError(f64),
    /// The representation's inputs without the representation
    /// (`observation = { raw = { side = 16 } }`): the raw-input baseline,
    /// [`super::raw::RawObserver`].
    Raw(super::raw::RawSpec),
}

impl ObservationKind {
    /// Whether a policy trained on `self` takes `other`'s observations as
    /// the same inputs: equal kinds, or the ground truth with and without a
    /// hole error (the same 18 values, one told less precisely).
    pub fn same_inputs(&self, other: &Self) -> bool {
        use ObservationKind::{GroundTruth as G, GroundTruthHoleError as E};
        matches!((self, other), (G | E(_), G | E(_))) || self == other
    }

    /// The observer (loading a representation's model from its file),
    /// encoding on every core.
    pub fn observer(&self) -> Result<std::sync::Arc<dyn Observer>, super::env::RlEnvError> {
        self.observer_on(0)
    }

    /// The same, a representation encoding on at most `threads` cores (0:
    /// all), as a run's `threads` setting asks.
    pub fn observer_on(
        &self,
        threads: usize,
    ) -> Result<std::sync::Arc<dyn Observer>, super::env::RlEnvError> {
        Ok(match self {
            ObservationKind::GroundTruth => std::sync::Arc::new(GroundTruth),
            ObservationKind::GroundTruthHoleError(std_m) => {
                if !(std_m.is_finite() && *std_m >= 0.0) {
                    return Err(shared_mem_schema::config::FieldError::new(
                        "observation.ground_truth_hole_error",
                        std_m,
                        "must be a standard deviation in metres, 0 or more",
                    )
                    .into());
                }
                std::sync::Arc::new(HoleError { std_m: *std_m })
            }
            ObservationKind::Raw(spec) => std::sync::Arc::new(super::raw::RawObserver::new(*spec)?),
            ObservationKind::Representation(dir) => std::sync::Arc::new(
                super::represent::load_on(dir, threads)
                    .map_err(|e| super::env::RlEnvError::Representation(e.to_string()))?,
            ),
        })
    }
}

/// [`HoleError`] whose standard deviation grows over training (the
/// training aid `training.hole_error_ramp_steps`, docs/rl.md): the
/// training loop sets the share of the ramp done before each update, so a
/// policy first learns to reach the opening told exactly and then, as the
/// error grows, to find it by touch. Validation and evaluation observe
/// through a plain [`HoleError`] at the full deviation.
#[derive(Debug)]
pub struct RampedHoleError {
    /// The full standard deviation per horizontal axis, m.
    pub std_m: f64,
    /// The share of `std_m` in use.
    share: super::env::Share,
}

impl RampedHoleError {
    /// Starts at no error.
    pub fn new(std_m: f64) -> Self {
        Self {
            std_m,
            share: super::env::Share::default(),
        }
    }

    /// Uses `share` (clamped to 0..1; not finite: 1) of the full deviation
    /// from now on.
    pub fn set_share(&self, share: f64) {
        self.share.set(share);
    }

    /// The deviation in use, m.
    pub fn current_std_m(&self) -> f64 {
        self.std_m * self.share.get()
    }
}

impl Observer for RampedHoleError {
    fn dim(&self) -> usize {
        GROUND_TRUTH_DIM
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        HoleError {
            std_m: self.current_std_m(),
        }
        .observe(views, out)
    }
}
