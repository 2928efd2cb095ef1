//! The daemon's fault policy on real iceoryx2 services, the test playing the
//! hardware, the learner and the operator: a fault outlives an episode
//! change and only a reset command clears it (counted, answered in the
//! status); a silent hardware stays lost when a fresh stream starts until a
//! reset, which is refused while it is silent; stale actions are dropped by
//! reason, and a frozen policy does not keep the arm running.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use rt_controller_daemon::{CycleOutcome, FAULT_HARDWARE_SILENT};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport::{self, Pub, Sub};
use shared_mem_schema::{ControllerCommand, ControllerMode, ControllerStatus, PolicyAction};
use std::time::Duration;

/// The rig with an operator's ports: reset commands out, status in.
struct Operator {
    commands: Pub<ControllerCommand>,
    status: Sub<ControllerStatus>,
}

impl Operator {
    fn open(rig: &DaemonRig) -> Self {
        let ns = rig.namespace().to_string();
        Self {
            commands: transport::publisher(&rig.peer, &ns).unwrap(),
            status: transport::subscriber(&rig.peer, &ns).unwrap(),
        }
    }

    fn reset(&self, seq: u64) {
        let c = ControllerCommand::reset(seq, mono_now_ns(), 0);
        transport::send(&self.commands, &c).unwrap();
    }

    /// The newest status that answers command `seq`, if one was published.
    fn answer(&self, seq: u64) -> Option<ControllerStatus> {
        let mut hit = None;
        transport::drain(&self.status, |s| {
            if s.command_seq == seq {
                hit = Some(*s);
            }
        })
        .unwrap();
        hit
    }
}

#[test]
fn a_fault_outlives_the_episode_and_only_a_reset_clears_it() {
    let mut rig = DaemonRig::new("fault-latch", |_| {});
    let op = Operator::open(&rig);
    for k in 0..5 {
        assert_eq!(rig.step(k), CycleOutcome::Sent);
    }
    assert_eq!(rig.daemon.mode(), ControllerMode::Idle);
    // A force overload for one cycle.
    rig.state.wrench[2] = 500.0;
    rig.step(5);
    rig.state.wrench[2] = 0.0;
    assert_eq!(rig.daemon.mode(), ControllerMode::Fault);
    for k in 6..20 {
        rig.step(k);
    }
    // The simulator resets: a new episode, the arm back at its start.
    rig.state.header.episode = 2;
    for k in 20..40 {
        assert_eq!(rig.step(k), CycleOutcome::Sent, "torques go on");
        assert_eq!(
            rig.daemon.mode(),
            ControllerMode::Fault,
            "step {k}: the fault was cleared by the episode change"
        );
    }
    assert_eq!(rig.daemon.control.fault_code(), 4, "force overload kept");
    // The reset: Idle at the next cycle, counted and answered.
    op.reset(77);
    rig.step(40);
    assert_eq!(rig.daemon.mode(), ControllerMode::Idle);
    let s = op.answer(77).expect("the status answers the reset at once");
    assert_eq!(s.command_result, ControllerCommand::RESULT_CLEARED);
    assert_eq!(
        (s.resets, s.faults, s.mode),
        (1, 1, ControllerMode::Idle as u32)
    );
    for k in 41..60 {
        rig.step(k);
    }
    assert_eq!(rig.daemon.mode(), ControllerMode::Idle, "it stays cleared");
    // A reset with nothing latched changes nothing.
    op.reset(78);
    rig.step(60);
    let s = op.answer(78).unwrap();
    assert_eq!(s.command_result, ControllerCommand::RESULT_NO_FAULT);
    assert_eq!(s.resets, 1);
}

