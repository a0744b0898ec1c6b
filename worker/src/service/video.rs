//! An evaluation job's video (`"video": {"episodes": N}`): a [`VideoRecorder`] beside the
//! job's rerun recorder follows its first N episodes; once they have ended (or the
//! evaluation has, if shorter) the frames go up as one GIF (`UploadVideo`), which the
//! dashboard's run page plays. An evaluation given back midway and resumed films its next
//! episodes instead; a failed upload loses the video, never the job.

use std::sync::{Arc, Mutex};

use crm_api::EvalSpec;

use super::run::Link;
use crate::video::{self, SharedVideo, VideoRecorder};

pub struct EvalVideo {
    recorder: SharedVideo,
    /// Episodes done when the video's last one ends.
    until: u64,
    size: (u32, u32),
    uploaded: bool,
}

impl EvalVideo {
    /// The video `spec` asks for, following the episodes from `resumed_from` on; none when it
    /// asks none or they were done before.
    pub fn for_job(spec: &EvalSpec, resumed_from: u64) -> Option<Self> {
        let video = spec.video.as_ref()?;
        (resumed_from < video.episodes).then(|| {
            let size = (video.width, video.height);
            EvalVideo {
                recorder: VideoRecorder::new(video.episodes - resumed_from, size).shared(),
                until: video.episodes,
                size,
                uploaded: false,
            }
        })
    }

    pub fn recorder(&self) -> crm_run::SharedRecorder {
        self.recorder.clone()
    }

    /// Uploads the video once `done` of `total` episodes have ended and its last one is
    /// among them (once).
    pub fn ship_when_done(&mut self, link: &Link, job: i64, done: u64, total: u64) {
        if self.uploaded || (done < self.until && done < total) {
            return;
        }
        self.uploaded = true;
        let (frames, episodes) = {
            let mut recorder = video::lock(&self.recorder);
            (recorder.take_frames(), recorder.ended)
        };
        if frames.is_empty() {
            return;
        }
        let shipped = video::gif_bytes(&frames).and_then(|gif| {
            link.handle.block_on(link.client.upload_video(
                job,
                &gif,
                episodes.max(1) as u32,
                frames.len() as u32,
                self.size,
            ))
        });
        match shipped {
            Ok(size) => tracing::info!(job, size, frames = frames.len(), "video uploaded"),
            Err(err) => {
                tracing::warn!(job, err = %format!("{err:#}"), "the video upload failed; the evaluation goes on without it")
            }
        }
    }
}

/// One recorder for the runtime from the job's rerun recorder and its video, either or both.
pub fn combined(
    rerun: Option<crm_run::SharedRecorder>,
    video: Option<&EvalVideo>,
) -> Option<crm_run::SharedRecorder> {
    match (rerun, video) {
        (None, None) => None,
        (Some(r), None) => Some(r),
        (None, Some(v)) => Some(v.recorder()),
        (Some(r), Some(v)) => Some(Arc::new(Mutex::new(crm_run::record::Tee(vec![
            r,
            v.recorder(),
        ])))),
    }
}
