//! Running a study through a coordinator so that it survives interruption: the runs not yet
//! on disk are found among the coordinator's sweeps of the study's name (a rerun of the same
//! command on the same data folder picks up where it stopped: the coordinator re-queues a
//! job whose worker went away, and the next worker resumes it from its last checkpoint) or
//! submitted as new sweeps, one per seed, in seed order; each run is written to the study's
//! folder as soon as its training and both evaluations have finished
//! ([`super::record`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use crm_api::{EvalReport, Iteration};
use serde_json::{Value, json};

use super::record::{self, CurvePoint, RunFile, StudyFile};
use crate::commands::remote::Rest;

/// The name of the coordinator's sweeps of study `name`.
fn sweep_name(name: &str) -> String {
    format!("crm results: {name}")
}

/// The coordinator's jobs of the study, by id.
pub fn study_jobs(rest: &Rest, name: &str) -> anyhow::Result<Vec<Value>> {
    let sweeps = rest.get("/api/v1/sweeps?limit=10000")?;
    let mut jobs = Vec::new();
    for sweep in sweeps["sweeps"].as_array().into_iter().flatten() {
        if sweep["name"].as_str() != Some(&sweep_name(name)) {
            continue;
        }
        let id = sweep["id"].as_i64().context("a sweep without id")?;
        let full = rest.get(&format!("/api/v1/sweeps/{id}"))?;
        jobs.extend(full["jobs"].as_array().cloned().unwrap_or_default());
    }
    Ok(jobs)
}

/// The training job of `algorithm` and `seed` among `jobs` that has not failed and was not
/// set aside (`--redo`), the newest.
fn train_job<'a>(
    jobs: &'a [Value],
    study: &StudyFile,
    algorithm: &str,
    seed: u64,
) -> Option<&'a Value> {
    let aside = study.superseded.get(algorithm);
    jobs.iter()
        .filter(|j| {
            j["kind"] == "train"
                && j["algorithm"] == algorithm
                && j["spec"]["seed"].as_u64() == Some(seed)
                && !matches!(j["state"].as_str(), Some("failed" | "cancelled"))
                && !j["id"]
                    .as_i64()
                    .is_some_and(|id| aside.is_some_and(|a| a.contains(&id)))
        })
        .max_by_key(|j| j["id"].as_i64())
}

/// The sweep body of the study's runs of `seed` for `algorithms`.
fn sweep_request(study: &StudyFile, seed: u64, algorithms: &[String]) -> Value {
    let mut base = json!({
        "steps": study.steps, "envs": study.envs, "tasks": study.tasks,
        "config": study.ppo, "sac": study.sac,
    });
    if study.world != "crm" {
        base["world"] = json!(study.world);
    }
    if let Some(settle) = study.settle_s {
        base["settle_s"] = json!(settle);
    }
    let mut eval =
        json!({"episodes": study.episodes, "seed": study.eval_seed, "tasks": study.tasks});
    if study.world != "crm" {
        eval["world"] = json!(study.world);
    }
    json!({
        "name": sweep_name(&study.name),
        "base": base,
        "axes": {"algorithm": algorithms, "seed": [seed]},
        "eval": eval,
    })
}

/// Seconds between a job's start and end.
fn wall_s(job: &Value) -> f64 {
    match (job["started_at"].as_f64(), job["finished_at"].as_f64()) {
        (Some(start), Some(end)) => (end - start) / 1000.0,
        _ => f64::NAN,
    }
}

/// The state of one run on the coordinator, as far as it has come.
enum Progress {
    /// Still training or evaluating (or waiting for a worker).
    Waiting,
    /// Everything it needs is done: write it.
    Done(Box<Finished>),
    /// It cannot finish: the message says why.
    Failed(String),
}

struct Finished {
    train: Value,
    eval: Value,
    deterministic: Value,
    checkpoint: i64,
}

