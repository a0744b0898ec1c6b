//! Rerun recordings (issue: stream stage transitions and trajectories to the viewer). A
//! [`Recorder`] is shared by the environment that records (`crm_run::record::Recorded`, which
//! calls it through the runtime's `Recorder` and `EpisodeLog` traits; each control step of a
//! recorded episode is logged by `scene.rs`) and by the job that ships the bytes: every Nth episode becomes its own rerun recording (so the viewer lists
//! episodes side by side), written to memory and handed out as whole `.rrd` streams, which
//! concatenate into one file; or each recording streams live to a viewer. Training series
//! (success, returns, stage mix per iteration) go to one more recording. `inspect.rs` reads a
//! file back.

pub mod inspect;
mod scene;

use std::any::Any;
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use anyhow::Context;
use crm_api::{Iteration, RecordSpec};
use rerun::sink::MemorySinkStorage;
use rerun::{RecordingStream, RecordingStreamBuilder};

use crm_run::eval::EpisodeRecord;
use crm_run::record::{EpisodeLog, Move};

/// The application id every recording carries.
pub const APP_ID: &str = "crm-grasp";

/// Where recordings go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    /// Into memory, taken out by [`Recorder::take_pending`] (for a file or an upload).
    Memory,
    /// Live to a viewer (`rerun+http://HOST:PORT/proxy`).
    Live(String),
    /// Nowhere: the viewer was unreachable (the job goes on).
    Off,
}

/// One recorded episode's stream.
pub struct EpisodeStream {
    pub rec: RecordingStream,
    storage: Option<MemorySinkStorage>,
}

/// What a job records and what it has recorded so far.
pub struct Recorder {
    target: Target,
    every: u64,
    max_episodes: u64,
    /// Names recordings: `job 12`, `checkpoint policy.safetensors`.
    label: String,
    seen: u64,
    recorded: u64,
    training: Option<EpisodeStream>,
    pending: Vec<u8>,
    pending_episodes: u32,
    /// The recorded episodes' summaries with their transitions, kept for a training job to
    /// report (evaluations report every episode on their own); `None` keeps none.
    summaries: Option<Vec<EpisodeRecord>>,
}

/// A recorder shared between an environment and its job (the runtime takes it as a
/// `crm_run::record::SharedRecorder`).
pub type SharedRecorder = Arc<Mutex<Recorder>>;

/// The recorder as the runtime takes it.
pub fn for_runtime(recorder: &Option<SharedRecorder>) -> Option<crm_run::SharedRecorder> {
    recorder
        .clone()
        .map(|recorder| recorder as crm_run::SharedRecorder)
}

/// Locks a shared recorder; a poisoned lock still holds usable counters.
pub fn lock(recorder: &SharedRecorder) -> MutexGuard<'_, Recorder> {
    recorder.lock().unwrap_or_else(|e| e.into_inner())
}

/// Whether something listens at the viewer URL's host and port (within two seconds).
pub fn reachable(url: &str) -> Result<(), String> {
    let address = crm_api::record::viewer_address(url)?;
    let addrs: Vec<_> = address
        .to_socket_addrs()
        .map_err(|e| format!("{address}: {e}"))?
        .collect();
    for addr in &addrs {
        if TcpStream::connect_timeout(addr, Duration::from_secs(2)).is_ok() {
            return Ok(());
        }
    }
    Err(format!("no viewer answers at {address}"))
}

impl Recorder {
    /// A recorder for `spec`; a live viewer that does not answer turns it off with a warning
    /// (the job goes on without streaming).
    pub fn new(spec: &RecordSpec, label: impl Into<String>) -> Self {
        let label = label.into();
        let target = match &spec.connect {
            None => Target::Memory,
            Some(url) => match reachable(url) {
                Ok(()) => Target::Live(url.clone()),
                Err(why) => {
                    tracing::warn!(%label, %why, "viewer unreachable: recording off, the job goes on");
                    Target::Off
                }
            },
        };
        Self {
            target,
            every: spec.every,
            max_episodes: spec.max_episodes,
            label,
            seen: 0,
            recorded: 0,
            training: None,
            pending: Vec::new(),
            pending_episodes: 0,
            summaries: None,
        }
    }

    /// Keeps a summary of each recorded episode that ends, for [`Recorder::take_summaries`].
    pub fn keeping_summaries(mut self) -> Self {
        self.summaries = Some(Vec::new());
        self
    }

    pub fn shared(self) -> SharedRecorder {
        Arc::new(Mutex::new(self))
    }

    pub fn target(&self) -> &Target {
        &self.target
    }

