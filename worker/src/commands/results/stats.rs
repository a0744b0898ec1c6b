//! Interval estimates as the field reports them since Agarwal et al. (NeurIPS 2021, "Deep RL
//! at the Edge of the Statistical Precipice"), computed as their `rliable` library computes
//! them (`rliable/metrics.py`, `rliable/library.py`), on a score matrix of runs x tasks:
//!
//! - aggregates: the interquartile mean (`scipy.stats.trim_mean(scores, 0.25, axis=None)`),
//!   the mean, the median of the tasks' mean scores and the optimality gap (`gamma -
//!   mean(min(scores, gamma))`, gamma 1);
//! - their 95% intervals by the stratified bootstrap (runs resampled with replacement within
//!   each task, the percentile method with numpy's linear interpolation), as
//!   `rly.get_interval_estimates` with `StratifiedBootstrap`;
//! - the probability of improvement `P(X > Y)`: per task the Mann-Whitney U of X's runs
//!   against Y's over the number of pairs (ties count a half), averaged over tasks, with its
//!   interval from both algorithms' runs resampled independently within each task
//!   (`StratifiedIndependentBootstrap`);
//! - the performance profile: the share of run x task scores above each threshold.
//!
//! The bootstrap draws from a seeded ChaCha8 stream, so a report rebuilds byte for byte; its
//! bounds agree with rliable's (another generator) to the bootstrap's own precision
//! (`python/tests/test_rliable.py` checks 0.02 at the same number of samples).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// rliable's default number of bootstrap samples (`get_interval_estimates(reps=50000)`).
pub const REPS: usize = 50_000;
/// The interval's size: rliable's default 95%.
pub const CONFIDENCE: f64 = 0.95;

/// A score matrix: `runs` rows of `tasks` scores each, row by row.
#[derive(Clone, Debug, PartialEq)]
pub struct Scores {
    pub runs: usize,
    pub tasks: usize,
    pub data: Vec<f64>,
}

impl Scores {
    /// The matrix of `rows` (one per run, each with the same number of tasks); `None` when
    /// empty or ragged.
    pub fn new(rows: &[Vec<f64>]) -> Option<Self> {
        let tasks = rows.first()?.len();
        if tasks == 0 || rows.iter().any(|r| r.len() != tasks) {
            return None;
        }
        Some(Self {
            runs: rows.len(),
            tasks,
            data: rows.concat(),
        })
    }

    fn at(&self, run: usize, task: usize) -> f64 {
        self.data[run * self.tasks + task]
    }

    /// One stratified resample into `into` (of the same shape): per task, `runs` runs drawn
    /// with replacement.
    fn resample(&self, rng: &mut ChaCha8Rng, into: &mut Scores) {
        into.runs = self.runs;
        into.tasks = self.tasks;
        into.data.clear();
        into.data.resize(self.data.len(), 0.0);
        for task in 0..self.tasks {
            for run in 0..self.runs {
                let pick = rng.random_range(0..self.runs);
                into.data[run * self.tasks + task] = self.at(pick, task);
            }
        }
    }

    fn empty() -> Self {
        Self {
            runs: 0,
            tasks: 0,
            data: Vec::new(),
        }
    }
}

/// The interquartile mean of every score: `scipy.stats.trim_mean(x, 0.25, axis=None)`, the
/// mean after `floor(n / 4)` scores are cut from each end of the sorted scores.
pub fn iqm(scores: &Scores) -> f64 {
    let mut sorted = scores.data.clone();
    sorted.sort_by(f64::total_cmp);
    let cut = sorted.len() / 4;
    average(&sorted[cut..sorted.len() - cut])
}

fn average(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The mean of every score.
pub fn mean(scores: &Scores) -> f64 {
    average(&scores.data)
}

/// The median over tasks of each task's mean over runs (rliable's `aggregate_median`; numpy's
/// median: the mean of the two middle values of an even count).
pub fn median(scores: &Scores) -> f64 {
    let task_means: Vec<f64> = (0..scores.tasks)
        .map(|t| (0..scores.runs).map(|r| scores.at(r, t)).sum::<f64>() / scores.runs as f64)
        .collect();
    percentile(&task_means, 50.0)
}

/// How far the scores fall short of 1 on average, counting none above it.
pub fn optimality_gap(scores: &Scores) -> f64 {
    1.0 - scores.data.iter().map(|s| s.min(1.0)).sum::<f64>() / scores.data.len() as f64
}

/// numpy's `percentile(x, q)` with its default linear interpolation.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let position = q / 100.0 * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = (below + 1).min(sorted.len() - 1);
    let share = position - below as f64;
    sorted[below] + (sorted[above] - sorted[below]) * share
}

