//! Training the representation on a real (small) dataset: a fast-mode
//! collection at 64×64 px, built into a dataset; a short training run whose
//! losses fall and whose contact accuracy beats the majority class on the
//! test split; an interrupted run that resumes to the same parameters as an
//! uninterrupted one; the exported model's encoder and evaluation.

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::*;
use learner::collect::{CollectConfig, collect_fast};
use learner::dataset::{self, BuildConfig, Dataset};
use learner::models::{Encoder, ModelKind, ObservationRef};
use learner::train::{self, Split, TrainConfig, TrainOptions};
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const SIDE: u32 = 64;

/// One dataset for every test of this file: 8 heuristic episodes of 100
/// actions (5 s: approach, insertion, and pressing at the bottom, where
/// contact is), two pegs.
fn dataset() -> &'static Path {
    static DIR: OnceLock<(test_support::ScratchDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let root = test_support::scratch_dir("repr-data");
        let logs = root.join("logs");
        let mut world = hw_sim::WorldConfig::default();
        world.task.enabled = true;
        world.camera.width = SIDE;
        world.camera.height = SIDE;
        let cfg = CollectConfig {
            out_dir: logs.clone(),
            states: u64::MAX,
            episodes: Some(8),
            episode_actions: 100,
            pegs: vec![hw_sim::PegShape::Square, hw_sim::PegShape::Hexagon],
            seed: 21,
            workers: 2,
            world,
            controller: rt_controller::ControllerConfig::default(),
            mix: Mix {
                heuristic_fraction: 1.0,
                end_after_completion: None,
                ..Mix::default()
            },
            log: LogOptions {
                view_rate_hz: 10.0,
                ..LogOptions::default()
            },
            resume: false,
        };
        collect_fast(&cfg, &AtomicBool::new(false)).unwrap();
        let out = root.join("ds");
        let files = dataset::find_logs(std::slice::from_ref(&logs)).unwrap();
        let b = BuildConfig {
            block_samples: 16,
            ..BuildConfig::default()
        };
        dataset::build(&files, &out, &b, 2, |p, r| {
            if let Err(e) = r {
                panic!("{}: {e}", p.display());
            }
        })
        .unwrap();
        (root, out)
    })
    .1
}

fn small(kind: ModelKind, epochs: u32) -> TrainConfig {
    let mut c = TrainConfig::default();
    c.model.kind = kind;
    c.model.latent_dim = 16;
    c.model.image_size = SIDE as usize;
    c.model.depth_convs_per_stage = 1;
    c.train.batch = 32;
    c.train.epochs = epochs;
    c.train.lr = 1e-3;
    c.train.seed = 3;
    c.train.test_fraction = 0.25;
    c.train.shuffle_blocks = 4;
    c
}

#[test]
fn the_split_keeps_every_episode_on_one_side() {
    let ds = Dataset::open(dataset()).unwrap();
    let s = Split::by_episode(&ds.meta, 0.25, 3);
    assert!(!s.test.is_empty() && !s.train.is_empty());
    for e in &s.test {
        assert!(!s.train.contains(e), "episode {e} on both sides");
    }
    assert_eq!(s.train.len() + s.test.len(), ds.meta.episodes.len());
    // Each peg has a test episode.
    for peg in [hw_sim::PegShape::Square, hw_sim::PegShape::Hexagon] {
        assert!(
            ds.meta
                .episodes
                .iter()
                .any(|e| e.peg == peg && s.test.contains(&e.episode))
        );
    }
    // The loader restricted to the test episodes yields only theirs.
    let loader = dataset::Loader::new(
        &ds,
        dataset::LoaderConfig {
            batch: 16,
            episodes: Some(std::sync::Arc::new(Split::table(&s.test))),
            ..Default::default()
        },
    );
    let mut n = 0;
    for b in loader {
        for smp in b.unwrap().samples {
            assert!(s.test.contains(&smp.episode));
            n += 1;
        }
    }
    assert_eq!(n as u64, Split::samples(&ds.meta, &s.test));
    // The split keeps the dataset's camera; read back against a dataset of
    // another camera (a resume on a rebuilt dataset), it is refused.
    assert!(s.camera.is_some() && s.camera == ds.meta.camera);
    let dir = test_support::scratch_dir("split");
    let path = dir.join("split.json");
    std::fs::write(&path, serde_json::to_vec(&s).unwrap()).unwrap();
    assert_eq!(Split::read(&path, &ds.meta).unwrap(), s);
    let mut other = ds.meta.clone();
    other.camera.as_mut().unwrap().pose_pos_m[2] += 0.05;
    let e = Split::read(&path, &other).unwrap_err().to_string();
    assert!(
        e.contains("the run started on a dataset of the camera"),
        "{e}"
    );
}

