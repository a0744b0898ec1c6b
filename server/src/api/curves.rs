//! `GET /api/v1/charts`: training curves of one or several runs as an SVG image, for the
//! dashboard and for anyone who wants a plot without a notebook. Query: `runs=1,2` (train job
//! ids), `metric` (see [`Metric`]), `x=steps|episodes|wall`, `smooth` in [0, 0.99], `group=seeds`
//! (runs whose configuration differs only in the seed become one mean curve with a ±1 std
//! band), `width`, `height`.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;

use axum::extract::{Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use crm_api::Iteration;

use super::error::ApiError;
use crate::AppState;
use crate::charts::{Chart, Series, mean_and_std, render, smooth};
use crate::store::Job;

/// The curves a chart can show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    Success,
    EpisodeLength,
    Return,
    /// Intra-stage and transition reward per episode, two curves per run.
    RewardSplit,
    /// Share of steps in each CRM stage, one curve per stage.
    Stages,
    /// Training success of the tasks a run is weakest on, one curve per task.
    Tasks,
    PolicyLoss,
    ValueLoss,
    Entropy,
    ApproxKl,
    LearningRate,
    StepsPerS,
}

impl Metric {
    pub const NAMES: [&str; 12] = [
        "success",
        "episode_length",
        "return",
        "reward_split",
        "stages",
        "task_success",
        "policy_loss",
        "value_loss",
        "entropy",
        "approx_kl",
        "learning_rate",
        "steps_per_s",
    ];
    const ALL: [Metric; 12] = [
        Self::Success,
        Self::EpisodeLength,
        Self::Return,
        Self::RewardSplit,
        Self::Stages,
        Self::Tasks,
        Self::PolicyLoss,
        Self::ValueLoss,
        Self::Entropy,
        Self::ApproxKl,
        Self::LearningRate,
        Self::StepsPerS,
    ];

    pub fn from_name(name: &str) -> Option<Self> {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .map(|k| Self::ALL[k])
    }

    fn title(self) -> &'static str {
        match self {
            Self::Success => "success rate (last 100 episodes)",
            Self::EpisodeLength => "mean episode length",
            Self::Return => "mean episode return",
            Self::RewardSplit => "intra-stage vs transition reward per episode",
            Self::Stages => "stage occupancy (share of steps)",
            Self::Tasks => "weakest tasks (success over each task's last 50 episodes)",
            Self::PolicyLoss => "policy loss",
            Self::ValueLoss => "value loss",
            Self::Entropy => "entropy",
            Self::ApproxKl => "approximate KL",
            Self::LearningRate => "learning rate",
            Self::StepsPerS => "environment steps per second",
        }
    }

    fn y_range(self) -> Option<(f64, f64)> {
        matches!(self, Self::Success | Self::Stages | Self::Tasks).then_some((0.0, 1.0))
    }

    /// The curve names within one run and their values at one iteration; per-episode means
    /// are missing (NaN) where no episode ended. `names` are the stages or the tasks that
    /// [`Self::Stages`] and [`Self::Tasks`] draw.
    fn parts(self, it: &Iteration, names: &[String]) -> Vec<(String, f64)> {
        let one = |v: f64| vec![(String::new(), v)];
        let ended = |v: Option<f64>| v.unwrap_or(f64::NAN);
        match self {
            Self::Success => one(it.success_rate_last_100),
            Self::EpisodeLength => one(ended(it.mean_episode_length)),
            Self::Return => one(ended(it.mean_return)),
            Self::RewardSplit => vec![
                ("intra-stage".into(), ended(it.mean_intra_return)),
                ("transition".into(), ended(it.mean_transition_return)),
            ],
            Self::Stages => names
                .iter()
                .map(|s| (s.clone(), it.stage_mix.get(s).copied().unwrap_or(0.0)))
                .collect(),
            Self::Tasks => names
                .iter()
                .map(|t| {
                    (
                        t.clone(),
                        it.task_success.get(t).copied().unwrap_or(f64::NAN),
                    )
                })
                .collect(),
            Self::PolicyLoss => one(it.policy_loss),
            Self::ValueLoss => one(it.value_loss),
            Self::Entropy => one(it.entropy),
            Self::ApproxKl => one(it.approx_kl),
            Self::LearningRate => one(it.learning_rate),
            Self::StepsPerS => one(it.steps_per_s),
        }
    }
}

/// Tasks a `task_success` chart draws per run: the run's weakest at its last iteration.
const WEAKEST_TASKS: usize = 6;

/// The `count` tasks with the lowest training success at the run's last iteration that has
/// any (ties by name).
fn weakest_tasks(iterations: &[Iteration], count: usize) -> Vec<String> {
    let Some(last) = iterations
        .iter()
        .rev()
        .find(|it| !it.task_success.is_empty())
    else {
        return Vec::new();
    };
    crm_api::jobs::weakest_tasks(&last.task_success, count)
        .into_iter()
        .map(|(task, _)| task.to_string())
        .collect()
}

