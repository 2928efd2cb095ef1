//! hw-sim throughput on one core:
//! - physics: simulated seconds per wall second, with the peg inside the
//!   hole pressed against its walls and bottom (contacts active), alone and
//!   with rt-controller's step in the loop;
//! - camera: one 128×128 RGB-D frame with its flow.
//!
//! `cargo bench -p hw-sim --bench sim` prints the tables; it asserts no
//! timing, only that the scene measured is the one described (the peg at
//! the bottom of its hole and touching the box, the controller running).
//! `cargo test -p hw-sim --bench sim`, or `-- --test` after `cargo bench`
//! (criterion's convention: a run without `--bench`), is the quick mode that
//! scripts/test.sh runs: every table and check once, with few repetitions.

use hw_sim::{CameraFrame, PegShape, Stage, WorldConfig};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use std::time::Instant;

#[path = "../tests/common/mod.rs"]
mod common;
use common::{Action, Rig as Loop, ZERO};

/// The world of `peg` with its box fixed under the initial pose.
fn fixed_box(peg: PegShape) -> Loop {
    let mut config = WorldConfig::default();
    config.task.peg = peg;
    config.task.box_xy_range_m = [0.0, 0.0];
    config.task.box_yaw_range_rad = 0.0;
    Loop::new(config)
}

/// The scripted 20 Hz action toward the bottom of the hole: while above the
/// box, over the hole and rolled into line first; then down, slowing
/// towards the bottom (a rigid bottom met at 0.1 m/s is a force spike that
/// trips the controller's force limit), to a goal 2 mm below it; once
/// within 3 mm of the bottom and touching the box it stops, and the peg
/// keeps pressing with the force reached.
fn toward_bottom(l: &Loop) -> Action {
    let hole = l.world.hole_pose().unwrap();
    let depth = l.world.box_geometry().unwrap().depth;
    let tip = l.world.peg_tip_pose().translation.vector;
    let goal = hole * nalgebra::Point3::new(0.0, 0.0, -depth - 0.002);
    let mut d = goal.coords - tip;
    // The triangle and semicircle holes are not symmetric under the
    // initial roll.
    let psi = l.world.task().unwrap().s_psi_rad;
    let above = l.world.task().unwrap().s_m.z > 0.0;
    if above && ((tip.xy() - goal.coords.xy()).norm() > 0.002 || psi.abs() > 0.01) {
        d.z = (hole.translation.z + 0.02 - tip.z).max(-0.005);
    }
    // At the bottom, stop: the tip cannot follow, and further steps would
    // only wind the reference (and the pressing force) up. Only once it
    // touches: since the arm's home pose points the peg straight down, the
    // peg no longer wedges against the walls on the way, and stopping 3 mm
    // short of the bottom left it hanging free in the hole, "completed" with
    // no contact to measure.
    let task = l.world.task().unwrap();
    if task.s_m.z < -(depth - 0.003) && task.in_contact {
        d = nalgebra::Vector3::zeros();
    }
    let step = (0.25 * d.norm()).clamp(0.0005, 0.005);
    let n = d.norm();
    if n > step {
        d *= step / n;
    }
    [d.x, d.y, d.z, (-psi).clamp(-0.05, 0.05)]
}