#[test]
fn a_short_run_learns_contact_better_than_the_majority_and_its_losses_fall() {
    let out = test_support::scratch_dir("repr-run");
    let cfg = small(ModelKind::Full, 8);
    let s = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false).unwrap();
    assert!(s.finished);
    let train_rows: Vec<_> = s.rows.iter().filter(|r| r.split == "train").collect();
    let test_rows: Vec<_> = s.rows.iter().filter(|r| r.split == "test").collect();
    assert_eq!(train_rows.len(), 8);
    let (first, last) = (train_rows[0], train_rows[7]);
    eprintln!("first {first:?}\nlast {last:?}\ntest {:?}", test_rows[7]);
    assert!(last.loss.total < first.loss.total, "total loss fell");
    assert!(last.loss.flow < first.loss.flow, "flow loss fell");
    assert!(last.loss.contact < first.loss.contact, "contact loss fell");
    let t = test_rows[7];
    assert!(
        t.contact_acc > t.contact_majority_acc,
        "test contact accuracy {} vs majority {}",
        t.contact_acc,
        t.contact_majority_acc
    );
    // The files a run leaves.
    for f in [
        "config.toml",
        "split.json",
        "metrics.csv",
        "curve_total.png",
        "curve_contact_acc.png",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 16);
    // The exported model encodes observations, the mean of z, batch-size
    // independent.
    let dev = burn::prelude::Device::flex();
    let enc = Encoder::load(&s.model_dir, &dev).unwrap();
    let ds = Dataset::open(dataset()).unwrap();
    let smp = ds.read_block(0, 0).unwrap();
    let obs: Vec<ObservationRef<'_>> = smp.iter().take(5).map(ObservationRef::from).collect();
    let z = enc.encode(&obs).unwrap();
    assert_eq!(z.len(), 5 * 16);
    let z1 = enc.encode(&obs[2..3]).unwrap();
    for (a, b) in z1.iter().zip(&z[2 * 16..3 * 16]) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }
    // A wrong-sized image is refused, naming it.
    let mut bad = smp[0].clone();
    bad.rgb.truncate(10);
    let e = enc
        .encode(&[ObservationRef::from(&bad)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("rgb"), "{e}");

    // Evaluation: the table with its baselines and the pictures.
    let eval_dir = out.join("eval");
    let r = train::eval::eval(&train::eval::EvalOptions {
        run: out.to_path_buf(),
        data: dataset().to_path_buf(),
        out: eval_dir.clone(),
        device: Default::default(),
        pca_samples: 200,
        flow_images: 2,
    })
    .unwrap();
    assert_eq!(r.rows.len(), 5, "all sensors and each one masked");
    assert!(r.markdown.contains("majority contact acc"));
    assert!(
        r.markdown.contains("epoch 8 (as trained)"),
        "{}",
        r.markdown
    );
    for f in [
        "table.md",
        "flow_actions.png",
        "pca_z_contact.png",
        "pca_z_policy.png",
    ] {
        assert!(eval_dir.join(f).exists(), "{f}");
    }
}

/// Every parameter value of a run's exported model, in module order (the
/// files also hold parameter ids, which differ between runs).
fn weights(dir: &Path) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0.extend(p.val().try_into_vec_as::<f32>().unwrap());
        }
    }
    let dev = Device::flex();
    let (net, _) = train::checkpoint::import(&dir.join("model"), &dev).unwrap();
    let mut c = Collect(Vec::new());
    net.visit(&mut c);
    assert!(c.0.len() > 1000);
    c.0
}

