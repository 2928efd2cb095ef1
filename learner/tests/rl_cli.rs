//! `learner policy train` and `eval` end to end on a tiny run: files
//! written, a resumed run continues from the checkpoint, the evaluation
//! reports the four categories.

use std::path::Path;
use std::process::{Command, Output};

const CONFIG: &str = r#"
seed = 3
num_envs = 2
threads = 2
env_steps = 80
checkpoint_every = 1

[env]
max_steps = 20

[policy]
batch_steps = 40
hidden = [16, 16]
"#;

fn learner() -> Command {
    Command::new(env!("CARGO_BIN_EXE_learner"))
}

/// `learner policy eval --checkpoint ck [extra…] --json json` to its end;
/// returns the report it wrote and what it printed.
fn eval_report(ck: &Path, extra: &[&str], json: &Path) -> (learner::rl::run::EvalReport, String) {
    let o = learner()
        .args(["policy", "eval"])
        .args(extra)
        .arg("--json")
        .arg(json)
        .arg("--checkpoint")
        .arg(ck)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap();
    (report, String::from_utf8_lossy(&o.stdout).to_string())
}

/// `learner policy train [extra…] --config cfg --out out` to its end.
/// `--set`'s value for a ground-truth observation told the hole with a
/// per-episode error of `std_m` per axis.
fn hole_error(std_m: f64) -> String {
    format!("observation={{ground_truth_hole_error={std_m}}}")
}

