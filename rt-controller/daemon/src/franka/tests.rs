//! franky-sim never raises a robot error (docs/franka.md), so the path
//! from the robot's error to the daemon's Fault is checked here on
//! errors built as franka-rs builds them.
use super::*;
use crate::config::{Clock, DaemonConfig};
use crate::{Daemon, FAULT_ROBOT_LIMIT};
use franka::{ControlException, Errors, MoveStatus};
use robot_model::descriptions::{FR3_READY_Q, builtin};
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerMode, ControllerStatus};

fn aborted(errors: &[&str], status: MoveStatus) -> FrankaError {
    let mut e = ControlException::new(format!(
        "libfranka: Move command aborted: motion aborted by reflex! [{}]",
        errors.join(", ")
    ));
    e.move_status = Some(status);
    let mut flags = Errors::default();
    for name in errors {
        flags.0[Errors::index_of(name).unwrap()] = true;
    }
    e.last_motion_errors = flags;
    FrankaError::Control(e)
}

#[test]
fn robot_errors_map_to_fault_codes_with_the_robots_reason() {
    let r = MoveStatus::ReflexAborted;
    for (errors, code) in [
        (
            &["communication_constraints_violation"][..],
            FAULT_ROBOT_COMMUNICATION,
        ),
        (&["joint_position_limits_violation"], FAULT_ROBOT_LIMIT),
        (&["joint_velocity_violation"], FAULT_ROBOT_LIMIT),
        (&["tau_J_range_violation"], FAULT_ROBOT_LIMIT),
        (&["controller_torque_discontinuity"], FAULT_ROBOT_LIMIT),
        (&["cartesian_reflex"], FAULT_ROBOT_REFLEX),
        (
            &["joint_reflex", "power_limit_violation"],
            FAULT_ROBOT_LIMIT,
        ),
        (&[], FAULT_ROBOT_REFLEX),
    ] {
        let e = aborted(errors, r);
        assert_eq!(robot_fault_code(&e), code, "{errors:?}");
        let HardwareError::Robot { reason, .. } = robot_error(&e, "reading the robot state") else {
            unreachable!()
        };
        assert!(reason.starts_with("reading the robot state: libfranka: Move command aborted"));
        for name in errors {
            assert!(reason.contains(name), "{reason}");
        }
    }
    let user_stop = aborted(&[], MoveStatus::EmergencyAborted);
    assert_eq!(robot_fault_code(&user_stop), FAULT_ROBOT_OTHER);
    let lost = FrankaError::Network("libfranka: UDP receive: Timeout".into());
    assert_eq!(robot_fault_code(&lost), FAULT_ROBOT_OTHER);
    assert!(
        robot_error(&lost, "reading the robot state")
            .to_string()
            .contains("UDP receive: Timeout")
    );
}

/// States of an FR3 at rest, then the robot's error.
struct FailingRobot {
    state: HardwareState,
    polls: u64,
    fail_at: u64,
    sent: u64,
    finished: bool,
}

impl Hardware for FailingRobot {
    fn name(&self) -> &'static str {
        "failing"
    }
    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError> {
        self.polls += 1;
        if self.polls >= self.fail_at {
            let e = aborted(
                &["joint_position_limits_violation"],
                MoveStatus::ReflexAborted,
            );
            return Err(robot_error(&e, "reading the robot state"));
        }
        self.state.header.seq = self.polls;
        self.state.step = self.polls;
        self.state.header.t_hw_ns = self.polls * 1_000_000;
        Ok(Some(&self.state))
    }
    fn send(&mut self, _: &TorqueCommand) -> Result<(), HardwareError> {
        self.sent += 1;
        Ok(())
    }
    fn finish(&mut self) -> Result<(), HardwareError> {
        self.finished = true;
        Ok(())
    }
}

