//! The controller's side channel: its mode, status (counters and latency
//! histograms) and the operator's commands.

use crate::message::{HEADER_BYTES as H, Header, Message, message};
use crate::topics;
use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Bins of a [`LatencyHistogram`] (1 µs each).
pub const HISTOGRAM_BINS: usize = 2000;

/// The controller's mode as carried in messages.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerMode {
    /// Holding the start pose, no action yet.
    Idle = 0,
    /// Following actions.
    Running = 1,
    /// Holding the last target (actions stopped).
    Holding = 2,
    /// Latched safe state.
    Fault = 3,
    /// No hardware state: no torques sent.
    HardwareLost = 4,
}

impl ControllerMode {
    /// Decodes a `mode` field; `None` for unknown values.
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Idle,
            1 => Self::Running,
            2 => Self::Holding,
            3 => Self::Fault,
            4 => Self::HardwareLost,
            _ => return None,
        })
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Running => "running",
            Self::Holding => "holding",
            Self::Fault => "fault",
            Self::HardwareLost => "hardware-lost",
        }
    }
}

/// A histogram of durations in 1 µs bins, cumulative since start.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct LatencyHistogram {
    /// Samples recorded.
    pub count: u64,
    /// Samples at or above `HISTOGRAM_BINS` µs.
    pub overflow: u64,
    /// Largest sample, ns.
    pub max_ns: u64,
    /// Sum of samples, ns.
    pub sum_ns: u64,
    /// `bins[i]`: samples in [i, i+1) µs.
    pub bins: [u32; HISTOGRAM_BINS],
}

impl LatencyHistogram {
    /// An empty histogram.
    pub const EMPTY: Self = Self {
        count: 0,
        overflow: 0,
        max_ns: 0,
        sum_ns: 0,
        bins: [0; HISTOGRAM_BINS],
    };

    /// Records one duration (never allocates).
    pub fn record(&mut self, ns: u64) {
        self.count += 1;
        self.sum_ns = self.sum_ns.saturating_add(ns);
        self.max_ns = self.max_ns.max(ns);
        let us = (ns / 1000) as usize;
        match self.bins.get_mut(us) {
            Some(b) => *b = b.saturating_add(1),
            None => self.overflow += 1,
        }
    }

    /// The `p`-quantile (0..=1), µs, as the upper edge of its bin; the
    /// maximum when it falls in the overflow; 0 when empty.
    pub fn quantile_us(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((p.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, &b) in self.bins.iter().enumerate() {
            seen += u64::from(b);
            if seen >= rank {
                return (i + 1) as f64;
            }
        }
        self.max_ns as f64 / 1000.0
    }

    /// Mean, µs.
    pub fn mean_us(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64 / 1000.0
        }
    }
}

/// Controller → anyone, ~10 Hz: mode, counters and timing.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct ControllerStatus {
    /// Header.
    pub header: Header,
    /// Control cycles run.
    pub cycles: u64,
    /// Cycles that started after their deadline had passed a whole period.
    pub overruns: u64,
    /// Actions received.
    pub actions_received: u64,
    /// Actions applied (clamped included).
    pub actions_accepted: u64,
    /// Garbage actions (NaN, out of range, wrong schema) counted and ignored.
    pub actions_rejected: u64,
    /// Actions dropped unread because the controller's action queue was
    /// full (the oldest goes): a flood, not bad values.
    pub actions_overflow: u64,
    /// Valid actions ignored (fault or hold).
    pub actions_ignored: u64,
    /// Times the action stream went silent past the timeout.
    pub action_timeouts: u64,
    /// Faults raised.
    pub faults: u64,
    /// Cycles without a new hardware state.
    pub hardware_misses: u64,
    /// Hardware states never controlled: a newer one had arrived by the
    /// cycle (their steps have no sensor frame).
    pub hardware_states_skipped: u64,
    /// Sequence number of the newest action applied.
    pub last_action_seq: u64,
    /// Actions dropped as stale because the observation they answer is
    /// older than the controller's `safety.max_action_age_s` (hardware
    /// time), or their sender stamped none.
    pub actions_too_old: u64,
    /// Actions dropped as stale because they answer an observation the
    /// hardware has not made yet (a hardware time after the current state's).
    pub actions_from_future: u64,
    /// Actions dropped as stale because they answer another episode.
    pub actions_other_episode: u64,
    /// Actions dropped as stale because their sequence number is not above
    /// the newest one applied this episode (a replay).
    pub actions_replayed: u64,
    /// Faults (the control law's, or a silent hardware) cleared by a
    /// [`ControllerCommand::RESET`].
    pub resets: u64,
    /// `header.seq` of the last [`ControllerCommand`] handled (0: none).
    pub command_seq: u64,
    /// Controller mode ([`ControllerMode`] as u32).
    pub mode: u32,
    /// Fault reason code (0: none; see rt-controller's docs).
    pub fault_code: u32,
    /// 1 when the real-time set-up (memory lock, SCHED_FIFO) succeeded.
    pub realtime: u32,
    /// Result of the command `command_seq`: a `ControllerCommand::RESULT_*`
    /// (0 before any).
    pub command_result: u32,
    /// Wake-up latency of each cycle past its absolute deadline.
    pub wakeup_latency: LatencyHistogram,
    /// Compute time of each cycle (read state → torques sent → frame
    /// published).
    pub compute: LatencyHistogram,
    /// From an action's publication to the first torque command that
    /// reflects it.
    pub action_latency: LatencyHistogram,
}