#[test]
fn an_interrupted_run_resumes_to_the_same_parameters() {
    let mut cfg = small(ModelKind::Full, 2);
    cfg.train.checkpoint_every = 1000;
    let whole = test_support::scratch_dir("repr-whole");
    train::train(&cfg, dataset(), &whole, &TrainOptions::default(), &|| false).unwrap();
    // Interrupted after 3 steps of the first epoch, resumed twice.
    let parts = test_support::scratch_dir("repr-parts");
    let stop_at = |n| TrainOptions {
        stop_after_steps: Some(n),
        ..Default::default()
    };
    let s = train::train(&cfg, dataset(), &parts, &stop_at(3), &|| false).unwrap();
    assert!(!s.finished);
    assert_eq!(s.steps, 3);
    // Starting over into a used directory is refused.
    let e = train::train(&cfg, dataset(), &parts, &TrainOptions::default(), &|| false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--resume"), "{e}");
    let resume = |n: Option<u64>| TrainOptions {
        resume: true,
        stop_after_steps: n,
        ..Default::default()
    };
    let s = train::train(&cfg, dataset(), &parts, &resume(Some(4)), &|| false).unwrap();
    assert_eq!(s.steps, 7);
    let s = train::train(&cfg, dataset(), &parts, &resume(None), &|| false).unwrap();
    assert!(s.finished);
    let (a, b) = (weights(&whole), weights(&parts));
    assert!(a == b, "resumed parameters differ");
    let a = std::fs::read_to_string(whole.join("metrics.csv")).unwrap();
    let b = std::fs::read_to_string(parts.join("metrics.csv")).unwrap();
    assert_eq!(a, b);
    // A finished run is extended by a resume with more epochs (the only
    // field a resume may change).
    let mut longer = cfg.clone();
    longer.train.epochs = 3;
    let s3 = train::train(&longer, dataset(), &parts, &resume(None), &|| false).unwrap();
    assert!(s3.finished && s3.steps > s.steps);
    assert_eq!(s3.rows.len(), 6);
    // Resuming with another configuration is refused.
    let mut other = cfg.clone();
    other.train.lr = 0.5;
    let e = train::train(&other, dataset(), &parts, &resume(None), &|| false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("another configuration"), "{e}");
}

/// A variant without a pairing loss writes NaN accuracies into its rows (as
/// JSON nulls in the checkpoint); stopped after its first epoch, it resumes.
#[test]
fn a_run_without_pairing_resumes_after_its_first_epoch() {
    let mut cfg = small(ModelKind::Full, 2);
    cfg.loss.pairing = 0.0;
    cfg.train.max_batches_per_epoch = 2;
    cfg.train.max_test_batches = 1;
    cfg.train.checkpoint_every = 1000;
    let out = test_support::scratch_dir("repr-no-pairing");
    let opts = |resume, n| TrainOptions {
        resume,
        stop_after_steps: n,
        ..Default::default()
    };
    let s = train::train(&cfg, dataset(), &out, &opts(false, Some(3)), &|| false).unwrap();
    assert!(!s.finished);
    assert!(
        s.rows.iter().any(|r| r.pairing_acc.is_nan()),
        "{:?}",
        s.rows
    );
    let s = train::train(&cfg, dataset(), &out, &opts(true, None), &|| false)
        .expect("a checkpoint with NaN accuracies resumes");
    assert!(s.finished);
    assert_eq!(s.rows.len(), 4);
    assert!(
        s.rows
            .iter()
            .all(|r| r.pairing_acc.is_nan() && r.loss.pairing.is_nan())
    );
}

#[test]
fn the_baselines_train_on_the_same_data() {
    for kind in [ModelKind::Deterministic, ModelKind::Reconstruction] {
        let out = test_support::scratch_dir("repr-baseline");
        let mut cfg = small(kind, 1);
        cfg.train.max_batches_per_epoch = 3;
        let s = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false).unwrap();
        assert!(s.finished, "{kind:?}");
        let test = s.rows.iter().find(|r| r.split == "test").unwrap();
        assert!(test.loss.total.is_finite(), "{kind:?}: {test:?}");
        match kind {
            ModelKind::Deterministic => {
                assert!(test.loss.kl.is_nan() && test.loss.flow.is_finite())
            }
            _ => {
                assert!(test.loss.recon_rgb.is_finite() && test.loss.flow.is_nan());
                // No heads, no accuracies (not a 0 % that reads as measured).
                assert!(test.contact_acc.is_nan() && test.pairing_acc.is_nan());
            }
        }
    }
}

#[test]
fn the_pose_target_trains_exports_and_encodes() {
    let out = test_support::scratch_dir("repr-ee-pose");
    let mut cfg = small(ModelKind::Full, 1);
    cfg.model.ee_target = learner::models::EeTarget::Pose;
    cfg.train.max_batches_per_epoch = 3;
    let s = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false).unwrap();
    let test = s.rows.iter().find(|r| r.split == "test").unwrap();
    assert!(test.loss.ee.is_finite() && test.loss.ee > 0.0, "{test:?}");
    // The export says which head it has, so it loads into the same shape,
    // and encodes.
    let enc = learner::models::Encoder::load(&s.model_dir, &Device::flex()).unwrap();
    assert_eq!(enc.config().ee_target, learner::models::EeTarget::Pose);
    let ds = Dataset::open(dataset()).unwrap();
    let smp = ds.read_block(0, 0).unwrap();
    let obs: Vec<ObservationRef<'_>> = smp.iter().take(3).map(ObservationRef::from).collect();
    let z = enc.encode(&obs).unwrap();
    assert!(z.len() == 3 * 16 && z.iter().all(|x| x.is_finite()));
    // Evaluation makes the pose labels and names the target.
    let opts = train::eval::EvalOptions {
        run: out.to_path_buf(),
        data: dataset().to_path_buf(),
        out: out.join("eval"),
        device: Default::default(),
        pca_samples: 50,
        flow_images: 1,
    };
    let r = train::eval::eval(&opts).unwrap();
    assert!(
        r.markdown.contains("end-effector target Pose"),
        "{}",
        r.markdown
    );
    assert!(r.rows[0].1.loss.ee.is_finite());
    // A run whose configuration no longer matches its export is refused.
    let cfg_path = out.join("config.toml");
    let text = std::fs::read_to_string(&cfg_path).unwrap();
    assert!(text.contains("ee_target = \"pose\""), "{text}");
    std::fs::write(&cfg_path, text.replace("ee_target = \"pose\"", "")).unwrap();
    let e = train::eval::eval(&opts).unwrap_err().to_string();
    assert!(e.contains("disagree"), "{e}");
}

#[test]
fn a_dataset_of_another_image_size_is_refused() {
    let out = test_support::scratch_dir("repr-mismatch");
    let mut cfg = small(ModelKind::Full, 1);
    cfg.model.image_size = 128;
    let e = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("64×64") && e.contains("image_size"), "{e}");
}

