//! A policy that travels with its representation: `learner policy package`
//! copies a training checkpoint and the representation it observes through
//! into one directory (the checkpoint naming the model as `model`, beside
//! it), so that the directory works wherever it is put, for `policy eval`,
//! `policy export` and `learner stack --policy`. What repository
//! `artifacts/` ships is made by it.
//!
//! How a checkpoint finds its representation: a relative model path is
//! taken beside the checkpoint when the model is there
//! ([`resolve_beside`]), else relative to the working directory, as
//! training wrote it (a run's `runs/full-near/model`).

use std::path::{Path, PathBuf};

use super::ObservationKind;
use super::run::{Checkpoint, RunError};

/// The name of the representation's directory inside a package.
pub const MODEL_DIR: &str = "model";

/// The file of a representation directory that marks it as one (written
/// by `learner repr train` beside `model.bpk`).
const MODEL_MARK: &str = "model.json";

/// Makes `c`'s relative representation path, when a model is found there
/// relative to `checkpoint`'s directory, that path; a package's (`model`)
/// always, so that a missing one is named there and never taken from the
/// working directory. Anything else is left as it is.
pub fn resolve_beside(checkpoint: &Path, c: &mut Checkpoint) {
    if let ObservationKind::Representation(model) = &mut c.config.observation
        && model.is_relative()
    {
        let dir = checkpoint.parent().unwrap_or(Path::new(""));
        let beside = dir.join(&*model);
        if beside.join(MODEL_MARK).is_file() || *model == Path::new(MODEL_DIR) {
            *model = beside;
        }
    }
}

/// Why a package could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PackageError {
    /// The checkpoint could not be read.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The output directory already holds something.
    #[error(
        "{0}: not empty; a package replaces what was shipped rather than adding to it, so \
         remove the directory first"
    )]
    NotEmpty(PathBuf),
    /// The representation the checkpoint names is not a model directory.
    #[error(
        "{checkpoint}: its representation {model} holds no {MODEL_MARK} (is it a `learner repr \
         train` run's model/?)"
    )]
    NoModel {
        /// The checkpoint.
        checkpoint: PathBuf,
        /// The directory it names.
        model: PathBuf,
    },
    /// Copying or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> PackageError + '_ {
    move |source| PackageError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `out/checkpoint.json` (the checkpoint, its representation named
/// `model`), `out/model/` (the representation's files) and, when the run
/// directory holds one, `out/run.json` (its provenance). `out` must be
/// absent or empty. Returns the new checkpoint's path.
pub fn package(checkpoint: &Path, out: &Path) -> Result<PathBuf, PackageError> {
    let mut c = super::run::read_checkpoint(checkpoint)?;
    if out.exists() && std::fs::read_dir(out).map_err(io(out))?.next().is_some() {
        return Err(PackageError::NotEmpty(out.to_path_buf()));
    }
    std::fs::create_dir_all(out).map_err(io(out))?;
    if let ObservationKind::Representation(model) = &mut c.config.observation {
        if !model.join(MODEL_MARK).is_file() {
            return Err(PackageError::NoModel {
                checkpoint: checkpoint.to_path_buf(),
                model: model.clone(),
            });
        }
        let dest = out.join(MODEL_DIR);
        std::fs::create_dir_all(&dest).map_err(io(&dest))?;
        for entry in std::fs::read_dir(&*model).map_err(io(model))? {
            let from = entry.map_err(io(model))?.path();
            if from.is_file() {
                let to = dest.join(from.file_name().expect("a file has a name"));
                std::fs::copy(&from, &to).map_err(io(&from))?;
            }
        }
        *model = PathBuf::from(MODEL_DIR);
    }
    let path = super::run::checkpoint_path(out);
    super::run::write_json(&path, &c)?;
    if let Some(run) = checkpoint.parent().map(|d| d.join("run.json"))
        && run.is_file()
    {
        let to = out.join("run.json");
        std::fs::copy(&run, &to).map_err(io(&run))?;
    }
    Ok(path)
}
