//! Finding the opening by touch: measurements on the RL environment with the
//! stiff tilt wrist (gt-trpo-stiff-ft's controller), docs/experiments.md "A
//! policy that searches by touch".
//!
//! - `touch_probe press`: the peg pressed onto the box's top face at a set
//!   of offsets from the hole's axis (with about 35 N: the target keeps
//!   going down for 15 steps; the raw reading, the free-space wrench not
//!   subtracted); prints the wrench in the hole frame and the centre of
//!   pressure it implies on the peg's bottom face, relative to the tip. Were
//!   the peg square to the face, over the rim the centre of pressure would
//!   lie on the side away from the opening; it sits at the lowest edge or
//!   corner the box carries. At (0, 0) the peg goes into the hole.
//! - `touch_probe search SIGMA_MM EPISODES`: the touch search
//!   (`learner::rl::search::TouchSearch`) told the hole with a per-episode
//!   error of SIGMA_MM per axis (`observe::HoleError`, the same draw as
//!   `policy eval --set observation={ground_truth_hole_error=σ}`); `TOUCH_PITCH_MM`, `TOUCH_SLIDE_MM`,
//!   `TOUCH_STEP_MM`, `TOUCH_PRESS_N`, `TOUCH_LEAD_MM_PER_N`,
//!   `TOUCH_DESCENT_UNTIL_MM` override its settings (in `zsearch` too),
//!   `TOUCH_DESCENT_MM` sets `descent_m`, `TOUCH_BOUND_MM` `bound_m`,
//!   `TOUCH_TRACE` prints the steps near the box, `TOUCH_PEG` (square,
//!   triangle, semicircle, hexagon) picks the peg, `TOUCH_BOX_YAW_RAD` the
//!   box's yaw range (`policy eval --set env.world.task.box_yaw_range_rad=R`). Prints each
//!   episode and the outcomes.
//! - `touch_probe zsearch MODEL_DIR WORLD_TOML|- FIT TEST`: the search told
//!   where the opening is by a linear probe of a representation's z means
//!   (`search::ProbedSearchView`), fitted on FIT episodes (seeds from
//!   3 000 000), run on TEST episodes; `TOUCH_TRUE_ROLL` gives it the true
//!   roll instead of the probe's, `TOUCH_FIT_ROUNDS` sets the probe's
//!   `fit_rounds` (each further round FIT more episodes of the search told
//!   by the probe so far), `TOUCH_ROLL_GAIN` sets the search's
//!   `roll_gain` (also in `search`), `TOUCH_PROBE_BELOW_MM` the height
//!   below which the probe is fitted and read (30), `TOUCH_APPROACH_PROBE`
//!   adds the approach probe above it (`approach`),
//!   `TOUCH_APPROACH_RADIUS_MM` sets `approach_radius_m`, `TOUCH_TRACE`
//!   prints each step's height and roll.
//! - `touch_probe zfit MODEL_DIR WORLD_TOML|- FIT TEST`: how well z places
//!   the tip relative to the hole near the box (below 30 mm, above the
//!   opening): the states of the search told the truth with a 10 mm error
//!   (`TOUCH_FIT_ERROR_MM`), FIT episodes (seeds from 3 000 000) to fit and
//!   TEST others (seeds from 1 000 000) to score; a linear probe (the
//!   search's) against MLPs of z means fitted for `TOUCH_ZFIT_EPOCHS` (200)
//!   epochs. Prints the test RMS of (x, y) together, in mm.
//!
//! Episodes use seeds from 1 000 000, as `learner policy eval` does.

use learner::rl::observe::{HoleError, Observer};
use learner::rl::search::{
    IN_OPENING_M, SEARCH_VIEW_DIM, SearchView, TouchSearch, TouchSearchConfig,
};
use learner::rl::{Outcome, RlEnv, RlEnvConfig};
use nalgebra::{Point3, Vector3};

