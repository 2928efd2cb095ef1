//! The daemon's whole cycle (shared-memory input, actions, control step,
//! torque command, sensor frame, status), counted over thousands of cycles
//! against real iceoryx2 services. A peer in the same process plays the
//! hardware and the learner outside the counted region. Cycles in which the
//! QP filter had to solve are left out: clarabel's own fixed per-solve block
//! is pinned down by tests/allocation.rs.
//!
//! Our code allocates nothing. iceoryx2 0.10 does, once per publication:
//! `Publisher::loan_uninit` wraps the loaned chunk's bookkeeping in a new
//! reference-counted block (`ChunkMutSharedState::new`), freed when the
//! sample is sent. Receiving allocates nothing. The test pins that down
//! exactly (one block per publication, no growth of the live heap), so any
//! other allocation fails it; removing the remaining one is an open item of
//! the real-time stack issue.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use rt_controller_daemon::CycleOutcome;
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;
use shared_mem_schema::{ControllerStatus, PolicyAction, SCHEMA_VERSION, SensorFrame};
use std::sync::atomic::Ordering;
use test_support::alloc::{Counting, TRACE, count, live_bytes};

#[global_allocator]
static GLOBAL: Counting = Counting;

fn action(rig: &DaemonRig, seq: u64, dx: f64, version: u32) -> PolicyAction {
    let mut a = rig.action(seq, [dx, 0.0, 0.0, 0.0]);
    a.header.schema_version = version;
    a
}

#[test]
fn daemon_cycles_allocate_only_iceoryx2s_block_per_publication() {
    TRACE.store(
        std::env::var_os("RT_ALLOC_TRACE").is_some(),
        Ordering::Relaxed,
    );
    let mut rig = DaemonRig::new("alloc", |_| {});
    let ns = rig.namespace().to_string();
    let sensor_sub = transport::subscriber::<SensorFrame>(&rig.peer, &ns).unwrap();
    let status_sub = transport::subscriber::<ControllerStatus>(&rig.peer, &ns).unwrap();
    let nv = rig.daemon.model().nv();
    // The robot holds itself: the measured torques are its gravity torques,
    // so the torque-rate limiter starts where the control law is.
    let mut rm = rig.daemon.model().create_data();
    let q = rig.state.q;
    robot_model::gravity(rig.daemon.model(), &mut rm, &q[..nv]);
    rig.state.tau_measured[..nv].copy_from_slice(rm.g.as_slice());
    rig.state.wrench = [0.0, 0.0, -0.7, 0.0, 0.0, 0.0];

    let (mut counted, mut exact, mut commands, mut frames, mut statuses) = (0, 0, 0, 0, 0);
    let mut worst_excess = 0i64;
    let mut live_after_warmup = None;
    for k in 0..5000u64 {
        rig.publish_state(k);
        if k % 50 == 0 {
            // Small motions, garbage values and another schema's bytes.
            let seq = k + 1;
            let a = match (k / 50) % 10 {
                3 => action(&rig, seq, f64::NAN, SCHEMA_VERSION),
                6 => action(&rig, seq, 1e9, SCHEMA_VERSION),
                8 => action(&rig, seq, 0.0005, SCHEMA_VERSION + 1),
                n => {
                    let dx = if n % 2 == 0 { 0.0005 } else { -0.0005 };
                    action(&rig, seq, dx, SCHEMA_VERSION)
                }
            };
            transport::send(&rig.actions, &a).unwrap();
        }
        let skipped_before = rig.daemon.control.data.supervisor.counters.qp_skipped;
        let mut outcome = None;
        let n = count(|| {
            let now = mono_now_ns();
            let fresh = rig.daemon.poll_hardware(now).unwrap();
            outcome = Some(rig.daemon.cycle(now, fresh).unwrap());
        })
        .allocations;
        assert_eq!(outcome, Some(CycleOutcome::Sent), "cycle {k}");
        let c = transport::drain(&rig.torques, |c| {
            assert_eq!(c.state_step, k);
            assert!(c.tau[..nv].iter().all(|t| t.is_finite()));
        })
        .unwrap();
        let f = transport::drain(&sensor_sub, |_| {}).unwrap();
        let s = transport::drain(&status_sub, |_| {}).unwrap();
        (commands, frames, statuses) = (commands + c, frames + f, statuses + s);
        // The first cycles connect the daemon's ports to the peer's
        // subscribers (start-up work); count from the tenth.
        if k >= 10 && rig.daemon.control.data.supervisor.counters.qp_skipped > skipped_before {
            counted += 1;
            let publications = (c + f + s) as i64;
            if n as i64 == publications {
                exact += 1;
            }
            worst_excess = worst_excess.max(n as i64 - publications);
        }
        if k == 100 {
            live_after_warmup = Some(live_bytes());
        }
    }
    assert_eq!(commands, 5000);
    assert_eq!(frames, 5000);
    assert!(statuses >= 2, "status published {statuses} times");
    assert!(counted > 4000, "only {counted} cycles without a QP solve");
    assert_eq!(
        exact,
        counted,
        "{} of {counted} cycles allocated other than one block per publication (worst: {worst_excess} more)",
        counted - exact
    );
    let growth = live_bytes() - live_after_warmup.unwrap();
    assert!(growth <= 0, "the live heap grew by {growth} bytes");
    let garbage = rig.daemon.control.data.supervisor.counters.actions_rejected
        + rig.daemon.stats.actions_garbage;
    assert_eq!(
        garbage, 30,
        "NaN, huge and foreign-schema actions are counted"
    );
}
