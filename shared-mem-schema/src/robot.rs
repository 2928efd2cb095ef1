//! The control loop's messages: the hardware state and torque command
//! exchanged with the (simulated) robot at 1 kHz, the controller's sensor
//! frame to the learner, and the policy's 20 Hz action.

use crate::message::{HEADER_BYTES as H, Header, Message, message};
use crate::topics;
use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Joint arrays hold this many entries; `n_joints` says how many are used.
pub const MAX_JOINTS: usize = 8;

/// Robot → controller, every hardware cycle (1 kHz).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct HardwareState {
    /// Header; `flags` bits: [`HardwareState::BRAKES_ENGAGED`].
    pub header: Header,
    /// Hardware step index since start (lockstep: the command for this
    /// state must carry it in [`TorqueCommand::state_step`]).
    pub step: u64,
    /// Sequence number of the torque command applied during the step that
    /// led to this state (0: none yet).
    pub applied_command_seq: u64,
    /// Used entries of the joint arrays.
    pub n_joints: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint positions, rad (or m).
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities, rad/s.
    pub v: [f64; MAX_JOINTS],
    /// Joint torques applied (measured), N·m.
    pub tau_measured: [f64; MAX_JOINTS],
    /// Wrist wrench the tool exerts on the flange in the F/T sensor frame:
    /// force (N) then moment (N·m).
    pub wrench: [f64; 6],
}

impl HardwareState {
    /// Flag: no valid torque command, the brakes hold the arm.
    pub const BRAKES_ENGAGED: u32 = 1;

    /// All zeros but the joint count and the schema version.
    pub fn empty(n_joints: usize) -> Self {
        Self {
            header: Header::new(0, 0, 0, 0),
            step: 0,
            applied_command_seq: 0,
            n_joints: n_joints as u32,
            reserved: 0,
            q: [0.0; MAX_JOINTS],
            v: [0.0; MAX_JOINTS],
            tau_measured: [0.0; MAX_JOINTS],
            wrench: [0.0; 6],
        }
    }
}

/// Controller → robot, every control cycle.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct TorqueCommand {
    /// Header.
    pub header: Header,
    /// [`HardwareState::step`] of the state this command answers.
    pub state_step: u64,
    /// Sequence number of the newest policy action reflected in `tau`
    /// (0: none).
    pub action_seq: u64,
    /// Used entries of `tau`.
    pub n_joints: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint torques, N·m.
    pub tau: [f64; MAX_JOINTS],
}

impl TorqueCommand {
    /// All zeros but the joint count and the schema version.
    pub fn empty(n_joints: usize) -> Self {
        Self {
            header: Header::new(0, 0, 0, 0),
            state_step: 0,
            action_seq: 0,
            n_joints: n_joints as u32,
            reserved: 0,
            tau: [0.0; MAX_JOINTS],
        }
    }
}

/// Controller → learner, every control cycle (1 kHz).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct SensorFrame {
    /// Header (`t_hw_ns` is the hardware time of the state).
    pub header: Header,
    /// Hardware step of the state.
    pub step: u64,
    /// Sequence number of the newest action reflected in `tau_cmd`.
    pub action_seq: u64,
    /// Used entries of the joint arrays.
    pub n_joints: u32,
    /// Controller mode ([`ControllerMode`](crate::ControllerMode) as u32).
    pub mode: u32,
    /// Fault code after this cycle, as [`ControllerStatus::fault_code`](crate::ControllerStatus::fault_code) (0:
    /// none).
    pub fault_code: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Joint positions, rad.
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities, rad/s.
    pub v: [f64; MAX_JOINTS],
    /// Torques commanded this cycle, N·m.
    pub tau_cmd: [f64; MAX_JOINTS],
    /// Torques measured, N·m.
    pub tau_measured: [f64; MAX_JOINTS],
    /// End-effector position in the base frame, m.
    pub ee_pos_m: [f64; 3],
    /// End-effector orientation in the base frame, quaternion (x, y, z, w).
    pub ee_quat_xyzw: [f64; 4],
    /// End-effector twist in the base frame: linear (m/s) then angular
    /// (rad/s).
    pub ee_twist: [f64; 6],
    /// Wrist wrench in the F/T sensor frame: force (N) then moment (N·m).
    pub wrench: [f64; 6],
    /// Torques the hardware was sent for this cycle, N·m, as they left the
    /// daemon: on hw-sim `tau_cmd` itself; on a Franka what crossed the
    /// wire, after the gravity the robot adds itself was taken off and the
    /// effort clamp, low-pass filter and rate limiter were applied. NaN in
    /// a log of schema version 3, which did not record them.
    pub tau_sent: [f64; MAX_JOINTS],
}

/// Learner → controller, 20 Hz: the paper's action, a displacement of the
/// end-effector target.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct PolicyAction {
    /// Header (`t_hw_ns`: hardware time of the observation it answers).
    pub header: Header,
    /// Lockstep only: the hardware step at which the controller applies it
    /// (0: as soon as it arrives, the deployed behaviour).
    pub apply_at_step: u64,
    /// Position step (x, y, z) in the base frame, m.
    pub delta_pos_m: [f64; 3],
    /// Roll step about the base z axis, rad.
    pub delta_roll_rad: f64,
}

