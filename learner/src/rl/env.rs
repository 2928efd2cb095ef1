//! The RL environment over the fast path: [`RlEnv`] is one episode at a
//! time of [`FastEnv`] (hw-sim's world and rt-controller's control cycle at
//! 1 kHz) acted on at 20 Hz, with the staged reward and the episode's
//! outcome; [`VecEnv`] steps many of them in parallel on all cores and
//! observes them in one batch.
//!
//! Actions: the policy's 4-vector is clipped to [−1, 1] per component and
//! scaled by [`ActionScale`] into (Δx, Δy, Δz) in the base frame, m, and
//! Δroll, rad (`PolicyAction`'s convention); the controller clamps again at
//! its own limits (1 cm, 0.05 rad), which the defaults stay within.
//!
//! An episode ends by truncation after `max_steps` policy steps (500, the
//! paper's simulation episodes), or terminates early when the controller
//! faults (a force overload, a joint limit): the arm is then held and the
//! episode can no longer progress.

use super::reward::{Outcome, RewardConfig, RewardGeometry, RewardStage, reward};
use crate::fast_env::{EnvError, FastEnv};
use hw_sim::{TaskState, WorldConfig};
pub use learner_node::deploy::ActionScale;
use learner_node::observe::ObsView;
use learner_node::policy::{Observation, TaskGeometry};
use nalgebra::Isometry3;
use rt_controller::ControllerConfig;
use serde::{Deserialize, Serialize};
use shared_mem_schema::Message;
use shared_mem_schema::config::FieldError;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// The paper's simulation episode length, policy steps.
pub const PAPER_EPISODE_STEPS: u32 = 500;

/// Why the RL environment failed.
#[derive(Debug, thiserror::Error)]
pub enum RlEnvError {
    /// The fast path could not be built or stepped.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// A configuration value is unusable.
    #[error("invalid RL configuration: {0}")]
    Config(#[from] FieldError),
    /// The representation model the observation names could not be loaded.
    #[error("the observation's representation: {0}")]
    Representation(String),
    /// The world's camera is not the one the observer's representation
    /// was trained with: its z would describe another scene.
    #[error(
        "the world's camera ({world}) is not the camera the representation was trained with \
         ({model}); give the world (its [camera]) the training data's camera"
    )]
    Camera {
        /// The world's.
        world: Box<shared_mem_schema::CameraCalibration>,
        /// The representation's.
        model: Box<shared_mem_schema::CameraCalibration>,
    },
    /// The world has no task (`task.enabled = false`).
    #[error("the RL environment needs the peg-in-hole task (task.enabled = true)")]
    NoTask,
    /// A batch of the wrong size.
    #[error("{what}: {got} values, expected {expected}")]
    Shape {
        /// Which argument.
        what: &'static str,
        /// Values given.
        got: usize,
        /// Values expected.
        expected: usize,
    },
    /// Stepped before its reset, or after its episode ended.
    #[error("environment {0} has no running episode (reset it first)")]
    NotRunning(usize),
}

