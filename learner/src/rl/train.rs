//! On-policy rollouts from a [`BatchEnv`] and the training loop: collect
//! `batch_steps` steps with the current policy, estimate advantages (GAE
//! over the baseline's values), update the policy (TRPO or PPO), fit the
//! baseline.
//!
//! Episodes continue across updates: a trajectory cut by the end of a batch
//! is bootstrapped with the baseline's value of its last state, and goes on
//! in the next batch. Episode seeds are `seed`, `seed + 1`, … in the order
//! episodes start, and the action noise of update k is drawn from its own
//! stream, so a run is the same whatever the number of threads.

use super::env::RlEnvError;
use super::gaussian::{GaussianPolicy, RolloutBatch, UpdateStats, gae};
use super::obs_norm::ObsNorm;
use super::ppo::{Adam, PpoConfig, ppo_update};
use super::reward::{Outcome, normalised_return};
use super::trpo::{TrpoConfig, trpo_step};
use super::value::{Baseline, BaselineKind, ValueConfig, explained_variance};
use super::vec::BatchEnv;
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::FieldError;

/// The policy-gradient algorithm of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Algorithm {
    /// Trust-region policy optimisation, the paper's.
    #[default]
    Trpo,
    /// Proximal policy optimisation (clipped surrogate).
    Ppo,
}

/// What the value baseline observes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CriticInput {
    /// The policy's own observation, under its normalisation.
    #[default]
    Policy,
    /// The simulator's ground-truth state (the 18 values of
    /// [`super::observe::GroundTruth`]) under its own running
    /// normalisation: an asymmetric critic (Pinto et al. 2018), allowed in
    /// simulation because only the actor is deployed. Training only.
    GroundTruth,
}

/// The policy and its learning (`[policy]`): what both algorithms share,
/// with each one's own settings in `[policy.trpo]` and `[policy.ppo]`.
/// Defaults are the paper's appendix (simulation column) and, where it is
/// silent, pytorch-trpo's, which the paper's implementation was based on
/// (docs/rl.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PolicyConfig {
    /// The update rule.
    pub algorithm: Algorithm,
    /// Environment steps per policy update (paper: 2000).
    pub batch_steps: usize,
    /// Discount γ (paper: 0.995).
    pub gamma: f64,
    /// GAE λ (paper: 0.97).
    pub gae_lambda: f64,
    /// What the value baseline sees (`policy`: the policy's observation;
    /// `ground_truth`: the simulator's state, an asymmetric critic).
    pub critic: CriticInput,
    /// For a run started from `init_from`: every action component's log σ
    /// starts at this rather than at the source's (a distilled student
    /// carries its teacher's exploration noise). None: the source's.
    pub init_from_log_std: Option<f64>,
    /// Hidden layer widths of the policy's MLP (pytorch-trpo: 64, 64).
    pub hidden: Vec<usize>,
    /// Initial log σ of every action component (pytorch-trpo: 0).
    pub init_log_std: f64,
    /// Normalise the observations by their running mean and standard
    /// deviation before the policy's network and the baseline
    /// (pytorch-trpo's `ZFilter`: on).
    pub normalise_observations: bool,
    /// Normalised observations are clipped to ±this (pytorch-trpo: 5).
    pub observation_clip: f64,
    /// Keep the observation statistics as they are (no running update):
    /// for fine-tuning a policy whose inputs were normalised by the data it
    /// learned from, where a drifting normalisation changes what it does
    /// with no gradient step (and no KL bound) behind it.
    pub freeze_obs_norm: bool,
    /// The value baseline: `linear` (rllab's features) or `network`
    /// (pytorch-trpo's value MLP).
    pub baseline: BaselineKind,
    /// Ridge regularisation of the linear baseline's least squares (grown
    /// ×10 while the normal equations are not positive definite).
    pub baseline_ridge: f64,
    /// The value network's shape and fitting.
    pub value: ValueConfig,
    /// TRPO's settings.
    pub trpo: TrpoConfig,
    /// PPO's settings.
    pub ppo: PpoConfig,
    /// Updates at a run's start (its first, also from `init_from`) in which
    /// only the value baseline learns: the policy and its observation
    /// statistics stay as they are while it acts. Fine-tuning a distilled
    /// policy with a fresh baseline otherwise steps along advantages of a
    /// baseline that knows nothing yet (DAPG, Rajeswaran et al. 2018, warm
    /// the critic first). 0: none.
    pub value_warmup_updates: u64,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        Self {
            algorithm: Algorithm::Trpo,
            batch_steps: 2000,
            gamma: 0.995,
            gae_lambda: 0.97,
            critic: CriticInput::Policy,
            init_from_log_std: None,
            hidden: vec![64, 64],
            init_log_std: 0.0,
            normalise_observations: true,
            observation_clip: 5.0,
            freeze_obs_norm: false,
            baseline: BaselineKind::Linear,
            baseline_ridge: 1e-5,
            value: ValueConfig::default(),
            trpo: TrpoConfig::default(),
            ppo: PpoConfig::default(),
            value_warmup_updates: 0,
        }
    }
}

