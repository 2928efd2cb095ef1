//! The loop's statistics.

use shared_mem_schema::LatencyHistogram;

/// Statistics of the loop (cumulative since start).
pub struct Stats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles that finished after their next deadline.
    pub overruns: u64,
    /// Cycles without a new hardware state.
    pub hardware_misses: u64,
    /// Hardware states never controlled because a newer one had arrived by
    /// the cycle (counted from the gaps in the states' steps).
    pub hardware_states_skipped: u64,
    /// Actions received.
    pub actions_received: u64,
    /// Actions refused before the control law saw them (another schema
    /// version).
    pub actions_garbage: u64,
    /// Actions dropped from the full action queue (the oldest goes).
    pub actions_overflow: u64,
    /// Actions dropped as answers to an earlier episode.
    pub actions_stale: u64,
    /// Sensor frames and status messages that could not be published (the
    /// loop goes on: only the torque command is the arm's).
    pub publish_errors: u64,
    /// Failed receives of the action stream (the loop goes on; without
    /// actions the control law holds).
    pub receive_errors: u64,
    /// Wake-up latency past the deadline.
    pub wakeup: LatencyHistogram,
    /// Compute time per cycle.
    pub compute: LatencyHistogram,
    /// Action publication → first torque reflecting it.
    pub action_latency: LatencyHistogram,
}

impl Stats {
    /// Nothing counted yet.
    pub const EMPTY: Self = Self {
        cycles: 0,
        overruns: 0,
        hardware_misses: 0,
        hardware_states_skipped: 0,
        actions_received: 0,
        actions_garbage: 0,
        actions_overflow: 0,
        actions_stale: 0,
        publish_errors: 0,
        receive_errors: 0,
        wakeup: LatencyHistogram::EMPTY,
        compute: LatencyHistogram::EMPTY,
        action_latency: LatencyHistogram::EMPTY,
    };
}

/// Totals of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunSummary {
    /// Cycles run.
    pub cycles: u64,
    /// Overruns.
    pub overruns: u64,
}
