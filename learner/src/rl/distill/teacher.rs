//! Who labels the student's states: a trained policy or the touch search
//! (told by the truth or through probes of a representation), and one
//! round's collection under DAgger's mixture of teacher and student.

use super::samples::Samples;
use super::{DistillConfig, refuse};
use crate::rl::gaussian::GaussianPolicy;
use crate::rl::observe::Observer;
use crate::rl::probe::LinearProbe;
use crate::rl::run::{RunError, TrainConfig, read_json, write_json};
use crate::rl::search::{
    BeliefProbeConfig, BeliefProbes, ProbedSearchView, SearchView, TouchSearch, TouchSearchConfig,
    fit_belief_probe,
};
use crate::rl::train::TrainerState;
use crate::rl::vec::{BatchEnv, VecEnv};
use learner_node::progress::Progress;
use stack_common::rng;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where the probe of a representation-told search teacher is kept.
fn probe_path(out: &Path) -> PathBuf {
    out.join("search-probe.json")
}

/// Where the search teacher's approach probe (`approach`) is kept.
fn approach_probe_path(out: &Path) -> PathBuf {
    out.join("search-approach-probe.json")
}

/// Seed of the first episode a search teacher's probe is fitted on: apart
/// from DAgger's (from `dagger.episode_seed`, 5 000 000 by default),
/// validation's and evaluation's (from 1 000 000) episodes.
const PROBE_FIT_SEED: u64 = 7_000_000;

/// The touch-search teacher of the distillation run in `out` as it
/// labelled the run's rounds: its search and its view, through the run's
/// saved probes when a representation tells it. For comparing a student
/// with its teacher on the same episodes (`distill_fit shadow`).
pub fn search_teacher_of(out: &Path) -> Result<(TouchSearch, Arc<dyn Observer>), RunError> {
    let cfg_path = out.join("distill-config.json");
    let cfg: DistillConfig = read_json(&cfg_path)?;
    let search = cfg
        .search_teacher
        .as_ref()
        .ok_or_else(|| refuse("not a distillation from the touch search".into(), &cfg_path))?;
    let view: Arc<dyn Observer> = match &search.probe {
        Some(p) => probed_view(search, p, &cfg.student, out, false)?,
        None => Arc::new(SearchView {
            std_m: search.hole_error_m,
        }),
    };
    let teacher = TouchSearch {
        cfg: search.clone(),
        scale: cfg.student.env.action.clone(),
    };
    Ok((teacher, view))
}

/// The representation-told search teacher's view through its probes: fitted
/// in the student's environment (a fresh run) or read back (a resumed one).
pub(super) fn probed_view(
    search: &TouchSearchConfig,
    p: &BeliefProbeConfig,
    student_cfg: &TrainConfig,
    out: &Path,
    fresh: bool,
) -> Result<Arc<dyn Observer>, RunError> {
    let path = probe_path(out);
    let approach_path = approach_probe_path(out);
    // A resumed run's rounds were labelled through its probes: refit ones
    // could label the next rounds differently.
    for (needed, path) in [(true, &path), (p.approach, &approach_path)] {
        if needed && !fresh && !path.exists() {
            return Err(refuse(
                "resuming: a probe of the search teacher is missing; its rounds were labelled \
                 through it (start afresh without --resume)"
                    .into(),
                path,
            ));
        }
    }
    let repr = crate::rl::ObservationKind::Representation(p.representation.clone())
        .observer_on(student_cfg.threads)?;
    let probes = if !fresh {
        let read = |path: &Path| -> Result<LinearProbe, RunError> {
            let probe: LinearProbe = read_json(path)?;
            probe.check().map_err(|e| refuse(e.to_string(), path))?;
            Ok(probe)
        };
        BeliefProbes {
            near: read(&path)?,
            approach: if p.approach {
                Some(read(&approach_path)?)
            } else {
                None
            },
        }
    } else {
        eprintln!(
            "learner: fitting the search teacher's probe{} of {} on {} episodes per round, {} \
             round(s)",
            if p.approach {
                "s (near and approach)"
            } else {
                ""
            },
            p.representation.display(),
            p.fit_episodes,
            p.fit_rounds
        );
        let progress = Progress::new(
            p.fit_episodes.saturating_mul(u64::from(p.fit_rounds)),
            "episodes",
        );
        let probes = fit_belief_probe(
            &student_cfg.env,
            repr.as_ref(),
            search,
            p,
            PROBE_FIT_SEED,
            &mut |ep, rows| progress.update(ep, format!("{rows} states")),
        )?;
        progress.finish();
        write_json(&path, &probes.near)?;
        if let Some(a) = &probes.approach {
            write_json(&approach_path, a)?;
        }
        probes
    };
    for (probe, path, targets) in [
        (Some(&probes.near), &path, 3),
        (probes.approach.as_ref(), &approach_path, 2),
    ] {
        if let Some(probe) = probe
            && (probe.features() != repr.dim() || probe.targets != targets)
        {
            return Err(refuse(
                format!(
                    "a probe of {} features to {} targets; the representation gives {} and the \
                     search needs {targets}",
                    probe.features(),
                    probe.targets,
                    repr.dim()
                ),
                path,
            ));
        }
    }
    Ok(Arc::new(ProbedSearchView {
        repr,
        probes,
        below_m: p.below_m,
    }))
}

