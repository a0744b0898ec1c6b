//! Running one leased job: heartbeats on a timer (a cancelled or lost lease stops the job),
//! progress on a client stream, checkpoints uploaded periodically and at the end; training
//! resumes from the checkpoint the lease names. A worker that is stopping (SIGTERM, SIGINT)
//! ends a training job at the next iteration boundary with a checkpoint upload, an evaluation
//! at its current episode's end with its progress (the next lease goes on from there), and
//! gives the job back to the queue. With the coordinator's MLflow setting, a training job logs
//! to its MLflow run and an evaluation into its training job's. The learning itself runs on a
//! blocking thread (it uses rayon for the environments).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use crm_api::{EvalSpec, TrainSpec};
use crm_proto::pb::{self, progress};
use tokio::sync::mpsc;

use super::{Client, WorkerOptions};
use crate::record::{Recorder, SharedRecorder, lock};
use crm_run::Env;
use crm_run::Trainer;
use crm_run::eval::{EpisodeRecord, EvalProgress, evaluate_from};

use super::video::{EvalVideo, combined};
use crm_run::imitation;

/// A scratch folder removed on drop.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// What the blocking part needs to talk to the coordinator.
pub(super) struct Link {
    pub(super) client: Client,
    job: i64,
    pub(super) handle: tokio::runtime::Handle,
    progress: mpsc::Sender<pb::Progress>,
    cancelled: Arc<AtomicBool>,
    /// The worker is stopping: end the job where it can be resumed and give it back.
    preempted: Arc<AtomicBool>,
    /// An evaluation stopped midway: where it stood (JSON), given back with the job.
    eval_progress: Arc<std::sync::Mutex<Option<String>>>,
}

impl Link {
    fn send(&self, body: progress::Body) -> anyhow::Result<()> {
        self.progress
            .blocking_send(pb::Progress {
                worker_id: self.client.worker_id.clone(),
                job_id: self.job,
                body: Some(body),
                lease_token: self.client.lease_token.clone(),
            })
            .map_err(|_| anyhow::anyhow!("the progress stream closed (lease lost?)"))
    }

    /// Whether the job must end now: cancelled, its lease lost, or the worker stopping.
    fn stopped(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed) || self.preempted()
    }

    fn preempted(&self) -> bool {
        self.preempted.load(Ordering::Relaxed)
    }
}

/// Runs `job` to its end: completes it, gives it back when `stopping` is set meanwhile (the
/// next lease resumes it), or returns the error for the caller to report.
pub async fn run_job(
    client: &Client,
    options: &WorkerOptions,
    job: pb::Job,
    stopping: &Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let id = job.job_id;
    tracing::info!(
        job = id,
        kind = job.kind,
        attempt = job.attempt,
        "running job"
    );
    let cancelled = Arc::new(AtomicBool::new(false));
    let heartbeat = {
        let mut inner = client.inner.clone();
        let request = pb::HeartbeatRequest {
            worker_id: client.worker_id.clone(),
            job_id: id,
            worker_secret: client.worker_secret.clone(),
            lease_token: client.lease_token.clone(),
        };
        let (period, flag) = (client.heartbeat, cancelled.clone());
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(period).await;
                match inner.heartbeat(request.clone()).await {
                    Ok(reply) if reply.get_ref().stop => {
                        tracing::warn!(
                            job = request.job_id,
                            "job cancelled or lease lost; stopping"
                        );
                        flag.store(true, Ordering::Relaxed);
                        return;
                    }
                    Ok(_) => {}
                    Err(status) => tracing::warn!(%status, "heartbeat failed"),
                }
            }
        })
    };
    let (tx, rx) = mpsc::channel(256);
    let reporter = {
        let mut inner = client.inner.clone();
        tokio::spawn(async move {
            inner
                .report_progress(tokio_stream::wrappers::ReceiverStream::new(rx))
                .await
        })
    };
    let scratch = Scratch(std::env::temp_dir().join(format!(
        "crm-worker-{}-job{id}-{}",
        std::process::id(),
        crm_server::store::now_ms()
    )));
    std::fs::create_dir_all(&scratch.0)?;
    let link = Link {
        client: client.clone(),
        job: id,
        handle: tokio::runtime::Handle::current(),
        progress: tx,
        cancelled: cancelled.clone(),
        preempted: stopping.clone(),
        eval_progress: Arc::default(),
    };
    let eval_progress = link.eval_progress.clone();
    let dir = scratch.0.clone();
    let options = options.clone();
    let outcome = tokio::task::spawn_blocking(move || match job.kind.as_str() {
        "train" => train(&link, &options, &job, &dir),
        "eval" => eval(&link, &options, &job, &dir),
        other => bail!("unknown job kind {other:?}"),
    })
    .await
    .context("the job's thread panicked");
    heartbeat.abort();
    // All progress is delivered before the job is completed.
    let streamed = reporter.await;
    let result = outcome??;
    if let Ok(Err(status)) = &streamed
        && !cancelled.load(Ordering::Relaxed)
    {
        tracing::warn!(%status, "progress stream ended with an error");
    }
    match result {
        Some(value) => client.complete(id, &value).await,
        None if stopping.load(Ordering::Relaxed) && !cancelled.load(Ordering::Relaxed) => {
            let progress = eval_progress
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .take();
            client.release(id, progress).await?;
            tracing::info!(job = id, "stopping: the job is queued again");
            Ok(())
        }
        None => {
            tracing::info!(job = id, "stopped");
            Ok(())
        }
    }
}

