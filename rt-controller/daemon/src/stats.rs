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
    /// Hardware states dropped because they did not advance (a step or a
    /// hardware time not above the last one's in the episode), outside a
    /// lockstep re-publication: they neither count as fresh nor keep the
    /// hardware from being found silent.
    pub hardware_states_stale: u64,
    /// Actions received.
    pub actions_received: u64,
    /// Actions refused before the control law saw them (another schema
    /// version).
    pub actions_garbage: u64,
    /// Actions refused for their address: outside lockstep any
    /// `apply_at_step` (it would hold the queue's front), in lockstep one
    /// that is not a policy-period boundary (the only steps the loop waits
    /// for an action at).
    pub actions_misaddressed: u64,
    /// Actions applied with their step cut by the speed bound (sooner than
    /// a policy period after the last applied one; `admission.rs`).
    pub actions_speed_cut: u64,
    /// Actions dropped from the full action queue (the oldest goes).
    pub actions_overflow: u64,
    /// Actions dropped as answers to another episode than the hardware's.
    pub actions_other_episode: u64,
    /// Actions dropped because the observation they answer is older than
    /// `timing.max_action_age_ms` on the hardware's clock.
    pub actions_too_old: u64,
    /// Actions dropped because they answer an observation the hardware has
    /// not made yet (a stamp after the current state's).
    pub actions_from_future: u64,
    /// Actions dropped because their sequence number is not above the
    /// newest one applied this episode.
    pub actions_replayed: u64,
    /// Actions dropped because their sequence number jumps more than
    /// `control::MAX_SEQ_JUMP` past the newest one applied this episode (a
    /// forged `u64::MAX` would otherwise starve the policy).
    pub actions_seq_jump: u64,
    /// Controller commands received.
    pub commands: u64,
    /// Resets refused (the hardware still silent, or an unknown command).
    pub commands_refused: u64,
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
    /// Actions dropped as stale, every reason together.
    pub fn actions_stale(&self) -> u64 {
        self.actions_other_episode
            + self.actions_too_old
            + self.actions_from_future
            + self.actions_replayed
            + self.actions_seq_jump
    }

    /// Nothing counted yet.
    pub const EMPTY: Self = Self {
        cycles: 0,
        overruns: 0,
        hardware_misses: 0,
        hardware_states_skipped: 0,
        hardware_states_stale: 0,
        actions_received: 0,
        actions_garbage: 0,
        actions_misaddressed: 0,
        actions_speed_cut: 0,
        actions_overflow: 0,
        actions_other_episode: 0,
        actions_too_old: 0,
        actions_from_future: 0,
        actions_replayed: 0,
        actions_seq_jump: 0,
        commands: 0,
        commands_refused: 0,
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
