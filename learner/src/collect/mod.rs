//! Data collection for the self-supervised dataset: episodes with the
//! paper's mix of a random policy and a heuristic one that makes contact
//! with the box (Sec. "Experiments": "We roll out a random policy as well as
//! a heuristic policy while collecting the data"), over the four pegs and
//! randomised box poses, one MCAP shard per episode.
//!
//! Fast mode runs [`FastEnv`] (simulator and control core in one process, in
//! lockstep) on every core, one environment per worker thread; the live mode
//! is `learner run` with the same mix through the real-time stack. Both
//! write the same log format, so the dataset builder reads either.

mod error;

pub use error::CollectError;

use crate::fast_env::FastEnv;
use hw_sim::{PegShape, WorldConfig};
use learner_node::log::events::{EpisodeEnd, Event, Reset};
use learner_node::log::{LogError, LogOptions, LogWriter, RunConfig, RunMode};
use learner_node::mix::{EpisodePolicy, Mix, MixedPolicy};
use learner_node::policy::TaskGeometry;
use learner_node::progress::Progress;
use rt_controller::ControllerConfig;
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::{Message, Stage, hw_time_ns};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

/// What `learner collect` does in fast mode.
#[derive(Debug, Clone)]
pub struct CollectConfig {
    /// Where the shards go.
    pub out_dir: PathBuf,
    /// 20 Hz states to collect: the first episodes whose states reach this
    /// many ([`StateBudget`]).
    pub states: u64,
    /// At most this many episodes (none: as many as `states` needs). A
    /// state budget takes the same episodes whatever the worker count or
    /// the threads' scheduling: see [`StateBudget`].
    pub episodes: Option<u64>,
    /// Actions per episode.
    pub episode_actions: u32,
    /// Pegs, taken in turn.
    pub pegs: Vec<PegShape>,
    /// Seed of the first episode (episode i uses `seed + i`).
    pub seed: u64,
    /// Worker threads (environments).
    pub workers: usize,
    /// The world (its peg is replaced per episode).
    pub world: WorldConfig,
    /// The control law.
    pub controller: ControllerConfig,
    /// The policy mix.
    pub mix: Mix,
    /// Log options.
    pub log: LogOptions,
    /// Continue the collection in `out_dir`: the episodes its manifest
    /// lists (with their files present) are kept and not run again. Without
    /// it, a directory that already holds a collection is refused.
    pub resume: bool,
}

/// What one episode wrote.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeShard {
    /// Episode number.
    pub episode: u64,
    /// Its seed.
    pub seed: u64,
    /// Peg.
    pub peg: PegShape,
    /// Policy.
    pub policy: EpisodePolicy,
    /// 20 Hz states (camera frames) written.
    pub states: u64,
    /// Best stage reached.
    pub stage: Stage,
    /// The controller's fault, if it faulted (it stays latched until the
    /// episode ends).
    pub fault: Option<EpisodeFault>,
    /// The file.
    pub file: PathBuf,
    /// Cut short by a stop (Ctrl-C): a resumed collection runs it again.
    #[serde(default)]
    pub interrupted: bool,
}

/// Where the peg was when the controller faulted, from the simulator's
/// task state at that cycle.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum FaultSite {
    /// Touching the box outside the hole (its top face or rim, mostly: the
    /// first contact of a descent).
    Box,
    /// In the hole, above the bottom.
    InHole,
    /// At the hole's bottom (the completed stage).
    Bottom,
    /// Not touching the box.
    NoContact,
}

impl FaultSite {
    /// All sites, in order.
    pub const ALL: [FaultSite; 4] = [Self::Box, Self::InHole, Self::Bottom, Self::NoContact];

    /// Name used in tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Box => "box",
            Self::InHole => "in_hole",
            Self::Bottom => "bottom",
            Self::NoContact => "no_contact",
        }
    }

    fn of(task: Option<&hw_sim::TaskState>) -> Self {
        match task {
            Some(t) if t.stage_now == Stage::Completed => Self::Bottom,
            Some(t) if t.in_hole => Self::InHole,
            Some(t) if t.in_contact => Self::Box,
            _ => Self::NoContact,
        }
    }
}

