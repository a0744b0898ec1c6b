//! `AppendRecording`: a worker sends recorded episodes (whole rerun streams) for a job it
//! holds; they are received whole, checked against the announced size and the per-job cap,
//! then appended to the job's `.rrd` file.

use crm_proto::pb::{self, recording_chunk};
use tonic::{Request, Response, Status, Streaming};

use super::{CoordinatorService, status};
use crate::errors::ErrorKind;

/// Most bytes one append may carry.
pub const MAX_APPEND_BYTES: u64 = 64 * 1024 * 1024;

impl CoordinatorService {
    pub(super) async fn append(
        &self,
        request: Request<Streaming<pb::RecordingChunk>>,
    ) -> Result<Response<pb::RecordingReply>, Status> {
        let mut stream = request.into_inner();
        let meta = match stream.message().await? {
            Some(pb::RecordingChunk {
                body: Some(recording_chunk::Body::Meta(meta)),
            }) => meta,
            _ => return Err(ErrorKind::InvalidField.status("the first chunk must carry meta")),
        };
        self.require_lease(&meta.worker_id, meta.job_id, &meta.lease_token)
            .await?;
        if meta.size == 0 || meta.size > MAX_APPEND_BYTES {
            return Err(
                ErrorKind::InvalidField.status(format!("meta.size: 1 to {MAX_APPEND_BYTES} bytes"))
            );
        }
        let stored = self
            .state
            .store
            .recording(meta.job_id)
            .await
            .map_err(status)?
            .map_or(0, |r| r.size as u64);
        let cap = self.state.config.max_recording_bytes;
        if stored + meta.size > cap {
            return Err(ErrorKind::TooLarge.status(format!(
                "the job's recording would pass {cap} bytes (max_recording_bytes)"
            )));
        }
        let bytes = receive(&mut stream, meta.size, |chunk| match chunk.body {
            Some(recording_chunk::Body::Data(data)) => Some(data),
            _ => None,
        })
        .await?;
        let row = self
            .state
            .store
            .append_recording(meta.job_id, &bytes, i64::from(meta.episodes))
            .await
            .map_err(status)?;
        tracing::info!(
            job = meta.job_id,
            size = row.size,
            episodes = row.episodes,
            "recording appended"
        );
        self.state.notify();
        Ok(Response::new(pb::RecordingReply {
            size: row.size as u64,
            episodes: row.episodes as u32,
        }))
    }
}

/// Receives the data chunks that follow a stream's meta chunk (an upload of a recording or a
/// video): exactly `size` bytes, each chunk's data taken by `data` (`None`: not a data chunk).
pub(super) async fn receive<T>(
    stream: &mut Streaming<T>,
    size: u64,
    data: impl Fn(T) -> Option<Vec<u8>>,
) -> Result<Vec<u8>, Status> {
    let mut bytes = Vec::with_capacity(size as usize);
    while let Some(chunk) = stream.message().await? {
        let Some(data) = data(chunk) else {
            return Err(ErrorKind::InvalidField.status("only data chunks after meta"));
        };
        if (bytes.len() + data.len()) as u64 > size {
            return Err(ErrorKind::InvalidField.status("more bytes than meta.size"));
        }
        bytes.extend_from_slice(&data);
    }
    if bytes.len() as u64 != size {
        return Err(ErrorKind::InvalidField
            .status(format!("got {} bytes, meta.size says {size}", bytes.len())));
    }
    Ok(bytes)
}