impl PolicyConfig {
    /// Values per state its value baseline sees in `env`.
    pub fn critic_dim<E: BatchEnv>(&self, env: &E) -> usize {
        match self.critic {
            CriticInput::Policy => env.obs_dim(),
            CriticInput::GroundTruth => env.critic_dim(),
        }
    }

    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), FieldError> {
        for (name, v) in [
            ("policy.gamma", self.gamma),
            ("policy.gae_lambda", self.gae_lambda),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(FieldError::new(name, v, "must be within [0, 1]"));
            }
        }
        if !(self.baseline_ridge.is_finite() && self.baseline_ridge > 0.0) {
            return Err(FieldError::new(
                "policy.baseline_ridge",
                self.baseline_ridge,
                "must be positive and finite",
            ));
        }
        if !(self.observation_clip.is_finite() && self.observation_clip > 0.0) {
            return Err(FieldError::new(
                "policy.observation_clip",
                self.observation_clip,
                "must be positive and finite",
            ));
        }
        if let Some(l) = self.init_from_log_std
            && !l.is_finite()
        {
            return Err(FieldError::new(
                "policy.init_from_log_std",
                l,
                "must be finite",
            ));
        }
        if !self.init_log_std.is_finite() {
            return Err(FieldError::new(
                "policy.init_log_std",
                self.init_log_std,
                "must be finite",
            ));
        }
        if self.batch_steps == 0 {
            return Err(FieldError::new(
                "policy.batch_steps",
                0,
                "must be at least 1",
            ));
        }
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(FieldError::new(
                "policy.hidden",
                format!("{:?}", self.hidden),
                "at least one layer, each at least 1 wide",
            ));
        }
        // Both are checked whichever runs: a configuration is valid or not
        // as a whole.
        self.value.validate()?;
        self.trpo.validate()?;
        self.ppo.validate()
    }
}

/// One finished episode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpisodeStats {
    /// The seed it was reset with.
    pub seed: u64,
    /// Sum of its rewards.
    pub reward: f64,
    /// That sum over the highest attainable (5 per step, full length).
    pub normalised: f64,
    /// Its category.
    pub outcome: Outcome,
    /// Policy steps it ran.
    pub steps: u32,
    /// It ended early (a controller fault).
    pub terminated: bool,
}

/// One update of the training loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IterationStats {
    /// Update number, from 1.
    pub iteration: u64,
    /// Environment (policy) steps so far.
    pub env_steps: u64,
    /// The episodes that ended during this batch.
    pub episodes: Vec<EpisodeStats>,
    /// What the policy update did.
    pub update: UpdateStats,
    /// Mean σ of the policy after the update.
    pub mean_std: f64,
    /// The share of the batch's λ-returns the baseline explained before
    /// it was fitted to them ([`explained_variance`]).
    #[serde(default)]
    pub baseline_explained: f64,
}