/// What only the environments a policy learns from do (`[env.training]`,
/// docs/rl.md "Training aids"): validation, evaluation and the live stack
/// never see them, so the real fault stays in every reported number.
///
/// Why: an exploring policy that meets the rim at full speed overloads the
/// force supervisor (100 N), and an episode that ends there loses every
/// reward it would still have earned: from scratch, with the stiff wrist,
/// TRPO learned to hover above the opening rather than risk it. A graded
/// penalty keeps the lesson (press gently) without ending the episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainingAids {
    /// The supervisor's force overload in training, N (None: the
    /// controller's own `safety.max_force_n`).
    pub max_force_n: Option<f64>,
    /// The supervisor's moment overload in training, N·m (None: the
    /// controller's own `safety.max_moment_nm`).
    pub max_moment_nm: Option<f64>,
    /// The force penalty starts at this peak force per step, N.
    pub force_penalty_from_n: f64,
    /// Reward taken per newton of a step's peak force above
    /// `force_penalty_from_n` (0: no penalty).
    pub force_penalty_per_n: f64,
    /// Reward taken, besides, for a step whose peak force is above the
    /// controller's own `safety.max_force_n`: the step that would have
    /// faulted in evaluation (0: none).
    pub overload_penalty: f64,
    /// With a hole error (`observation = { ground_truth_hole_error = σ }`),
    /// the training environments' error grows linearly from 0 to σ over
    /// this many environment steps ([`super::observe::RampedHoleError`]);
    /// 0: σ from the start.
    pub hole_error_ramp_steps: u64,
    /// With a ramped hole error: the ramp advances only through updates
    /// whose training episodes completed the insertion at least this often
    /// (a share, 0..1), so the error grows only while the policy copes
    /// with it; 0: the ramp follows the steps alone.
    pub hole_error_gate: f64,
    /// `[from, to]` environment steps over which the training overload
    /// limits (`max_force_n`, `max_moment_nm`) fall linearly to the
    /// controller's own, the evaluated fault: from `to` on a training
    /// episode ends where an evaluated one would. `[0, 0]`: no ramp.
    pub overload_ramp_steps: [u64; 2],
    /// Potential-based shaping (Ng, Harada and Russell 1999) of lateral
    /// progress: each step earns this much per millimetre by which it
    /// brought the tip's true horizontal distance from the hole's axis
    /// closer, and loses as much per millimetre it moved away (0: none).
    /// Its undiscounted sum over an episode is the potential's change
    /// alone; under the discount γ it departs from the policy-invariant
    /// form γΦ(s') − Φ(s) by (1 − γ)·Φ(s'), a small extra pull towards the
    /// axis. It mostly says sooner which way the opening lies.
    pub lateral_shaping_per_mm: f64,
}

impl Default for TrainingAids {
    fn default() -> Self {
        Self {
            max_force_n: None,
            max_moment_nm: None,
            force_penalty_from_n: 50.0,
            force_penalty_per_n: 0.0,
            overload_penalty: 0.0,
            hole_error_ramp_steps: 0,
            hole_error_gate: 0.0,
            overload_ramp_steps: [0, 0],
            lateral_shaping_per_mm: 0.0,
        }
    }
}

