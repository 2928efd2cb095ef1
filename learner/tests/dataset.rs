//! The data pipeline end to end: a short fast-mode collection, the dataset
//! built from its logs, labels against the simulator's ground truth, the
//! loader, and damaged inputs (collection's resume, budget, stops and
//! failures: collection.rs).

use learner::collect::{CollectConfig, collect_fast};
use learner::dataset::{self, BuildConfig, Dataset, Loader, LoaderConfig};
use learner::fast_env::FastEnv;
use learner::labels::FlowLabeler;
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use learner_node::policy::{HeuristicConfig, HeuristicPolicy};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use std::sync::atomic::AtomicBool;

fn world() -> hw_sim::WorldConfig {
    let mut w = hw_sim::WorldConfig::default();
    w.task.enabled = true;
    w
}

#[test]
fn kinematic_flow_labels_agree_with_the_simulators_ground_truth() {
    let mut env = FastEnv::new(world(), rt_controller::ControllerConfig::default()).unwrap();
    env.reset(5).unwrap();
    let task = learner::collect::task_of(env.world()).unwrap();
    let mut policy = HeuristicPolicy::new(HeuristicConfig::default());
    let mut msg = <shared_mem_schema::CameraFrame as shared_mem_schema::Message>::boxed_zeroed();
    env.render_camera(&mut msg);
    let cam = env.world().camera().clone();
    let cal = msg.calibration;
    assert_eq!(cal.focal_px, cam.focal_px);
    let model = env.world().model().clone();
    let mut labeler = FlowLabeler::new(model, &env.world().config().task, &cal).unwrap();
    let mut prev_q = env.world().q().to_vec();
    let mut prev_depth = env.rendered().depth_m.clone();
    let mut obs = None;
    let (mut compared, mut moving) = (0, 0);
    for _ in 0..40 {
        let a = obs.as_ref().map(|o| policy.act(o, &env.wrench, &task));
        for c in 0..ACTION_PERIOD_STEPS {
            env.cycle(if c == 0 { a.as_ref() } else { None }).unwrap();
        }
        obs = env.last_observation();
        assert!(env.world().camera_due());
        env.render_camera(&mut msg);
        let gt = env.rendered();
        let q = env.world().q().to_vec();
        labeler.label(&prev_q, &q, &prev_depth, 0.01);
        let (mut both, mut either, mut err) = (0usize, 0usize, 0.0f64);
        for i in 0..gt.flow_mask.len() {
            let (g, l) = (gt.flow_mask[i] == 1, labeler.mask[i] == 1);
            either += (g || l) as usize;
            if g && l {
                both += 1;
                let d = [
                    gt.flow_px[i][0] - labeler.flow_px[i][0],
                    gt.flow_px[i][1] - labeler.flow_px[i][1],
                ];
                err += (d[0].hypot(d[1])) as f64;
                moving += (gt.flow_px[i][0].hypot(gt.flow_px[i][1]) > 0.05) as usize;
            }
        }
        // A still arm: both masks empty, in full agreement.
        let iou = if either == 0 {
            1.0
        } else {
            both as f64 / either as f64
        };
        let epe = err / both.max(1) as f64;
        assert!(iou > 0.97, "mask IoU {iou:.3}");
        assert!(epe < 0.02, "mean endpoint difference {epe:.4} px");
        compared += both;
        prev_q = q;
        prev_depth = gt.depth_m.clone();
    }
    assert!(
        compared > 10_000 && moving > 1000,
        "{compared} pixels, {moving} moving"
    );
}

/// A short collection shared by the tests below (`end_after_completion`:
/// the mix's setting).
fn collect_with(
    dir: &std::path::Path,
    fraction: f64,
    actions: u32,
    end_after_completion: Option<u32>,
) -> learner::collect::CollectSummary {
    collect_in(dir, world(), fraction, actions, end_after_completion)
}

