//! What a frozen representation tells a policy: linear probes (ridge least
//! squares through faer, `learner::rl::probe::LinearProbe`, the bias not
//! penalised) from its z means to the task's ground truth, fitted
//! on some episodes and scored (R²) on others, over states of the RL
//! environment under random actions (uniform in [−1, 1] per component, as an
//! untrained policy's noise).
//!
//! The same from z through an MLP (64, 64, the value network's code) shows
//! what a policy's network could read beyond a linear map.
//!
//! Targets: the tip relative to the hole (x, y, z in the hole frame), the
//! hole's position in the base frame (x, y: only the camera sees where the
//! randomised box is), the tip's base-frame position (x, y), the peg's roll
//! relative to the hole (the task's s_ψ) and its proprioceptive roll (from
//! the episode's start); the roll errors print in mrad. Each is
//! also probed from the tip's base-frame position and roll alone (what
//! proprioception gives), so that the camera's share shows.
//!
//! Usage: `repr_probe MODEL_DIR EPISODES STEPS [THREADS [WORLD_TOML [at-box]]]`
//! (episode seeds from 3 000 000; the last quarter of the episodes is the
//! test split; WORLD_TOML: hw-sim's world, for a model trained with another
//! camera than the default one, which the model's own camera must match,
//! `-` for the default). `at-box`: instead of uniform random actions, each
//! episode steers the tip (from the ground truth) to a random point within
//! ±15 mm of the hole (base-frame x, y) and 2–20 mm above its frame's
//! origin, with noise, and probes the
//! states with the tip less than 30 mm above the box: where a policy must
//! act on the opening. STEPS counts the descent too.
//! Beside R², the test error's root mean square (mm for positions, bias
//! included). The MLP's first column is the explained variance (R² less
//! the error's mean), as the earlier runs recorded it.

use learner::rl::observe::ObservationKind;
use learner::rl::probe::{LinearProbe, standardiser};
use learner::rl::value::explained_variance;
use learner::rl::{RlEnv, RlEnvConfig, ValueConfig, ValueNet};

/// Ridge fit (`LinearProbe`: features standardised by the training rows'
/// mean and deviation, ridge 10⁻³ per row) on rows `train`; per target on
/// rows `test`, R² and the root mean square of the error.
fn probe(x: &[Vec<f64>], y: &[Vec<f64>], train: &[usize], test: &[usize]) -> Vec<(f64, f64)> {
    let pick = |rows: &[Vec<f64>]| train.iter().map(|&i| rows[i].clone()).collect::<Vec<_>>();
    let p = LinearProbe::fit(&pick(x), &pick(y), 1e-3).expect("probe");
    let pred: Vec<Vec<f64>> = test.iter().map(|&i| p.predict(&x[i])).collect();
    (0..y[0].len())
        .map(|t| {
            let mean = test.iter().map(|&i| y[i][t]).sum::<f64>() / test.len() as f64;
            let (mut ss_res, mut ss_tot) = (0.0, 0.0);
            for (j, &i) in test.iter().enumerate() {
                ss_res += (y[i][t] - pred[j][t]).powi(2);
                ss_tot += (y[i][t] - mean).powi(2);
            }
            (
                1.0 - ss_res / ss_tot.max(1e-300),
                (ss_res / test.len() as f64).sqrt(),
            )
        })
        .collect()
}

/// An MLP probe (the value network's code: 64, 64 tanh, Adam with an L2
/// penalty) per target, fitted on rows `train`; on rows `test`, the
/// explained variance (R² up to the error's mean) and the root mean square
/// of the error (with its mean).
fn mlp_probe(x: &[Vec<f64>], y: &[Vec<f64>], train: &[usize], test: &[usize]) -> Vec<(f64, f64)> {
    let d = x[0].len();
    let n = train.len() as f64;
    let (mean, sd) = standardiser(train.iter().map(|&i| x[i].as_slice()), d);
    let rows = |idx: &[usize]| -> Vec<f64> {
        let (mean, sd) = (&mean, &sd);
        idx.iter()
            .flat_map(|&i| (0..d).map(move |c| (x[i][c] - mean[c]) / sd[c]))
            .collect()
    };
    let (xtr, xte) = (rows(train), rows(test));
    let (ttr, tte) = (vec![0.0; train.len()], vec![0.0; test.len()]);
    let cfg = ValueConfig {
        epochs: 100,
        ..Default::default()
    };
    let mut rng = stack_common::rng::seeded(12, 0);
    (0..y[0].len())
        .map(|t| {
            let ytr: Vec<f64> = train.iter().map(|&i| y[i][t]).collect();
            let yte: Vec<f64> = test.iter().map(|&i| y[i][t]).collect();
            // Centred and scaled, so that the network's fixed scale is the
            // target's spread.
            let m = ytr.iter().sum::<f64>() / n;
            let s = (ytr.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n)
                .sqrt()
                .max(1e-12);
            let ytr: Vec<f64> = ytr.iter().map(|v| (v - m) / s).collect();
            let mut net = ValueNet::new(d, &cfg.hidden, &mut rng);
            net.fit(&xtr, &ttr, &ytr, &cfg, &mut rng);
            let pred: Vec<f64> = net.predict(&xte, &tte).iter().map(|v| v * s + m).collect();
            let mse = pred
                .iter()
                .zip(&yte)
                .map(|(p, t)| (p - t).powi(2))
                .sum::<f64>()
                / yte.len() as f64;
            (explained_variance(&pred, &yte), mse.sqrt())
        })
        .collect()
}

