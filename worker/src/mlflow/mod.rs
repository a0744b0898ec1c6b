//! Logging a training run to a user's MLflow tracking server (`crm train --mlflow-uri`, and
//! every training job of a coordinator started with `crm-server --mlflow-uri`), so that
//! crm-grasp runs sit beside a lab's others: the run's settings as parameters, every series
//! TensorBoard gets as metrics by environment step, tags for the algorithm, the world and its
//! hash, the seed and the lineage, and the final checkpoint and the job's document as
//! artifacts; an evaluation of a job's checkpoint goes into the job's run.
//!
//! Every call runs on a thread of its own behind a queue, so a server that is down, slow or
//! refusing never fails or slows the training: a failure is reported once on standard error
//! and retried with a growing pause (0.5 s to 30 s) for as long as the run lasts (a request
//! the server refuses, HTTP 4xx, three times, then dropped); when the server answers again the
//! queue drains in order. At the end [`Logger::finish`] waits a bounded time for the queue
//! and reports what did not reach the server.

mod client;

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use client::{Client, Metric};
use client::{MAX_METRICS, MAX_PARAMS, MAX_TAGS, Refused, Run};

/// Longest parameter value MLflow 2.x and 3.x store (`MAX_PARAM_VAL_LENGTH`).
const MAX_PARAM_CHARS: usize = 6000;
/// Longest tag value (`MAX_TAG_VAL_LENGTH`).
const MAX_TAG_CHARS: usize = 8000;
/// Seconds one request may take before it counts as failed.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);
const FIRST_PAUSE: Duration = Duration::from_millis(500);
/// Tries of a request the server refuses (HTTP 4xx) before it is dropped, said so.
const REFUSED_TRIES: u32 = 3;
const LONGEST_PAUSE: Duration = Duration::from_secs(30);

/// Where a run logs.
#[derive(Clone, Debug)]
pub struct Target {
    /// The tracking server (`http://HOST:PORT`).
    pub uri: String,
    /// The experiment's name (made when missing).
    pub experiment: String,
    /// The run's name in the server's UI.
    pub run_name: String,
}

/// How the logger finds its run.
#[derive(Clone, Debug)]
pub enum Find {
    /// A new run with this tag (key, value), for a later [`Find::OrCreate`] to find.
    Tagged(String, String),
    /// The run with this tag (key, value), made with it when there is none: a coordinator's
    /// job logs to one run across its leases.
    OrCreate(String, String),
    /// The run with this tag, or nothing is logged: an evaluation of a training job's
    /// checkpoint goes into that job's run.
    Existing(String, String),
}

enum Op {
    Start {
        tags: Vec<(String, String)>,
        find: Find,
    },
    Batch {
        params: Vec<(String, String)>,
        metrics: Vec<Metric>,
        tags: Vec<(String, String)>,
    },
    Artifact {
        name: String,
        bytes: Vec<u8>,
    },
    End {
        status: Option<String>,
    },
}

/// A run being logged; calls return at once.
pub struct Logger {
    tx: mpsc::Sender<Op>,
    /// Set when [`Logger::finish`] stops waiting: the thread gives up what is left.
    abort: Arc<AtomicBool>,
    done: mpsc::Receiver<()>,
    thread: Option<JoinHandle<()>>,
    run_id: Arc<Mutex<Option<String>>>,
    uri: String,
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// A value cut to `max` characters (MLflow refuses longer ones), marked when cut.
fn cut(value: &str, max: usize) -> String {
    if value.chars().count() <= max {
        return value.to_string();
    }
    let mut kept: String = value.chars().take(max - 1).collect();
    kept.push('…');
    kept
}

/// A JSON document as MLflow parameters: one per leaf, keys joined by dots
/// (`config.learning_rate`, as TensorBoard's hparams), values as JSON text (strings bare).
pub fn flatten(document: &serde_json::Value) -> Vec<(String, String)> {
    crm_api::tensorboard::hparams::flatten(document)
        .into_iter()
        .map(|(key, value)| {
            let text = match value {
                serde_json::Value::String(s) => s,
                other => other.to_string(),
            };
            (key, cut(&text, MAX_PARAM_CHARS))
        })
        .collect()
}

impl Logger {
    /// Starts logging a training run of `spec` in `world` (name, hash): the job's document as
    /// parameters and as the artifact `job.json`, and crm's tags.
    pub fn training(
        target: &Target,
        spec: &crm_api::TrainSpec,
        world: (&str, &str),
        find: Find,
    ) -> anyhow::Result<Self> {
        let document = serde_json::to_value(spec)?;
        let params = flatten(&document);
        let tags = vec![
            (
                "crm.algorithm".to_string(),
                spec.algorithm.name().to_string(),
            ),
            ("crm.seed".to_string(), spec.seed.to_string()),
            ("crm.world".to_string(), world.0.to_string()),
            ("crm.world_hash".to_string(), world.1.to_string()),
            (
                "crm.version".to_string(),
                env!("CARGO_PKG_VERSION").to_string(),
            ),
        ];
        let logger = Self::start(target, find, params, tags)?;
        logger.artifact("job.json", serde_json::to_vec_pretty(&document)?);
        Ok(logger)
    }

