//! The paper's early-stop rule over recent episodes (section V-B-2).

/// The paper's early-stop rule: stop when the most recent `window` episodes reach a success
/// rate of at least `threshold` (section V-B-2).
#[derive(Clone, Debug)]
pub struct EarlyStop {
    window: usize,
    threshold: f32,
    recent: std::collections::VecDeque<bool>,
}

impl EarlyStop {
    pub fn new(window: usize, threshold: f32) -> Self {
        Self {
            window: window.max(1),
            threshold,
            recent: std::collections::VecDeque::with_capacity(window.max(1)),
        }
    }

    /// Records an episode; returns whether training should stop now.
    pub fn record(&mut self, success: bool) -> bool {
        if self.recent.len() == self.window {
            self.recent.pop_front();
        }
        self.recent.push_back(success);
        self.should_stop()
    }

    /// A full window at or above the threshold.
    pub fn should_stop(&self) -> bool {
        self.recent.len() == self.window && self.success_rate() >= self.threshold
    }

    /// The window's outcomes, oldest first (a checkpoint of the training state keeps them).
    pub fn outcomes(&self) -> Vec<bool> {
        self.recent.iter().copied().collect()
    }

    /// Goes on with these outcomes in the window (the newest `window` of them).
    pub fn restore(&mut self, outcomes: &[bool]) {
        self.recent.clear();
        let skip = outcomes.len().saturating_sub(self.window);
        self.recent.extend(&outcomes[skip..]);
    }

    /// Success rate over the episodes in the window so far.
    pub fn success_rate(&self) -> f32 {
        if self.recent.is_empty() {
            return 0.0;
        }
        self.recent.iter().filter(|&&s| s).count() as f32 / self.recent.len() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn early_stop_needs_a_full_window_at_99_percent() {
        let mut rule = EarlyStop::new(100, 0.99);
        for _ in 0..99 {
            assert!(!rule.record(true), "a window of 99 is not full");
        }
        assert!(rule.record(true));
        // One failure in the last 100 is still 99%; a second drops below.
        assert!(rule.record(false));
        assert!(!rule.record(false));
        for _ in 0..98 {
            rule.record(true);
        }
        assert!(!rule.should_stop(), "two failures still in the window");
        assert!(rule.record(true), "one failure left in the window: 99%");
        assert!((rule.success_rate() - 0.99).abs() < 1e-6);
    }
}
