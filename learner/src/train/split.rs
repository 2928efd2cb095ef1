//! Training and test splits by episode: no episode has samples on both
//! sides, and the test split is never trained on.

use crate::dataset::Meta;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use stack_common::rng;

/// Which episodes are in which split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Split {
    /// Episode numbers for training, ascending.
    pub train: Vec<u32>,
    /// Episode numbers held out for testing, ascending.
    pub test: Vec<u32>,
    /// The dataset's camera when the run started (absent from runs started
    /// before it was kept): a resume on a dataset of another camera is
    /// refused, so that the export's camera is the one the model saw.
    #[serde(default)]
    pub camera: Option<shared_mem_schema::CameraCalibration>,
}

impl Split {
    /// Draws `test_fraction` of each peg's episodes (at least one where a peg
    /// has two or more) for testing, seeded; the rest train.
    pub fn by_episode(meta: &Meta, test_fraction: f64, seed: u64) -> Self {
        let mut rng = rng::seeded(seed, 47);
        let mut by_peg: std::collections::BTreeMap<String, Vec<u32>> = Default::default();
        for e in &meta.episodes {
            by_peg
                .entry(format!("{:?}", e.peg))
                .or_default()
                .push(e.episode);
        }
        let (mut train, mut test) = (Vec::new(), Vec::new());
        for (_, mut eps) in by_peg {
            eps.shuffle(&mut rng);
            let mut k = (test_fraction * eps.len() as f64).round() as usize;
            if test_fraction > 0.0 && eps.len() >= 2 {
                k = k.clamp(1, eps.len() - 1);
            }
            test.extend_from_slice(&eps[..k.min(eps.len())]);
            train.extend_from_slice(&eps[k.min(eps.len())..]);
        }
        train.sort_unstable();
        test.sort_unstable();
        Self {
            train,
            test,
            camera: meta.camera,
        }
    }

    /// Reads a run's split.json, checking every episode it names is in
    /// `meta`.
    pub fn read(path: &std::path::Path, meta: &Meta) -> super::Result<Self> {
        let bad = |what: String| super::TrainError::BadFile {
            path: path.to_path_buf(),
            what,
        };
        let text = std::fs::read(path).map_err(super::io_err(path))?;
        let split: Self = serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))?;
        let known: std::collections::HashSet<u32> =
            meta.episodes.iter().map(|e| e.episode).collect();
        if let Some(e) = split
            .train
            .iter()
            .chain(&split.test)
            .find(|e| !known.contains(e))
        {
            return Err(bad(format!(
                "episode {e} is not in the dataset: another dataset than the run's?"
            )));
        }
        // `samples` searches the lists by bisection: each must ascend, each
        // episode once.
        for (name, list) in [("train", &split.train), ("test", &split.test)] {
            if let Some(w) = list.windows(2).find(|w| w[0] >= w[1]) {
                return Err(bad(format!(
                    "{name} must list its episodes ascending, each once: {} before {}",
                    w[0], w[1]
                )));
            }
        }
        // Held-out accuracy is only held out if no episode is in both.
        let train: std::collections::HashSet<u32> = split.train.iter().copied().collect();
        if let Some(e) = split.test.iter().find(|e| train.contains(e)) {
            return Err(bad(format!(
                "episode {e} is in both train and test: the test split must be held out"
            )));
        }
        if let Some(run) = split.camera {
            match meta.camera {
                Some(now) if now.same_camera(&run) => {}
                now => {
                    return Err(bad(format!(
                        "the run started on a dataset of the camera {run}; this dataset's is {}: \
                         another dataset than the run's?",
                        now.map_or("not recorded".to_string(), |c| c.to_string())
                    )));
                }
            }
        }
        Ok(split)
    }

    /// A membership table indexed by episode number, for
    /// [`crate::dataset::LoaderConfig::episodes`].
    pub fn table(episodes: &[u32]) -> Vec<bool> {
        let n = episodes.iter().max().map_or(0, |&m| m as usize + 1);
        let mut t = vec![false; n];
        for &e in episodes {
            t[e as usize] = true;
        }
        t
    }

    /// Samples of the episodes `episodes` in `meta`.
    pub fn samples(meta: &Meta, episodes: &[u32]) -> u64 {
        meta.episodes
            .iter()
            .filter(|e| episodes.binary_search(&e.episode).is_ok())
            .map(|e| e.samples)
            .sum()
    }
}
