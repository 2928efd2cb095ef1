//! The wrist F/T sensor: the peg's weight at rest in free space, and the
//! controller's force when pressing on the box.

mod common;

use common::{Rig, fixed_box_config, script};
use hw_sim::WorldConfig;
use nalgebra::{Point3, Vector3};

fn mean_wrench(rig: &mut Rig, cycles: usize) -> ([f64; 6], Vector3<f64>) {
    let mut sum = [0.0; 6];
    let mut f_cmd = Vector3::zeros();
    for k in 0..cycles {
        rig.cycle(if k % 50 == 0 {
            Some(&common::ZERO)
        } else {
            None
        });
        let w = rig.world.wrench_true();
        for i in 0..6 {
            sum[i] += w[i] / cycles as f64;
        }
        f_cmd += rig.data().osc.force.fixed_rows::<3>(0).into_owned() / cycles as f64;
    }
    (sum, f_cmd)
}

#[test]
fn at_rest_in_free_space_it_reads_the_pegs_weight() {
    let mut rig = Rig::new(WorldConfig::default());
    rig.run(&[], 2.0);
    let (w, _) = mean_wrench(&mut rig, 200);
    let peg = rig.world.peg().unwrap().clone();
    let link = rig.world.link_pose(peg.link);
    let sensor = link * peg.sensor_in_link;
    let g_sensor = sensor.rotation.inverse() * Vector3::new(0.0, 0.0, -9.81 * peg.mass_kg);
    let m_sensor = peg.com_sensor.cross(&g_sensor);
    eprintln!(
        "peg {:.4} kg; reading {w:?}; expected {g_sensor:?} {m_sensor:?}",
        peg.mass_kg
    );
    for i in 0..3 {
        assert!(
            (w[i] - g_sensor[i]).abs() < 2e-3 * 9.81 * peg.mass_kg + 1e-4,
            "force {i}: {w:?}"
        );
        assert!((w[3 + i] - m_sensor[i]).abs() < 1e-4, "moment {i}: {w:?}");
    }
}

#[test]
fn pressing_on_the_box_reads_the_controllers_force() {
    let mut rig = Rig::new(fixed_box_config([0.59, 0.05]));
    let hole = rig.world.hole_pose().unwrap();
    let start = rig.tip().translation.vector;
    // Onto the top face 5 cm beside the hole (slowly for the last 2 cm, as
    // a careful operator would), then 1 cm "into" it.
    let above = hole * Point3::new(0.0, -0.05, 0.02);
    let into = hole * Point3::new(0.0, -0.05, -0.01);
    let actions = script(start, &[(above.coords, 0.005), (into.coords, 0.001)]);
    rig.run(&actions, 1.5);
    assert!(rig.world.task().unwrap().in_contact);
    let (w, f_cmd) = mean_wrench(&mut rig, 500);
    let peg = rig.world.peg().unwrap().clone();
    let sensor = rig.world.link_pose(peg.link) * peg.sensor_in_link;
    let f_world = sensor.rotation * Vector3::new(w[0], w[1], w[2]);
    eprintln!("F/T force (base frame) {f_world:?}; controller force {f_cmd:?}");
    // At rest the flange balances what the peg exerts on it with the
    // controller's task force: W = −f (see docs/hw-sim.md).
    assert!(f_cmd.z < -2.0, "the controller is not pressing: {f_cmd:?}");
    let err = (f_world + f_cmd).norm();
    assert!(
        err < 0.02 * f_cmd.norm() + 0.05,
        "F/T {f_world:?} vs −f {:?}",
        -f_cmd
    );
}
