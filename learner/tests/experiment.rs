//! `learner experiment` end to end at a tiny scale, on the representation
//! tests' small dataset: collection through the policy's camera, every
//! stage and its resume, DAgger from each variant's own probe.

mod common;

use common::{SIDE, dataset};
use learner::dataset::Dataset;
use std::path::{Path, PathBuf};

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
        md.contains("| Full | TRPO from scratch | hexagon | 2 |") && md.contains("| 78% |"),
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
        md.contains("| Full | TRPO from scratch | square |") && !md.contains("ground-truth"),
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

/// The learned route (`[policy] distill` with a checkpoint teacher on the
/// ground truth, then `finetune`), two training seeds: every variant's
/// student learns from the same teacher on its own z, PPO then fine-tunes
/// it from there on the same z, the fine-tunes' policies are evaluated and
/// pooled into one row; a second invocation redoes nothing; a teacher that observes a representation is refused before
/// anything runs.
#[test]
fn an_experiment_runs_the_learned_route_through_a_fine_tune() {
    use learner::experiment::{ExperimentConfig, RunOptions, run};
    use learner::rl::ObservationKind;
    let dir = test_support::scratch_dir("experiment-learned");
    let repr = tiny_repr_config(&dir);
    // The teacher: a short PPO run on the ground truth.
    let teacher = dir.join("teacher");
    let tcfg: learner::rl::run::TrainConfig = toml::from_str(
        "seed = 3\nnum_envs = 1\nthreads = 1\nenv_steps = 20\n\
         [env]\nmax_steps = 20\n[policy]\nalgorithm = \"ppo\"\nbatch_steps = 20\nhidden = [8]\n",
    )
    .unwrap();
    learner::rl::run::train(tcfg, &teacher, false, &|| false).unwrap();
    let teacher_ckpt = teacher.join("checkpoint.json");
    let distill = dir.join("distill.toml");
    let distill_text = format!(
        "teacher = {teacher_ckpt:?}\n\n[camera]\nwidth = {SIDE}\nheight = {SIDE}\n\n\
         [student]\nnum_envs = 2\nthreads = 2\n\n[student.policy]\nhidden = [8]\n\n\
         [student.validation]\nepisodes = 1\n\n\
         [dagger]\nrounds = 5\nsteps_per_round = 40\nepochs = 2\n"
    );
    std::fs::write(&distill, &distill_text).unwrap();
    let finetune = dir.join("finetune.toml");
    std::fs::write(
        &finetune,
        format!(
            "num_envs = 2\nthreads = 2\nenv_steps = 80\n\n\
             [env]\nmax_steps = 20\n\n[env.world.camera]\nwidth = {SIDE}\nheight = {SIDE}\n\n\
             [policy]\nalgorithm = \"ppo\"\nbatch_steps = 40\nhidden = [8]\nbaseline = \"network\"\n\
             critic = \"ground_truth\"\nfreeze_obs_norm = true\ninit_from_log_std = -2.0\n\n\
             [validation]\nevery = 1\nepisodes = 1\n"
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let cfg_path = dir.join("experiment.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[data]\ndataset = {:?}\n\n[representation]\nepochs = 1\n\n\
             [policy]\ndistill = {distill:?}\ndagger_rounds = 2\nfinetune = {finetune:?}\n\
             seeds = [1, 2]\n\n\
             [eval]\nepisodes = 2\n\n\
             [[variant]]\nname = \"Full\"\nrepresentation = {repr:?}\n\n\
             [[variant]]\nname = \"ground-truth\"\n",
            dataset(),
        ),
    )
    .unwrap();
    let cfg = ExperimentConfig::from_file(&cfg_path).unwrap();
    let opts = RunOptions::default();
    let rows = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(rows.len(), 2);
    // Each row pools the two training seeds' evaluations of the same
    // episodes, each seed's count beside.
    for r in &rows {
        assert_eq!(r.report.episodes, 4, "{}", r.variant);
        let seeds: Vec<u64> = r.per_seed.iter().map(|s| s.seed).collect();
        assert_eq!(seeds, [1, 2]);
        assert_eq!(
            r.per_seed.iter().map(|s| s.completed).sum::<usize>(),
            (r.report.outcomes[3] * 4.0).round() as usize
        );
    }
    let table = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(
        table.contains(" of 4 (")
            && table.contains("s1: ")
            && table.contains("| DAgger ← learned teacher → PPO on z |"),
        "{table}"
    );
    let read = |p: std::path::PathBuf| learner::rl::run::read_checkpoint(&p).unwrap();
    for (v, dim, seed) in [
        ("Full", 16, 1),
        ("Full", 16, 2),
        ("ground-truth", learner::rl::observe::GROUND_TRUTH_DIM, 2),
    ] {
        let (policy, finetune, eval) = (
            format!("policy-s{seed}/checkpoint.json"),
            format!("finetune-s{seed}/checkpoint.json"),
            format!("eval-square-s{seed}.json"),
        );
        // The student: the experiment's two rounds, not the file's five,
        // on the variant's own observation.
        let student = read(out.join(v).join(&policy));
        assert_eq!(student.config.seed, seed, "{v}");
        assert_eq!(student.state.iteration, 2, "{v}");
        assert_eq!(student.state.policy.sizes[0], dim, "{v}");
        // The fine-tune: from that student, on the same observation, its
        // critic on the truth.
        let ft = read(out.join(v).join(&finetune));
        assert_eq!(ft.config.seed, seed, "{v}");
        assert_eq!(ft.state.env_steps, 80, "{v}");
        assert_eq!(ft.config.observation, student.config.observation, "{v}");
        assert_eq!(
            ft.config.init_from.as_deref(),
            Some(out.join(v).join(&policy).as_path()),
            "{v}"
        );
        assert_eq!(ft.state.policy.sizes[0], dim, "{v}");
        // Its best validated policy was evaluated.
        let e: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join(v).join(&eval)).unwrap()).unwrap();
        assert_eq!(e["run_env_steps"], 80, "{v}");
        assert_eq!(
            e["policy_iteration"],
            ft.chosen_policy(false).iteration,
            "{v}"
        );
    }
    let full = read(out.join("Full/policy-s1/checkpoint.json"));
    assert_eq!(
        full.config.observation,
        ObservationKind::Representation(out.join("Full/repr/model"))
    );
    let stages = std::fs::read_to_string(out.join("stages.log")).unwrap();
    // Full: representation, then per seed DAgger, fine-tune, evaluation;
    // the ground truth: per seed DAgger, fine-tune, evaluation.
    assert_eq!(stages.lines().count(), 1 + 3 * 2 + 3 * 2, "{stages}");
    assert_eq!(stages.matches("fine-tune of the student").count(), 4);
    assert_eq!(stages.matches(", seed 2)").count(), 6, "{stages}");
    let again = run(&cfg, &out, &opts, &|| false).unwrap();
    assert_eq!(again, rows);
    assert_eq!(
        std::fs::read_to_string(out.join("stages.log")).unwrap(),
        stages
    );
    // A student distilled further after its fine-tune: the old fine-tune
    // is not silently reused, the message says what to delete.
    let mut more = cfg.clone();
    more.policy.dagger_rounds = Some(3);
    more.policy.seeds = vec![1];
    let only_gt = RunOptions {
        only: vec!["ground-truth".into()],
        ..Default::default()
    };
    let e = run(&more, &out, &only_gt, &|| false).unwrap_err();
    assert!(
        e.to_string().contains("round 2") && e.to_string().contains("now has 3"),
        "{e}"
    );
    // A student distilled again into another policy at the same round
    // (here seed 2's, its weights changed in place): refused too; and
    // the unchanged student's fine-tune is found finished.
    let mut two = cfg.clone();
    two.policy.seeds = vec![2];
    let before = std::fs::read_to_string(out.join("stages.log")).unwrap();
    assert!(run(&two, &out, &only_gt, &|| false).is_ok());
    assert_eq!(
        std::fs::read_to_string(out.join("stages.log")).unwrap(),
        before,
        "nothing reran"
    );
    // A mark of before the fingerprint (the round alone) is checked on the
    // round alone.
    let mark = out.join("ground-truth/finetune-s2/student-rounds.json");
    let written = std::fs::read_to_string(&mark).unwrap();
    std::fs::write(&mark, "2").unwrap();
    assert!(run(&two, &out, &only_gt, &|| false).is_ok());
    std::fs::write(&mark, "1").unwrap();
    let e = run(&two, &out, &only_gt, &|| false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("round 1") && e.contains("now has 2"), "{e}");
    std::fs::write(&mark, written).unwrap();
    let student2 = out.join("ground-truth/policy-s2/checkpoint.json");
    let mut changed = read(student2.clone());
    changed.state.policy.net[0] += 0.25;
    std::fs::write(&student2, serde_json::to_vec(&changed).unwrap()).unwrap();
    let e = run(&two, &out, &only_gt, &|| false)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("another student") && e.contains("both at round 2") && e.contains("finetune-s2"),
        "{e}"
    );
    // A fine-tune in another world than the students' is refused before
    // anything runs.
    let elsewhere = dir.join("finetune-elsewhere.toml");
    std::fs::write(
        &elsewhere,
        std::fs::read_to_string(&finetune).unwrap().replace(
            "[env]\nmax_steps = 20\n",
            "[env]\nmax_steps = 20\n[env.action]\nmax_step_m = 0.004\n",
        ),
    )
    .unwrap();
    let mut c = cfg.clone();
    c.policy.finetune = Some(elsewhere);
    let e = run(&c, &dir.join("refused-ft"), &opts, &|| false).unwrap_err();
    assert!(e.to_string().contains("not the students'"), "{e}");
    assert!(!dir.join("refused-ft/Full").exists(), "nothing ran");
    // A teacher on a representation is refused before anything runs.
    let mut on_z = read(teacher_ckpt.clone());
    on_z.config.observation = ObservationKind::Representation(out.join("Full/repr/model"));
    let z_teacher = dir.join("z-teacher.json");
    std::fs::write(&z_teacher, serde_json::to_vec(&on_z).unwrap()).unwrap();
    let bad = dir.join("bad-distill.toml");
    std::fs::write(
        &bad,
        distill_text.replace(&format!("{teacher_ckpt:?}"), &format!("{z_teacher:?}")),
    )
    .unwrap();
    let mut c = cfg.clone();
    c.policy.distill = Some(bad);
    let e = run(&c, &dir.join("refused"), &opts, &|| false).unwrap_err();
    assert!(
        e.to_string().contains("observes Representation(")
            && e.to_string().contains("not the ground truth"),
        "{e}"
    );
    assert!(!dir.join("refused/Full").exists(), "nothing ran");
}

