//! The safety supervisor through the whole step: garbage actions, action
//! time-outs, faults and their safe command.

mod common;

use common::{Bench, PANDA_READY, action, panda};
use rt_controller::{
    ActionStatus, ControllerConfig, FaultReason, Mode, Rejection, RobotState, step,
};
use test_support::{Rng, RngExt, Uniform};

#[test]
fn garbage_actions_are_counted_and_the_target_holds() {
    let mut b = Bench::new(panda(), ControllerConfig::default(), &PANDA_READY);
    b.cycle(Some(&action(0.005, 0.0, 0.0, 0.0)));
    let target = b.data.trajectory.target();
    for a in [
        action(f64::NAN, 0.0, 0.0, 0.0),
        action(0.0, f64::NEG_INFINITY, 0.0, 0.0),
        action(0.0, 0.0, 0.5, 0.0),
        action(0.0, 0.0, 0.0, 3.0),
    ] {
        let info = b.cycle(Some(&a));
        assert!(matches!(info.action, ActionStatus::Rejected(_)), "{info:?}");
        assert_eq!(b.data.trajectory.target(), target);
    }
    assert_eq!(b.data.supervisor.counters.actions_rejected, 4);
    let info = b.cycle(Some(&action(-0.0, 0.0, f64::MIN_POSITIVE / 2.0, 0.0)));
    assert_eq!(
        info.action,
        ActionStatus::Applied,
        "−0 and denormals are fine"
    );
    let info = b.cycle(Some(&action(0.05, 0.0, 0.0, 0.0)));
    assert_eq!(info.action, ActionStatus::Clamped);
    assert_eq!(
        rt_controller::supervisor::Supervisor::check_action(
            &ControllerConfig::default().safety,
            &[f64::NAN; 4]
        ),
        Err(Rejection::NonFinite)
    );
}

#[test]
fn ten_thousand_random_and_malformed_actions_never_exceed_the_limits() {
    let mut b = Bench::new(panda(), ControllerConfig::default(), &PANDA_READY);
    let mut rng = test_support::rng(99);
    let specials = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        f64::MIN_POSITIVE / 3.0,
        1e308,
        -1e-320,
        0.1,
        -0.01,
    ];
    for k in 0..10_000 {
        let pick = |r: &mut Rng| {
            if r.uniform(0.0, 1.0) < 0.3 {
                specials[r.random_range(0..specials.len())]
            } else {
                r.uniform(-0.012, 0.012)
            }
        };
        let a = action(
            pick(&mut rng),
            pick(&mut rng),
            pick(&mut rng),
            pick(&mut rng),
        );
        // One action per cycle: far more often than any policy would.
        b.cycle(Some(&a));
        assert_ne!(
            b.data.mode(),
            Mode::Fault,
            "cycle {k}: {:?}",
            b.data.supervisor.fault()
        );
    }
    b.assert_within_limits();
    let c = b.data.supervisor.counters;
    assert!(
        c.actions_rejected > 1000 && c.actions_accepted > 1000,
        "{c:?}"
    );
}

#[test]
fn a_silent_policy_makes_the_controller_hold_and_a_fresh_action_resumes() {
    let mut b = Bench::new(panda(), ControllerConfig::default(), &PANDA_READY);
    b.run(0.5, 50, |_| Some(action(0.004, 0.0, 0.0, 0.0)));
    assert_eq!(b.data.mode(), Mode::Running);
    let target = b.data.trajectory.target();
    // The last action came at t = 0.45 s; the hold comes 100 ms later.
    let mut held_at = None;
    for _ in 0..300 {
        let info = b.cycle(None);
        if info.mode == Mode::Holding && held_at.is_none() {
            held_at = Some(b.t);
        }
    }
    let held_at = held_at.expect("holds");
    assert!((held_at - 0.551).abs() < 0.0015, "held at {held_at}");
    assert_eq!(b.data.trajectory.target(), target);
    let p = b.data.ee.pos;
    assert!((p.x - target[0]).abs() < 3e-4, "rests at its last target");
    b.cycle(Some(&action(0.0, 0.004, 0.0, 0.0)));
    assert_eq!(b.data.mode(), Mode::Running);
    // A requested hold (shutdown) ignores actions until released.
    b.data.supervisor.request_hold(b.t);
    let info = b.cycle(Some(&action(0.0, 0.004, 0.0, 0.0)));
    assert_eq!(
        (info.mode, info.action),
        (Mode::Holding, ActionStatus::Ignored)
    );
    b.data.supervisor.release_hold();
    assert_eq!(
        b.cycle(Some(&action(0.0, 0.004, 0.0, 0.0))).mode,
        Mode::Running
    );
}