#[test]
fn the_frozen_representation_observes_the_rl_environment() {
    use learner::rl::{BatchEnv, ObservationKind, Observer, RlEnvConfig, VecEnv};
    let out = test_support::scratch_dir("repr-observer");
    let mut cfg = small(ModelKind::Full, 1);
    cfg.train.max_batches_per_epoch = 2;
    let s = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false).unwrap();
    let mut env = RlEnvConfig {
        max_steps: 20,
        ..Default::default()
    };
    env.world.camera.width = SIDE;
    env.world.camera.height = SIDE;
    let kind = ObservationKind::Representation(s.model_dir.clone());
    let observer = kind.observer().unwrap();
    assert_eq!(observer.dim(), 16);
    assert!(observer.needs_camera());
    let mut v = VecEnv::new(&env, 2, observer, 2).unwrap();
    v.reset(&[(0, 5), (1, 6)]).unwrap();
    let first = v.observations().to_vec();
    assert_eq!(first.len(), 2 * 16);
    for _ in 0..3 {
        v.step(&[0.0, 0.0, -1.0, 0.0, 0.5, 0.0, -1.0, 0.0]).unwrap();
    }
    let later = v.observations().to_vec();
    assert!(later.iter().all(|x| x.is_finite()));
    assert!(
        later.iter().any(|&x| x != 0.0),
        "not the zeros of a refused batch"
    );
    assert_ne!(first, later, "z follows the arm");
    // The two environments (different boxes) are told apart.
    assert_ne!(later[..16], later[16..]);
    // A model directory that is not there is refused, naming it.
    let e = ObservationKind::Representation(out.join("nowhere"))
        .observer()
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("nowhere"), "{e}");
    // The export keeps the dataset's camera; a world with another camera
    // (another size, or the same moved by 5 cm) is refused before any step.
    let rep = std::sync::Arc::new(learner::rl::represent::load(&s.model_dir).unwrap());
    let trained = rep.camera().expect("the export keeps the camera");
    assert!(trained.same_camera(&env.world.camera.calibration()));
    let mut wide = env.clone();
    wide.world.camera.width = 128;
    wide.world.camera.height = 128;
    let mut moved = env.clone();
    moved.world.camera.eye_m[0] += 0.05;
    for other in [&wide, &moved] {
        let e = VecEnv::new(other, 1, rep.clone(), 1)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("the world's camera") && e.contains("trained with"),
            "{e}"
        );
    }
    // Past that check (an observer that does not say its camera), frames
    // of another camera are still not encoded: zeros, counted.
    struct Unchecked(std::sync::Arc<learner::rl::Representation>);
    impl learner::rl::observe::Observer for Unchecked {
        fn dim(&self) -> usize {
            self.0.dim()
        }
        fn needs_camera(&self) -> bool {
            true
        }
        fn observe(&self, views: &[learner::rl::observe::ObsView<'_>], out: &mut [f64]) {
            self.0.observe(views, out)
        }
    }
    for other in [&wide, &moved] {
        let before = rep.rejected();
        let unchecked = std::sync::Arc::new(Unchecked(rep.clone()));
        let mut v = VecEnv::new(other, 1, unchecked, 1).unwrap();
        v.reset(&[(0, 5)]).unwrap();
        assert!(v.observations().iter().all(|&x| x == 0.0));
        assert!(rep.rejected() > before);
    }
}

#[test]
fn distill_keeps_a_camera_observing_teachers_camera() {
    use learner::rl::distill::{DistillConfig, distill};
    use learner::rl::{GaussianPolicy, ObservationKind};
    let out = test_support::scratch_dir("repr-distill-camera");
    let mut cfg = small(ModelKind::Full, 1);
    cfg.train.max_batches_per_epoch = 2;
    let s = train::train(&cfg, dataset(), &out, &TrainOptions::default(), &|| false).unwrap();
    // A teacher on the representation: a short ground-truth run whose
    // checkpoint is then said to observe z, with a policy of z's size.
    let teacher_cfg: learner::rl::run::TrainConfig = toml::from_str(
        "seed = 3\nnum_envs = 1\nthreads = 1\nenv_steps = 20\n\
         [env]\nmax_steps = 20\n[policy]\nbatch_steps = 20\nhidden = [8]\n",
    )
    .unwrap();
    let run = out.join("teacher");
    let mut c = learner::rl::run::train(teacher_cfg, &run, false, &|| false).unwrap();
    c.config.observation = ObservationKind::Representation(s.model_dir.clone());
    c.config.env.world.camera.width = SIDE;
    c.config.env.world.camera.height = SIDE;
    c.state.policy = GaussianPolicy::new(16, &[8], 4, -1.0, &mut hw_sim::rng::seeded(1, 0));
    c.best = None;
    c.best_validated = None;
    let path = run.join("on-z.json");
    std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
    let text = format!(
        "teacher = \"{}\"\n[student]\nnum_envs = 1\nthreads = 1\n\
         [student.validation]\nepisodes = 1\n[dagger]\nrounds = 1\nsteps_per_round = 20\n\
         [camera]\nvertical_fov_deg = 40.0\n",
        path.display()
    );
    let dc: DistillConfig = toml::from_str(&text).unwrap();
    // The teacher sees through its own environment's camera: another one
    // for the student would change the teacher's inputs, so it is refused
    // before any step.
    let e = distill(dc, &out.join("student"), false, &|| false)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera") && e.contains("the teacher observes through"),
        "{e}"
    );
    assert!(!out.join("student/checkpoint.json").exists());
}

