//! `learner policy distill` end to end on a tiny run: a teacher whose
//! actions vary with the state is imitated, rounds resume from their
//! files, a stop loses no finished round, a foreign environment is refused.

use learner::rl::distill::{DistillConfig, RoundPoint, Samples, distill, read_config, round_path};
use learner::rl::run::{self, RunError, read_checkpoint};
use learner::rl::{GaussianPolicy, ObservationKind};
use std::path::Path;
use std::process::Command;

const TEACHER: &str = r#"
seed = 3
num_envs = 2
threads = 2
env_steps = 40
checkpoint_every = 1

[env]
max_steps = 20

[policy]
batch_steps = 40
hidden = [16, 16]
"#;

/// The student observes the ground truth as the teacher does (no
/// representation model exists in a test), through its own network.
fn student_config(teacher: &Path, rounds: u64) -> String {
    format!(
        r#"
teacher = "{}"

[student]
seed = 4
num_envs = 2
threads = 2

[student.policy]
hidden = [32, 32]

[student.validation]
episodes = 1

[dagger]
rounds = {rounds}
steps_per_round = 80
epochs = 300
minibatch = 16
learning_rate = 3e-3
"#,
        teacher.display()
    )
}

/// A trained teacher checkpoint whose policy is replaced by one whose mean
/// action varies strongly with the state (a fresh policy's is near 0).
fn teacher(dir: &Path) -> std::path::PathBuf {
    let cfg = dir.join("teacher.toml");
    std::fs::write(&cfg, TEACHER).unwrap();
    let out = dir.join("teacher");
    let o = Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(["policy", "train", "--config"])
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = out.join("checkpoint.json");
    let mut c = read_checkpoint(&path).unwrap();
    let mut rng = stack_common::rng::seeded(7, 0);
    let mut p = GaussianPolicy::new(18, &[16, 16], 4, -1.0, &mut rng);
    p.net = p.mlp().init(&mut rng, 4.0);
    c.state.policy = p;
    c.best = None;
    c.best_validated = None;
    std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
    path
}

#[test]
fn the_student_learns_the_teachers_actions_and_resumes() {
    let dir = test_support::scratch_dir("rl-distill");
    let teacher = teacher(dir.path());
    let cfg_path = dir.path().join("distill.toml");
    std::fs::write(&cfg_path, student_config(&teacher, 2)).unwrap();
    let out = dir.path().join("student");
    let o = Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(["policy", "distill", "--config"])
        .arg(&cfg_path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "checkpoint.json",
        "distill.csv",
        "distill.json",
        "distill.png",
        "distill-error.png",
        "rounds/round-000.bin",
        "rounds/round-001.bin",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let c = read_checkpoint(&out.join("checkpoint.json")).unwrap();
    assert_eq!((c.state.iteration, c.state.env_steps), (2, 160));
    assert_eq!(c.validations.len(), 2);
    assert!(c.best_validated.is_some());
    // The student's checkpoint is a policy run's: observation, environment
    // and normalisation as `init_from` and `policy eval` need them.
    let teacher_cfg = read_checkpoint(&teacher).unwrap().config;
    assert_eq!(c.config.env, teacher_cfg.env);
    assert_eq!(c.config.observation, ObservationKind::GroundTruth);
    assert!(c.state.policy.obs_norm.is_some());
    assert_eq!(c.state.policy.sizes, vec![18, 32, 32, 4]);
    let rounds: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("distill.json")).unwrap()).unwrap();
    let err = |r: usize, k: &str| rounds[r][k].as_f64().unwrap();
    // Round 0 acts with the teacher alone; the fresh student's error is
    // the teacher's action spread. The refit brings it far down, and the
    // refitted student is close on the states of round 1 too.
    assert_eq!(rounds[0]["beta"].as_f64(), Some(1.0));
    assert_eq!(rounds[1]["beta"].as_f64(), Some(0.5));
    // Round 0 is the teacher's alone; in round 1 the student acts in about
    // half of the 80 steps (β drawn per step and environment, seeded).
    let by_student = |r: usize| rounds[r]["student_steps"].as_u64().unwrap();
    assert_eq!(by_student(0), 0);
    assert!((24..=56).contains(&by_student(1)), "{rounds:?}");
    assert!(err(0, "error_before") > 0.05, "{rounds:?}");
    assert!(
        err(0, "error_after") < 0.1 * err(0, "error_before"),
        "{rounds:?}"
    );
    assert!(
        err(1, "error_before") < 0.7 * err(0, "error_before"),
        "{rounds:?}"
    );

    // One more round: the first two rounds' samples are read back and the
    // counters go on, exactly as in a run of three rounds uninterrupted.
    let cfg: DistillConfig = toml::from_str(&student_config(&teacher, 3)).unwrap();
    let c = distill(cfg.clone(), &out, true, &|| false).unwrap();
    assert_eq!((c.state.iteration, c.state.env_steps), (3, 240));
    let rounds: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("distill.json")).unwrap()).unwrap();
    assert_eq!(rounds.len(), 3);
    assert_eq!(rounds[2]["samples"].as_u64(), Some(240));
    let whole = dir.path().join("whole");
    let w = distill(cfg.clone(), &whole, false, &|| false).unwrap();
    assert_eq!(w.state.policy, c.state.policy);
    assert_eq!(w.state.episodes_started, c.state.episodes_started);
    let bytes = |d: &Path| std::fs::read(d.join("rounds/round-002.bin")).unwrap();
    assert_eq!(bytes(&whole), bytes(&out));

    // A stop during the next round loses nothing finished and counts
    // nothing of the dropped round.
    let mut more = cfg.clone();
    more.dagger.rounds = 4;
    let stopped = distill(more.clone(), &out, true, &|| true).unwrap();
    let on_disk = read_checkpoint(&out.join("checkpoint.json")).unwrap();
    for s in [&stopped.state, &on_disk.state] {
        assert_eq!(
            (s.iteration, s.env_steps, s.episodes_started),
            (3, 240, c.state.episodes_started)
        );
    }
    // A resume under other settings than the run's is refused.
    let mut other = more;
    other.dagger.learning_rate *= 2.0;
    let e = distill(other, &out, true, &|| false).unwrap_err();
    assert!(e.to_string().contains("distill-config.json"), "{e}");
    let c = stopped;

    // The evaluation takes the student's checkpoint.
    let r = run::evaluate(
        &c.chosen_policy(false).policy.clone(),
        &c.config,
        1,
        1_000_000,
        &|| false,
    )
    .unwrap();
    assert_eq!(r.episodes, 1);
}