fn collect_in(
    dir: &std::path::Path,
    world: hw_sim::WorldConfig,
    fraction: f64,
    actions: u32,
    end_after_completion: Option<u32>,
) -> learner::collect::CollectSummary {
    let cfg = CollectConfig {
        out_dir: dir.to_path_buf(),
        states: u64::MAX,
        episodes: Some(2),
        episode_actions: actions,
        pegs: vec![hw_sim::PegShape::Square, hw_sim::PegShape::Hexagon],
        seed: 11,
        workers: 2,
        world,
        controller: rt_controller::ControllerConfig::default(),
        mix: Mix {
            heuristic_fraction: fraction,
            end_after_completion,
            ..Mix::default()
        },
        log: LogOptions {
            view_rate_hz: 50.0,
            ..LogOptions::default()
        },
        resume: false,
    };
    collect_fast(&cfg, &AtomicBool::new(false)).unwrap()
}

#[test]
fn a_short_collection_builds_the_expected_dataset() {
    let logs_dir = test_support::scratch_dir("logs");
    let logs = logs_dir.to_path_buf();
    // 5 s, a collection episode: the heuristic completes in about 3 s.
    let summary = collect_with(&logs, 1.0, 100, None);
    // Two episodes, whichever worker ran them.
    assert_eq!(summary.shards.len(), 2);
    assert_eq!(summary.states, 2 * 99);
    assert!(logs.join("manifest.jsonl").exists());

    // A damaged log beside them is skipped and named; the rest builds.
    let bad = logs.join("zz-broken.mcap");
    let good = std::fs::read(&summary.shards[0].file).unwrap();
    std::fs::write(&bad, &good[..good.len() / 2]).unwrap();

    let out = test_support::scratch_dir("ds");
    let files = dataset::find_logs(std::slice::from_ref(&logs)).unwrap();
    assert_eq!(files.len(), 3);
    let cfg = BuildConfig {
        block_samples: 16,
        shard_samples: 64,
        ..BuildConfig::default()
    };
    let mut skipped = Vec::new();
    let meta = dataset::build(&files, &out, &cfg, 2, |p, r| {
        if let Err(e) = r {
            skipped.push((p.to_path_buf(), e));
        }
    })
    .unwrap();
    assert_eq!(skipped.len(), 1);
    assert!(skipped[0].1.contains("offset"), "{}", skipped[0].1);
    // One sample per action the controller applied: where it faulted (the
    // heuristic pressing on the bottom can overload the wrist), the actions
    // it ignored start no interval. The frames say so.
    let mut applied = 0;
    let mut faulted = 0;
    for shard in &summary.shards {
        let log = learner_node::log::LogReader::open(&shard.file).unwrap();
        let frames: Vec<shared_mem_schema::SensorFrame> = log
            .read_raw(learner_node::log::topics::SENSOR, None)
            .unwrap();
        let mut seqs: Vec<u64> = frames
            .iter()
            .map(|f| f.action_seq)
            .filter(|&s| s > 0)
            .collect();
        seqs.dedup();
        applied += seqs.len() as u64;
        faulted += frames
            .iter()
            .filter(|f| {
                f.mode == shared_mem_schema::ControllerMode::Fault as u32 && f.fault_code != 0
            })
            .count();
    }
    assert!(applied <= summary.states);
    assert_eq!(meta.samples, applied, "one sample per applied action");
    if applied < summary.states {
        assert!(
            faulted > 0,
            "actions were not applied but no frame shows a fault"
        );
    }
    assert_eq!(meta.episodes.len(), 2);
    // The camera is kept: a model trained on these images is valid for it.
    let camera = world().camera.calibration();
    let kept = meta.camera.expect("the dataset keeps its camera");
    assert!(kept.same_camera(&camera), "{kept} against {camera}");
    assert_eq!(kept.width, 128);
    assert_eq!(
        meta.shards.len() as u64,
        meta.samples.div_ceil(64),
        "shards of 64 samples"
    );

    let ds = Dataset::open(&out).unwrap();
    let s = &ds.stats;
    // The heuristic goes down into the box: some contact, mostly free.
    assert!(
        s.contact_next_ratio > 0.05 && s.contact_next_ratio < 0.9,
        "contact ratio {}",
        s.contact_next_ratio
    );
    // At least one episode (the square) touches and leaves the box.
    assert!(ds.pairing_ratio() >= 0.45, "pairing {}", ds.pairing_ratio());
    assert!(
        s.mask_ratio > 0.02 && s.mask_ratio < 0.4,
        "mask {}",
        s.mask_ratio
    );
    assert!(s.depth.mean[0] > 0.5 && s.depth.mean[0] < 3.0);
    assert!(s.action.std.iter().all(|&x| x > 1e-5));

    // Stored samples equal a fresh labelling of the same log.
    let direct = dataset::episode_samples(&files[0], &cfg, &mut Default::default()).unwrap();
    let block = ds.read_block(0, 0).unwrap();
    for (k, b) in block.iter().enumerate() {
        let mut d = direct.samples[k].clone();
        d.episode = b.episode;
        assert_eq!(&d, b, "sample {k}");
    }
    // The stage each sample carries (format 4) only rises through an
    // episode, and the heuristic gets beyond "failed".
    for w in direct.samples.windows(2) {
        assert!(
            w[0].stage <= w[1].stage,
            "{:?} then {:?}",
            w[0].stage,
            w[1].stage
        );
    }
    assert!(direct.samples.last().unwrap().stage > shared_mem_schema::Stage::Failed);
    // Labels are consistent: the next position is where the next sample
    // starts, and the action moved the target the way it says.
    for w in direct.samples.windows(2) {
        assert_eq!(
            w[0].ee_next,
            [
                w[1].proprio[0],
                w[1].proprio[1],
                w[1].proprio[2],
                w[1].proprio[3]
            ]
        );
    }

    // One epoch of the loader: every sample exactly once, batches full but
    // the last, negatives with the opposite contact state.
    let loader = Loader::new(
        &ds,
        LoaderConfig {
            batch: 25,
            seed: 3,
            shuffle_blocks: 2,
            ..LoaderConfig::default()
        },
    );
    let mut seen = vec![0u32; ds.len() as usize];
    let (mut batches, mut negatives) = (0, 0);
    let mut order = Vec::new();
    for b in loader {
        let b = b.unwrap();
        batches += 1;
        assert!(b.len == 25 || seen.iter().filter(|&&c| c == 0).count() == b.len);
        for (k, &id) in b.ids.iter().enumerate() {
            seen[id as usize] += 1;
            order.push(id);
            if b.paired[k] == 0 {
                negatives += 1;
                assert_ne!(b.samples[k].wrench, ds.wrench_of(id), "haptics swapped");
            } else {
                assert_eq!(b.samples[k].wrench, ds.wrench_of(id));
            }
        }
    }
    assert!(seen.iter().all(|&c| c == 1), "each sample once per epoch");
    assert_eq!(batches, (ds.len() as usize).div_ceil(25));
    assert!(negatives > 20, "{negatives} negatives");
    assert!(
        order.windows(2).filter(|w| w[1] == w[0] + 1).count() < order.len() / 4,
        "shuffled"
    );

    // A contact sheet is written.
    let sheet = out.join("sheet.png");
    dataset::contact_sheet(&ds, 4, &sheet).unwrap();
    // Four rows (samples) of four tiles (RGB, depth, flow, mask) each.
    let png = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&sheet).unwrap(),
    ));
    let info = png.read_info().unwrap().info().clone();
    let (w, h) = (ds.meta.width as u32, ds.meta.height as u32);
    assert_eq!((info.width, info.height), (4 * w, 4 * h));

    // Damaged datasets: a cut shard names its block's offset, a foreign
    // format version is refused.
    let shard = out.join(&ds.meta.shards[1].0);
    let bytes = std::fs::read(&shard).unwrap();
    std::fs::write(&shard, &bytes[..bytes.len() / 2]).unwrap();
    let last = ds.meta.shards[1].1.len() - 1;
    let e = ds.read_block(1, last).unwrap_err().to_string();
    assert!(
        e.contains("byte offset") && e.contains("shard-00001"),
        "{e}"
    );
    // A shard of an older format (13 proprioception values) among them is
    // refused by its magic, naming this build's version.
    let mut old = bytes.clone();
    old[..8].copy_from_slice(b"VTDSHRD1");
    std::fs::write(&shard, &old).unwrap();
    let e = Dataset::open(&out).err().unwrap().to_string();
    assert!(
        e.contains("shard-00001")
            && e.contains("VTDSHRD1")
            && e.contains(&format!("version {}", dataset::FORMAT_VERSION)),
        "{e}"
    );
    std::fs::write(&shard, &bytes).unwrap();
    assert!(Dataset::open(&out).is_ok());
    let text = std::fs::read_to_string(out.join("meta.json")).unwrap();
    let version = format!("\"format_version\": {}", dataset::FORMAT_VERSION);
    assert!(text.contains(&version), "{text}");
    // Format 4, whose end-effector label had no roll, as well as 1.
    for old in [1, 4] {
        std::fs::write(
            out.join("meta.json"),
            text.replace(&version, &format!("\"format_version\": {old}")),
        )
        .unwrap();
        let e = Dataset::open(&out).err().unwrap().to_string();
        assert!(
            e.contains(&format!("format version {old}")) && e.contains("learner dataset build"),
            "{e}"
        );
    }
}