/// The wrench the peg exerts on the flange in the hole frame: force, and
/// moment about the tip.
fn wrench_at_tip(env: &RlEnv) -> (Vector3<f64>, Vector3<f64>) {
    let w = env.fast().world();
    let peg = w.peg().expect("peg");
    let hole = env.task_geometry().hole_pose;
    let sensor = w.link_pose(peg.link) * peg.sensor_in_link;
    // The mean of the newest 8 readings, as the ground truth observes it.
    let mut r = [0.0; 6];
    let n = 8.min(env.fast().wrench.len()).max(1);
    for x in env
        .fast()
        .wrench
        .ordered()
        .skip(env.fast().wrench.len().saturating_sub(n))
    {
        for (a, b) in r.iter_mut().zip(x) {
            *a += b / n as f64;
        }
    }
    let to_hole = hole.rotation.inverse() * sensor.rotation;
    let f = to_hole * Vector3::new(r[0], r[1], r[2]);
    let m_o = to_hole * Vector3::new(r[3], r[4], r[5]);
    let o = hole.inverse() * Point3::from(sensor.translation.vector);
    let tip = Point3::from(env.task().s_m);
    // M_tip = M_o + (o − tip) × F.
    (f, m_o + (o - tip).cross(&f))
}

/// The centre of pressure on the tip's plane relative to the tip (hole
/// frame, x and y), m, for a wrench whose force is mostly along z: the
/// point r with r × F = M for F = (0, 0, F_z).
fn centre_of_pressure(f: &Vector3<f64>, m: &Vector3<f64>) -> [f64; 2] {
    [-m.y / f.z, m.x / f.z]
}

fn config() -> RlEnvConfig {
    let mut cfg = RlEnvConfig::default();
    // gt-trpo-stiff-ft's wrist (configs/rt-controller/stiff-tilts.toml).
    cfg.controller.impedance.kp = [300.0, 300.0, 300.0, 3000.0, 3000.0, 300.0];
    task_from_env(&mut cfg.world.task);
    cfg
}

/// `TOUCH_PEG` and `TOUCH_BOX_YAW_RAD` into the task (applied again after a
/// world file replaces the world).
fn task_from_env(task: &mut hw_sim::config::TaskConfig) {
    if let Ok(name) = std::env::var("TOUCH_PEG") {
        // The parser behind the CLI's `--peg`.
        task.peg = <hw_sim::PegShape as clap::ValueEnum>::from_str(&name, false)
            .unwrap_or_else(|e| panic!("TOUCH_PEG={name}: {e}"));
    }
    if let Ok(v) = std::env::var("TOUCH_BOX_YAW_RAD") {
        task.box_yaw_range_rad = v
            .parse()
            .unwrap_or_else(|e| panic!("TOUCH_BOX_YAW_RAD={v}: {e}"));
    }
}

/// A step in the hole frame (x, y, z, roll) through the env's action scale.
fn act(env: &RlEnv, d: Vector3<f64>, roll: f64) -> [f64; 4] {
    let d = env.task_geometry().hole_pose.rotation * d;
    env.action_scale().from_delta(&[d.x, d.y, d.z, roll])
}

fn press() {
    let cfg = config();
    let mut env = RlEnv::new(&cfg).expect("env");
    let offsets_mm = [
        (0.0, 0.0),
        (3.0, 0.0),
        (-3.0, 0.0),
        (0.0, 3.0),
        (0.0, -3.0),
        (6.0, 0.0),
        (4.0, 4.0),
        (-4.0, 6.0),
        (10.0, -5.0),
        (1.5, 0.0),
    ];
    println!("offset mm | F hole N | M at tip N·m | CoP rel. tip mm | tip z mm");
    for (i, (ox, oy)) in offsets_mm.iter().enumerate() {
        env.reset(1_000_000 + i as u64, false).expect("reset");
        let goal = Vector3::new(ox * 1e-3, oy * 1e-3, 0.0);
        let mut pressed = 0;
        for _ in 0..cfg.max_steps {
            let t = env.task();
            let s = t.s_m;
            let roll = -t.s_psi_rad;
            let mut d = goal - s;
            let lateral = (d.x * d.x + d.y * d.y).sqrt();
            d.z = if lateral > 0.0005 && s.z > 0.01 {
                0.0
            } else {
                -0.001
            };
            if s.z < 0.003 {
                // Close to the face: hold x/y exactly, press.
                d.x = goal.x - s.x;
                d.y = goal.y - s.y;
            }
            let a = act(&env, d, roll);
            let o = env.step(&a, false).expect("step");
            let (f, _) = wrench_at_tip(&env);
            if s.z < 0.002 && f.z.abs() > 2.0 {
                pressed += 1;
            }
            if pressed >= 15 || o.done() {
                break;
            }
        }
        let (f, m) = wrench_at_tip(&env);
        let c = centre_of_pressure(&f, &m);
        let t = env.task();
        println!(
            "({ox:5.1}, {oy:5.1}) | ({:6.2}, {:6.2}, {:6.2}) | ({:6.3}, {:6.3}, {:6.3}) | ({:6.1}, {:6.1}) | {:6.2}  s ({:.1}, {:.1})",
            f.x,
            f.y,
            f.z,
            m.x,
            m.y,
            m.z,
            c[0] * 1e3,
            c[1] * 1e3,
            t.s_m.z * 1e3,
            t.s_m.x * 1e3,
            t.s_m.y * 1e3,
        );
    }
}

