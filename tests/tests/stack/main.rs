//! End-to-end tests that start the real processes: hw-sim, rt-controller
//! and the policy node, over real shared memory. The test process plays the
//! learner (or a misbehaving peer) where a test needs to see inside.

mod foxglove_ws;
mod garbage;
mod insertion;
mod lockstep;
mod peers;
mod systemd;
mod trained;

use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;
use shared_mem_schema::{PolicyAction, SensorFrame};
use std::time::Duration;
use tests::wait_for;

pub(crate) fn start_sim_and_controller(
    ns: &str,
    dir: &std::path::Path,
    controller_args: &[&str],
) -> (learner_node::stack::Managed, learner_node::stack::Managed) {
    let sim = tests::start("hw-sim", &["--namespace", ns, "--no-camera"], dir);
    let mut args = vec!["--namespace", ns, "--no-realtime"];
    args.extend_from_slice(controller_args);
    let ctl = tests::start("rt-controller", &args, dir);
    (sim, ctl)
}

/// An action answering `frame` (its episode and hardware time), as a
/// policy node stamps it: the daemon drops actions answering no frame of
/// the current episode, or one older than two policy periods.
pub(crate) fn action(seq: u64, dx: f64, version: u32, frame: &SensorFrame) -> PolicyAction {
    let mut a = PolicyAction::new(seq, mono_now_ns(), [dx, 0.0, 0.0, 0.0]);
    a.header.schema_version = version;
    a.header.episode = frame.header.episode;
    a.header.t_hw_ns = frame.header.t_hw_ns;
    a
}

/// The newest sensor frame, waiting up to 5 s for one.
pub(crate) fn latest(frames: &transport::Sub<SensorFrame>) -> SensorFrame {
    let mut newest = wait_for(frames, Duration::from_secs(5), |_| true).expect("sensor frames");
    transport::drain(frames, |f| newest = *f).unwrap();
    newest
}