/// Drives the peg to the bottom of its hole with 20 Hz actions.
fn inserted(peg: PegShape) -> Loop {
    let mut l = fixed_box(peg);
    for k in 0..10_000u64 {
        let action = (k % ACTION_PERIOD_STEPS == 0).then(|| toward_bottom(&l));
        l.cycle(action.as_ref());
    }
    l
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Repetitions of each measurement: the full bench's, or the quick mode's.
struct Reps {
    /// Timed runs of 1000 physics steps (and of 1000 controlled ones).
    runs: usize,
    /// Frames rendered per peg.
    frames: usize,
    /// Episodes per peg.
    episodes: usize,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--test") || !args.iter().any(|a| a == "--bench");
    let reps = if quick {
        Reps {
            runs: 1,
            frames: 10,
            episodes: 1,
        }
    } else {
        Reps {
            runs: 5,
            frames: 200,
            episodes: 3,
        }
    };
    if quick {
        println!("quick mode (a check that the bench runs; its figures are not the bench's)");
    }
    println!("| peg | stage | physics only (sim s / wall s) | with controller (sim s / wall s) |");
    println!("|---|---|---|---|");
    for peg in PegShape::ALL {
        let mut l = inserted(peg);
        let stage = l.world.task().unwrap().best_stage;
        let tau = l.data().torques().to_vec();
        let mut physics = Vec::new();
        let mut full = Vec::new();
        for _ in 0..reps.runs {
            let t0 = Instant::now();
            for _ in 0..1000 {
                l.world.step(&tau).unwrap();
            }
            physics.push(1.0 / t0.elapsed().as_secs_f64());
            let t0 = Instant::now();
            for k in 0..1000 {
                l.cycle((k % ACTION_PERIOD_STEPS == 0).then_some(&ZERO));
            }
            full.push(1.0 / t0.elapsed().as_secs_f64());
        }
        assert_eq!(
            stage,
            Stage::Completed,
            "{peg:?}: the script did not reach the bottom"
        );
        assert!(
            l.world.task().unwrap().in_contact,
            "{peg:?}: at the bottom but not touching the box: no contact to measure"
        );
        // The controller must still be running: a faulted one only holds
        // gravity, and the contact would not be the pressing one measured.
        assert_eq!(l.data().last.mode, rt_controller::Mode::Running, "{peg:?}");
        println!(
            "| {} | {} (in contact: {}) | {:.1} | {:.1} |",
            peg.name(),
            stage.name(),
            l.world.task().unwrap().in_contact,
            median(physics),
            median(full)
        );
    }

    println!();
    println!("| peg | render 128×128 RGB-D + flow, median | p90 |");
    println!("|---|---|---|");
    for peg in PegShape::ALL {
        let mut l = inserted(peg);
        let mut frame = CameraFrame::default();
        l.world.render(&mut frame);
        let mut times = Vec::new();
        for _ in 0..reps.frames {
            l.cycle(None);
            let t0 = Instant::now();
            l.world.render(&mut frame);
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        println!(
            "| {} | {:.3} ms | {:.3} ms |",
            peg.name(),
            times[times.len() / 2],
            times[times.len() * 9 / 10]
        );
    }

    println!();
    println!(
        "| peg | 500-step episode: hw-sim (physics + 500 frames), wall s | with rt-controller's step, wall s | stage |"
    );
    println!("|---|---|---|---|");
    for peg in PegShape::ALL {
        let (mut sim, mut total) = (Vec::new(), Vec::new());
        let mut stage = Stage::Failed;
        for _ in 0..reps.episodes {
            let mut l = fixed_box(peg);
            let mut frame = CameraFrame::default();
            let mut in_sim = std::time::Duration::ZERO;
            let t0 = Instant::now();
            for _ in 0..500 {
                let a = toward_bottom(&l);
                for k in 0..ACTION_PERIOD_STEPS {
                    l.control((k == 0).then_some(&a));
                    let t1 = Instant::now();
                    l.apply();
                    if l.world.camera_due() {
                        l.world.render(&mut frame);
                    }
                    in_sim += t1.elapsed();
                }
            }
            total.push(t0.elapsed().as_secs_f64());
            sim.push(in_sim.as_secs_f64());
            stage = l.world.task().unwrap().best_stage;
            assert_eq!(l.data().last.mode, rt_controller::Mode::Running, "{peg:?}");
        }
        println!(
            "| {} | {:.3} | {:.3} | {} |",
            peg.name(),
            median(sim),
            median(total),
            stage.name()
        );
    }
}
