//! Running normalization, as Stable-Baselines3's `VecNormalize` does it (the authors trained
//! with it): observations by a running mean and variance per feature, rewards by the running
//! standard deviation of the discounted return.
//!
//! Observations are normalized per stage and per feature of that stage's abstraction
//! (`phi_i` picks different features in different stages, and the same feature is
//! distributed differently in approach and in grasp), then clipped to `+/-10` (SB3's
//! `clip_obs`). The statistics travel in the checkpoint, so evaluation, recording and
//! serving see the inputs the policy was trained on.
//!
//! Rewards: both parts, intra-stage and transition, are divided by the same factor, so the
//! ratio the machine sets between them holds (SB3 would also clip the scaled reward at 10,
//! which would cut the transition rewards; we do not clip).

/// SB3 `RunningMeanStd`'s initial count (`epsilon = 1e-4`).
const INITIAL_COUNT: f64 = 1e-4;
/// SB3 `VecNormalize`'s `epsilon` under the square root.
const EPSILON: f64 = 1e-8;
/// SB3 `VecNormalize`'s `clip_obs`.
pub const CLIP_OBS: f32 = 10.0;

/// Running mean and variance of a vector of features (Chan et al.'s parallel update, as SB3's
/// `RunningMeanStd.update_from_moments`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunningMeanStd {
    pub count: f64,
    pub mean: Vec<f64>,
    pub var: Vec<f64>,
}

impl RunningMeanStd {
    pub fn new(width: usize) -> Self {
        Self {
            count: INITIAL_COUNT,
            mean: vec![0.0; width],
            var: vec![1.0; width],
        }
    }

    /// Folds in a batch of rows (each at least `width` long; extra values ignored).
    pub fn update<'a>(&mut self, rows: impl Iterator<Item = &'a [f32]> + Clone) {
        let width = self.mean.len();
        let n = rows.clone().count() as f64;
        if n == 0.0 {
            return;
        }
        let mut batch_mean = vec![0.0f64; width];
        for row in rows.clone() {
            for (m, &x) in batch_mean.iter_mut().zip(row) {
                *m += f64::from(x);
            }
        }
        batch_mean.iter_mut().for_each(|m| *m /= n);
        let mut batch_var = vec![0.0f64; width];
        for row in rows {
            for ((v, &x), m) in batch_var.iter_mut().zip(row).zip(&batch_mean) {
                *v += (f64::from(x) - m).powi(2);
            }
        }
        batch_var.iter_mut().for_each(|v| *v /= n);
        let total = self.count + n;
        for k in 0..width {
            let delta = batch_mean[k] - self.mean[k];
            let m2 = self.var[k] * self.count
                + batch_var[k] * n
                + delta * delta * self.count * n / total;
            self.mean[k] += delta * n / total;
            self.var[k] = m2 / total;
        }
        self.count = total;
    }
}

/// Observation statistics per stage, over the padded abstract state.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsNorm {
    width: usize,
    stages: Vec<RunningMeanStd>,
}

