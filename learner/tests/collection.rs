//! Collection in fast mode over several workers: a resumed collection does
//! not run its episodes again, a state budget takes the same episodes
//! whatever the worker count, a stopped episode is left out of the
//! dataset, and a failed episode stops the other workers.

use learner::collect::{CollectConfig, collect_fast};
use learner::dataset::{self, BuildConfig};
use learner::fast_env::FastEnv;
use learner_node::log::LogOptions;
use learner_node::mix::Mix;
use std::sync::atomic::AtomicBool;

fn world() -> hw_sim::WorldConfig {
    let mut w = hw_sim::WorldConfig::default();
    w.task.enabled = true;
    w
}

/// A collection of six-action episodes (four to six states each) into
/// `out`, no state budget or episode cap, two workers, no Foxglove views.
fn six_action_collection(
    out: &std::path::Path,
    pegs: Vec<hw_sim::PegShape>,
    seed: u64,
) -> CollectConfig {
    CollectConfig {
        out_dir: out.to_path_buf(),
        states: u64::MAX,
        episodes: None,
        episode_actions: 6,
        pegs,
        seed,
        workers: 2,
        world: world(),
        controller: rt_controller::ControllerConfig::default(),
        mix: Mix::default(),
        log: LogOptions {
            foxglove: false,
            ..LogOptions::default()
        },
        resume: false,
    }
}

