//! How well a policy network can fit a distillation's samples offline, and
//! where it misses: `learner policy distill` refits for a few epochs per
//! round; this fits the saved rounds for as long as asked and scores the
//! fit on rounds held out (other episodes), per action component, on all
//! samples and on those where the teacher's lateral action is large (the
//! reach towards the hole, |Δx| or |Δy| ≥ 0.5).
//!
//! Usage: `distill_fit RUN_DIR EPOCHS HIDDEN [TEST_ROUNDS]` (HIDDEN like
//! `64,64`, or `linear`; the last TEST_ROUNDS rounds, default 2, are the test split).
//!
//! `distill_fit phases RUN_DIR ROUND [CHECKPOINT]`: a touch-search
//! distillation's student (the run's checkpoint, or CHECKPOINT: for
//! example a copy taken before ROUND was fitted) scored on ROUND's samples,
//! split by where the teacher was (its view in `round-NNN.teacher.bin`,
//! phased by the run's own search settings: in the opening, on the box,
//! above it below the probe's band, higher up).
//!
//! `distill_fit shadow RUN_DIR EPISODES student|teacher [last]`: a
//! touch-search distillation's student (its best validated policy, or its
//! last) or its teacher (as it labelled the run's rounds) driven over the
//! evaluation's episodes (seeds 1 000 000 on), with the teacher's action
//! and phase read at every state: per episode, where the tip first met
//! the box against where the teacher believed the opening, how long it
//! searched there, how close it came to the opening's axis, how the
//! student's lateral step agreed with the teacher's on the box, and how far
//! the teacher's belief was off on the way down (above the probe's band),
//! and the peg's true roll relative to the hole at the start, at landing
//! and at most on the box.
//!
//! `DISTILL_FIT_ROLL_WEIGHT=w` multiplies the Δroll labels by w before
//! fitting and scoring (1 by default).
//!
//! `DISTILL_FIT_L2=λ` fits with that L2 penalty on every parameter (0 by
//! default, as `learner policy distill`).
//!
//! `DISTILL_FIT_PROBE=FILE` appends a linear probe's readings of each
//! observation (a `search-probe.json`) to it: the same information, made
//! explicit, to tell what the student cannot fit from what it cannot find.

use learner::rl::GaussianPolicy;
use learner::rl::distill::Samples;
use learner::rl::mlp::MseFit;
use learner::rl::obs_norm::ObsNorm;
use learner::rl::ppo::Adam;

fn merge(parts: &[Samples]) -> Samples {
    let mut all = Samples {
        obs_dim: parts[0].obs_dim,
        act_dim: parts[0].act_dim,
        ..Default::default()
    };
    for p in parts {
        all.obs.extend_from_slice(&p.obs);
        all.actions.extend_from_slice(&p.actions);
    }
    all
}

/// `s` with `probe`'s readings of each observation appended to it.
fn with_probe(s: &Samples, probe: &learner::rl::probe::LinearProbe) -> Samples {
    let d = s.obs_dim;
    let mut out = Samples {
        obs_dim: d + probe.targets,
        act_dim: s.act_dim,
        actions: s.actions.clone(),
        ..Default::default()
    };
    for o in s.obs.chunks_exact(d) {
        let z: Vec<f64> = o.iter().map(|&v| v as f64).collect();
        out.obs.extend_from_slice(o);
        out.obs.extend(probe.predict(&z).iter().map(|&v| v as f32));
    }
    out
}

/// Mean squared error per component over all samples and over the reach
/// samples, with their counts.
fn score(policy: &GaussianPolicy, s: &Samples) -> (Vec<f64>, Vec<f64>, usize) {
    let k = s.act_dim;
    let obs: Vec<f64> = s.obs.iter().map(|&v| v as f64).collect();
    let m = policy.means(&obs);
    let (mut all, mut reach, mut n_reach) = (vec![0.0; k], vec![0.0; k], 0);
    for (p, t) in m.chunks_exact(k).zip(s.actions.chunks_exact(k)) {
        let far = t[0].abs() >= 0.5 || t[1].abs() >= 0.5;
        n_reach += far as usize;
        for c in 0..k {
            let e = (p[c] - t[c] as f64).powi(2);
            all[c] += e;
            if far {
                reach[c] += e;
            }
        }
    }
    let n = s.len().max(1) as f64;
    (
        all.iter().map(|v| v / n).collect(),
        reach.iter().map(|v| v / n_reach.max(1) as f64).collect(),
        n_reach,
    )
}

