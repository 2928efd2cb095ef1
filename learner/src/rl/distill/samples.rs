//! What a round collects and where it is kept: the student's and the
//! teacher's observations side by side ([`Pair`]), the samples and their
//! file format ([`Samples`]), the rounds' paths.

use crate::rl::observe::{ObsView, Observer};
use crate::rl::run::RunError;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Two observers side by side: each observation is the first's values,
/// then the second's.
pub struct Pair {
    first: Arc<dyn Observer>,
    second: Arc<dyn Observer>,
}

impl Pair {
    /// `first`'s observation followed by `second`'s.
    pub fn new(first: Arc<dyn Observer>, second: Arc<dyn Observer>) -> Self {
        Self { first, second }
    }
}

impl Observer for Pair {
    fn dim(&self) -> usize {
        self.first.dim() + self.second.dim()
    }

    fn needs_camera(&self) -> bool {
        self.first.needs_camera() || self.second.needs_camera()
    }

    fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
        let (a, b) = (self.first.dim(), self.second.dim());
        let mut fa = vec![0.0; views.len() * a];
        let mut fb = vec![0.0; views.len() * b];
        self.first.observe(views, &mut fa);
        self.second.observe(views, &mut fb);
        for (i, o) in out.chunks_exact_mut(a + b).enumerate() {
            o[..a].copy_from_slice(&fa[i * a..(i + 1) * a]);
            o[a..].copy_from_slice(&fb[i * b..(i + 1) * b]);
        }
    }

    fn rejected(&self) -> u64 {
        self.first.rejected() + self.second.rejected()
    }

    /// The second's (the student's) camera, else the first's. `distill`
    /// checks each of the two against the world before it builds one.
    fn camera(&self) -> Option<shared_mem_schema::CameraCalibration> {
        self.second.camera().or_else(|| self.first.camera())
    }
}

/// One round's samples: the student's observations (as observed, not
/// normalised) and the teacher's clipped mean actions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Samples {
    /// Observation size.
    pub obs_dim: usize,
    /// Action size.
    pub act_dim: usize,
    /// Observations, samples × `obs_dim`.
    pub obs: Vec<f32>,
    /// Target actions, samples × `act_dim`.
    pub actions: Vec<f32>,
}

const MAGIC: &[u8; 8] = b"DAGGER01";

impl Samples {
    /// Samples held.
    pub fn len(&self) -> usize {
        self.actions.len() / self.act_dim.max(1)
    }

    /// True when none are held.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// The samples split by environment: rounds of a run with `num_envs`
    /// environments hold one row per environment per step, in order, so
    /// row i is environment i mod `num_envs`'s. The last `held` of them
    /// go to the second part (whole episodes); None for it when `held`
    /// is 0.
    ///
    /// # Panics
    ///
    /// If `held` exceeds `num_envs`, or the samples are not whole steps
    /// of `num_envs` rows (then no row's environment is known).
    pub fn split_envs(&self, num_envs: usize, held: usize) -> (Samples, Option<Samples>) {
        assert!(
            held <= num_envs,
            "{held} of {num_envs} environments held out"
        );
        assert!(
            num_envs > 0 && self.len().is_multiple_of(num_envs),
            "{} samples are not whole steps of {num_envs} environments",
            self.len()
        );
        let part = || Samples {
            obs_dim: self.obs_dim,
            act_dim: self.act_dim,
            ..Default::default()
        };
        if held == 0 {
            return (self.clone(), None);
        }
        let (mut fitted, mut out) = (part(), part());
        let (od, ad) = (self.obs_dim, self.act_dim);
        for i in 0..self.len() {
            let to = if i % num_envs >= num_envs - held {
                &mut out
            } else {
                &mut fitted
            };
            to.obs.extend_from_slice(&self.obs[i * od..(i + 1) * od]);
            to.actions
                .extend_from_slice(&self.actions[i * ad..(i + 1) * ad]);
        }
        (fitted, Some(out))
    }

    /// Writes the samples (a header, then little-endian f32s), atomically.
    pub fn write(&self, path: &Path) -> Result<(), RunError> {
        let mut b = Vec::with_capacity(32 + 4 * (self.obs.len() + self.actions.len()));
        b.extend_from_slice(MAGIC);
        for v in [self.obs_dim, self.act_dim, self.len()] {
            b.extend_from_slice(&(v as u64).to_le_bytes());
        }
        for v in self.obs.iter().chain(&self.actions) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        crate::write_atomic(path, &b).map_err(|source| RunError::Io {
            path: path.into(),
            source,
        })
    }