/// Runs one good step, then one with the bad state; checks the safe command
/// and the latch, resets, and returns the fault's reason.
fn fault_with(q: &[f64], v: &[f64], wrench: Option<&[f64; 6]>) -> FaultReason {
    let model = panda();
    let ctrl = rt_controller::Controller::new(&model, ControllerConfig::default()).unwrap();
    let mut d = ctrl.create_data(&model);
    let zero = [0.0; 7];
    let ok = RobotState {
        q: &PANDA_READY,
        v: &zero,
        tau_measured: None,
        wrench: None,
    };
    step(&model, &ctrl, &mut d, &ok, None, 0.0);
    let before = d.torques().to_vec();
    let bad = RobotState {
        q,
        v,
        tau_measured: None,
        wrench,
    };
    let info = step(
        &model,
        &ctrl,
        &mut d,
        &bad,
        Some(&action(0.001, 0.0, 0.0, 0.0)),
        0.001,
    );
    assert_eq!(info.mode, Mode::Fault);
    assert_eq!(info.action, ActionStatus::Ignored);
    let reason = d.supervisor.fault().expect("a reason");
    let limits = model.effort_limits();
    for (i, t) in d.torques().iter().enumerate() {
        assert!(t.is_finite() && t.abs() <= limits[i]);
        assert!(
            (t - before[i]).abs() <= 1.0 + 1e-9,
            "the rate limit holds in Fault"
        );
    }
    // Latched until reset; a reset returns to Idle, holding the pose it sees.
    assert_eq!(
        step(&model, &ctrl, &mut d, &ok, None, 0.002).mode,
        Mode::Fault
    );
    d.reset(0.003);
    assert_eq!(
        step(&model, &ctrl, &mut d, &ok, None, 0.004).mode,
        Mode::Idle
    );
    assert_eq!(d.supervisor.counters.faults, 1);
    reason
}

#[test]
fn faults_latch_with_their_reason_and_command_finite_limited_torques() {
    let zero = [0.0; 7];
    let mut q = PANDA_READY;
    q[2] = f64::NAN;
    assert_eq!(fault_with(&q, &zero, None), FaultReason::NonFiniteState);
    let mut q = PANDA_READY;
    q[3] = -3.2; // panda_joint4 limit −3.0718
    assert!(matches!(
        fault_with(&q, &zero, None),
        FaultReason::JointPositionLimit { joint: 3, .. }
    ));
    let mut v = zero;
    v[6] = 4.0; // limit 2.61 rad/s
    assert!(matches!(
        fault_with(&PANDA_READY, &v, None),
        FaultReason::JointVelocityLimit { joint: 6, .. }
    ));
    let push = [0.0, 0.0, 150.0, 0.0, 0.0, 0.0];
    assert!(matches!(
        fault_with(&PANDA_READY, &zero, Some(&push)),
        FaultReason::ForceOverload { .. }
    ));
    let twist = [0.0, 0.0, 0.0, 20.0, 0.0, 0.0];
    assert!(matches!(
        fault_with(&PANDA_READY, &zero, Some(&twist)),
        FaultReason::MomentOverload { .. }
    ));
    let bad_wrench = [0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        fault_with(&PANDA_READY, &zero, Some(&bad_wrench)),
        FaultReason::NonFiniteState
    );
}

#[test]
fn bad_configuration_names_the_field() {
    let model = panda();
    let mut c = ControllerConfig::default();
    c.impedance.kp[2] = f64::NAN;
    let e = rt_controller::Controller::new(&model, c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("impedance.kp[2]"), "{e}");
    let c = ControllerConfig {
        ee_frame: "no_such_frame".into(),
        ..Default::default()
    };
    let e = rt_controller::Controller::new(&model, c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no_such_frame"), "{e}");
    let mut c = ControllerConfig::default();
    c.osc.rest_q = Some(vec![0.0; 6]);
    let e = rt_controller::Controller::new(&model, c)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("osc.rest_q") && e.contains('6') && e.contains('7'),
        "{e}"
    );
    let mut c = ControllerConfig::default();
    c.trajectory.workspace_min_m[1] = 1.0;
    let e = rt_controller::Controller::new(&model, c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("workspace_min_m[1]"), "{e}");
}