/// The x axis of a training curve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Axis {
    Steps,
    Episodes,
    Wall,
}

impl Axis {
    fn label(self) -> &'static str {
        match self {
            Self::Steps => "environment steps",
            Self::Episodes => "episodes",
            Self::Wall => "wall time (minutes)",
        }
    }

    fn values(self, iterations: &[Iteration]) -> Vec<f64> {
        let mut episodes = 0.0;
        iterations
            .iter()
            .map(|it| match self {
                Self::Steps => it.steps as f64,
                Self::Episodes => {
                    episodes += it.episodes as f64;
                    episodes
                }
                Self::Wall => it.wall_s / 60.0,
            })
            .collect()
    }
}

/// Parses `runs=1,2,3`: at most 12 positive ids, each an existing training run.
/// Most runs one chart or comparison takes.
pub const MAX_RUNS: usize = 50;

/// The runs of `runs=1,2,3` (1 to [`MAX_RUNS`] positive ids, comma-separated, no spaces or
/// leading zeros; a repeated id counts once), each a training run.
pub async fn runs_of(state: &AppState, text: Option<&String>) -> Result<Vec<Job>, ApiError> {
    let text = text.ok_or_else(|| ApiError::invalid("runs", "give run ids, as runs=1,2"))?;
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() > MAX_RUNS {
        return Err(ApiError::invalid(
            "runs",
            format!("give between 1 and {MAX_RUNS} run ids"),
        ));
    }
    let mut jobs = Vec::new();
    for part in parts {
        let id = run_id(part)
            .ok_or_else(|| ApiError::invalid("runs", format!("{part:?} is not a run id")))?;
        let job = state
            .store
            .job(id)
            .await
            .map_err(|_| ApiError::not_found("runs", format!("no run {id}")))?;
        if job.kind != "train" {
            return Err(ApiError::not_found(
                "runs",
                format!("job {id} is not a training run"),
            ));
        }
        if !jobs.iter().any(|j: &Job| j.id == id) {
            jobs.push(job);
        }
    }
    Ok(jobs)
}

/// A run id as the OpenAPI document's pattern has it: 1 to 18 digits, no leading zero.
fn run_id(text: &str) -> Option<i64> {
    let digits = text.len() <= 18 && text.bytes().all(|b| b.is_ascii_digit());
    (digits && !text.starts_with('0') && !text.is_empty())
        .then(|| text.parse().ok())
        .flatten()
}

/// A run's configuration without its seed (and its recording, which changes nothing it
/// learns): runs with equal keys are seeds of one experiment.
pub fn config_key(job: &Job) -> String {
    let mut spec: serde_json::Value = serde_json::from_str(&job.spec).unwrap_or_default();
    if let Some(map) = spec.as_object_mut() {
        map.remove("seed");
        map.remove("record");
    }
    format!("{}|{spec}", job.algorithm)
}

fn number(
    query: &HashMap<String, String>,
    key: &str,
    default: f64,
    range: (f64, f64),
) -> Result<f64, ApiError> {
    let Some(text) = query.get(key) else {
        return Ok(default);
    };
    text.parse::<f64>()
        .ok()
        .filter(|v| (range.0..=range.1).contains(v))
        .ok_or_else(|| ApiError::invalid(key, format!("a number from {} to {}", range.0, range.1)))
}

fn integer(
    query: &HashMap<String, String>,
    key: &str,
    default: u32,
    range: (u32, u32),
) -> Result<u32, ApiError> {
    let Some(text) = query.get(key) else {
        return Ok(default);
    };
    text.parse::<u32>()
        .ok()
        .filter(|v| (range.0..=range.1).contains(v))
        .ok_or_else(|| {
            ApiError::invalid(key, format!("an integer from {} to {}", range.0, range.1))
        })
}

