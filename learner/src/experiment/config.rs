//! The experiment's configuration: its stages (data, representation,
//! policy, evaluation) and its variants.

use crate::train::DeviceKind;
use anyhow::{Context, Result, bail, ensure};
use hw_sim::PegShape;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// An experiment (TOML; see configs/experiments/).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// The dataset every representation trains on.
    pub data: DataStage,
    /// The representation stage.
    #[serde(default)]
    pub representation: ReprStage,
    /// The policy stage.
    #[serde(default)]
    pub policy: PolicyStage,
    /// The evaluation.
    #[serde(default)]
    pub eval: EvalStage,
    /// The variants compared.
    pub variant: Vec<Variant>,
}

/// Where the dataset is, and how to make it when it is not there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataStage {
    /// The built dataset (used as it is when it opens).
    pub dataset: PathBuf,
    /// When it is absent: collect this many 20 Hz states on the fast path
    /// (`collect_pegs`, the default heuristic/random mix, in the policy
    /// configuration's world and controller) and build it. 0: a missing
    /// dataset is an error.
    #[serde(default)]
    pub collect_states: u64,
    /// Seed of the collection's first episode.
    #[serde(default = "one")]
    pub collect_seed: u64,
    /// The pegs collected, taken in turn (empty: all four). One peg gives
    /// the paper's transfer experiments a representation that has never
    /// seen the others.
    #[serde(default)]
    pub collect_pegs: Vec<PegShape>,
    /// A hw-sim world file to collect in instead of the policy
    /// configuration's world, whose camera it must share (a dataset of the
    /// box turned for a policy trained with it square, or of noisy
    /// sensors). Relative to the working directory.
    #[serde(default)]
    pub collect_world: Option<PathBuf>,
}

fn one() -> u64 {
    1
}

/// Representation training, shared by the variants.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReprStage {
    /// Epochs (overrides each variant's configuration; the paper: 20).
    pub epochs: Option<u32>,
    /// Batch size (overrides each variant's configuration).
    pub batch: Option<usize>,
    /// Where the representations train: `"cpu"` (the default), or a GPU
    /// through `"vulkan"` or `"cuda"` (a learner built with that feature).
    pub device: DeviceKind,
}

/// Policy training, shared by the variants.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyStage {
    /// The base training configuration (`learner policy train`'s; absent:
    /// its defaults, the paper's TRPO). Its observation is replaced by the
    /// variant's.
    pub config: Option<PathBuf>,
    /// Environment steps (overrides the base; the paper: 1M).
    pub env_steps: Option<u64>,
    /// In place of `config`: a `learner policy distill` configuration. The
    /// student observes the variant's z means, and the search teacher's
    /// probe (`[search_teacher.probe]`) reads the same representation, so
    /// each variant's teacher knows the opening only as well as its z tells
    /// it. For the ground-truth variant the probe is dropped: the search is
    /// told the hole with the configuration's `hole_error_m`. The policy
    /// evaluated is the last round's (DAgger has no best-logged update).
    ///
    /// Or the learned route: a distillation whose `teacher` is a trained
    /// checkpoint on the ground truth (a learned searching teacher,
    /// privileged, in the teacher only), the same teacher for every
    /// variant, each variant's student on its own z. A teacher that
    /// observes a representation is refused (it would read its own model,
    /// not the variant's).
    pub distill: Option<PathBuf>,
    /// With `distill`: DAgger's rounds (overrides the distillation's).
    pub dagger_rounds: Option<u64>,
    /// With `distill`: a `learner policy train` configuration (PPO) that
    /// then fine-tunes each variant's student on its own z, starting from
    /// it (`init_from`; the observation replaced by the variant's). The
    /// policy evaluated is then the fine-tune's best validated one.
    pub finetune: Option<PathBuf>,
    /// Training seeds: each variant's policy is trained (distilled,
    /// fine-tuned) once per seed, each evaluated on the same episodes, and
    /// the row pools them with each seed's count beside. Empty: once, with
    /// the policy configuration's own seed.
    pub seeds: Vec<u64>,
}

