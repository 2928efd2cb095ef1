//! The daemon's fixed-capacity FIFO of policy actions.

use shared_mem_schema::PolicyAction;

/// Whether `a` may be queued while the hardware is in `episode`: an action
/// names the episode of the observation it answers, and one of another
/// episode is stale (episode 0 is hw-sim's idle start, an episode like any
/// other). Before any state, anything may wait in the queue.
pub(crate) fn for_episode(a: &PolicyAction, episode: Option<u64>) -> bool {
    episode.is_none_or(|e| e == a.header.episode)
}

/// Fixed-capacity FIFO of actions (no allocation after construction).
pub(crate) struct ActionQueue {
    items: [Option<PolicyAction>; 16],
    head: usize,
    len: usize,
}

impl ActionQueue {
    pub(crate) fn new() -> Self {
        Self {
            items: [None; 16],
            head: 0,
            len: 0,
        }
    }

    /// Appends; when full the oldest is dropped (returns true then).
    pub(crate) fn push(&mut self, a: PolicyAction) -> bool {
        let cap = self.items.len();
        let dropped = self.len == cap;
        if dropped {
            self.head = (self.head + 1) % cap;
            self.len -= 1;
        }
        self.items[(self.head + self.len) % cap] = Some(a);
        self.len += 1;
        dropped
    }

    pub(crate) fn front(&self) -> Option<&PolicyAction> {
        (self.len > 0)
            .then(|| self.items[self.head].as_ref())
            .flatten()
    }

    pub(crate) fn pop(&mut self) -> Option<PolicyAction> {
        if self.len == 0 {
            return None;
        }
        let a = self.items[self.head].take();
        self.head = (self.head + 1) % self.items.len();
        self.len -= 1;
        a
    }

    pub(crate) fn clear(&mut self) {
        while self.pop().is_some() {}
    }

    /// The next action for hardware step `step`: actions addressed to a
    /// later step wait for it.
    pub(crate) fn next_for(&mut self, step: u64) -> Option<PolicyAction> {
        match self.front() {
            Some(a) if a.apply_at_step == 0 || a.apply_at_step <= step => self.pop(),
            _ => None,
        }
    }

    /// Drops actions addressed to steps before `step`.
    pub(crate) fn drop_before(&mut self, step: u64) {
        while self
            .front()
            .is_some_and(|a| a.apply_at_step != 0 && a.apply_at_step < step)
        {
            self.pop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn action(seq: u64, at: u64) -> PolicyAction {
        let mut a = PolicyAction::new(seq, 0, [0.0; 4]);
        a.apply_at_step = at;
        a
    }

    #[test]
    fn overflow_drops_the_oldest_and_addressed_actions_wait() {
        let mut q = ActionQueue::new();
        for s in 1..=17 {
            assert_eq!(q.push(action(s, 0)), s == 17);
        }
        assert_eq!(q.pop().map(|a| a.header.seq), Some(2));
        q.clear();
        q.push(action(1, 50));
        q.push(action(2, 100));
        assert!(q.next_for(49).is_none());
        assert_eq!(q.next_for(50).map(|a| a.header.seq), Some(1));
        q.drop_before(101);
        assert!(q.front().is_none());
    }

    #[test]
    fn actions_of_another_episode_are_stale() {
        let mut a = action(1, 50);
        assert!(!for_episode(&a, Some(2)), "episode 0 is an episode");
        assert!(for_episode(&a, Some(0)));
        a.header.episode = 1;
        assert!(for_episode(&a, None));
        assert!(for_episode(&a, Some(1)));
        assert!(!for_episode(&a, Some(2)));
    }
}
