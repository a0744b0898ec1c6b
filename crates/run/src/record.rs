//! Recording a job's episodes behind two traits, so that the runtime knows no viewer: a
//! [`Recorder`] decides which episodes are followed and takes the training series; an
//! [`EpisodeLog`] follows one episode step by step (the `crm` binary's rerun recorder
//! implements both). [`Recorded`] is the grasping environment with an optional recorder.
//! Without one (every environment but the first in training, and every job that does not
//! record) a step costs one `Option` check more than `GraspEnv`'s. With one, each episode the
//! recorder picks is logged step by step: the scene, contacts, the CRM stage and every
//! transition with its event and transition reward, which this wrapper derives with the same
//! pure `Machine::step` the `CrmEnv` around it takes.

use std::sync::{Arc, Mutex, MutexGuard};

use crm::{EnvStep, Environment, Machine, StageId};
use crm_api::Iteration;
use grasp_sim::GraspEnv;

/// One finished episode, with the machine's transition history: what an evaluation reports
/// of each episode and a training job of each recorded one.
#[derive(Clone, Debug)]
pub struct EpisodeRecord {
    pub task: String,
    pub success: bool,
    /// How it ended (`success`, `failure (dropped)`, ...: [`grasp_sim::events::outcome_label`]).
    pub outcome: String,
    /// Simulated seconds, the arm's execution included.
    pub sim_seconds: f64,
    pub length: usize,
    pub total_return: f64,
    /// (step, from stage, to stage, event, transition reward).
    pub transitions: Vec<(usize, String, String, String, f32)>,
}

/// Watches a job's episodes and its training series.
pub trait Recorder: Send {
    /// Counts an episode starting (`what`: its task and seed); a log when this one is to be
    /// followed.
    fn begin_episode(&mut self, what: &str) -> Option<Box<dyn EpisodeLog>>;
    /// Ends a followed episode; `summary` when it ended (not cut short by a reset).
    fn end_episode(&mut self, log: Box<dyn EpisodeLog>, summary: Option<EpisodeRecord>);
    /// One training iteration's series.
    fn log_iteration(&mut self, iteration: &Iteration);
}

/// The machine's move in one control step, as a log shows it.
#[derive(Clone, Copy, Debug)]
pub struct Move<'a> {
    pub from: &'a str,
    pub to: &'a str,
    pub to_id: StageId,
    pub intra_reward: f32,
    pub transition_reward: f32,
    /// The event that moved the machine, if one did.
    pub event: Option<&'a str>,
}

/// One followed episode (`Any`, so its recorder can take back the log it opened).
pub trait EpisodeLog: Send + std::any::Any {
    /// The episode's first state, in `stage`.
    fn start(&mut self, env: &GraspEnv, stage: &str, stage_id: StageId);
    /// Control step `step`: the world after it and the machine's move (none when the
    /// machine refused the step).
    fn step(&mut self, step: i64, env: &GraspEnv, moved: Option<Move<'_>>);
    /// The end: the stage reached after `steps` steps, or cut short (`truncated`).
    fn end(&mut self, stage: &str, steps: i64, truncated: bool);
}

/// A recorder shared between an environment and its job.
pub type SharedRecorder = Arc<Mutex<dyn Recorder>>;

/// Locks a shared recorder; a poisoned lock still holds usable counters.
pub fn lock(recorder: &SharedRecorder) -> MutexGuard<'_, dyn Recorder + 'static> {
    recorder.lock().unwrap_or_else(|e| e.into_inner())
}

struct Episode {
    log: Box<dyn EpisodeLog>,
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
            lock(recorder).end_episode(episode.log, ended.then_some(episode.summary));
        }
    }

    fn begin(&mut self, seed: u64) {
        let Some(recorder) = &self.recorder else {
            return;
        };
        let what = format!("{} seed {seed}", self.inner.task().id);
        let Some(mut log) = lock(recorder).begin_episode(&what) else {
            return;
        };
        let stage = self.machine.initial();
        log.start(&self.inner, self.machine.stage_name(stage), stage);
        self.episode = Some(Episode {
            log,
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
        let fired: Vec<usize> = step
            .events
            .iter()
            .filter_map(|name| self.machine.event_id(name))
            .collect();
        let outcome = self.machine.step(episode.stage, &step.observation, &fired);
        let mut ended = step.truncated;
        let moved = outcome.as_ref().ok().map(|outcome| Move {
            from: self.machine.stage_name(outcome.from),
            to: self.machine.stage_name(outcome.next),
            to_id: outcome.next,
            intra_reward: outcome.intra_reward,
            transition_reward: outcome.transition_reward,
            event: outcome.event.map(|event| self.machine.event_name(event)),
        });
        episode.log.step(episode.step, &self.inner, moved);
        if let (Ok(outcome), Some(moved)) = (&outcome, moved) {
            let summary = &mut episode.summary;
            summary.length = episode.step as usize;
            summary.total_return +=
                f64::from(outcome.intra_reward) + f64::from(outcome.transition_reward);
            if let Some(event) = moved.event {
                summary.transitions.push((
                    // 0-based, as the machine's history counts.
                    summary.length - 1,
                    moved.from.to_string(),
                    moved.to.to_string(),
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
            episode.log.end(stage, episode.step, !done);
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

/// Several recorders watching the same episodes (a rerun recording and a video of one
/// evaluation): each decides on its own which episodes it follows.
pub struct Tee(pub Vec<SharedRecorder>);

/// One episode's logs, one a recorder of the [`Tee`] (none where it does not follow it).
struct TeeLog(Vec<Option<Box<dyn EpisodeLog>>>);

impl Recorder for Tee {
    fn begin_episode(&mut self, what: &str) -> Option<Box<dyn EpisodeLog>> {
        let logs: Vec<_> = self.0.iter().map(|r| lock(r).begin_episode(what)).collect();
        logs.iter()
            .any(Option::is_some)
            .then(|| Box::new(TeeLog(logs)) as Box<dyn EpisodeLog>)
    }

    fn end_episode(&mut self, log: Box<dyn EpisodeLog>, summary: Option<EpisodeRecord>) {
        if let Ok(tee) = (log as Box<dyn std::any::Any>).downcast::<TeeLog>() {
            for (recorder, log) in self.0.iter().zip(tee.0) {
                if let Some(log) = log {
                    lock(recorder).end_episode(log, summary.clone());
                }
            }
        }
    }

    fn log_iteration(&mut self, iteration: &Iteration) {
        for recorder in &self.0 {
            lock(recorder).log_iteration(iteration);
        }
    }
}

impl EpisodeLog for TeeLog {
    fn start(&mut self, env: &GraspEnv, stage: &str, stage_id: StageId) {
        for log in self.0.iter_mut().flatten() {
            log.start(env, stage, stage_id);
        }
    }

    fn step(&mut self, step: i64, env: &GraspEnv, moved: Option<Move<'_>>) {
        for log in self.0.iter_mut().flatten() {
            log.step(step, env, moved);
        }
    }

    fn end(&mut self, stage: &str, steps: i64, truncated: bool) {
        for log in self.0.iter_mut().flatten() {
            log.end(stage, steps, truncated);
        }
    }
}