/// The evaluation of every policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalStage {
    /// Episodes per policy and peg (the paper: 50).
    pub episodes: usize,
    /// Seed of the first evaluation episode (training seeds start at the
    /// run's seed; these are far from them).
    pub seed: u64,
    /// Pegs evaluated on (absent: the one the policy trained on). Another
    /// peg than the training one is the paper's transfer.
    pub pegs: Vec<PegShape>,
}

impl Default for EvalStage {
    fn default() -> Self {
        Self {
            episodes: 50,
            seed: 1_000_000,
            pegs: Vec::new(),
        }
    }
}

/// One compared model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    /// Its name in tables and charts (also its directory).
    pub name: String,
    /// The representation's training configuration; absent: the policy
    /// observes the privileged ground truth (a reference, not in the paper).
    pub representation: Option<PathBuf>,
    /// A representation already trained with `representation`'s
    /// configuration on `data.dataset` (its exported model directory): used
    /// as it is instead of training the variant's own. Its `model.json`'s
    /// epochs, architecture and dataset must be the variant's (checked), for
    /// the comparison to be fair.
    #[serde(default)]
    pub model: Option<PathBuf>,
    /// The paper's completed-insertion share for it, where the paper's text
    /// gives one (0..1).
    pub paper_completed: Option<f64>,
}

impl ExperimentConfig {
    /// Reads and checks a configuration file.
    pub fn from_file(path: &Path) -> Result<Self> {
        Self::from_file_with(path, &[])
    }

    /// [`ExperimentConfig::from_file`] with `sets` (`KEY=VALUE`, dotted
    /// paths into the file's tables) applied before it is checked.
    pub fn from_file_with(path: &Path, sets: &[String]) -> Result<Self> {
        let cfg: Self = if sets.is_empty() {
            shared_mem_schema::config::read_toml(path)?
        } else {
            crate::settings::read_with_overrides(Some(path), sets)?
        };
        cfg.validate()
            .with_context(|| format!("{}", path.display()))?;
        Ok(cfg)
    }