/// A URDF joint whose velocity limit is zero or absent reads as unlimited
/// (robot-model), so the velocity fault could never fire: the controller
/// refuses the robot, naming the joint.
#[test]
fn a_joint_without_a_finite_velocity_limit_is_refused_by_name() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../robot-model/urdf/panda.urdf"
    );
    let urdf = std::fs::read_to_string(path).unwrap();
    let limit = r#"<limit lower="-1.7628" upper="1.7628" velocity="2.175" effort="87"/>"#;
    assert_eq!(urdf.matches(limit).count(), 1, "panda_joint2's limit");
    // An absent velocity attribute: urdf-rs's parser refuses the file, and
    // the error names the joint.
    let absent = r#"<limit lower="-1.7628" upper="1.7628" effort="87"/>"#;
    let e = robot_model::Model::from_urdf_str(&urdf.replace(limit, absent), &Default::default())
        .expect_err("a <limit> without velocity was accepted")
        .to_string();
    assert!(
        e.contains("joint `panda_joint2`: <limit> has no `velocity` attribute"),
        "{e}"
    );
    // A zero velocity limit: robot-model reads it as unlimited; the
    // controller must refuse it.
    let edited = r#"<limit lower="-1.7628" upper="1.7628" velocity="0" effort="87"/>"#;
    let model = robot_model::Model::from_urdf_str(
        &urdf.replace(limit, edited),
        &robot_model::LoadOptions::default(),
    )
    .expect("robot-model accepts it (as unlimited)");
    assert_eq!(model.velocity_limits()[1], f64::INFINITY);
    let e = rt_controller::Controller::new(&model, ControllerConfig::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("panda_joint2") && e.contains("velocity limit"),
        "{edited}: {e}"
    );
    // The unedited robot is accepted.
    let model = robot_model::Model::from_urdf_str(&urdf, &Default::default()).unwrap();
    rt_controller::Controller::new(&model, ControllerConfig::default()).unwrap();
}

/// The first state of an episode with NaN measured torques and a joint so
/// far past its speed limit that `h(q, v)` overflows: the rate limiter must
/// not start from a non-finite `h` (its box became NaN and `f64::clamp`
/// panicked in the safe command).
#[test]
fn a_first_state_with_nan_torques_and_a_runaway_joint_faults_without_panicking() {
    let model = panda();
    let ctrl = rt_controller::Controller::new(&model, ControllerConfig::default()).unwrap();
    let limits = model.effort_limits();
    let nan = [f64::NAN; 7];
    for speed in [1e155, 1e200, f64::MAX, -f64::MAX] {
        for joint in [0, 3, 6] {
            let mut d = ctrl.create_data(&model);
            let mut v = [0.0; 7];
            v[joint] = speed;
            let mut q = PANDA_READY;
            q[(joint + 1) % 7] = 100.0; // and another joint out of its range
            let state = RobotState {
                q: &q,
                v: &v,
                tau_measured: Some(&nan),
                wrench: None,
            };
            let info = step(&model, &ctrl, &mut d, &state, None, 0.0);
            assert_eq!(info.mode, Mode::Fault);
            assert!(
                matches!(
                    d.supervisor.fault(),
                    Some(
                        FaultReason::JointPositionLimit { .. }
                            | FaultReason::JointVelocityLimit { .. }
                    )
                ),
                "the state's reason is kept: {:?}",
                d.supervisor.fault()
            );
            // With neither the measured torques nor h usable, the rate
            // limiter starts from the gravity torque at this pose.
            let mut rm = model.create_data();
            let g = robot_model::gravity(&model, &mut rm, &q).clone();
            let first = d.torques().to_vec();
            for (i, t) in first.iter().enumerate() {
                assert!(
                    t.is_finite() && t.abs() <= limits[i],
                    "{speed} {joint}: {first:?}"
                );
                assert!(
                    (t - g[i]).abs() <= 1.0 + 1e-9,
                    "{speed} {joint}: {first:?} vs {g}"
                );
            }
            // The next command stays within the rate limit of this one.
            let zero = [0.0; 7];
            let calm = RobotState {
                q: &PANDA_READY,
                v: &zero,
                tau_measured: None,
                wrench: None,
            };
            step(&model, &ctrl, &mut d, &calm, None, 0.001);
            for (i, t) in d.torques().iter().enumerate() {
                assert!(t.is_finite() && (t - first[i]).abs() <= 1.0 + 1e-9);
            }
        }
    }
}

