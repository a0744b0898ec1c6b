//! A task curriculum: episodes drawn more often from the tasks the policy fails.
//!
//! The benchmark mixes tasks a policy solves early (presses, twists) with tasks it fails for a
//! long time (thin handles, a fragile bowl); drawn uniformly, the hard tasks get 1/26 of the
//! experience each. In the spirit of Prioritized Level Replay (Jiang, Grefenstette and
//! Rocktaschel, ICML 2021), each task is drawn with weight `floor + (1 - success)`, where
//! `success` is its success rate over its last `window` training episodes (a task not seen
//! yet counts as failed). The floor keeps every task in the mix, so solved tasks are not
//! forgotten: with the default 0.2 a solved task is drawn 6 times less often than one never
//! solved. Off by default (the paper draws tasks uniformly).

use std::collections::VecDeque;

/// Training episodes per task that its success rate looks at.
pub const WINDOW: usize = 50;
/// The weight of a task solved every time.
pub const FLOOR: f32 = 0.2;

/// Per-task success over a sliding window, and the sampling weights it gives.
#[derive(Clone, Debug)]
pub struct TaskCurriculum {
    outcomes: Vec<VecDeque<bool>>,
    window: usize,
    floor: f32,
}

impl TaskCurriculum {
    /// A curriculum over `tasks` tasks with the default window and floor.
    pub fn new(tasks: usize) -> Self {
        Self::with(tasks, WINDOW, FLOOR)
    }

    pub fn with(tasks: usize, window: usize, floor: f32) -> Self {
        Self {
            outcomes: vec![VecDeque::with_capacity(window); tasks],
            window: window.max(1),
            floor,
        }
    }

    /// Each task's recent outcomes, oldest first (a checkpoint of the training state keeps
    /// them).
    pub fn outcomes(&self) -> Vec<Vec<bool>> {
        self.outcomes
            .iter()
            .map(|list| list.iter().copied().collect())
            .collect()
    }

    /// Goes on with these outcomes per task (extra tasks ignored, the newest `window` kept).
    pub fn restore(&mut self, outcomes: &[Vec<bool>]) {
        for (list, saved) in self.outcomes.iter_mut().zip(outcomes) {
            list.clear();
            let skip = saved.len().saturating_sub(self.window);
            list.extend(&saved[skip..]);
        }
    }

    /// Records an episode of task `task` (ignored when out of range).
    pub fn record(&mut self, task: usize, success: bool) {
        if let Some(list) = self.outcomes.get_mut(task) {
            if list.len() == self.window {
                list.pop_front();
            }
            list.push_back(success);
        }
    }

    /// Episodes of `task` in its window (0 for a task out of range).
    pub fn episodes(&self, task: usize) -> usize {
        self.outcomes.get(task).map_or(0, VecDeque::len)
    }

    /// Success rate of `task` over its window (0 before its first episode).
    pub fn success_rate(&self, task: usize) -> f32 {
        match self.outcomes.get(task) {
            Some(list) if !list.is_empty() => {
                list.iter().filter(|&&s| s).count() as f32 / list.len() as f32
            }
            _ => 0.0,
        }
    }

    /// The sampling weight of every task: `floor + (1 - success rate)`.
    pub fn weights(&self) -> Vec<f32> {
        (0..self.outcomes.len())
            .map(|t| self.floor + (1.0 - self.success_rate(t)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_tasks_weigh_more_and_solved_ones_keep_the_floor() {
        let mut c = TaskCurriculum::with(3, 4, 0.2);
        for _ in 0..4 {
            c.record(0, true);
            c.record(1, false);
        }
        c.record(2, true);
        c.record(2, false);
        c.record(7, true); // out of range: ignored
        let w = c.weights();
        assert!((w[0] - 0.2).abs() < 1e-6, "{w:?}");
        assert!((w[1] - 1.2).abs() < 1e-6, "{w:?}");
        assert!((w[2] - 0.7).abs() < 1e-6, "{w:?}");
    }

    #[test]
    fn the_window_forgets_old_episodes() {
        let mut c = TaskCurriculum::with(1, 2, 0.2);
        c.record(0, false);
        c.record(0, true);
        c.record(0, true);
        assert_eq!(c.success_rate(0), 1.0);
        assert_eq!(c.episodes(0), 2);
        assert_eq!(TaskCurriculum::new(2).success_rate(1), 0.0);
        assert_eq!(TaskCurriculum::new(2).episodes(1), 0);
        assert_eq!(c.episodes(5), 0);
    }
}