#[test]
fn the_command_killed_mid_epoch_resumes_from_its_checkpoint() {
    use std::process::{Command, Stdio};
    let dir = test_support::scratch_dir("repr-kill");
    let mut cfg = small(ModelKind::Full, 2);
    cfg.train.checkpoint_every = 2;
    let config = dir.join("small.toml");
    std::fs::write(&config, toml::to_string(&cfg).unwrap()).unwrap();
    let out = dir.join("run");
    let cmd = |resume: bool| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_learner"));
        c.args(["repr", "train", "--config"])
            .arg(&config)
            .arg("--data")
            .arg(dataset())
            .arg("--out")
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        if resume {
            c.arg("--resume");
        }
        c
    };
    let mut child = cmd(false).spawn().unwrap();
    // Killed (SIGKILL: no chance to checkpoint) once a checkpoint of the
    // first epoch exists.
    let state = out.join("checkpoint").join("state.json");
    let t0 = std::time::Instant::now();
    let steps_at_kill = loop {
        if let Ok(text) = std::fs::read(&state) {
            let s: train::checkpoint::LoopState = serde_json::from_slice(&text).unwrap();
            if s.steps >= 2 && s.epoch == 0 {
                child.kill().unwrap();
                child.wait().unwrap();
                break s.steps;
            }
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before a checkpoint"
        );
        assert!(t0.elapsed().as_secs() < 300, "no checkpoint within 300 s");
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    assert!(!out.join("model").exists(), "killed before the end");
    // A new run into the same directory is refused; --resume finishes it.
    assert!(!cmd(false).status().unwrap().success());
    assert!(cmd(true).status().unwrap().success());
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 4, "{csv}");
    let s: train::checkpoint::LoopState =
        serde_json::from_slice(&std::fs::read(&state).unwrap()).unwrap();
    assert!(s.steps > steps_at_kill && s.epoch == 2);
    assert!(out.join("model").join("model.json").exists());
}

/// An experiment without its dataset collects it in the policy
/// configuration's world: the representation learns the camera the policy
/// will see through. Only the pegs `collect_pegs` names are collected (the
/// transfer experiments' representation that has seen one peg).
#[test]
fn an_experiment_collects_through_the_policys_camera() {
    use learner::experiment::{ExperimentConfig, RunOptions, run};
    let dir = test_support::scratch_dir("experiment-camera");
    // The policy's camera, which the collection's own world shares.
    let camera = format!(
        "width = {SIDE}\nheight = {SIDE}\neye_m = [0.9, -0.24, 0.77]\ntarget_m = [0.58, 0.0, 0.2]\n"
    );
    let policy = dir.join("policy.toml");
    std::fs::write(
        &policy,
        format!("num_envs = 2\nenv_steps = 400\n\n[env.world.camera]\n{camera}"),
    )
    .unwrap();
    let repr = dir.join("repr.toml");
    std::fs::write(
        &repr,
        format!("[model]\nkind = \"full\"\nlatent_dim = 16\nimage_size = {SIDE}\n"),
    )
    .unwrap();
    let data = dir.join("data");
    // The collection's own world: the policy's camera, the box turned by at
    // most 0.05 rad (the policy's world keeps the default 0.26).
    let world = dir.join("world.toml");
    std::fs::write(
        &world,
        format!("[camera]\n{camera}\n[task]\nbox_yaw_range_rad = 0.05\n"),
    )
    .unwrap();
    let cfg_path = dir.join("experiment.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[data]\ndataset = {data:?}\ncollect_states = 120\n\
             collect_pegs = [\"hexagon\", \"triangle\"]\ncollect_world = {world:?}\n\n\
             [policy]\nconfig = {policy:?}\n\n\
             [[variant]]\nname = \"Full\"\nrepresentation = {repr:?}\n"
        ),
    )
    .unwrap();
    let cfg = ExperimentConfig::from_file(&cfg_path).unwrap();
    // Stopped once the dataset is built: only the collection is tested.
    let built = || data.join("meta.json").exists();
    let e = run(&cfg, &dir.join("out"), &RunOptions::default(), &built).unwrap_err();
    assert!(e.to_string().contains("stopped"), "{e}");
    let ds = Dataset::open(&data).unwrap();
    let pcfg = learner::rl::run::read_config(&policy).unwrap();
    let camera = ds.meta.camera.expect("kept");
    assert!(camera.same_camera(&pcfg.env.world.camera.calibration()));
    assert!(!camera.same_camera(&hw_sim::config::CameraConfig::default().calibration()));
    let manifest = std::fs::read_to_string(dir.join("out/collect/manifest.jsonl")).unwrap();
    // Taken in turn by episode number (workers may finish out of order).
    let episodes: Vec<serde_json::Value> = manifest
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(episodes.len() >= 2, "{manifest}");
    for e in &episodes {
        let i = e["episode"].as_u64().unwrap() as usize;
        assert_eq!(e["peg"], ["hexagon", "triangle"][i % 2], "{manifest}");
    }
    let log =
        learner_node::log::LogReader::open(&dir.join("out/collect/episode-000000.mcap")).unwrap();
    let logged = &log.read_config(None).unwrap()[0].1;
    assert_eq!(
        logged.world.task.box_yaw_range_rad, 0.05,
        "collected in collect_world"
    );
    assert_eq!(pcfg.env.world.task.box_yaw_range_rad, 0.26);
    // A collection world with another camera is refused before anything
    // runs, naming the field.
    std::fs::write(&world, "[task]\nbox_yaw_range_rad = 0.05\n").unwrap();
    let mut other = cfg.clone();
    other.data.dataset = dir.join("data2");
    let e = run(&other, &dir.join("out3"), &RunOptions::default(), &|| false)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("data.collect_world") && e.contains("camera"),
        "{e}"
    );
    assert!(!dir.join("out3/collect").exists());
    // The dataset, now there, under a policy with another camera: refused
    // before any training, naming the dataset.
    std::fs::write(
        &policy,
        format!("num_envs = 2\n\n[env.world.camera]\nwidth = {SIDE}\nheight = {SIDE}\n"),
    )
    .unwrap();
    let e = run(&cfg, &dir.join("out2"), &RunOptions::default(), &|| false)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("data.dataset") && e.contains("is not the policy's world's"),
        "{e}"
    );
    assert!(!dir.join("out2/Full/repr").exists());
}

