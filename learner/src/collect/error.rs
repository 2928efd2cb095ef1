//! Why a collection, or one of its episodes, failed.

use crate::fast_env::EnvError;
use learner_node::log::LogError;
use std::path::PathBuf;

/// Why a collection (or one of its episodes) failed; names the file or
/// episode at fault.
#[derive(Debug, thiserror::Error)]
pub enum CollectError {
    /// No pegs were given.
    #[error("no pegs to collect with")]
    NoPegs,
    /// Episodes of zero actions were asked for.
    #[error("episodes need at least one action")]
    NoActions,
    /// The world has no task (its hole pose is unknown).
    #[error("the world has no task")]
    NoTask,
    /// The output directory already holds a collection and resuming was
    /// not asked for.
    #[error(
        "{}: already holds a collection ({episodes} episodes in manifest.jsonl); resume it or \
         collect into another directory",
        dir.display()
    )]
    NotEmpty {
        /// The directory.
        dir: PathBuf,
        /// Episodes its manifest lists.
        episodes: usize,
    },
    /// An episode on file was collected with another seed or peg than this
    /// collection would give it.
    #[error("{}: episode {episode}: {detail}; resume with the same settings or collect into another directory", dir.display())]
    Mismatch {
        /// The directory.
        dir: PathBuf,
        /// The episode.
        episode: u64,
        /// What differs.
        detail: String,
    },
    /// A line of the manifest is not an episode record.
    #[error("{}: line {line}: {detail}", path.display())]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// Its line, from 1.
        line: usize,
        /// Why.
        detail: String,
    },
    /// The world has no box.
    #[error("the world has no box")]
    NoBox,
    /// A file or directory of the collection could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The environment failed.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// The episode's log could not be written.
    #[error(transparent)]
    Log(#[from] LogError),
    /// One episode failed.
    #[error("episode {episode} ({}): {source}", path.display())]
    Episode {
        /// Episode number.
        episode: u64,
        /// Its log.
        path: PathBuf,
        /// Why.
        #[source]
        source: Box<CollectError>,
    },
}
