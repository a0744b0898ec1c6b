//! A coordinator client that adds the bearer token to every call, and the calls a job makes.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use crm_proto::pb::coordinator_client::CoordinatorClient;
use crm_proto::pb::{self, checkpoint_chunk, recording_chunk, video_chunk};
use tonic::metadata::{Ascii, MetadataValue};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;

/// Adds `authorization: Bearer <token>` when a token is set.
#[derive(Clone)]
pub struct AddToken(Option<MetadataValue<Ascii>>);

impl tonic::service::Interceptor for AddToken {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(value) = &self.0 {
            request
                .metadata_mut()
                .insert("authorization", value.clone());
        }
        Ok(request)
    }
}

/// A connected, registered worker.
#[derive(Clone)]
pub struct Client {
    pub inner: CoordinatorClient<InterceptedService<Channel, AddToken>>,
    pub worker_id: String,
    /// The secret the coordinator gave this worker at registration.
    pub worker_secret: String,
    /// The secret of the job this client acts for (`Job.lease_token`; empty between jobs).
    pub lease_token: String,
    pub heartbeat: Duration,
    /// The coordinator's MLflow tracking server, when it names one.
    pub mlflow: Option<MlflowSetting>,
}

/// The coordinator's MLflow setting, from its answer to `Register`.
#[derive(Clone, Debug)]
pub struct MlflowSetting {
    pub uri: String,
    pub experiment: String,
    /// This coordinator among others logging to the experiment.
    pub coordinator_id: String,
}

impl MlflowSetting {
    /// Where job `job`'s run logs.
    pub fn target(&self, job: i64) -> crate::mlflow::Target {
        crate::mlflow::Target {
            uri: self.uri.clone(),
            experiment: self.experiment.clone(),
            run_name: format!("job-{job}"),
        }
    }

    /// The tag that finds job `job`'s run: `crm.job` = `COORDINATOR/JOB`.
    pub fn job_tag(&self, job: i64) -> (String, String) {
        ("crm.job".into(), format!("{}/{job}", self.coordinator_id))
    }
}

/// tonic's TLS settings for a coordinator or a policy server: `ca` (a PEM file) as the only
/// root, or the system's roots.
pub fn client_tls(ca: Option<&Path>) -> anyhow::Result<tonic::transport::ClientTlsConfig> {
    let tls = tonic::transport::ClientTlsConfig::new();
    Ok(match ca {
        Some(path) => {
            let pem = std::fs::read(path)
                .with_context(|| format!("--ca {}: cannot read it", path.display()))?;
            if !String::from_utf8_lossy(&pem).contains("-----BEGIN CERTIFICATE-----") {
                bail!("--ca {}: no PEM certificate in it", path.display());
            }
            tls.ca_certificate(tonic::transport::Certificate::from_pem(pem))
        }
        None => tls.with_native_roots(),
    })
}

/// Bytes per uploaded chunk.
const CHUNK: usize = 256 * 1024;

impl Client {
    /// Connects to the coordinator's gRPC at `url`; an `https://` one is checked against `ca`
    /// (a PEM file) or, without it, the system's roots.
    pub async fn connect(
        url: &str,
        token: Option<&str>,
        ca: Option<&Path>,
    ) -> anyhow::Result<Self> {
        let token = match token {
            Some(t) => Some(
                format!("Bearer {t}")
                    .parse()
                    .context("--token: not a valid header value")?,
            ),
            None => None,
        };
        let mut endpoint = Channel::from_shared(url.to_string())
            .with_context(|| format!("--coordinator: {url:?} is not a URL"))?
            .connect_timeout(Duration::from_secs(5));
        if url.starts_with("https://") || ca.is_some() {
            endpoint = endpoint
                .tls_config(client_tls(ca)?)
                .context("--coordinator: TLS settings")?;
        }
        let channel = endpoint
            .connect()
            .await
            .with_context(|| format!("connecting to {url}"))?;
        let inner = CoordinatorClient::with_interceptor(channel, AddToken(token))
            .max_decoding_message_size(8 << 20);
        Ok(Self {
            inner,
            worker_id: String::new(),
            worker_secret: String::new(),
            lease_token: String::new(),
            heartbeat: Duration::from_secs(5),
            mlflow: None,
        })
    }

    /// Downloads checkpoint `id` to `path`.
    pub async fn download(&self, id: i64, path: &Path) -> anyhow::Result<pb::CheckpointMeta> {
        let mut stream = self
            .inner
            .clone()
            .download_checkpoint(pb::DownloadRequest {
                worker_id: self.worker_id.clone(),
                checkpoint_id: id,
                worker_secret: self.worker_secret.clone(),
            })
            .await?
            .into_inner();
        let meta = match stream.message().await? {
            Some(pb::CheckpointChunk {
                body: Some(checkpoint_chunk::Body::Meta(meta)),
            }) => meta,
            _ => bail!("checkpoint {id}: the coordinator sent no metadata"),
        };
        let mut bytes = Vec::with_capacity(meta.size as usize);
        while let Some(chunk) = stream.message().await? {
            if let Some(checkpoint_chunk::Body::Data(data)) = chunk.body {
                bytes.extend_from_slice(&data);
            }
        }
        if bytes.len() as u64 != meta.size {
            bail!(
                "checkpoint {id}: got {} bytes of {}",
                bytes.len(),
                meta.size
            );
        }
        tokio::fs::write(path, &bytes).await?;
        Ok(meta)
    }

