//! What the learner writes for other tools and later readers: TensorBoard
//! scalar event files ([`tensorboard`]), a run's provenance
//! ([`provenance`], `run.json`) and safetensors weights ([`safetensors`]:
//! the exported policy, and the representation under the PyTorch twin's
//! names, [`repr_export`]).

pub mod provenance;
pub mod repr_export;
pub mod safetensors;
pub mod tensorboard;

pub use provenance::record_start;
pub use tensorboard::ScalarLog;
