//! The simulated robot's hardware interface: [`World`] ↔ the wire messages.
//!
//! State out ([`HardwareState`]: the sensor readings, the brakes flag and,
//! while braked, the gravity load the joints carry, which is what torque
//! sensors read), torque command in (applied for one physics step, or the
//! brakes when there is none). hw-sim's process, the learner's fast path and
//! hw-sim's own tests and bench all go through here, so they all exercise the
//! hardware the controller is deployed against. No transport and no clock
//! here: the caller stamps the monotonic time.

use crate::world::{SimError, World};
use robot_model::Data;
use shared_mem_schema::{
    HardwareState, Header, MAX_JOINTS, SCHEMA_VERSION, TorqueCommand, hw_time_ns,
};

/// The hardware side of one simulated robot: brakes, the gravity-load
/// workspace and the state's sequence numbers. Allocates only in
/// [`SimHardware::new`].
pub struct SimHardware {
    dynamics: Data,
    /// Joint positions the brakes hold, while engaged after a command.
    brake_q: Vec<f64>,
    braking: bool,
    /// A command was applied this episode (before the first, the brakes
    /// hold the arm).
    commanded: bool,
    zeros: Vec<f64>,
    tau: Vec<f64>,
    state_seq: u64,
    last_command_seq: u64,
}

impl SimHardware {
    /// The interface to `world`'s robot, brakes engaged.
    pub fn new(world: &World) -> Self {
        let nv = world.model().nv();
        Self {
            dynamics: world.model().create_data(),
            brake_q: vec![0.0; nv],
            braking: false,
            commanded: false,
            zeros: vec![0.0; nv],
            tau: vec![0.0; nv],
            state_seq: 0,
            last_command_seq: 0,
        }
    }

    /// A new episode (the world was reset): brakes engaged until the first
    /// command.
    pub fn reset(&mut self) {
        self.braking = false;
        self.commanded = false;
    }

    /// Whether the brakes hold the arm (no command yet this episode, or the
    /// last step had none).
    pub fn brakes_engaged(&self) -> bool {
        self.braking || !self.commanded
    }

    /// Whether `c` can be applied to a robot of `nv` joints: this schema,
    /// the joint count, finite torques.
    pub fn valid_command(c: &TorqueCommand, nv: usize) -> bool {
        c.header.schema_version == SCHEMA_VERSION
            && c.n_joints as usize == nv
            && c.tau[..nv].iter().all(|t| t.is_finite())
    }

    /// Writes the current state of `world` as the hardware publishes it,
    /// stamped `t_mono_ns` and `episode`.
    pub fn state(&mut self, world: &World, episode: u64, t_mono_ns: u64, out: &mut HardwareState) {
        self.state_seq += 1;
        let mut header = Header::new(
            self.state_seq,
            t_mono_ns,
            hw_time_ns(world.time_s()),
            episode,
        );
        let r = world.readings();
        let nv = r.q.len();
        out.step = world.step_index();
        out.applied_command_seq = self.last_command_seq;
        out.n_joints = nv as u32;
        out.reserved = 0;
        out.q = [0.0; MAX_JOINTS];
        out.v = [0.0; MAX_JOINTS];
        out.tau_measured = [0.0; MAX_JOINTS];
        out.q[..nv].copy_from_slice(&r.q);
        out.v[..nv].copy_from_slice(&r.v);
        out.wrench = r.wrench;
        if self.brakes_engaged() {
            header.flags |= HardwareState::BRAKES_ENGAGED;
            // Braked joints carry the gravity load: what torque sensors read.
            robot_model::gravity(world.model(), &mut self.dynamics, world.q());
            out.tau_measured[..nv].copy_from_slice(self.dynamics.g.as_slice());
        } else {
            out.tau_measured[..nv].copy_from_slice(&r.tau_applied);
        }
        out.header = header;
    }

    /// One physics step of `world`: with `cmd`'s torques, or, without a
    /// command, with the brakes holding the joints where they were when they
    /// engaged. `cmd` must be [valid](SimHardware::valid_command).
    pub fn apply(
        &mut self,
        world: &mut World,
        cmd: Option<&TorqueCommand>,
    ) -> Result<(), SimError> {
        let nv = self.tau.len();
        match cmd {
            Some(c) => {
                self.tau.copy_from_slice(&c.tau[..nv]);
                self.braking = false;
                self.commanded = true;
                self.last_command_seq = c.header.seq;
                world.step(&self.tau)
            }
            None => {
                if !self.braking {
                    self.brake_q.copy_from_slice(world.q());
                    self.braking = true;
                }
                world.set_joint_state(&self.brake_q, &self.zeros)?;
                world.step(&self.zeros)
            }
        }
    }
}
