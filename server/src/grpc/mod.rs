//! The gRPC side (tonic): the `Coordinator` service workers call to register, lease jobs,
//! heartbeat, stream progress, move checkpoints in chunks, append rerun recordings
//! (`recording.rs`) and finish jobs. With a token
//! configured, every call must carry `authorization: Bearer <token>`.

use std::pin::Pin;
use std::sync::Arc;

use crm_proto::pb::coordinator_server::{Coordinator, CoordinatorServer};
use crm_proto::pb::{self, checkpoint_chunk, progress};
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;
use tokio_stream::Stream;
use tonic::service::interceptor::InterceptedService;
use tonic::{Request, Response, Status, Streaming};

use crate::AppState;
use crate::auth::{Scope, Tokens, Verdict};
use crate::errors::ErrorKind;
use crate::secrets;
use crate::store::{Lease, NewCheckpoint, StoreError};

mod recording;
mod video;

/// Bytes per checkpoint chunk sent to workers.
pub const CHUNK: usize = 256 * 1024;

/// Largest evaluation progress a worker may give back: its running sums per objective and
/// per task (a few kilobytes for the built-in benchmark's 26 tasks).
const MAX_EVAL_PROGRESS_BYTES: usize = 1 << 20;

/// Refuses calls without a token holding `scope` (`crate::auth`): `Unauthenticated` without a
/// known token, `PermissionDenied` with one lacking the scope.
#[derive(Clone)]
pub struct TokenCheck {
    tokens: Arc<Tokens>,
    scope: Scope,
}

impl TokenCheck {
    pub fn new(tokens: Tokens, scope: Scope) -> Self {
        Self {
            tokens: Arc::new(tokens),
            scope,
        }
    }
}

impl tonic::service::Interceptor for TokenCheck {
    fn call(&mut self, request: Request<()>) -> Result<Request<()>, Status> {
        let given = crate::auth::bearer(
            request
                .metadata()
                .get("authorization")
                .and_then(|v| v.to_str().ok()),
        );
        match self.tokens.check(given, self.scope) {
            Verdict::Allowed => Ok(request),
            Verdict::Unauthenticated => {
                Err(ErrorKind::Unauthorized.status("missing or wrong bearer token"))
            }
            Verdict::Forbidden => Err(ErrorKind::Forbidden
                .status(format!("this token lacks the {} scope", self.scope.name()))),
        }
    }
}

/// The coordinator service with its token check (the worker scope).
pub fn service(
    state: Arc<AppState>,
) -> InterceptedService<CoordinatorServer<CoordinatorService>, TokenCheck> {
    let check = TokenCheck::new(state.tokens.clone(), Scope::Worker);
    let max = (CHUNK * 4).max(4 << 20);
    InterceptedService::new(
        CoordinatorServer::new(CoordinatorService { state })
            .max_decoding_message_size(max)
            .max_encoding_message_size(max),
        check,
    )
}

pub struct CoordinatorService {
    state: Arc<AppState>,
}

fn status(err: StoreError) -> Status {
    let message = match &err {
        StoreError::NotFound => "unknown worker, job or checkpoint".to_string(),
        StoreError::Conflict(state) => format!("job is {state}"),
        other => {
            tracing::error!(err = %other, "store error");
            other.to_string()
        }
    };
    ErrorKind::of_store(&err).status(message)
}

impl CoordinatorService {
    fn ttl_ms(&self) -> i64 {
        i64::from(self.state.config.lease_ttl_s) * 1000
    }

    /// Refuses a call about `job` unless `token` is its current lease's secret and
    /// `worker` holds that lease (a stale lease's token, or another worker's, is refused);
    /// returns the token's hash, which names the lease in the store.
    async fn require_lease(&self, worker: &str, job: i64, token: &str) -> Result<String, Status> {
        let hash = secrets::hash(token);
        if self
            .state
            .store
            .holds(Lease::new(worker, job, &hash))
            .await
            .map_err(status)?
        {
            Ok(hash)
        } else {
            Err(ErrorKind::Conflict.status(format!(
                "worker {worker} does not hold job {job} under this lease token"
            )))
        }
    }