    /// Appends recorded episodes (whole `.rrd` streams) to `job`'s recording; returns the
    /// stored size.
    pub async fn append_recording(
        &self,
        job: i64,
        bytes: &[u8],
        episodes: u32,
    ) -> anyhow::Result<u64> {
        let meta = pb::RecordingChunk {
            body: Some(recording_chunk::Body::Meta(pb::RecordingMeta {
                job_id: job,
                worker_id: self.worker_id.clone(),
                size: bytes.len() as u64,
                episodes,
                lease_token: self.lease_token.clone(),
            })),
        };
        let chunks: Vec<pb::RecordingChunk> = std::iter::once(meta)
            .chain(bytes.chunks(CHUNK).map(|c| pb::RecordingChunk {
                body: Some(recording_chunk::Body::Data(c.to_vec())),
            }))
            .collect();
        let reply = self
            .inner
            .clone()
            .append_recording(tokio_stream::iter(chunks))
            .await?;
        Ok(reply.into_inner().size)
    }

    /// Stores `gif` as `job`'s video (`episodes` episodes in `frames` frames of `size`);
    /// returns the stored size.
    pub async fn upload_video(
        &self,
        job: i64,
        gif: &[u8],
        episodes: u32,
        frames: u32,
        size: (u32, u32),
    ) -> anyhow::Result<u64> {
        let meta = pb::VideoChunk {
            body: Some(video_chunk::Body::Meta(pb::VideoMeta {
                job_id: job,
                worker_id: self.worker_id.clone(),
                size: gif.len() as u64,
                episodes,
                frames,
                width: size.0,
                height: size.1,
                lease_token: self.lease_token.clone(),
            })),
        };
        let chunks: Vec<pb::VideoChunk> = std::iter::once(meta)
            .chain(gif.chunks(CHUNK).map(|c| pb::VideoChunk {
                body: Some(video_chunk::Body::Data(c.to_vec())),
            }))
            .collect();
        let reply = self
            .inner
            .clone()
            .upload_video(tokio_stream::iter(chunks))
            .await?;
        Ok(reply.into_inner().size)
    }

    /// Uploads the checkpoint at `path` for `job`; returns its id.
    pub async fn upload(
        &self,
        job: i64,
        algorithm: &str,
        steps: u64,
        path: &Path,
    ) -> anyhow::Result<i64> {
        let bytes = tokio::fs::read(path).await?;
        let meta = pb::CheckpointChunk {
            body: Some(checkpoint_chunk::Body::Meta(pb::CheckpointMeta {
                job_id: job,
                worker_id: self.worker_id.clone(),
                steps,
                algorithm: algorithm.to_string(),
                size: bytes.len() as u64,
                lease_token: self.lease_token.clone(),
            })),
        };
        // Chunks are cut as the stream sends them: a checkpoint with a replay buffer is
        // hundreds of megabytes, held once.
        let total = bytes.len();
        let chunks = std::iter::once(meta).chain((0..total.div_ceil(CHUNK)).map(move |i| {
            let end = ((i + 1) * CHUNK).min(total);
            pb::CheckpointChunk {
                body: Some(checkpoint_chunk::Body::Data(bytes[i * CHUNK..end].to_vec())),
            }
        }));
        let reply = self
            .inner
            .clone()
            .upload_checkpoint(tokio_stream::iter(chunks))
            .await?;
        Ok(reply.into_inner().checkpoint_id)
    }

    pub async fn complete(&self, job: i64, result: &serde_json::Value) -> anyhow::Result<()> {
        self.inner
            .clone()
            .complete(pb::CompleteRequest {
                worker_id: self.worker_id.clone(),
                job_id: job,
                result_json: result.to_string(),
                lease_token: self.lease_token.clone(),
            })
            .await?;
        Ok(())
    }

    pub async fn fail(&self, job: i64, message: &str) -> anyhow::Result<()> {
        self.inner
            .clone()
            .fail(pb::FailRequest {
                worker_id: self.worker_id.clone(),
                job_id: job,
                message: message.to_string(),
                lease_token: self.lease_token.clone(),
            })
            .await?;
        Ok(())
    }

    /// Gives the job back to the queue unfinished (this worker is stopping).
    /// Gives `job` back unfinished; an evaluation with where it stood (`eval_progress`).
    pub async fn release(&self, job: i64, eval_progress: Option<String>) -> anyhow::Result<()> {
        self.inner
            .clone()
            .release(pb::ReleaseRequest {
                worker_id: self.worker_id.clone(),
                job_id: job,
                lease_token: self.lease_token.clone(),
                eval_progress_json: eval_progress.unwrap_or_default(),
            })
            .await?;
        Ok(())
    }
}
