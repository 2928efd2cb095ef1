//! The simulated arm against robot-model: initial poses, and joint
//! accelerations under torque against M⁻¹(τ − h).

use hw_sim::rng;
use hw_sim::{World, WorldConfig};
use nalgebra::DVector;

fn bare_arm(robot: &str, dt: f64) -> World {
    let config = WorldConfig {
        robot: robot.into(),
        dt_s: dt,
        joint_damping: vec![0.0],
        joint_friction: vec![0.0],
        clamp_torques: false,
        task: hw_sim::config::TaskConfig {
            enabled: false,
            ..Default::default()
        },
        ..Default::default()
    };
    World::new(config).expect("world builds")
}

#[test]
fn link_poses_match_forward_kinematics() {
    for robot in ["iiwa14", "panda"] {
        let mut world = bare_arm(robot, 1e-3);
        let model = world.model().clone();
        let mut data = model.create_data();
        let mut rng = rng::seeded(11, 0);
        for _ in 0..20 {
            let q: Vec<f64> = (0..7).map(|_| rng::uniform(&mut rng, -1.5, 1.5)).collect();
            world.set_joint_state(&q, &[0.0; 7]).unwrap();
            assert!(
                world.q().iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-12),
                "{robot}: q read back {:?} vs {:?}",
                world.q(),
                q
            );
            robot_model::forward_kinematics(&model, &mut data, &q);
            for j in 0..=7 {
                let expect = data.o_m_i[j].to_isometry().to_homogeneous();
                let got = world.link_pose(j).to_homogeneous();
                let err = (expect - got).amax();
                assert!(err < 1e-12, "{robot} body {j}: pose error {err:e}");
            }
        }
    }
}

/// rapier integrates the multibody semi-implicitly: its velocity update
/// solves (M + dt·(∂gyroscopic/∂v + damping)) Δv = dt·(τ − h), so its
/// acceleration differs from M⁻¹(τ − h) by a term of order dt·|∂h/∂v|·|a|.
/// Measured here at random states: the error shrinks in proportion to dt.
#[test]
fn joint_accelerations_match_model_dynamics() {
    for robot in ["iiwa14", "panda"] {
        let mut worst = Vec::new();
        for dt in [1e-3, 1e-4] {
            let mut world = bare_arm(robot, dt);
            let model = world.model().clone();
            let mut data = model.create_data();
            let effort = model.effort_limits();
            let mut rng = rng::seeded(5, 0);
            let mut max_rel: f64 = 0.0;
            for _ in 0..50 {
                let q: Vec<f64> = (0..7).map(|_| rng::uniform(&mut rng, -1.5, 1.5)).collect();
                let v: Vec<f64> = (0..7).map(|_| rng::uniform(&mut rng, -1.0, 1.0)).collect();
                let tau: Vec<f64> = (0..7)
                    .map(|k| rng::uniform(&mut rng, -0.3, 0.3) * effort[k])
                    .collect();
                world.set_joint_state(&q, &v).unwrap();
                world.step(&tau).unwrap();
                let a_sim: Vec<f64> = world
                    .v()
                    .iter()
                    .zip(&v)
                    .map(|(v1, v0)| (v1 - v0) / dt)
                    .collect();
                let a_model = robot_model::forward_dynamics(&model, &mut data, &q, &v, &tau)
                    .unwrap()
                    .clone();
                let diff = DVector::from_vec(a_sim.clone()) - &a_model;
                let rel = diff.norm() / a_model.norm().max(1.0);
                max_rel = max_rel.max(rel);
            }
            worst.push(max_rel);
        }
        eprintln!(
            "{robot}: max relative acceleration error dt=1e-3: {:.2e}, dt=1e-4: {:.2e}",
            worst[0], worst[1]
        );
        assert!(worst[0] < 0.02, "{robot}: {:.3e} at dt = 1 ms", worst[0]);
        assert!(
            worst[1] < 0.3 * worst[0],
            "{robot}: error does not shrink with dt: {worst:?}"
        );
    }
}
