//! Peg-in-hole with the real controller core: a scripted 20 Hz action
//! sequence inserts the square peg; the same script against a hole moved by
//! 1 cm only touches the box; the peg never passes through the box.

mod common;

use common::{Rig, fixed_box_config, insertion_script, script};
use hw_sim::Stage;
use nalgebra::Vector3;

#[test]
fn scripted_insertion_completes_and_a_moved_hole_fails() {
    let mut rig = Rig::new(fixed_box_config([0.59, 0.0]));
    let hole = rig.world.hole_pose().unwrap();
    let actions = insertion_script(&rig, &hole);
    rig.run(&actions, 1.0);
    let task = *rig.world.task().unwrap();
    eprintln!("nominal: s = {:?}, stage {:?}", task.s_m, task.best_stage);
    assert_eq!(task.best_stage, Stage::Completed, "s = {:?}", task.s_m);
    assert!(task.s_m.x.abs() < 0.002 && task.s_m.y.abs() < 0.002);

    // The same actions, the box 1 cm away along y.
    let mut moved = Rig::new(fixed_box_config([0.59, 0.01]));
    moved.run(&actions, 1.0);
    let task = *moved.world.task().unwrap();
    eprintln!("moved: s = {:?}, stage {:?}", task.s_m, task.best_stage);
    assert_eq!(task.best_stage, Stage::Touched, "s = {:?}", task.s_m);
    assert!(
        task.s_m.z > -0.001,
        "the peg sank into the box: {:?}",
        task.s_m
    );
}

/// Slam the peg onto the box top, away from the hole, as fast as the
/// controller goes (its largest step every period), and press 10 cm
/// "through" it: the tip stays on the surface.
#[test]
fn the_peg_never_passes_through_the_box() {
    let mut rig = Rig::new(fixed_box_config([0.59, 0.05]));
    let hole = rig.world.hole_pose().unwrap();
    let start = rig.tip().translation.vector;
    let target = hole * nalgebra::Point3::new(0.0, -0.05, -0.1);
    let mut actions = script(
        start,
        &[(Vector3::new(start.x, start.y - 0.0, start.z), 0.01)],
    );
    actions.extend(script(start, &[(target.coords, 0.01)]));
    rig.run(&actions, 1.0);
    let task = *rig.world.task().unwrap();
    eprintln!(
        "slam: lowest tip height outside the hole {:.5} m, stage {:?}",
        rig.lowest_outside_hole_m, task.best_stage
    );
    assert_eq!(task.best_stage, Stage::Touched);
    assert!(
        rig.lowest_outside_hole_m > -0.001,
        "{}",
        rig.lowest_outside_hole_m
    );
}