/// The student's squared error on one round by the teacher's phase.
fn phases(args: &[String]) -> Result<(), Box<dyn std::error::Error>> {
    use learner::rl::distill::{round_path, teacher_round_path};
    use learner::rl::search::{SEARCH_VIEW_DIM, SearchPhase};
    let usage = "usage: distill_fit phases RUN_DIR ROUND [CHECKPOINT]";
    let dir = std::path::PathBuf::from(args.get(2).ok_or(usage)?);
    let round: u64 = args.get(3).ok_or(usage)?.parse()?;
    let ckpt = args
        .get(4)
        .map_or_else(|| dir.join("checkpoint.json"), std::path::PathBuf::from);
    let policy = learner::rl::run::read_checkpoint(&ckpt)?.state.policy;
    let s = Samples::read(&round_path(&dir, round))?;
    let t = Samples::read(&teacher_round_path(&dir, round))?;
    if t.obs_dim != SEARCH_VIEW_DIM || t.actions != s.actions {
        return Err("the teacher file is not a touch search's view of the same samples".into());
    }
    // The run's own search settings: its phases, and the probe's band
    // (30 mm, the probe's default, for a search told the truth).
    let cfg: learner::rl::distill::DistillConfig =
        serde_json::from_slice(&std::fs::read(dir.join("distill-config.json"))?)?;
    let search = cfg
        .search_teacher
        .ok_or("not a distillation from the touch search")?;
    let below = search.probe.as_ref().map_or(0.03, |p| p.below_m);
    let names = [
        "in the opening".to_string(),
        "on the box (below 1 mm, or carried)".to_string(),
        format!("above the box, below {:.0} mm", below * 1e3),
        format!("above {:.0} mm", below * 1e3),
    ];
    let k = s.act_dim;
    let obs: Vec<f64> = s.obs.iter().map(|&v| v as f64).collect();
    let m = policy.means(&obs);
    // Per phase: count, squared error per component, label sum and square.
    let mut acc = vec![(0usize, vec![0.0; k], vec![0.0; k], vec![0.0; k]); 4];
    for ((p, y), o) in m
        .chunks_exact(k)
        .zip(s.actions.chunks_exact(k))
        .zip(t.obs.chunks_exact(SEARCH_VIEW_DIM))
    {
        let o: Vec<f64> = o.iter().map(|&v| v as f64).collect();
        let phase = match search.phase(&o) {
            SearchPhase::InOpening => 0,
            SearchPhase::OnBox => 1,
            SearchPhase::Above if o[2] < below => 2,
            SearchPhase::Above => 3,
        };
        let a = &mut acc[phase];
        a.0 += 1;
        for c in 0..k {
            a.1[c] += (p[c] - y[c] as f64).powi(2);
            a.2[c] += y[c] as f64;
            a.3[c] += (y[c] as f64).powi(2);
        }
    }
    let total: f64 = acc.iter().map(|a| a.1.iter().sum::<f64>()).sum();
    println!(
        "round {round}: {} samples, the student of {}",
        s.len(),
        ckpt.display()
    );
    println!(
        "phase | share of samples | error Δx Δy Δz | share of the error | label variance Δx Δy"
    );
    for (name, (n, e, sum, sq)) in names.iter().zip(&acc) {
        let n1 = (*n).max(1) as f64;
        let var = |c: usize| sq[c] / n1 - (sum[c] / n1).powi(2);
        println!(
            "{name} | {:.2} | {:.3} {:.3} {:.3} | {:.2} | {:.3} {:.3}",
            *n as f64 / s.len().max(1) as f64,
            e[0] / n1,
            e[1] / n1,
            e[2] / n1,
            e.iter().sum::<f64>() / total.max(1e-300),
            var(0),
            var(1)
        );
    }
    Ok(())
}