fn main() {
    let usage = "usage: repr_probe MODEL_DIR EPISODES STEPS [THREADS [WORLD_TOML|- [at-box]]]";
    let args: Vec<String> = std::env::args().collect();
    let model = args.get(1).expect(usage);
    let episodes: u64 = args.get(2).expect(usage).parse().expect(usage);
    let steps: u32 = args.get(3).expect(usage).parse().expect(usage);
    let threads: usize = args.get(4).map_or(1, |t| t.parse().expect(usage));
    let observer = ObservationKind::Representation(model.into())
        .observer_on(threads)
        .expect("model");
    let mut cfg = RlEnvConfig::default();
    assert!(args.len() <= 7, "{usage}");
    let at_box = match args.get(6).map(String::as_str) {
        None => false,
        Some("at-box") => true,
        Some(other) => panic!("{other}: the sixth argument can only be at-box; {usage}"),
    };
    if let Some(w) = args.get(5).filter(|w| *w != "-") {
        cfg.world =
            hw_sim::WorldConfig::from_file(std::path::Path::new(w)).expect("the world file");
        cfg.world.task.enabled = true;
    }
    let mut env = RlEnv::new(&cfg).expect("env");
    learner::rl::observe::check_camera(&cfg.world.camera, observer.as_ref())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut rng = stack_common::rng::seeded(11, 0);
    let (mut z, mut own, mut targets, mut episode) = (vec![], vec![], vec![], vec![]);
    for ep in 0..episodes {
        env.reset(3_000_000 + ep, true).expect("reset");
        let hole = env.task_geometry().hole_pose.translation.vector;
        // at-box: the point this episode steers to, relative to the hole
        // frame's origin along base-frame axes, m.
        let mut goal = [0.0; 3];
        if at_box {
            goal = [
                stack_common::rng::uniform(&mut rng, -0.015, 0.015),
                stack_common::rng::uniform(&mut rng, -0.015, 0.015),
                stack_common::rng::uniform(&mut rng, 0.002, 0.020),
            ];
        }
        for _ in 0..steps {
            let s = env.task().s_m;
            let a: Vec<f64> = if at_box {
                // Actions move the tip in the base frame.
                let tip = env.observation().expect("observation").ee_pos;
                let top = env.task_geometry().hole_pose * nalgebra::Point3::origin();
                let to = [
                    top.x + goal[0] - tip.x,
                    top.y + goal[1] - tip.y,
                    top.z + goal[2] - tip.z,
                ];
                (0..4)
                    .map(|k| {
                        let aim = if k < 3 { to[k] / 0.01 } else { 0.0 };
                        (aim + 0.3 * stack_common::rng::normal(&mut rng)).clamp(-1.0, 1.0)
                    })
                    .collect()
            } else {
                (0..4)
                    .map(|_| stack_common::rng::uniform(&mut rng, -1.0, 1.0))
                    .collect()
            };
            // Probed only once the tip is within 3 cm of the box top.
            if at_box && s.z > 0.03 {
                if env.step(&a, true).expect("step").done() {
                    break;
                }
                continue;
            }
            let view = env.view().expect("view");
            let mut out = vec![0.0; observer.dim()];
            observer.observe(std::slice::from_ref(&view), &mut out);
            let o = env.observation().expect("observation");
            z.push(out);
            own.push(vec![o.ee_pos.x, o.ee_pos.y, o.ee_pos.z, o.proprio.roll_rad]);
            targets.push(vec![
                s.x,
                s.y,
                s.z,
                hole.x,
                hole.y,
                o.ee_pos.x,
                o.ee_pos.y,
                env.task().s_psi_rad,
                o.proprio.roll_rad,
            ]);
            episode.push(ep);
            if env.step(&a, true).expect("step").done() {
                break;
            }
        }
    }
    let cut = episodes - episodes / 4;
    let (train, test): (Vec<usize>, Vec<usize>) = (0..z.len()).partition(|&i| episode[i] < cut);
    println!(
        "{} states of {episodes} episodes ({} train, {} test), {} rejected",
        z.len(),
        train.len(),
        test.len(),
        observer.rejected()
    );
    let names = [
        "tip-hole x",
        "tip-hole y",
        "tip-hole z",
        "hole x",
        "hole y",
        "tip x",
        "tip y",
        "psi (mrad)",
        "roll (mrad)",
    ];
    let from_z = probe(&z, &targets, &train, &test);
    let from_own = probe(&own, &targets, &train, &test);
    let from_z_mlp = mlp_probe(&z, &targets, &train, &test);
    // The test targets' deviation, mm: the RMS error of predicting their
    // mean.
    let spread = |i: usize| {
        let n = test.len() as f64;
        let m = test.iter().map(|&t| targets[t][i]).sum::<f64>() / n;
        1e3 * (test
            .iter()
            .map(|&t| (targets[t][i] - m).powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
    };
    println!(
        "test         R² from z   from tip pose   EV, z (MLP)    | RMS error, mm: z   tip pose   z (MLP)   target's sd"
    );
    for (i, n) in names.iter().enumerate() {
        println!(
            "{n:<12} {:>9.3} {:>14.3} {:>14.3}   | {:>16.1} {:>10.1} {:>9.1} {:>13.1}",
            from_z[i].0,
            from_own[i].0,
            from_z_mlp[i].0,
            1e3 * from_z[i].1,
            1e3 * from_own[i].1,
            1e3 * from_z_mlp[i].1,
            spread(i)
        );
    }
}