impl IterationStats {
    /// Mean episode reward of the batch's finished episodes (None: none
    /// finished).
    pub fn mean_return(&self) -> Option<f64> {
        (!self.episodes.is_empty()).then(|| {
            self.episodes.iter().map(|e| e.reward).sum::<f64>() / self.episodes.len() as f64
        })
    }

    /// Mean normalised episode reward of the finished episodes.
    pub fn mean_normalised(&self) -> Option<f64> {
        (!self.episodes.is_empty()).then(|| {
            self.episodes.iter().map(|e| e.normalised).sum::<f64>() / self.episodes.len() as f64
        })
    }

    /// Share of the finished episodes in each category ([`Outcome::ALL`]
    /// order).
    pub fn outcome_shares(&self) -> [f64; 4] {
        let mut s = [0.0; 4];
        let n = self.episodes.len().max(1) as f64;
        for e in &self.episodes {
            s[e.outcome.index()] += 1.0 / n;
        }
        s
    }
}

/// Samples of one environment's current trajectory segment.
#[derive(Debug, Clone, Default)]
struct Segment {
    /// The observations as the environment gave them.
    obs: Vec<f64>,
    /// The critic's observations (empty without an asymmetric critic).
    critic: Vec<f64>,
    actions: Vec<f64>,
    rewards: Vec<f64>,
    times: Vec<f64>,
}

/// A batch being collected, with what the baseline needs.
#[derive(Debug, Default)]
struct Collected {
    /// Its `obs` is empty until the batch is complete: the network's inputs
    /// are made from `raw` then, under the statistics that include it.
    batch: RolloutBatch,
    /// The observations as the environment gave them.
    raw: Vec<f64>,
    /// The critic's observations as the environment gave them.
    critic_raw: Vec<f64>,
    /// Step of each sample over the episode length.
    times: Vec<f64>,
    /// The baseline's value of each sample's state.
    values: Vec<f64>,
}

impl Collected {
    /// Moves a finished or cut segment in, with its advantages against
    /// `baseline` (which sees the observations as `policy`'s network does,
    /// or the critic's under `critic_norm`); `last` is the state after it
    /// (policy's and critic's observation) and its time (None: the episode
    /// ended, by a fault or at the horizon: nothing to bootstrap).
    fn finish(
        &mut self,
        seg: &mut Segment,
        last: Option<(&[f64], &[f64], f64)>,
        baseline: &Baseline,
        policy: &GaussianPolicy,
        critic_norm: Option<&ObsNorm>,
        cfg: &PolicyConfig,
    ) {
        if seg.rewards.is_empty() {
            return;
        }
        let inputs = |obs: &[f64], critic: &[f64]| match critic_norm {
            Some(n) => n.apply(critic),
            None => policy.inputs(obs),
        };
        let values = baseline.predict(&inputs(&seg.obs, &seg.critic), &seg.times);
        let last_value = last.map_or(0.0, |(o, c, t)| baseline.predict(&inputs(o, c), &[t])[0]);
        let adv = gae(&seg.rewards, &values, last_value, cfg.gamma, cfg.gae_lambda);
        self.raw.append(&mut seg.obs);
        self.critic_raw.append(&mut seg.critic);
        self.batch.actions.append(&mut seg.actions);
        self.batch.advantages.extend(adv);
        self.times.append(&mut seg.times);
        self.values.extend(values);
        seg.rewards.clear();
    }
}

/// The state a run resumes from (a checkpoint).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainerState {
    /// The policy.
    pub policy: GaussianPolicy,
    /// The value baseline.
    #[serde(default)]
    pub baseline: Baseline,
    /// Updates done.
    pub iteration: u64,
    /// Environment steps taken.
    pub env_steps: u64,
    /// Episodes started.
    pub episodes_started: u64,
    /// Seed of the run.
    pub seed: u64,
    /// PPO's optimiser, or the refit's in a distillation (`policy
    /// distill`); empty for TRPO, which keeps no state between updates.
    /// PPO resizes it when its parameters are not the refit's.
    #[serde(default)]
    pub adam: Adam,
    /// The asymmetric critic's observation statistics (None: the baseline
    /// sees the policy's observation).
    #[serde(default)]
    pub critic_norm: Option<ObsNorm>,
}

