//! The scripted touch search (`learner::rl::search`): told the hole several
//! millimetres off, it lands on the box's top face beside the opening, slides
//! until the peg drops in, and completes the insertion; its step follows
//! the spiral it is built on; bad settings are named.

use learner::rl::observe::{HoleError, Observer};
use learner::rl::search::{
    BOUND_RAMP_M, BeliefProbeConfig, SEARCH_VIEW_DIM, SearchView, TouchSearch, TouchSearchConfig,
};
use learner::rl::{Outcome, RlEnv, RlEnvConfig};

fn config() -> RlEnvConfig {
    let mut cfg = RlEnvConfig::default();
    // gt-trpo-stiff-ft's wrist (configs/rt-controller/stiff-tilts.toml).
    cfg.controller.impedance.kp = [300.0, 300.0, 300.0, 3000.0, 3000.0, 300.0];
    cfg
}

#[test]
fn the_touch_search_finds_a_misplaced_hole() {
    let cfg = config();
    let mut env = RlEnv::new(&cfg).unwrap();
    let std_m = 0.004;
    let search = TouchSearch {
        cfg: TouchSearchConfig {
            hole_error_m: std_m,
            ..Default::default()
        },
        scale: cfg.action.clone(),
    };
    let view = SearchView { std_m };
    // Two evaluation seeds whose draws put the believed hole 4 and 10 mm
    // off (`touch_probe search 4 10`, episodes 4 and 5).
    for seed in [1_000_004, 1_000_005] {
        env.reset(seed, false).unwrap();
        let e = HoleError { std_m }.error(&env.task_geometry().hole_pose);
        let off = e[0].hypot(e[1]);
        assert!(off > 0.004, "seed {seed}: the error is {off} m");
        // Steps the box carried the peg (pressed on its top face), where
        // the first contact was, and the outcome.
        let mut carried = 0;
        let mut first_contact = None;
        let last = loop {
            let mut o = [0.0; SEARCH_VIEW_DIM];
            view.observe(&[env.view().unwrap()], &mut o);
            if o[6] > 1.0 && o[2].abs() < 0.001 {
                carried += 1;
                first_contact.get_or_insert(env.task().s_m);
            }
            let out = env.step(&search.means(&o), false).unwrap();
            if out.done() {
                break out;
            }
        };
        let at = first_contact.expect("the peg never rested on the box");
        println!(
            "seed {seed}: error ({:.1}, {:.1}) mm, first carried at ({:.1}, {:.1}) mm, \
             {carried} steps carried, {}",
            e[0] * 1e3,
            e[1] * 1e3,
            at.x * 1e3,
            at.y * 1e3,
            last.outcome.name()
        );
        // It came down where it was told, beside the opening (the hole's
        // outline is 1 mm wider than the peg on each side) ...
        assert!(at.x.abs().max(at.y.abs()) > 0.002, "{at:?}");
        // ... searched on the top face, and found it.
        assert!(carried >= 5, "{carried}");
        assert_eq!(last.outcome, Outcome::CompletedInsertion);
    }
}

/// A [`SearchView`] observation: believed offset, height, roll, force in
/// the hole frame, hole yaw.
fn obs(b: [f64; 2], z: f64, f: [f64; 3]) -> [f64; SEARCH_VIEW_DIM] {
    [b[0], b[1], z, 0.0, f[0], f[1], f[2], 0.0]
}

