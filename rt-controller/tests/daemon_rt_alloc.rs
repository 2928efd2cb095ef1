//! With the daemon's allocator installed, the control loop never reaches the
//! heap: the blocks iceoryx2 (one per publication) and clarabel (a fixed set
//! per QP solve) take come from the lock-free real-time pools, and all of
//! them go back. Thousands of cycles against real iceoryx2 services, with
//! actions that saturate the torque filter so the QP is solved.

use robot_model::descriptions::{IIWA14_HOME_Q, builtin};
use rt_controller::daemon::config::{Clock, DaemonConfig};
use rt_controller::daemon::rt_alloc::{self, RtAllocator};
use rt_controller::daemon::{CycleOutcome, Daemon, SimBackend};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;
use shared_mem_schema::{HardwareState, Header, MAX_JOINTS, PolicyAction, TorqueCommand};

#[global_allocator]
static GLOBAL: RtAllocator = RtAllocator;

#[test]
fn the_control_loop_never_reaches_the_heap() {
    transport::quiet_logs();
    let ns = format!("rtalloc-{}", std::process::id());
    let mut cfg = DaemonConfig::default();
    cfg.backend.namespace = ns.clone();
    cfg.timing.clock = Clock::Hardware;
    cfg.realtime.enabled = false;
    cfg.timing.status_period_ms = 5.0;
    cfg.controller.impedance.kp = [1500.0; 6];
    let model = builtin("iiwa14").unwrap();
    let nv = model.nv();
    let peer = transport::create_node("rtalloc-peer").unwrap();
    let hw_pub = transport::publisher::<HardwareState>(&peer, &ns).unwrap();
    let tau_sub = transport::subscriber::<TorqueCommand>(&peer, &ns).unwrap();
    let act_pub = transport::publisher::<PolicyAction>(&peer, &ns).unwrap();
    let node = transport::create_node("rtalloc-daemon").unwrap();
    let backend = SimBackend::open(&node, &ns).unwrap();
    let mut daemon = Daemon::new(cfg, model, backend, &node).unwrap();

    let mut state = HardwareState {
        header: Header::new(0, 0, 0, 1),
        step: 0,
        applied_command_seq: 0,
        n_joints: nv as u32,
        reserved: 0,
        q: [0.0; MAX_JOINTS],
        v: [0.0; MAX_JOINTS],
        tau_measured: [0.0; MAX_JOINTS],
        wrench: [0.0; 6],
    };
    state.q[..nv].copy_from_slice(&IIWA14_HOME_Q);

    // Warm-up outside the real-time section (connections, first solve).
    let mut run = |daemon: &mut Daemon<SimBackend>, k: u64| {
        state.header.seq = k + 1;
        state.header.t_hw_ns = k * 1_000_000;
        state.step = k;
        transport::send(&hw_pub, &state).unwrap();
        if k.is_multiple_of(50) {
            // Bang-bang steps: the torque filter saturates and solves.
            let s = if (k / 50).is_multiple_of(2) { 0.01 } else { -0.01 };
            let a = PolicyAction {
                header: Header::new(k + 1, mono_now_ns(), 0, 1),
                apply_at_step: 0,
                delta_pos_m: [s, s, 0.0],
                delta_roll_rad: 0.05,
            };
            transport::send(&act_pub, &a).unwrap();
        }
        rt_alloc::enter_realtime();
        let now = mono_now_ns();
        let fresh = daemon.poll_hardware(now).unwrap();
        let out = daemon.cycle(now, fresh).unwrap();
        rt_alloc::leave_realtime();
        assert_eq!(out, CycleOutcome::Sent);
        transport::drain(&tau_sub, |_| {}).unwrap();
    };
    for k in 0..200 {
        run(&mut daemon, k);
    }
    let before = rt_alloc::stats();
    let solved_before = daemon.data.supervisor.counters.qp_solved;
    for k in 200..5200 {
        run(&mut daemon, k);
    }
    let after = rt_alloc::stats();
    let solves = daemon.data.supervisor.counters.qp_solved - solved_before;
    assert!(
        solves > 100,
        "only {solves} QP solves: the test must exercise the solver"
    );
    assert_eq!(
        after.system_allocs_on_rt_thread, before.system_allocs_on_rt_thread,
        "the control loop allocated from the heap"
    );
    assert!(
        after.pool_allocs - before.pool_allocs >= 10_000,
        "the pools served only {} blocks",
        after.pool_allocs - before.pool_allocs
    );
    assert_eq!(after.pool_in_use, before.pool_in_use, "pool blocks leaked");
}
