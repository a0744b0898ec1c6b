//! Comparison views as JSON, for the dashboard and for scripts:
//! `GET /api/v1/compare?runs=1,2` (the runs, seed groups, their configurations side by side
//! with the differing keys flagged, and Table I from each run's latest evaluation with the
//! best cells marked) and `GET /api/v1/topology` (the selection network's pick and
//! probabilities per task beside the assigned topology, and success per objective and topology
//! from evaluations with a forced topology).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;

use axum::Json;
use axum::extract::{Query, State};
use axum::response::{IntoResponse, Response};
use crm_api::EvalReport;
use serde_json::{Value, json};

use super::curves::{config_key, runs_of};
use super::error::ApiError;
use crate::AppState;
use crate::store::{Job, JobFilter};

/// The shipped selection network's table (`crm topology table`), checked against the network
/// by a test in the worker.
const TOPOLOGY_PICKS: &str = include_str!("../../../models/topology-picks.json");

/// Nested JSON objects as dotted keys (`config.learning_rate`); arrays stay whole.
pub fn flatten(prefix: &str, value: &Value, out: &mut BTreeMap<String, String>) {
    match value {
        Value::Object(map) => {
            for (key, v) in map {
                let path = if prefix.is_empty() {
                    key.clone()
                } else {
                    format!("{prefix}.{key}")
                };
                flatten(&path, v, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.to_string());
        }
    }
}

/// Each configuration key with every run's value and whether they differ.
pub fn config_diff(jobs: &[Job]) -> Vec<Value> {
    let flat: Vec<BTreeMap<String, String>> = jobs
        .iter()
        .map(|job| {
            let mut out = BTreeMap::new();
            out.insert("algorithm".into(), format!("{:?}", job.algorithm));
            let spec: Value = serde_json::from_str(&job.spec).unwrap_or_default();
            flatten("", &spec, &mut out);
            out
        })
        .collect();
    let keys: BTreeSet<&String> = flat.iter().flat_map(BTreeMap::keys).collect();
    keys.into_iter()
        .map(|key| {
            let values: Vec<Option<&String>> = flat.iter().map(|f| f.get(key)).collect();
            let differs = values.iter().any(|v| *v != values[0]);
            json!({"key": key, "values": values, "differs": differs})
        })
        .collect()
}

/// Every evaluation that finished, newest first.
async fn finished_evaluations(state: &AppState) -> Result<Vec<Job>, ApiError> {
    state
        .store
        .jobs(&JobFilter {
            kind: Some("eval".into()),
            state: Some("succeeded".into()),
            ..JobFilter::default()
        })
        .await
        .map_err(|e| ApiError::store("evaluation", e))
}

/// What an evaluation measured, without where it was recorded: evaluations with equal keys
/// ran the same tasks, episodes, seed and topology, so their tables compare.
fn eval_key(job: &Job) -> String {
    let mut spec: Value = serde_json::from_str(&job.spec).unwrap_or_default();
    if let Some(map) = spec.as_object_mut() {
        map.remove("record");
        if map.get("topology").and_then(Value::as_str) == Some("task") {
            map.remove("topology");
        }
    }
    spec.to_string()
}

/// An evaluation's topology: a forced name, `auto`, or `task` (each task's assigned one).
fn topology_of(job: &Job) -> String {
    let spec: Value = serde_json::from_str(&job.spec).unwrap_or_default();
    spec["topology"].as_str().unwrap_or("task").to_string()
}

fn forced(job: &Job) -> bool {
    topology_of(job) != "task"
}

/// Each run's finished evaluations (of any of its checkpoints) with their reports, newest
/// first.
async fn evaluations_of(
    state: &AppState,
    run: &Job,
    evaluations: &[Job],
) -> Result<Vec<(Job, EvalReport)>, ApiError> {
    let ids: Vec<i64> = state
        .store
        .checkpoints(Some(run.id), false)
        .await
        .map_err(|e| ApiError::store("checkpoint", e))?
        .iter()
        .map(|c| c.id)
        .collect();
    Ok(evaluations
        .iter()
        .filter(|e| e.checkpoint_id.is_some_and(|c| ids.contains(&c)))
        .filter_map(|e| Some((e.clone(), serde_json::from_str(e.result.as_deref()?).ok()?)))
        .collect())
}

/// One evaluation per run for Table I: the evaluation setting (tasks, episodes, seed,
/// topology) that most of the runs share, newest first, so the columns measure the same thing;
/// a run without it gets its newest evaluation that kept the assigned topologies, else its
/// newest.
fn pick_evaluations(per_run: Vec<Vec<(Job, EvalReport)>>) -> Vec<Option<(Job, EvalReport)>> {
    let mut counts: Vec<(String, usize, i64)> = Vec::new();
    for evaluations in &per_run {
        let mut seen = BTreeSet::new();
        for (e, _) in evaluations.iter().filter(|(e, _)| !forced(e)) {
            let key = eval_key(e);
            if seen.insert(key.clone()) {
                match counts.iter_mut().find(|(k, _, _)| *k == key) {
                    Some(entry) => {
                        entry.1 += 1;
                        entry.2 = entry.2.max(e.id);
                    }
                    None => counts.push((key, 1, e.id)),
                }
            }
        }
    }
    let common = counts
        .into_iter()
        .max_by_key(|(_, runs, newest)| (*runs, *newest))
        .map(|(key, _, _)| key);
    per_run
        .into_iter()
        .map(|mut evaluations| {
            let at = |evaluations: &[(Job, EvalReport)]| {
                evaluations
                    .iter()
                    .position(|(e, _)| common.as_ref() == Some(&eval_key(e)))
                    .or_else(|| evaluations.iter().position(|(e, _)| !forced(e)))
                    .or((!evaluations.is_empty()).then_some(0))
            };
            at(&evaluations).map(|k| evaluations.swap_remove(k))
        })
        .collect()
}

/// Which columns hold the best value of each row: highest success, shortest episodes.
fn best(columns: &[Option<&EvalReport>], objectives: &[String]) -> Value {
    let mut rows = serde_json::Map::new();
    let pick = |get: &dyn Fn(&EvalReport) -> Option<f64>, higher: bool| -> Vec<usize> {
        let values: Vec<Option<f64>> = columns.iter().map(|c| c.and_then(get)).collect();
        let target = values
            .iter()
            .flatten()
            .copied()
            .fold(None, |acc: Option<f64>, v| {
                Some(acc.map_or(v, |a| if higher { a.max(v) } else { a.min(v) }))
            });
        let Some(target) = target else {
            return Vec::new();
        };
        (0..values.len())
            .filter(|&k| values[k].is_some_and(|v| (v - target).abs() < 1e-9))
            .collect()
    };
    for objective in objectives.iter().map(String::as_str).chain(["overall"]) {
        let get_success = |r: &EvalReport| match objective {
            "overall" => Some(r.success_rate),
            o => r.per_objective.get(o).map(|row| row.success_rate),
        };
        let get_length = |r: &EvalReport| match objective {
            "overall" => Some(r.mean_episode_length),
            o => r.per_objective.get(o).map(|row| row.mean_episode_length),
        };
        rows.insert(
            objective.to_string(),
            json!({"success": pick(&get_success, true), "length": pick(&get_length, false)}),
        );
    }
    Value::Object(rows)
}

pub async fn compare(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    if let Some(key) = query.keys().find(|k| k.as_str() != "runs") {
        return Err(ApiError::invalid(key.clone(), "unknown query parameter"));
    }
    let jobs = runs_of(&state, query.get("runs")).await?;
    let evaluations = finished_evaluations(&state).await?;
    let mut columns = Vec::new();
    let mut reports = Vec::new();
    let mut per_run = Vec::new();
    for job in &jobs {
        per_run.push(evaluations_of(&state, job, &evaluations).await?);
    }
    for (job, found) in jobs.iter().zip(pick_evaluations(per_run)) {
        columns.push(json!({
            "run": job.id,
            "algorithm": job.algorithm,
            "evaluation": found.as_ref().map(|(e, _)| e.id),
            "checkpoint": found.as_ref().and_then(|(e, _)| e.checkpoint_id),
            "topology": found.as_ref().map(|(e, _)| topology_of(e)),
            "tasks": found.as_ref().and_then(|(e, _)| {
                let spec: crm_api::EvalSpec = serde_json::from_str(&e.spec).ok()?;
                Some(crm_api::jobs::task_list(&spec.task, &spec.tasks))
            }),
            "report": found.as_ref().map(|(_, r)| r),
        }));
        reports.push(found.map(|(_, r)| r));
    }
    let objectives = state.catalog.objectives.clone();
    let refs: Vec<Option<&EvalReport>> = reports.iter().map(Option::as_ref).collect();
    let mut groups: Vec<(String, Vec<i64>)> = Vec::new();
    for job in &jobs {
        let key = config_key(job);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, ids)) => ids.push(job.id),
            None => groups.push((key, vec![job.id])),
        }
    }
    Ok(Json(json!({
        "runs": jobs,
        "groups": groups.into_iter().map(|(_, ids)| ids).collect::<Vec<_>>(),
        "config": config_diff(&jobs),
        "table": {
            "objectives": objectives,
            "columns": columns,
            "best": best(&refs, &objectives),
        },
    }))
    .into_response())
}