impl TrainerState {
    /// A run's state before its first update.
    pub fn fresh(policy: GaussianPolicy, baseline: Baseline, seed: u64) -> Self {
        Self {
            policy,
            baseline,
            iteration: 0,
            env_steps: 0,
            episodes_started: 0,
            seed,
            adam: Adam::default(),
            critic_norm: None,
        }
    }
}

/// The training loop over a batch of environments.
pub struct Trainer<E: BatchEnv> {
    env: E,
    cfg: PolicyConfig,
    /// Policy, baseline and counters (what a checkpoint holds).
    pub state: TrainerState,
    segments: Vec<Segment>,
    /// Step within its episode of each environment's current state.
    t: Vec<u32>,
    /// Seed of each environment's current episode.
    seeds: Vec<u64>,
    /// Environments whose next episode has not started.
    pending: Vec<bool>,
}

impl<E: BatchEnv> Trainer<E> {
    /// A fresh run: a new policy drawn from `seed`.
    pub fn new(env: E, cfg: PolicyConfig, seed: u64) -> Result<Self, RlEnvError> {
        cfg.validate()?;
        let mut rng = stack_common::rng::seeded(seed, 900);
        let mut policy = GaussianPolicy::new(
            env.obs_dim(),
            &cfg.hidden,
            env.act_dim(),
            cfg.init_log_std,
            &mut rng,
        );
        if cfg.normalise_observations {
            policy.obs_norm = Some(ObsNorm::new(env.obs_dim(), cfg.observation_clip));
        }
        let mut rng = stack_common::rng::seeded(seed, 901);
        let baseline = Baseline::new(cfg.baseline, cfg.critic_dim(&env), &cfg.value, &mut rng);
        let state = TrainerState::fresh(policy, baseline, seed);
        Self::resume(env, cfg, state)
    }

    /// A run resumed from `state` (its episodes in progress start afresh).
    pub fn resume(env: E, cfg: PolicyConfig, mut state: TrainerState) -> Result<Self, RlEnvError> {
        cfg.validate()?;
        if cfg.critic == CriticInput::GroundTruth && env.critic_dim() == 0 {
            return Err(RlEnvError::Config(FieldError::new(
                "policy.critic",
                "ground_truth",
                "these environments give the value baseline no state of its own",
            )));
        }
        let critic_dim = cfg.critic_dim(&env);
        let n = env.num_envs();
        if state.policy.sizes.first() != Some(&env.obs_dim())
            || state.policy.act_dim() != env.act_dim()
        {
            return Err(RlEnvError::Shape {
                what: "policy input (observation size)",
                got: state.policy.sizes.first().copied().unwrap_or(0),
                expected: env.obs_dim(),
            });
        }
        // The network only means something under the scaling it learned
        // with: a policy trained without normalisation cannot gain it, nor
        // lose it, by a setting.
        let has_norm = state.policy.obs_norm.is_some();
        if cfg.normalise_observations != has_norm {
            return Err(RlEnvError::Config(FieldError::new(
                "policy.normalise_observations",
                cfg.normalise_observations,
                if has_norm {
                    "the policy to continue was trained with its observations normalised \
                     (set it to true)"
                } else {
                    "the policy to continue was trained without observation normalisation \
                     (set it to false)"
                },
            )));
        }
        if !state.baseline.fits(cfg.baseline, critic_dim, &cfg.value) {
            return Err(RlEnvError::Config(FieldError::new(
                "policy.baseline",
                format!("{:?}", cfg.baseline),
                format!(
                    "the state to continue has a {:?} baseline that is not this one \
                     (policy.value.hidden {:?} over {} observation values, policy.critic)",
                    state.baseline.kind(),
                    cfg.value.hidden,
                    critic_dim
                ),
            )));
        }
        if let Some(n) = &state.policy.obs_norm
            && n.dim() != env.obs_dim()
        {
            return Err(RlEnvError::Shape {
                what: "observation normalisation",
                got: n.dim(),
                expected: env.obs_dim(),
            });
        }
        // The critic's statistics start with its first batch (a run from
        // `init_from` brings none).
        match cfg.critic {
            CriticInput::Policy => state.critic_norm = None,
            CriticInput::GroundTruth => {
                if state
                    .critic_norm
                    .as_ref()
                    .is_none_or(|n| n.dim() != critic_dim)
                {
                    state.critic_norm = Some(ObsNorm::new(critic_dim, cfg.observation_clip));
                }
            }
        }
        Ok(Self {
            env,
            cfg,
            state,
            segments: vec![Segment::default(); n],
            t: vec![0; n],
            seeds: vec![0; n],
            pending: vec![true; n],
        })
    }