#[test]
fn the_search_step_follows_its_spiral() {
    let cfg = TouchSearchConfig::default();
    let s = TouchSearch {
        cfg: cfg.clone(),
        scale: Default::default(),
    };
    // Above the box, 5 mm off: towards the believed hole and down.
    let d = s.step(&obs([0.005, 0.0], 0.05, [0.0; 3]));
    assert!(
        (d.x + cfg.step_m).abs() < 1e-12 && d.y == 0.0 && d.z == -cfg.step_m,
        "{d}"
    );
    // 0.2 mm off, high up: the rest of the way over and down.
    let d = s.step(&obs([0.0002, 0.0], 0.05, [0.0; 3]));
    assert!(d.z == -cfg.step_m && d.x == -0.0002 && d.y == 0.0, "{d}");
    // In the opening: down, no lateral move.
    let d = s.step(&obs([0.003, 0.0], -0.01, [0.0; 3]));
    assert_eq!((d.x, d.y, d.z), (0.0, 0.0, -cfg.step_m));
    // Carried at r = 5 mm on +x with no lateral force: a tangential slide
    // (anticlockwise, +y) of the slide length, radial part
    // (p/2π − L/2)/r of it; pressing at the set force holds the height.
    let r = 0.005;
    let d = s.step(&obs([r, 0.0], 0.0, [0.0, 0.0, cfg.press_n * 1.5]));
    let k = (cfg.pitch_m / std::f64::consts::TAU - 0.5 * cfg.slide_m) / r;
    assert!((d.y - cfg.slide_m).abs() < 1e-12, "{d}");
    assert!((d.x - k * cfg.slide_m).abs() < 1e-12, "{d}");
    assert_eq!(d.z, 0.0);
    // A lateral force (the target leading the tip) turns it inwards.
    let d2 = s.step(&obs([r, 0.0], 0.0, [0.0, 1.0, cfg.press_n * 1.5]));
    assert!(d2.x < d.x - 1e-4, "{d2}");
    // Too little force presses down, too much backs off.
    assert!(s.step(&obs([r, 0.0], 0.0, [0.0, 0.0, 0.3 * cfg.press_n])).z < 0.0);
    assert!(s.step(&obs([r, 0.0], 0.0, [0.0, 0.0, 3.0 * cfg.press_n])).z > 0.0);
    // The hole's yaw turns the base-frame action: a step along the hole's
    // x at yaw 90° is a base-frame y step.
    let mut o = obs([0.005, 0.0], 0.05, [0.0; 3]);
    o[7] = std::f64::consts::FRAC_PI_2;
    let a = s.means(&o);
    assert!(a[0].abs() < 1e-9 && a[1] < -0.5, "{a:?}");
    // The roll turns against the believed roll error: all of it, or the
    // gain's share.
    o[3] = 0.01;
    let whole = s.means(&o)[3];
    assert!(whole < 0.0, "{whole}");
    let quarter = TouchSearch {
        cfg: TouchSearchConfig {
            roll_gain: 0.25,
            ..cfg.clone()
        },
        scale: Default::default(),
    }
    .means(&o)[3];
    assert!((quarter - 0.25 * whole).abs() < 1e-12, "{quarter} {whole}");
    // Above the box, towards the believed opening: a full step whenever
    // the offset exceeds one; with an approach radius of 10 mm, the offset
    // times step/radius within it and a full step beyond.
    let proportional = TouchSearch {
        cfg: TouchSearchConfig {
            approach_radius_m: Some(0.01),
            ..cfg.clone()
        },
        scale: Default::default(),
    };
    let high = |b: [f64; 2]| obs(b, 0.1, [0.0; 3]);
    let near = high([0.004, -0.003]);
    let d = s.step(&near);
    assert!(
        (d.x + 0.8 * cfg.step_m).abs() < 1e-12 && (d.y - 0.6 * cfg.step_m).abs() < 1e-12,
        "{d}"
    );
    assert_eq!(d.z, -cfg.step_m);
    let d = proportional.step(&near);
    assert!(
        (d.x + 0.4 * cfg.step_m).abs() < 1e-12 && (d.y - 0.3 * cfg.step_m).abs() < 1e-12,
        "{d}"
    );
    assert_eq!(d.z, -cfg.step_m);
    let far = high([0.03, 0.04]);
    assert_eq!(proportional.step(&far), s.step(&far));
    // Within a step of the belief: the offset itself, or its step/radius
    // share.
    let close = high([0.0004, 0.0003]);
    assert_eq!(s.step(&close).x, -0.0004);
    assert!((proportional.step(&close).x + 0.0004 * cfg.step_m / 0.01).abs() < 1e-15);
    // A fast descent: 1.5 mm down above descent_until_m (20 mm), step_m
    // at and below it; the lateral step and the search on the box are
    // unchanged.
    let fast = TouchSearch {
        cfg: TouchSearchConfig {
            descent_m: Some(0.0015),
            ..cfg.clone()
        },
        scale: Default::default(),
    };
    for (b, z, down) in [
        ([0.004, -0.003], 0.1, 0.0015),
        ([0.0004, 0.0003], 0.021, 0.0015),
        ([0.004, -0.003], 0.02, cfg.step_m),
        ([0.004, -0.003], 0.005, cfg.step_m),
    ] {
        let o = obs(b, z, [0.0; 3]);
        let (d, slow) = (fast.step(&o), s.step(&o));
        assert_eq!((d.x, d.y, d.z), (slow.x, slow.y, -down), "at {z} m");
    }
    let on_box = obs([0.004, 0.0], 0.0, [0.0, 0.0, cfg.press_n * 1.5]);
    assert_eq!(fast.step(&on_box), s.step(&on_box));
    // Bounded at 15 mm: within it the spiral; halfway through the ramp
    // beyond it half the spiral's step and half a slide straight in;
    // past the ramp a slide straight in; above the box, unchanged.
    let bounded = TouchSearch {
        cfg: TouchSearchConfig {
            bound_m: Some(0.015),
            ..cfg.clone()
        },
        scale: Default::default(),
    };
    let pressed = |b: [f64; 2]| obs(b, 0.0, [0.0, 0.0, cfg.press_n * 1.5]);
    for inside in [pressed([0.004, 0.0]), pressed([0.0, -0.015]), far] {
        assert_eq!(bounded.step(&inside), s.step(&inside));
    }
    let mid = pressed([0.0, -(0.015 + 0.5 * BOUND_RAMP_M)]);
    let (d, spiral) = (bounded.step(&mid), s.step(&mid));
    assert!((d.x - 0.5 * spiral.x).abs() < 1e-12, "{d} {spiral}");
    assert!(
        (d.y - (0.5 * spiral.y + 0.5 * cfg.slide_m)).abs() < 1e-12,
        "{d}"
    );
    assert_eq!(d.z, spiral.z);
    let d = bounded.step(&pressed([-0.018, 0.024]));
    assert!(
        (d.x - 0.6 * cfg.slide_m).abs() < 1e-12 && (d.y + 0.8 * cfg.slide_m).abs() < 1e-12,
        "{d}"
    );
}

