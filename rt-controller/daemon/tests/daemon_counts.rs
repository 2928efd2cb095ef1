//! What the daemon's status counts apart: actions dropped from a full
//! queue (a flood) are not rejections (bad values), and hardware states
//! superseded before a cycle took them are counted as skipped.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use shared_mem_schema::ControllerStatus;
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;

fn cycle(rig: &mut DaemonRig) {
    let now = mono_now_ns();
    let fresh = rig.daemon.poll_hardware(now).unwrap();
    rig.daemon.cycle(now, fresh).unwrap();
}

fn status(rig: &mut DaemonRig, sub: &transport::Sub<ControllerStatus>) -> ControllerStatus {
    rig.daemon.publish_status(mono_now_ns());
    let mut last = None;
    transport::drain(sub, |s| last = Some(*s)).unwrap();
    last.expect("a status")
}

#[test]
fn queue_overflow_is_counted_apart_from_rejections() {
    let mut rig = DaemonRig::new("counts-overflow", |_| {});
    let ns = rig.namespace().to_string();
    let status_sub = transport::subscriber::<ControllerStatus>(&rig.peer, &ns).unwrap();
    let mut seq = 0;
    let mut flood = |rig: &mut DaemonRig| {
        // As many as the daemon's subscriber holds: all of them arrive.
        for _ in 0..16 {
            seq += 1;
            // Stamped with the episode and the state it answers: fresh.
            let a = rig.action(seq, [0.0005, 0.0, 0.0, 0.0]);
            transport::send(&rig.actions, &a).unwrap();
        }
    };
    rig.publish_state(0);
    flood(&mut rig);
    cycle(&mut rig); // 16 queued, one taken: 15 left
    rig.publish_state(1);
    flood(&mut rig);
    cycle(&mut rig); // 31 for 16 places: the 15 oldest dropped
    let s = status(&mut rig, &status_sub);
    assert_eq!(s.actions_received, 32, "{s:?}");
    assert_eq!(s.actions_overflow, 15, "{s:?}");
    assert_eq!(
        s.actions_rejected, 0,
        "valid actions counted as garbage: {s:?}"
    );
    // One applied: the second cycle is too soon after it for another
    // (the rate admission holds it at the queue's front).
    assert_eq!(s.actions_accepted + s.actions_ignored, 1, "{s:?}");
}

#[test]
fn superseded_hardware_states_are_counted_as_skipped() {
    let mut rig = DaemonRig::new("counts-skipped", |_| {});
    let ns = rig.namespace().to_string();
    let status_sub = transport::subscriber::<ControllerStatus>(&rig.peer, &ns).unwrap();
    for k in 0..3 {
        rig.publish_state(k);
        cycle(&mut rig);
    }
    // A burst: states 3, 4 and 5 arrive before the next cycle, which
    // controls 5 only.
    for k in 3..6 {
        rig.publish_state(k);
    }
    cycle(&mut rig);
    rig.publish_state(6);
    cycle(&mut rig);
    let s = status(&mut rig, &status_sub);
    assert_eq!(s.hardware_states_skipped, 2, "{s:?}");
    let mut steps = Vec::new();
    transport::drain(&rig.torques, |c| steps.push(c.state_step)).unwrap();
    assert_eq!(steps, [0, 1, 2, 5, 6]);
}

#[test]
fn a_cycle_receives_at_most_its_cap_of_actions_however_many_peers_flood() {
    use rt_controller_daemon::control::MAX_ACTIONS_PER_CYCLE;
    let mut rig = DaemonRig::new("counts-cap", |_| {});
    let ns = rig.namespace().to_string();
    let status_sub = transport::subscriber::<ControllerStatus>(&rig.peer, &ns).unwrap();
    // Three peers, each filling its share of the daemon's subscriber.
    let extra: Vec<transport::Pub<shared_mem_schema::PolicyAction>> = (0..2)
        .map(|_| transport::publisher(&rig.peer, &ns).unwrap())
        .collect();
    rig.publish_state(0);
    let mut seq = 0;
    for p in extra.iter().chain([&rig.actions]) {
        for _ in 0..16 {
            seq += 1;
            transport::send(p, &rig.action(seq, [0.0; 4])).unwrap();
        }
    }
    let mut received = Vec::new();
    for k in 0..4 {
        rig.publish_state(k + 1);
        cycle(&mut rig);
        received.push(status(&mut rig, &status_sub).actions_received);
    }
    let per_cycle: Vec<u64> = received
        .iter()
        .scan(0, |last, &r| {
            let d = r - *last;
            *last = r;
            Some(d)
        })
        .collect();
    let cap = MAX_ACTIONS_PER_CYCLE as u64;
    assert_eq!(per_cycle, [cap, cap, cap, 48 - 3 * cap], "{received:?}");
}
