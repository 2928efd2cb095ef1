//! The small dataset the representation's tests train on, shared by
//! repr_train.rs and experiment.rs (each test binary collects it once).

use learner::collect::{CollectConfig, collect_fast};
use learner::dataset::{self, BuildConfig};
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

/// The images' side, px.
pub const SIDE: u32 = 64;

/// One dataset for every test of a binary: 8 heuristic episodes of 100
/// actions (5 s: approach, insertion, and pressing at the bottom, where
/// contact is), two pegs.
pub fn dataset() -> &'static Path {
    static DIR: OnceLock<(test_support::ScratchDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let root = test_support::scratch_dir("repr-data");
        let logs = root.join("logs");
        let mut world = hw_sim::WorldConfig::default();
        world.task.enabled = true;
        world.camera.width = SIDE;
        world.camera.height = SIDE;
        let cfg = CollectConfig {
            out_dir: logs.clone(),
            states: u64::MAX,
            episodes: Some(8),
            episode_actions: 100,
            pegs: vec![hw_sim::PegShape::Square, hw_sim::PegShape::Hexagon],
            seed: 21,
            workers: 2,
            world,
            controller: rt_controller::ControllerConfig::default(),
            mix: Mix {
                heuristic_fraction: 1.0,
                end_after_completion: None,
                ..Mix::default()
            },
            log: LogOptions {
                view_rate_hz: 10.0,
                ..LogOptions::default()
            },
            resume: false,
        };
        collect_fast(&cfg, &AtomicBool::new(false)).unwrap();
        let out = root.join("ds");
        let files = dataset::find_logs(std::slice::from_ref(&logs)).unwrap();
        let b = BuildConfig {
            block_samples: 16,
            ..BuildConfig::default()
        };
        dataset::build(&files, &out, &b, 2, |p, r| {
            if let Err(e) = r {
                panic!("{}: {e}", p.display());
            }
        })
        .unwrap();
        (root, out)
    })
    .1
}
