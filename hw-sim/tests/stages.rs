//! The task's stages are the ground truth that policies are scored (and RL
//! rewarded) on, so a policy must not reach them by a shortcut: a peg pushed
//! down beside the box, to the floor, is never inserted or completed, while
//! one pushed down the hole completes, for all four pegs.

mod common;

use common::{Rig, fixed_box_config, insertion_script, script};
use hw_sim::{PegShape, Stage, WorldConfig};
use nalgebra::Vector3;

fn config(peg: PegShape) -> WorldConfig {
    let mut c = fixed_box_config([0.59, 0.0]);
    c.task.peg = peg;
    c
}

/// Where each peg goes down, from the hole's centre in the base x-y plane,
/// m: towards the robot, to either side, and diagonally. The box's corners
/// are 11.3 cm from the centre, the pegs' within 2.2 cm of the tip and the
/// last link's surface within 4.5 cm of it: 15 cm or more keeps peg and arm
/// beside the box at any yaw (the peg touching its side would be allowed,
/// as "touched").
const BESIDE: [(PegShape, [f64; 2]); 4] = [
    (PegShape::Square, [-0.15, 0.0]),
    (PegShape::Triangle, [0.0, 0.16]),
    (PegShape::Semicircle, [0.0, -0.16]),
    (PegShape::Hexagon, [-0.12, 0.12]),
];

/// Beside the box at the start height, then straight down to z = 0, the
/// floor and the lowest height the controller's workspace allows. The tip
/// ends 10 cm below the box's top face, lower than the hole's bottom: by
/// its height alone it would read "completed".
#[test]
fn a_peg_pushed_down_beside_the_box_is_never_inserted() {
    for (peg, offset) in BESIDE {
        let mut rig = Rig::new(config(peg));
        let hole = rig.world.hole_pose().unwrap().translation.vector;
        let height = rig.world.box_geometry().unwrap().height;
        let start = rig.tip().translation.vector;
        let (x, y) = (hole.x + offset[0], hole.y + offset[1]);
        let actions = script(
            start,
            &[
                (Vector3::new(x, y, start.z), 0.01),
                (Vector3::new(x, y, 0.0), 0.005),
            ],
        );
        rig.run(&actions, 1.0);
        let task = *rig.world.task().unwrap();
        // `lowest_outside_hole_m`: the tip's lowest height relative to the
        // top face while well outside the hole (all of this descent).
        let lowest = rig.lowest_outside_hole_m;
        eprintln!(
            "{peg:?} beside the box: lowest tip height {lowest:.4} m (top face 0), \
             end s = {:?}, best stage {:?}",
            task.s_m, task.best_stage
        );
        assert!(
            lowest < -(height - 0.01),
            "{peg:?}: the tip did not reach the floor ({lowest} m): the test proves nothing"
        );
        assert!(
            task.best_stage <= Stage::Touched,
            "{peg:?}: a peg beside the box reached {:?} (s = {:?})",
            task.best_stage,
            task.s_m
        );
        assert!(!task.in_hole, "{peg:?}: s = {:?}", task.s_m);
    }
}

/// The same pegs pushed down the hole (the insertion script of
/// `insertion.rs`) complete.
#[test]
fn a_peg_pushed_down_the_hole_completes() {
    for peg in PegShape::ALL {
        let mut rig = Rig::new(config(peg));
        let hole = rig.world.hole_pose().unwrap();
        let actions = insertion_script(&rig, &hole);
        rig.run(&actions, 1.0);
        let task = *rig.world.task().unwrap();
        eprintln!(
            "{peg:?} down the hole: s = {:?}, best stage {:?}",
            task.s_m, task.best_stage
        );
        assert_eq!(
            task.best_stage,
            Stage::Completed,
            "{peg:?}: s = {:?}",
            task.s_m
        );
        assert!(task.in_hole, "{peg:?}: s = {:?}", task.s_m);
        assert!(
            task.s_m.x.abs() < 0.002 && task.s_m.y.abs() < 0.002,
            "{peg:?}: s = {:?}",
            task.s_m
        );
    }
}
