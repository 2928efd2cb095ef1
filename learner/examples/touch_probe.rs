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
//!   `policy eval --hole-error-mm`); `TOUCH_PITCH_MM`, `TOUCH_SLIDE_MM`,
//!   `TOUCH_PRESS_N`, `TOUCH_LEAD_MM_PER_N` override its settings,
//!   `TOUCH_STICK_N` sets `stick_n`,
//!   `TOUCH_TRACE` prints the steps near the box, `TOUCH_PEG` (square,
//!   triangle, semicircle, hexagon) picks the peg. Prints each episode and
//!   the outcomes.
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
//!
//! Episodes use seeds from 1 000 000, as `learner policy eval` does.

use learner::rl::observe::{HoleError, Observer};
use learner::rl::search::{SEARCH_VIEW_DIM, SearchView, TouchSearch, TouchSearchConfig};
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
    if let Ok(name) = std::env::var("TOUCH_PEG") {
        // The parser behind the CLI's `--peg`.
        cfg.world.task.peg = <hw_sim::PegShape as clap::ValueEnum>::from_str(&name, false)
            .unwrap_or_else(|e| panic!("TOUCH_PEG={name}: {e}"));
    }
    cfg
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

fn search(sigma_mm: f64, episodes: u64) {
    let cfg = config();
    let mut env = RlEnv::new(&cfg).expect("env");
    // The library's search, its settings overridable for tuning.
    let mut sc = TouchSearchConfig {
        hole_error_m: sigma_mm * 1e-3,
        ..Default::default()
    };
    let var = |name: &str, v: &mut f64, unit: f64| {
        if let Ok(s) = std::env::var(name) {
            *v = s.parse::<f64>().expect(name) * unit;
        }
    };
    var("TOUCH_PITCH_MM", &mut sc.pitch_m, 1e-3);
    var("TOUCH_SLIDE_MM", &mut sc.slide_m, 1e-3);
    var("TOUCH_PRESS_N", &mut sc.press_n, 1.0);
    var("TOUCH_LEAD_MM_PER_N", &mut sc.lead_m_per_n, 1e-3);
    var("TOUCH_ROLL_GAIN", &mut sc.roll_gain, 1.0);
    if let Ok(v) = std::env::var("TOUCH_STICK_N") {
        sc.stick_n = Some(v.parse().expect("TOUCH_STICK_N"));
    }
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

/// The search told where the hole is by a representation
/// (`search::ProbedSearchView`): a linear probe from its z means to the
/// tip's offset from the hole and the peg's roll relative to it, fitted on
/// `fit` episodes of the search told the truth with a 10 mm error
/// (`TOUCH_FIT_ERROR_MM`), replaces the believed offset and roll below 30
/// mm (`TOUCH_PROBE_BELOW_MM`) above the box on `test` other episodes (`TOUCH_TRUE_ROLL`: the roll
/// stays the truth's). Height, force and the hole's yaw stay the truth's:
/// this asks whether z places the opening well enough for the search.
fn zsearch(model: &str, world: &str, fit: u64, test: u64) {
    use learner::rl::ObservationKind;
    use learner::rl::search::{BeliefProbeConfig, ProbedSearchView, fit_belief_probe};
    let mut cfg = config();
    if world != "-" {
        cfg.world = hw_sim::WorldConfig::from_file(std::path::Path::new(world)).expect("world");
        cfg.world.task.enabled = true;
    }
    let repr = ObservationKind::Representation(model.into())
        .observer_on(0)
        .expect("model");
    let fit_err: f64 = std::env::var("TOUCH_FIT_ERROR_MM").map_or(10.0, |v| v.parse().expect("mm"));
    let pc = BeliefProbeConfig {
        representation: model.into(),
        fit_episodes: fit,
        fit_hole_error_m: fit_err * 1e-3,
        // TOUCH_FIT_ROLL_ERROR_RAD: the fitting episodes' roll error.
        fit_roll_error_rad: std::env::var("TOUCH_FIT_ROLL_ERROR_RAD")
            .map_or(0.0, |v| v.parse().expect("rad")),
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
    let search = TouchSearchConfig {
        roll_gain: std::env::var("TOUCH_ROLL_GAIN").map_or(1.0, |v| v.parse().expect("gain")),
        approach_radius_m: std::env::var("TOUCH_APPROACH_RADIUS_MM")
            .ok()
            .map(|v| v.parse::<f64>().expect("TOUCH_APPROACH_RADIUS_MM: mm") * 1e-3),
        ..Default::default()
    };
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

fn main() {
    let usage = "usage: touch_probe press | touch_probe search SIGMA_MM EPISODES | \
                 touch_probe zsearch MODEL_DIR WORLD_TOML|- FIT_EPISODES TEST_EPISODES";
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("press") => press(),
        Some("search") => {
            let sigma: f64 = args.get(2).expect(usage).parse().expect(usage);
            let n: u64 = args.get(3).expect(usage).parse().expect(usage);
            search(sigma, n)
        }
        Some("zsearch") => {
            let model = args.get(2).expect(usage);
            let world = args.get(3).expect(usage);
            let fit: u64 = args.get(4).expect(usage).parse().expect(usage);
            let test: u64 = args.get(5).expect(usage).parse().expect(usage);
            zsearch(model, world, fit, test)
        }
        _ => panic!("{usage}"),
    }
}
