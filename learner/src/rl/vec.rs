//! Many [`RlEnv`]s stepped in parallel (one chunk per thread, lockstep at
//! the policy's rate) and observed in one batch.

use super::env::{RlEnv, RlEnvConfig, RlEnvError, StepOutcome};
use super::observe::Observer;
use std::sync::Arc;

/// A batch of environments acted on together: what the RL algorithms
/// collect rollouts from. [`VecEnv`] is the fast path's; tests also use
/// small analytic tasks.
pub trait BatchEnv {
    /// Environments in the batch.
    fn num_envs(&self) -> usize;
    /// Length of one observation.
    fn obs_dim(&self) -> usize;
    /// Length of one action.
    fn act_dim(&self) -> usize;
    /// Policy steps per episode before truncation.
    fn max_steps(&self) -> u32;
    /// Starts a new episode in each listed environment (index, seed).
    fn reset(&mut self, which: &[(usize, u64)]) -> Result<(), RlEnvError>;
    /// One step of every environment (all must be running): `actions`
    /// holds `num_envs() * act_dim()` policy outputs.
    fn step(&mut self, actions: &[f64]) -> Result<&[StepOutcome], RlEnvError>;
    /// The latest observation of every environment, one after the other.
    fn observations(&self) -> &[f64];
    /// Length of one critic observation: what an asymmetric value
    /// baseline sees beside the policy's (0: none, the default).
    fn critic_dim(&self) -> usize {
        0
    }
    /// The latest critic observation of every environment, one after the
    /// other (`num_envs() * critic_dim()` values). The policy never sees
    /// them: they are the simulator's privileged state.
    fn critic_observations(&self) -> &[f64] {
        &[]
    }
}

/// Runs `f` on every item, the items split into `threads` contiguous
/// chunks run on scoped threads; results in item order.
pub fn par_map<T: Send, R: Send>(
    items: &mut [T],
    threads: usize,
    f: impl Fn(usize, &mut T) -> R + Sync,
) -> Vec<R> {
    let n = items.len();
    if threads <= 1 || n <= 1 {
        return items.iter_mut().enumerate().map(|(i, t)| f(i, t)).collect();
    }
    let chunk = n.div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks_mut(chunk)
            .enumerate()
            .map(|(c, part)| {
                s.spawn(move || {
                    part.iter_mut()
                        .enumerate()
                        .map(|(j, t)| f(c * chunk + j, t))
                        .collect::<Vec<R>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("an environment thread panicked"))
            .collect()
    })
}

/// The threads "all cores" means here.
pub fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The vectorised fast-path environment.
pub struct VecEnv {
    envs: Vec<RlEnv>,
    observer: Arc<dyn Observer>,
    /// The value baseline's own observer (privileged), if it has one.
    critic: Option<Arc<dyn Observer>>,
    critic_obs: Vec<f64>,
    threads: usize,
    obs: Vec<f64>,
    outcomes: Vec<StepOutcome>,
    max_steps: u32,
    overload_share: Arc<super::env::Share>,
}

impl VecEnv {
    /// `n` environments of `cfg`, observed by `observer`, stepped on
    /// `threads` threads (0: all cores).
    pub fn new(
        cfg: &RlEnvConfig,
        n: usize,
        observer: Arc<dyn Observer>,
        threads: usize,
    ) -> Result<Self, RlEnvError> {
        if n == 0 {
            return Err(shared_mem_schema::config::FieldError::new(
                "num_envs",
                0,
                "must be at least 1",
            )
            .into());
        }
        let overload_share = Arc::new(super::env::Share::default());
        let mut envs = (0..n)
            .map(|_| RlEnv::for_training(cfg))
            .collect::<Result<Vec<_>, _>>()?;
        for e in &mut envs {
            e.share_overload_ramp(overload_share.clone());
        }
        // After the world is built, so that an invalid camera is named by
        // its field rather than reported as another camera.
        super::observe::check_camera(&cfg.world.camera, observer.as_ref())?;
        let threads = if threads == 0 { all_cores() } else { threads };
        Ok(Self {
            obs: vec![0.0; n * observer.dim()],
            outcomes: Vec::with_capacity(n),
            envs,
            observer,
            critic: None,
            critic_obs: Vec::new(),
            threads: threads.min(n),
            max_steps: cfg.max_steps,
            overload_share,
        })
    }

    /// The same environments with `critic` observing them for the value
    /// baseline as well (an asymmetric critic). The critic must not need
    /// the camera: it sees the simulator's state.
    pub fn with_critic(mut self, critic: Arc<dyn Observer>) -> Self {
        self.critic_obs = vec![0.0; self.envs.len() * critic.dim()];
        self.critic = Some(critic);
        self
    }

    /// The overload ramp's progress, read by every environment
    /// (`training.overload_ramp_steps`; the training loop sets it).
    pub fn overload_share(&self) -> &super::env::Share {
        &self.overload_share
    }

    /// Environment `i`.
    pub fn env(&self, i: usize) -> &RlEnv {
        &self.envs[i]
    }

    /// Threads used.
    pub fn threads(&self) -> usize {
        self.threads
    }

    fn observe(&mut self) {
        let views: Vec<_> = self.envs.iter().filter_map(|e| e.view()).collect();
        if views.len() == self.envs.len() {
            self.observer.observe(&views, &mut self.obs);
            if let Some(c) = &self.critic {
                c.observe(&views, &mut self.critic_obs);
            }
        }
    }
}

impl BatchEnv for VecEnv {
    fn num_envs(&self) -> usize {
        self.envs.len()
    }

    fn obs_dim(&self) -> usize {
        self.observer.dim()
    }

    fn act_dim(&self) -> usize {
        4
    }

    fn max_steps(&self) -> u32 {
        self.max_steps
    }

    fn reset(&mut self, which: &[(usize, u64)]) -> Result<(), RlEnvError> {
        let n = self.envs.len();
        let mut seeds = vec![None; n];
        for &(i, seed) in which {
            if i >= n {
                return Err(RlEnvError::Shape {
                    what: "environment index",
                    got: i,
                    expected: n,
                });
            }
            seeds[i] = Some(seed);
        }
        let camera = self.observer.needs_camera();
        par_map(&mut self.envs, self.threads, |i, e| match seeds[i] {
            Some(seed) => e.reset(seed, camera),
            None => Ok(()),
        })
        .into_iter()
        .collect::<Result<Vec<()>, _>>()?;
        self.observe();
        Ok(())
    }

    fn step(&mut self, actions: &[f64]) -> Result<&[StepOutcome], RlEnvError> {
        let n = self.envs.len();
        if actions.len() != n * 4 {
            return Err(RlEnvError::Shape {
                what: "actions",
                got: actions.len(),
                expected: n * 4,
            });
        }
        let camera = self.observer.needs_camera();
        let results = par_map(&mut self.envs, self.threads, |i, e| {
            e.step(&actions[4 * i..4 * i + 4], camera)
                .map_err(|err| match err {
                    RlEnvError::NotRunning(_) => RlEnvError::NotRunning(i),
                    other => other,
                })
        });
        self.outcomes.clear();
        for r in results {
            self.outcomes.push(r?);
        }
        self.observe();
        Ok(&self.outcomes)
    }

    fn observations(&self) -> &[f64] {
        &self.obs
    }

    fn critic_dim(&self) -> usize {
        self.critic.as_ref().map_or(0, |c| c.dim())
    }

    fn critic_observations(&self) -> &[f64] {
        &self.critic_obs
    }
}