/// An eigen-decomposition of `Λ⁻¹` that does not converge within its cap
/// (nalgebra's uncapped one can loop forever) is a dynamics failure: Fault,
/// finite torques within the limits and the rate limit.
#[test]
fn an_eigen_decomposition_out_of_iterations_is_a_dynamics_failure() {
    let model = panda();
    let mut config = ControllerConfig::default();
    config.osc.eigen_max_iter = 1;
    let ctrl = rt_controller::Controller::new(&model, config).unwrap();
    let mut d = ctrl.create_data(&model);
    let zero = [0.0; 7];
    let state = RobotState {
        q: &PANDA_READY,
        v: &zero,
        tau_measured: None,
        wrench: None,
    };
    let info = step(&model, &ctrl, &mut d, &state, None, 0.0);
    assert_eq!(info.mode, Mode::Fault);
    assert_eq!(d.supervisor.fault(), Some(FaultReason::DynamicsFailure));
    let limits = model.effort_limits();
    let mut before = d.torques().to_vec();
    for k in 1..50 {
        step(&model, &ctrl, &mut d, &state, None, k as f64 * 0.001);
        for (i, t) in d.torques().iter().enumerate() {
            assert!(t.is_finite() && t.abs() <= limits[i]);
            assert!((t - before[i]).abs() <= 1.0 + 1e-9);
        }
        before = d.torques().to_vec();
    }
    // Gravity compensation in Fault: the held arm's torques are h(q, 0).
    let mut rm = model.create_data();
    let g = robot_model::gravity(&model, &mut rm, &PANDA_READY).clone();
    for (t, g) in d.torques().iter().zip(g.iter()) {
        assert!((t - g).abs() < 1e-6, "{t} vs {g}");
    }
    let cfg = ControllerConfig::default();
    assert_eq!(cfg.osc.eigen_max_iter, 180);
    let mut bad = cfg.clone();
    bad.osc.eigen_max_iter = 0;
    let e = rt_controller::Controller::new(&model, bad)
        .unwrap_err()
        .to_string();
    assert!(e.contains("osc.eigen_max_iter"), "{e}");
}

/// The Fault damping is bounded per joint by its inertia: the discrete
/// closed loop `v ← (I − h M⁻¹ D) v` has every eigenvalue of `h M⁻¹ D` below
/// 1 (monotone decay, no chatter) on both robots, over random poses. With
/// the plain 5 N·m·s/rad it is far above 2 (unstable) on the iiwa's wrist.
#[test]
fn the_fault_damping_decays_monotonically_at_the_control_period() {
    use nalgebra::{DMatrix, SymmetricEigen};
    let mut rng = test_support::rng(16);
    for model in [panda(), common::iiwa()] {
        let nv = model.nv();
        let ctrl = rt_controller::Controller::new(&model, ControllerConfig::default()).unwrap();
        let h = ctrl.config().period_s;
        let (lo, hi) = (model.lower_limits(), model.upper_limits());
        let mut data = model.create_data();
        let mut worst_bounded: f64 = 0.0;
        let mut worst_plain: f64 = 0.0;
        for _ in 0..200 {
            let q: Vec<f64> = (0..nv).map(|i| rng.uniform(lo[i], hi[i])).collect();
            let m = robot_model::crba(&model, &mut data, &q).clone();
            let minv = m.clone().try_inverse().unwrap();
            // Eigenvalues of h M⁻¹ D are those of h D^½ M⁻¹ D^½ (symmetric).
            let lambda_max = |d: &[f64]| {
                let s = DMatrix::from_fn(nv, nv, |i, j| h * (d[i] * d[j]).sqrt() * minv[(i, j)]);
                SymmetricEigen::new(s).eigenvalues.max()
            };
            let bounded: Vec<f64> = (0..nv)
                .map(|i| rt_controller::fault_damping(&ctrl, &m, i))
                .collect();
            let plain = vec![ctrl.config().safety.fault_damping_nms; nv];
            worst_bounded = worst_bounded.max(lambda_max(&bounded));
            worst_plain = worst_plain.max(lambda_max(&plain));
        }
        assert!(
            worst_bounded < 1.0,
            "bounded damping: largest eigenvalue of h M⁻¹ D = {worst_bounded}"
        );
        eprintln!("eigenvalue of h M⁻¹ D: bounded {worst_bounded:.3}, plain {worst_plain:.3}");
    }
}