pub async fn chart(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    const KNOWN: [&str; 7] = ["runs", "metric", "x", "smooth", "group", "width", "height"];
    if let Some(key) = query.keys().find(|k| !KNOWN.contains(&k.as_str())) {
        return Err(ApiError::invalid(key.clone(), "unknown query parameter"));
    }
    let metric_name = query.get("metric").map_or("success", String::as_str);
    let metric = Metric::from_name(metric_name).ok_or_else(|| {
        ApiError::invalid("metric", format!("one of {}", Metric::NAMES.join(", ")))
    })?;
    let axis = match query.get("x").map_or("steps", String::as_str) {
        "steps" => Axis::Steps,
        "episodes" => Axis::Episodes,
        "wall" => Axis::Wall,
        _ => return Err(ApiError::invalid("x", "one of steps, episodes, wall")),
    };
    let weight = number(&query, "smooth", 0.0, (0.0, 0.99))?;
    let group = match query.get("group").map_or("none", String::as_str) {
        "none" => false,
        "seeds" => true,
        _ => return Err(ApiError::invalid("group", "none or seeds")),
    };
    let width = integer(&query, "width", 640, (200, 2000))?;
    let height = integer(&query, "height", 320, (150, 1500))?;
    let jobs = runs_of(&state, query.get("runs")).await?;

    let mut curves = Vec::new();
    for job in &jobs {
        let rows = state
            .store
            .metrics(job.id)
            .await
            .map_err(|e| ApiError::store("run", e))?;
        let iterations: Vec<Iteration> = rows
            .iter()
            .filter_map(|m| serde_json::from_str(&m.data).ok())
            .collect();
        curves.push((job, iterations));
    }
    let names: Vec<String> = if metric == Metric::Tasks {
        curves
            .iter()
            .flat_map(|(_, its)| weakest_tasks(its, WEAKEST_TASKS))
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    } else {
        curves
            .iter()
            .flat_map(|(_, its)| its.iter().flat_map(|it| it.stage_mix.keys().cloned()))
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    };

    // Runs, or groups of seeds, in the order first named.
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for (k, (job, _)) in curves.iter().enumerate() {
        let key = if group {
            config_key(job)
        } else {
            job.id.to_string()
        };
        match groups.iter_mut().find(|(g, _)| *g == key) {
            Some((_, members)) => members.push(k),
            None => groups.push((key, vec![k])),
        }
    }
    let mut series = Vec::new();
    for (_, members) in &groups {
        let first = &curves[members[0]];
        let name = if members.len() == 1 {
            format!("run {} {}", first.0.id, first.0.algorithm)
        } else {
            let ids: Vec<String> = members
                .iter()
                .map(|&m| curves[m].0.id.to_string())
                .collect();
            format!(
                "{} x{} seeds (runs {})",
                first.0.algorithm,
                members.len(),
                ids.join(",")
            )
        };
        let x = axis.values(&first.1);
        // Per part (curve within a run): each member's smoothed values.
        let mut parts: BTreeMap<usize, (String, Vec<Vec<f64>>)> = BTreeMap::new();
        for &m in members {
            let per_iteration: Vec<Vec<(String, f64)>> = curves[m]
                .1
                .iter()
                .map(|it| metric.parts(it, &names))
                .collect();
            let count = per_iteration.first().map_or(0, Vec::len);
            for p in 0..count {
                let values: Vec<f64> = per_iteration.iter().map(|v| v[p].1).collect();
                let entry = parts
                    .entry(p)
                    .or_insert_with(|| (per_iteration[0][p].0.clone(), Vec::new()));
                entry.1.push(smooth(&values, weight));
            }
        }
        for (_, (part, values)) in parts {
            let label = if part.is_empty() {
                name.clone()
            } else {
                format!("{name} {part}")
            };
            let (mean, std) = mean_and_std(&values);
            let kept: Vec<((f64, f64), f64)> = x
                .iter()
                .copied()
                .zip(mean)
                .zip(std)
                .filter(|((_, y), _)| y.is_finite())
                .collect();
            series.push(Series {
                label,
                points: kept.iter().map(|(p, _)| *p).collect(),
                band: (members.len() > 1).then(|| kept.iter().map(|(_, s)| *s).collect()),
            });
        }
    }
    let svg = render(
        &Chart {
            title: metric.title(),
            x_label: axis.label(),
            y_label: metric_name,
            y_range: metric.y_range(),
            size: (width, height),
        },
        &series,
    )
    .map_err(ApiError::internal)?;
    Ok((
        [
            (header::CONTENT_TYPE, "image/svg+xml"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        svg,
    )
        .into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iteration(tasks: &[(&str, f64)]) -> Iteration {
        Iteration {
            task_success: tasks.iter().map(|(t, s)| (t.to_string(), *s)).collect(),
            ..Iteration::default()
        }
    }

    #[test]
    fn the_task_chart_draws_the_weakest_tasks_of_the_last_iteration() {
        let its = vec![
            iteration(&[("a", 0.0), ("b", 0.0), ("c", 0.0)]),
            iteration(&[("a", 0.9), ("b", 0.2), ("c", 0.5)]),
            // An iteration before any episode ended reports no tasks.
            Iteration::default(),
        ];
        assert_eq!(weakest_tasks(&its, 2), ["b", "c"]);
        assert!(weakest_tasks(&[Iteration::default()], 2).is_empty());
        let parts = Metric::Tasks.parts(&its[0], &["b".into(), "z".into()]);
        assert_eq!(parts[0], ("b".to_string(), 0.0));
        assert!(parts[1].1.is_nan(), "a task not drawn yet is a gap");
    }
}