#[test]
fn logs_of_two_cameras_do_not_make_one_dataset() {
    let a = test_support::scratch_dir("cam-a");
    let b = test_support::scratch_dir("cam-b");
    collect_in(&a, world(), 1.0, 4, None);
    let mut moved = world();
    moved.camera.eye_m[2] += 0.05;
    collect_in(&b, moved.clone(), 1.0, 4, None);
    let files = dataset::find_logs(&[a.to_path_buf(), b.to_path_buf()]).unwrap();
    assert_eq!(files.len(), 4);
    let out = test_support::scratch_dir("cam-ds");
    let mut skipped = Vec::new();
    let meta = dataset::build(&files, &out, &BuildConfig::default(), 2, |p, r| {
        if let Err(e) = r {
            skipped.push((p.to_path_buf(), e));
        }
    })
    .unwrap();
    // The logs of the second camera (read after the first's) are skipped,
    // each named with the remedy; the first camera's make the dataset.
    assert_eq!(skipped.len(), 2, "{skipped:?}");
    for (p, e) in &skipped {
        assert!(p.starts_with(&*b), "{}", p.display());
        assert!(e.contains("one dataset per camera"), "{e}");
    }
    assert_eq!(meta.episodes.len(), 2);
    assert!(
        meta.camera
            .unwrap()
            .same_camera(&world().camera.calibration())
    );
    // The second camera's logs alone build, and keep their camera.
    let files = dataset::find_logs(&[b.to_path_buf()]).unwrap();
    let meta = dataset::build(&files, &out, &BuildConfig::default(), 2, |_, _| {}).unwrap();
    assert!(
        meta.camera
            .unwrap()
            .same_camera(&moved.camera.calibration())
    );
    assert!(
        !meta
            .camera
            .unwrap()
            .same_camera(&world().camera.calibration())
    );
}

