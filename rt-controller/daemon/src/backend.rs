//! What the daemon needs of a robot, and the simulator backend (hw-sim over
//! shared memory). The Franka backend ([`crate::franka`]) implements the
//! same trait.

use shared_mem_schema::transport::{self, Pub, StackNode, Sub, TransportError};
use shared_mem_schema::{HardwareState, TorqueCommand};

/// A hardware interface failure.
#[derive(Debug, thiserror::Error)]
pub enum HardwareError {
    /// A shared-memory service failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// No state arrived at start-up.
    #[error(
        "no hardware state from the {backend} backend within {timeout_s} s (is hw-sim running \
         in namespace '{namespace}'?)"
    )]
    NoStartupState {
        /// The backend's name.
        backend: &'static str,
        /// How long the daemon waited, s.
        timeout_s: f64,
        /// The service namespace.
        namespace: String,
    },
    /// The robot is not the one the configuration describes (found at
    /// start-up, before the arm is held): a setting to correct, not a fault,
    /// so the daemon exits as for a bad configuration and is not restarted.
    #[error("the robot does not match the configuration: {0}")]
    Mismatch(String),
    /// The robot stopped the control session (a reflex, a limit, a
    /// communication constraint violation, a lost connection), or a sensor
    /// of the robot's failed: the daemon's Fault, with the robot's (or the
    /// sensor's) own words.
    #[error("the robot or its sensor reported an error (fault code {code}): {reason}")]
    Robot {
        /// The fault code published in the status
        /// (`crate::FAULT_ROBOT_*`).
        code: u32,
        /// The robot's reason, as its client library words it.
        reason: String,
    },
}

/// What the daemon needs of a robot. Implementations never block, except
/// that a hardware which clocks the loop itself (the Franka) waits in
/// [`Hardware::poll`] for its next state: one period while it talks, up to
/// its client's time-out when it falls silent (docs/franka.md).
pub trait Hardware {
    /// Short name for logs.
    fn name(&self) -> &'static str;
    /// The newest state since the last call, or `None` when nothing new
    /// arrived.
    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError>;
    /// Sends a torque command.
    fn send(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError>;
    /// The joint torques the last [`Hardware::send`] put on the wire, N·m,
    /// where the backend changes the command's `tau` on the way (the
    /// Franka's gravity, filter and rate limiter); `None` where it sends
    /// `tau` as it is. The sensor frame's `tau_sent` records it.
    fn sent_torques(&self) -> Option<&[f64]> {
        None
    }
    /// Ends the control session after the loop's last command (the
    /// shutdown hold's end), or after the loop ended in an error; called
    /// outside the real-time section. The Franka backend finishes its
    /// motion there, so that the robot's own controller takes the arm over
    /// without a jump.
    fn finish(&mut self) -> Result<(), HardwareError> {
        Ok(())
    }
}

/// hw-sim over shared memory.
pub struct SimBackend {
    states: Sub<HardwareState>,
    commands: Pub<TorqueCommand>,
    latest: HardwareState,
}

impl SimBackend {
    /// Opens the hardware services of `namespace` on `node`.
    pub fn open(node: &StackNode, namespace: &str) -> Result<Self, TransportError> {
        Ok(Self {
            states: transport::subscriber(node, namespace)?,
            commands: transport::publisher(node, namespace)?,
            latest: HardwareState::empty(0),
        })
    }
}

/// Most hardware states one poll of the simulator backend receives.
pub const MAX_STATES_PER_POLL: usize = 8;

impl Hardware for SimBackend {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn poll(&mut self) -> Result<Option<&HardwareState>, HardwareError> {
        let mut got = false;
        let latest = &mut self.latest;
        // Bounded: a peer flooding `hw/state` cannot stretch the cycle.
        transport::drain_at_most(&self.states, MAX_STATES_PER_POLL, |s| {
            if !got || s.header.seq > latest.header.seq || s.header.episode != latest.header.episode
            {
                *latest = *s;
            }
            got = true;
        })?;
        Ok(got.then_some(&self.latest))
    }

    fn send(&mut self, cmd: &TorqueCommand) -> Result<(), HardwareError> {
        Ok(transport::send(&self.commands, cmd)?)
    }
}