    /// Refuses a call naming `worker` unless `secret` is the one it was given at registration.
    async fn require_worker(&self, worker: &str, secret: &str) -> Result<(), Status> {
        let hash = secrets::hash(secret);
        if self
            .state
            .store
            .worker_secret_matches(worker, &hash)
            .await
            .map_err(status)?
        {
            Ok(())
        } else {
            Err(ErrorKind::Forbidden.status(format!(
                "worker_secret: not the secret worker {worker} was registered with"
            )))
        }
    }
}

#[tonic::async_trait]
impl Coordinator for CoordinatorService {
    async fn register(
        &self,
        request: Request<pb::RegisterRequest>,
    ) -> Result<Response<pb::RegisterReply>, Status> {
        let r = request.into_inner();
        crm_api::check_name(&r.name)
            .map_err(|why| ErrorKind::InvalidField.status(format!("name: {why}")))?;
        let secret =
            secrets::new_secret().map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
        let worker = self
            .state
            .store
            .register_worker(
                &r.name,
                i64::from(r.cores),
                &r.version,
                &secrets::hash(&secret),
            )
            .await
            .map_err(status)?;
        tracing::info!(worker = worker.id, name = worker.name, "worker registered");
        let config = &self.state.config;
        let canonical =
            std::fs::canonicalize(&config.data_dir).unwrap_or_else(|_| config.data_dir.clone());
        Ok(Response::new(pb::RegisterReply {
            worker_id: worker.id,
            heartbeat_interval_s: config.heartbeat_interval_s,
            lease_ttl_s: config.lease_ttl_s,
            worker_secret: secret,
            mlflow_uri: config.mlflow_uri.clone().unwrap_or_default(),
            mlflow_experiment: config.mlflow_experiment.clone(),
            coordinator_id: crate::launcher::short_hash(canonical.to_string_lossy().as_bytes()),
        }))
    }

    async fn lease(
        &self,
        request: Request<pb::LeaseRequest>,
    ) -> Result<Response<pb::LeaseReply>, Status> {
        let r = request.into_inner();
        let worker = r.worker_id;
        self.require_worker(&worker, &r.worker_secret).await?;
        let store = &self.state.store;
        let token = secrets::new_secret().map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
        let hash = secrets::hash(&token);
        let leased = store.lease(&worker, &hash, self.ttl_ms()).await;
        let Some(job) = leased.map_err(status)? else {
            return Ok(Response::new(pb::LeaseReply { job: None }));
        };
        let eval_progress_json = match job.kind.as_str() {
            "eval" => store
                .eval_resume(job.id)
                .await
                .map_err(status)?
                .unwrap_or_default(),
            _ => String::new(),
        };
        // An evaluation's training job: the one that saved the checkpoint it evaluates.
        let train_job_id = match (job.kind.as_str(), job.checkpoint_id) {
            ("eval", Some(checkpoint)) => store
                .checkpoint(checkpoint)
                .await
                .ok()
                .and_then(|c| c.job_id)
                .unwrap_or(0),
            _ => 0,
        };
        let checkpoint_id = match job.kind.as_str() {
            "eval" => job.checkpoint_id.unwrap_or(0),
            _ => store
                .latest_checkpoint(job.id)
                .await
                .map_err(status)?
                .map_or(0, |c| c.id),
        };
        tracing::info!(
            job = job.id,
            worker,
            attempt = job.attempts,
            checkpoint_id,
            "job leased"
        );
        self.state.notify();
        Ok(Response::new(pb::LeaseReply {
            job: Some(pb::Job {
                job_id: job.id,
                kind: job.kind,
                spec_json: job.spec,
                checkpoint_id,
                attempt: u32::try_from(job.attempts - 1).unwrap_or(0),
                lease_token: token,
                eval_progress_json,
                train_job_id,
            }),
        }))
    }

    async fn heartbeat(
        &self,
        request: Request<pb::HeartbeatRequest>,
    ) -> Result<Response<pb::HeartbeatReply>, Status> {
        let r = request.into_inner();
        self.require_worker(&r.worker_id, &r.worker_secret).await?;
        let hash = secrets::hash(&r.lease_token);
        let lease = Lease::new(&r.worker_id, r.job_id, &hash);
        let held = self
            .state
            .store
            .heartbeat(lease, self.ttl_ms())
            .await
            .map_err(status)?;
        Ok(Response::new(pb::HeartbeatReply { stop: !held }))
    }