fn train(
    link: &Link,
    options: &WorkerOptions,
    job: &pb::Job,
    dir: &Path,
) -> anyhow::Result<Option<serde_json::Value>> {
    let mut spec: TrainSpec = serde_json::from_str(&job.spec_json).context("the job's spec")?;
    if spec.envs.is_none() {
        spec.envs = options.envs;
    }
    // A job resumes from its own last checkpoint (the lease names it); a fresh one may start
    // from a stored checkpoint's weights (`fine_tune`).
    let init = if job.checkpoint_id != 0 {
        let path = dir.join("resume.safetensors");
        link.handle
            .block_on(link.client.download(job.checkpoint_id, &path))
            .context("downloading the checkpoint to resume from")?;
        Some((path, true))
    } else if let Some(id) = spec.fine_tune {
        let path = dir.join("fine-tune.safetensors");
        link.handle
            .block_on(link.client.download(id, &path))
            .with_context(|| format!("fine_tune: downloading checkpoint {id}"))?;
        Some((path, false))
    } else {
        None
    };
    let algorithm = spec.algorithm.name();
    // A training job reports the episodes it records with their transitions (the run page's
    // episode list); evaluations report every episode themselves.
    let recorder = recorder_for(spec.record.as_ref(), job.job_id, true);
    let env = env_for(spec.world.as_deref(), options)?;
    let mut trainer = Trainer::new(
        spec.clone(),
        &env,
        init.as_ref().map(|(path, resume)| {
            if *resume {
                crm_run::Init::Resume(path)
            } else {
                crm_run::Init::FineTune(path)
            }
        }),
        crate::record::for_runtime(&recorder),
    )?;
    let resumed_from = trainer.steps();
    if resumed_from > 0 {
        tracing::info!(
            job = job.job_id,
            steps = resumed_from,
            "resumed from checkpoint"
        );
    } else {
        // A resumed job's checkpoint already holds the clone; a fresh one clones first (when
        // its spec asks for imitation).
        // The phases report at most once a second (and when one ends), as evaluations do.
        let mut last: Option<Instant> = None;
        let mut sent = Ok(());
        let finished = imitation::imitate(
            &spec,
            &env,
            &mut trainer,
            |line| {
                tracing::info!(job = job.job_id, "{line}");
                !link.stopped()
            },
            |name, done, total| {
                if done == total || last.is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
                    last = Some(Instant::now());
                    sent = link.send(progress::Body::Phase(pb::PhaseProgress {
                        name: name.to_string(),
                        done,
                        total,
                    }));
                }
                sent.is_ok() && !link.stopped()
            },
        )?;
        sent?;
        if !finished {
            return Ok(None);
        }
    }
    let path = dir.join("checkpoint.safetensors");
    // The coordinator's MLflow server: one run per job, found again by its tag on a new lease.
    let mlflow = link.client.mlflow.as_ref().and_then(|m| {
        let (key, value) = m.job_tag(job.job_id);
        crate::mlflow::Logger::training(
            &m.target(job.job_id),
            &spec,
            trainer.world(),
            crate::mlflow::Find::OrCreate(key, value),
        )
        .map_err(|err| tracing::warn!(err = %format!("{err:#}"), "mlflow: not logging"))
        .ok()
    });
    let every = Duration::from_secs(options.checkpoint_every_s.max(1));
    let mut last_upload = Instant::now();
    // (steps, id) of the newest upload, so the final one is not sent twice.
    let mut uploaded: Option<(u64, i64)> = None;
    // Whether the coordinator refused a checkpoint with the training state for its size.
    let mut state_refused = false;
    let mut upload = |trainer: &Trainer| -> anyhow::Result<i64> {
        if let Some((steps, id)) = uploaded
            && steps == trainer.steps()
        {
            return Ok(id);
        }
        if state_refused {
            trainer.save_policy(&path)?;
        } else {
            trainer.save(&path)?;
        }
        let send = |path: &Path| {
            link.handle.block_on(
                link.client
                    .upload(job.job_id, algorithm, trainer.steps(), path),
            )
        };
        let id = match send(&path) {
            // The whole training state (a large replay buffer) is over the coordinator's
            // limit: the policy alone from now on, so that the run goes on; a resume will
            // not be the same run.
            Err(error) if !state_refused && !trainer.finished() && too_large(&error).is_some() => {
                state_refused = true;
                eprintln!(
                    "job {}: the checkpoint with its training state is refused ({}); \
                     uploading the policy alone from now on",
                    job.job_id,
                    too_large(&error).unwrap_or_default()
                );
                trainer.save_policy(&path)?;
                send(&path)
            }
            other => other,
        }
        .context("uploading a checkpoint")?;
        uploaded = Some((trainer.steps(), id));
        Ok(id)
    };
    while !trainer.finished() {
        if link.stopped() {
            if link.preempted() && !link.cancelled.load(Ordering::Relaxed) {
                // Stopping: the run's state so far, for whoever leases the job next.
                upload(&trainer)?;
            }
            if let Some(mlflow) = mlflow {
                mlflow.finish(Some("KILLED"), MLFLOW_WAIT);
            }
            return Ok(None);
        }
        let it = trainer.iterate()?;
        let sent = link.send(progress::Body::IterationJson(serde_json::to_string(&it)?));
        if let Some(mlflow) = &mlflow {
            mlflow.metrics(it.steps, &crm_api::tensorboard::scalars(&it));
        }
        if sent.is_err() && link.stopped() {
            return Ok(None);
        }
        sent?;
        ship(link, job.job_id, recorder.as_ref());
        if last_upload.elapsed() >= every {
            upload(&trainer)?;
            last_upload = Instant::now();
        }
    }
    if link.stopped() {
        return Ok(None);
    }
    let checkpoint_id = upload(&trainer)?;
    ship(link, job.job_id, recorder.as_ref());
    if let Some(mlflow) = mlflow {
        if let Err(err) = mlflow.checkpoint(&path) {
            tracing::warn!(err = %format!("{err:#}"), "mlflow: the checkpoint is not logged");
        }
        mlflow.finish(Some("FINISHED"), MLFLOW_WAIT);
    }
    Ok(Some(serde_json::json!({
        "steps": trainer.steps(),
        "stopped_early": trainer.stopped_early(),
        "resumed_from_steps": resumed_from,
        "fine_tuned_from": spec.fine_tune,
        "checkpoint_id": checkpoint_id,
    })))
}