/// The search's settings from the environment, for tuning (see the
/// module's doc).
fn overrides(sc: &mut TouchSearchConfig) {
    let var = |name: &str, v: &mut f64, unit: f64| {
        if let Ok(s) = std::env::var(name) {
            *v = s.parse::<f64>().expect(name) * unit;
        }
    };
    var("TOUCH_PITCH_MM", &mut sc.pitch_m, 1e-3);
    var("TOUCH_SLIDE_MM", &mut sc.slide_m, 1e-3);
    var("TOUCH_STEP_MM", &mut sc.step_m, 1e-3);
    var("TOUCH_PRESS_N", &mut sc.press_n, 1.0);
    var("TOUCH_LEAD_MM_PER_N", &mut sc.lead_m_per_n, 1e-3);
    var("TOUCH_ROLL_GAIN", &mut sc.roll_gain, 1.0);
    var("TOUCH_DESCENT_UNTIL_MM", &mut sc.descent_until_m, 1e-3);
    // The optional settings: set when their variable is.
    let opt = |name: &str, v: &mut Option<f64>, unit: f64| {
        if let Ok(s) = std::env::var(name) {
            *v = Some(s.parse::<f64>().expect(name) * unit);
        }
    };
    opt("TOUCH_DESCENT_MM", &mut sc.descent_m, 1e-3);
    opt("TOUCH_BOUND_MM", &mut sc.bound_m, 1e-3);
}

fn search(sigma_mm: f64, episodes: u64) {
    let cfg = config();
    let mut env = RlEnv::new(&cfg).expect("env");
    // The library's search, its settings overridable for tuning.
    let mut sc = TouchSearchConfig {
        hole_error_m: sigma_mm * 1e-3,
        ..Default::default()
    };
    overrides(&mut sc);
    sc.validate().unwrap_or_else(|e| panic!("{e}"));
    let view = SearchView {
        std_m: sc.hole_error_m,
    };
    let policy = TouchSearch {
        cfg: sc.clone(),
        scale: cfg.action.clone(),
    };
    let err = HoleError {
        std_m: sc.hole_error_m,
    };
    let mut counts = [0u32; 4];
    let trace = std::env::var_os("TOUCH_TRACE").is_some();
    for ep in 0..episodes {
        env.reset(1_000_000 + ep, false).expect("reset");
        let e = err.error(&env.task_geometry().hole_pose);
        let o = loop {
            let mut obs = [0.0; SEARCH_VIEW_DIM];
            view.observe(&[env.view().expect("view")], &mut obs);
            let a = policy.means(&obs);
            let o = env.step(&a, false).expect("step");
            if trace && env.task().s_m.z < 0.004 {
                let t = env.task();
                let d = policy.step(&obs);
                println!(
                    "  step {:3} s ({:5.2}, {:5.2}, {:5.2}) mm F ({:5.1}, {:5.1}, {:5.1}) d ({:.2}, {:.2}, {:.2}) mm",
                    o.steps,
                    t.s_m.x * 1e3,
                    t.s_m.y * 1e3,
                    t.s_m.z * 1e3,
                    obs[4],
                    obs[5],
                    obs[6],
                    d.x * 1e3,
                    d.y * 1e3,
                    d.z * 1e3
                );
            }
            if o.done() {
                break o;
            }
        };
        counts[o.outcome.index()] += 1;
        println!(
            "ep {ep}: error ({:.1}, {:.1}) mm {:?} steps {} final s ({:.1}, {:.1}, {:.1}) mm",
            e[0] * 1e3,
            e[1] * 1e3,
            o.outcome,
            o.steps,
            env.task().s_m.x * 1e3,
            env.task().s_m.y * 1e3,
            env.task().s_m.z * 1e3,
        );
    }
    println!(
        "{} peg, σ {sigma_mm} mm: outcomes {:?} over {episodes}",
        cfg.world.task.peg.name(),
        Outcome::ALL
            .iter()
            .zip(counts)
            .map(|(o, c)| format!("{}: {c}", o.name()))
            .collect::<Vec<_>>()
    );
}