    async fn report_progress(
        &self,
        request: Request<Streaming<pb::Progress>>,
    ) -> Result<Response<pb::ProgressReply>, Status> {
        let mut stream = request.into_inner();
        let store = &self.state.store;
        let mut accepted = 0;
        let mut leased: Option<(String, i64, String, u64)> = None;
        while let Some(message) = stream.message().await? {
            let key = (message.worker_id.clone(), message.job_id);
            let budget = match &leased {
                Some((w, j, t, budget)) if (w, *j, t) == (&key.0, key.1, &message.lease_token) => {
                    *budget
                }
                _ => {
                    self.require_lease(&key.0, key.1, &message.lease_token)
                        .await?;
                    let job = store.job(key.1).await.map_err(status)?;
                    let budget = serde_json::from_str::<serde_json::Value>(&job.spec)
                        .ok()
                        .and_then(|s| s["steps"].as_u64().or(s["episodes"].as_u64()))
                        .unwrap_or(1);
                    leased = Some((key.0.clone(), key.1, message.lease_token.clone(), budget));
                    budget
                }
            };
            match message.body {
                Some(progress::Body::IterationJson(json)) => {
                    let it: crm_api::Iteration = serde_json::from_str(&json).map_err(|e| {
                        ErrorKind::InvalidField.status(format!("iteration_json: {e}"))
                    })?;
                    if i64::try_from(it.steps).is_err() || i64::try_from(it.iteration).is_err() {
                        return Err(ErrorKind::InvalidField
                            .status("iteration_json: steps and iteration must be below 2^63"));
                    }
                    let fraction = (it.steps as f64 / budget.max(1) as f64).min(1.0);
                    store
                        .add_metric(key.1, &it, fraction)
                        .await
                        .map_err(status)?;
                }
                Some(progress::Body::Eval(eval)) => {
                    let fraction = eval.episodes_done as f64 / eval.episodes_total.max(1) as f64;
                    store
                        .set_progress(key.1, fraction.min(1.0))
                        .await
                        .map_err(status)?;
                }
                Some(progress::Body::Episode(episode)) => {
                    let json = serde_json::json!({
                        "task": episode.task,
                        "success": episode.success,
                        "length": episode.length,
                        "return": episode.episode_return,
                        "transitions": episode.transitions.iter().map(|t| serde_json::json!({
                            "step": t.step, "from": t.from_stage, "to": t.to_stage,
                            "event": t.event, "reward": t.reward,
                        })).collect::<Vec<_>>(),
                    });
                    store
                        .add_episode(
                            key.1,
                            &json.to_string(),
                            i64::from(self.state.config.episodes_kept),
                        )
                        .await
                        .map_err(status)?;
                }
                Some(progress::Body::Phase(phase)) => {
                    if phase.name.is_empty() || phase.name.len() > 64 || phase.done > phase.total {
                        return Err(ErrorKind::InvalidField
                            .status("phase: a name of 1 to 64 bytes and done <= total"));
                    }
                    store
                        .set_phase(key.1, &phase.name, phase.done, phase.total)
                        .await
                        .map_err(status)?;
                }
                None => return Err(ErrorKind::InvalidField.status("progress: empty body")),
            }
            accepted += 1;
            self.state.notify();
        }
        Ok(Response::new(pb::ProgressReply { accepted }))
    }