fn eval(
    link: &Link,
    options: &WorkerOptions,
    job: &pb::Job,
    dir: &Path,
) -> anyhow::Result<Option<serde_json::Value>> {
    let spec: EvalSpec = serde_json::from_str(&job.spec_json).context("the job's spec")?;
    let env = env_for(spec.world.as_deref(), options)?;
    let path = dir.join("eval.safetensors");
    link.handle
        .block_on(link.client.download(job.checkpoint_id, &path))
        .context("downloading the checkpoint")?;
    let mut last = Instant::now();
    let mut send_failed = None;
    let recorder = recorder_for(spec.record.as_ref(), job.job_id, false);
    // Given back midway before: go on from where it stood, the episodes done kept.
    let mut from = match job.eval_progress_json.as_str() {
        "" => EvalProgress::default(),
        text => serde_json::from_str(text).context("the job's eval_progress_json")?,
    };
    let resumed_from = from.done;
    if let Some(recorder) = &recorder {
        lock(recorder).skip_episodes(resumed_from);
    }
    let mut video = EvalVideo::for_job(&spec, resumed_from);
    let runtime = combined(crate::record::for_runtime(&recorder), video.as_ref());
    let report = evaluate_from(
        &path,
        &spec,
        &env,
        runtime,
        &mut from,
        |done, total, record| {
            ship(link, job.job_id, recorder.as_ref());
            if let Some(video) = &mut video {
                video.ship_when_done(link, job.job_id, done, total);
            }
            let mut sent = link.send(summary(record));
            if sent.is_ok() && (done == total || last.elapsed() >= Duration::from_secs(1)) {
                last = Instant::now();
                sent = link.send(progress::Body::Eval(pb::EvalProgress {
                    episodes_done: done,
                    episodes_total: total,
                }));
            }
            if let Err(err) = sent {
                send_failed = Some(err);
                return false;
            }
            !link.stopped()
        },
    );
    if link.cancelled.load(Ordering::Relaxed) {
        return Ok(None);
    }
    if link.preempted() && report.is_err() {
        // Stopping midway: where it stood, for whoever leases the job next (unless an
        // episode's summary may not have reached the coordinator).
        ship(link, job.job_id, recorder.as_ref());
        if send_failed.is_none() {
            let progress = serde_json::to_string(&from)?;
            *link
                .eval_progress
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(progress);
        }
        return Ok(None);
    }
    if let Some(err) = send_failed {
        return Err(err);
    }
    ship(link, job.job_id, recorder.as_ref());
    let report = report?;
    // Into the MLflow run of the training job that made the checkpoint.
    if let Some(m) = &link.client.mlflow
        && job.train_job_id != 0
    {
        let (key, value) = m.job_tag(job.train_job_id);
        match crate::mlflow::Logger::start(
            &m.target(job.train_job_id),
            crate::mlflow::Find::Existing(key, value),
            Vec::new(),
            Vec::new(),
        ) {
            Ok(mlflow) => {
                mlflow.metrics(report.trained_steps, &eval_scalars(&report));
                let kind = if report.deterministic {
                    "deterministic"
                } else {
                    "sampled"
                };
                mlflow.tags(vec![(
                    format!("crm.eval.{kind}.job"),
                    job.job_id.to_string(),
                )]);
                mlflow.finish(None, MLFLOW_WAIT);
            }
            Err(err) => tracing::warn!(err = %format!("{err:#}"), "mlflow: not logging"),
        }
    }
    let mut value = serde_json::to_value(report)?;
    value["checkpoint_id"] = serde_json::Value::from(job.checkpoint_id);
    if resumed_from > 0 {
        value["resumed_from_episodes"] = serde_json::Value::from(resumed_from);
    }
    Ok(Some(value))
}

