//! The Fault command is a quiet safe state: after a force overload in
//! hw-sim (the peg driven onto the box's top face), the iiwa 14 and the
//! Panda settle under gravity compensation with damping. Velocities decay,
//! no joint torque rides the torque-rate limit, and the wrist force does not
//! alternate from cycle to cycle (with the plain 5 N·m·s/rad, the iiwa's
//! joint 7 swung the rate limit's full 1 N·m every cycle and the F/T force
//! alternated at 500 Hz).
//!
//! The simulator and the control cycle run in one process, in lockstep
//! (the learner's fast path: the same `SimHardware` and `ControlCycle` calls
//! as the processes), so the run is deterministic.

use hw_sim::WorldConfig;
use learner::fast_env::FastEnv;
use rt_controller::ControllerConfig;
use shared_mem_schema::ControllerMode;
use shared_mem_schema::rates::ACTION_PERIOD_STEPS;

/// One cycle after the fault: velocities, commanded torques, wrist force.
struct Sample {
    v: Vec<f64>,
    tau: Vec<f64>,
    force: [f64; 3],
}

/// Drives `robot`'s peg onto the box's top face until the force overload
/// (`max_force_n` lowered to 15 N) faults the controller, then records
/// `seconds` of the Fault command.
fn fault_and_record(robot: &str, seconds: f64) -> (Vec<Sample>, f64) {
    let mut world = WorldConfig {
        robot: robot.into(),
        ..Default::default()
    };
    // The box right under the start pose: 5 cm to the side is its top face,
    // clear of the hole.
    world.task.box_xy_range_m = [0.0, 0.0];
    world.task.box_yaw_range_rad = 0.0;
    let mut ctrl = ControllerConfig::default();
    ctrl.safety.max_force_n = 15.0;
    let rate_step = ctrl.qp.torque_rate_limit_nm_s * ctrl.period_s;
    let mut env = FastEnv::new(world, ctrl).unwrap();
    env.reset(1).unwrap();
    let nv = env.controller_data().torques().len();
    let mut actions = 0u64;
    let faulted = loop {
        assert!(actions < 400, "{robot}: no force overload after 20 s");
        let a = if actions < 5 {
            [0.01, 0.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, -0.01, 0.0]
        };
        env.cycle(Some(&a)).unwrap();
        actions += 1;
        let mut hit = false;
        for _ in 1..ACTION_PERIOD_STEPS {
            env.cycle(None).unwrap();
            let f = env.sensor_frame();
            if f.mode == ControllerMode::Fault as u32 {
                assert_eq!(f.fault_code, 4, "{robot}: not the force overload");
                hit = true;
                break;
            }
        }
        if hit {
            break env.sensor_frame().step;
        }
    };
    let n = (seconds * 1000.0) as usize;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        env.cycle(None).unwrap();
        let f = env.sensor_frame();
        assert_eq!(
            f.mode,
            ControllerMode::Fault as u32,
            "{robot}: Fault latched"
        );
        out.push(Sample {
            v: f.v[..nv].to_vec(),
            tau: f.tau_cmd[..nv].to_vec(),
            force: [f.wrench[0], f.wrench[1], f.wrench[2]],
        });
    }
    eprintln!("{robot}: force overload at step {faulted}");
    (out, rate_step)
}

fn settles(robot: &str) {
    let (s, rate_step) = fault_and_record(robot, 3.0);
    let nv = s[0].v.len();
    // The first 0.5 s are the transition from the running command to the
    // safe one (it slews at the rate limit by design); the rest is judged.
    let judged = &s[500..];
    let max_abs_v = |w: &[Sample]| {
        w.iter()
            .flat_map(|x| x.v.iter())
            .fold(0.0f64, |m, v| m.max(v.abs()))
    };
    let early = max_abs_v(&s[..500]);
    let late = max_abs_v(&s[s.len() - 500..]);
    // Torque steps: the largest, and the cycles at the rate limit.
    let mut worst_step = vec![0.0f64; nv];
    let mut at_limit = 0usize;
    for w in judged.windows(2) {
        for (i, worst) in worst_step.iter_mut().enumerate() {
            let d = (w[1].tau[i] - w[0].tau[i]).abs();
            *worst = worst.max(d);
            if d >= 0.9 * rate_step {
                at_limit += 1;
            }
        }
    }
    // Cycle-to-cycle alternation of the wrist force: consecutive changes
    // of opposite sign, both larger than 1 mN (the filtered, noise-free
    // sensor of a settling arm changes smoothly).
    let mut alternations = 0usize;
    let mut longest_run = 0usize;
    for c in 0..3 {
        let mut run = 0usize;
        for w in judged.windows(3) {
            let (d0, d1) = (w[1].force[c] - w[0].force[c], w[2].force[c] - w[1].force[c]);
            if d0 * d1 < 0.0 && d0.abs() > 1e-3 && d1.abs() > 1e-3 {
                alternations += 1;
                run += 1;
                longest_run = longest_run.max(run);
            } else {
                run = 0;
            }
        }
    }
    eprintln!(
        "{robot}: max |v| first 0.5 s {early:.4} rad/s, last 0.5 s {late:.5} rad/s; largest \
         torque step per joint after 0.5 s {worst_step:.4?} N·m (rate limit {rate_step} N·m), \
         {at_limit} at the limit; {alternations} force alternations, longest run {longest_run}"
    );
    assert_eq!(
        at_limit, 0,
        "{robot}: a torque rides the rate limit in Fault"
    );
    assert!(
        late < 0.01 && late <= early,
        "{robot}: velocities do not decay (first 0.5 s {early}, last 0.5 s {late} rad/s)"
    );
    assert!(
        longest_run < 5 && alternations < judged.len() / 100,
        "{robot}: the wrist force alternates ({alternations} alternations, runs up to \
         {longest_run})"
    );
}

#[test]
fn the_iiwa_settles_in_fault() {
    settles("iiwa14");
}

#[test]
fn the_panda_settles_in_fault() {
    settles("panda");
}