    /// The environments.
    pub fn env(&self) -> &E {
        &self.env
    }

    /// The settings.
    pub fn config(&self) -> &PolicyConfig {
        &self.cfg
    }

    fn next_seed(&mut self) -> u64 {
        let s = self.state.seed.wrapping_add(self.state.episodes_started);
        self.state.episodes_started += 1;
        s
    }

    /// Collects one batch and updates the policy.
    pub fn iterate(&mut self) -> Result<IterationStats, RlEnvError> {
        let n = self.env.num_envs();
        let (od, ad) = (self.env.obs_dim(), self.env.act_dim());
        // The critic's observation length (0: it sees the policy's).
        let cd = if self.state.critic_norm.is_some() {
            self.env.critic_dim()
        } else {
            0
        };
        let max_steps = self.env.max_steps();
        let horizon = max_steps.max(1) as f64;
        let mut rng = stack_common::rng::seeded(self.state.seed, 1000 + self.state.iteration);
        let mut col = Collected::default();
        let mut episodes = Vec::new();
        let mut collected = 0usize;
        while collected < self.cfg.batch_steps {
            // Episodes start when they are next stepped, so that a batch
            // ending with finished episodes leaves nothing half begun (a
            // checkpoint then resumes exactly).
            let idle: Vec<usize> = (0..n).filter(|&i| self.pending[i]).collect();
            let which: Vec<_> = idle.into_iter().map(|i| (i, self.next_seed())).collect();
            if !which.is_empty() {
                for &(i, seed) in &which {
                    self.seeds[i] = seed;
                    self.t[i] = 0;
                    self.pending[i] = false;
                }
                self.env.reset(&which)?;
            }
            let obs = self.env.observations().to_vec();
            let critic = self.env.critic_observations()[..n * cd].to_vec();
            let actions = self.state.policy.sample(&obs, &mut rng);
            let outcomes = self.env.step(&actions)?.to_vec();
            collected += n;
            self.state.env_steps += n as u64;
            for (i, out) in outcomes.iter().enumerate() {
                let seg = &mut self.segments[i];
                seg.obs.extend_from_slice(&obs[i * od..(i + 1) * od]);
                seg.critic.extend_from_slice(&critic[i * cd..(i + 1) * cd]);
                seg.actions
                    .extend_from_slice(&actions[i * ad..(i + 1) * ad]);
                seg.rewards.push(out.reward);
                seg.times.push(self.t[i] as f64 / horizon);
                self.t[i] += 1;
                if out.done() {
                    // The episode is over, by a fault or at the horizon: the
                    // task is a finite-horizon MDP (time is in the
                    // baseline's features), so nothing follows its last
                    // step. Bootstrapping at the horizon fed the baseline's
                    // extrapolation to t = 1 (never fitted) back into its
                    // own targets, and the learned return fell.
                    col.finish(
                        seg,
                        None,
                        &self.state.baseline,
                        &self.state.policy,
                        self.state.critic_norm.as_ref(),
                        &self.cfg,
                    );
                    episodes.push(EpisodeStats {
                        seed: self.seeds[i],
                        reward: out.episode_reward,
                        normalised: normalised_return(out.episode_reward, max_steps),
                        outcome: out.outcome,
                        steps: out.steps,
                        terminated: out.terminated,
                    });
                    self.pending[i] = true;
                }
            }
        }
        // Cut the running segments at the batch's end; they go on next time.
        let obs = self.env.observations().to_vec();
        let critic = self.env.critic_observations()[..n * cd].to_vec();
        for i in (0..n).filter(|&i| !self.pending[i]) {
            let last = (
                &obs[i * od..(i + 1) * od],
                &critic[i * cd..(i + 1) * cd],
                self.t[i] as f64 / horizon,
            );
            let mut seg = std::mem::take(&mut self.segments[i]);
            col.finish(
                &mut seg,
                Some(last),
                &self.state.baseline,
                &self.state.policy,
                self.state.critic_norm.as_ref(),
                &self.cfg,
            );
        }
        // The baseline learns the λ-returns (advantage + value) of this batch.
        let Collected {
            mut batch,
            raw,
            critic_raw,
            times,
            values,
        } = col;
        // The statistics take in this batch before the update, and the
        // update and the baseline see the inputs the next batch's policy
        // will: old and new policy are compared under the statistics the
        // new one acts with (OpenAI baselines' trpo_mpi and ppo1 update
        // their `ob_rms` so). The actions were drawn under the previous
        // statistics, a mismatch that shrinks as they settle.
        let warming = self.state.iteration < self.cfg.value_warmup_updates;
        if let Some(n) = &mut self.state.policy.obs_norm
            && !warming
            && !self.cfg.freeze_obs_norm
        {
            n.update(&raw);
        }
        batch.obs = self.state.policy.inputs(&raw);
        // The critic's statistics take in every batch, warm-up included:
        // only the policy must act unchanged then.
        let critic_inputs = self.state.critic_norm.as_mut().map(|n| {
            n.update(&critic_raw);
            n.apply(&critic_raw)
        });
        let targets: Vec<f64> = batch
            .advantages
            .iter()
            .zip(&values)
            .map(|(a, v)| a + v)
            .collect();
        let baseline_explained = explained_variance(&values, &targets);
        let update = match self.cfg.algorithm {
            // The baseline alone learns (below); the policy is left as is.
            _ if warming => UpdateStats {
                kl: 0.0,
                improvement: 0.0,
                expected: 0.0,
                step_fraction: 0.0,
                clip_fraction: 0.0,
            },
            Algorithm::Trpo => trpo_step(&mut self.state.policy, &mut batch, &self.cfg.trpo),
            Algorithm::Ppo => {
                // Minibatch order from its own stream: the same run on any
                // number of threads, and after a resume.
                // (Stream 2·2³² + k: apart from the action noise's 1000 + k.)
                let mut order =
                    stack_common::rng::seeded(self.state.seed, (2 << 32) + self.state.iteration);
                ppo_update(
                    &mut self.state.policy,
                    &mut batch,
                    &self.cfg.ppo,
                    &mut self.state.adam,
                    &mut order,
                )
            }
        };
        // The value network's minibatch order from its own stream (3·2³² + k).
        let mut order =
            stack_common::rng::seeded(self.state.seed, (3 << 32) + self.state.iteration);
        self.state.baseline.fit(
            critic_inputs.as_deref().unwrap_or(&batch.obs),
            &times,
            &targets,
            self.cfg.baseline_ridge,
            &self.cfg.value,
            &mut order,
        );
        self.state.iteration += 1;
        let ls = &self.state.policy.log_std;
        Ok(IterationStats {
            iteration: self.state.iteration,
            env_steps: self.state.env_steps,
            episodes,
            update,
            mean_std: ls.iter().map(|l| l.exp()).sum::<f64>() / ls.len() as f64,
            baseline_explained,
        })
    }
}
