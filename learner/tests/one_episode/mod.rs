//! One short heuristic episode of the square peg, collected through the
//! fast path: the smallest real log a reader test can damage (shared by
//! dataset_inputs.rs and fuzz_readers.rs).

use learner::collect::{CollectConfig, collect_fast};
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Collects one 24-action heuristic episode into `dir` in `world`, with
/// `seed`; returns its log.
pub fn collect_one(dir: &Path, world: hw_sim::WorldConfig, seed: u64) -> PathBuf {
    let cfg = CollectConfig {
        out_dir: dir.to_path_buf(),
        states: u64::MAX,
        episodes: Some(1),
        episode_actions: 24,
        pegs: vec![hw_sim::PegShape::Square],
        seed,
        workers: 1,
        world,
        controller: rt_controller::ControllerConfig::default(),
        mix: Mix {
            heuristic_fraction: 1.0,
            ..Mix::default()
        },
        log: LogOptions {
            foxglove: false,
            ..LogOptions::default()
        },
        resume: false,
    };
    let summary = collect_fast(&cfg, &AtomicBool::new(false)).unwrap();
    summary.shards[0].file.clone()
}