/// Operator or learner → controller: leaving a latched fault. The daemon
/// answers in [`ControllerStatus`] (`command_seq`, `command_result`,
/// `resets`), published at once.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct ControllerCommand {
    /// Header (`seq`: the request id echoed in
    /// [`ControllerStatus::command_seq`]; `episode`: the hardware episode
    /// the sender saw, for the log).
    pub header: Header,
    /// What to do ([`ControllerCommand::RESET`]).
    pub command: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

impl ControllerCommand {
    /// Leave Fault (or a silent hardware's fault) for Idle, holding the
    /// pose the arm then has.
    pub const RESET: u32 = 1;
    /// Result: a fault was latched and is cleared.
    pub const RESULT_CLEARED: u32 = 1;
    /// Result: there was no fault to clear (nothing changed).
    pub const RESULT_NO_FAULT: u32 = 2;
    /// Result: refused, the hardware is still silent (no state within
    /// `hardware_timeout_ms`); the fault stays latched.
    pub const RESULT_HARDWARE_SILENT: u32 = 3;
    /// Result: refused, not a known command.
    pub const RESULT_UNKNOWN: u32 = 4;

    /// A reset request with id `seq`, sent at `t_mono_ns` by a sender that
    /// saw hardware episode `episode`.
    pub fn reset(seq: u64, t_mono_ns: u64, episode: u64) -> Self {
        Self {
            header: Header::new(seq, t_mono_ns, 0, episode),
            command: Self::RESET,
            reserved: 0,
        }
    }

    /// Text of a `RESULT_*` code.
    pub fn result_name(result: u32) -> &'static str {
        match result {
            0 => "none",
            Self::RESULT_CLEARED => "cleared",
            Self::RESULT_NO_FAULT => "no fault to clear",
            Self::RESULT_HARDWARE_SILENT => "refused: the hardware is silent",
            Self::RESULT_UNKNOWN => "refused: unknown command",
            _ => "?",
        }
    }
}

message!(ControllerStatus, topics::STATUS, "ControllerStatus");
message!(
    ControllerCommand,
    topics::CONTROLLER_COMMAND,
    "ControllerCommand"
);

// Layouts (`Pod` rejects padding; these pin the sizes).
const _: () = assert!(size_of::<LatencyHistogram>() == 32 + 4 * HISTOGRAM_BINS);
const _: () =
    assert!(size_of::<ControllerStatus>() == H + 144 + 16 + 3 * size_of::<LatencyHistogram>());
const _: () = assert!(size_of::<ControllerCommand>() == H + 8);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles() {
        let mut h = LatencyHistogram::EMPTY;
        assert_eq!(h.quantile_us(0.5), 0.0);
        for us in 0..100u64 {
            h.record(us * 1000 + 500);
        }
        assert_eq!(h.count, 100);
        assert_eq!(h.quantile_us(0.5), 50.0);
        assert_eq!(h.quantile_us(0.99), 99.0);
        assert_eq!(h.quantile_us(1.0), 100.0);
        h.record(10_000_000);
        assert_eq!(h.overflow, 1);
        assert_eq!(h.quantile_us(1.0), 10_000.0);
        assert!((h.mean_us() - (4950.0 + 50.0 + 10_000.0) / 101.0).abs() < 1e-9);
    }
}