/// Who labels the student's states.
pub(super) enum Teacher {
    /// A trained policy's mean.
    Policy(GaussianPolicy),
    /// The scripted touch search.
    Search(TouchSearch),
}

impl Teacher {
    fn means(&self, obs: &[f64]) -> Vec<f64> {
        match self {
            Teacher::Policy(p) => p.means(obs),
            Teacher::Search(s) => s.means(obs),
        }
    }
}

/// One round's collection: `steps` steps over all environments, each acting
/// with the teacher's mean with probability `beta`, the student's
/// otherwise; with the number of steps the student acted. None when
/// stopped.
#[allow(clippy::too_many_arguments)]
pub(super) fn collect(
    env: &mut VecEnv,
    teacher: &Teacher,
    student: &GaussianPolicy,
    td: usize,
    beta: f64,
    cfg: &DistillConfig,
    state: &mut TrainerState,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Option<(Samples, Samples, usize)>, RunError> {
    let n = env.num_envs();
    let (od, ad) = (env.obs_dim(), env.act_dim());
    let sd = od - td;
    let mut pick = rng::seeded(cfg.student.seed, (5 << 32) + state.iteration);
    let mut s = Samples {
        obs_dim: sd,
        act_dim: ad,
        ..Default::default()
    };
    let mut seen_by_teacher = Samples {
        obs_dim: td,
        act_dim: ad,
        ..Default::default()
    };
    let next_seed = |state: &mut TrainerState| {
        let seed = cfg.dagger.episode_seed + state.episodes_started;
        state.episodes_started += 1;
        seed
    };
    // Every round starts fresh episodes: a resumed round collects what the
    // uninterrupted one would have.
    let which: Vec<(usize, u64)> = (0..n).map(|i| (i, next_seed(state))).collect();
    env.reset(&which)?;
    let (mut tobs, mut sobs) = (Vec::new(), Vec::new());
    let (mut collected, mut by_student) = (0, 0);
    while collected < cfg.dagger.steps_per_round {
        if stop() {
            return Ok(None);
        }
        tobs.clear();
        sobs.clear();
        for o in env.observations().chunks_exact(od) {
            tobs.extend_from_slice(&o[..td]);
            sobs.extend_from_slice(&o[td..]);
        }
        let mut target = teacher.means(&tobs);
        for a in target.iter_mut() {
            *a = if a.is_nan() { 0.0 } else { a.clamp(-1.0, 1.0) };
        }
        let mut act = student.means(&sobs);
        for i in 0..n {
            if rng::unit(&mut pick) < beta {
                act[i * ad..(i + 1) * ad].copy_from_slice(&target[i * ad..(i + 1) * ad]);
            } else {
                by_student += 1;
            }
        }
        s.obs.extend(sobs.iter().map(|&v| v as f32));
        s.actions.extend(target.iter().map(|&v| v as f32));
        seen_by_teacher.obs.extend(tobs.iter().map(|&v| v as f32));
        seen_by_teacher
            .actions
            .extend(target.iter().map(|&v| v as f32));
        let outcomes = env.step(&act)?.to_vec();
        collected += n;
        state.env_steps += n as u64;
        let which: Vec<(usize, u64)> = outcomes
            .iter()
            .enumerate()
            .filter(|(_, o)| o.done())
            .map(|(i, _)| (i, next_seed(state)))
            .collect();
        if !which.is_empty() {
            env.reset(&which)?;
        }
    }
    Ok(Some((s, seen_by_teacher, by_student)))
}