/// Where `algorithm`'s run of `seed` stands; submits its deterministic evaluation once its
/// training has succeeded (the id kept in the run's folder, `pending.json`).
fn progress(
    rest: &Rest,
    study: &StudyFile,
    dir: &Path,
    jobs: &[Value],
    train: &Value,
) -> anyhow::Result<Progress> {
    match train["state"].as_str() {
        Some("succeeded") => {}
        Some("failed" | "cancelled") => {
            return Ok(Progress::Failed(format!(
                "training job {}: {}",
                train["id"],
                train["error"].as_str().unwrap_or("cancelled")
            )));
        }
        _ => return Ok(Progress::Waiting),
    }
    let checkpoint = train["result"]["checkpoint_id"]
        .as_i64()
        .with_context(|| format!("training job {} has no final checkpoint", train["id"]))?;
    let Some(eval) = jobs
        .iter()
        .find(|j| j["kind"] == "eval" && j["checkpoint_id"].as_i64() == Some(checkpoint))
    else {
        return Ok(Progress::Waiting);
    };
    let pending = dir.join("pending.json");
    let known: Option<i64> = std::fs::read_to_string(&pending)
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .filter(|v| v["checkpoint_id"].as_i64() == Some(checkpoint))
        .and_then(|v| v["deterministic_eval"].as_i64());
    let deterministic = match known.map(|id| rest.get(&format!("/api/v1/jobs/{id}"))) {
        Some(Ok(job)) if !matches!(job["state"].as_str(), Some("failed" | "cancelled")) => job,
        _ => {
            let mut spec = json!({
                "kind": "eval", "checkpoint_id": checkpoint, "episodes": study.episodes,
                "seed": study.eval_seed, "tasks": study.tasks, "deterministic": true,
            });
            if study.world != "crm" {
                spec["world"] = json!(study.world);
            }
            let id = rest.submit(&spec)?;
            record::write_json(
                &pending,
                &json!({"checkpoint_id": checkpoint, "deterministic_eval": id}),
            )?;
            return Ok(Progress::Waiting);
        }
    };
    for job in [eval, &deterministic] {
        match job["state"].as_str() {
            Some("succeeded") => {}
            Some("failed" | "cancelled") => {
                return Ok(Progress::Failed(format!(
                    "evaluation job {}: {}",
                    job["id"],
                    job["error"].as_str().unwrap_or("cancelled")
                )));
            }
            _ => return Ok(Progress::Waiting),
        }
    }
    Ok(Progress::Done(Box::new(Finished {
        train: train.clone(),
        eval: eval.clone(),
        deterministic,
        checkpoint,
    })))
}

/// Writes a finished run's files, `run.json` last (its presence marks the run finished).
fn write_run(rest: &Rest, dir: &Path, done: &Finished) -> anyhow::Result<()> {
    let train = &done.train;
    let id = train["id"].as_i64().context("a job without id")?;
    let metrics = rest.get(&format!("/api/v1/runs/{id}/metrics"))?;
    let curve: Vec<CurvePoint> = metrics["metrics"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|m| serde_json::from_value::<Iteration>(m["data"].clone()).ok())
        .map(|it| CurvePoint::of(&it))
        .collect();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::write(dir.join("curve.csv"), record::curve_csv(&curve))
        .with_context(|| format!("writing {}", dir.join("curve.csv").display()))?;
    let report = |job: &Value| -> anyhow::Result<EvalReport> {
        serde_json::from_value(job["result"].clone())
            .with_context(|| format!("evaluation job {}'s report", job["id"]))
    };
    record::write_json(&dir.join("eval.json"), &report(&done.eval)?)?;
    record::write_json(
        &dir.join("eval-deterministic.json"),
        &report(&done.deterministic)?,
    )?;
    let bytes = rest.get_bytes(&format!("/api/v1/checkpoints/{}/download", done.checkpoint))?;
    std::fs::write(dir.join("checkpoint.safetensors"), bytes)
        .with_context(|| format!("writing {}", dir.join("checkpoint.safetensors").display()))?;
    let file = RunFile {
        algorithm: train["algorithm"].as_str().unwrap_or_default().to_string(),
        seed: train["spec"]["seed"].as_u64().unwrap_or_default(),
        steps: train["result"]["steps"].as_u64().unwrap_or_default(),
        stopped_early: train["result"]["stopped_early"].as_bool().unwrap_or(false),
        train_wall_s: wall_s(train),
        leases: train["attempts"].as_u64().unwrap_or(1),
        resumed_from_steps: train["result"]["resumed_from_steps"].as_u64(),
        eval_wall_s: wall_s(&done.eval),
        eval_deterministic_wall_s: wall_s(&done.deterministic),
        train_job: id,
        checkpoint_id: done.checkpoint,
    };
    std::fs::remove_file(dir.join("pending.json")).ok();
    record::write_json(&dir.join("run.json"), &file)
}