    /// Checks the values, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        ensure!(!self.variant.is_empty(), "variant: at least one is needed");
        ensure!(self.eval.episodes > 0, "eval.episodes: must be at least 1");
        if self.policy.distill.is_some() {
            ensure!(
                self.policy.config.is_none() && self.policy.env_steps.is_none(),
                "policy.distill: give either a distillation (distill = …, its length its \
                 dagger.rounds) or a training configuration (config, env_steps), not both"
            );
        } else {
            ensure!(
                self.policy.dagger_rounds.is_none() && self.policy.finetune.is_none(),
                "policy.dagger_rounds, policy.finetune: they follow a distillation (distill = …)"
            );
        }
        ensure!(
            self.policy.dagger_rounds != Some(0),
            "policy.dagger_rounds: must be at least 1"
        );
        for (i, s) in self.policy.seeds.iter().enumerate() {
            ensure!(
                !self.policy.seeds[..i].contains(s),
                "policy.seeds: {s} is given twice"
            );
        }
        for (i, v) in self.variant.iter().enumerate() {
            ensure!(
                !v.name.is_empty()
                    && !v.name.starts_with('.')
                    && v.name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_.=".contains(c)),
                "variant[{i}].name `{}`: letters, digits and - _ . = only, not starting with a \
                 dot (it names a directory)",
                v.name
            );
            if v.model.is_some() && v.representation.is_none() {
                bail!(
                    "variant[{i}].model: needs the representation configuration it was trained \
                     with (representation = …)"
                );
            }
            if let Some(p) = v.paper_completed {
                ensure!(
                    (0.0..=1.0).contains(&p),
                    "variant[{i}].paper_completed {p}: must be within 0..1"
                );
            }
            ensure!(
                !self.variant[..i].iter().any(|w| w.name == v.name),
                "variant[{i}].name `{}`: used twice",
                v.name
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rl::distill;
    use crate::rl::run as policy_run;
    use crate::train;

    /// Every shipped experiment loads; the paper-scale one trains its
    /// representations on the GPU through Vulkan, the others on the CPU;
    /// the old `cuda = true` is refused, naming the field.
    #[test]
    fn the_shipped_experiments_load_and_name_their_device() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let dir = root.join("configs/experiments");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_none_or(|x| x != "toml") {
                continue;
            }
            let cfg = ExperimentConfig::from_file(&p)
                .unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            // The paper-scale experiments are for a GPU machine.
            let paper_scale = p
                .file_stem()
                .is_some_and(|s| s.to_string_lossy().ends_with("_paper"));
            let expected = if paper_scale {
                DeviceKind::Vulkan
            } else {
                DeviceKind::Cpu
            };
            assert_eq!(cfg.representation.device, expected, "{}", p.display());
            // The files it names load too: a typo there would otherwise
            // surface hours into a run. (Paths are the repository root's.)
            let at = |f: &Path| format!("{}: {}", p.display(), f.display());
            if let Some(f) = &cfg.policy.distill {
                distill::read_config(&root.join(f)).unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            for f in [&cfg.policy.config, &cfg.policy.finetune]
                .into_iter()
                .flatten()
            {
                policy_run::read_config(&root.join(f)).unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            if let Some(f) = &cfg.data.collect_world {
                hw_sim::WorldConfig::from_file(&root.join(f))
                    .unwrap_or_else(|e| panic!("{}: {e}", at(f)));
            }
            for v in &cfg.variant {
                if let Some(f) = &v.representation {
                    train::ReprTrainConfig::from_file(&root.join(f))
                        .unwrap_or_else(|e| panic!("{}: {e}", at(f)));
                }
            }
            n += 1;
        }
        assert!(n >= 3, "{n} experiments in {}", dir.display());
        // The shipped distillations load too, those no experiment names
        // among them (docs/results.md runs them by themselves).
        let dir = root.join("configs/distill");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                distill::read_config(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                n += 1;
            }
        }
        assert!(n >= 4, "{n} distillations in {}", dir.display());
        let e = toml::from_str::<ReprStage>("cuda = true").unwrap_err();
        assert!(e.to_string().contains("cuda"), "{e}");
        let r: ReprStage = toml::from_str("device = \"vulkan\"").unwrap();
        assert_eq!(r.device, DeviceKind::Vulkan);
    }

    /// A distillation beside a training configuration, and a trained model
    /// without the configuration it was trained with, are refused by name.
    #[test]
    fn contradictory_policy_and_model_settings_are_refused() {
        let base = "[data]\ndataset = \"d\"\n\n[[variant]]\nname = \"Full\"\n";
        for (extra, field) in [
            (
                "[policy]\ndistill = \"a.toml\"\nconfig = \"b.toml\"\n",
                "policy.distill",
            ),
            (
                "[policy]\ndistill = \"a.toml\"\nenv_steps = 5\n",
                "policy.distill",
            ),
            ("", "variant[0].model"),
            ("[policy]\nfinetune = \"f.toml\"\n", "policy.finetune"),
            (
                "[policy]\ndistill = \"a.toml\"\ndagger_rounds = 0\n",
                "policy.dagger_rounds",
            ),
        ] {
            let mut text = format!("{extra}{base}");
            if extra.is_empty() {
                text += "model = \"m\"\n";
            }
            let cfg: ExperimentConfig = toml::from_str(&text).unwrap();
            let e = cfg.validate().unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
        let ok: ExperimentConfig =
            toml::from_str(&format!("[policy]\ndistill = \"a.toml\"\n{base}")).unwrap();
        ok.validate().unwrap();
    }
}
