//! The FR3's position-dependent joint speed limits through the whole step:
//! the QP brakes a joint that nears its stop faster than the robot allows
//! there, and the supervisor faults before the robot's own reflex, where
//! the URDF's constant limits would allow both.

use robot_model::descriptions::{FR3_READY_Q, builtin};
use rt_controller::{
    Controller, ControllerConfig, FaultReason, Mode, RobotState, SpeedLimitSource, step,
};

fn config(source: SpeedLimitSource, fault_scale: f64) -> ControllerConfig {
    let mut c = ControllerConfig {
        ee_frame: "fr3_hand_tcp".into(),
        joint_speed_limits: source,
        ..ControllerConfig::default()
    };
    c.safety.velocity_fault_scale = fault_scale;
    c
}

/// One step of the FR3 at the ready pose but joint 0 at `q0` moving at
/// `v0`: the mode after it, joint 0's upper acceleration bound and the
/// fault, if any.
fn one_step(
    source: SpeedLimitSource,
    fault_scale: f64,
    q0: f64,
    v0: f64,
) -> (Mode, f64, Option<FaultReason>) {
    let model = builtin("fr3").unwrap();
    let ctrl = Controller::new(&model, config(source, fault_scale)).unwrap();
    let mut d = ctrl.create_data(&model);
    let mut q = FR3_READY_Q.to_vec();
    q[0] = q0;
    let mut v = vec![0.0; 7];
    v[0] = v0;
    let state = RobotState {
        q: &q,
        v: &v,
        tau_measured: None,
        wrench: None,
    };
    step(&model, &ctrl, &mut d, &state, None, 0.0);
    (d.mode(), d.acc_hi[0], d.supervisor.fault())
}

#[test]
fn near_its_stop_the_qp_brakes_a_joint_the_fr3_would_fault_and_the_urdf_would_not() {
    // At 2.5 rad the FR3 allows −0.30 + √(12·0.2501) − 0.001 = 1.431 rad/s
    // towards the stop (0.9 of it: 1.288), the URDF 2.62.
    let (mode, acc_hi, _) = one_step(SpeedLimitSource::Fr3, 1.2, 2.5, 1.5);
    assert_ne!(mode, Mode::Fault);
    assert!(acc_hi < -4.0, "must decelerate: {acc_hi}");
    let (mode, acc_hi, _) = one_step(SpeedLimitSource::Urdf, 1.2, 2.5, 1.5);
    assert_ne!(mode, Mode::Fault);
    assert!(
        acc_hi > 0.0,
        "the constant limit lets it speed up: {acc_hi}"
    );
}

#[test]
fn the_supervisor_faults_on_the_fr3_limit_at_the_joints_position() {
    // At 2.70 rad the FR3 allows 0.475 rad/s towards the stop: 1 rad/s is a
    // fault with its limits, well inside the URDF's 2.62 rad/s.
    let (mode, _, fault) = one_step(SpeedLimitSource::Fr3, 0.95, 2.70, 1.0);
    assert_eq!(mode, Mode::Fault);
    assert!(
        matches!(
            fault,
            Some(FaultReason::JointVelocityLimit { joint: 0, .. })
        ),
        "{fault:?}"
    );
    // Moving away from that stop at the same speed is fine, and so is a
    // joint at rest right at its stop (the robot's limit there is zero).
    assert_ne!(
        one_step(SpeedLimitSource::Fr3, 0.95, 2.70, -1.0).0,
        Mode::Fault
    );
    assert_ne!(
        one_step(SpeedLimitSource::Fr3, 0.95, 2.7437, 0.0).0,
        Mode::Fault
    );
    // With the URDF's limits the same state is no fault.
    assert_ne!(
        one_step(SpeedLimitSource::Urdf, 1.0, 2.70, 1.0).0,
        Mode::Fault
    );
}

#[test]
fn the_fr3_limits_on_another_robot_are_refused_by_name() {
    let mut c = config(SpeedLimitSource::Fr3, 1.0);
    c.ee_frame = "peg_tip".into();
    let panda = builtin("panda").unwrap();
    let e = Controller::new(&panda, c).unwrap_err().to_string();
    assert!(e.contains("joint_speed_limits"), "{e}");
    let toml = "ee_frame = \"fr3_hand_tcp\"\njoint_speed_limits = \"fr3\"\n";
    let c: ControllerConfig = toml::from_str(toml).unwrap();
    assert_eq!(c.joint_speed_limits, SpeedLimitSource::Fr3);
    assert!(toml::from_str::<ControllerConfig>("joint_speed_limits = \"fast\"").is_err());
}
