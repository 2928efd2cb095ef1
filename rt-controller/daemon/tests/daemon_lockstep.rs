//! The daemon in lockstep with the hardware: a long wait for the policy's
//! action is the controller's own delay, not the hardware's silence.

#[path = "common/daemon_rig.rs"]
mod daemon_rig;

use daemon_rig::DaemonRig;
use rt_controller_daemon::CycleOutcome;
use shared_mem_schema::process::mono_now_ns;

#[test]
fn a_long_wait_for_the_action_is_not_hardware_silence() {
    let mut rig = DaemonRig::new("lockstep-wait", |c| {
        c.timing.lockstep_actions = true;
        c.timing.hardware_timeout_ms = 20.0;
        // No action arrives: the wait runs to its end, well past the
        // hardware timeout.
        c.timing.lockstep_action_timeout_s = 0.15;
    });
    let period = rig.daemon.config().timing.action_period_steps;
    for k in 0..=period {
        rig.publish_state(k);
        let now = mono_now_ns();
        let fresh = rig.daemon.poll_hardware(now).unwrap();
        let outcome = rig.daemon.cycle(now, fresh).unwrap();
        assert_eq!(outcome, CycleOutcome::Sent, "step {k}");
    }
    // Step `period` waited for its action; the hardware has only now got its
    // command and has not answered yet.
    let now = mono_now_ns();
    let fresh = rig.daemon.poll_hardware(now).unwrap();
    assert!(!fresh);
    assert_eq!(
        rig.daemon.cycle(now, fresh).unwrap(),
        CycleOutcome::Missed,
        "the wait was counted as hardware silence"
    );
}