impl TrainingAids {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<(), FieldError> {
        for (name, v) in [
            ("training.max_force_n", self.max_force_n),
            ("training.max_moment_nm", self.max_moment_nm),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v > 0.0)
            {
                return Err(FieldError::new(name, v, "must be positive and finite"));
            }
        }
        for (name, v) in [
            ("training.force_penalty_from_n", self.force_penalty_from_n),
            ("training.force_penalty_per_n", self.force_penalty_per_n),
            ("training.overload_penalty", self.overload_penalty),
            (
                "training.lateral_shaping_per_mm",
                self.lateral_shaping_per_mm,
            ),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(FieldError::new(name, v, "must be finite and >= 0"));
            }
        }
        if !(0.0..=1.0).contains(&self.hole_error_gate) {
            return Err(FieldError::new(
                "training.hole_error_gate",
                self.hole_error_gate,
                "must be a share in 0..1",
            ));
        }
        if self.hole_error_gate > 0.0 && self.hole_error_ramp_steps == 0 {
            return Err(FieldError::new(
                "training.hole_error_gate",
                self.hole_error_gate,
                "gates the hole error's ramp: set training.hole_error_ramp_steps",
            ));
        }
        let [from, to] = self.overload_ramp_steps;
        if from > to || (to > 0 && from == to) {
            return Err(FieldError::new(
                "training.overload_ramp_steps",
                format!("[{from}, {to}]"),
                "must be [from, to] with from < to, or [0, 0] for none",
            ));
        }
        if to > 0 && self.max_force_n.is_none() && self.max_moment_nm.is_none() {
            return Err(FieldError::new(
                "training.overload_ramp_steps",
                format!("[{from}, {to}]"),
                "ramps the training overload limits: set training.max_force_n or \
                 training.max_moment_nm above the controller's",
            ));
        }
        Ok(())
    }

    /// The share of the way from the training limits to the evaluated
    /// ones after `env_steps` (0 before the ramp and without one).
    pub fn overload_share(&self, env_steps: u64) -> f64 {
        let [from, to] = self.overload_ramp_steps;
        if to == 0 {
            return 0.0;
        }
        (env_steps.saturating_sub(from) as f64 / (to - from) as f64).min(1.0)
    }

    /// The reward a step with `peak_force_n` loses where the evaluated
    /// supervisor faults above `limit_n`.
    pub fn force_penalty(&self, peak_force_n: f64, limit_n: f64) -> f64 {
        let over = if peak_force_n > limit_n {
            self.overload_penalty
        } else {
            0.0
        };
        over + self.force_penalty_per_n * (peak_force_n - self.force_penalty_from_n).max(0.0)
    }

    /// The shaping a step from `before` to `after` (tip positions in the
    /// hole frame, m) earns: the potential −k·‖s_xy‖ (k per mm) after
    /// minus before.
    pub fn lateral_shaping(&self, before: &TaskState, after: &TaskState) -> f64 {
        let d = |t: &TaskState| t.s_m.x.hypot(t.s_m.y) * 1e3;
        self.lateral_shaping_per_mm * (d(before) - d(after))
    }
}

/// A share in 0..1 that a training loop sets and environments on other
/// threads read (a schedule's progress).
#[derive(Debug, Default)]
pub struct Share(AtomicU64);

impl Share {
    /// Sets the share, clamped to 0..1 (not finite: 1).
    pub fn set(&self, share: f64) {
        let s = if share.is_finite() {
            share.clamp(0.0, 1.0)
        } else {
            1.0
        };
        self.0.store(s.to_bits(), Ordering::Relaxed);
    }

    /// The share set last (0 before any).
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::Relaxed))
    }
}

/// The RL environment's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RlEnvConfig {
    /// The simulated world (peg, box ranges, noise, perturbations).
    pub world: WorldConfig,
    /// The controller.
    pub controller: ControllerConfig,
    /// The staged reward's constants.
    pub reward: RewardConfig,
    /// The action's scale.
    pub action: ActionScale,
    /// Policy steps per episode before truncation.
    pub max_steps: u32,
    /// What only training environments do.
    pub training: TrainingAids,
}

impl Default for RlEnvConfig {
    fn default() -> Self {
        Self {
            world: WorldConfig::default(),
            controller: ControllerConfig::default(),
            reward: RewardConfig::default(),
            action: ActionScale::default(),
            max_steps: PAPER_EPISODE_STEPS,
            training: TrainingAids::default(),
        }
    }
}

impl RlEnvConfig {
    /// Checks the RL environment's own values (the world and the controller
    /// are checked when built).
    pub fn validate(&self) -> Result<(), FieldError> {
        self.reward.validate()?;
        self.training.validate()?;
        for (name, v) in [
            ("action.max_step_m", self.action.max_step_m),
            ("action.max_roll_rad", self.action.max_roll_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(FieldError::new(name, v, "must be positive and finite"));
            }
        }
        if self.max_steps == 0 {
            return Err(FieldError::new("max_steps", 0, "must be at least 1"));
        }
        Ok(())
    }
}

/// What one policy step of one environment gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    /// The staged reward of the state reached.
    pub reward: f64,
    /// Its stage.
    pub stage: RewardStage,
    /// The episode ended early (a controller fault): no value to bootstrap.
    pub terminated: bool,
    /// The episode reached `max_steps`.
    pub truncated: bool,
    /// The episode's category so far (the best stage the simulator saw).
    pub outcome: Outcome,
    /// Policy steps taken in the episode.
    pub steps: u32,
    /// Sum of the episode's rewards so far.
    pub episode_reward: f64,
}