/// Per-episode record of [`shadow`].
#[derive(Default)]
struct Shadowed {
    outcome: usize,
    /// First step on the box: its index, the tip's true distance from the
    /// hole's axis, the teacher's belief's error there (mm).
    land: Option<(u32, f64, f64)>,
    on_box: u32,
    /// Nearest the tip came to the axis on the box after landing, mm.
    min_r: f64,
    /// Farthest, mm.
    max_r: f64,
    /// First step in the opening.
    opening: Option<u32>,
    /// Sum of cosines between the student's and the teacher's lateral steps
    /// on the box, and their count.
    cos: (f64, u32),
    /// Squared error of the teacher's belief (x, y together, mm²) summed
    /// over the way down above the probe's band, and its count.
    way_down: (f64, u32),
    /// The peg's true roll relative to the hole (wrapped by its symmetry)
    /// at the start, at landing, and the largest |roll| on the box, rad.
    roll: (f64, f64, f64),
}

/// The teacher's belief's RMS error on an episode's way down, mm.
fn way_down_rms(r: &Shadowed) -> Option<f64> {
    (r.way_down.1 > 0).then(|| (r.way_down.0 / f64::from(r.way_down.1)).sqrt())
}

fn shadow(args: &[String]) -> Result<(), Box<dyn std::error::Error>> {
    use learner::rl::RlEnv;
    use learner::rl::search::{SEARCH_VIEW_DIM, SearchPhase};
    let usage = "usage: distill_fit shadow RUN_DIR EPISODES student|teacher [last]";
    let dir = std::path::PathBuf::from(args.get(2).ok_or(usage)?);
    let episodes: u64 = args.get(3).ok_or(usage)?.parse()?;
    let student_drives = match args.get(4).map(String::as_str) {
        Some("student") => true,
        Some("teacher") => false,
        _ => return Err(usage.into()),
    };
    let last = args.get(5).map(String::as_str) == Some("last");
    let (teacher, t_view) = learner::rl::distill::search_teacher_of(&dir)?;
    let ckpt = learner::rl::run::read_checkpoint(&dir.join("checkpoint.json"))?;
    let chosen = ckpt.chosen_policy(last);
    eprintln!("student: {chosen}");
    eprintln!(
        "driven by the {}",
        if student_drives { "student" } else { "teacher" }
    );
    let policy = chosen.policy.clone();
    let s_view = ckpt.config.observation.observer_on(1)?;
    let mut env = RlEnv::new(&ckpt.config.env)?;
    // The probe's band: above it the belief is the approach probe's (or
    // the truth's), below it the near probe's.
    let band = teacher.cfg.probe.as_ref().map_or(0.03, |p| p.below_m);
    let (mut to, mut so) = (vec![0.0; SEARCH_VIEW_DIM], vec![0.0; s_view.dim()]);
    let mut all = Vec::new();
    for ep in 0..episodes {
        env.reset(1_000_000 + ep, true)?;
        let mut r = Shadowed {
            min_r: f64::INFINITY,
            ..Default::default()
        };
        let mut step = 0u32;
        r.roll.0 = env.task().s_psi_rad;
        let out = loop {
            let v = env.view().ok_or("no view after reset")?;
            t_view.observe(&[v], &mut to);
            s_view.observe(&[env.view().ok_or("no view")?], &mut so);
            let (at, st) = (teacher.means(&to), policy.means(&so));
            let s = env.task().s_m;
            let rad = 1e3 * s.x.hypot(s.y);
            match teacher.cfg.phase(&to) {
                SearchPhase::OnBox => {
                    let psi = env.task().s_psi_rad;
                    if r.land.is_none() {
                        let e = 1e3 * (to[0] - s.x).hypot(to[1] - s.y);
                        r.land = Some((step, rad, e));
                        r.roll.1 = psi;
                    }
                    r.roll.2 = r.roll.2.max(psi.abs());
                    r.on_box += 1;
                    r.min_r = r.min_r.min(rad);
                    r.max_r = r.max_r.max(rad);
                    let (nt, ns) = (at[0].hypot(at[1]), st[0].hypot(st[1]));
                    if nt > 1e-9 && ns > 1e-9 {
                        r.cos.0 += (at[0] * st[0] + at[1] * st[1]) / (nt * ns);
                        r.cos.1 += 1;
                    }
                }
                // Below the top face within the opening's reach of the
                // axis (a tip beside the box is below it too).
                SearchPhase::InOpening if rad < 25.0 => {
                    r.opening.get_or_insert(step);
                }
                SearchPhase::InOpening => {}
                SearchPhase::Above if s.z >= band => {
                    r.way_down.0 += 1e6 * ((to[0] - s.x).powi(2) + (to[1] - s.y).powi(2));
                    r.way_down.1 += 1;
                }
                SearchPhase::Above => {}
            }
            let o = env.step(if student_drives { &st } else { &at }, true)?;
            step += 1;
            if o.done() {
                break o;
            }
        };
        r.outcome = out.outcome.index();
        let f = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.1}"));
        println!(
            "ep {ep}: {} | landed at step {} {} mm from the axis, belief {} mm off | {} steps on the box, nearest {} mm, farthest {} mm | opening at step {} | cos {} | belief RMS on the way down {} mm | roll at the start {:.3}, at landing {}, largest on the box {} rad",
            out.outcome.name(),
            r.land.map_or("-".into(), |l| l.0.to_string()),
            f(r.land.map(|l| l.1)),
            f(r.land.map(|l| l.2)),
            r.on_box,
            f(r.min_r.is_finite().then_some(r.min_r)),
            f((r.on_box > 0).then_some(r.max_r)),
            r.opening.map_or("-".into(), |s| s.to_string()),
            f((r.cos.1 > 0).then(|| r.cos.0 / r.cos.1 as f64)),
            f(way_down_rms(&r)),
            r.roll.0,
            r.land.map_or("-".into(), |_| format!("{:.3}", r.roll.1)),
            r.land.map_or("-".into(), |_| format!("{:.3}", r.roll.2)),
        );
        all.push(r);
    }
    println!(
        "outcome | episodes | landed (mean step, mm from the axis, belief mm off) | steps on the box | nearest, farthest mm | reached the opening | cos | belief RMS on the way down, mm | |roll| at the start, at landing, largest on the box, rad"
    );
    for (i, o) in learner::rl::Outcome::ALL.iter().enumerate() {
        let g: Vec<&Shadowed> = all.iter().filter(|r| r.outcome == i).collect();
        if g.is_empty() {
            continue;
        }
        // Means over the episodes that have the value ("-" for none).
        let mean = |f: &dyn Fn(&Shadowed) -> Option<f64>, digits: usize| {
            let v: Vec<f64> = g.iter().filter_map(|r| f(r)).collect();
            if v.is_empty() {
                "-".to_string()
            } else {
                format!("{:.*}", digits, v.iter().sum::<f64>() / v.len() as f64)
            }
        };
        println!(
            "{} | {} | {} ({}, {}, {}) | {} | {}, {} | {} | {} | {} | {}, {}, {}",
            o.name(),
            g.len(),
            g.iter().filter(|r| r.land.is_some()).count(),
            mean(&|r| r.land.map(|l| f64::from(l.0)), 0),
            mean(&|r| r.land.map(|l| l.1), 1),
            mean(&|r| r.land.map(|l| l.2), 1),
            mean(&|r| Some(f64::from(r.on_box)), 0),
            mean(&|r| r.min_r.is_finite().then_some(r.min_r), 1),
            mean(&|r| (r.on_box > 0).then_some(r.max_r), 1),
            g.iter().filter(|r| r.opening.is_some()).count(),
            mean(&|r| (r.cos.1 > 0).then(|| r.cos.0 / f64::from(r.cos.1)), 2),
            mean(&way_down_rms, 1),
            mean(&|r| Some(r.roll.0.abs()), 3),
            mean(&|r| r.land.map(|_| r.roll.1.abs()), 3),
            mean(&|r| r.land.map(|_| r.roll.2), 3),
        );
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("phases") {
        return phases(&args);
    }
    if args.get(1).map(String::as_str) == Some("shadow") {
        return shadow(&args);
    }
    let usage = "usage: distill_fit RUN_DIR EPOCHS HIDDEN [TEST_ROUNDS]";
    let dir = std::path::PathBuf::from(args.get(1).ok_or(usage)?);
    let epochs: usize = args.get(2).ok_or(usage)?.parse()?;
    // `linear`: no hidden layer.
    let hidden: Vec<usize> = match args.get(3).ok_or(usage)?.as_str() {
        "linear" => Vec::new(),
        h => h.split(',').map(|v| v.parse()).collect::<Result<_, _>>()?,
    };
    let test_rounds: usize = args.get(4).map_or(Ok(2), |v| v.parse())?;
    // The rounds the checkpoint counts: a file beyond them is a round that
    // was stopped before its record.
    let done = learner::rl::run::read_checkpoint(&dir.join("checkpoint.json"))?
        .state
        .iteration;
    let mut rounds = Vec::new();
    for r in 0..done {
        let path = dir.join("rounds").join(format!("round-{r:03}.bin"));
        rounds.push(Samples::read(&path)?);
    }
    if rounds.len() <= test_rounds {
        return Err(format!("{} rounds in {}: too few", rounds.len(), dir.display()).into());
    }
    if let Ok(path) = std::env::var("DISTILL_FIT_PROBE") {
        let probe: learner::rl::probe::LinearProbe =
            serde_json::from_slice(&std::fs::read(&path)?)?;
        for r in &mut rounds {
            *r = with_probe(r, &probe);
        }
    }
    // Δroll's labels are a hundredth of the others' size with the touch
    // search's roll_gain 0.01: scaled up, the squared error weighs them
    // as much (errors and variances below are in the scaled units).
    let roll_weight: f64 =
        std::env::var("DISTILL_FIT_ROLL_WEIGHT").map_or(Ok(1.0), |v| v.parse())?;
    for r in &mut rounds {
        for a in r.actions.chunks_exact_mut(r.act_dim) {
            a[3] *= roll_weight as f32;
        }
    }
    let split = rounds.len() - test_rounds;
    let (train, test) = (merge(&rounds[..split]), merge(&rounds[split..]));
    let (d, k) = (train.obs_dim, train.act_dim);
    let mut rng = stack_common::rng::seeded(1, 0);
    let mut policy = GaussianPolicy::new(d, &hidden, k, 0.0, &mut rng);
    let obs: Vec<f64> = train.obs.iter().map(|&v| v as f64).collect();
    let targets: Vec<f64> = train.actions.iter().map(|&v| v as f64).collect();
    let mut norm = ObsNorm::new(d, 5.0);
    norm.update(&obs);
    policy.obs_norm = Some(norm);
    let inputs = policy.inputs(&obs);
    let mut adam = Adam::default();
    let l2: f64 = std::env::var("DISTILL_FIT_L2").map_or(Ok(0.0), |v| v.parse())?;
    let fit = MseFit {
        epochs: 1,
        minibatch: 256,
        learning_rate: 1e-3,
        l2,
    };
    let mlp = policy.mlp();
    println!(
        "{} train samples (rounds 0–{}), {} test (rounds {}–{}), hidden {hidden:?}, L2 {l2}",
        train.len(),
        split - 1,
        test.len(),
        split,
        rounds.len() - 1
    );
    println!("epoch | train: Δx Δy Δz Δroll | test: Δx Δy Δz Δroll | test, reach samples: Δx Δy");
    let f = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.4}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    for e in 1..=epochs {
        fit.run(
            &mlp,
            &mut policy.net,
            &mut adam,
            &inputs,
            &targets,
            &mut rng,
        );
        if e == 1 || e % 10 == 0 || e == epochs {
            let (tr, _, _) = score(&policy, &train);
            let (te, reach, n) = score(&policy, &test);
            println!(
                "{e} | {} | {} | {} ({n} samples)",
                f(&tr),
                f(&te),
                f(&reach[..2])
            );
        }
    }
    let (_, reach0, n) = score(
        &GaussianPolicy::new(d, &hidden, k, 0.0, &mut stack_common::rng::seeded(2, 0)),
        &test,
    );
    println!(
        "for scale, a fresh policy (mean near 0): test reach Δx Δy {} ({n} samples)",
        f(&reach0[..2])
    );
    let labels: Vec<f64> = test.actions.iter().map(|&x| f64::from(x)).collect();
    let (_, sd) = learner::rl::probe::standardiser(labels.chunks_exact(k), k);
    println!(
        "test label variance: Δx Δy Δz Δroll {} (Δroll ×{roll_weight})",
        f(&sd.iter().map(|s| s * s).collect::<Vec<_>>())
    );
    Ok(())
}