/// The environment (in `world`'s world, task on, unless `-`) and the
/// representation exported at `model`, for `zsearch` and `zfit`.
fn on_representation(model: &str, world: &str) -> (RlEnvConfig, std::sync::Arc<dyn Observer>) {
    let mut cfg = config();
    if world != "-" {
        cfg.world = hw_sim::WorldConfig::from_file(std::path::Path::new(world)).expect("world");
        cfg.world.task.enabled = true;
        task_from_env(&mut cfg.world.task);
    }
    let repr = learner::rl::ObservationKind::Representation(model.into())
        .observer_on(0)
        .expect("model");
    (cfg, repr)
}

/// The fitting episodes' hole error, m: `TOUCH_FIT_ERROR_MM`, or 10 mm.
fn fit_error_m() -> f64 {
    std::env::var("TOUCH_FIT_ERROR_MM").map_or(10.0, |v| v.parse::<f64>().expect("mm")) * 1e-3
}

/// The search told where the hole is by a representation
/// (`search::ProbedSearchView`): a linear probe from its z means to the
/// tip's offset from the hole and the peg's roll relative to it, fitted on
/// `fit` episodes of the search told the truth with a 10 mm error
/// (`TOUCH_FIT_ERROR_MM`), replaces the believed offset and roll below 30
/// mm (`TOUCH_PROBE_BELOW_MM`) above the box on `test` other episodes (`TOUCH_TRUE_ROLL`: the roll
/// stays the truth's). Height, force and the hole's yaw stay the truth's:
/// this asks whether z places the opening well enough for the search.
fn zsearch(model: &str, world: &str, fit: u64, test: u64) {
    use learner::rl::search::{BeliefProbeConfig, ProbedSearchView, fit_belief_probe};
    let (cfg, repr) = on_representation(model, world);
    let pc = BeliefProbeConfig {
        representation: model.into(),
        fit_episodes: fit,
        fit_hole_error_m: fit_error_m(),
        // TOUCH_PROBE_BELOW_MM: the height below which the probe is fitted
        // and read (30 mm, the default, otherwise).
        below_m: std::env::var("TOUCH_PROBE_BELOW_MM").map_or(0.03, |v| {
            v.parse::<f64>().expect("TOUCH_PROBE_BELOW_MM: mm") * 1e-3
        }),
        // TOUCH_FIT_ROUNDS: rounds of fitting, the later ones on the search
        // told by the probe so far.
        fit_rounds: std::env::var("TOUCH_FIT_ROUNDS").map_or(1, |v| v.parse().expect("rounds")),
        // TOUCH_APPROACH_PROBE: a second probe tells the way down too.
        approach: std::env::var_os("TOUCH_APPROACH_PROBE").is_some(),
    };
    assert!(pc.fit_rounds >= 1, "TOUCH_FIT_ROUNDS must be at least 1");
    // TOUCH_ROLL_GAIN: the search's roll gain (its fitting episodes' too).
    // TOUCH_APPROACH_RADIUS_MM: the search's `approach_radius_m`.
    let mut search = TouchSearchConfig {
        roll_gain: 1.0,
        approach_radius_m: std::env::var("TOUCH_APPROACH_RADIUS_MM")
            .ok()
            .map(|v| v.parse::<f64>().expect("TOUCH_APPROACH_RADIUS_MM: mm") * 1e-3),
        ..Default::default()
    };
    overrides(&mut search);
    search.validate().unwrap_or_else(|e| panic!("{e}"));
    let probes = fit_belief_probe(
        &cfg,
        repr.as_ref(),
        &search,
        &pc,
        3_000_000,
        &mut |ep, rows| {
            eprint!(
                "\rfit: {ep}/{} episodes, {rows} states",
                fit * u64::from(pc.fit_rounds)
            )
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    eprintln!();
    let view = ProbedSearchView {
        repr,
        probes,
        below_m: pc.below_m,
    };
    let policy = TouchSearch {
        cfg: search.clone(),
        scale: cfg.action.clone(),
    };
    let mut env = RlEnv::new(&cfg).expect("env");
    // TOUCH_TRUE_ROLL: the roll from the truth instead of the probe.
    let true_roll = std::env::var_os("TOUCH_TRUE_ROLL").is_some();
    // TOUCH_TRACE: each step's height and roll.
    let zs_trace = std::env::var_os("TOUCH_TRACE").is_some();
    let mut counts = [0u32; 4];
    let (mut se, mut n, mut psi_se, mut roll_se, mut read_ss) = (0.0, 0usize, 0.0, 0.0, 0.0);
    // The probe's squared error and count where the tip is within 10 mm of
    // the hole's axis, and farther.
    let (mut near, mut far) = ((0.0, 0usize), (0.0, 0usize));
    // The approach probe's, above `below_m`.
    let mut up = (0.0, 0usize);
    for ep in 0..test {
        env.reset(1_000_000 + ep, true).expect("reset");
        let (mut ep_se, mut ep_n) = (0.0, 0usize);
        let o = loop {
            let mut o = [0.0; SEARCH_VIEW_DIM];
            view.observe(&[env.view().expect("view")], &mut o);
            let s = env.task().s_m;
            let psi = env.task().s_psi_rad;
            if s.z < pc.below_m && s.z > -0.002 {
                psi_se += (o[3] - psi).powi(2);
                roll_se += psi * psi;
                read_ss += o[3] * o[3];
            }
            if true_roll {
                o[3] = psi;
            }
            if zs_trace {
                println!(
                    "  z {:+.1} mm, roll off the hole {:+.3} rad, told {:+.3}",
                    s.z * 1e3,
                    psi,
                    o[3]
                );
            }
            // The probe's error where it is read, above the opening.
            if s.z < pc.below_m && s.z > -0.002 {
                let e = (o[0] - s.x).powi(2) + (o[1] - s.y).powi(2);
                ep_se += e;
                ep_n += 1;
                let band = if s.x.hypot(s.y) < 0.01 {
                    &mut near
                } else {
                    &mut far
                };
                band.0 += e;
                band.1 += 1;
            }
            if pc.approach && s.z >= pc.below_m {
                up.0 += (o[0] - s.x).powi(2) + (o[1] - s.y).powi(2);
                up.1 += 1;
            }
            let out = env.step(&policy.means(&o), true).expect("step");
            if out.done() {
                break out;
            }
        };
        se += ep_se;
        n += ep_n;
        counts[o.outcome.index()] += 1;
        println!(
            "ep {ep}: {:?}, probe RMS (x, y together) {:.1} mm over {ep_n} states above the box, final s ({:.1}, {:.1}, {:.1}) mm",
            o.outcome,
            1e3 * (ep_se / ep_n.max(1) as f64).sqrt(),
            env.task().s_m.x * 1e3,
            env.task().s_m.y * 1e3,
            env.task().s_m.z * 1e3,
        );
    }
    let rms = |(se, n): (f64, usize)| 1e3 * (se / n.max(1) as f64).sqrt();
    println!(
        "probe RMS (x, y together) with the tip within 10 mm of the hole's axis {:.1} mm over {} states, farther {:.1} mm over {} states",
        rms(near),
        near.1,
        rms(far),
        far.1
    );
    if pc.approach {
        println!(
            "approach probe RMS (x, y together) above {:.0} mm: {:.1} mm over {} states",
            pc.below_m * 1e3,
            rms(up),
            up.1
        );
    }
    println!(
        "z-told search: probe RMS {:.1} mm, roll {:.3} rad; the peg's roll off the hole's {:.3} rad RMS, the probe's reading of it {:.3} rad RMS; rejected frames {}; outcomes {:?} over {test}",
        1e3 * (se / n.max(1) as f64).sqrt(),
        (psi_se / n.max(1) as f64).sqrt(),
        (roll_se / n.max(1) as f64).sqrt(),
        (read_ss / n.max(1) as f64).sqrt(),
        view.rejected(),
        Outcome::ALL
            .iter()
            .zip(counts)
            .map(|(o, c)| format!("{}: {c}", o.name()))
            .collect::<Vec<_>>()
    );
}

/// [`near_rows`]' rows: inputs, targets, (episode, on the box).
type Rows = (Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<(u64, bool)>);

/// Near-box rows (z means; tip x, y relative to the hole, mm; the episode
/// and whether the tip is on the box, below 1 mm) of `episodes` episodes
/// from `first_seed` of the search told the truth with a per-episode error
/// of `err_m`.
fn near_rows(
    cfg: &RlEnvConfig,
    repr: &dyn Observer,
    err_m: f64,
    first_seed: u64,
    episodes: u64,
) -> Rows {
    let mut env = RlEnv::new(cfg).expect("env");
    let view = SearchView { std_m: err_m };
    let policy = TouchSearch {
        cfg: TouchSearchConfig {
            hole_error_m: err_m,
            roll_gain: 0.01,
            ..Default::default()
        },
        scale: cfg.action.clone(),
    };
    let (mut xs, mut ys, mut eps) = (Vec::new(), Vec::new(), Vec::new());
    let mut z = vec![0.0; repr.dim()];
    for ep in 0..episodes {
        env.reset(first_seed + ep, true).expect("reset");
        loop {
            let v = env.view().expect("view");
            let s = v.task.s_m;
            let mut o = [0.0; SEARCH_VIEW_DIM];
            view.observe(std::slice::from_ref(&v), &mut o);
            if s.z < 0.03 && s.z > IN_OPENING_M {
                repr.observe(std::slice::from_ref(&v), &mut z);
                xs.push(z.clone());
                ys.push(vec![s.x * 1e3, s.y * 1e3]);
                eps.push((ep, s.z < 0.001));
            }
            if env.step(&policy.means(&o), true).expect("step").done() {
                break;
            }
        }
        eprint!(
            "\rrows: {ep} episodes from {first_seed}, {} states",
            xs.len()
        );
    }
    eprintln!();
    (xs, ys, eps)
}

/// Prints the RMS error of (x, y) together over the rows: all, within
/// 10 mm of the axis, on the box, 1–30 mm above it, and the whole split
/// into each episode's mean error (bias) and the rest (jitter about it), mm.
fn report(name: &str, pred: &[Vec<f64>], ys: &[Vec<f64>], eps: &[(u64, bool)]) {
    // Sums of squares and counts: all, near the axis, on the box, above.
    let mut acc = [(0.0, 0usize); 4];
    let mut by_ep: std::collections::BTreeMap<u64, Vec<[f64; 2]>> = Default::default();
    for ((p, y), &(ep, on_box)) in pred.iter().zip(ys).zip(eps) {
        let e = [p[0] - y[0], p[1] - y[1]];
        let sq = e[0] * e[0] + e[1] * e[1];
        let near = y[0].hypot(y[1]) < 10.0;
        for (i, yes) in [true, near, on_box, !on_box].into_iter().enumerate() {
            if yes {
                acc[i].0 += sq;
                acc[i].1 += 1;
            }
        }
        by_ep.entry(ep).or_default().push(e);
    }
    let (mut bias, mut jitter) = (0.0, 0.0);
    for errs in by_ep.values() {
        let m = errs.len() as f64;
        let mean = [
            errs.iter().map(|e| e[0]).sum::<f64>() / m,
            errs.iter().map(|e| e[1]).sum::<f64>() / m,
        ];
        for e in errs {
            bias += mean[0].powi(2) + mean[1].powi(2);
            jitter += (e[0] - mean[0]).powi(2) + (e[1] - mean[1]).powi(2);
        }
    }
    let rms = |(sq, n): (f64, usize)| (sq / n.max(1) as f64).sqrt();
    let n = acc[0].1.max(1) as f64;
    println!(
        "{name} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1}",
        rms(acc[0]),
        rms(acc[1]),
        rms(acc[2]),
        rms(acc[3]),
        (bias / n).sqrt(),
        (jitter / n).sqrt()
    );
}

/// RMS error of (x, y) together over the rows, mm.
fn report_fit(pred: &[Vec<f64>], ys: &[Vec<f64>]) -> f64 {
    let sq: f64 = pred
        .iter()
        .zip(ys)
        .map(|(p, y)| (p[0] - y[0]).powi(2) + (p[1] - y[1]).powi(2))
        .sum();
    (sq / ys.len().max(1) as f64).sqrt()
}

fn zfit(model: &str, world: &str, fit: u64, test: u64) {
    use learner::rl::GaussianPolicy;
    use learner::rl::mlp::MseFit;
    use learner::rl::obs_norm::ObsNorm;
    use learner::rl::ppo::Adam;
    use learner::rl::probe::LinearProbe;
    let (cfg, repr) = on_representation(model, world);
    let err = fit_error_m();
    let epochs: usize =
        std::env::var("TOUCH_ZFIT_EPOCHS").map_or(200, |v| v.parse().expect("epochs"));
    let (xs, ys, _) = near_rows(&cfg, repr.as_ref(), err, 3_000_000, fit);
    let (xt, yt, et) = near_rows(&cfg, repr.as_ref(), err, 1_000_000, test);
    let on_box = et.iter().filter(|e| e.1).count();
    println!(
        "{} fitting states, {} test states ({on_box} on the box); test RMS of (x, y) together, mm",
        xs.len(),
        xt.len()
    );
    println!(
        "reading | all | within 10 mm of the axis | on the box | 1-30 mm above | per-episode bias | jitter about it"
    );
    report("zero", &vec![vec![0.0, 0.0]; yt.len()], &yt, &et);
    let linear = LinearProbe::fit(&xs, &ys, 1e-3).expect("fit");
    let lp: Vec<Vec<f64>> = xt.iter().map(|z| linear.predict(z)).collect();
    report("linear probe (ridge 1e-3)", &lp, &yt, &et);
    let d = xs[0].len();
    let flat = |v: &[Vec<f64>]| v.iter().flatten().copied().collect::<Vec<f64>>();
    let (x_fit, y_fit, x_test) = (flat(&xs), flat(&ys), flat(&xt));
    for hidden in [vec![64, 64], vec![256, 256]] {
        let mut rng = stack_common::rng::seeded(1, 0);
        let mut net = GaussianPolicy::new(d, &hidden, 2, 0.0, &mut rng);
        let mut norm = ObsNorm::new(d, 5.0);
        norm.update(&x_fit);
        net.obs_norm = Some(norm);
        let inputs = net.inputs(&x_fit);
        let mlp = net.mlp();
        let mut adam = Adam::default();
        let step = MseFit {
            epochs: 1,
            minibatch: 256,
            learning_rate: 1e-3,
            l2: 0.0,
        };
        for e in 1..=epochs {
            step.run(&mlp, &mut net.net, &mut adam, &inputs, &y_fit, &mut rng);
            if e % 50 == 0 || e == epochs {
                let p = net.means(&x_test);
                let p: Vec<Vec<f64>> = p.chunks_exact(2).map(<[f64]>::to_vec).collect();
                let f: Vec<Vec<f64>> = net
                    .means(&x_fit)
                    .chunks_exact(2)
                    .map(<[f64]>::to_vec)
                    .collect();
                let (fa, fitted) = (report_fit(&f, &ys), format!("MLP {hidden:?}, epoch {e}"));
                report(&format!("{fitted} (fitting states {fa:.1})"), &p, &yt, &et);
            }
        }
    }
}

fn main() {
    let usage = "usage: touch_probe press | touch_probe search SIGMA_MM EPISODES | \
                 touch_probe zsearch MODEL_DIR WORLD_TOML|- FIT_EPISODES TEST_EPISODES | \
                 touch_probe zfit MODEL_DIR WORLD_TOML|- FIT_EPISODES TEST_EPISODES";
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("press") => press(),
        Some("search") => {
            let sigma: f64 = args.get(2).expect(usage).parse().expect(usage);
            let n: u64 = args.get(3).expect(usage).parse().expect(usage);
            search(sigma, n)
        }
        Some(mode @ ("zsearch" | "zfit")) => {
            let model = args.get(2).expect(usage);
            let world = args.get(3).expect(usage);
            let fit: u64 = args.get(4).expect(usage).parse().expect(usage);
            let test: u64 = args.get(5).expect(usage).parse().expect(usage);
            if mode == "zsearch" {
                zsearch(model, world, fit, test)
            } else {
                zfit(model, world, fit, test)
            }
        }
        _ => panic!("{usage}"),
    }
}