    /// Ends a training run: its final checkpoint as an artifact, with its lineage (from the
    /// checkpoint's header) as a tag.
    pub fn checkpoint(&self, path: &std::path::Path) -> anyhow::Result<()> {
        let header = crm_learn::Checkpoint::read_header(path)?;
        self.tags(vec![
            (
                "crm.lineage".to_string(),
                serde_json::to_string(&header.lineage)?,
            ),
            ("crm.steps".to_string(), header.steps.to_string()),
        ]);
        let name = path
            .file_name()
            .map_or("checkpoint.safetensors".into(), |n| {
                n.to_string_lossy().to_string()
            });
        self.artifact(&name, std::fs::read(path)?);
        Ok(())
    }

    /// Starts logging to `target`: the run is made with `tags` and given `params` as soon as
    /// the server answers. Errors only for a URI that is no URL.
    pub fn start(
        target: &Target,
        find: Find,
        params: Vec<(String, String)>,
        tags: Vec<(String, String)>,
    ) -> anyhow::Result<Self> {
        let client = Client::new(&target.uri, REQUEST_TIMEOUT)?;
        let (tx, rx) = mpsc::channel();
        let (done_tx, done) = mpsc::channel();
        let run_id = Arc::new(Mutex::new(None));
        let slot = run_id.clone();
        let abort = Arc::new(AtomicBool::new(false));
        let stop = abort.clone();
        let target_for_thread = target.clone();
        let thread = std::thread::Builder::new()
            .name("mlflow".into())
            .spawn(move || {
                work(client, &target_for_thread, rx, &slot, &stop);
                done_tx.send(()).ok();
            })?;
        let tags = tags
            .into_iter()
            .map(|(k, v)| (k, cut(&v, MAX_TAG_CHARS)))
            .chain([("mlflow.runName".to_string(), target.run_name.clone())])
            .collect();
        tx.send(Op::Start { tags, find }).ok();
        for chunk in params.chunks(MAX_PARAMS) {
            tx.send(Op::Batch {
                params: chunk.to_vec(),
                metrics: Vec::new(),
                tags: Vec::new(),
            })
            .ok();
        }
        Ok(Self {
            tx,
            abort,
            done,
            thread: Some(thread),
            run_id,
            uri: target.uri.clone(),
        })
    }

    /// Logs metric values at environment step `step` (non-finite ones are left out: MLflow's
    /// JSON has no NaN).
    pub fn metrics(&self, step: u64, values: &[(String, f64)]) {
        let timestamp = now_ms();
        let metrics: Vec<Metric> = values
            .iter()
            .filter(|(_, v)| v.is_finite())
            .map(|(key, value)| Metric {
                key: key.clone(),
                value: *value,
                step,
                timestamp,
            })
            .collect();
        for chunk in metrics.chunks(MAX_METRICS) {
            self.tx
                .send(Op::Batch {
                    params: Vec::new(),
                    metrics: chunk.to_vec(),
                    tags: Vec::new(),
                })
                .ok();
        }
    }