#[test]
fn bad_search_settings_are_named() {
    for (name, cfg) in [
        (
            "search_teacher.pitch_m",
            TouchSearchConfig {
                pitch_m: 0.0,
                ..Default::default()
            },
        ),
        (
            "search_teacher.hole_error_m",
            TouchSearchConfig {
                hole_error_m: f64::NAN,
                ..Default::default()
            },
        ),
        (
            "search_teacher.approach_radius_m",
            TouchSearchConfig {
                approach_radius_m: Some(0.0005),
                ..Default::default()
            },
        ),
        (
            "search_teacher.descent_m",
            TouchSearchConfig {
                descent_m: Some(-0.001),
                ..Default::default()
            },
        ),
        (
            "search_teacher.descent_m",
            TouchSearchConfig {
                descent_m: Some(0.0),
                ..Default::default()
            },
        ),
        (
            "search_teacher.bound_m",
            TouchSearchConfig {
                bound_m: Some(0.0),
                ..Default::default()
            },
        ),
        (
            "search_teacher.bound_m",
            TouchSearchConfig {
                bound_m: Some(f64::INFINITY),
                ..Default::default()
            },
        ),
        (
            "search_teacher.descent_until_m",
            TouchSearchConfig {
                descent_until_m: f64::NAN,
                ..Default::default()
            },
        ),
        (
            "search_teacher.descent_until_m",
            TouchSearchConfig {
                descent_until_m: -0.01,
                ..Default::default()
            },
        ),
        (
            "search_teacher.roll_gain",
            TouchSearchConfig {
                roll_gain: 0.0,
                ..Default::default()
            },
        ),
        (
            "search_teacher.roll_gain",
            TouchSearchConfig {
                roll_gain: 1.5,
                ..Default::default()
            },
        ),
        (
            "search_teacher.roll_gain",
            TouchSearchConfig {
                roll_gain: f64::NAN,
                ..Default::default()
            },
        ),
        (
            "search_teacher.lead_m_per_n",
            TouchSearchConfig {
                lead_m_per_n: -1.0,
                ..Default::default()
            },
        ),
    ] {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
    }
    TouchSearchConfig::default().validate().unwrap();
    // A probe's settings, and a hole error beside a probe.
    let probe = BeliefProbeConfig {
        representation: "model".into(),
        fit_episodes: 40,
        fit_hole_error_m: 0.01,
        below_m: 0.03,
        fit_rounds: 1,
        approach: false,
    };
    let with = |p: BeliefProbeConfig, hole_error_m: f64| TouchSearchConfig {
        hole_error_m,
        probe: Some(p),
        ..Default::default()
    };
    with(probe.clone(), 0.0).validate().unwrap();
    for (name, cfg) in [
        ("search_teacher.hole_error_m", with(probe.clone(), 0.002)),
        (
            "search_teacher.probe.below_m",
            with(
                BeliefProbeConfig {
                    below_m: 0.0,
                    ..probe.clone()
                },
                0.0,
            ),
        ),
        (
            "search_teacher.probe.fit_episodes",
            with(
                BeliefProbeConfig {
                    fit_episodes: 0,
                    ..probe
                },
                0.0,
            ),
        ),
    ] {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
    }
}