/// An episode's summary as the coordinator stores it.
/// The environment options of a job's world: the built-in one, or the folder of that name
/// under this worker's `--worlds`.
fn env_for(world: Option<&str>, options: &WorkerOptions) -> anyhow::Result<Env> {
    match world {
        None => Ok(Env::default()),
        Some(name) if name == crm_api::worlds::BUILTIN => Ok(Env::default()),
        Some(name) => {
            let found = crm_api::worlds::discover(options.worlds.as_deref())?
                .into_iter()
                .find(|w| w.name == name)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "this worker has no world {name:?}: start it with --worlds naming the \
                         folder that holds it"
                    )
                })?;
            Ok(Env::new(crm_run::EnvSpec {
                world: found.dir,
                ..crm_run::EnvSpec::default()
            }))
        }
    }
}

fn summary(record: &EpisodeRecord) -> progress::Body {
    progress::Body::Episode(pb::EpisodeSummary {
        task: record.task.clone(),
        success: record.success,
        length: record.length as u32,
        episode_return: record.total_return as f32,
        transitions: record
            .transitions
            .iter()
            .map(|(step, from, to, event, reward)| pb::Transition {
                step: *step as u32,
                from_stage: from.clone(),
                to_stage: to.clone(),
                event: event.clone(),
                reward: *reward,
            })
            .collect(),
    })
}