    /// A new recording (a fresh random id, so a job resumed elsewhere never merges two
    /// episodes) named `name`.
    fn open(&self, name: String) -> anyhow::Result<EpisodeStream> {
        let builder = RecordingStreamBuilder::new(APP_ID).recording_name(name);
        Ok(match &self.target {
            Target::Live(url) => EpisodeStream {
                rec: builder
                    .connect_grpc_opts(url.clone())
                    .with_context(|| format!("connecting to the viewer at {url}"))?,
                storage: None,
            },
            _ => {
                let (rec, storage) = builder.memory().context("a rerun memory sink")?;
                EpisodeStream {
                    rec,
                    storage: Some(storage),
                }
            }
        })
    }

    /// Counts `n` episodes as begun, recording those due, without recording them: an
    /// evaluation going on from another worker's progress (that worker recorded them).
    pub fn skip_episodes(&mut self, n: u64) {
        for _ in 0..n {
            self.seen += 1;
            let due = self.every > 0 && (self.seen - 1).is_multiple_of(self.every);
            if self.target != Target::Off && due && self.recorded < self.max_episodes {
                self.recorded += 1;
            }
        }
    }

    /// Counts an episode starting; returns a stream when this one is to be recorded.
    pub fn begin_episode(&mut self, what: &str) -> Option<EpisodeStream> {
        self.seen += 1;
        let due = self.every > 0 && (self.seen - 1).is_multiple_of(self.every);
        if self.target == Target::Off || !due || self.recorded >= self.max_episodes {
            return None;
        }
        let name = format!("{} · episode {} · {what}", self.label, self.seen);
        match self.open(name) {
            Ok(stream) => {
                self.recorded += 1;
                Some(stream)
            }
            Err(err) => {
                tracing::warn!(err = %format!("{err:#}"), "recording off");
                self.target = Target::Off;
                None
            }
        }
    }

    /// Finishes a recorded episode: its bytes join the pending ones, or it is flushed to the
    /// viewer. `summary` is the episode's, when it ended (not cut short by a reset).
    pub fn end_episode(&mut self, stream: EpisodeStream, summary: Option<EpisodeRecord>) {
        match self.drain(&stream) {
            Ok(_) => self.pending_episodes += 1,
            Err(err) => tracing::warn!(err = %format!("{err:#}"), "an episode's recording is lost"),
        }
        if let (Some(summaries), Some(summary)) = (&mut self.summaries, summary) {
            summaries.push(summary);
        }
    }

    /// The summaries of the recorded episodes that ended since the last call.
    pub fn take_summaries(&mut self) -> Vec<EpisodeRecord> {
        self.summaries
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    fn drain(&mut self, stream: &EpisodeStream) -> anyhow::Result<usize> {
        match &stream.storage {
            Some(storage) => {
                let bytes = storage.drain_as_bytes().context("encoding the recording")?;
                self.pending.extend_from_slice(&bytes);
                Ok(bytes.len())
            }
            None => {
                stream
                    .rec
                    .flush_with_timeout(Duration::from_secs(2))
                    .map_err(|e| anyhow::anyhow!("flushing to the viewer: {e}"))?;
                Ok(0)
            }
        }
    }

    /// Logs one training iteration's series (timeline `iteration`) into the job's training
    /// recording.
    pub fn log_iteration(&mut self, it: &Iteration) {
        if self.target == Target::Off || self.every == 0 {
            return;
        }
        if self.training.is_none() {
            let name = format!("{} · training", self.label);
            self.training = self.open(name).ok();
        }
        let Some(stream) = self.training.take() else {
            return;
        };
        if let Err(err) = scene::log_iteration(&stream.rec, it) {
            tracing::warn!(%err, "logging a training iteration");
        }
        if let Err(err) = self.drain(&stream) {
            tracing::warn!(err = %format!("{err:#}"), "a training iteration's recording is lost");
        }
        self.training = Some(stream);
    }

    /// The bytes (whole `.rrd` streams) and episode count recorded since the last call.
    pub fn take_pending(&mut self) -> Option<(Vec<u8>, u32)> {
        if self.pending.is_empty() {
            return None;
        }
        let episodes = std::mem::take(&mut self.pending_episodes);
        Some((std::mem::take(&mut self.pending), episodes))
    }
}

impl crm_run::record::Recorder for Recorder {
    fn begin_episode(&mut self, what: &str) -> Option<Box<dyn EpisodeLog>> {
        Recorder::begin_episode(self, what).map(|stream| Box::new(stream) as Box<dyn EpisodeLog>)
    }

    fn end_episode(&mut self, log: Box<dyn EpisodeLog>, summary: Option<EpisodeRecord>) {
        match (log as Box<dyn Any>).downcast::<EpisodeStream>() {
            Ok(stream) => Recorder::end_episode(self, *stream, summary),
            Err(_) => tracing::warn!("an episode log this recorder did not open"),
        }
    }