impl StepOutcome {
    /// The episode ended (terminated or truncated).
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// One environment.
pub struct RlEnv {
    fast: FastEnv,
    reward: RewardConfig,
    action: ActionScale,
    max_steps: u32,
    geom: RewardGeometry,
    obs: Option<Observation>,
    hole: Isometry3<f64>,
    free_wrench: [f64; 6],
    steps: u32,
    episode_reward: f64,
    running: bool,
    camera: Option<Box<shared_mem_schema::CameraFrame>>,
    aids: Option<TrainingAids>,
    /// The configured (evaluated) force overload, N.
    eval_max_force_n: f64,
    /// The configured (evaluated) moment overload, N·m.
    eval_max_moment_nm: f64,
    /// How far the training overload limits have fallen to the evaluated
    /// ones (`training.overload_ramp_steps`).
    overload_share: Arc<Share>,
}

impl RlEnv {
    /// Builds the environment as it is evaluated (no training aids); call
    /// [`RlEnv::reset`] before stepping.
    pub fn new(cfg: &RlEnvConfig) -> Result<Self, RlEnvError> {
        Self::build(cfg, None)
    }

    /// Builds an environment to learn from: `cfg.training`'s aids applied
    /// (the supervisor's training limits, the force penalty).
    pub fn for_training(cfg: &RlEnvConfig) -> Result<Self, RlEnvError> {
        Self::build(cfg, Some(cfg.training.clone()))
    }

    fn build(cfg: &RlEnvConfig, aids: Option<TrainingAids>) -> Result<Self, RlEnvError> {
        cfg.validate()?;
        if !cfg.world.task.enabled {
            return Err(RlEnvError::NoTask);
        }
        let mut controller = cfg.controller.clone();
        if let Some(a) = &aids {
            let s = &mut controller.safety;
            s.max_force_n = a.max_force_n.unwrap_or(s.max_force_n);
            s.max_moment_nm = a.max_moment_nm.unwrap_or(s.max_moment_nm);
        }
        let fast = FastEnv::new(cfg.world.clone(), controller)?;
        let geom = RewardGeometry {
            hole_depth_m: cfg.world.task.hole_depth_m,
            symmetry: cfg.world.task.peg.symmetry_order(),
        };
        Ok(Self {
            fast,
            reward: cfg.reward.clone(),
            action: cfg.action.clone(),
            max_steps: cfg.max_steps,
            geom,
            obs: None,
            hole: Isometry3::identity(),
            free_wrench: [0.0; 6],
            steps: 0,
            episode_reward: 0.0,
            running: false,
            camera: None,
            aids,
            eval_max_force_n: cfg.controller.safety.max_force_n,
            eval_max_moment_nm: cfg.controller.safety.max_moment_nm,
            overload_share: Arc::default(),
        })
    }

    /// Starts an episode: the world rebuilt with `seed` (which draws the
    /// box pose), then one policy period with no action so that the first
    /// observation has a full wrench window and a settled arm.
    pub fn reset(&mut self, seed: u64, camera: bool) -> Result<(), RlEnvError> {
        self.fast.reset(seed)?;
        let obs = self.fast.step(None)?;
        self.free_wrench = self.fast.sensor_frame().wrench;
        self.hole = self.fast.world().hole_pose().ok_or(RlEnvError::NoTask)?;
        self.obs = Some(obs);
        self.steps = 0;
        self.episode_reward = 0.0;
        self.running = true;
        self.render(camera);
        Ok(())
    }

    fn render(&mut self, camera: bool) {
        if camera {
            let msg = self
                .camera
                .get_or_insert_with(shared_mem_schema::CameraFrame::boxed_zeroed);
            self.fast.render_camera(msg);
        }
    }