fn train(extra: &[&str], cfg: &Path, out: &Path) -> Output {
    learner()
        .args(["policy", "train"])
        .args(extra)
        .arg("--config")
        .arg(cfg)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn train_resume_and_evaluate() {
    let dir = test_support::scratch_dir("rl-cli");
    let cfg = dir.path().join("train.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let out = dir.path().join("run");
    assert!(train(&[], &cfg, &out).status.success());
    for f in ["checkpoint.json", "curve.csv", "return.png", "outcomes.png"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("curve.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2, "{csv}");
    assert!(csv.starts_with("iteration,env_steps,episodes,mean_return"));
    // Resume for 40 more steps: one more update, history kept.
    let resumed = train(&["--resume", "--set", "env_steps=120"], &cfg, &out);
    assert!(resumed.status.success());
    let c = learner::rl::run::read_checkpoint(&out.join("checkpoint.json")).unwrap();
    assert_eq!(c.state.iteration, 3);
    assert_eq!(c.state.env_steps, 120);
    assert_eq!(c.history.len(), 3);
    // A checkpoint after every update: the best policy is that of the
    // update whose episodes earned most.
    let best = c.best.as_ref().expect("episodes ended");
    let top = c
        .history
        .iter()
        .filter_map(|p| p.mean_normalised)
        .fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(best.mean_normalised, top);
    assert_eq!(
        Some(best.mean_normalised),
        c.history[best.iteration as usize - 1].mean_normalised
    );
    let o = learner()
        .args(["policy", "eval", "--episodes", "2", "--checkpoint"])
        .arg(out.join("checkpoint.json"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    for name in [
        "completed insertion",
        "inserted into hole",
        "touched the box",
        "failed",
        "normalised reward",
    ] {
        assert!(text.contains(name), "{text}");
    }
    // Told the hole with an error: 0 mm is the ground truth itself, 20 mm
    // changes what the policy does; a negative one is refused by name.
    let eval = |extra: &[&str], json: &str| {
        let o = learner()
            .args(["policy", "eval", "--episodes", "2", "--checkpoint"])
            .arg(out.join("checkpoint.json"))
            .args(extra)
            .arg("--json")
            .arg(dir.path().join(json))
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let read = |json: &str| std::fs::read_to_string(dir.path().join(json)).unwrap();
    assert!(eval(&[], "exact.json").0);
    assert!(eval(&["--set", &hole_error(0.0)], "zero.json").0);
    assert!(eval(&["--set", &hole_error(0.02)], "off.json").0);
    assert_eq!(read("exact.json"), read("zero.json"));
    assert_ne!(read("exact.json"), read("off.json"));
    let (ok, err) = eval(&["--set", &hole_error(-0.001)], "bad.json");
    assert!(
        !ok && err.contains("observation.ground_truth_hole_error"),
        "{err}"
    );
}

#[test]
fn a_bad_configuration_is_named() {
    let dir = test_support::scratch_dir("rl-cli-bad");
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "[policy.trpo]\nmax_kl = -1.0\n").unwrap();
    let o = train(&[], &cfg, &dir.path().join("run"));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("policy.trpo.max_kl"), "{err}");
    let o = learner()
        .args(["policy", "train", "--config"])
        .arg(dir.path().join("missing.toml"))
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.toml"));
}

#[test]
fn ppo_trains_and_the_evaluation_takes_transfer_and_perturbations() {
    let dir = test_support::scratch_dir("rl-cli-ppo");
    let cfg = dir.path().join("train.toml");
    // Episodes of 20 s: hw-sim's random pushes start within 1–20 s.
    std::fs::write(
        &cfg,
        "seed = 5\nnum_envs = 2\nthreads = 2\nenv_steps = 60\n\n[env]\nmax_steps = 400\n\n\
         [policy]\nbatch_steps = 60\nhidden = [8]\n\n[policy.ppo]\nminibatch = 16\nepochs = 2\n",
    )
    .unwrap();
    let out = dir.path().join("run");
    assert!(
        train(&["--set", "policy.algorithm=ppo"], &cfg, &out)
            .status
            .success()
    );
    let c = learner::rl::run::read_checkpoint(&out.join("checkpoint.json")).unwrap();
    assert_eq!(c.config.policy.algorithm, learner::rl::Algorithm::Ppo);
    // No episode of 400 steps ended in 60: no training result, no best
    // policy yet (evaluation then takes the last).
    assert!(c.best.is_none());
    // 60 steps in one batch: 2 epochs of 4 minibatches of ≤ 16.
    assert_eq!(c.state.adam.t, 8);
    let eval = |extra: &[&str], json: &str| {
        let args = [
            &["--episodes", "1", "--set", "env.world.task.peg=triangle"][..],
            extra,
        ]
        .concat();
        let (r, text) = eval_report(&out.join("checkpoint.json"), &args, &dir.path().join(json));
        assert!(text.contains("triangle peg, trained on square"), "{text}");
        assert_eq!(r.episodes, 1);
        r
    };
    let calm = eval(&[], "calm.json");
    let again = eval(&[], "again.json");
    assert_eq!(calm, again, "an evaluation is repeatable");
    // Actions drawn from the Gaussian: seeded by the episode, so repeatable,
    // and not the mean's episode.
    let sampled = eval(&["--sample"], "sampled.json");
    assert!(sampled.sampled && !calm.sampled);
    assert_eq!(sampled, eval(&["--sample"], "sampled-again.json"));
    assert_ne!(calm.normalised, sampled.normalised, "sampled actions");
    // The same seed and policy: only the perturbation differs.
    let pushed = eval(
        &["--set", "env.world.perturbations.random_pushes=3"],
        "pushed.json",
    );
    assert_ne!(calm.normalised, pushed.normalised, "pushes");
    let noisy = eval(&["--set", "env.world.noise.force_std_n=0.5"], "noisy.json");
    assert_ne!(calm.normalised, noisy.normalised, "force noise");
    // A noise scale of 0 switches the noise off, one of 1 leaves it as set.
    let off = eval(
        &[
            "--set",
            "env.world.noise.force_std_n=0.5",
            "--set",
            "env.world.noise.episode_scale=[0, 0]",
        ],
        "off.json",
    );
    assert_eq!(calm.normalised, off.normalised, "noise scaled to 0");
    let full = eval(
        &[
            "--set",
            "env.world.noise.force_std_n=0.5",
            "--set",
            "env.world.noise.episode_scale=[1, 1]",
        ],
        "full.json",
    );
    assert_eq!(noisy.normalised, full.normalised, "noise scaled by 1");
    let twisted = eval(
        &["--set", "env.world.noise.torque_std_nm=0.05"],
        "twisted.json",
    );
    assert_ne!(calm.normalised, twisted.normalised, "moment noise");
    // The box square to the peg's start instead of turned up to 0.26 rad.
    let square = eval(
        &["--set", "env.world.task.box_yaw_range_rad=0"],
        "square.json",
    );
    assert_ne!(calm.normalised, square.normalised, "box yaw");
    // A bad value is refused, naming what is wrong.
    let refused = |arg: &str| {
        let o = learner()
            .args(["policy", "eval", "--set", arg, "--checkpoint"])
            .arg(out.join("checkpoint.json"))
            .output()
            .unwrap();
        assert!(!o.status.success(), "{arg}");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let err = refused("env.world.task.box_yaw_range_rad=-0.1");
    assert!(err.contains("task.box_yaw_range_rad"), "{err}");
    let err = refused("env.world.noise.force_std_n=-1");
    assert!(err.contains("force_std_n"), "{err}");
    let err = refused("env.world.noise.torque_std_nm=-1");
    assert!(err.contains("torque_std_nm"), "{err}");
    let err = refused("env.world.noise.episode_scale=[-1, -1]");
    assert!(err.contains("noise.episode_scale"), "{err}");
    // A policy cannot be evaluated on inputs it was not trained on.
    let err = refused("observation={representation=\"nowhere\"}");
    assert!(err.contains("does not take"), "{err}");
}

#[test]
fn validation_episodes_choose_the_policy_to_evaluate() {
    use learner::rl::run::{ChosenBy, TrainConfig, read_checkpoint, train};
    let dir = test_support::scratch_dir("rl-cli-validation");
    let text = format!("{CONFIG}\n[validation]\nevery = 1\nepisodes = 2\n");
    let cfg: TrainConfig = toml::from_str(&text).unwrap();
    let out = dir.path().join("run");
    let c = train(cfg, &out, false, &|| false).unwrap();
    // One validation per update, on file and in the checkpoint.
    assert_eq!(c.validations.len(), c.history.len());
    let csv = std::fs::read_to_string(out.join("validation.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + c.validations.len(), "{csv}");
    // The best is the one with most completions, then the highest reward.
    let key = |p: &learner::rl::run::ValidationPoint| (p.outcomes[3], p.mean_normalised);
    let top = c
        .validations
        .iter()
        .max_by(|a, b| key(a).partial_cmp(&key(b)).unwrap())
        .unwrap();
    let best = c.best_validated.as_ref().expect("validated");
    assert_eq!(key(&best.validation), key(top));
    let read = read_checkpoint(&out.join("checkpoint.json")).unwrap();
    let chosen = read.chosen_policy(false);
    assert!(
        matches!(chosen.why, ChosenBy::Validation { .. }),
        "{chosen}"
    );
    assert_eq!(chosen.iteration, best.validation.iteration);
    assert!(matches!(read.chosen_policy(true).why, ChosenBy::Last));
    // Validation needs episodes.
    let bad: TrainConfig = toml::from_str(&format!(
        "{CONFIG}\n[validation]\nevery = 1\nepisodes = 0\n"
    ))
    .unwrap();
    let e = train(bad, &dir.path().join("bad"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("validation.episodes"), "{e}");
}

#[test]
fn the_shipped_policy_configurations_load() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/policy");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        let distill = path
            .file_name()
            .is_some_and(|f| f.to_string_lossy().starts_with("distill"));
        // A distillation's file: its student is a training run's configuration.
        let cfg = if distill {
            learner::rl::distill::read_config(&path).map(|d| d.student)
        } else {
            learner::rl::run::read_config(&path)
        }
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        cfg.env.validate().unwrap();
        cfg.policy.validate().unwrap();
        assert!(cfg.validation.every > 0, "{}", path.display());
        n += 1;
    }
    assert!(n >= 3);
}

#[test]
fn a_run_can_start_from_another_runs_policy() {
    use learner::rl::observe::ObservationKind;
    use learner::rl::run::{TrainConfig, train};
    let dir = test_support::scratch_dir("rl-cli-init");
    let base: TrainConfig = toml::from_str(CONFIG).unwrap();
    let a = train(base.clone(), &dir.path().join("a"), false, &|| false).unwrap();
    // Another configuration (a stiffer wrist), from A's last policy.
    let mut cfg = base.clone();
    cfg.env.controller.impedance.kp = [300.0, 300.0, 300.0, 3000.0, 3000.0, 300.0];
    cfg.init_from = Some(dir.path().join("a/checkpoint.json"));
    cfg.env_steps = 0;
    let b = train(cfg.clone(), &dir.path().join("b"), false, &|| false).unwrap();
    assert_eq!(b.state.policy, a.state.policy);
    assert_eq!(b.state.baseline, a.state.baseline);
    assert_eq!((b.state.iteration, b.state.env_steps), (0, 0));
    assert!(b.history.is_empty());
    // With a value network where the source had the linear baseline: the
    // same policy, a fresh network.
    let mut net = cfg.clone();
    net.policy.baseline = learner::rl::BaselineKind::Network;
    let n = train(net.clone(), &dir.path().join("net"), false, &|| false).unwrap();
    assert_eq!(n.state.policy, a.state.policy);
    assert_eq!(n.state.baseline.kind(), learner::rl::BaselineKind::Network);
    // With an asymmetric critic and a new exploration σ: the same network,
    // every log σ reset, a value network over the ground truth's 18 values
    // and the time, and it trains on.
    let mut asym = net.clone();
    asym.policy.critic = learner::rl::train::CriticInput::GroundTruth;
    asym.policy.init_from_log_std = Some(-2.0);
    asym.env_steps = 40;
    let m = train(asym, &dir.path().join("asym"), false, &|| false).unwrap();
    assert_eq!(m.state.iteration, 1);
    match &m.state.baseline {
        learner::rl::Baseline::Network(v) => assert_eq!(v.sizes[0], 18 + 1),
        other => panic!("{other:?}"),
    }
    assert_eq!(m.state.policy.sizes, a.state.policy.sizes);
    assert!(
        m.state.policy.log_std.iter().all(|l| (l + 2.0).abs() < 0.1),
        "{:?}",
        m.state.policy.log_std
    );
    assert_eq!(m.state.critic_norm.as_ref().map(|c| c.dim()), Some(18));
    // It trains on from there.
    cfg.env_steps = 40;
    let c = train(cfg.clone(), &dir.path().join("c"), false, &|| false).unwrap();
    assert_eq!(c.state.iteration, 1);
    assert_ne!(c.state.policy, a.state.policy);
    // Other hidden layers than the source policy's are refused.
    let mut wide = cfg.clone();
    wide.policy.hidden = vec![32, 32];
    let e = train(wide, &dir.path().join("w"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("policy.hidden"), "{e}");
    // So is another observation normalisation than the source policy's,
    // or another clip, naming the file and the setting.
    let mut raw = cfg.clone();
    raw.policy.normalise_observations = !base.policy.normalise_observations;
    let mut clip = cfg.clone();
    clip.policy.observation_clip = 3.0;
    for (k, other) in [raw, clip].into_iter().enumerate() {
        let e = train(other, &dir.path().join(format!("n{k}")), false, &|| false).unwrap_err();
        assert!(
            e.to_string().contains("a/checkpoint.json")
                && e.to_string().contains("policy.normalise_observations"),
            "{e}"
        );
    }
    // A policy of another observation is refused, naming the file.
    let mut other =
        learner::rl::run::read_checkpoint(&dir.path().join("a/checkpoint.json")).unwrap();
    other.config.observation = ObservationKind::Representation("elsewhere/model".into());
    let path = dir.path().join("other.json");
    std::fs::write(&path, serde_json::to_vec(&other).unwrap()).unwrap();
    cfg.init_from = Some(path);
    let e = train(cfg, &dir.path().join("d"), false, &|| false).unwrap_err();
    assert!(
        e.to_string().contains("other.json") && e.to_string().contains("init_from"),
        "{e}"
    );
}

#[test]
fn the_camera_perturbations_reach_a_representation_policy() {
    use learner::models::{ModelConfig, Normaliser, ReprNet, init};
    let dir = test_support::scratch_dir("rl-cli-camera");
    // An untrained Full Model (d = 16, the camera's 128 px), exported as
    // `learner repr train` does, through the default world's camera.
    let model = ModelConfig {
        latent_dim: 16,
        depth_convs_per_stage: 1,
        ..ModelConfig::default()
    };
    let net = init::seeded(ReprNet::new(&model, &burn::prelude::Device::flex()), 5);
    let model_dir = dir.path().join("model");
    learner::train::checkpoint::export(
        &model_dir,
        &net,
        &learner::train::checkpoint::ExportMeta {
            model: model.clone(),
            normaliser: Normaliser::identity(),
            dataset: "none (untrained)".into(),
            epochs: 0,
            camera: Some(hw_sim::config::CameraConfig::default().calibration()),
        },
    )
    .unwrap();
    // Episodes of 20 s: the random occlusions start within 1–20 s. One
    // update of 40 steps (no episode ends; the evaluation takes the last).
    let cfg = dir.path().join("train.toml");
    std::fs::write(
        &cfg,
        format!(
            "seed = 3\nnum_envs = 2\nthreads = 2\nenv_steps = 40\n\
             observation = {{ representation = {:?} }}\n\n[env]\nmax_steps = 400\n\n\
             [policy]\nbatch_steps = 40\nhidden = [8]\n",
            model_dir.display().to_string()
        ),
    )
    .unwrap();
    let out = dir.path().join("run");
    let o = train(&[], &cfg, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let eval = |extra: &[&str], json: &str| {
        let args = [&["--episodes", "1"][..], extra].concat();
        eval_report(&out.join("checkpoint.json"), &args, &dir.path().join(json))
            .0
            .normalised
    };
    // The policy's actions follow z, so a perturbation of what the camera
    // gives changes the episode; the same seed, nothing else differs.
    let calm = eval(&[], "calm.json");
    assert_eq!(calm, eval(&[], "again.json"), "an evaluation is repeatable");
    for (args, what) in [
        (
            &["--set", "env.world.perturbations.random_occlusions=3"][..],
            "occlusions",
        ),
        (&["--set", "env.world.noise.rgb_std=8"][..], "RGB noise"),
        (
            &["--set", "env.world.noise.depth_std_m=0.005"][..],
            "depth noise",
        ),
    ] {
        assert_ne!(calm, eval(args, &format!("{what}.json")), "{what}");
    }
}
