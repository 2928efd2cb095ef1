//! Training the representation on a real (small) dataset: a fast-mode
//! collection at 64×64 px, built into a dataset; a short training run whose
//! losses fall and whose contact accuracy beats the majority class on the
//! test split; an interrupted run that resumes to the same parameters as an
//! uninterrupted one; the exported model's encoder and evaluation
//! (`learner experiment` on the same data: experiment.rs).

mod common;

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::*;
use common::{SIDE, dataset};
use learner::dataset::{self, Dataset};
use learner::models::{Encoder, ModelKind, ObservationRef};
use learner::train::{self, ReprTrainConfig, Split, TrainOptions};
use std::path::Path;

fn small(kind: ModelKind, epochs: u32) -> ReprTrainConfig {
    let mut c = ReprTrainConfig::default();
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
    c.state.policy = GaussianPolicy::new(16, &[8], 4, -1.0, &mut stack_common::rng::seeded(1, 0));
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