    /// One policy step with the policy output `a` (clipped and scaled by
    /// the action scale).
    pub fn step(&mut self, a: &[f64], camera: bool) -> Result<StepOutcome, RlEnvError> {
        if !self.running {
            return Err(RlEnvError::NotRunning(0));
        }
        let delta = self.action.to_delta(a);
        let before = *self.task();
        let obs = self.fast.step(Some(&delta))?;
        self.obs = Some(obs);
        self.steps += 1;
        let task = *self.task();
        let (mut r, stage) = reward(&self.reward, &self.geom, &task);
        if let Some(a) = &self.aids {
            r -= a.force_penalty(self.fast.peak_force_n(), self.eval_max_force_n);
            r += a.lateral_shaping(&before, &task);
        }
        self.episode_reward += r;
        let terminated = self.fast.sensor_frame().fault_code != 0 || self.ramped_overload();
        let truncated = !terminated && self.steps >= self.max_steps;
        self.running = !(terminated || truncated);
        self.render(camera);
        Ok(StepOutcome {
            reward: r,
            stage,
            terminated,
            truncated,
            outcome: Outcome::from_stage(task.best_stage),
            steps: self.steps,
            episode_reward: self.episode_reward,
        })
    }

    /// Makes this environment read the overload ramp's progress from `share`.
    pub fn share_overload_ramp(&mut self, share: Arc<Share>) {
        self.overload_share = share;
    }

    /// The training overload limits in force now, (N, N·m): the training
    /// aids' own moved `overload_share` of the way to the evaluated ones
    /// (None: an evaluated environment, the controller's limits alone).
    pub fn overload_limits(&self) -> Option<(f64, f64)> {
        let a = self.aids.as_ref()?;
        let s = self.overload_share.get();
        let lerp = |train: Option<f64>, eval: f64| {
            let t = train.unwrap_or(eval);
            t + s * (eval - t)
        };
        Some((
            lerp(a.max_force_n, self.eval_max_force_n),
            lerp(a.max_moment_nm, self.eval_max_moment_nm),
        ))
    }

    /// The last step went past the ramped training limits, below the
    /// controller's own (which latch a fault themselves): the training
    /// episode ends there, as a fault would end it.
    fn ramped_overload(&self) -> bool {
        if self.overload_share.get() <= 0.0 {
            return false;
        }
        self.overload_limits()
            .is_some_and(|(f, m)| self.fast.peak_force_n() > f || self.fast.peak_moment_nm() > m)
    }

    /// The simulator's task state (present: the task is required).
    pub fn task(&self) -> &TaskState {
        self.fast.world().task().expect("the task is enabled")
    }

    /// Where the hole is, as the scripted policies take it.
    pub fn task_geometry(&self) -> TaskGeometry {
        TaskGeometry {
            hole_pose: self.hole,
            symmetry: self.geom.symmetry,
            depth_m: self.geom.hole_depth_m,
        }
    }

    /// The observation of the last step (None before the first reset).
    pub fn observation(&self) -> Option<&Observation> {
        self.obs.as_ref()
    }

    /// The fast path underneath.
    pub fn fast(&self) -> &FastEnv {
        &self.fast
    }

    /// The action scale.
    pub fn action_scale(&self) -> &ActionScale {
        &self.action
    }

    /// The reward's geometry (hole depth, symmetry).
    pub fn reward_geometry(&self) -> RewardGeometry {
        self.geom
    }

    /// What an observer reads (None before the first reset).
    pub fn view(&self) -> Option<ObsView<'_>> {
        Some(ObsView {
            obs: self.obs.as_ref()?,
            wrench: &self.fast.wrench,
            free_wrench: &self.free_wrench,
            task: self.task(),
            hole_pose: &self.hole,
            symmetry: self.geom.symmetry,
            camera: self.camera.as_deref(),
        })
    }
}