/// Recounts a dataset's balance from its samples and its logs: the stage
/// from each log's stage events at the sample's frame, contact from the
/// sample, motion from its position label.
fn recount(ds: &Dataset) -> dataset::Balance {
    use learner_node::log::{Event, LogReader, topics};
    let mut b = dataset::Balance::default();
    let mut samples = Vec::new();
    for (shard, blocks) in ds.meta.shards.iter().enumerate() {
        for k in 0..blocks.1.len() {
            samples.extend(ds.read_block(shard, k).unwrap());
        }
    }
    for e in &ds.meta.episodes {
        let log = LogReader::open(std::path::Path::new(&e.source)).unwrap();
        let frames: Vec<shared_mem_schema::SensorFrame> =
            log.read_raw(topics::SENSOR, None).unwrap();
        let events = log.read_events(None).unwrap();
        for s in &samples[e.first_id as usize..(e.first_id + e.samples) as usize] {
            let f = frames.iter().find(|f| f.step == s.step).unwrap();
            let stage = events
                .iter()
                .filter_map(|(t, ev)| match ev {
                    Event::Stage { stage } if *t <= f.header.t_hw_ns => Some(*stage),
                    _ => None,
                })
                .max()
                .unwrap_or(hw_sim::Stage::Failed);
            let moved = (0..3)
                .map(|k| (s.ee_next[k] as f64 - f.ee_pos_m[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let tags = dataset::SampleTags {
                stage,
                moving: moved > dataset::MOVING_M,
            };
            b.add(e.policy, tags, s.contact);
        }
    }
    b
}

/// Builds a dataset from the logs in `logs` into a scratch directory named
/// `tag`, opens it, and checks its stored balance against a recount.
fn build_and_recount(logs: &std::path::Path, tag: &str) -> (test_support::ScratchDir, Dataset) {
    let out = test_support::scratch_dir(tag);
    let files = dataset::find_logs(&[logs.to_path_buf()]).unwrap();
    dataset::build(&files, &out, &BuildConfig::default(), 2, |_, r| {
        r.unwrap();
    })
    .unwrap();
    let ds = Dataset::open(&out).unwrap();
    assert_eq!(ds.stats.balance, recount(&ds));
    (out, ds)
}

#[test]
fn inspect_reports_the_balance_and_collection_ends_episodes_after_completion() {
    // Full 5 s episodes: the heuristic completes (about 3 s) and rests.
    let full = test_support::scratch_dir("full");
    let summary = collect_with(&full, 1.0, 100, None);
    assert!(summary.shards.iter().all(|s| s.states == 99));
    let (out, ds) = build_and_recount(&full, "full-ds");
    let b = &ds.stats.balance;
    assert_eq!(b.total().samples, ds.meta.samples);
    assert_eq!(
        b.policy_total(learner_node::mix::EpisodePolicy::Random)
            .samples,
        0
    );
    let done = b.heuristic[hw_sim::Stage::Completed.code() as usize];
    let completed = summary
        .shards
        .iter()
        .filter(|s| s.stage == hw_sim::Stage::Completed)
        .count() as u64;
    assert!(completed >= 1, "{:?}", summary.shards);
    // Resting at the bottom: many samples, mostly still, in contact.
    assert!(done.samples >= 10 * completed, "{done:?}");
    assert!(done.moving * 2 < done.samples, "{done:?}");
    assert!(done.contact * 2 > done.samples, "{done:?}");

    // `learner dataset inspect` shows it, and writes its contact sheet into
    // the dataset's directory when not told where (not the working one).
    let sheet = out.join("contact-sheet.png");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(["dataset", "inspect"])
        .arg(&*out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{text}");
    assert!(sheet.is_file(), "no {}:\n{text}", sheet.display());
    assert!(
        text.contains(&format!("contact sheet: {}", sheet.display())),
        "{text}"
    );
    let all = b.total();
    let row = format!(
        "| heuristic | completed | {} | {:.1} % | {:.1} % | {:.1} % |",
        done.samples,
        100.0 * done.samples as f64 / all.samples as f64,
        100.0 * done.contact as f64 / done.samples as f64,
        100.0 * done.moving as f64 / done.samples as f64
    );
    assert!(text.contains(&row), "{row} not in:\n{text}");
    assert!(
        text.contains(&format!("| all | all | {} | 100.0 % |", all.samples)),
        "{text}"
    );

    // By default a completed episode ends 10 actions after completion.
    let short = test_support::scratch_dir("short");
    let n = Mix::default().end_after_completion.expect("on by default");
    let summary = collect_with(&short, 1.0, 100, Some(n));
    let (_out, ds) = build_and_recount(&short, "short-ds");
    let b = &ds.stats.balance;
    // The same episodes: one that completed early ends early, the others
    // run their length (or complete within its last 10 actions).
    assert!(
        summary.shards.iter().any(|s| s.states < 99),
        "{:?}",
        summary.shards
    );
    for s in &summary.shards {
        if s.stage != hw_sim::Stage::Completed {
            assert_eq!(s.states, 99, "{s:?}");
        }
    }
    let rest = b.heuristic[hw_sim::Stage::Completed.code() as usize].samples;
    assert!(
        rest <= 2 * (n as u64 + 1),
        "{rest} samples after completion"
    );
}

/// A copy of the log at `from`, written to `to` message by message, with the
/// focal length of the camera frames from the third on scaled by `focal`.
fn copy_log(from: &std::path::Path, to: &std::path::Path, focal: f64) {
    use learner_node::log::{LogReader, LogWriter, topics};
    use shared_mem_schema::{CameraFrame, Message, PolicyAction, SensorFrame};
    let r = LogReader::open(from).unwrap();
    let opts = LogOptions {
        foxglove: false,
        ..LogOptions::default()
    };
    let mut w = LogWriter::create_with(to, opts).unwrap();
    for (t, c) in r.read_config(None).unwrap() {
        w.config(t, &c).unwrap();
    }
    for (t, e) in r.read_events(None).unwrap() {
        w.event(t, &e).unwrap();
    }
    for f in r.read_raw::<SensorFrame>(topics::SENSOR, None).unwrap() {
        w.sensor(&f).unwrap();
    }
    for a in r.read_raw::<PolicyAction>(topics::ACTION, None).unwrap() {
        w.action(&a).unwrap();
    }
    let mut cam = CameraFrame::boxed_zeroed();
    for (k, c) in r.read_camera(None).unwrap().into_iter().enumerate() {
        cam.header = c.header;
        cam.index = c.index;
        cam.calibration = c.calibration;
        if k >= 2 {
            cam.calibration.focal_px *= focal;
        }
        cam.rgb[..c.rgb.len()].copy_from_slice(&c.rgb);
        cam.depth_m[..c.depth_m.len()].copy_from_slice(&c.depth_m);
        w.camera(&cam).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_log_whose_camera_changes_within_the_episode_is_skipped_and_named() {
    use learner::collect::run_episode;
    let dir = test_support::scratch_dir("camera-changes");
    let controller = rt_controller::ControllerConfig::default();
    let mut env = FastEnv::new(world(), controller.clone()).unwrap();
    let log = LogOptions {
        foxglove: false,
        ..LogOptions::default()
    };
    let original = dir.path().join("original.mcap");
    let shard = run_episode(
        &mut env,
        world(),
        &controller,
        &Mix::default(),
        0,
        40,
        8,
        &original,
        &log,
        || true,
    )
    .unwrap();
    assert!(shard.states >= 4, "{} states", shard.states);
    // The copy itself builds as the original does: what the second copy
    // changes is the camera alone.
    for (focal, tag) in [(1.0, "same"), (1.01, "changed")] {
        let logs = dir.path().join(tag);
        std::fs::create_dir_all(&logs).unwrap();
        copy_log(&original, &logs.join("episode-000000.mcap"), focal);
        let out = test_support::scratch_dir(&format!("camera-changes-{tag}"));
        let files = dataset::find_logs(&[logs]).unwrap();
        let meta = dataset::build(&files, &out, &BuildConfig::default(), 1, |_, _| {}).unwrap();
        if focal == 1.0 {
            assert_eq!(meta.episodes.len(), 1, "{:?}", meta.skipped);
            assert_eq!(meta.samples, shard.states);
        } else {
            assert!(meta.episodes.is_empty(), "{:?}", meta.episodes);
            assert_eq!(meta.skipped.len(), 1, "{:?}", meta.skipped);
            let (path, why) = &meta.skipped[0];
            assert!(path.ends_with("episode-000000.mcap"), "{path}");
            assert!(
                why.contains("calibration changes within the episode"),
                "{why}"
            );
        }
    }
}