/// The aggregates rliable reports, in the order [`AGGREGATES`] names them.
pub type Aggregate = fn(&Scores) -> f64;
pub const AGGREGATES: [(&str, Aggregate); 4] = [
    ("iqm", iqm),
    ("mean", mean),
    ("median", median),
    ("optimality_gap", optimality_gap),
];

/// A point estimate with its interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    pub point: f64,
    pub low: f64,
    pub high: f64,
}

/// The percentile interval of `samples` of size [`CONFIDENCE`].
fn interval(samples: &[f64]) -> (f64, f64) {
    let tail = (1.0 - CONFIDENCE) / 2.0 * 100.0;
    (percentile(samples, tail), percentile(samples, 100.0 - tail))
}

/// Each aggregate of [`AGGREGATES`] with its stratified-bootstrap interval, `reps` samples
/// from `seed`.
pub fn aggregates(scores: &Scores, reps: usize, seed: u64) -> Vec<(&'static str, Estimate)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut samples = vec![Vec::with_capacity(reps); AGGREGATES.len()];
    let mut buffer = Scores::empty();
    for _ in 0..reps {
        scores.resample(&mut rng, &mut buffer);
        for (k, (_, f)) in AGGREGATES.iter().enumerate() {
            samples[k].push(f(&buffer));
        }
    }
    AGGREGATES
        .iter()
        .zip(samples)
        .map(|((name, f), samples)| {
            let (low, high) = interval(&samples);
            let point = f(scores);
            (*name, Estimate { point, low, high })
        })
        .collect()
}

/// `P(X > Y)`: per task, the share of run pairs where X scores more (a tie counts a half),
/// averaged over tasks (rliable's `probability_of_improvement`).
pub fn probability_of_improvement(x: &Scores, y: &Scores) -> f64 {
    let per_task = (0..x.tasks).map(|task| {
        let mut wins = 0.0;
        for i in 0..x.runs {
            for j in 0..y.runs {
                let (a, b) = (x.at(i, task), y.at(j, task));
                wins += if a > b {
                    1.0
                } else if a == b {
                    0.5
                } else {
                    0.0
                };
            }
        }
        wins / (x.runs * y.runs) as f64
    });
    per_task.sum::<f64>() / x.tasks as f64
}

/// [`probability_of_improvement`] with its interval: each algorithm's runs resampled
/// independently within each task, `reps` samples from `seed`.
pub fn improvement(x: &Scores, y: &Scores, reps: usize, seed: u64) -> Estimate {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut bx, mut by) = (Scores::empty(), Scores::empty());
    let samples: Vec<f64> = (0..reps)
        .map(|_| {
            x.resample(&mut rng, &mut bx);
            y.resample(&mut rng, &mut by);
            probability_of_improvement(&bx, &by)
        })
        .collect();
    let (low, high) = interval(&samples);
    Estimate {
        point: probability_of_improvement(x, y),
        low,
        high,
    }
}

/// The performance profile: per threshold, the share of every run x task score above it.
pub fn profile(scores: &Scores, thresholds: &[f64]) -> Vec<f64> {
    let n = scores.data.len() as f64;
    thresholds
        .iter()
        .map(|tau| scores.data.iter().filter(|s| **s > *tau).count() as f64 / n)
        .collect()
}

/// `crm results --stats-of FILE`'s input: score matrices by algorithm (runs x tasks), the
/// algorithm compared against the rest, the bootstrap's samples and seed.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatsRequest {
    pub scores: std::collections::BTreeMap<String, Vec<Vec<f64>>>,
    pub reference: Option<String>,
    #[serde(default = "default_reps")]
    pub reps: usize,
    #[serde(default)]
    pub seed: u64,
}

fn default_reps() -> usize {
    REPS
}

