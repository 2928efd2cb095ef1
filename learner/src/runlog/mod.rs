//! What a training run writes beside its own CSV files for other tools and
//! for later readers: TensorBoard scalar event files ([`tensorboard`]) and
//! its provenance ([`provenance`], `run.json`).

pub mod provenance;
pub mod tensorboard;

pub use provenance::record_start;
pub use tensorboard::ScalarLog;
