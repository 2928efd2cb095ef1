//! The control step's allocations, counted over thousands of cycles
//! (unsaturated, saturated with QP solves, actions, garbage actions, holds,
//! a fault and its reset) under a counting global allocator.
//!
//! Our code allocates nothing. clarabel 0.11's `solve()` resets its own
//! profiling timers at every call, which drops and rebuilds a small nested
//! `HashMap` (its API cannot turn the timers off: `solve` unwraps them).
//! That is a fixed set of small blocks, freed and re-taken each solve from
//! the thread's allocator cache; this test pins it down exactly: zero
//! allocations in every cycle without a solve, the same count in every
//! solve, and no growth of the live heap.

mod common;

use common::{PANDA_READY, action, panda};
use rt_controller::{ControllerConfig, Mode};
use std::sync::atomic::Ordering;
use test_support::alloc::{Counting, TRACE, count, largest, live_bytes};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn control_steps_allocate_nothing_but_clarabels_fixed_timer_block() {
    TRACE.store(
        std::env::var_os("RT_ALLOC_TRACE").is_some(),
        Ordering::Relaxed,
    );
    let mut config = ControllerConfig::default();
    config.impedance.kp = [1500.0; 6];
    let model = panda();
    let ctrl = rt_controller::Controller::new(&model, config).unwrap();
    let mut data = ctrl.create_data(&model);
    // The plant integrates outside the counted region; only the step counts.
    let mut q = PANDA_READY;
    let mut v = [0.0; 7];
    let mut sim = model.create_data();
    let garbage = [
        action(f64::NAN, 0.0, 0.0, 0.0),
        action(0.0, f64::INFINITY, 0.0, 0.0),
        action(1e9, 0.0, 0.0, 0.0),
        action(-0.0, 0.0, 0.0, f64::MIN_POSITIVE / 8.0),
    ];
    let mut outside_solver = 0;
    let mut per_solve = std::collections::BTreeMap::<usize, usize>::new();
    let mut solved = 0;
    let mut first_solve = None;
    let mut live_after_warmup = None;
    for k in 0..6000_usize {
        let t = k as f64 * 0.001;
        let a = match k {
            _ if k % 50 != 0 => None,
            _ if k % 250 == 0 => Some(garbage[(k / 250) % 4]),
            // Bang-bang steps that saturate the torque filter.
            _ => Some(action(
                if (k / 50) % 2 == 0 { 0.01 } else { -0.01 },
                if (k / 100) % 2 == 0 { 0.01 } else { -0.01 },
                0.0,
                0.05,
            )),
        };
        // A quiet spell (hold), then a fault from a NaN state and a reset.
        let quiet = (3000..3300).contains(&k);
        let nan_q = k == 4000;
        let mut qs = q;
        if nan_q {
            qs[2] = f64::NAN;
        }
        let state = rt_controller::RobotState {
            q: &qs,
            v: &v,
            tau_measured: None,
            wrench: None,
        };
        let mut outcome = None;
        let n = count(|| {
            let info = rt_controller::step(
                &model,
                &ctrl,
                &mut data,
                &state,
                if quiet { None } else { a.as_ref() },
                t,
            );
            outcome = info.qp;
            if info.mode == Mode::Fault && k == 4001 {
                data.reset(t);
            }
        })
        .allocations;
        match outcome {
            Some(
                rt_controller::QpOutcome::Solved { .. } | rt_controller::QpOutcome::Fallback(_),
            ) => {
                solved += 1;
                if first_solve.is_none() {
                    first_solve = Some(n);
                } else {
                    *per_solve.entry(n).or_default() += 1;
                }
            }
            _ => outside_solver += n,
        }
        if k == 1000 {
            live_after_warmup = Some(live_bytes());
        }
        let tau: Vec<f64> = data.torques().to_vec();
        let acc = robot_model::forward_dynamics(&model, &mut sim, &q, &v, &tau)
            .unwrap()
            .clone();
        for i in 0..7 {
            v[i] += 0.001 * acc[i];
            q[i] += 0.001 * v[i];
        }
    }
    let c = data.supervisor.counters;
    assert!(solved > 100, "the QP must have run: {c:?}");
    assert!(
        c.actions_rejected >= 10 && c.faults == 1 && c.action_timeouts >= 1,
        "{c:?}"
    );
    assert_eq!(
        outside_solver, 0,
        "allocations in control steps without a QP solve"
    );
    // After the first solve (which sizes clarabel's outer timer map), every
    // solve makes the same single allocation.
    assert!(first_solve.unwrap() <= 4, "first solve: {first_solve:?}");
    assert_eq!(
        per_solve.len(),
        1,
        "allocations per solve vary: {per_solve:?}"
    );
    let (&n, _) = per_solve.iter().next().unwrap();
    assert_eq!(n, 1, "allocations per solve");
    let largest = largest();
    assert!(largest <= 1024, "largest block {largest} bytes");
    // No growth: what the solver takes it gives back.
    let live = live_bytes();
    assert_eq!(Some(live), live_after_warmup, "live heap grew");
    println!("{solved} solves, {n} allocations each, largest block {largest} B");
}