/// `learner experiment --set` changes the file's settings before they are
/// checked: a bad value and an unknown key are named, a good one read.
#[test]
fn an_experiments_settings_take_set() {
    use learner::experiment::ExperimentConfig;
    let dir = test_support::scratch_dir("experiment-set");
    let cfg_path = dir.join("experiment.toml");
    std::fs::write(
        &cfg_path,
        "[data]\ndataset = \"data\"\n\n[[variant]]\nname = \"Full\"\n",
    )
    .unwrap();
    let sets = ["eval.episodes=7".to_string()];
    let cfg = ExperimentConfig::from_file_with(&cfg_path, &sets).unwrap();
    assert_eq!(cfg.eval.episodes, 7);
    let plain = ExperimentConfig::from_file(&cfg_path).unwrap();
    assert_ne!(plain.eval.episodes, 7);
    for (set, named) in [
        ("eval.episodes=0", "eval.episodes"),
        ("eval.nosuch=1", "nosuch"),
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_learner"))
            .args(["experiment", "--config"])
            .arg(&cfg_path)
            .arg("--out")
            .arg(dir.join("out"))
            .args(["--set", set])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{set}: {err}");
        assert!(err.contains(named), "{set}: {err}");
    }
    // Nothing ran: the refusal came before any stage.
    assert!(!dir.join("out").exists());
}
