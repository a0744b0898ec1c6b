//! `Recorded`: the grasping environment with an optional recorder. Without one (every
//! environment but the first in training, and every job that does not record) a step costs
//! one `Option` check more than `GraspEnv`'s. With one, each episode the recorder picks is
//! logged step by step: the scene, contacts, the CRM stage and every transition with its
//! event and transition reward, which this wrapper derives with the same pure
//! `Machine::step` the `CrmEnv` around it takes.

use crm::{EnvStep, Environment, Machine};
use grasp_sim::GraspEnv;

use super::{EpisodeStream, SharedRecorder, lock, scene};
use crate::jobs::eval::EpisodeRecord;

struct Episode {
    stream: EpisodeStream,
    step: i64,
    stage: crm::StageId,
    /// What the job reports of the episode when it ends (its transitions, its return).
    summary: EpisodeRecord,
}

/// A `GraspEnv` that records the episodes its recorder asks for.
pub struct Recorded {
    inner: GraspEnv,
    machine: Machine,
    recorder: Option<SharedRecorder>,
    episode: Option<Episode>,
}

impl Recorded {
    pub fn new(inner: GraspEnv, machine: Machine, recorder: Option<SharedRecorder>) -> Self {
        Self {
            inner,
            machine,
            recorder,
            episode: None,
        }
    }

    pub fn inner(&self) -> &GraspEnv {
        &self.inner
    }

    /// The environment, for settings that apply from its next reset (task weights).
    pub fn inner_mut(&mut self) -> &mut GraspEnv {
        &mut self.inner
    }

    /// Ends the recorded episode; `ended` when it ended (not cut short by a reset), so its
    /// summary is kept.
    fn finish(&mut self, ended: bool) {
        if let (Some(episode), Some(recorder)) = (self.episode.take(), &self.recorder) {
            lock(recorder).end_episode(episode.stream, ended.then_some(episode.summary));
        }
    }

    fn begin(&mut self, seed: u64) {
        let Some(recorder) = &self.recorder else {
            return;
        };
        let what = format!("{} seed {seed}", self.inner.task().id);
        let Some(stream) = lock(recorder).begin_episode(&what) else {
            return;
        };
        let stage = self.machine.initial();
        let rec = &stream.rec;
        rec.set_time_sequence("step", 0);
        let parts = self.inner.parts();
        let logged = scene::log_shapes(rec, &parts)
            .and_then(|()| scene::log_poses(rec, &parts))
            .and_then(|()| {
                scene::log_contacts(rec, &[], self.inner.grasp_location().map(Into::into))
            })
            .and_then(|()| scene::log_stage(rec, self.machine.stage_name(stage), stage, true));
        if let Err(err) = logged {
            tracing::warn!(%err, "recording an episode's start");
        }
        self.episode = Some(Episode {
            stream,
            step: 0,
            stage,
            summary: EpisodeRecord {
                task: self.inner.task().id.clone(),
                success: false,
                outcome: String::new(),
                sim_seconds: 0.0,
                length: 0,
                total_return: 0.0,
                transitions: Vec::new(),
            },
        });
    }

    fn log_step(&mut self, step: &EnvStep) {
        let Some(episode) = &mut self.episode else {
            return;
        };
        episode.step += 1;
        let rec = &episode.stream.rec;
        rec.set_time_sequence("step", episode.step);
        let fired: Vec<usize> = step
            .events
            .iter()
            .filter_map(|name| self.machine.event_id(name))
            .collect();
        let outcome = self.machine.step(episode.stage, &step.observation, &fired);
        let parts = self.inner.parts();
        let mut logged = scene::log_poses(rec, &parts).and_then(|()| {
            scene::log_contacts(
                rec,
                &self.inner.contacts_view(),
                self.inner.grasp_location().map(Into::into),
            )
        });
        let mut ended = step.truncated;
        if let Ok(outcome) = &outcome {
            let from = self.machine.stage_name(outcome.from);
            let to = self.machine.stage_name(outcome.next);
            logged = logged
                .and_then(|()| {
                    scene::log_rewards(rec, outcome.intra_reward, outcome.transition_reward)
                })
                .and_then(|()| {
                    scene::log_stage(rec, to, outcome.next, outcome.next != outcome.from)
                });
            let summary = &mut episode.summary;
            summary.length = episode.step as usize;
            summary.total_return +=
                f64::from(outcome.intra_reward) + f64::from(outcome.transition_reward);
            if let Some(event) = outcome.event {
                let event = self.machine.event_name(event);
                logged = logged.and_then(|()| {
                    scene::log_transition(rec, from, to, event, outcome.transition_reward)
                });
                summary.transitions.push((
                    // 0-based, as the machine's history counts.
                    summary.length - 1,
                    from.to_string(),
                    to.to_string(),
                    event.to_string(),
                    outcome.transition_reward,
                ));
            }
            episode.stage = outcome.next;
            ended |= outcome.done;
        }
        if ended {
            let stage = self.machine.stage_name(episode.stage);
            let done = !step.truncated || outcome.as_ref().is_ok_and(|o| o.done);
            episode.summary.success = done && stage == "success";
            episode.summary.outcome =
                self.inner
                    .outcome_label(if done { stage } else { "truncated" });
            episode.summary.sim_seconds = f64::from(self.inner.sim_seconds());
            logged = logged.and_then(|()| scene::log_end(rec, stage, episode.step, !done));
        }
        if let Err(err) = logged {
            tracing::warn!(%err, "recording a step");
        }
        if ended {
            self.finish(true);
        }
    }
}

impl Environment for Recorded {
    fn reset(&mut self, seed: u64) -> Result<Vec<f32>, String> {
        // An episode cut short (a reset before its end) is kept as it is, without a summary.
        self.finish(false);
        let observation = self.inner.reset(seed)?;
        self.begin(seed);
        Ok(observation)
    }

    fn set_stage(&mut self, stage: &str) {
        self.inner.set_stage(stage);
    }

    fn step(&mut self, action: &[f32]) -> Result<EnvStep, String> {
        let step = self.inner.step(action)?;
        if self.episode.is_some() {
            self.log_step(&step);
        }
        Ok(step)
    }

    fn episode_tag(&self) -> Option<usize> {
        self.inner.episode_tag()
    }
}