/// A controller fault during an episode.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeFault {
    /// Episode time of the fault, s.
    pub t_s: f64,
    /// The supervisor's reason.
    pub reason: String,
    /// Where the peg was.
    pub site: FaultSite,
    /// Norm of the wrist force at the fault, N.
    pub force_n: f64,
    /// Highest tip speed in the 10 cycles before the fault, m/s (an impact's
    /// approach speed).
    pub tip_speed_mps: f64,
}

/// Tip speeds of the last few cycles (fixed ring).
#[derive(Debug, Default)]
struct RecentSpeeds {
    v: [f64; 10],
    next: usize,
}

impl RecentSpeeds {
    fn push(&mut self, frame: &shared_mem_schema::SensorFrame) {
        let t = &frame.ee_twist;
        self.v[self.next] = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        self.next = (self.next + 1) % self.v.len();
    }

    fn max(&self) -> f64 {
        self.v.iter().copied().fold(0.0, f64::max)
    }
}

/// Which episodes a state budget takes: the shortest run of episodes from
/// 0 whose states reach it. Workers finish episodes out of order, so the
/// count of states written when a worker looks is scheduling luck; the
/// first episodes whose states reach the budget are not. Episodes past that
/// cut that a worker had already started are run to their end and dropped.
#[derive(Debug, Clone)]
pub struct StateBudget {
    target: u64,
    /// Finished episodes not yet part of the contiguous run from 0.
    pending: std::collections::BTreeMap<u64, u64>,
    /// The first episode not finished.
    next: u64,
    /// States of episodes `0..next`.
    prefix: u64,
    /// The last episode the budget takes, once known.
    last: Option<u64>,
}

impl StateBudget {
    /// A budget of `target` states; none of it spent.
    pub fn new(target: u64) -> Self {
        Self {
            target,
            pending: Default::default(),
            next: 0,
            prefix: 0,
            last: None,
        }
    }

    /// Records that `episode` finished with `states` states.
    pub fn finish(&mut self, episode: u64, states: u64) {
        if episode < self.next {
            return;
        }
        self.pending.insert(episode, states);
        while self.last.is_none()
            && let Some(n) = self.pending.remove(&self.next)
        {
            self.prefix += n;
            if self.prefix >= self.target {
                self.last = Some(self.next);
            }
            self.next += 1;
        }
    }

    /// Whether the budget takes `episode`: true until the episodes before
    /// it are known to reach it.
    pub fn takes(&self, episode: u64) -> bool {
        self.target > 0 && self.last.is_none_or(|l| episode <= l)
    }

    /// Whether the episodes it takes are all known (no worker need start
    /// another).
    pub fn settled(&self) -> bool {
        self.target == 0 || self.last.is_some()
    }
}

/// Result of a collection run.
#[derive(Debug, Clone)]
pub struct CollectSummary {
    /// Episodes written.
    pub shards: Vec<EpisodeShard>,
    /// States written.
    pub states: u64,
    /// Wall time, s.
    pub wall_s: f64,
}

/// Per policy: episodes, completions and controller faults by where the
/// peg was (with the median force and approach speed of each site's
/// faults), as a Markdown table.
pub fn fault_table(shards: &[EpisodeShard]) -> String {
    let median = |mut v: Vec<f64>| -> String {
        if v.is_empty() {
            return "–".into();
        }
        v.sort_by(f64::total_cmp);
        format!("{:.0}", v[v.len() / 2])
    };
    let mut out = String::from("| policy | episodes | completed | faulted |");
    for site in FaultSite::ALL {
        out += &format!(" {} |", site.name());
    }
    out += "\n|---|---|---|---|";
    out += &"---|".repeat(FaultSite::ALL.len());
    for kind in [EpisodePolicy::Heuristic, EpisodePolicy::Random] {
        let eps: Vec<&EpisodeShard> = shards.iter().filter(|s| s.policy == kind).collect();
        let faults: Vec<&EpisodeFault> = eps.iter().filter_map(|s| s.fault.as_ref()).collect();
        out += &format!(
            "\n| {} | {} | {} | {} |",
            kind.name(),
            eps.len(),
            eps.iter().filter(|s| s.stage == Stage::Completed).count(),
            faults.len()
        );
        for site in FaultSite::ALL {
            let at: Vec<&&EpisodeFault> = faults.iter().filter(|f| f.site == site).collect();
            if at.is_empty() {
                out += " 0 |";
            } else {
                out += &format!(
                    " {} ({} N, {} mm/s) |",
                    at.len(),
                    median(at.iter().map(|f| f.force_n).collect()),
                    median(at.iter().map(|f| 1e3 * f.tip_speed_mps).collect()),
                );
            }
        }
    }
    out
}

