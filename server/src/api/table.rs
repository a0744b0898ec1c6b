//! A sweep's progress and its Table I aggregated over seeds: one row per configuration (the
//! values of every axis but `seed`), with the success rate and episode length per objective
//! and overall as mean and standard deviation over its evaluated runs, and how many runs
//! reached the early stop and at which step. The standard deviation is the population one
//! (numpy's default, `ddof=0`), over the runs whose final checkpoint has a finished
//! evaluation of the sweep.

use std::collections::BTreeSet;

use serde_json::{Map, Value, json};

use crate::store::Job;

/// What `GET /api/v1/sweeps/{id}` adds to the sweep and its jobs.
pub struct Summary {
    pub progress: Value,
    pub table: Value,
}

/// Mean and population standard deviation of `values`, with their count.
pub fn mean_std(values: &[f64]) -> Value {
    if values.is_empty() {
        return json!({"mean": null, "std": null, "n": 0});
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    json!({"mean": mean, "std": var.sqrt(), "n": values.len()})
}

fn json_of(text: Option<&str>) -> Value {
    text.and_then(|t| serde_json::from_str(t).ok())
        .unwrap_or(Value::Null)
}

/// The value at `path` (`config.learning_rate`) in a job's spec.
fn at<'a>(spec: &'a Value, path: &str) -> &'a Value {
    path.split('.').fold(spec, |v, key| &v[key])
}

/// A training run with its spec, parsed once.
type RunSpec<'a> = (&'a Job, Value);

pub fn summary(sweep: &Value, jobs: &[Job]) -> Summary {
    let axes: Vec<String> = sweep["axes"]
        .as_object()
        .map(|a| a.keys().filter(|k| *k != "seed").cloned().collect())
        .unwrap_or_default();
    let has_eval = sweep["eval"].is_object();
    let train: Vec<&Job> = jobs.iter().filter(|j| j.kind == "train").collect();
    // Every training job, and the evaluation of each that has not failed or been cancelled
    // (the only ones that will have a final checkpoint), when the sweep has an evaluation.
    let evaluable = train
        .iter()
        .filter(|j| j.state != "failed" && j.state != "cancelled")
        .count();
    let total = train.len() + if has_eval { evaluable } else { 0 };
    let count = |state: &str| jobs.iter().filter(|j| j.state == state).count();
    let (succeeded, failed, cancelled) = (count("succeeded"), count("failed"), count("cancelled"));
    let finished = succeeded + failed + cancelled;
    let progress = json!({
        "jobs": total,
        "created": jobs.len(),
        "succeeded": succeeded,
        "failed": failed,
        "cancelled": cancelled,
        "finished": finished,
        "fraction": if total == 0 { 1.0 } else { (finished as f64 / total as f64).min(1.0) },
    });

    // Rows in the order their configuration first appears (the grid's order).
    let mut rows: Vec<(Map<String, Value>, Vec<RunSpec>)> = Vec::new();
    for run in &train {
        let spec = json_of(Some(&run.spec));
        let mut config = Map::new();
        for key in &axes {
            let value = if key == "algorithm" {
                Value::from(run.algorithm.clone())
            } else {
                at(&spec, key).clone()
            };
            config.insert(key.clone(), value);
        }
        match rows.iter_mut().find(|(c, _)| *c == config) {
            Some((_, runs)) => runs.push((*run, spec)),
            None => rows.push((config, vec![(*run, spec)])),
        }
    }
    let mut objectives = BTreeSet::new();
    let rows: Vec<Value> = rows
        .into_iter()
        .map(|(config, runs)| {
            let reports: Vec<Value> = runs
                .iter()
                .filter_map(|(run, _)| report_of(run, jobs))
                .collect();
            for report in &reports {
                if let Some(per) = report["per_objective"].as_object() {
                    objectives.extend(per.keys().cloned());
                }
            }
            let stopped: Vec<i64> = runs
                .iter()
                .filter_map(|(run, _)| {
                    let result = json_of(run.result.as_deref());
                    (result["stopped_early"] == true)
                        .then(|| result["steps"].as_i64())
                        .flatten()
                })
                .collect();
            let label = config
                .iter()
                .map(|(k, v)| match v {
                    Value::String(s) => format!("{k}={s}"),
                    other => format!("{k}={other}"),
                })
                .collect::<Vec<_>>()
                .join(", ");
            json!({
                "config": config,
                "label": if label.is_empty() { "all runs".to_string() } else { label },
                "runs": runs.iter().map(|(r, _)| r.id).collect::<Vec<_>>(),
                "seeds": runs.iter().map(|(_, spec)| spec["seed"].clone()).collect::<Vec<_>>(),
                "evaluated": reports.len(),
                "reports": reports,
                "early_stop": {"runs": stopped.len(), "steps": stopped},
            })
        })
        .collect();
    let objectives: Vec<String> = objectives.into_iter().collect();
    let rows: Vec<Value> = rows
        .into_iter()
        .map(|mut row| {
            let reports = row["reports"].as_array().cloned().unwrap_or_default();
            let column = |f: &dyn Fn(&Value) -> Option<f64>| -> Value {
                mean_std(&reports.iter().filter_map(f).collect::<Vec<_>>())
            };
            let mut per = Map::new();
            for objective in &objectives {
                per.insert(
                    objective.clone(),
                    json!({
                        "success": column(&|r| r["per_objective"][objective]["success_rate"].as_f64()),
                        "length": column(&|r| r["per_objective"][objective]["mean_episode_length"].as_f64()),
                    }),
                );
            }
            row["overall"] = json!({
                "success": column(&|r| r["success_rate"].as_f64()),
                "length": column(&|r| r["mean_episode_length"].as_f64()),
            });
            row["per_objective"] = Value::Object(per);
            if let Some(map) = row.as_object_mut() {
                map.remove("reports");
            }
            row
        })
        .collect();
    Summary {
        progress,
        table: json!({"objectives": objectives, "rows": rows, "std": "population (ddof=0)"}),
    }
}