    /// Reads what [`Samples::write`] wrote; a file of another format or a
    /// truncated one is an error naming it.
    pub fn read(path: &Path) -> Result<Self, RunError> {
        let bad = |detail: String| RunError::Parse {
            path: path.into(),
            detail,
        };
        let bytes = std::fs::read(path).map_err(|source| RunError::Io {
            path: path.into(),
            source,
        })?;
        if bytes.len() < 32 || &bytes[..8] != MAGIC {
            return Err(bad("not a DAgger samples file (no DAGGER01 header)".into()));
        }
        let u = |k: usize| u64::from_le_bytes(bytes[8 + 8 * k..16 + 8 * k].try_into().unwrap());
        let (od, ad, n) = (u(0) as usize, u(1) as usize, u(2) as usize);
        let expected = od
            .checked_add(ad)
            .and_then(|per| n.checked_mul(per))
            .and_then(|v| v.checked_mul(4))
            .and_then(|b| b.checked_add(32));
        let Some(expected) = expected else {
            return Err(bad(format!(
                "a header of {n} samples of {od} + {ad} values (corrupt)"
            )));
        };
        if expected != bytes.len() {
            return Err(bad(format!(
                "{} bytes, expected {expected} for {n} samples of {od} + {ad} values (truncated?)",
                bytes.len()
            )));
        }
        let values = (expected - 32) / 4;
        let f: Vec<f32> = bytes[32..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        debug_assert_eq!(f.len(), values);
        Ok(Self {
            obs_dim: od,
            act_dim: ad,
            actions: f[n * od..].to_vec(),
            obs: f[..n * od].to_vec(),
        })
    }
}

/// Where round `round`'s samples are kept.
pub fn round_path(out: &Path, round: u64) -> PathBuf {
    out.join("rounds").join(format!("round-{round:03}.bin"))
}

/// Where round `round`'s teacher observations are kept: the same samples
/// as [`round_path`]'s, each with what the teacher observed in place of
/// what the student did (for diagnosis; a resume does not read them).
pub fn teacher_round_path(out: &Path, round: u64) -> PathBuf {
    out.join("rounds")
        .join(format!("round-{round:03}.teacher.bin"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rl::RlEnvConfig;

    /// Writes `value` `dim` times per view.
    struct Constant {
        dim: usize,
        value: f64,
    }

    impl Observer for Constant {
        fn dim(&self) -> usize {
            self.dim
        }
        fn observe(&self, views: &[ObsView<'_>], out: &mut [f64]) {
            assert_eq!(out.len(), views.len() * self.dim);
            out.fill(self.value);
        }
    }

    #[test]
    fn a_split_by_environment_keeps_each_environments_rows_together() {
        // 3 environments, 2 steps: rows 0..6, environment = row mod 3.
        let s = Samples {
            obs_dim: 2,
            act_dim: 1,
            obs: (0..12).map(|v| v as f32).collect(),
            actions: (0..6).map(|v| v as f32).collect(),
        };
        let (fitted, held) = s.split_envs(3, 1);
        let held = held.unwrap();
        assert_eq!(fitted.actions, [0.0, 1.0, 3.0, 4.0]);
        assert_eq!(fitted.obs, [0.0, 1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 9.0]);
        assert_eq!(held.actions, [2.0, 5.0]);
        assert_eq!(held.obs, [4.0, 5.0, 10.0, 11.0]);
        let (all, none) = s.split_envs(3, 0);
        assert_eq!((all, none), (s, None));
    }

    /// The teacher's values first, then the student's, per environment:
    /// what `collect` splits at the teacher's size.
    #[test]
    fn a_pair_puts_the_first_observers_values_first() {
        let mut env = crate::rl::RlEnv::new(&RlEnvConfig::default()).unwrap();
        env.reset(1, false).unwrap();
        let pair = Pair::new(
            Arc::new(Constant { dim: 2, value: 1.0 }),
            Arc::new(Constant { dim: 3, value: 2.0 }),
        );
        assert_eq!(pair.dim(), 5);
        assert!(!pair.needs_camera());
        let view = env.view().unwrap();
        let mut out = vec![0.0; 10];
        pair.observe(&[env.view().unwrap(), view], &mut out);
        assert_eq!(out, [1.0, 1.0, 2.0, 2.0, 2.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
    }
}