#[test]
fn a_restarted_hardware_stays_lost_until_a_reset_once_it_streams() {
    let mut rig = DaemonRig::new("hw-restart", |c| c.timing.hardware_timeout_ms = 20.0);
    let op = Operator::open(&rig);
    for k in 0..10 {
        rig.step(k);
    }
    transport::drain(&rig.torques, |_| {}).unwrap();
    // The hardware dies: silent past the timeout (a sleep can only be
    // longer than asked).
    std::thread::sleep(Duration::from_millis(30));
    let now = mono_now_ns();
    assert!(!rig.daemon.poll_hardware(now).unwrap());
    assert_eq!(
        rig.daemon.cycle(now, false).unwrap(),
        CycleOutcome::HardwareLost
    );
    assert_eq!(rig.daemon.mode(), ControllerMode::HardwareLost);
    // A reset while it is silent is refused.
    op.reset(5);
    let now = mono_now_ns();
    rig.daemon.cycle(now, false).unwrap();
    let s = op.answer(5).expect("answered");
    assert_eq!(s.command_result, ControllerCommand::RESULT_HARDWARE_SILENT);
    assert_eq!(s.mode, ControllerMode::HardwareLost as u32);
    assert_eq!(s.fault_code, FAULT_HARDWARE_SILENT);
    // It restarts as a restarted hw-sim does: sequence from 1, step 0,
    // episode 0 (its idle start), a new episode after that.
    rig.state.header.episode = 0;
    for k in 0..30 {
        if k == 15 {
            rig.state.header.episode = 1;
        }
        assert_eq!(rig.step(k), CycleOutcome::HardwareLost, "step {k}");
    }
    let sent = transport::drain(&rig.torques, |_| {}).unwrap();
    assert_eq!(
        sent, 0,
        "torques sent to a restarted hardware before a reset"
    );
    // Now the reset clears it: torques again, from Idle.
    op.reset(6);
    assert_eq!(rig.step(30), CycleOutcome::Sent);
    assert_eq!(rig.daemon.mode(), ControllerMode::Idle);
    let s = op.answer(6).expect("answered");
    assert_eq!(s.command_result, ControllerCommand::RESULT_CLEARED);
    assert_eq!(s.resets, 1);
    assert_eq!(transport::drain(&rig.torques, |_| {}).unwrap(), 1);
}

/// Stale actions counted so far: too old, from the future, of another
/// episode, replayed.
fn stale(rig: &DaemonRig) -> (u64, u64, u64, u64) {
    let s = &rig.daemon.stats;
    (
        s.actions_too_old,
        s.actions_from_future,
        s.actions_other_episode,
        s.actions_replayed,
    )
}

#[test]
fn stale_actions_are_dropped_by_reason_and_a_frozen_policy_ends_in_holding() {
    let mut rig = DaemonRig::new("stale", |_| {});
    let age_ns = 100_000_000; // timing.max_action_age_ms by default
    let mut k = 0;
    rig.run(200, &mut k);
    // A fresh one (answering the state just published) is applied.
    let fresh = rig.action(1, [0.001, 0.0, 0.0, 0.0]);
    transport::send(&rig.actions, &fresh).unwrap();
    rig.run(1, &mut k);
    assert_eq!(rig.daemon.mode(), ControllerMode::Running);
    assert_eq!(rig.daemon.control.last_action_seq(), 1);
    let t = rig.state.header.t_hw_ns;
    type Edit<'a> = &'a dyn Fn(&mut PolicyAction);
    let edits: [(u64, Edit); 4] = [
        (2, &|a| a.header.t_hw_ns = t - age_ns - 1_000_000),
        (3, &|a| a.header.t_hw_ns = t + 1_000_000_000),
        (4, &|a| a.header.episode = 7),
        (1, &|_| {}),
    ];
    for (seq, edit) in edits {
        let mut a = rig.action(seq, [0.001, 0.0, 0.0, 0.0]);
        edit(&mut a);
        transport::send(&rig.actions, &a).unwrap();
        // Half a policy period: the rate admission's interval.
        rig.run(25, &mut k);
        assert_eq!(rig.daemon.control.last_action_seq(), 1, "seq {seq} applied");
    }
    assert_eq!(stale(&rig), (1, 1, 1, 1));

    // A frozen policy: the same message again and again, 20 Hz.
    let frozen = rig.action(10, [0.001, 0.0, 0.0, 0.0]);
    for _ in 0..20 {
        transport::send(&rig.actions, &frozen).unwrap();
        rig.run(50, &mut k);
    }
    assert_eq!(
        rig.daemon.mode(),
        ControllerMode::Holding,
        "a frozen policy kept the arm running"
    );
    // Each repetition after the first is dropped: a replay, and once the
    // observation it answers is 100 ms old, too old (checked first).
    let (too_old, _, _, replayed) = stale(&rig);
    assert_eq!((too_old - 1) + (replayed - 1), 19);
    assert!(replayed >= 2 && too_old >= 2, "{too_old} {replayed}");
    assert_eq!(rig.daemon.control.last_action_seq(), 10);
    // The same message under new numbers: too old (100 ms) by then.
    let mut renumbered = frozen;
    for n in 0..10u64 {
        renumbered.header.seq = 100 + n;
        transport::send(&rig.actions, &renumbered).unwrap();
        rig.run(50, &mut k);
    }
    assert_eq!(rig.daemon.mode(), ControllerMode::Holding);
    assert_eq!(stale(&rig).0, too_old + 10);
}