/// Runs the study in `dir` on the coordinator at `rest` until every run is on disk; calls
/// `landed` after each run is written (the caller rebuilds the report then). Returns early,
/// with an error saying so, once `stop` is set.
pub fn run(
    rest: &Rest,
    dir: &Path,
    study: &StudyFile,
    stop: &AtomicBool,
    mut landed: impl FnMut(&str, u64) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    // The runs this invocation submitted: one missing again was cancelled or lost, and is
    // reported, not submitted twice.
    let mut submitted = std::collections::BTreeSet::new();
    let mut failures = BTreeMap::new();
    loop {
        let on_disk = record::Study::read(dir)?;
        let jobs = study_jobs(rest, &study.name)?;
        let mut open = 0;
        let mut missing: BTreeMap<u64, Vec<String>> = BTreeMap::new();
        for &seed in &study.seeds {
            for algorithm in &study.algorithms {
                if on_disk.finished(algorithm, seed) || failures.contains_key(&(algorithm, seed)) {
                    continue;
                }
                let run_dir = record::run_dir(dir, algorithm, seed);
                match train_job(&jobs, study, algorithm, seed) {
                    None if submitted.contains(&(algorithm, seed)) => {
                        let why = "its training job was cancelled or failed on the coordinator";
                        eprintln!("{algorithm} seed {seed}: {why}");
                        failures.insert((algorithm, seed), why.to_string());
                    }
                    None => missing.entry(seed).or_default().push(algorithm.clone()),
                    Some(train) => match progress(rest, study, &run_dir, &jobs, train)? {
                        Progress::Waiting => open += 1,
                        Progress::Done(done) => {
                            write_run(rest, &run_dir, &done)?;
                            eprintln!("landed: {algorithm} seed {seed} -> {}", run_dir.display());
                            landed(algorithm, seed)?;
                        }
                        Progress::Failed(why) => {
                            eprintln!("{algorithm} seed {seed} failed: {why}");
                            failures.insert((algorithm, seed), why);
                        }
                    },
                }
            }
        }
        if !missing.is_empty() {
            for (seed, algorithms) in &missing {
                let created =
                    rest.post_json("/api/v1/sweeps", &sweep_request(study, *seed, algorithms))?;
                eprintln!(
                    "sweep {}: seed {seed}, {}",
                    created["sweep"]["id"],
                    algorithms.join(", ")
                );
                for algorithm in algorithms {
                    let name = study
                        .algorithms
                        .iter()
                        .find(|a| *a == algorithm)
                        .context("an algorithm of the study")?;
                    submitted.insert((name, *seed));
                }
            }
            continue;
        }
        if open == 0 {
            break;
        }
        for _ in 0..20 {
            if stop.load(Ordering::Relaxed) {
                bail!(
                    "stopped by a signal before the study finished (the runs on disk are kept; \
                     run the same command to continue)"
                );
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }
    if !failures.is_empty() {
        let lines: Vec<String> = failures
            .iter()
            .map(|((a, s), why)| format!("{a} seed {s}: {why}"))
            .collect();
        bail!(
            "{} runs failed (the report leaves them out; rerun the command to retry them):\n  {}",
            lines.len(),
            lines.join("\n  ")
        );
    }
    Ok(())
}
