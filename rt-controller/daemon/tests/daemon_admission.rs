//! Action admission on real iceoryx2 services (issue 52, item 3): a peer
//! that publishes valid-looking actions every millisecond moves the target
//! no faster than a policy at its rate and largest step, and an address
//! (`apply_at_step`) outside lockstep cannot hold the queue.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use shared_mem_schema::transport;

fn target_x(rig: &DaemonRig) -> f64 {
    rig.daemon.control.data.trajectory.target()[0]
}

fn accepted(rig: &DaemonRig) -> u64 {
    rig.daemon.control.data.supervisor.counters.actions_accepted
}

#[test]
fn a_peer_at_1_khz_moves_the_target_one_largest_step_per_policy_period() {
    let mut rig = DaemonRig::new("flood", |_| {});
    let max_step = rig.daemon.config().controller.trajectory.max_step_m;
    let mut k = 0;
    rig.run(50, &mut k);
    // The policy's action, then a flood of the largest step every cycle
    // for two policy periods, each stamped as the policy stamps its own.
    transport::send(&rig.actions, &rig.action(1, [0.0; 4])).unwrap();
    rig.run(1, &mut k);
    assert_eq!(accepted(&rig), 1);
    let x0 = target_x(&rig);
    for seq in 2..102 {
        transport::send(&rig.actions, &rig.action(seq, [max_step, 0.0, 0.0, 0.0])).unwrap();
        rig.run(1, &mut k);
    }
    // 100 cycles: an action at most every 25 (4 of them), each cut to half
    // the largest step; without the bounds the target would lead by the
    // anti-windup bound, 3 cm.
    let moved = target_x(&rig) - x0;
    assert_eq!(
        accepted(&rig),
        1 + 4,
        "applied at most at the policy rate's double"
    );
    assert_eq!(rig.daemon.stats.actions_speed_cut, 4);
    assert!(
        moved <= 2.0 * max_step + 1e-12,
        "moved {moved} m in two policy periods"
    );
    assert!(
        moved > 1.5 * max_step,
        "the flood's own steps did apply: {moved}"
    );
}

#[test]
fn a_policy_at_its_rate_is_neither_held_nor_cut() {
    let mut rig = DaemonRig::new("at-rate", |_| {});
    let max_step = rig.daemon.config().controller.trajectory.max_step_m;
    let mut k = 0;
    rig.run(10, &mut k);
    let x0 = target_x(&rig);
    // Jitter: 48 to 52 steps apart.
    for (seq, gap) in [(1u64, 1u64), (2, 50), (3, 48), (4, 52)] {
        rig.run(gap - 1, &mut k);
        transport::send(
            &rig.actions,
            &rig.action(seq, [max_step / 5.0, 0.0, 0.0, 0.0]),
        )
        .unwrap();
        rig.run(1, &mut k);
        assert_eq!(accepted(&rig), seq, "action {seq} was held");
    }
    assert_eq!(rig.daemon.stats.actions_speed_cut, 0);
    assert!((target_x(&rig) - x0 - 4.0 * max_step / 5.0).abs() < 1e-12);
}

#[test]
fn an_address_outside_lockstep_is_refused_and_holds_nothing() {
    let mut rig = DaemonRig::new("addressed", |_| {});
    let mut k = 0;
    rig.run(10, &mut k);
    let mut a = rig.action(1, [0.001, 0.0, 0.0, 0.0]);
    a.apply_at_step = k + 1_000_000;
    transport::send(&rig.actions, &a).unwrap();
    rig.run(1, &mut k);
    assert_eq!(rig.daemon.stats.actions_misaddressed, 1);
    // The next action is applied at once: nothing waits at the front.
    transport::send(&rig.actions, &rig.action(2, [0.001, 0.0, 0.0, 0.0])).unwrap();
    rig.step(k);
    assert_eq!(rig.daemon.control.last_action_seq(), 2);
    assert_eq!(accepted(&rig), 1);
}

#[test]
fn in_lockstep_only_the_next_boundaries_may_be_addressed() {
    let mut rig = DaemonRig::new("addressed-lockstep", |c| c.timing.lockstep_actions = true);
    for k in 0..10 {
        rig.step(k);
    }
    // A boundary far ahead would wait at the queue's front through every
    // boundary before it; one between boundaries is never waited for.
    for at in [10_000, 75] {
        let mut a = rig.action(1, [0.001, 0.0, 0.0, 0.0]);
        a.apply_at_step = at;
        transport::send(&rig.actions, &a).unwrap();
    }
    let mut a = rig.action(2, [0.001, 0.0, 0.0, 0.0]);
    a.apply_at_step = 50;
    transport::send(&rig.actions, &a).unwrap();
    rig.step(10);
    assert_eq!(rig.daemon.stats.actions_misaddressed, 2);
    for k in 11..=50 {
        rig.step(k);
    }
    assert_eq!(
        rig.daemon.control.last_action_seq(),
        2,
        "the next boundary's action"
    );
}
