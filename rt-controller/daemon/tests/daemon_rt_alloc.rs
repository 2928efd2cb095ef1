//! With the daemon's allocator installed, the control loop never reaches the
//! heap: the blocks iceoryx2 (one per publication) and clarabel (a fixed set
//! per QP solve) take come from the lock-free real-time pools, and all of
//! them go back. Thousands of cycles against real iceoryx2 services, with
//! actions that saturate the torque filter so the QP is solved.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use rt_controller_daemon::CycleOutcome;
use rt_controller_daemon::rt_alloc::{self, RtAllocator};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;

#[global_allocator]
static GLOBAL: RtAllocator = RtAllocator;

#[test]
fn the_control_loop_never_reaches_the_heap() {
    let mut rig = DaemonRig::new("rtalloc", |c| c.controller.impedance.kp = [1500.0; 6]);
    let run = |rig: &mut DaemonRig, k: u64| {
        rig.publish_state(k);
        if k.is_multiple_of(50) {
            // Bang-bang steps: the torque filter saturates and solves.
            let s = if (k / 50).is_multiple_of(2) {
                0.01
            } else {
                -0.01
            };
            let a = rig.action(k + 1, [s, s, 0.0, 0.05]);
            transport::send(&rig.actions, &a).unwrap();
        }
        rt_alloc::enter_realtime();
        let now = mono_now_ns();
        let fresh = rig.daemon.poll_hardware(now).unwrap();
        let out = rig.daemon.cycle(now, fresh).unwrap();
        rt_alloc::leave_realtime();
        assert_eq!(out, CycleOutcome::Sent);
        transport::drain(&rig.torques, |_| {}).unwrap();
    };
    // Warm-up outside the measured window (connections, first solve).
    for k in 0..200 {
        run(&mut rig, k);
    }
    let before = rt_alloc::stats();
    let solved_before = rig.daemon.control.data.supervisor.counters.qp_solved;
    for k in 200..5200 {
        run(&mut rig, k);
    }
    let after = rt_alloc::stats();
    let solves = rig.daemon.control.data.supervisor.counters.qp_solved - solved_before;
    assert!(
        solves > 100,
        "only {solves} QP solves: the test must exercise the solver"
    );
    assert_eq!(
        after.system_allocs_on_rt_thread, before.system_allocs_on_rt_thread,
        "the control loop allocated from the heap"
    );
    assert_eq!(
        after.system_frees_on_rt_thread, before.system_frees_on_rt_thread,
        "the control loop freed heap blocks"
    );
    assert!(
        after.pool_allocs - before.pool_allocs >= 10_000,
        "the pools served only {} blocks",
        after.pool_allocs - before.pool_allocs
    );
    assert_eq!(after.pool_in_use, before.pool_in_use, "pool blocks leaked");
}
