//! Rate and speed admission of policy actions: whoever publishes on the
//! action service, the reference moves no faster than a policy at its rate
//! and its largest step would move it.
//!
//! The queue's checks (episode, age, sequence) compare values any peer
//! subscribed to the sensor frames can copy, so they cannot tell a second
//! publisher from the policy. What this bounds instead is the effect: an
//! action is applied at most every `min_interval_steps` hardware steps, and
//! its step is cut to `max_step × k / period` for `k` steps since the last
//! applied one. A 20 Hz policy (k = period) is never cut; a peer at 1 kHz
//! moves the target at most one largest step per policy period.

/// The last applied action's place, per episode.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RateGate {
    last: Option<(u64, u64)>,
}

impl RateGate {
    /// Whether an action may be applied at hardware `step` of `episode`:
    /// the first of an episode always, later ones `min_interval` steps after
    /// the last applied (a held action waits at the queue's front).
    pub(crate) fn due(&self, episode: u64, step: u64, min_interval: u64) -> bool {
        match self.last {
            // A step behind the last is a restarted stream: due.
            Some((e, s)) if e == episode && step >= s => step - s >= min_interval,
            _ => true,
        }
    }

    /// Cuts `delta`'s position and roll steps to their share of the largest
    /// (`max_step_m`, `max_step_rad`) for the steps since the last applied
    /// action, `period` of them giving the whole. Non-finite components are
    /// left for the supervisor to refuse (a clamp would turn a NaN into a
    /// bound). Returns whether anything was cut.
    pub(crate) fn bound(
        &self,
        delta: &mut [f64; 4],
        at: (u64, u64),
        period: u64,
        max_step_m: f64,
        max_step_rad: f64,
    ) -> bool {
        let share = match self.last {
            Some((e, s)) if e == at.0 && at.1 >= s && at.1 - s < period => {
                (at.1 - s) as f64 / period as f64
            }
            _ => return false,
        };
        let mut cut = false;
        for (i, x) in delta.iter_mut().enumerate() {
            let b = share * if i < 3 { max_step_m } else { max_step_rad };
            if x.is_finite() && x.abs() > b {
                *x = x.signum() * b;
                cut = true;
            }
        }
        cut
    }

    /// Records an action applied at hardware `step` of `episode`.
    pub(crate) fn applied(&mut self, episode: u64, step: u64) {
        self.last = Some((episode, step));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gate_holds_until_the_interval_and_opens_for_a_new_episode() {
        let mut g = RateGate::default();
        assert!(g.due(1, 7, 25));
        g.applied(1, 7);
        assert!(!g.due(1, 8, 25));
        assert!(!g.due(1, 31, 25));
        assert!(g.due(1, 32, 25));
        assert!(g.due(2, 8, 25), "another episode's first");
        // A step behind the last is a restarted stream (hw-sim after a
        // hardware loss counts from its start): due, and not cut.
        assert!(g.due(1, 3, 25));
        let mut d = [0.01, 0.0, 0.0, 0.0];
        assert!(!g.bound(&mut d, (1, 3), 50, 0.01, 0.05));
    }

    #[test]
    fn steps_are_cut_to_their_share_of_the_period() {
        let mut g = RateGate::default();
        let mut d = [0.01, -0.01, 0.002, 0.05];
        assert!(
            !g.bound(&mut d, (1, 0), 50, 0.01, 0.05),
            "the first is whole"
        );
        g.applied(1, 0);
        assert!(g.bound(&mut d, (1, 25), 50, 0.01, 0.05));
        assert_eq!(d, [0.005, -0.005, 0.002, 0.025]);
        let mut d = [0.01, f64::NAN, 0.0, 0.0];
        g.bound(&mut d, (1, 5), 50, 0.01, 0.05);
        assert!((d[0] - 0.001).abs() < 1e-15);
        assert!(d[1].is_nan(), "a NaN is left for the supervisor");
        let mut d = [0.01; 4];
        assert!(!g.bound(&mut d, (1, 50), 50, 0.01, 0.05), "a whole period");
        assert!(!g.bound(&mut d, (2, 1), 50, 0.01, 0.05), "another episode");
    }
}
