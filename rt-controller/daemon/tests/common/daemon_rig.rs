//! The daemon on real iceoryx2 services, with a peer in the same process
//! playing the hardware and the learner (for the allocation tests).
#![allow(dead_code)]

use robot_model::descriptions::{IIWA14_HOME_Q, builtin};
use rt_controller_daemon::config::{Clock, DaemonConfig};
use rt_controller_daemon::{Daemon, SimBackend};
use shared_mem_schema::transport::{self, Pub, StackNode, Sub};
use shared_mem_schema::{HardwareState, PolicyAction, TorqueCommand};

pub struct DaemonRig {
    pub daemon: Daemon<SimBackend>,
    pub hw: Pub<HardwareState>,
    pub torques: Sub<TorqueCommand>,
    pub actions: Pub<PolicyAction>,
    /// The state the peer publishes (the iiwa at its home pose, at rest).
    pub state: HardwareState,
    pub peer: StackNode,
    _node: StackNode,
}

impl DaemonRig {
    /// A hardware-clocked daemon without real-time set-up, status every
    /// 5 ms, in a namespace of its own; `edit` adjusts the configuration.
    pub fn new(tag: &str, edit: impl FnOnce(&mut DaemonConfig)) -> Self {
        transport::quiet_logs();
        let ns = format!("{tag}-{}", std::process::id());
        let mut cfg = DaemonConfig::default();
        cfg.backend.namespace = ns.clone();
        cfg.timing.clock = Clock::Hardware;
        cfg.realtime.enabled = false;
        cfg.timing.status_period_ms = 5.0;
        edit(&mut cfg);
        let model = builtin("iiwa14").unwrap();
        let nv = model.nv();
        let peer = transport::create_node(&format!("{tag}-peer")).unwrap();
        let hw = transport::publisher::<HardwareState>(&peer, &ns).unwrap();
        let torques = transport::subscriber::<TorqueCommand>(&peer, &ns).unwrap();
        let actions = transport::publisher::<PolicyAction>(&peer, &ns).unwrap();
        let node = transport::create_node(&format!("{tag}-daemon")).unwrap();
        let backend = SimBackend::open(&node, &ns).unwrap();
        let daemon = Daemon::new(cfg, model, backend, &node).unwrap();
        let mut state = HardwareState::empty(nv);
        state.header.episode = 1;
        state.q[..nv].copy_from_slice(&IIWA14_HOME_Q);
        Self {
            daemon,
            hw,
            torques,
            actions,
            state,
            peer,
            _node: node,
        }
    }

    /// The namespace's name is private to the rig; subscribers of other
    /// topics are opened on the peer node.
    pub fn namespace(&self) -> &str {
        &self.daemon.config().backend.namespace
    }

    /// An action `delta` numbered `seq`, answering the state last published
    /// (its episode and hardware time), as a policy node stamps it.
    pub fn action(&self, seq: u64, delta: [f64; 4]) -> PolicyAction {
        let mut a = PolicyAction::new(seq, shared_mem_schema::process::mono_now_ns(), delta);
        a.header.episode = self.state.header.episode;
        a.header.t_hw_ns = self.state.header.t_hw_ns;
        a
    }

    /// Publishes the state of step `k` and runs one cycle on it (the state
    /// must be fresh).
    pub fn step(&mut self, k: u64) -> rt_controller_daemon::CycleOutcome {
        self.publish_state(k);
        let now = shared_mem_schema::process::mono_now_ns();
        let fresh = self.daemon.poll_hardware(now).unwrap();
        assert!(fresh, "step {k}");
        self.daemon.cycle(now, fresh).unwrap()
    }

    /// `n` cycles on the states of steps `*k`, `*k + 1`, ... (`*k` moves on).
    pub fn run(&mut self, n: u64, k: &mut u64) {
        for _ in 0..n {
            self.step(*k);
            *k += 1;
        }
    }

    /// Publishes the state of hardware step `k` (1 ms apart).
    pub fn publish_state(&mut self, k: u64) {
        self.state.header.seq = k + 1;
        self.state.header.t_mono_ns = shared_mem_schema::process::mono_now_ns();
        self.state.header.t_hw_ns = k * shared_mem_schema::rates::CONTROL_PERIOD_NS;
        self.state.step = k;
        transport::send(&self.hw, &self.state).unwrap();
    }
}