/// The job's recorder, when its spec asks for one; with `summaries` it keeps the recorded
/// episodes' summaries for [`ship`] to report.
fn recorder_for(
    spec: Option<&crm_api::RecordSpec>,
    job: i64,
    summaries: bool,
) -> Option<SharedRecorder> {
    spec.filter(|r| r.enabled()).map(|r| {
        let recorder = Recorder::new(r, format!("job {job}"));
        if summaries {
            recorder.keeping_summaries().shared()
        } else {
            recorder.shared()
        }
    })
}

/// Sends what the recorder holds to the coordinator: the summaries of the episodes it kept
/// (training jobs), then the recording. A failed append loses those episodes'
/// recording, never the job.
fn ship(link: &Link, job: i64, recorder: Option<&SharedRecorder>) {
    let Some(recorder) = recorder else {
        return;
    };
    let (pending, summaries) = {
        let mut recorder = lock(recorder);
        (recorder.take_pending(), recorder.take_summaries())
    };
    for record in &summaries {
        if let Err(err) = link.send(summary(record)) {
            tracing::warn!(job, err = %format!("{err:#}"), "an episode summary was not sent");
        }
    }
    let Some((bytes, episodes)) = pending else {
        return;
    };
    match link
        .handle
        .block_on(link.client.append_recording(job, &bytes, episodes))
    {
        Ok(size) => tracing::debug!(job, size, episodes, "recording appended"),
        Err(err) => {
            tracing::warn!(job, err = %format!("{err:#}"), "a recording append failed; those episodes are not kept")
        }
    }
}

/// The coordinator's message when an upload was refused for its size (gRPC
/// `RESOURCE_EXHAUSTED`).
fn too_large(error: &anyhow::Error) -> Option<String> {
    error
        .downcast_ref::<tonic::Status>()
        .filter(|status| status.code() == tonic::Code::ResourceExhausted)
        .map(|status| status.message().to_string())
}

/// How long a job's end waits for its MLflow records to reach the server.
const MLFLOW_WAIT: Duration = Duration::from_secs(10);

/// An evaluation's figures as MLflow metrics: `eval/sampled/...` or `eval/deterministic/...`,
/// overall and per objective.
fn eval_scalars(report: &crm_api::EvalReport) -> Vec<(String, f64)> {
    let kind = if report.deterministic {
        "deterministic"
    } else {
        "sampled"
    };
    let mut out = vec![
        (format!("eval/{kind}/success_rate"), report.success_rate),
        (
            format!("eval/{kind}/mean_episode_length"),
            report.mean_episode_length,
        ),
        (format!("eval/{kind}/episodes"), report.episodes as f64),
    ];
    for (objective, row) in &report.per_objective {
        out.push((
            format!("eval/{kind}/{objective}/success_rate"),
            row.success_rate,
        ));
    }
    out
}