impl PolicyAction {
    /// An action to apply as soon as it arrives, from the policy's vector
    /// (Δx, Δy, Δz in m, Δroll in rad).
    pub fn new(seq: u64, t_mono_ns: u64, delta: [f64; 4]) -> Self {
        let [x, y, z, roll] = delta;
        Self {
            header: Header::new(seq, t_mono_ns, 0, 0),
            apply_at_step: 0,
            delta_pos_m: [x, y, z],
            delta_roll_rad: roll,
        }
    }

    /// The policy's vector (Δx, Δy, Δz in m, Δroll in rad).
    pub fn delta(&self) -> [f64; 4] {
        let [x, y, z] = self.delta_pos_m;
        [x, y, z, self.delta_roll_rad]
    }
}

message!(HardwareState, topics::HARDWARE_STATE, "HardwareState");
message!(TorqueCommand, topics::TORQUE_COMMAND, "TorqueCommand");

impl Message for SensorFrame {
    const TOPIC: &'static str = topics::SENSOR;
    const NAME: &'static str = "SensorFrame";
    fn header(&self) -> &Header {
        &self.header
    }

    /// Version 3 had no `tau_sent`, the last field: its bytes are this
    /// layout's without it, and the torques sent read as NaN (unknown).
    fn upgrade(bytes: &[u8], version: u32) -> Option<Box<Self>> {
        let tail = std::mem::offset_of!(SensorFrame, tau_sent);
        if version != 3 || bytes.len() != tail {
            return None;
        }
        let mut f = Self::boxed_zeroed();
        bytemuck::bytes_of_mut(&mut *f)[..tail].copy_from_slice(bytes);
        f.tau_sent = [f64::NAN; MAX_JOINTS];
        Some(f)
    }
}
message!(PolicyAction, topics::ACTION, "PolicyAction");

// Layouts (`Pod` rejects padding; these pin the sizes).
const J: usize = 8 * MAX_JOINTS;
const _: () = assert!(size_of::<HardwareState>() == H + 16 + 8 + 3 * J + 48);
const _: () = assert!(size_of::<TorqueCommand>() == H + 16 + 8 + J);
const _: () = assert!(size_of::<SensorFrame>() == H + 16 + 16 + 5 * J + 8 * 19);
const _: () = assert!(size_of::<PolicyAction>() == H + 8 + 32);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::{OLDEST_RECORDED_VERSION, SCHEMA_VERSION};

    fn frame() -> SensorFrame {
        let mut f = *SensorFrame::boxed_zeroed();
        f.header = Header::new(7, 1, 2, 3);
        f.step = 11;
        f.q[6] = 0.5;
        f.tau_cmd[1] = -4.0;
        f.wrench[5] = 0.25;
        f.tau_sent[1] = -3.5;
        f
    }

    #[test]
    fn a_version_3_sensor_frame_reads_with_unknown_torques_sent() {
        let mut f = frame();
        f.header.schema_version = OLDEST_RECORDED_VERSION;
        let tail = std::mem::offset_of!(SensorFrame, tau_sent);
        let old = SensorFrame::read_recorded(&f.as_bytes()[..tail]).unwrap();
        assert_eq!(old.header, f.header);
        assert_eq!((old.step, old.q, old.tau_cmd), (f.step, f.q, f.tau_cmd));
        assert_eq!(old.wrench, f.wrench);
        assert!(old.tau_sent.iter().all(|t| t.is_nan()));
    }

    #[test]
    fn this_versions_frame_reads_whole_and_others_are_refused_by_version() {
        let f = frame();
        assert_eq!(*SensorFrame::read_recorded(f.as_bytes()).unwrap(), f);
        let tail = std::mem::offset_of!(SensorFrame, tau_sent);
        // This version's frame cut short is a size error, not an upgrade.
        let e = SensorFrame::read_recorded(&f.as_bytes()[..tail]).unwrap_err();
        assert!(e.contains("bytes"), "{e}");
        for v in [OLDEST_RECORDED_VERSION - 1, SCHEMA_VERSION + 1] {
            let mut g = f;
            g.header.schema_version = v;
            let e = SensorFrame::read_recorded(g.as_bytes()).unwrap_err();
            assert!(e.contains(&format!("schema version {v}")), "{e}");
        }
        let e = SensorFrame::read_recorded(&f.as_bytes()[..10]).unwrap_err();
        assert!(e.contains("header"), "{e}");
    }

    #[test]
    fn messages_whose_layout_did_not_change_read_from_the_oldest_version() {
        let mut a = PolicyAction::new(5, 1, [0.001, 0.0, -0.002, 0.01]);
        a.header.schema_version = OLDEST_RECORDED_VERSION;
        assert_eq!(*PolicyAction::read_recorded(a.as_bytes()).unwrap(), a);
    }
}
