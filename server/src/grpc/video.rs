//! `UploadVideo`: a worker sends the GIF of an evaluation's first episodes for a job it
//! holds; it is received whole, checked against the announced size, the per-job recording cap
//! and the GIF signature, then stored in place of an earlier one.

use crm_proto::pb::{self, video_chunk};
use tonic::{Request, Response, Status, Streaming};

use super::{CoordinatorService, status};
use crate::errors::ErrorKind;
use crate::store::VideoInfo;

impl CoordinatorService {
    pub(super) async fn put_video(
        &self,
        request: Request<Streaming<pb::VideoChunk>>,
    ) -> Result<Response<pb::VideoReply>, Status> {
        let mut stream = request.into_inner();
        let meta = match stream.message().await? {
            Some(pb::VideoChunk {
                body: Some(video_chunk::Body::Meta(meta)),
            }) => meta,
            _ => return Err(ErrorKind::InvalidField.status("the first chunk must carry meta")),
        };
        self.require_lease(&meta.worker_id, meta.job_id, &meta.lease_token)
            .await?;
        let cap = self
            .state
            .config
            .max_recording_bytes
            .min(super::recording::MAX_APPEND_BYTES);
        if meta.size == 0 || meta.size > cap {
            return Err(ErrorKind::InvalidField.status(format!("meta.size: 1 to {cap} bytes")));
        }
        for (field, value) in [("meta.width", meta.width), ("meta.height", meta.height)] {
            if !(16..=4096).contains(&value) {
                return Err(ErrorKind::InvalidField.status(format!("{field}: 16 to 4096 pixels")));
            }
        }
        if meta.episodes == 0 || meta.frames == 0 {
            return Err(ErrorKind::InvalidField.status("meta.episodes and meta.frames: at least 1"));
        }
        let bytes = super::recording::receive(&mut stream, meta.size, |chunk| match chunk.body {
            Some(video_chunk::Body::Data(data)) => Some(data),
            _ => None,
        })
        .await?;
        if !bytes.starts_with(b"GIF89a") && !bytes.starts_with(b"GIF87a") {
            return Err(ErrorKind::InvalidField.status("data: not a GIF"));
        }
        let info = VideoInfo {
            episodes: i64::from(meta.episodes),
            frames: i64::from(meta.frames),
            width: i64::from(meta.width),
            height: i64::from(meta.height),
        };
        let row = self
            .state
            .store
            .put_video(meta.job_id, &bytes, info)
            .await
            .map_err(status)?;
        tracing::info!(
            job = meta.job_id,
            size = row.size,
            frames = row.frames,
            "video stored"
        );
        self.state.notify();
        Ok(Response::new(pb::VideoReply {
            size: row.size as u64,
        }))
    }
}