    async fn upload_checkpoint(
        &self,
        request: Request<Streaming<pb::CheckpointChunk>>,
    ) -> Result<Response<pb::CheckpointReply>, Status> {
        let mut stream = request.into_inner();
        let meta = match stream.message().await? {
            Some(pb::CheckpointChunk {
                body: Some(checkpoint_chunk::Body::Meta(meta)),
            }) => meta,
            _ => return Err(ErrorKind::InvalidField.status("the first chunk must carry meta")),
        };
        self.require_lease(&meta.worker_id, meta.job_id, &meta.lease_token)
            .await?;
        if crm_api::Algorithm::parse(&meta.algorithm).is_none() {
            return Err(ErrorKind::InvalidField.status("meta.algorithm: unknown algorithm"));
        }
        let Ok(steps) = i64::try_from(meta.steps) else {
            return Err(ErrorKind::InvalidField.status("meta.steps: must be below 2^63"));
        };
        let max = self.state.config.max_checkpoint_bytes;
        if meta.size > max {
            return Err(ErrorKind::TooLarge.status(format!(
                "meta.size: {} bytes, over this coordinator's limit of {max} \
                 (crm-server --max-checkpoint-bytes)",
                meta.size
            )));
        }
        let dir = self.state.store.checkpoint_dir();
        let name = format!(
            "job{}-{}-{}.safetensors",
            meta.job_id,
            meta.steps,
            crate::store::now_ms()
        );
        let partial = dir.join(format!("{name}.partial"));
        let mut file = tokio::fs::File::create(&partial)
            .await
            .map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
        let mut written = 0u64;
        // The file's hash, and its first bytes up to the end of the safetensors header.
        let mut hasher = Sha256::new();
        let mut prefix = Vec::new();
        let mut want = 8u64;
        let result: Result<(), Status> = async {
            while let Some(chunk) = stream.message().await? {
                let Some(checkpoint_chunk::Body::Data(data)) = chunk.body else {
                    return Err(ErrorKind::InvalidField.status("only data chunks after meta"));
                };
                written += data.len() as u64;
                if written > meta.size {
                    return Err(ErrorKind::InvalidField.status("more bytes than meta.size"));
                }
                hasher.update(&data);
                let mut offset = 0;
                while (prefix.len() as u64) < want && offset < data.len() {
                    let take = ((want - prefix.len() as u64) as usize).min(data.len() - offset);
                    prefix.extend_from_slice(&data[offset..offset + take]);
                    offset += take;
                    if prefix.len() >= 8 {
                        want = crm_api::checkpoint::header_len(&prefix).unwrap_or(8);
                    }
                }
                file.write_all(&data)
                    .await
                    .map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
            }
            if written != meta.size {
                return Err(ErrorKind::InvalidField
                    .status(format!("got {written} bytes, meta.size says {}", meta.size)));
            }
            // Checked as an uploaded checkpoint is: a file its evaluations could not load
            // is refused now, not when a worker tries.
            let info = crm_api::checkpoint::inspect(&prefix, written)
                .map_err(|e| ErrorKind::InvalidField.status(format!("checkpoint: {e}")))?;
            if info.algorithm.name() != meta.algorithm {
                return Err(ErrorKind::InvalidField.status(format!(
                    "meta.algorithm: {:?}, the checkpoint says {:?}",
                    meta.algorithm,
                    info.algorithm.name()
                )));
            }
            file.sync_all()
                .await
                .map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
            tokio::fs::rename(&partial, dir.join(&name))
                .await
                .map_err(|e| ErrorKind::Internal.status(e.to_string()))
        }
        .await;
        if let Err(err) = result {
            tokio::fs::remove_file(&partial).await.ok();
            return Err(err);
        }
        let sha256 = crate::uploads::hex(&hasher.finalize());
        let row = self
            .state
            .store
            .add_checkpoint(&NewCheckpoint {
                job: Some(meta.job_id),
                algorithm: &meta.algorithm,
                steps,
                size: written as i64,
                file: &name,
                sha256: &sha256,
                name: None,
            })
            .await
            .map_err(status)?;
        tracing::info!(
            job = meta.job_id,
            checkpoint = row.id,
            steps = meta.steps,
            "checkpoint stored"
        );
        let keep = self.state.config.keep_checkpoints;
        match self.state.store.prune_checkpoints(meta.job_id, keep).await {
            Ok(0) => {}
            Ok(removed) => tracing::info!(job = meta.job_id, removed, "old checkpoints removed"),
            Err(err) => tracing::warn!(job = meta.job_id, %err, "checkpoint retention failed"),
        }
        self.state.notify();
        Ok(Response::new(pb::CheckpointReply {
            checkpoint_id: row.id,
        }))
    }

    async fn append_recording(
        &self,
        request: Request<Streaming<pb::RecordingChunk>>,
    ) -> Result<Response<pb::RecordingReply>, Status> {
        self.append(request).await
    }

    async fn upload_video(
        &self,
        request: Request<Streaming<pb::VideoChunk>>,
    ) -> Result<Response<pb::VideoReply>, Status> {
        self.put_video(request).await
    }

    type DownloadCheckpointStream =
        Pin<Box<dyn Stream<Item = Result<pb::CheckpointChunk, Status>> + Send>>;