    /// Sets tags (later values replace earlier ones).
    pub fn tags(&self, tags: Vec<(String, String)>) {
        let tags: Vec<(String, String)> = tags
            .into_iter()
            .map(|(k, v)| (k, cut(&v, MAX_TAG_CHARS)))
            .collect();
        for chunk in tags.chunks(MAX_TAGS) {
            self.tx
                .send(Op::Batch {
                    params: Vec::new(),
                    metrics: Vec::new(),
                    tags: chunk.to_vec(),
                })
                .ok();
        }
    }

    /// Uploads `bytes` as the run's artifact `name`.
    pub fn artifact(&self, name: &str, bytes: Vec<u8>) {
        self.tx
            .send(Op::Artifact {
                name: name.to_string(),
                bytes,
            })
            .ok();
    }

    /// The run's id once the server made it.
    pub fn run_id(&self) -> Option<String> {
        self.run_id
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// Ends the run with `status` (`FINISHED`, `KILLED`, `FAILED`; `None` leaves it as it is,
    /// for an evaluation logged into a training run) and waits at most `wait` for the queue to
    /// reach the server; reports what did not. Returns the run's id.
    pub fn finish(mut self, status: Option<&str>, wait: Duration) -> Option<String> {
        self.tx
            .send(Op::End {
                status: status.map(str::to_string),
            })
            .ok();
        let thread = self.thread.take();
        match self.done.recv_timeout(wait) {
            Ok(()) => {
                if let Some(thread) = thread {
                    thread.join().ok();
                }
            }
            Err(_) => {
                self.abort.store(true, Ordering::Relaxed);
                eprintln!(
                    "mlflow: {} did not take the run's last records within {} s; they are not \
                     logged there (the run itself is complete)",
                    self.uri,
                    wait.as_secs()
                );
            }
        }
        self.run_id()
    }
}

impl Drop for Logger {
    /// A run dropped without [`Logger::finish`] (its training failed) ends as `FAILED`, sent
    /// without waiting.
    fn drop(&mut self) {
        if self.thread.take().is_some() {
            self.tx
                .send(Op::End {
                    status: Some("FAILED".into()),
                })
                .ok();
        }
    }
}

/// The logging thread: sends the queue in order, retrying the front until it goes through.
fn work(
    client: Client,
    target: &Target,
    rx: mpsc::Receiver<Op>,
    run_id: &Mutex<Option<String>>,
    abort: &AtomicBool,
) {
    let mut queue: VecDeque<Op> = VecDeque::new();
    let mut run: Option<Run> = None;
    // Whether this logger made its run (a run found again keeps the parameters it has:
    // MLflow's parameters cannot change).
    let mut created = false;
    let mut refusals = 0;
    let mut pause = FIRST_PAUSE;
    let mut failing: Option<String> = None;
    let mut closed = false;
    loop {
        if abort.load(Ordering::Relaxed) {
            return;
        }
        if queue.is_empty() {
            if closed {
                return;
            }
            match rx.recv() {
                Ok(op) => queue.push_back(op),
                Err(_) => return,
            }
        }
        while let Ok(op) = rx.try_recv() {
            queue.push_back(op);
        }
        let Some(op) = queue.front() else { continue };
        let sent = match (op, &run) {
            (Op::Start { tags, find }, _) => {
                match start(&client, &target.experiment, &target.run_name, tags, find) {
                    Ok(Some((found, made))) => {
                        created = made;
                        *run_id
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner) =
                            Some(found.run_id.clone());
                        run = Some(found);
                        Ok(())
                    }
                    Ok(None) => {
                        if let Find::Existing(key, value) = find {
                            eprintln!(
                                "mlflow: no run in experiment {:?} of {} has {key} = {value}; \
                                 nothing is logged",
                                target.experiment,
                                client.base()
                            );
                        }
                        return;
                    }
                    Err(err) => Err(err),
                }
            }
            (_, None) => Err(anyhow::anyhow!("the run was not made")),
            (
                Op::Batch {
                    params,
                    metrics,
                    tags,
                },
                Some(run),
            ) => {
                let params: &[(String, String)] = if created { params } else { &[] };
                if params.is_empty() && metrics.is_empty() && tags.is_empty() {
                    Ok(())
                } else {
                    client.log_batch(&run.run_id, params, metrics, tags)
                }
            }
            (Op::Artifact { name, bytes }, Some(run)) => {
                match client.upload_artifact(run, name, bytes) {
                    // A server without the artifact proxy never takes one: said, not retried.
                    Err(err) if err.to_string().contains("not behind its artifact proxy") => {
                        eprintln!("mlflow: {err:#}");
                        Ok(())
                    }
                    other => other,
                }
            }
            (Op::End { status: None }, Some(_)) => Ok(()),
            (
                Op::End {
                    status: Some(status),
                },
                Some(run),
            ) => client.set_status(&run.run_id, status, Some(now_ms())),
        };
        let sent = match sent {
            // Refused again and again: dropped, so the rest of the queue goes on.
            Err(err) if err.downcast_ref::<Refused>().is_some() => {
                refusals += 1;
                if refusals >= REFUSED_TRIES {
                    if matches!(queue.front(), Some(Op::Start { .. })) {
                        eprintln!("mlflow: {err:#}; no run to log to, nothing is logged");
                        return;
                    }
                    eprintln!("mlflow: {err:#}; refused {refusals} times, dropped");
                    Ok(())
                } else {
                    Err(err)
                }
            }
            other => other,
        };
        match sent {
            Ok(()) => {
                refusals = 0;
                let ended = matches!(queue.pop_front(), Some(Op::End { .. }));
                if failing.take().is_some() {
                    eprintln!("mlflow: {} answers again; logging goes on", client.base());
                }
                pause = FIRST_PAUSE;
                if ended {
                    return;
                }
            }
            Err(err) => {
                let message = format!("{err:#}");
                if failing.as_deref() != Some(message.as_str()) {
                    eprintln!(
                        "mlflow: {message}; training goes on, logging to {} is retried",
                        client.base()
                    );
                    failing = Some(message);
                }
                let until = Instant::now() + pause;
                while let Some(left) = until.checked_duration_since(Instant::now()) {
                    match rx.recv_timeout(left) {
                        Ok(op) => queue.push_back(op),
                        Err(RecvTimeoutError::Timeout) => break,
                        Err(RecvTimeoutError::Disconnected) => {
                            closed = true;
                            std::thread::sleep(left);
                            break;
                        }
                    }
                }
                pause = (pause * 2).min(LONGEST_PAUSE);
            }
        }
    }
}

/// The run a logger writes to and whether it was made now: found by its tag, or made
/// (`None`: an [`Find::Existing`] run that is not there).
fn start(
    client: &Client,
    experiment: &str,
    name: &str,
    tags: &[(String, String)],
    find: &Find,
) -> anyhow::Result<Option<(Run, bool)>> {
    let experiment_id = client.experiment(experiment)?;
    let (tag, search, create) = match find {
        Find::Tagged(key, value) => (Some((key, value)), false, true),
        Find::OrCreate(key, value) => (Some((key, value)), true, true),
        Find::Existing(key, value) => (Some((key, value)), true, false),
    };
    if let Some((key, value)) = tag.filter(|_| search) {
        if let Some(found) = client.find_run(&experiment_id, key, value)? {
            if create {
                // A job leased again: its run goes on.
                client.set_status(&found.run_id, "RUNNING", None)?;
            }
            return Ok(Some((found, false)));
        }
        if !create {
            return Ok(None);
        }
    }
    let mut tags = tags.to_vec();
    if let Some((key, value)) = tag {
        tags.push((key.clone(), value.clone()));
    }
    let made = client.create_run(&experiment_id, name, now_ms(), &tags)?;
    Ok(Some((made, true)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_document_flattens_to_dotted_parameters() {
        let long = "x".repeat(MAX_PARAM_CHARS + 10);
        let mut out = flatten(
            &serde_json::json!({"algorithm": "crm-ppo", "config": {"gamma": 0.99, "hidden": [256, 256]}, "none": null, "long": long}),
        );
        out.sort();
        assert_eq!(out[0], ("algorithm".into(), "crm-ppo".into()));
        assert_eq!(out[1], ("config.gamma".into(), "0.99".into()));
        assert_eq!(out[2], ("config.hidden".into(), "[256,256]".into()));
        assert_eq!(out[3].0, "long");
        assert_eq!(out[3].1.chars().count(), MAX_PARAM_CHARS);
        assert!(out[3].1.ends_with('…'));
        assert_eq!(out.len(), 4, "null is left out");
    }
}