/// The report of the sweep's finished evaluation of `run`'s final checkpoint (the newest
/// one, if it was evaluated more than once).
fn report_of(run: &Job, jobs: &[Job]) -> Option<Value> {
    let checkpoint = json_of(run.result.as_deref())["checkpoint_id"].as_i64()?;
    jobs.iter()
        .rev()
        .find(|j| j.kind == "eval" && j.state == "succeeded" && j.checkpoint_id == Some(checkpoint))
        .map(|j| json_of(j.result.as_deref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(
        id: i64,
        kind: &str,
        algorithm: &str,
        spec: Value,
        result: Value,
        checkpoint: Option<i64>,
    ) -> Job {
        Job {
            id,
            kind: kind.into(),
            state: "succeeded".into(),
            algorithm: algorithm.into(),
            task: None,
            spec: spec.to_string(),
            checkpoint_id: checkpoint,
            rerun_of: None,
            worker_id: None,
            attempts: 1,
            lease_expires_at: None,
            progress: 1.0,
            steps: 0,
            steps_per_s: None,
            result: Some(result.to_string()),
            error: None,
            created_at: 0,
            started_at: None,
            finished_at: None,
            phase: None,
            sweep_id: Some(1),
        }
    }

    fn report(success: f64, length: f64) -> Value {
        json!({"success_rate": success, "mean_episode_length": length,
               "per_objective": {"press": {"success_rate": success, "mean_episode_length": length}}})
    }

    #[test]
    fn rows_group_seeds_and_give_mean_and_population_std() {
        let sweep = json!({"axes": {"algorithm": ["crm-ppo", "lppo"], "seed": [0, 1]}, "eval": {"episodes": 10}});
        let mut jobs = Vec::new();
        let runs = [
            ("crm-ppo", 0, 0.5, 10.0, false),
            ("crm-ppo", 1, 1.0, 20.0, true),
            ("lppo", 0, 0.25, 30.0, false),
            ("lppo", 1, 0.25, 30.0, false),
        ];
        for (k, (algorithm, seed, success, length, early)) in runs.into_iter().enumerate() {
            let id = k as i64 + 1;
            let checkpoint = 100 + id;
            jobs.push(job(
                id,
                "train",
                algorithm,
                json!({"algorithm": algorithm, "seed": seed}),
                json!({"checkpoint_id": checkpoint, "stopped_early": early, "steps": 4096 * id}),
                None,
            ));
            jobs.push(job(
                10 + id,
                "eval",
                algorithm,
                json!({}),
                report(success, length),
                Some(checkpoint),
            ));
        }
        let summary = summary(&sweep, &jobs);
        assert_eq!(summary.progress["jobs"], 8);
        assert_eq!(summary.progress["fraction"], 1.0);
        let rows = summary.table["rows"].as_array().expect("rows");
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0]["label"], "algorithm=crm-ppo");
        assert_eq!(rows[0]["runs"], json!([1, 2]));
        // crm-ppo: success 0.5 and 1.0 -> mean 0.75, population std 0.25; lengths 10, 20.
        assert_eq!(
            rows[0]["overall"]["success"],
            json!({"mean": 0.75, "std": 0.25, "n": 2})
        );
        assert_eq!(
            rows[0]["overall"]["length"],
            json!({"mean": 15.0, "std": 5.0, "n": 2})
        );
        assert_eq!(rows[0]["per_objective"]["press"]["success"]["mean"], 0.75);
        assert_eq!(rows[0]["early_stop"], json!({"runs": 1, "steps": [8192]}));
        assert_eq!(
            rows[1]["overall"]["success"],
            json!({"mean": 0.25, "std": 0.0, "n": 2})
        );
        assert_eq!(summary.table["objectives"], json!(["press"]));
    }

    #[test]
    fn runs_without_an_evaluation_count_but_do_not_enter_the_means() {
        let sweep = json!({"axes": {"seed": [0, 1]}, "eval": {"episodes": 10}});
        let jobs = vec![
            job(
                1,
                "train",
                "ppo",
                json!({"seed": 0}),
                json!({"checkpoint_id": 5}),
                None,
            ),
            job(
                2,
                "train",
                "ppo",
                json!({"seed": 1}),
                json!({"checkpoint_id": 6}),
                None,
            ),
            job(3, "eval", "ppo", json!({}), report(0.5, 12.0), Some(5)),
        ];
        let summary = summary(&sweep, &jobs);
        let row = &summary.table["rows"][0];
        assert_eq!(row["label"], "all runs");
        assert_eq!(row["evaluated"], 1);
        assert_eq!(row["overall"]["success"]["n"], 1);
        assert_eq!(summary.progress["jobs"], 4);
        assert_eq!(summary.progress["finished"], 3);
        assert_eq!(mean_std(&[]), json!({"mean": null, "std": null, "n": 0}));
    }

    #[test]
    fn a_failed_run_expects_no_evaluation_so_the_sweep_can_finish() {
        let sweep = json!({"axes": {"seed": [0, 1]}, "eval": {"episodes": 10}});
        let mut failed = job(2, "train", "ppo", json!({"seed": 1}), json!({}), None);
        failed.state = "failed".into();
        let jobs = vec![
            job(
                1,
                "train",
                "ppo",
                json!({"seed": 0}),
                json!({"checkpoint_id": 5}),
                None,
            ),
            failed,
            job(3, "eval", "ppo", json!({}), report(0.5, 12.0), Some(5)),
        ];
        let summary = summary(&sweep, &jobs);
        assert_eq!(summary.progress["jobs"], 3);
        assert_eq!(summary.progress["fraction"], 1.0);
        assert_eq!(summary.progress["failed"], 1);
    }
}