    async fn download_checkpoint(
        &self,
        request: Request<pb::DownloadRequest>,
    ) -> Result<Response<Self::DownloadCheckpointStream>, Status> {
        let r = request.into_inner();
        self.require_worker(&r.worker_id, &r.worker_secret).await?;
        let row = self
            .state
            .store
            .checkpoint(r.checkpoint_id)
            .await
            .map_err(status)?;
        let bytes = tokio::fs::read(self.state.store.checkpoint_path(&row))
            .await
            .map_err(|e| ErrorKind::Internal.status(e.to_string()))?;
        let meta = pb::CheckpointChunk {
            body: Some(checkpoint_chunk::Body::Meta(pb::CheckpointMeta {
                job_id: row.job_id.unwrap_or(0),
                worker_id: String::new(),
                steps: row.steps as u64,
                algorithm: row.algorithm,
                size: bytes.len() as u64,
                lease_token: String::new(),
            })),
        };
        let chunks: Vec<Result<pb::CheckpointChunk, Status>> = std::iter::once(Ok(meta))
            .chain(bytes.chunks(CHUNK).map(|c| {
                Ok(pb::CheckpointChunk {
                    body: Some(checkpoint_chunk::Body::Data(c.to_vec())),
                })
            }))
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }

    async fn complete(
        &self,
        request: Request<pb::CompleteRequest>,
    ) -> Result<Response<pb::CompleteReply>, Status> {
        let r = request.into_inner();
        if serde_json::from_str::<serde_json::Value>(&r.result_json).is_err() {
            return Err(ErrorKind::InvalidField.status("result_json: not JSON"));
        }
        let hash = self
            .require_lease(&r.worker_id, r.job_id, &r.lease_token)
            .await?;
        let evaluation = self
            .state
            .store
            .succeed(Lease::new(&r.worker_id, r.job_id, &hash), &r.result_json)
            .await
            .map_err(status)?;
        tracing::info!(job = r.job_id, worker = r.worker_id, "job succeeded");
        if let Some(eval) = evaluation {
            tracing::info!(job = r.job_id, eval, "the sweep's evaluation queued");
        }
        self.state.notify();
        Ok(Response::new(pb::CompleteReply {}))
    }

    async fn fail(
        &self,
        request: Request<pb::FailRequest>,
    ) -> Result<Response<pb::CompleteReply>, Status> {
        let r = request.into_inner();
        let hash = self
            .require_lease(&r.worker_id, r.job_id, &r.lease_token)
            .await?;
        let lease = Lease::new(&r.worker_id, r.job_id, &hash);
        self.state
            .store
            .finish(lease, "failed", None, Some(&r.message))
            .await
            .map_err(status)?;
        tracing::warn!(
            job = r.job_id,
            worker = r.worker_id,
            message = r.message,
            "job failed"
        );
        self.state.notify();
        Ok(Response::new(pb::CompleteReply {}))
    }

    async fn release(
        &self,
        request: Request<pb::ReleaseRequest>,
    ) -> Result<Response<pb::CompleteReply>, Status> {
        let r = request.into_inner();
        let hash = self
            .require_lease(&r.worker_id, r.job_id, &r.lease_token)
            .await?;
        let progress = match r.eval_progress_json.as_str() {
            "" => None,
            text => {
                let kind = self.state.store.job(r.job_id).await.map_err(status)?.kind;
                let parsed: Option<serde_json::Value> = serde_json::from_str(text).ok();
                let fits = parsed
                    .as_ref()
                    .is_some_and(|v| v.is_object() && v["done"].is_u64());
                if kind != "eval" || text.len() > MAX_EVAL_PROGRESS_BYTES || !fits {
                    return Err(ErrorKind::InvalidField.status(format!(
                        "eval_progress_json: an evaluation's progress, a JSON object with \
                         \"done\" of at most {MAX_EVAL_PROGRESS_BYTES} bytes"
                    )));
                }
                Some(text)
            }
        };
        self.state
            .store
            .release(Lease::new(&r.worker_id, r.job_id, &hash), progress)
            .await
            .map_err(status)?;
        tracing::info!(
            job = r.job_id,
            worker = r.worker_id,
            "job given back; queued again"
        );
        self.state.notify();
        Ok(Response::new(pb::CompleteReply {}))
    }
}