/// `GET /api/v1/topology[?checkpoint_id=N]`: the heat map pools the finished evaluations of one
/// checkpoint, or of all when none is named.
pub async fn topology(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    let mut only = None;
    for (key, value) in &query {
        match key.as_str() {
            "checkpoint_id" => {
                only = Some(
                    value
                        .parse::<i64>()
                        .ok()
                        .filter(|id| *id > 0)
                        .ok_or_else(|| ApiError::invalid("checkpoint_id", "a positive integer"))?,
                )
            }
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    let picks: Value = serde_json::from_str(TOPOLOGY_PICKS).map_err(ApiError::internal)?;
    let all = finished_evaluations(&state).await?;
    // Checkpoints with evaluations under a forced topology, and how many, for the picker.
    let mut forced_counts: BTreeMap<i64, u64> = BTreeMap::new();
    for job in all.iter().filter(|j| forced(j)) {
        if let Some(c) = job.checkpoint_id {
            *forced_counts.entry(c).or_default() += 1;
        }
    }
    let evaluations: Vec<&Job> = all
        .iter()
        .filter(|j| only.is_none() || j.checkpoint_id == only)
        .collect();
    // (objective, topology) -> (successes, episodes, evaluations); topology is a forced name,
    // "task" (each task's assigned one) or "auto" (the network's pick).
    let mut cells: BTreeMap<(String, String), (f64, u64, u64)> = BTreeMap::new();
    for job in evaluations {
        let topology = topology_of(job);
        let Some(report) = job
            .result
            .as_deref()
            .and_then(|r| serde_json::from_str::<EvalReport>(r).ok())
        else {
            continue;
        };
        for (objective, row) in &report.per_objective {
            let cell = cells
                .entry((objective.clone(), topology.clone()))
                .or_default();
            cell.0 += row.success_rate * row.episodes as f64;
            cell.1 += row.episodes;
            cell.2 += 1;
        }
    }
    let results: Vec<Value> = cells
        .into_iter()
        .filter(|(_, (_, episodes, _))| *episodes > 0)
        .map(
            |((objective, topology), (successes, episodes, evaluations))| {
                json!({
                    "objective": objective,
                    "topology": topology,
                    "success_rate": successes / episodes as f64,
                    "episodes": episodes,
                    "evaluations": evaluations,
                })
            },
        )
        .collect();
    let tasks = picks["tasks"].as_array().cloned().unwrap_or_default();
    let agree = tasks
        .iter()
        .filter(|t| t["picked"] == t["assigned"])
        .count();
    Ok(Json(json!({
        "model": picks["model"],
        "topologies": state.catalog.topologies,
        "objectives": state.catalog.objectives,
        "tasks": tasks,
        "picked_as_assigned": agree,
        "checkpoint_id": only,
        "checkpoints": forced_counts
            .iter()
            .map(|(id, n)| json!({"checkpoint_id": id, "forced_evaluations": n}))
            .collect::<Vec<_>>(),
        "results": results,
    }))
    .into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flatten_uses_dotted_keys() {
        let mut out = BTreeMap::new();
        flatten(
            "",
            &json!({"a": 1, "config": {"lr": 0.1, "x": [1, 2]}}),
            &mut out,
        );
        assert_eq!(out["a"], "1");
        assert_eq!(out["config.lr"], "0.1");
        assert_eq!(out["config.x"], "[1,2]");
    }

    #[test]
    fn best_marks_highest_success_and_shortest_episodes_with_ties() {
        let report = |s: f64, l: f64| EvalReport {
            algorithm: "crm-ppo".into(),
            trained_steps: 0,
            episodes: 10,
            seed: 0,
            success_rate: s,
            mean_episode_length: l,
            mean_sim_seconds: 0.0,
            objective: Default::default(),
            deterministic: false,
            per_objective: BTreeMap::new(),
            per_task: BTreeMap::new(),
            outcomes: BTreeMap::new(),
            hold_s: None,
            authors_judge: None,
        };
        let (a, b, c) = (report(0.5, 100.0), report(0.9, 120.0), report(0.9, 90.0));
        let best = best(&[Some(&a), None, Some(&b), Some(&c)], &[]);
        assert_eq!(best["overall"]["success"], json!([2, 3]));
        assert_eq!(best["overall"]["length"], json!([3]));
    }

    fn evaluation(id: i64, spec: Value) -> (Job, EvalReport) {
        let job = Job {
            id,
            kind: "eval".into(),
            state: "succeeded".into(),
            algorithm: "crm-ppo".into(),
            task: None,
            spec: spec.to_string(),
            checkpoint_id: Some(1),
            rerun_of: None,
            worker_id: None,
            attempts: 1,
            lease_expires_at: None,
            phase: None,
            sweep_id: None,
            progress: 1.0,
            steps: 0,
            steps_per_s: None,
            result: None,
            error: None,
            created_at: 0,
            started_at: None,
            finished_at: None,
        };
        let report = EvalReport {
            algorithm: "crm-ppo".into(),
            trained_steps: 0,
            episodes: 10,
            seed: 0,
            success_rate: 0.0,
            mean_episode_length: 0.0,
            mean_sim_seconds: 0.0,
            objective: Default::default(),
            deterministic: false,
            per_objective: BTreeMap::new(),
            per_task: BTreeMap::new(),
            outcomes: BTreeMap::new(),
            hold_s: None,
            authors_judge: None,
        };
        (job, report)
    }

    #[test]
    fn table_one_uses_the_evaluation_setting_most_runs_share() {
        let a = json!({"episodes": 60, "tasks": ["mouse-press"]});
        let b = json!({"episodes": 40, "tasks": ["valve-twist"]});
        let c = json!({"episodes": 5});
        let forced = json!({"episodes": 60, "tasks": ["mouse-press"], "topology": "platform"});
        // Each run's evaluations, newest first. Setting a: runs 1, 2, 3; b: runs 1, 3.
        let picked = pick_evaluations(vec![
            vec![evaluation(8, b.clone()), evaluation(3, a.clone())],
            vec![evaluation(4, a.clone())],
            vec![evaluation(7, a.clone()), evaluation(5, b)],
            vec![evaluation(6, forced)],
            vec![],
            vec![evaluation(10, c)],
        ]);
        let ids: Vec<Option<i64>> = picked
            .iter()
            .map(|p| p.as_ref().map(|(e, _)| e.id))
            .collect();
        // a where a run has it; else the newest unforced; else the newest; else none.
        assert_eq!(
            ids,
            vec![Some(3), Some(4), Some(7), Some(6), None, Some(10)]
        );
        // Between settings shared by as many runs, the newer wins.
        let x = json!({"episodes": 1});
        let y = json!({"episodes": 2});
        let picked = pick_evaluations(vec![
            vec![evaluation(2, x.clone()), evaluation(1, y.clone())],
            vec![evaluation(4, y), evaluation(3, x)],
        ]);
        assert_eq!(picked[0].as_ref().map(|(e, _)| e.id), Some(1));
        assert_eq!(picked[1].as_ref().map(|(e, _)| e.id), Some(4));
    }

    #[test]
    fn the_shipped_picks_cover_the_catalog() {
        let picks: Value = serde_json::from_str(TOPOLOGY_PICKS).expect("parses");
        let catalog = crm_api::Catalog::builtin().expect("catalog");
        let tasks = picks["tasks"].as_array().expect("tasks");
        assert_eq!(tasks.len(), catalog.tasks.len());
        for (task, entry) in tasks.iter().zip(&catalog.tasks) {
            assert_eq!(task["task"], entry.id.as_str());
            assert_eq!(task["assigned"], entry.topology.as_str());
        }
    }
}