#[test]
fn a_hardware_that_republishes_one_state_ends_hardware_lost() {
    let mut rig = DaemonRig::new("hw-frozen", |c| c.timing.hardware_timeout_ms = 20.0);
    for k in 0..10 {
        assert_eq!(rig.step(k), CycleOutcome::Sent);
    }
    // Frozen: the same state (step 9) again and again, then an older one,
    // for longer than the timeout. Outside lockstep none is fresh, and the
    // silence timer runs on.
    let start = std::time::Instant::now();
    let mut lost = false;
    while start.elapsed() < Duration::from_millis(500) && !lost {
        rig.publish_state(9);
        let now = mono_now_ns();
        assert!(
            !rig.daemon.poll_hardware(now).unwrap(),
            "a repeat is not fresh"
        );
        lost = rig.daemon.cycle(now, false).unwrap() == CycleOutcome::HardwareLost;
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(lost, "a frozen hardware never became HardwareLost");
    assert_eq!(rig.daemon.mode(), ControllerMode::HardwareLost);
    assert!(rig.daemon.stats.hardware_states_stale > 0);
}

#[test]
fn a_state_behind_the_last_one_is_dropped() {
    let mut rig = DaemonRig::new("hw-behind", |_| {});
    for k in 0..10 {
        rig.step(k);
    }
    rig.publish_state(5);
    assert!(!rig.daemon.poll_hardware(mono_now_ns()).unwrap());
    assert_eq!(rig.daemon.stats.hardware_states_stale, 1);
    // The stream goes on from where it was.
    assert_eq!(rig.step(10), CycleOutcome::Sent);
}

#[test]
fn a_forged_sequence_number_jump_cannot_starve_the_policy() {
    let mut rig = DaemonRig::new("seq-jump", |_| {});
    let mut k = 0;
    rig.run(50, &mut k);
    transport::send(&rig.actions, &rig.action(1, [0.001, 0.0, 0.0, 0.0])).unwrap();
    rig.run(25, &mut k);
    assert_eq!(rig.daemon.control.last_action_seq(), 1);
    // A peer copies the newest frame's stamps with seq = u64::MAX.
    transport::send(&rig.actions, &rig.action(u64::MAX, [0.01, 0.0, 0.0, 0.0])).unwrap();
    rig.run(25, &mut k);
    assert_eq!(
        rig.daemon.control.last_action_seq(),
        1,
        "the jump was applied"
    );
    assert_eq!(rig.daemon.stats.actions_seq_jump, 1);
    // The policy's next action still counts.
    transport::send(&rig.actions, &rig.action(2, [0.001, 0.0, 0.0, 0.0])).unwrap();
    rig.run(25, &mut k);
    assert_eq!(rig.daemon.control.last_action_seq(), 2);
    // A new episode: a forged first action is bounded by the newest of any
    // episode, and the policy's own (numbered on) is applied.
    rig.state.header.episode = 2;
    rig.run(5, &mut k);
    transport::send(&rig.actions, &rig.action(u64::MAX, [0.01, 0.0, 0.0, 0.0])).unwrap();
    rig.run(25, &mut k);
    assert_eq!(rig.daemon.stats.actions_seq_jump, 2);
    transport::send(&rig.actions, &rig.action(3, [0.001, 0.0, 0.0, 0.0])).unwrap();
    rig.run(25, &mut k);
    assert_eq!(rig.daemon.control.last_action_seq(), 3);
}
