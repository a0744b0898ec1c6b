//! The small environment trait where an environment (`grasp-sim`) and a learner meet, and
//! [`CrmEnv`], which runs an environment inside a machine.

use crate::episode::Episode;
use crate::error::{Error, Result};
use crate::machine::{Machine, StageId};
use crate::reward::RewardMode;

/// What an environment returns for one control step.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvStep {
    /// The global observation `u_{t+1}`, laid out as the spec's `features`.
    pub observation: Vec<f32>,
    /// Names of the events that hold in `u_{t+1}` (the machine picks the edge; events it does
    /// not declare are ignored).
    pub events: Vec<&'static str>,
    /// The episode hit its time limit without reaching a terminal stage.
    pub truncated: bool,
}

/// A seeded, synchronous environment driven through the union action space of a spec.
pub trait Environment {
    /// Starts a new episode from `seed` and returns the first global observation.
    fn reset(&mut self, seed: u64) -> std::result::Result<Vec<f32>, String>;
    /// Tells the environment which stage the machine is in (events such as a grasp time-out
    /// depend on it).
    fn set_stage(&mut self, stage: &str);
    /// Applies one union-space action (already scaled and masked) for one control step.
    fn step(&mut self, action: &[f32]) -> std::result::Result<EnvStep, String>;
    /// A label for the current episode that learners may count outcomes by (the grasping
    /// environment's task index); `None` by default.
    fn episode_tag(&self) -> Option<usize> {
        None
    }
}

/// One step of an environment inside a machine, as a learner sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct CrmStep {
    /// The stage after the step.
    pub stage: StageId,
    /// `phi_j(u_{t+1})`.
    pub abstract_state: Vec<f32>,
    /// Intra-stage reward after the reward mode.
    pub intra_reward: f32,
    /// Transition reward after the reward mode.
    pub transition_reward: f32,
    /// The event that moved the machine, by name.
    pub event: Option<String>,
    /// A terminal stage was reached.
    pub done: bool,
    /// The time limit ended the episode first.
    pub truncated: bool,
    /// How many action values were outside `[-1, 1]` and clipped.
    pub clipped: usize,
}

/// An environment run through a machine with a reward mode.
pub struct CrmEnv<E> {
    machine: Machine,
    env: E,
    mode: RewardMode,
    episode: Episode,
}

impl<E: Environment> CrmEnv<E> {
    pub fn new(machine: Machine, env: E, mode: RewardMode) -> Self {
        let episode = Episode::new(&machine);
        Self {
            machine,
            env,
            mode,
            episode,
        }
    }

    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    pub fn env(&self) -> &E {
        &self.env
    }

    pub fn env_mut(&mut self) -> &mut E {
        &mut self.env
    }

    /// Gives the machine and the environment back.
    pub fn into_parts(self) -> (Machine, E) {
        (self.machine, self.env)
    }

    pub fn episode(&self) -> &Episode {
        &self.episode
    }

    /// Resets the environment and the machine; returns the initial stage and abstract state.
    pub fn reset(&mut self, seed: u64) -> Result<(StageId, Vec<f32>)> {
        self.episode = Episode::new(&self.machine);
        let stage = self.episode.stage();
        self.env.set_stage(self.machine.stage_name(stage));
        let observation = self.env.reset(seed).map_err(Error::Env)?;
        Ok((stage, self.machine.abstract_state(stage, &observation)?))
    }

    /// Applies a stage action (length `|A_i|`, or the full union space with masked
    /// dimensions ignored) and steps the machine.
    pub fn step(&mut self, action: &[f32]) -> Result<CrmStep> {
        let stage = self.episode.stage();
        if self.machine.is_terminal(stage) {
            return Err(Error::EpisodeOver(
                self.machine.stage_name(stage).to_string(),
            ));
        }
        let (union_action, clipped) = self.machine.expand_action(stage, action)?;
        let env_step = self.env.step(&union_action).map_err(Error::Env)?;
        // A machine may use a subset of the environment's events (a flat machine has no
        // `arrive`); the others are ignored.
        let fired: Vec<usize> = env_step
            .events
            .iter()
            .filter_map(|name| self.machine.event_id(name))
            .collect();
        let outcome = self
            .episode
            .advance(&self.machine, &env_step.observation, &fired)?;
        if outcome.next != stage {
            self.env.set_stage(self.machine.stage_name(outcome.next));
        }
        let (intra_reward, transition_reward) = self
            .mode
            .apply(outcome.intra_reward, outcome.transition_reward);
        Ok(CrmStep {
            stage: outcome.next,
            abstract_state: outcome.abstract_state,
            intra_reward,
            transition_reward,
            event: outcome
                .event
                .map(|e| self.machine.event_name(e).to_string()),
            done: outcome.done,
            truncated: env_step.truncated && !outcome.done,
            clipped,
        })
    }
}