/// A Full Model of d = 16 at the test images' size, one depth convolution
/// per stage, written as `repr.toml` in `dir`: the experiments' tests'
/// representation.
fn tiny_repr_config(dir: &Path) -> PathBuf {
    let repr = dir.join("repr.toml");
    std::fs::write(
        &repr,
        format!(
            "[model]\nkind = \"full\"\nlatent_dim = 16\nimage_size = {SIDE}\n\
             depth_convs_per_stage = 1\n\n[train]\nbatch = 32\nepochs = 3\nlr = 1e-3\n\
             test_fraction = 0.25\nshuffle_blocks = 4\n"
        ),
    )
    .unwrap();
    repr
}

/// `learner experiment` end to end at a tiny scale: a representation
/// variant and the ground-truth reference, each trained and evaluated on
/// two pegs (one of them a transfer); a second invocation finds every stage
/// done and redoes none.
#[test]
fn an_experiment_runs_every_stage_and_resumes() {
    use learner::experiment::{ExperimentConfig, RunOptions, run};
    let dir = test_support::scratch_dir("experiment");
    let repr = tiny_repr_config(&dir);
    let policy = dir.join("policy.toml");
    std::fs::write(
        &policy,
        format!(
            "num_envs = 2\nthreads = 2\nenv_steps = 400\n\n[env]\nmax_steps = 20\n\n\
             [env.world.camera]\nwidth = {SIDE}\nheight = {SIDE}\n\n\
             [policy]\nbatch_steps = 40\nhidden = [8]\n"
        ),
    )
    .unwrap();
    let cfg_path = dir.join("experiment.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[data]\ndataset = {:?}\n\n[representation]\nepochs = 1\n\n\
             [policy]\nconfig = {:?}\nenv_steps = 40\n\n\
             [eval]\nepisodes = 2\npegs = [\"square\", \"hexagon\"]\n\n\
             [[variant]]\nname = \"Full\"\nrepresentation = {:?}\npaper_completed = 0.78\n\n\
             [[variant]]\nname = \"ground-truth\"\n",
            dataset(),
            policy,
            repr
        ),
    )
    .unwrap();
    let cfg = ExperimentConfig::from_file(&cfg_path).unwrap();
    let out = dir.join("out");
    let opts = RunOptions::default();
    let rows = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(rows.len(), 4, "two variants × two pegs");
    assert_eq!(rows[0].variant, "Full");
    assert_eq!(rows[0].paper_completed, Some(0.78));
    for r in &rows {
        assert_eq!(r.report.episodes, 2);
        assert!((r.report.outcomes.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    }
    // The variant's policy observed its representation's z (d = 16).
    let c = learner::rl::run::read_checkpoint(&out.join("Full/policy/checkpoint.json")).unwrap();
    assert_eq!(c.state.policy.sizes[0], 16);
    assert_eq!(c.state.env_steps, 40);
    let gt = learner::rl::run::read_checkpoint(&out.join("ground-truth/policy/checkpoint.json"))
        .unwrap();
    assert_eq!(
        gt.state.policy.sizes[0],
        learner::rl::observe::GROUND_TRUTH_DIM
    );
    for f in [
        "results.md",
        "results.csv",
        "results.json",
        "completed-square.png",
        "completed-hexagon.png",
        "Full/repr/model/model.json",
        "Full/eval-hexagon.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert_eq!(md.lines().count(), 2 + 4, "{md}");
    assert!(
        md.contains("| Full | hexagon | 2 |") && md.contains("| 78% |"),
        "{md}"
    );
    let stages = std::fs::read_to_string(out.join("stages.log")).unwrap();
    assert_eq!(stages.lines().count(), 1 + 2 + 4, "{stages}");
    // Again: everything is on file.
    let again = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(again, rows);
    assert_eq!(
        std::fs::read_to_string(out.join("stages.log")).unwrap(),
        stages
    );
    // Another evaluation seed for one variant: only its evaluations are
    // done again, and the other variant's rows stay in the results.
    let mut reseeded = cfg.clone();
    reseeded.eval.seed = 7;
    let only_gt = RunOptions {
        only: vec!["ground-truth".into()],
        ..Default::default()
    };
    let mixed = run(&reseeded, &out, &only_gt, &|| false).unwrap();
    assert_eq!(mixed.len(), 4);
    assert_eq!(mixed[..2], rows[..2], "the Full rows are kept from file");
    let stages2 = std::fs::read_to_string(out.join("stages.log")).unwrap();
    assert_eq!(stages2.lines().count(), 7 + 2, "{stages2}");
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert_eq!(md.lines().count(), 2 + 4, "{md}");
    // Stopped after the first variant (a new evaluation seed, Ctrl-C once
    // its last evaluation is on file): that variant's rows are in the
    // results already, the second's not.
    let mut seed9 = cfg.clone();
    seed9.eval.seed = 9;
    let full_seed = || {
        std::fs::read(out.join("Full/eval-hexagon.json"))
            .ok()
            .and_then(|t| serde_json::from_slice::<serde_json::Value>(&t).ok())
            .and_then(|v| v["seed"].as_u64())
    };
    let e = run(&seed9, &out, &opts, &|| full_seed() == Some(9)).unwrap_err();
    assert!(e.to_string().contains("stopped"), "{e}");
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert_eq!(md.lines().count(), 2 + 2, "{md}");
    assert!(
        md.contains("| Full | square |") && !md.contains("ground-truth"),
        "{md}"
    );
    // The paper's number belongs to the training peg, not to transfer.
    assert_eq!(rows[1].peg, hw_sim::PegShape::Hexagon);
    assert_eq!(rows[1].paper_completed, None);
    // Stopped (Ctrl-C) in a fresh directory: an error that says so, and
    // the same call afterwards finishes.
    let fresh = dir.join("stopped");
    let e = run(&cfg, &fresh, &only_gt, &|| true).unwrap_err();
    assert!(e.to_string().contains("stopped"), "{e}");
    let resumed = run(&cfg, &fresh, &only_gt, &|| false).unwrap();
    assert_eq!(resumed.len(), 2);
    // A name that is not a variant is refused.
    let e = run(
        &cfg,
        &out,
        &RunOptions {
            only: vec!["Fu11".into()],
            ..Default::default()
        },
        &|| false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("Fu11"), "{e}");
}

/// `learner experiment` through DAgger (`[policy] distill`): each variant's
/// student observes its own z, and its teacher's probe reads the same
/// representation (the ground truth's teacher is told the truth, no probe);
/// a variant given an already trained `model` trains none; the evaluated
/// policy is the last round's; a second invocation redoes nothing.
#[test]
fn an_experiment_distils_from_each_variants_own_probe() {
    use learner::experiment::{ExperimentConfig, RunOptions, run};
    use learner::rl::distill::DistillConfig;
    let dir = test_support::scratch_dir("experiment-distill");
    let repr = tiny_repr_config(&dir);
    // The probe's band reaches the start (below_m 1 m), so that 20-step
    // episodes give it states to fit.
    let distill = dir.join("distill.toml");
    std::fs::write(
        &distill,
        format!(
            "[search_teacher.probe]\nrepresentation = \"replaced\"\nfit_episodes = 1\n\
             below_m = 1.0\n\n\
             [student]\nnum_envs = 2\nthreads = 2\n\n[student.env]\nmax_steps = 20\n\n\
             [student.env.world.camera]\nwidth = {SIDE}\nheight = {SIDE}\n\n\
             [student.policy]\nhidden = [8]\n\n[student.validation]\nepisodes = 1\n\n\
             [dagger]\nrounds = 2\nsteps_per_round = 40\nepochs = 2\n"
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let model = out.join("Full/repr/model");
    let cfg_path = dir.join("experiment.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[data]\ndataset = {:?}\n\n[representation]\nepochs = 1\n\n\
             [policy]\ndistill = {:?}\n\n[eval]\nepisodes = 2\n\n\
             [[variant]]\nname = \"Full\"\nrepresentation = {repr:?}\npaper_completed = 0.78\n\n\
             [[variant]]\nname = \"ground-truth\"\n\n\
             [[variant]]\nname = \"reused\"\nrepresentation = {repr:?}\nmodel = {model:?}\n",
            dataset(),
            distill,
        ),
    )
    .unwrap();
    let cfg = ExperimentConfig::from_file(&cfg_path).unwrap();
    let opts = RunOptions::default();
    let rows = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(rows.len(), 3, "three variants on the training peg");
    assert_eq!(rows[0].paper_completed, Some(0.78));
    for r in &rows {
        assert_eq!(r.report.episodes, 2);
    }
    let recorded = |v: &str| -> DistillConfig {
        let text = std::fs::read(out.join(v).join("policy/distill-config.json")).unwrap();
        serde_json::from_slice(&text).unwrap()
    };
    let probe_of = |v: &str| {
        recorded(v)
            .search_teacher
            .unwrap()
            .probe
            .map(|p| p.representation)
    };
    // Full's teacher and student read Full's model, and so do the reused
    // variant's, which trained no representation of its own.
    assert_eq!(probe_of("Full"), Some(model.clone()));
    assert_eq!(probe_of("reused"), Some(model.clone()));
    assert!(!out.join("reused/repr").exists());
    assert_eq!(probe_of("ground-truth"), None);
    for (v, dim) in [
        ("Full", 16),
        ("reused", 16),
        ("ground-truth", learner::rl::observe::GROUND_TRUTH_DIM),
    ] {
        let c =
            learner::rl::run::read_checkpoint(&out.join(v).join("policy/checkpoint.json")).unwrap();
        assert_eq!(c.state.iteration, 2, "{v}: both rounds");
        assert_eq!(c.state.policy.sizes[0], dim, "{v}");
        assert!(
            out.join(v).join("policy/rounds/round-001.bin").exists(),
            "{v}"
        );
        // The last round's policy was evaluated.
        let e: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join(v).join("eval-square.json")).unwrap())
                .unwrap();
        assert_eq!(e["policy_iteration"], 2, "{v}");
    }
    assert!(out.join("Full/policy/search-probe.json").exists());
    let stages = std::fs::read_to_string(out.join("stages.log")).unwrap();
    // Full: representation, policy, evaluation; the others: policy and
    // evaluation.
    assert_eq!(stages.lines().count(), 3 + 2 + 2, "{stages}");
    assert_eq!(stages.matches("DAgger, 2 rounds").count(), 3, "{stages}");
    let again = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(again, rows);
    assert_eq!(
        std::fs::read_to_string(out.join("stages.log")).unwrap(),
        stages
    );
    // The last round is what is evaluated, whatever validated best: a
    // checkpoint whose best validation names round 1 is evaluated again at
    // round 2.
    let ckpt = out.join("reused/policy/checkpoint.json");
    let mut c = learner::rl::run::read_checkpoint(&ckpt).unwrap();
    c.best_validated.as_mut().unwrap().validation.iteration = 1;
    std::fs::write(&ckpt, serde_json::to_vec(&c).unwrap()).unwrap();
    std::fs::remove_file(out.join("reused/eval-square.json")).unwrap();
    let only_reused = RunOptions {
        only: vec!["reused".into()],
        ..Default::default()
    };
    run(&cfg, &out, &only_reused, &|| false).unwrap();
    let e: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("reused/eval-square.json")).unwrap())
            .unwrap();
    assert_eq!(e["policy_iteration"], 2);
    // A distillation without a probe is refused before anything runs.
    let text = std::fs::read_to_string(&distill).unwrap();
    let unprobed = "[search_teacher]\n\n".to_string() + &text[text.find("[student]").unwrap()..];
    let bad = dir.join("bad-distill.toml");
    std::fs::write(&bad, unprobed).unwrap();
    let mut c = cfg.clone();
    c.policy.distill = Some(bad);
    let e = run(&c, &dir.join("refused"), &opts, &|| false).unwrap_err();
    assert!(e.to_string().contains("no [search_teacher.probe]"), "{e}");
    assert!(!dir.join("refused/Full").exists(), "nothing ran");
    // A model trained otherwise than the variant's own would be is refused:
    // more epochs, or another architecture.
    let mut longer = cfg.clone();
    longer.representation.epochs = Some(2);
    let e = run(&longer, &out, &only_reused, &|| false).unwrap_err();
    assert!(e.to_string().contains("trained 1 epochs"), "{e}");
    let other = dir.join("repr-d8.toml");
    std::fs::write(
        &other,
        std::fs::read_to_string(&repr)
            .unwrap()
            .replace("latent_dim = 16", "latent_dim = 8"),
    )
    .unwrap();
    let mut narrower = cfg.clone();
    narrower.variant[2].representation = Some(other);
    let e = run(&narrower, &out, &only_reused, &|| false).unwrap_err();
    assert!(e.to_string().contains("model configuration"), "{e}");
    // A model that is not there is named before anything runs for it.
    let mut missing = cfg.clone();
    missing.variant[2].model = Some(dir.join("nowhere"));
    let e = run(&missing, &out, &only_reused, &|| false).unwrap_err();
    assert!(e.to_string().contains("nowhere"), "{e}");
}
