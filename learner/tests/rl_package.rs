//! `learner policy package`: a checkpoint and its representation in one
//! directory that evaluates wherever it is moved; and the policy the
//! repository ships (artifacts/z-ppo-square, made by that command) loads
//! and acts from a copy outside the repository.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use learner::rl::ObservationKind;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn learner(cwd: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_learner"));
    c.current_dir(cwd);
    c
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn err(o: Output) -> String {
    assert!(
        !o.status.success(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// One episode of `ck`'s policy, run from `cwd`: its report.
fn eval_one(cwd: &Path, ck: &Path, json: &Path) -> learner::rl::run::EvalReport {
    ok(learner(cwd)
        .args([
            "policy",
            "eval",
            "--episodes",
            "1",
            "--seed",
            "7",
            "--checkpoint",
        ])
        .arg(ck)
        .arg("--json")
        .arg(json)
        .output()
        .unwrap());
    serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap()
}

/// Copies every file of `from` into `to` (one level deep: a package).
fn copy_package(from: &Path, to: &Path) {
    std::fs::create_dir_all(to.join("model")).unwrap();
    for sub in ["", "model"] {
        for e in std::fs::read_dir(from.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.is_file() {
                std::fs::copy(&p, to.join(sub).join(p.file_name().unwrap())).unwrap();
            }
        }
    }
}

#[test]
fn a_packaged_policy_evaluates_wherever_it_is_moved() {
    let dir = test_support::scratch_dir("policy-package");
    // A run directory: a committed policy on z, naming its representation
    // by an absolute path, with a run record beside it.
    let run = dir.join("run");
    std::fs::create_dir_all(&run).unwrap();
    let lab = repo().join("lab/results/z-ppo-finetune/critic-frozen-s3");
    let mut c = learner::rl::run::read_checkpoint(&lab.join("checkpoint.json")).unwrap();
    let model = repo().join("lab/results/full-near-repro/model");
    c.config.observation = ObservationKind::Representation(model.clone());
    let ck = run.join("checkpoint.json");
    std::fs::write(&ck, serde_json::to_vec(&c).unwrap()).unwrap();
    std::fs::copy(lab.join("run.json"), run.join("run.json")).unwrap();

    let pkg = dir.join("pkg");
    let out = ok(learner(dir.path())
        .args(["policy", "package", "--checkpoint"])
        .arg(&ck)
        .arg("--out")
        .arg(&pkg)
        .output()
        .unwrap());
    assert!(out.contains("checkpoint.json written"), "{out}");
    for f in ["model.bpk", "model.json"] {
        assert_eq!(
            std::fs::read(pkg.join("model").join(f)).unwrap(),
            std::fs::read(model.join(f)).unwrap(),
            "{f}"
        );
    }
    assert!(pkg.join("run.json").is_file());
    let raw: serde_json::Value =
        serde_json::from_slice(&std::fs::read(pkg.join("checkpoint.json")).unwrap()).unwrap();
    assert_eq!(
        raw["config"]["observation"],
        serde_json::json!({"representation": "model"})
    );

    // Moved under another name and evaluated from a third directory: the
    // model is found beside the checkpoint.
    let moved = dir.join("elsewhere/shipped");
    std::fs::create_dir_all(moved.parent().unwrap()).unwrap();
    std::fs::rename(&pkg, &moved).unwrap();
    let cwd = dir.join("cwd");
    std::fs::create_dir_all(&cwd).unwrap();
    let r = eval_one(&cwd, &moved.join("checkpoint.json"), &dir.join("r.json"));
    assert_eq!(r.episodes, 1);
    assert!(r.mean_normalised.is_finite());
    // The same policy through its original checkpoint acts the same.
    let same = eval_one(&cwd, &ck, &dir.join("same.json"));
    assert_eq!(r.normalised, same.normalised);

    // Packaging again into a directory that holds something is refused.
    let e = err(learner(dir.path())
        .args(["policy", "package", "--checkpoint"])
        .arg(&ck)
        .arg("--out")
        .arg(&moved)
        .output()
        .unwrap());
    assert!(e.contains("not empty") && e.contains("shipped"), "{e}");

    // Without its model, the package's checkpoint names where it looked,
    // and does not take a `model` of the working directory instead.
    std::fs::remove_dir_all(moved.join("model")).unwrap();
    std::fs::create_dir_all(cwd.join("model")).unwrap();
    for f in ["model.bpk", "model.json"] {
        std::fs::copy(model.join(f), cwd.join("model").join(f)).unwrap();
    }
    let e = err(learner(&cwd)
        .args(["policy", "eval", "--episodes", "1", "--checkpoint"])
        .arg(moved.join("checkpoint.json"))
        .output()
        .unwrap());
    assert!(
        e.contains(&moved.join("model").display().to_string()),
        "{e}"
    );

    // A checkpoint whose representation is not a model directory is
    // refused, naming it, and nothing is written.
    c.config.observation = ObservationKind::Representation(dir.join("no-model"));
    std::fs::write(&ck, serde_json::to_vec(&c).unwrap()).unwrap();
    let e = err(learner(dir.path())
        .args(["policy", "package", "--checkpoint"])
        .arg(&ck)
        .arg("--out")
        .arg(dir.join("pkg2"))
        .output()
        .unwrap());
    assert!(e.contains("no-model") && e.contains("model.json"), "{e}");
    assert!(!dir.join("pkg2/checkpoint.json").exists());
}

/// The shipped policy, copied outside the repository, evaluates from
/// there: its checkpoint names its representation beside it, and that is
/// the representation results.md's section 1 measured.
#[test]
fn the_shipped_policy_acts_from_a_copy_outside_the_repository() {
    let shipped = repo().join("artifacts/z-ppo-square");
    let dir = test_support::scratch_dir("shipped-policy");
    let copy = dir.join("z-ppo-square");
    copy_package(&shipped, &copy);
    for f in ["model.bpk", "model.json"] {
        assert_eq!(
            std::fs::read(copy.join("model").join(f)).unwrap(),
            std::fs::read(repo().join("lab/results/full-near-repro/model").join(f)).unwrap(),
            "{f}"
        );
    }
    let r = eval_one(
        dir.path(),
        &copy.join("checkpoint.json"),
        &dir.join("r.json"),
    );
    assert_eq!(r.episodes, 1);
    assert!(r.mean_normalised.is_finite());
    // It was trained on z alone: what the actor sees is the representation.
    let c = learner::rl::run::read_checkpoint(&copy.join("checkpoint.json")).unwrap();
    assert_eq!(
        c.config.observation,
        ObservationKind::Representation(copy.join("model"))
    );
    assert_eq!(c.state.policy.sizes[0], 128);
}
