//! Label balance of a dataset: how its samples split by the task stage
//! reached, contact and motion (stats.json's `balance`, shown by `learner
//! dataset inspect`). A collection whose episodes outlast the insertion
//! weights the data towards a peg resting at the bottom; this makes it
//! visible.

use learner_node::mix::EpisodePolicy;
use serde::{Deserialize, Serialize};
use shared_mem_schema::Stage;

/// A sample counts as moving when the tip moves more than this between its
/// frame and the next (50 ms later: 5 mm/s), m. The heuristic's slowest
/// deliberate motion (0.5 mm steps near a surface) is twice that; a peg
/// resting on the bottom moves less than a tenth of it.
pub const MOVING_M: f64 = 0.00025;

/// What the balance needs of one sample besides its contact label.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleTags {
    /// The best stage the episode had reached by the sample's frame.
    pub stage: Stage,
    /// The tip moved more than [`MOVING_M`] until the next frame.
    pub moving: bool,
}

/// Counts of one policy's samples at one stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StageCounts {
    /// Samples.
    pub samples: u64,
    /// Of them, in contact.
    pub contact: u64,
    /// Of them, moving.
    pub moving: u64,
}

impl StageCounts {
    fn add(&mut self, other: &StageCounts) {
        self.samples += other.samples;
        self.contact += other.contact;
        self.moving += other.moving;
    }
}

/// Sample counts per policy and per stage reached (indexed by
/// [`Stage::code`]: failed, touched, inserted, completed).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Balance {
    /// Heuristic episodes.
    pub heuristic: [StageCounts; 4],
    /// Random episodes.
    pub random: [StageCounts; 4],
    /// Episodes of a trained policy (absent from datasets built before
    /// there were any).
    #[serde(default)]
    pub learned: [StageCounts; 4],
    /// Imported episodes (`learner dataset import`; absent before).
    #[serde(default)]
    pub imported: [StageCounts; 4],
}

impl Balance {
    /// Counts one sample.
    pub fn add(&mut self, policy: EpisodePolicy, tags: SampleTags, contact: bool) {
        let row = match policy {
            EpisodePolicy::Heuristic => &mut self.heuristic,
            EpisodePolicy::Random => &mut self.random,
            EpisodePolicy::Learned => &mut self.learned,
            EpisodePolicy::Imported => &mut self.imported,
        };
        let c = &mut row[tags.stage.code() as usize];
        c.samples += 1;
        c.contact += contact as u64;
        c.moving += tags.moving as u64;
    }

    /// One policy's counts summed over the stages.
    pub fn policy_total(&self, policy: EpisodePolicy) -> StageCounts {
        let row = match policy {
            EpisodePolicy::Heuristic => &self.heuristic,
            EpisodePolicy::Random => &self.random,
            EpisodePolicy::Learned => &self.learned,
            EpisodePolicy::Imported => &self.imported,
        };
        let mut t = StageCounts::default();
        for c in row {
            t.add(c);
        }
        t
    }

    /// All samples' counts.
    pub fn total(&self) -> StageCounts {
        let mut t = self.policy_total(EpisodePolicy::Heuristic);
        t.add(&self.policy_total(EpisodePolicy::Random));
        t.add(&self.policy_total(EpisodePolicy::Learned));
        t.add(&self.policy_total(EpisodePolicy::Imported));
        t
    }

    /// A Markdown table: per policy and stage reached, the share of all
    /// samples and, within the row, the shares in contact and moving.
    pub fn table(&self) -> String {
        let all = self.total().samples.max(1) as f64;
        let pct = |n: u64, of: u64| {
            if of == 0 {
                "–".to_string()
            } else {
                format!("{:.1} %", 100.0 * n as f64 / of as f64)
            }
        };
        let line = |policy: &str, stage: &str, c: &StageCounts| {
            format!(
                "| {policy} | {stage} | {} | {:.1} % | {} | {} |\n",
                c.samples,
                100.0 * c.samples as f64 / all,
                pct(c.contact, c.samples),
                pct(c.moving, c.samples)
            )
        };
        let mut out = String::from(
            "| policy | stage reached | samples | of all | in contact | moving |\n\
             |---|---|---|---|---|---|\n",
        );
        for (policy, row) in [
            (EpisodePolicy::Heuristic, &self.heuristic),
            (EpisodePolicy::Random, &self.random),
            (EpisodePolicy::Learned, &self.learned),
        ] {
            if policy == EpisodePolicy::Learned && self.policy_total(policy).samples == 0 {
                continue;
            }
            for stage in Stage::ALL {
                let c = &row[stage.code() as usize];
                if c.samples > 0 {
                    out += &line(policy.name(), stage.name(), c);
                }
            }
            out += &line(policy.name(), "all", &self.policy_total(policy));
        }
        out += &line("all", "all", &self.total());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_table() {
        let mut b = Balance::default();
        let tag = |stage, moving| SampleTags { stage, moving };
        for _ in 0..3 {
            b.add(EpisodePolicy::Heuristic, tag(Stage::Completed, false), true);
        }
        b.add(EpisodePolicy::Heuristic, tag(Stage::Failed, true), false);
        b.add(EpisodePolicy::Random, tag(Stage::Touched, true), true);
        assert_eq!(
            b.heuristic[3],
            StageCounts {
                samples: 3,
                contact: 3,
                moving: 0
            }
        );
        assert_eq!(b.total().samples, 5);
        assert_eq!(b.total().moving, 2);
        let t = b.table();
        assert!(
            t.contains("| heuristic | completed | 3 | 60.0 % | 100.0 % | 0.0 % |"),
            "{t}"
        );
        assert!(
            t.contains("| all | all | 5 | 100.0 % | 80.0 % | 40.0 % |"),
            "{t}"
        );
        assert!(
            !t.contains("| random | failed"),
            "empty rows are left out: {t}"
        );
    }
}
