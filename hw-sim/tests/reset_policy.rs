//! A reset command's world configuration comes from any peer: its robot is
//! a built-in one or a file in the robot directory configured at start, and
//! it may tighten the torque clamp but never turn it off.

use hw_sim::WorldConfig;
use hw_sim::reset::{ResetError, ResetPolicy};
use robot_model::descriptions::{PANDA_URDF, RobotCatalog};

fn refusal(policy: &ResetPolicy, toml: &str) -> String {
    match policy.admit(toml.as_bytes(), 1) {
        Ok(_) => panic!("{toml:?} was admitted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_reset_names_no_file_outside_the_robot_directory() {
    let policy = ResetPolicy::new(WorldConfig::default(), RobotCatalog::builtin_only());
    for robot in ["/etc/passwd", "/dev/zero", "../../etc/shadow", "my.urdf"] {
        let e = refusal(&policy, &format!("robot = {robot:?}\n"));
        assert!(e.contains("no robot directory is configured"), "{e}");
    }
    let c = policy.admit(b"robot = \"panda\"\n", 7).unwrap();
    assert_eq!((c.robot.as_str(), c.seed), ("panda", 7));

    let scratch = test_support::scratch_dir("reset-robots");
    std::fs::write(scratch.path().join("arm.urdf"), PANDA_URDF).unwrap();
    let robots = RobotCatalog::with_dir(scratch.path()).unwrap();
    let policy = ResetPolicy::new(WorldConfig::default(), robots);
    let world = policy.world(b"robot = \"arm.urdf\"\n", 3).unwrap();
    assert_eq!(world.model().name, "panda");
    let e = refusal(&policy, "robot = \"/etc/passwd\"\n");
    assert!(e.contains("plain relative path"), "{e}");
}

#[test]
fn a_reset_may_tighten_the_torque_clamp_but_not_relax_it() {
    let policy = ResetPolicy::new(WorldConfig::default(), RobotCatalog::builtin_only());
    let e = refusal(&policy, "clamp_torques = false\n");
    assert!(e.contains("may not relax"), "{e}");
    assert!(matches!(
        policy.admit(b"clamp_torques = false\n", 1),
        Err(ResetError::Relaxes {
            field: "clamp_torques",
            ..
        })
    ));
    assert!(
        policy
            .admit(b"clamp_torques = true\n", 1)
            .unwrap()
            .clamp_torques
    );
    // Started without the clamp (a dynamics test bench): a reset may turn
    // it on, and may leave it off.
    let start = WorldConfig {
        clamp_torques: false,
        ..WorldConfig::default()
    };
    let policy = ResetPolicy::new(start, RobotCatalog::builtin_only());
    assert!(
        policy
            .admit(b"clamp_torques = true\n", 1)
            .unwrap()
            .clamp_torques
    );
    assert!(
        !policy
            .admit(b"clamp_torques = false\n", 1)
            .unwrap()
            .clamp_torques
    );
}

#[test]
fn a_reset_cannot_stall_the_simulator() {
    let policy = ResetPolicy::new(WorldConfig::default(), RobotCatalog::builtin_only());
    for (toml, field) in [
        ("solver_iterations = 1000000000\n", "solver_iterations"),
        (
            "[perturbations]\nrandom_pushes = 4000000000\n",
            "perturbations.random_pushes",
        ),
        (
            "[perturbations]\nrandom_occlusions = 4000000000\n",
            "perturbations.random_occlusions",
        ),
    ] {
        let e = match policy.world(toml.as_bytes(), 1) {
            Ok(_) => panic!("{toml:?} was built"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(field), "{e}");
    }
    let e = refusal(&policy, "robot = 3\n");
    assert!(e.contains("robot"), "{e}");
    assert!(matches!(
        policy.admit(&[0xff, 0xfe], 1),
        Err(ResetError::NotUtf8)
    ));
}