/// The task geometry the policies need, from the simulated world.
pub fn task_of(world: &hw_sim::World) -> Result<TaskGeometry, CollectError> {
    Ok(TaskGeometry {
        hole_pose: world.hole_pose().ok_or(CollectError::NoTask)?,
        symmetry: world.config().task.peg.symmetry_order(),
        depth_m: world.box_geometry().ok_or(CollectError::NoBox)?.depth,
    })
}

/// Runs one episode in `env` and writes it to `path`; `on_state` is called
/// after every 20 Hz state written. Returns the shard's description.
#[allow(clippy::too_many_arguments)]
pub fn run_episode(
    env: &mut FastEnv,
    world: WorldConfig,
    controller: &ControllerConfig,
    mix: &Mix,
    episode: u64,
    seed: u64,
    actions: u32,
    path: &Path,
    log_opts: &LogOptions,
    mut on_state: impl FnMut() -> bool,
) -> Result<EpisodeShard, CollectError> {
    let peg = world.task.peg;
    env.reset_with(world, seed)?;
    let task = task_of(env.world())?;
    let mut policy = MixedPolicy::new(mix, seed);
    let mut log = LogWriter::create_with(path, log_opts.clone())?;
    let mut config = RunConfig::new(
        RunMode::Fast,
        env.world().config().clone(),
        policy.kind(),
        episode,
        seed,
    );
    config.controller = Some(controller.clone());
    log.config(0, &config)?;
    let hole = task.hole_pose;
    log.event(
        0,
        &Event::Reset(Box::new(Reset {
            episode,
            seed,
            peg,
            policy: policy.kind(),
            lockstep: None,
            world: None,
            hole_pos_m: hole.translation.vector.into(),
            hole_quat_xyzw: hole.rotation.coords.into(),
            hole_depth_m: task.depth_m,
        })),
    )?;
    let mut cam = shared_mem_schema::CameraFrame::boxed_zeroed();
    let mut states = 0u64;
    let mut best = Stage::Failed;
    let mut stage_of = |env: &FastEnv, log: &mut LogWriter| -> Result<(), LogError> {
        let s = env.world().task().map_or(Stage::Failed, |t| t.best_stage);
        if s > best {
            best = s;
            let t = hw_time_ns(env.world().time_s());
            log.event(t, &Event::Stage { stage: s })?;
        }
        Ok(())
    };
    // Camera frame of the start state.
    env.render_camera(&mut cam);
    log.camera(&cam)?;
    let mut obs = None;
    let mut stop = false;
    let mut fault = None;
    let mut speeds = RecentSpeeds::default();
    let mut completed_actions = 0u32;
    for _ in 0..actions {
        // The first cycle has no observation yet: it holds the start pose.
        let action = obs.as_ref().map(|o| policy.act(o, &env.wrench, &task));
        for c in 0..ACTION_PERIOD_STEPS {
            // The message the controller got, as the stack logs it.
            if let Some(m) = env.cycle(if c == 0 { action.as_ref() } else { None })? {
                log.action(&m)?;
            }
            let frame = env.sensor_frame();
            log.sensor(frame)?;
            if fault.is_none()
                && let Some(reason) = env.controller_data().supervisor.fault()
            {
                let w = &frame.wrench;
                fault = Some(EpisodeFault {
                    t_s: env.world().time_s(),
                    reason: format!("{reason:?}"),
                    site: FaultSite::of(env.world().task()),
                    force_n: (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt(),
                    tip_speed_mps: speeds.max(),
                });
            }
            speeds.push(frame);
        }
        obs = Some(env.last_observation().expect("cycles ran"));
        stage_of(env, &mut log)?;
        if env.world().task().map(|t| t.best_stage) == Some(Stage::Completed) {
            completed_actions += 1;
        }
        if env.world().camera_due() {
            env.render_camera(&mut cam);
            log.camera(&cam)?;
            if action.is_none() {
                continue;
            }
            // A state: a frame, the action taken from it and the frame after.
            states += 1;
            if !on_state() {
                stop = true;
                break;
            }
        }
        if mix
            .end_after_completion
            .is_some_and(|n| completed_actions > n)
        {
            break;
        }
    }
    // The sensor frame of the last camera frame's step: its sample needs
    // the next step's reading.
    if !stop {
        env.cycle(None)?;
        log.sensor(env.sensor_frame())?;
    }
    let t = hw_time_ns(env.world().time_s());
    log.event(
        t,
        &Event::Outcome(EpisodeEnd {
            stage: best,
            duration_s: None,
            actions: None,
            states: Some(states),
            interrupted: Some(stop),
        }),
    )?;
    let file = log.finish()?;
    Ok(EpisodeShard {
        episode,
        seed,
        peg,
        policy: policy.kind(),
        states,
        stage: best,
        fault,
        file,
        interrupted: stop,
    })
}

/// [`collect_fast`] until `stop` turns true (polled every 50 ms; for
/// example the process's termination request): the workers then finish
/// their episodes' files and stop. Returns the summary and whether `stop`
/// ended the collection.
pub fn collect_fast_until(
    cfg: &CollectConfig,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<(CollectSummary, bool), CollectError> {
    use std::sync::atomic::Ordering::Relaxed;
    let halt = AtomicBool::new(false);
    let done = AtomicBool::new(false);
    let summary = std::thread::scope(|s| {
        s.spawn(|| {
            while !done.load(Relaxed) {
                if stop() {
                    halt.store(true, Relaxed);
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        });
        let r = collect_fast(cfg, &halt);
        done.store(true, Relaxed);
        r
    })?;
    Ok((summary, halt.load(Relaxed)))
}

/// Fast-mode collection on `cfg.workers` threads. `stop` ends it early
/// (each worker finishes its episode's file cleanly).
pub fn collect_fast(
    cfg: &CollectConfig,
    stop: &AtomicBool,
) -> Result<CollectSummary, CollectError> {
    if cfg.pegs.is_empty() {
        return Err(CollectError::NoPegs);
    }
    if cfg.episode_actions == 0 {
        return Err(CollectError::NoActions);
    }
    std::fs::create_dir_all(&cfg.out_dir).map_err(|source| CollectError::Io {
        path: cfg.out_dir.clone(),
        source,
    })?;
    let start = Instant::now();
    let manifest_path = cfg.out_dir.join("manifest.jsonl");
    let manifest_err = |source: std::io::Error| CollectError::Io {
        path: manifest_path.clone(),
        source,
    };
    let listed = read_manifest(&manifest_path)?;
    // A manifest with any bytes (even a line cut short) or episode files.
    let started = std::fs::metadata(&manifest_path).is_ok_and(|m| m.len() > 0)
        || has_episode_files(&cfg.out_dir)?;
    if started && !cfg.resume {
        return Err(CollectError::NotEmpty {
            dir: cfg.out_dir.clone(),
            episodes: listed.len(),
        });
    }
    // Episodes on file are not run again; one whose file is gone, or that a
    // stop cut short, is. An episode listed twice (run again) counts once.
    // Files are looked up in `out_dir`, wherever the collection ran from.
    let mut by_episode = std::collections::BTreeMap::new();
    for mut s in listed {
        let Some(name) = s.file.file_name() else {
            continue;
        };
        s.file = cfg.out_dir.join(name);
        let peg = cfg.pegs[s.episode as usize % cfg.pegs.len()];
        if s.seed != cfg.seed + s.episode || s.peg != peg {
            return Err(CollectError::Mismatch {
                dir: cfg.out_dir.clone(),
                episode: s.episode,
                detail: format!(
                    "it was collected with seed {} and the {} peg, this collection gives it \
                     seed {} and the {} peg",
                    s.seed,
                    s.peg.name(),
                    cfg.seed + s.episode,
                    peg.name()
                ),
            });
        }
        if s.file.exists() && !s.interrupted {
            by_episode.insert(s.episode, s);
        } else {
            by_episode.remove(&s.episode);
        }
    }
    let kept: Vec<EpisodeShard> = by_episode.into_values().collect();
    if cfg.resume && manifest_path.exists() {
        // Rewritten with the records kept, so that a line cut short by a
        // crash does not run into the next one appended.
        write_manifest(&manifest_path, &kept).map_err(manifest_err)?;
    }
    let skip: std::collections::HashSet<u64> = kept.iter().map(|s| s.episode).collect();
    let next_episode = AtomicU64::new(0);
    let done = AtomicU64::new(kept.iter().map(|s| s.states).sum());
    let mut budget = StateBudget::new(cfg.states);
    for s in &kept {
        budget.finish(s.episode, s.states);
    }
    let budget = Mutex::new(budget);
    let taken = |i: u64| budget.lock().expect("not poisoned").takes(i);
    let episodes_done = AtomicU64::new(kept.len() as u64);
    let progress = Progress::new(cfg.states, "states");
    progress.resume_at(done.load(Ordering::Relaxed));
    let shards = Mutex::new(kept);
    let manifest = Mutex::new(
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&manifest_path)
            .map_err(manifest_err)?,
    );
    // A worker's error stops the others after their episodes: the budget
    // cannot settle past an episode that failed.
    let failed = AtomicBool::new(false);
    let ran = std::thread::scope(|s| -> Result<(), CollectError> {
        let mut handles = Vec::new();
        for _ in 0..cfg.workers.max(1) {
            handles.push(s.spawn(|| {
                let r = (|| -> Result<(), CollectError> {
                    let mut env: Option<FastEnv> = None;
                    loop {
                        if stop.load(Ordering::Relaxed)
                            || failed.load(Ordering::Relaxed)
                            || budget.lock().expect("not poisoned").settled()
                        {
                            return Ok(());
                        }
                        let i = next_episode.fetch_add(1, Ordering::Relaxed);
                        if cfg.episodes.is_some_and(|n| i >= n) {
                            return Ok(());
                        }
                        if skip.contains(&i) {
                            continue;
                        }
                        if !taken(i) {
                            return Ok(());
                        }
                        let mut world = cfg.world.clone();
                        world.task.enabled = true;
                        world.task.peg = cfg.pegs[i as usize % cfg.pegs.len()];
                        if env.is_none() {
                            env = Some(FastEnv::new(world.clone(), cfg.controller.clone())?);
                        }
                        let env = env.as_mut().expect("built");
                        let path = cfg.out_dir.join(format!("episode-{i:06}.mcap"));
                        let shard = run_episode(
                            env,
                            world,
                            &cfg.controller,
                            &cfg.mix,
                            i,
                            cfg.seed + i,
                            cfg.episode_actions,
                            &path,
                            &cfg.log,
                            || {
                                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                                progress.update(
                                    n,
                                    format!("{} episodes", episodes_done.load(Ordering::Relaxed)),
                                );
                                !stop.load(Ordering::Relaxed)
                            },
                        )
                        .map_err(|e| CollectError::Episode {
                            episode: i,
                            path: path.clone(),
                            source: Box::new(e),
                        })?;
                        episodes_done.fetch_add(1, Ordering::Relaxed);
                        if !shard.interrupted {
                            budget.lock().expect("not poisoned").finish(i, shard.states);
                        }
                        // Fails only on a path that is not UTF-8.
                        let line = serde_json::to_string(&shard)
                            .map_err(|e| manifest_err(std::io::Error::other(e)))?;
                        writeln!(manifest.lock().expect("not poisoned"), "{line}")
                            .map_err(manifest_err)?;
                        shards.lock().expect("not poisoned").push(shard);
                    }
                })();
                if r.is_err() {
                    failed.store(true, Ordering::Relaxed);
                }
                r
            }));
        }
        let mut first = Ok(());
        for h in handles {
            let r = h.join().expect("collection worker panicked");
            if first.is_ok() {
                first = r;
            }
        }
        first
    });
    let mut shards = shards.into_inner().expect("not poisoned");
    shards.sort_by_key(|s| s.episode);
    // Episodes this run started past the budget's cut (before the episodes
    // ahead of them were known to reach it) are dropped, file and record,
    // so that a budget's episodes do not depend on the worker count; also
    // when a worker failed, so that a resume does not keep them. Files go
    // first: a manifest line without its file is run again on resume, a
    // file without its line would enter the dataset. Episodes kept from an
    // earlier run are recorded data and stay.
    if let Some(last) = budget.into_inner().expect("not poisoned").last {
        let (surplus, keep): (Vec<_>, Vec<_>) = shards
            .into_iter()
            .partition(|s| s.episode > last && !skip.contains(&s.episode));
        shards = keep;
        if !surplus.is_empty() {
            for s in &surplus {
                std::fs::remove_file(&s.file).map_err(|source| CollectError::Io {
                    path: s.file.clone(),
                    source,
                })?;
            }
            drop(manifest);
            write_manifest(&manifest_path, &shards).map_err(manifest_err)?;
        }
    }
    // The last line counts what was kept: the surplus episodes above were
    // run but are not in the collection.
    let states = shards.iter().map(|s| s.states).sum();
    progress.update(states, format!("{} episodes", shards.len()));
    progress.finish();
    ran?;
    Ok(CollectSummary {
        states,
        shards,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// Replaces the manifest at `path` with one record per shard, atomically.
fn write_manifest(path: &Path, shards: &[EpisodeShard]) -> std::io::Result<()> {
    let mut text = String::new();
    for s in shards {
        // Fails only on a path that is not UTF-8.
        text.push_str(&serde_json::to_string(s).map_err(std::io::Error::other)?);
        text.push('\n');
    }
    crate::write_atomic(path, text.as_bytes())
}

/// Whether `dir` holds episode files (`episode-*.mcap`).
fn has_episode_files(dir: &Path) -> Result<bool, CollectError> {
    let entries = std::fs::read_dir(dir).map_err(|source| CollectError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    Ok(entries.flatten().any(|e| {
        let name = e.file_name();
        let name = name.to_string_lossy();
        name.starts_with("episode-") && name.ends_with(".mcap")
    }))
}

/// The episodes `manifest.jsonl` lists (none when there is no manifest). A
/// last line cut short by a crash is ignored (its episode runs again); any
/// other line that does not parse is an error naming it.
pub fn read_manifest(path: &Path) -> Result<Vec<EpisodeShard>, CollectError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => {
            return Err(CollectError::Io {
                path: path.to_path_buf(),
                source,
            });
        }
    };
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut out = Vec::with_capacity(lines.len());
    for (k, line) in lines.iter().enumerate() {
        match serde_json::from_str::<EpisodeShard>(line) {
            Ok(s) => out.push(s),
            Err(_) if k + 1 == lines.len() && !text.ends_with('\n') => {}
            Err(e) => {
                return Err(CollectError::Manifest {
                    path: path.to_path_buf(),
                    line: k + 1,
                    detail: e.to_string(),
                });
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::StateBudget;

    #[test]
    fn a_budget_takes_the_first_episodes_that_reach_it_in_any_finishing_order() {
        // Episodes 0-3 of 4, 3, 5, 2 states against a budget of 9: 0-2.
        let states = [4, 3, 5, 2];
        for order in [[0, 1, 2, 3], [3, 2, 1, 0], [2, 0, 3, 1], [1, 3, 0, 2]] {
            let mut b = StateBudget::new(9);
            for &e in &order {
                assert!(!b.settled() || !b.takes(3), "{order:?}");
                b.finish(e, states[e as usize]);
            }
            assert!(b.settled(), "{order:?}");
            assert!((0..3).all(|e| b.takes(e)) && !b.takes(3), "{order:?}");
        }
        // Finished episodes past a gap do not settle it.
        let mut b = StateBudget::new(9);
        b.finish(1, 100);
        b.finish(2, 100);
        assert!(!b.settled() && b.takes(5));
        b.finish(0, 1);
        assert!(b.settled() && b.takes(1) && !b.takes(2));
        // Exactly the budget is enough; nothing is taken from none.
        let mut b = StateBudget::new(4);
        b.finish(0, 4);
        assert!(b.settled() && !b.takes(1));
        let b = StateBudget::new(0);
        assert!(b.settled() && !b.takes(0));
    }
}