impl ObsNorm {
    /// Fresh statistics (mean 0, variance 1) for `stages` stages of `width` features.
    pub fn new(stages: usize, width: usize) -> Self {
        Self {
            width,
            stages: (0..stages).map(|_| RunningMeanStd::new(width)).collect(),
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn stage_count(&self) -> usize {
        self.stages.len()
    }

    pub fn stage(&self, stage: usize) -> Option<&RunningMeanStd> {
        self.stages.get(stage)
    }

    /// Folds in a batch of abstract states with their stages; states longer than the width
    /// or stages out of range are skipped.
    pub fn update(&mut self, states: &[Vec<f32>], stages: &[usize]) {
        for (stage, stats) in self.stages.iter_mut().enumerate() {
            let rows = states
                .iter()
                .zip(stages)
                .filter(|(s, k)| **k == stage && s.len() <= self.width)
                .map(|(s, _)| s.as_slice());
            // Slots past a stage's abstraction are padding; they stay at mean 0, variance 1.
            let Some(len) = rows.clone().next().map(<[f32]>::len) else {
                continue;
            };
            let mut part = RunningMeanStd {
                count: stats.count,
                mean: stats.mean[..len].to_vec(),
                var: stats.var[..len].to_vec(),
            };
            part.update(rows.filter(|r| r.len() == len));
            stats.count = part.count;
            stats.mean[..len].copy_from_slice(&part.mean);
            stats.var[..len].copy_from_slice(&part.var);
        }
    }

    /// Writes the normalized, clipped `state` of `stage` into `out` (the state's length).
    pub fn normalize_into(&self, state: &[f32], stage: usize, out: &mut [f32]) {
        let Some(stats) = self.stages.get(stage) else {
            out.copy_from_slice(state);
            return;
        };
        for (k, (o, &x)) in out.iter_mut().zip(state).enumerate() {
            let z = (f64::from(x) - stats.mean[k]) / (stats.var[k] + EPSILON).sqrt();
            *o = (z as f32).clamp(-CLIP_OBS, CLIP_OBS);
        }
    }

    /// The statistics as flat arrays for a checkpoint: means and variances `[stages x
    /// width]` and counts `[stages]`.
    pub fn to_parts(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mean = self.stages.iter().flat_map(|s| s.mean.clone()).collect();
        let var = self.stages.iter().flat_map(|s| s.var.clone()).collect();
        let count = self.stages.iter().map(|s| s.count).collect();
        (mean, var, count)
    }

    /// Rebuilds statistics from [`Self::to_parts`]; `None` when the lengths do not fit or a
    /// value is not finite (or a variance negative).
    pub fn from_parts(width: usize, mean: &[f64], var: &[f64], count: &[f64]) -> Option<Self> {
        let stages = count.len();
        if mean.len() != stages * width || var.len() != stages * width {
            return None;
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(finite(mean) && finite(var) && finite(count)) || var.iter().any(|&v| v < 0.0) {
            return None;
        }
        Some(Self {
            width,
            stages: (0..stages)
                .map(|s| RunningMeanStd {
                    count: count[s],
                    mean: mean[s * width..(s + 1) * width].to_vec(),
                    var: var[s * width..(s + 1) * width].to_vec(),
                })
                .collect(),
        })
    }
}

/// Reward scaling by the running standard deviation of each environment's discounted return
/// (SB3 `VecNormalize(norm_reward=True)`), one factor for both reward parts.
#[derive(Clone, Debug)]
pub struct RewardScaler {
    gamma: f64,
    returns: Vec<f64>,
    stats: RunningMeanStd,
}

impl RewardScaler {
    pub fn new(gamma: f32) -> Self {
        Self {
            gamma: f64::from(gamma),
            returns: Vec::new(),
            stats: RunningMeanStd::new(1),
        }
    }

    /// Folds in one environment's next reward (both parts summed) and whether its episode
    /// ended with it.
    pub fn observe(&mut self, env: usize, reward: f32, episode_ended: bool) {
        if self.returns.len() <= env {
            self.returns.resize(env + 1, 0.0);
        }
        self.returns[env] = self.returns[env] * self.gamma + f64::from(reward);
        let value = [self.returns[env] as f32];
        self.stats.update(std::iter::once(&value[..]));
        if episode_ended {
            self.returns[env] = 0.0;
        }
    }

    /// The running discounted return of each environment and the statistics of the returns
    /// seen: everything the next factor depends on.
    pub fn state(&self) -> (Vec<f64>, RunningMeanStd) {
        (self.returns.clone(), self.stats.clone())
    }

    /// Goes on from a [`Self::state`].
    pub fn restore(&mut self, returns: Vec<f64>, stats: RunningMeanStd) {
        self.returns = returns;
        self.stats = stats;
    }

    /// The factor every reward is multiplied by: `1 / sqrt(var(return) + eps)`.
    pub fn factor(&self) -> f32 {
        (1.0 / (self.stats.var[0] + EPSILON).sqrt()) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_moments_equal_the_batch_moments() {
        let rows: Vec<Vec<f32>> = (0..100)
            .map(|i| vec![i as f32, (i * i) as f32 * 0.01])
            .collect();
        let mut stats = RunningMeanStd::new(2);
        // Three uneven batches give the moments of all rows at once.
        stats.update(rows[..10].iter().map(Vec::as_slice));
        stats.update(rows[10..55].iter().map(Vec::as_slice));
        stats.update(rows[55..].iter().map(Vec::as_slice));
        for k in 0..2 {
            let xs: Vec<f64> = rows.iter().map(|r| f64::from(r[k])).collect();
            let mean = xs.iter().sum::<f64>() / 100.0;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 100.0;
            // The initial pseudo-count (1e-4 at mean 0, variance 1) weighs almost nothing.
            assert!((stats.mean[k] - mean).abs() < 1e-3 * mean.abs().max(1.0));
            assert!((stats.var[k] - var).abs() < 1e-3 * var.max(1.0));
        }
        assert!((stats.count - 100.0).abs() < 1e-3);
    }

    #[test]
    fn observations_are_normalized_per_stage_and_clipped() {
        let mut norm = ObsNorm::new(2, 3);
        // Stage 0 sees two features around 5 +/- 1; stage 1 three around 0 +/- 100.
        let states = vec![
            vec![4.0, 4.0],
            vec![6.0, 6.0],
            vec![100.0, -100.0, 0.0],
            vec![-100.0, 100.0, 0.0],
        ];
        norm.update(&states, &[0, 0, 1, 1]);
        let mut out = [0.0; 2];
        norm.normalize_into(&[6.0, 4.0], 0, &mut out);
        assert!(
            (out[0] - 1.0).abs() < 1e-3 && (out[1] + 1.0).abs() < 1e-3,
            "{out:?}"
        );
        let mut out = [0.0; 3];
        norm.normalize_into(&[100.0, 5000.0, 0.0], 1, &mut out);
        assert!((out[0] - 1.0).abs() < 1e-3, "{out:?}");
        assert_eq!(out[1], CLIP_OBS);
        // The padding slot of stage 0 was never updated.
        let stage0 = norm.stage(0).expect("stage 0");
        assert_eq!((stage0.mean[2], stage0.var[2]), (0.0, 1.0));
    }

    #[test]
    fn statistics_round_trip_through_flat_parts() {
        let mut norm = ObsNorm::new(3, 2);
        norm.update(&[vec![1.0, 2.0], vec![3.0]], &[0, 2]);
        let (mean, var, count) = norm.to_parts();
        let back = ObsNorm::from_parts(2, &mean, &var, &count).expect("parts");
        let mut a = [0.0; 2];
        let mut b = [0.0; 2];
        norm.normalize_into(&[0.5, -0.5], 0, &mut a);
        back.normalize_into(&[0.5, -0.5], 0, &mut b);
        assert_eq!(a, b);
        assert!(ObsNorm::from_parts(2, &mean[1..], &var, &count).is_none());
        assert!(ObsNorm::from_parts(2, &mean, &[-1.0; 6], &count).is_none());
    }

    #[test]
    fn reward_scaling_keeps_the_ratio_of_the_reward_parts() {
        let mut scaler = RewardScaler::new(0.99);
        for t in 0..500 {
            let ended = t % 50 == 49;
            scaler.observe(t % 4, if ended { 500.0 } else { -1.0 }, ended);
        }
        let factor = scaler.factor();
        assert!(factor > 0.0 && factor < 1.0, "{factor}");
        // One factor for both parts: a transition reward of 500 and an intra-stage reward
        // of -2 keep their ratio of -250.
        let (transition, intra) = (500.0 * factor, -2.0 * factor);
        assert!((transition / intra + 250.0).abs() < 1e-3);
    }
}