/// Summed over components, the mean squared error of `policy`'s means
/// against the samples' actions.
fn error_on(policy: &GaussianPolicy, s: &Samples) -> f64 {
    let obs: Vec<f64> = s.obs.iter().map(|&v| v as f64).collect();
    let means = policy.means(&obs);
    let sq: f64 = means
        .iter()
        .zip(&s.actions)
        .map(|(a, &t)| (a - t as f64).powi(2))
        .sum();
    sq / s.len() as f64
}

#[test]
fn held_out_episodes_choose_each_refits_epoch() {
    let dir = test_support::scratch_dir("rl-distill-holdout");
    let teacher = teacher(dir.path());
    // The second of the two environments is held out of every refit.
    let text = student_config(&teacher, 2) + "holdout_envs = 1\n";
    let cfg: DistillConfig = toml::from_str(&text).unwrap();
    let out = dir.path().join("student");
    let c = distill(cfg.clone(), &out, false, &|| false).unwrap();
    let rounds: Vec<RoundPoint> =
        serde_json::from_slice(&std::fs::read(out.join("distill.json")).unwrap()).unwrap();
    let mut all = Samples {
        obs_dim: 18,
        act_dim: 4,
        ..Default::default()
    };
    for r in 0..2 {
        let s = Samples::read(&round_path(&out, r)).unwrap();
        all.obs.extend_from_slice(&s.obs);
        all.actions.extend_from_slice(&s.actions);
    }
    let (fitted, held) = all.split_envs(2, 1);
    let held = held.unwrap();
    assert_eq!((fitted.len(), held.len()), (80, 80));
    // The kept network is the one whose held-out error was recorded, and
    // the fitted error is on the first environment's samples alone.
    let last = &rounds[1];
    let h = last.holdout.expect("a held-out error per round");
    let csv = std::fs::read_to_string(out.join("distill.csv")).unwrap();
    let row: Vec<&str> = csv.lines().nth(2).unwrap().split(',').collect();
    assert_eq!(row[row.len() - 1], h.epoch.to_string(), "{csv}");
    let p = &c.state.policy;
    assert!((error_on(p, &held) - h.error).abs() < 1e-9, "{h:?}");
    assert!((error_on(p, &fitted) - last.error_after).abs() < 1e-9);
    // The refit generalises to the held-out episodes at all.
    assert!(h.error < rounds[0].error_before, "{rounds:?}");
    // The same run without holding out fits every sample.
    let plain: DistillConfig = toml::from_str(&student_config(&teacher, 1)).unwrap();
    let c0 = distill(plain, &dir.path().join("plain"), false, &|| false).unwrap();
    let r0: Vec<RoundPoint> =
        serde_json::from_slice(&std::fs::read(dir.path().join("plain/distill.json")).unwrap())
            .unwrap();
    assert!(r0[0].holdout.is_none());
    let s0 = Samples::read(&round_path(&dir.path().join("plain"), 0)).unwrap();
    assert!((error_on(&c0.state.policy, &s0) - r0[0].error_after).abs() < 1e-9);
    // Holding out every environment is refused by name.
    let mut bad = cfg;
    bad.dagger.holdout_envs = 2;
    let e = distill(bad, &dir.path().join("bad"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("dagger.holdout_envs"), "{e}");
}

#[test]
fn bad_input_is_named() {
    let dir = test_support::scratch_dir("rl-distill-bad");
    let teacher = teacher(dir.path());
    // Another environment than the teacher's.
    let text = student_config(&teacher, 1) + "\n[student.env]\nmax_steps = 30\n";
    let cfg: DistillConfig = toml::from_str(&text).unwrap();
    let e = distill(cfg, &dir.path().join("a"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("student.env"), "{e}");
    // A stop before the first round: nothing to keep, said so.
    let cfg: DistillConfig = toml::from_str(&student_config(&teacher, 1)).unwrap();
    assert!(matches!(
        distill(cfg, &dir.path().join("b"), false, &|| true),
        Err(RunError::Stopped)
    ));
    // A missing teacher and a bad setting name themselves.
    let path = dir.path().join("bad.toml");
    std::fs::write(
        &path,
        student_config(&dir.path().join("nowhere.json"), 1).replace("rounds = 1", "rounds = 0"),
    )
    .unwrap();
    let cfg = read_config(&path).unwrap();
    let e = distill(cfg.clone(), &dir.path().join("c"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("dagger.rounds"), "{e}");
    let mut cfg = cfg;
    cfg.dagger.rounds = 1;
    let e = distill(cfg, &dir.path().join("c"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("nowhere.json"), "{e}");
    // The student may see through another camera than the teacher's world
    // has (a ground-truth teacher does not look): its checkpoint's
    // environment is the teacher's with that camera.
    let text = student_config(&teacher, 1)
        + "\n[camera]\nvertical_fov_deg = 40.0\neye_m = [0.9, -0.24, 0.77]\n\
           target_m = [0.58, 0.0, 0.2]\n";
    let cfg: DistillConfig = toml::from_str(&text).unwrap();
    let out = dir.path().join("d");
    let c = distill(cfg.clone(), &out, false, &|| false).unwrap();
    let teacher_env = read_checkpoint(&teacher).unwrap().config.env;
    let mut expected = teacher_env.clone();
    expected.world.camera = cfg.camera.clone().unwrap();
    assert_ne!(expected, teacher_env);
    assert_eq!(c.config.env, expected);
    // An invalid camera is named by its field.
    let text = student_config(&teacher, 1) + "\n[camera]\nwidth = 0\n";
    let bad: DistillConfig = toml::from_str(&text).unwrap();
    let e = distill(bad, &dir.path().join("e"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("camera.width"), "{e}");
    // A truncated samples file on resume.
    let f = out.join("rounds/round-000.bin");
    let bytes = std::fs::read(&f).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() - 5]).unwrap();
    let mut more = cfg;
    more.dagger.rounds = 2;
    let e = distill(more, &out, true, &|| false).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("round-000.bin") && msg.contains("truncated"),
        "{msg}"
    );
}

#[test]
fn the_touch_search_teaches_in_the_students_environment() {
    let dir = test_support::scratch_dir("rl-distill-search");
    // The student observes the ground truth told the hole with the same
    // per-episode error as the scripted teacher; both act in the student's
    // environment (here with a stiff wrist).
    let text = student_config(Path::new("unused"), 1)
        .replace(
            "teacher = \"unused\"",
            "search_teacher = { hole_error_m = 0.003 }",
        )
        .replace(
            "[student.policy]",
            "observation = { ground_truth_hole_error = 0.003 }\n\n\
             [student.env]\nmax_steps = 40\n\n\
             [student.env.controller.impedance]\n\
             kp = [300.0, 300.0, 300.0, 3000.0, 3000.0, 300.0]\n\n[student.policy]",
        );
    let cfg: DistillConfig = toml::from_str(&text).unwrap();
    assert!(cfg.teacher.is_none());
    let out = dir.path().join("s");
    let c = distill(cfg.clone(), &out, false, &|| false).unwrap();
    assert_eq!(c.config.env, cfg.student.env);
    assert_eq!(
        c.config.observation,
        ObservationKind::GroundTruthHoleError(0.003)
    );
    // The teacher's labels: in 40 steps from the start the search moves
    // towards the believed hole and down, each at its 1 mm step (2/3 of
    // the 1.5 mm scale).
    let s = learner::rl::distill::Samples::read(&out.join("rounds/round-000.bin")).unwrap();
    assert_eq!(s.len(), 80);
    let lateral = s
        .actions
        .chunks_exact(4)
        .map(|a| (a[0] as f64).hypot(a[1] as f64))
        .fold(0.0, f64::max);
    assert!((lateral - 2.0 / 3.0).abs() < 1e-3, "{lateral}");
    assert!(
        s.actions
            .chunks_exact(4)
            .all(|a| (a[2] + 2.0 / 3.0).abs() < 1e-6),
        "it descends at every step of the approach"
    );
    // Beside it, the same samples as the teacher saw them: its labels are
    // its actions on those observations (a search view: believed offset,
    // height, roll, force, the hole's yaw).
    let t = learner::rl::distill::Samples::read(&learner::rl::distill::teacher_round_path(&out, 0))
        .unwrap();
    assert_eq!(t.obs_dim, learner::rl::search::SEARCH_VIEW_DIM);
    assert_eq!(t.actions, s.actions);
    let search = learner::rl::search::TouchSearch {
        cfg: cfg.search_teacher.clone().unwrap(),
        scale: cfg.student.env.action.clone(),
    };
    let obs: Vec<f64> = t.obs.iter().map(|&v| v as f64).collect();
    let again: Vec<f32> = search
        .means(&obs)
        .iter()
        .map(|&v| v.clamp(-1.0, 1.0) as f32)
        .collect();
    let worst = again
        .iter()
        .zip(&t.actions)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    // The observations went through f32 too.
    assert!(worst < 1e-3, "{worst}");
    // Both teachers, or neither, are refused by name.
    for text in [
        text.clone().replace(
            "search_teacher = ",
            "teacher = \"x.json\"\nsearch_teacher = ",
        ),
        text.replace("search_teacher = { hole_error_m = 0.003 }", ""),
    ] {
        let cfg: DistillConfig = toml::from_str(&text).unwrap();
        let e = distill(cfg, &dir.path().join("t"), false, &|| false).unwrap_err();
        assert!(e.to_string().contains("give exactly one teacher"), "{e}");
    }
    // A bad search setting is named, and so is a slide the action scale
    // (1.5 mm) would clip.
    for slide in [-1.0, 0.002] {
        let mut bad = cfg.clone();
        bad.search_teacher.as_mut().unwrap().slide_m = slide;
        let e = distill(bad, &dir.path().join("u"), false, &|| false).unwrap_err();
        assert!(e.to_string().contains("search_teacher.slide_m"), "{e}");
    }
    let mut bad = cfg.clone();
    bad.search_teacher.as_mut().unwrap().descent_m = Some(0.002);
    let e = distill(bad, &dir.path().join("u"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("search_teacher.descent_m"), "{e}");
    // A search told by a representation reads it through the environment's
    // camera, which the student shares: a separate [camera] is refused
    // before the probe is fitted (its model, missing here, is not even
    // looked for).
    let mut probed = cfg;
    let search = probed.search_teacher.as_mut().unwrap();
    search.hole_error_m = 0.0;
    search.probe = Some(learner::rl::search::BeliefProbeConfig {
        representation: dir.path().join("no-model"),
        fit_episodes: 1,
        fit_hole_error_m: 0.01,
        below_m: 0.03,
        fit_rounds: 1,
        approach: false,
    });
    probed.camera = Some(hw_sim::config::CameraConfig::default());
    let e = distill(probed, &dir.path().join("v"), false, &|| false).unwrap_err();
    assert!(e.to_string().contains("[student.env.world.camera]"), "{e}");
}