/// The figures of a [`StatsRequest`] as JSON: per algorithm each aggregate's point and
/// interval, and `P(reference > other)` with its interval per other algorithm.
pub fn answer(request: &StatsRequest) -> anyhow::Result<serde_json::Value> {
    let mut matrices = std::collections::BTreeMap::new();
    for (algorithm, rows) in &request.scores {
        let scores = Scores::new(rows).ok_or_else(|| {
            anyhow::anyhow!("scores.{algorithm}: runs must be non-empty rows of equal length")
        })?;
        matrices.insert(algorithm.clone(), scores);
    }
    let mut out = serde_json::Map::new();
    for (algorithm, scores) in &matrices {
        let figures: serde_json::Map<String, serde_json::Value> =
            aggregates(scores, request.reps, request.seed)
                .into_iter()
                .map(|(name, e)| (name.to_string(), serde_json::json!(e)))
                .collect();
        out.insert(algorithm.clone(), figures.into());
    }
    let mut improvements = serde_json::Map::new();
    if let Some(reference) = &request.reference {
        let x = matrices
            .get(reference)
            .ok_or_else(|| anyhow::anyhow!("reference: {reference:?} has no scores"))?;
        for (other, y) in matrices.iter().filter(|(name, _)| *name != reference) {
            if y.tasks != x.tasks {
                anyhow::bail!(
                    "scores.{other}: {} tasks, {reference} has {}",
                    y.tasks,
                    x.tasks
                );
            }
            let e = improvement(x, y, request.reps, request.seed);
            improvements.insert(other.clone(), serde_json::json!(e));
        }
    }
    Ok(serde_json::json!({"aggregates": out, "improvement": improvements}))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_aggregates_are_scipys_and_numpys() {
        // trim_mean of 0..8 at 0.25 cuts 2 from each end: mean(2, 3, 4, 5) = 3.5.
        let row = |v: Vec<f64>| Scores::new(&[v]).expect("one run");
        assert_eq!(iqm(&row((0..8).map(f64::from).collect())), 3.5);
        // 10 scores: floor(2.5) = 2 cut from each end.
        assert_eq!(iqm(&row((0..10).map(f64::from).collect())), 4.5);
        // The median of the tasks' means over runs: tasks average 2, 1, 2.5, 10.
        let two =
            Scores::new(&[vec![3.0, 1.0, 2.0, 10.0], vec![1.0, 1.0, 3.0, 10.0]]).expect("two");
        assert_eq!(median(&two), 2.25);
        assert_eq!(percentile(&[0.0, 10.0], 2.5), 0.25);
        assert!((optimality_gap(&row(vec![0.5, 1.0, 1.5])) - 1.0 / 6.0).abs() < 1e-15);
    }

    #[test]
    fn improvement_counts_ties_as_halves_and_averages_tasks() {
        let x = Scores::new(&[vec![1.0, 0.5], vec![0.0, 0.5]]).expect("x");
        let y = Scores::new(&[vec![0.5, 0.5]]).expect("y");
        // task 0: 1 > 0.5, 0 < 0.5 -> 0.5; task 1: two ties -> 0.5.
        assert_eq!(probability_of_improvement(&x, &y), 0.5);
        let better = Scores::new(&[vec![1.0, 1.0]]).expect("better");
        assert_eq!(probability_of_improvement(&better, &y), 1.0);
        let e = improvement(&better, &y, 200, 1);
        assert_eq!((e.point, e.low, e.high), (1.0, 1.0, 1.0));
    }

    #[test]
    fn intervals_hold_the_point_and_narrow_with_agreeing_runs() {
        let rows: Vec<Vec<f64>> = (0..5)
            .map(|r| (0..6).map(|t| (r * 6 + t) as f64 / 30.0).collect())
            .collect();
        let scores = Scores::new(&rows).expect("scores");
        for (name, e) in aggregates(&scores, 2000, 7) {
            assert!(e.low <= e.point && e.point <= e.high, "{name}: {e:?}");
        }
        let same = Scores::new(&vec![vec![0.25; 4]; 5]).expect("same");
        let e = aggregates(&same, 100, 7)[0].1;
        assert_eq!((e.low, e.high), (0.25, 0.25));
        assert_eq!(aggregates(&scores, 300, 3), aggregates(&scores, 300, 3));
        assert_eq!(profile(&same, &[0.0, 0.25, 0.5]), [1.0, 0.0, 0.0]);
    }
}