    fn log_iteration(&mut self, iteration: &Iteration) {
        Recorder::log_iteration(self, iteration);
    }
}

impl EpisodeLog for EpisodeStream {
    fn start(&mut self, env: &grasp_sim::GraspEnv, stage: &str, stage_id: crm::StageId) {
        let rec = &self.rec;
        rec.set_time_sequence("step", 0);
        let parts = env.parts();
        let logged = scene::log_shapes(rec, &parts)
            .and_then(|()| scene::log_poses(rec, &parts))
            .and_then(|()| scene::log_contacts(rec, &[], env.grasp_location().map(Into::into)))
            .and_then(|()| scene::log_stage(rec, stage, stage_id, true));
        if let Err(err) = logged {
            tracing::warn!(%err, "recording an episode's start");
        }
    }

    fn step(&mut self, step: i64, env: &grasp_sim::GraspEnv, moved: Option<Move<'_>>) {
        let rec = &self.rec;
        rec.set_time_sequence("step", step);
        let parts = env.parts();
        let mut logged = scene::log_poses(rec, &parts).and_then(|()| {
            scene::log_contacts(
                rec,
                &env.contacts_view(),
                env.grasp_location().map(Into::into),
            )
        });
        if let Some(moved) = moved {
            logged = logged
                .and_then(|()| scene::log_rewards(rec, moved.intra_reward, moved.transition_reward))
                .and_then(|()| {
                    scene::log_stage(rec, moved.to, moved.to_id, moved.to != moved.from)
                });
            if let Some(event) = moved.event {
                logged = logged.and_then(|()| {
                    scene::log_transition(rec, moved.from, moved.to, event, moved.transition_reward)
                });
            }
        }
        if let Err(err) = logged {
            tracing::warn!(%err, "recording a step");
        }
    }

    fn end(&mut self, stage: &str, steps: i64, truncated: bool) {
        if let Err(err) = scene::log_end(&self.rec, stage, steps, truncated) {
            tracing::warn!(%err, "recording an episode's end");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_nth_episode_up_to_the_cap() {
        let spec = RecordSpec {
            every: 3,
            max_episodes: 2,
            connect: None,
        };
        let mut recorder = Recorder::new(&spec, "job 1");
        let picked: Vec<bool> = (0..10)
            .map(|_| match recorder.begin_episode("t") {
                Some(stream) => {
                    recorder.end_episode(stream, None);
                    true
                }
                None => false,
            })
            .collect();
        // Episodes 1 and 4; 7 would be the third, over the cap.
        assert_eq!(
            picked,
            [
                true, false, false, true, false, false, false, false, false, false
            ]
        );
        let (bytes, episodes) = recorder.take_pending().expect("bytes");
        assert_eq!(episodes, 2);
        assert!(bytes.starts_with(b"RRF"), "an rrd stream");
        assert!(recorder.take_pending().is_none());
    }

    #[test]
    fn a_training_recorder_keeps_the_summaries_of_ended_episodes() {
        let spec = RecordSpec {
            every: 1,
            max_episodes: 3,
            connect: None,
        };
        let summary = |task: &str| EpisodeRecord {
            task: task.into(),
            success: true,
            outcome: "success".into(),
            sim_seconds: 5.2,
            length: 12,
            total_return: 3.5,
            transitions: vec![(4, "approach".into(), "grasp".into(), "arrive".into(), 50.0)],
        };
        let mut training = Recorder::new(&spec, "job 3").keeping_summaries();
        let mut evaluation = Recorder::new(&spec, "job 4");
        for recorder in [&mut training, &mut evaluation] {
            let stream = recorder.begin_episode("t").expect("recorded");
            recorder.end_episode(stream, Some(summary("a")));
            // Cut short by a reset: no summary.
            let stream = recorder.begin_episode("t").expect("recorded");
            recorder.end_episode(stream, None);
        }
        let kept = training.take_summaries();
        assert_eq!(kept.len(), 1);
        assert_eq!((kept[0].task.as_str(), kept[0].transitions.len()), ("a", 1));
        assert!(training.take_summaries().is_empty(), "taken once");
        assert!(evaluation.take_summaries().is_empty());
        assert_eq!(training.take_pending().expect("bytes").1, 2);
    }

    #[test]
    fn an_unreachable_viewer_turns_recording_off() {
        // A port nothing listens on: bind one, then free it.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("port")
            .port();
        let spec = RecordSpec {
            connect: Some(format!("rerun+http://127.0.0.1:{port}/proxy")),
            ..RecordSpec::default()
        };
        let mut recorder = Recorder::new(&spec, "job 2");
        assert_eq!(recorder.target(), &Target::Off);
        assert!(recorder.begin_episode("t").is_none());
        assert!(recorder.take_pending().is_none());
    }
}