/// A stand-in for a representation whose "z" is the tip's true x offset
/// from the hole and the peg's roll relative to it, but not the y offset: a
/// probe of it reads x and the roll exactly and y not at all, so a search
/// told by the probe goes elsewhere than one told the truth.
struct NoY;

impl Observer for NoY {
    fn dim(&self) -> usize {
        2
    }

    fn observe(&self, views: &[learner::rl::observe::ObsView<'_>], out: &mut [f64]) {
        for (v, o) in views.iter().zip(out.chunks_exact_mut(2)) {
            o.copy_from_slice(&[v.task.s_m.x, v.task.s_psi_rad]);
        }
    }
}

/// A probe of [`NoY`] fitted on two episodes per round, 30 mm band.
fn noy_probe(rounds: u32, approach: bool) -> BeliefProbeConfig {
    BeliefProbeConfig {
        representation: "unused".into(),
        fit_episodes: 2,
        fit_hole_error_m: 0.01,
        below_m: 0.03,
        fit_rounds: rounds,
        approach,
    }
}

/// The probes fitted on [`NoY`] from seed 7 000 000, and the progress
/// calls (episodes, rows so far).
fn fit_noy(
    cfg: &RlEnvConfig,
    search: &TouchSearchConfig,
    pc: &BeliefProbeConfig,
) -> (learner::rl::search::BeliefProbes, Vec<(u64, usize)>) {
    let mut calls = Vec::new();
    let p =
        learner::rl::search::fit_belief_probe(cfg, &NoY, search, pc, 7_000_000, &mut |ep, rows| {
            calls.push((ep, rows))
        })
        .unwrap();
    (p, calls)
}

/// The states, at heights `counted` takes, of the search `search` told by
/// `view` on the seeds of a two-episode fit's second round.
fn states_of_told_search(
    cfg: &RlEnvConfig,
    search: &TouchSearchConfig,
    view: &dyn Observer,
    counted: impl Fn(f64) -> bool,
) -> usize {
    let teacher = TouchSearch {
        cfg: search.clone(),
        scale: cfg.action.clone(),
    };
    let mut env = RlEnv::new(cfg).unwrap();
    let mut n = 0;
    for seed in [7_000_002, 7_000_003] {
        env.reset(seed, false).unwrap();
        loop {
            let v = env.view().unwrap();
            n += usize::from(counted(v.task.s_m.z));
            let mut o = [0.0; SEARCH_VIEW_DIM];
            view.observe(&[v], &mut o);
            if env.step(&teacher.means(&o), false).unwrap().done() {
                break;
            }
        }
    }
    n
}

#[test]
fn a_belief_probe_fits_over_rounds_of_its_own_search() {
    use learner::rl::search::{IN_OPENING_M, ProbedSearchView};
    let cfg = config();
    let probe = |rounds: u32| noy_probe(rounds, false);
    let search = TouchSearchConfig {
        probe: Some(probe(2)),
        ..Default::default()
    };
    search.validate().unwrap();
    let (one, one_calls) = fit_noy(&cfg, &search, &probe(1));
    let (two, calls) = fit_noy(&cfg, &search, &probe(2));
    // Two rounds of two episodes each, the first as a one-round fit.
    assert_eq!(calls.iter().map(|c| c.0).collect::<Vec<_>>(), [1, 2, 3, 4]);
    assert_eq!(one_calls, calls[..2]);
    // The second round is the search told by the first round's probe, as
    // the teacher is, on the next two seeds: its states where the probe is
    // read are the rows it added.
    let view = ProbedSearchView {
        repr: std::sync::Arc::new(NoY),
        probes: one.clone(),
        below_m: 0.03,
    };
    let read = states_of_told_search(&cfg, &search, &view, |h| (IN_OPENING_M..0.03).contains(&h));
    assert!(read > 0);
    assert_eq!(calls[3].1 - calls[1].1, read, "{calls:?}");
    // Both probes read x and the roll exactly.
    for p in [&one.near, &two.near] {
        let got = p.predict(&[0.004, 0.05]);
        assert!((got[0] - 0.004).abs() < 1e-4, "{got:?}");
        assert!((got[2] - 0.05).abs() < 1e-4, "{got:?}");
    }
    // No rounds, or more fitting episodes than the seeds set apart, are
    // refused by name.
    for (rounds, episodes) in [(0, 2), (1_000, 2_000)] {
        let bad = TouchSearchConfig {
            probe: Some(BeliefProbeConfig {
                fit_episodes: episodes,
                ..probe(rounds)
            }),
            ..Default::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("search_teacher.probe.fit_rounds"), "{e}");
    }
}

#[test]
fn an_approach_probe_tells_the_way_down() {
    use learner::rl::search::{IN_OPENING_M, ProbedSearchView};
    let cfg = config();
    let search = TouchSearchConfig {
        probe: Some(noy_probe(2, true)),
        ..Default::default()
    };
    let (without, without_calls) = fit_noy(&cfg, &search, &noy_probe(1, false));
    let (with, with_calls) = fit_noy(&cfg, &search, &noy_probe(1, true));
    assert!(without.approach.is_none());
    // The first round's search is told the truth either way: the same near
    // rows and probe, and the states above the band as the approach's rows.
    assert_eq!(with.near, without.near);
    assert!(with_calls[1].1 > without_calls[1].1, "{with_calls:?}");
    let approach = with.approach.clone().expect("fitted");
    assert_eq!(approach.targets, 2);
    // NoY's "z" holds x and the roll, not y: x is read exactly.
    let a = approach.predict(&[0.004, 0.05]);
    assert!((a[0] - 0.004).abs() < 1e-4, "{a:?}");
    // The view: above the band the approach probe's offset and the true
    // roll; in the band the near probe's offset and roll.
    let view = ProbedSearchView {
        repr: std::sync::Arc::new(NoY),
        probes: with.clone(),
        below_m: 0.03,
    };
    let mut env = RlEnv::new(&cfg).unwrap();
    env.reset(7_000_010, false).unwrap();
    let v = env.view().unwrap();
    let t = v.task;
    assert!(t.s_m.z > 0.03, "the episode starts above the band");
    let mut o = [0.0; SEARCH_VIEW_DIM];
    view.observe(&[v], &mut o);
    let truth = approach.predict(&[t.s_m.x, t.s_psi_rad]);
    assert_eq!((o[0], o[1]), (truth[0], truth[1]));
    assert!((o[0] - t.s_m.x).abs() < 1e-4);
    assert_eq!(o[3], t.s_psi_rad);
    // A second round is the search told by both probes, on the next
    // seeds: every state of it above the opening gives a row.
    let (_, calls) = fit_noy(&cfg, &search, &noy_probe(2, true));
    assert_eq!(calls[..2], with_calls[..]);
    let rows = states_of_told_search(&cfg, &search, &view, |h| h >= IN_OPENING_M);
    assert_eq!(calls[3].1 - calls[1].1, rows, "{calls:?}");
}