#[test]
fn an_interrupted_collection_resumes_without_running_its_episodes_again() {
    use learner::collect::{CollectError, read_manifest};
    let dir = test_support::scratch_dir("collect-resume");
    let cfg = |episodes: u64, resume: bool| CollectConfig {
        episodes: Some(episodes),
        resume,
        ..six_action_collection(dir.path(), vec![hw_sim::PegShape::Square], 21)
    };
    let first = collect_fast(&cfg(3, false), &AtomicBool::new(false)).unwrap();
    assert_eq!(first.shards.len(), 3);
    let stamp = |ep: usize| {
        std::fs::metadata(&first.shards[ep].file)
            .unwrap()
            .modified()
            .unwrap()
    };
    let before: Vec<_> = (0..3).map(stamp).collect();
    // Without resuming, the directory is refused and nothing is touched.
    let e = collect_fast(&cfg(5, false), &AtomicBool::new(false)).unwrap_err();
    assert!(
        matches!(e, CollectError::NotEmpty { episodes: 3, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("resume"), "{e}");
    // Resuming with another seed would mix two collections: refused.
    let mut other = cfg(5, true);
    other.seed = 99;
    let e = collect_fast(&other, &AtomicBool::new(false)).unwrap_err();
    assert!(matches!(e, CollectError::Mismatch { .. }), "{e}");
    assert!(e.to_string().contains("seed"), "{e}");
    // Episode 1's file lost, episode 2 cut short by a stop, and a manifest
    // line cut short by a crash.
    std::fs::remove_file(&first.shards[1].file).unwrap();
    let manifest = dir.path().join("manifest.jsonl");
    let mut text = std::fs::read_to_string(&manifest)
        .unwrap()
        .lines()
        .map(|l| {
            if l.contains("\"episode\":2,") {
                l.replace("\"interrupted\":false", "\"interrupted\":true")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(text.contains("\"interrupted\":true"), "{text}");
    text.push_str("\n{\"episode\": 4, \"se");
    std::fs::write(&manifest, &text).unwrap();
    let resumed = collect_fast(&cfg(5, true), &AtomicBool::new(false)).unwrap();
    let eps: Vec<u64> = resumed.shards.iter().map(|s| s.episode).collect();
    assert_eq!(eps, [0, 1, 2, 3, 4]);
    assert!(resumed.shards.iter().all(|s| s.file.exists()));
    // Episode 0 was not run again; 1 and 2 were.
    assert_eq!(stamp(0), before[0]);
    assert_ne!(stamp(2), before[2]);
    assert!(resumed.shards.iter().all(|s| !s.interrupted));
    assert_eq!(
        resumed.states,
        resumed.shards.iter().map(|s| s.states).sum::<u64>()
    );
    // The manifest reads back with one record per episode.
    let listed: Vec<u64> = read_manifest(&manifest)
        .unwrap()
        .iter()
        .map(|s| s.episode)
        .collect();
    assert_eq!(listed.len(), 5, "{listed:?}");
    // Episode files without a manifest are not overwritten either.
    let bare = test_support::scratch_dir("collect-bare");
    std::fs::write(bare.path().join("episode-000000.mcap"), b"kept").unwrap();
    let mut c = cfg(1, false);
    c.out_dir = bare.path().to_path_buf();
    let e = collect_fast(&c, &AtomicBool::new(false)).unwrap_err();
    assert!(matches!(e, CollectError::NotEmpty { .. }), "{e}");
    assert_eq!(
        std::fs::read(bare.path().join("episode-000000.mcap")).unwrap(),
        b"kept"
    );
    // A damaged line that is not the last is named.
    let mut lines: Vec<String> = std::fs::read_to_string(&manifest)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    lines[0] = "not json".into();
    std::fs::write(&manifest, lines.join("\n") + "\n").unwrap();
    let e = read_manifest(&manifest).unwrap_err();
    assert!(e.to_string().contains("line 1"), "{e}");
}

#[test]
fn a_state_budget_takes_the_same_episodes_whatever_the_worker_count() {
    use learner::collect::read_manifest;
    let run = |workers: usize, tag: &str| {
        let dir = test_support::scratch_dir(tag);
        let cfg = CollectConfig {
            // Four to six states an episode: a budget of seven is reached
            // by the first two episodes.
            states: 7,
            workers,
            ..six_action_collection(
                dir.path(),
                vec![hw_sim::PegShape::Square, hw_sim::PegShape::Triangle],
                31,
            )
        };
        let s = collect_fast(&cfg, &AtomicBool::new(false)).unwrap();
        let files: Vec<String> = dataset::find_logs(&[dir.path().to_path_buf()])
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        let listed: Vec<u64> = read_manifest(&dir.path().join("manifest.jsonl"))
            .unwrap()
            .iter()
            .map(|s| s.episode)
            .collect();
        (s, files, listed, dir)
    };
    let (one, one_files, one_listed, _d1) = run(1, "budget-1");
    let eps = |s: &learner::collect::CollectSummary| -> Vec<u64> {
        s.shards.iter().map(|s| s.episode).collect()
    };
    // The premise: one worker stops after the episode that reached it.
    assert_eq!(eps(&one), [0, 1], "{:?}", one.shards);
    assert_eq!(one_listed, [0, 1]);
    assert_eq!(one_files.len(), 2, "{one_files:?}");
    // Three workers start episodes 0-2 at once; the budget takes 0 and 1
    // only, and the third's file and record are gone.
    let (three, three_files, three_listed, _d3) = run(3, "budget-3");
    assert_eq!(eps(&three), eps(&one), "{:?}", three.shards);
    assert_eq!(three.states, one.states);
    assert_eq!(three_files, one_files);
    assert_eq!(three_listed, one_listed);
}

#[test]
fn an_episode_cut_short_by_a_stop_is_left_out_of_the_dataset() {
    use learner::collect::run_episode;
    let dir = test_support::scratch_dir("cut-short");
    let controller = rt_controller::ControllerConfig::default();
    let mut env = FastEnv::new(world(), controller.clone()).unwrap();
    let log = LogOptions {
        foxglove: false,
        ..LogOptions::default()
    };
    let mut episode = |i: u64, stop_after: u64| {
        let mut states = 0;
        run_episode(
            &mut env,
            world(),
            &controller,
            &Mix::default(),
            i,
            40 + i,
            6,
            &dir.path().join(format!("episode-{i:06}.mcap")),
            &log,
            || {
                states += 1;
                states < stop_after
            },
        )
        .unwrap()
    };
    let whole = episode(0, u64::MAX);
    let cut = episode(1, 2);
    assert!(!whole.interrupted && cut.interrupted);
    assert_eq!(cut.states, 2);
    let out = test_support::scratch_dir("cut-short-ds");
    let files = dataset::find_logs(&[dir.path().to_path_buf()]).unwrap();
    let mut reported = Vec::new();
    let meta = dataset::build(&files, &out, &BuildConfig::default(), 2, |p, r| {
        reported.push((p.to_path_buf(), r));
    })
    .unwrap();
    // The whole episode builds; the cut one is skipped, named and listed.
    assert_eq!(meta.episodes.len(), 1, "{:?}", meta.episodes);
    assert_eq!(meta.samples, whole.states);
    assert_eq!(meta.skipped.len(), 1, "{:?}", meta.skipped);
    assert!(meta.skipped[0].0.ends_with("episode-000001.mcap"));
    assert!(
        meta.skipped[0].1.contains("cut short"),
        "{}",
        meta.skipped[0].1
    );
    assert!(reported[1].1.as_ref().is_err_and(|e| e.contains("resume")));
}

#[test]
fn a_failed_episode_stops_the_other_workers() {
    use learner::collect::{CollectError, read_manifest};
    let dir = test_support::scratch_dir("collect-fails");
    // Episode 1's log cannot be written: its path is a directory.
    std::fs::create_dir(dir.path().join("episode-000001.mcap")).unwrap();
    let cfg = CollectConfig {
        // Without the failure the workers would run all 40 episodes.
        episodes: Some(40),
        resume: true,
        ..six_action_collection(dir.path(), vec![hw_sim::PegShape::Square], 51)
    };
    let e = collect_fast(&cfg, &AtomicBool::new(false)).unwrap_err();
    assert!(matches!(e, CollectError::Episode { episode: 1, .. }), "{e}");
    assert!(e.to_string().contains("episode-000001.mcap"), "{e}");
    // The other worker stops after its episode in progress; what it had
    // finished is recorded with its file.
    let listed = read_manifest(&dir.path().join("manifest.jsonl")).unwrap();
    assert!(listed.len() <= 3, "{listed:?}");
    assert!(listed.iter().all(|s| s.episode != 1 && s.file.exists()));
}
