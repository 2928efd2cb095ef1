//! The fast path's sensor frames carry the controller's real mode and fault
//! (it runs rt-controller's `ControlCycle`, as the daemon does), and the
//! collector's logs keep them: a policy or a dataset reading a log sees when
//! the controller stopped following actions.

use hw_sim::WorldConfig;
use learner::collect::run_episode;
use learner::fast_env::FastEnv;
use learner_node::log::{LogOptions, LogReader, topics};
use learner_node::mix::Mix;
use rt_controller::{ControllerConfig, FaultReason, cycle::fault_code};
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;
use shared_mem_schema::{ControllerMode, SensorFrame};

/// `ControllerMode::Fault` and the code of a force overload, as published.
const FAULT: u32 = ControllerMode::Fault as u32;
const FORCE_OVERLOAD: u32 = 4;

fn mode(frame: &SensorFrame) -> ControllerMode {
    ControllerMode::from_u32(frame.mode).expect("a known mode")
}

/// The peg pushed down onto the box's top face (6 cm from the hole) with a
/// 20 N force limit: the controller runs, then faults on a force overload
/// once the peg presses (the lead limit lets it press with about 45 N).
/// Every frame carries the mode and fault code of its cycle: none before
/// the fault, Fault and the overload's code from its cycle on, latched
/// while actions keep coming.
#[test]
fn a_force_overload_reaches_the_sensor_frame() {
    let mut controller = ControllerConfig::default();
    controller.safety.max_force_n = 20.0;
    let mut env = FastEnv::new(WorldConfig::default(), controller).unwrap();
    let tip = env.world().peg_tip_pose().translation.vector;
    let mut world = WorldConfig::default();
    world.task.box_center_xy_m = Some([tip.x, tip.y + 0.06]);
    world.task.box_xy_range_m = [0.0, 0.0];
    world.task.box_yaw_range_rad = 0.0;
    env.reset_with(world, 1).unwrap();

    let down = [0.0, 0.0, -0.005, 0.0];
    let (mut running, mut faulted_at, mut cycles) = (0u64, None, 0u64);
    for k in 0..200 * ACTION_PERIOD_STEPS {
        let action = k.is_multiple_of(ACTION_PERIOD_STEPS).then_some(&down);
        env.cycle(action).unwrap();
        cycles += 1;
        let frame = *env.sensor_frame();
        let supervisor = &env.controller_data().supervisor;
        assert_eq!(
            frame.fault_code,
            fault_code(supervisor.fault()),
            "cycle {k}"
        );
        match faulted_at {
            None if frame.mode == FAULT => {
                assert_eq!(frame.fault_code, FORCE_OVERLOAD, "cycle {k}");
                assert!(
                    matches!(
                        supervisor.fault(),
                        Some(FaultReason::ForceOverload { force_n }) if force_n > 20.0
                    ),
                    "{:?}",
                    supervisor.fault()
                );
                assert!(
                    env.world().task().unwrap().in_contact,
                    "the overload came without contact"
                );
                faulted_at = Some(k);
            }
            None => {
                assert_eq!(frame.fault_code, 0, "cycle {k}: {:?}", mode(&frame));
                running += u64::from(mode(&frame) == ControllerMode::Running);
            }
            Some(at) => {
                assert_eq!(mode(&frame), ControllerMode::Fault, "cycle {k}");
                assert_eq!(frame.fault_code, FORCE_OVERLOAD, "cycle {k}");
                if k >= at + 5 * ACTION_PERIOD_STEPS {
                    break;
                }
            }
        }
    }
    let at = faulted_at.expect("pressing on the box never overloaded the 20 N limit");
    eprintln!("fault at cycle {at} after {running} running cycles ({cycles} cycles run)");
    assert!(running > 0, "the controller faulted before it ever ran");
    assert_eq!(env.controller_data().supervisor.counters.faults, 1);
}

/// A collected episode whose controller faults: an F/T sensor reading
/// 150 N too much (a bias in the world configuration) overloads the
/// default 100 N limit from the first cycle. Every sensor frame of the
/// collector's log, read back typed, carries Fault and the overload's code,
/// and the last one is the frame the fast path ended on.
#[test]
fn the_collectors_log_records_the_fault() {
    let mut world = WorldConfig::default();
    world.noise.ft_bias = [0.0, 0.0, 150.0, 0.0, 0.0, 0.0];
    let controller = ControllerConfig::default();
    let mut env = FastEnv::new(world.clone(), controller.clone()).unwrap();
    let dir = test_support::scratch_dir("fast-path-fault");
    let path = dir.join("fault.mcap");
    let opts = LogOptions {
        foxglove: false,
        ..Default::default()
    };
    let actions = 4;
    let shard = run_episode(
        &mut env,
        world,
        &controller,
        &Mix::default(),
        0,
        7,
        actions,
        &path,
        &opts,
        || true,
    )
    .unwrap();
    assert_eq!(mode(env.sensor_frame()), ControllerMode::Fault);
    assert_eq!(env.sensor_frame().fault_code, FORCE_OVERLOAD);

    let log = LogReader::open(&shard.file).unwrap();
    let frames: Vec<SensorFrame> = log.read_raw(topics::SENSOR, None).unwrap();
    // Every cycle's frame, and the one after the last camera frame.
    assert_eq!(
        frames.len() as u64,
        u64::from(actions) * ACTION_PERIOD_STEPS + 1
    );
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(mode(f), ControllerMode::Fault, "frame {i}");
        assert_eq!(f.fault_code, FORCE_OVERLOAD, "frame {i}");
    }
    assert_eq!(frames.last().unwrap(), env.sensor_frame());
}