#[test]
fn a_robot_error_becomes_the_daemons_published_fault() {
    transport::quiet_logs();
    let ns = format!("franka-fault-{}", std::process::id());
    let mut cfg = DaemonConfig {
        robot: "fr3".into(),
        ..DaemonConfig::default()
    };
    cfg.controller.ee_frame = "fr3_hand_tcp".into();
    cfg.backend.namespace = ns.clone();
    cfg.timing.clock = Clock::Hardware;
    cfg.realtime.enabled = false;
    let model = builtin("fr3").unwrap();
    let mut state = HardwareState::empty(7);
    state.header.episode = 1;
    state.q[..7].copy_from_slice(&FR3_READY_Q);
    let hw = FailingRobot {
        state,
        polls: 0,
        fail_at: 50,
        sent: 0,
        finished: false,
    };
    let node = transport::create_node("franka-fault").unwrap();
    let statuses = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let mut daemon = Daemon::new(cfg, model, hw, &node).unwrap();
    let err = daemon.run(|| false, || {}).unwrap_err();
    let HardwareError::Robot { code, reason } = &err else {
        panic!("{err}")
    };
    assert_eq!(*code, FAULT_ROBOT_LIMIT);
    assert!(
        reason.contains("joint_position_limits_violation"),
        "{reason}"
    );
    assert!(daemon.hardware().sent >= 40, "{}", daemon.hardware().sent);
    // The hardware ends what it can after the error too (a sensor's
    // fault leaves the robot's motion running until then).
    assert!(daemon.hardware().finished, "finish after the error");
    assert_eq!(daemon.mode(), ControllerMode::Fault);
    assert_eq!(daemon.fault_code(), FAULT_ROBOT_LIMIT);
    let mut last = None;
    transport::drain(&statuses, |s| last = Some(*s)).unwrap();
    let last = last.expect("a status");
    assert_eq!(last.mode, ControllerMode::Fault as u32);
    assert_eq!(last.fault_code, FAULT_ROBOT_LIMIT);
}

