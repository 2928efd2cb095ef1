//! The scripted heuristic with each trajectory target (`trajectory.target`:
//! accumulated, measured) over all four pegs and several box poses, in the
//! fast path: completion rate, time to completion, controller faults and
//! peak contact force, as a Markdown table (docs/paper.md).
//!
//! `cargo run --manifest-path lab/probes/Cargo.toml --release --bin
//! trajectory_target -- [seeds] [actions] [noise_m]`: `seeds` box poses per peg (default 8), episodes of
//! `actions` 20 Hz actions (default 100, a collection episode's 5 s), and
//! Gaussian noise of `noise_m` added to each position step (default 0; the
//! collection mix uses 0.001).

use hw_sim::{PegShape, Stage, WorldConfig};
use learner::fast_env::FastEnv;
use learner_node::mix::{Mix, MixedPolicy};
use learner_node::policy::TaskGeometry;
use rt_controller::{ControllerConfig, TrajectoryTarget};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;

/// One episode's result.
struct Trial {
    completed_s: Option<f64>,
    fault: Option<String>,
    peak_force_n: f64,
}

fn trial(target: TrajectoryTarget, peg: PegShape, seed: u64, actions: u32, noise_m: f64) -> Trial {
    let mut world = WorldConfig::default();
    world.task.peg = peg;
    let mut controller = ControllerConfig::default();
    controller.trajectory.target = target;
    let mut env = FastEnv::new(world, controller).expect("default configuration");
    env.reset(seed).expect("reset");
    let task = TaskGeometry {
        hole_pose: env.world().hole_pose().expect("task"),
        symmetry: peg.symmetry_order(),
        depth_m: env.world().box_geometry().expect("box").depth,
    };
    // The collection's heuristic with `noise_m` of noise (0: the bare
    // heuristic).
    let mix = Mix {
        heuristic_fraction: 1.0,
        heuristic_noise_m: noise_m,
        end_after_completion: None,
        ..Mix::default()
    };
    let mut policy = MixedPolicy::new(&mix, seed);
    let mut obs = env.step(None).expect("step");
    // Free space: the mean force before anything moves.
    let free = env.wrench.mean_force(32);
    let (mut completed_s, mut fault, mut peak) = (None, None, 0.0f64);
    for _ in 0..actions {
        let a = policy.act(&obs, &env.wrench, &task);
        for c in 0..ACTION_PERIOD_STEPS {
            env.cycle(if c == 0 { Some(&a) } else { None })
                .expect("cycle");
            let w = env.sensor_frame().wrench;
            let f = nalgebra::Vector3::new(w[0], w[1], w[2]) - free;
            peak = peak.max(f.norm());
            if fault.is_none()
                && let Some(r) = env.controller_data().supervisor.fault()
            {
                fault = Some(format!("{r:?} at {:.2} s", env.world().time_s()));
            }
        }
        obs = env.last_observation().expect("cycled");
        if completed_s.is_none()
            && env.world().task().map(|t| t.best_stage) == Some(Stage::Completed)
        {
            completed_s = Some(env.world().time_s());
        }
    }
    Trial {
        completed_s,
        fault,
        peak_force_n: peak,
    }
}

fn median_range(mut v: Vec<f64>, digits: usize) -> String {
    if v.is_empty() {
        return "–".into();
    }
    v.sort_by(f64::total_cmp);
    format!(
        "{:.d$} ({:.d$}–{:.d$})",
        v[v.len() / 2],
        v[0],
        v[v.len() - 1],
        d = digits
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: f64| -> f64 {
        args.get(i).map_or(default, |s| {
            s.parse()
                .unwrap_or_else(|_| panic!("argument {} ({s:?}) is not a number", i + 1))
        })
    };
    let seeds = arg(0, 8.0) as u64;
    let actions = arg(1, 100.0) as u32;
    let noise_m = arg(2, 0.0);
    println!(
        "heuristic, {seeds} box poses per peg (seeds 1..={seeds}), {actions} actions, noise {noise_m} m\n"
    );
    println!(
        "| target | peg | completed | time to completion, s: median (range) | faults | peak contact force, N: median (range) |"
    );
    println!("|---|---|---|---|---|---|");
    let targets = [TrajectoryTarget::Accumulated, TrajectoryTarget::Measured];
    // One thread per target.
    let results: Vec<Vec<(PegShape, Vec<Trial>)>> = std::thread::scope(|s| {
        let handles: Vec<_> = targets
            .iter()
            .map(|&t| {
                s.spawn(move || {
                    PegShape::ALL
                        .iter()
                        .map(|&peg| {
                            let trials = (1..=seeds)
                                .map(|seed| trial(t, peg, seed, actions, noise_m))
                                .collect();
                            (peg, trials)
                        })
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("no panic"))
            .collect()
    });
    for (t, rows) in targets.iter().zip(&results) {
        let mut all: Vec<&Trial> = Vec::new();
        for (peg, trials) in rows {
            row(t.name(), peg.name(), &trials.iter().collect::<Vec<_>>());
            all.extend(trials);
        }
        row(t.name(), "**all**", &all);
    }
    for (t, rows) in targets.iter().zip(&results) {
        for (peg, trials) in rows {
            for (seed, tr) in (1..).zip(trials) {
                if let Some(f) = &tr.fault {
                    println!("{} {} seed {seed}: {f}", t.name(), peg.name());
                }
            }
        }
    }
}

fn row(target: &str, peg: &str, trials: &[&Trial]) {
    let done: Vec<f64> = trials.iter().filter_map(|t| t.completed_s).collect();
    println!(
        "| {target} | {peg} | {}/{} | {} | {} | {} |",
        done.len(),
        trials.len(),
        median_range(done.clone(), 2),
        trials.iter().filter(|t| t.fault.is_some()).count(),
        median_range(trials.iter().map(|t| t.peak_force_n).collect(), 0),
    );
}