#[test]
fn the_flange_wrench_is_the_robots_estimate_moved_to_the_flange() {
    let mut s = RobotState::default();
    // F_T_EE: the hand's TCP, 0.1034 m along z, yaw -π/4; EE_T_K = I.
    let (c, si) = (
        std::f64::consts::FRAC_1_SQRT_2,
        -std::f64::consts::FRAC_1_SQRT_2,
    );
    s.F_T_EE = [
        c, si, 0.0, 0.0, -si, c, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1034, 1.0,
    ];
    s.EE_T_K = [
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];
    // The robot pushing with 10 N along K's x: the environment pushes
    // back, so the tool exerts 10 N along −(c, si) in F on the flange,
    // with a moment about F's origin from the 0.1034 m lever.
    s.K_F_ext_hat_K = [10.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let w = flange_wrench(&s);
    let want = [
        -10.0 * c,
        -10.0 * si,
        0.0,
        0.1034 * 10.0 * si,
        -0.1034 * 10.0 * c,
        0.0,
    ];
    for i in 0..6 {
        assert!((w[i] - want[i]).abs() < 1e-12, "{w:?} vs {want:?}");
    }
}

#[test]
fn a_robot_whose_load_is_not_the_models_is_refused_at_start_up() {
    let model = builtin("fr3").unwrap();
    let mut s = RobotState {
        q: FR3_READY_Q,
        m_ee: 0.73,
        m_total: 0.73,
        F_x_Ctotal: [-0.01, 0.0, 0.03],
        ..Default::default()
    };
    check_load(&model, FrankaGeneration::Fr3, &s).unwrap();
    // 0.2 kg missing at q = 0 shows at the other poses.
    s.q = [0.0; 7];
    s.m_load = 0.2;
    s.m_total = 0.93;
    assert!(check_load(&model, FrankaGeneration::Fr3, &s).is_err());
    s.q = FR3_READY_Q;
    // A 0.5 kg load set in Desk that the model does not carry.
    s.m_load = 0.5;
    s.m_total = 1.23;
    let Err(HardwareError::Mismatch(why)) = check_load(&model, FrankaGeneration::Fr3, &s) else {
        panic!("a 0.5 kg load was accepted");
    };
    assert!(
        why.contains("1.230 kg") && why.contains("load 0.500 kg"),
        "{why}"
    );
    s.m_total = f64::NAN;
    assert!(check_load(&model, FrankaGeneration::Fr3, &s).is_err());
}

#[test]
fn our_fr3_gravity_is_the_robots_with_its_default_hand_load() {
    // franka-rs' own FR3 model with the load the robot adds gravity for
    // (Desk's default hand: 0.73 kg at (-0.01, 0, 0.03) m in the flange
    // frame): what the backend takes off must be what the robot adds.
    let theirs = franka::Model::from_urdf(franka::model::FR3_URDF).unwrap();
    let ours = builtin("fr3").unwrap();
    let mut data = ours.create_data();
    for q in [
        FR3_READY_Q,
        [0.0, 0.0, 0.0, -1.57, 0.0, 1.57, 0.785],
        [0.5, -0.3, 0.4, -2.0, 0.7, 2.5, -1.0],
    ] {
        let want = theirs.gravity_q(
            &q,
            0.73,
            &[-0.01, 0.0, 0.03],
            &franka::model::DEFAULT_GRAVITY_EARTH,
        );
        let got = robot_model::gravity(&ours, &mut data, &q);
        for i in 0..7 {
            assert!(
                (got[i] - want[i]).abs() < 1e-6,
                "joint {i} at {q:?}: ours {} franka-rs {}",
                got[i],
                want[i]
            );
        }
    }
}

#[test]
fn the_watchdog_outlasts_the_robots_udp_time_out() {
    // A silent robot ends `read_once` after franka-rs's fixed UDP
    // time-out with fault 104, its record and final status; the
    // shipped unit's watchdog must not kill the daemon first.
    let unit =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/rt-controller.service");
    let text = std::fs::read_to_string(&unit).unwrap();
    let value = text
        .lines()
        .filter_map(|l| l.strip_prefix("WatchdogSec="))
        .next_back()
        .expect("WatchdogSec");
    let watchdog_s: f64 = value.trim_end_matches('s').parse().expect(value);
    let udp_s = franka::network::DEFAULT_UDP_TIMEOUT.as_secs_f64();
    // Half a second for the last feed's age and the fault's write.
    assert!(
        watchdog_s >= udp_s + 0.5,
        "WatchdogSec={value}, UDP {udp_s} s"
    );
}

#[test]
fn the_robots_own_limits_become_the_controllers_ramps_unchanged() {
    // franka-rs's FR3 description: the controller's limits from its
    // constants must equal franka-rs's own, margin included, over each
    // joint's range and past both stops.
    let served = franka::JointVelocityLimitsConfig::from_urdf(franka::model::FR3_URDF).unwrap();
    let ramps = ramps_of(served.joint_params());
    let model = robot_model::descriptions::builtin("fr3").unwrap();
    let ours = rt_controller::SpeedLimits::new(
        &rt_controller::SpeedLimitSource::Ramps(ramps.clone()),
        &model,
    )
    .unwrap();
    for k in 0..JOINTS {
        let (lo, hi) = (ramps[k].q_lo, ramps[k].q_hi);
        for i in 0..=100 {
            let mut q = [0.0; JOINTS];
            q[k] = lo - 0.1 + (hi - lo + 0.2) * f64::from(i) / 100.0;
            let j = ours.joint(k).unwrap();
            assert!(
                (j.upper(q[k]) - served.upper_limits(&q)[k]).abs() < 1e-12,
                "{k} {q:?}"
            );
            assert!(
                (j.lower(q[k]) - served.lower_limits(&q)[k]).abs() < 1e-12,
                "{k} {q:?}"
            );
        }
    }
}
