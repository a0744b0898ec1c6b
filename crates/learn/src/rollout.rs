//! Vectorized rollouts: several `crm::CrmEnv`s stepped in parallel, either each on its own
//! (learners that act one environment at a time: no barrier between steps) or in lock-step
//! with the policy evaluated on all of them in one batch. Deterministic per seed whatever the
//! thread count: each environment's episode seeds depend only on the base seed, its index and
//! its episode count, and the policy's noise comes from the environment's own generator (or,
//! in lock-step, is drawn in environment order on the calling thread).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::noise::Noise;

/// Collected experience: each environment's steps contiguous, environments in order.
#[derive(Clone, Debug, Default)]
pub struct Rollout {
    pub states: Vec<Vec<f32>>,
    pub stages: Vec<usize>,
    pub next_states: Vec<Vec<f32>>,
    pub next_stages: Vec<usize>,
    /// Sampled union-space actions (before the environment clips them).
    pub actions: Vec<Vec<f32>>,
    pub masks: Vec<Vec<f32>>,
    pub log_probs: Vec<f32>,
    pub intra: Vec<f32>,
    pub transition: Vec<f32>,
    pub terminal: Vec<bool>,
    /// The trajectory ends after this step (episode end, or the rollout's cut).
    pub last: Vec<bool>,
    /// The episode ended with this step (terminal stage or time limit; not the cut).
    pub ended: Vec<bool>,
    /// The environment (index) each step came from.
    pub env: Vec<usize>,
    /// Episodes that ended in this rollout.
    pub episodes: Vec<Episode>,
}

/// An episode that ended in a rollout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Episode {
    pub success: bool,
    /// Control steps.
    pub length: usize,
    /// Intra-stage plus transition rewards, unscaled.
    pub total_return: f32,
    /// The intra-stage and the transition part of `total_return`, unscaled.
    pub intra_return: f32,
    pub transition_return: f32,
    /// The environment's label for the episode ([`crm::Environment::episode_tag`]: the
    /// grasping environment's task index).
    pub tag: Option<usize>,
}

impl Rollout {
    pub fn len(&self) -> usize {
        self.states.len()
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    fn append(&mut self, mut other: Rollout) {
        if let Some(last) = other.last.last_mut() {
            // The rollout's cut is a trajectory end too: bootstrap from the value there.
            *last = true;
        }
        self.states.append(&mut other.states);
        self.stages.append(&mut other.stages);
        self.next_states.append(&mut other.next_states);
        self.next_stages.append(&mut other.next_stages);
        self.actions.append(&mut other.actions);
        self.masks.append(&mut other.masks);
        self.log_probs.append(&mut other.log_probs);
        self.intra.append(&mut other.intra);
        self.transition.append(&mut other.transition);
        self.terminal.append(&mut other.terminal);
        self.last.append(&mut other.last);
        self.ended.append(&mut other.ended);
        self.env.append(&mut other.env);
        self.episodes.append(&mut other.episodes);
    }
}

struct Slot<E> {
    env: crm::CrmEnv<E>,
    stage: crm::StageId,
    state: Vec<f32>,
    episode: u64,
    /// The running episode's intra-stage and transition returns.
    episode_intra: f32,
    episode_transition: f32,
    episode_length: usize,
    buffer: Rollout,
    /// This environment's policy noise, for learners that act one environment at a time.
    noise: Noise,
    /// The running episode's actions: replayed from its seed, they put the environment back
    /// where it is ([`VecEnv::restore`]).
    actions: Vec<Vec<f32>>,
}

/// Where one environment stands in its stream, as a checkpoint keeps it: its episode count
/// (its next reset's seed), its noise generator and the running episode's actions.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvState {
    pub episode: u64,
    pub noise: u64,
    pub actions: Vec<Vec<f32>>,
}

impl<E: crm::Environment> Slot<E> {
    /// Steps the environment with `action`, records the step, and starts the next episode
    /// (seeded by the base seed, the environment's index `k` and its episode count) when
    /// this one ends.
    fn advance(
        &mut self,
        k: usize,
        base_seed: u64,
        action: Vec<f32>,
        log_prob: f32,
        mask: Vec<f32>,
    ) -> Result<()> {
        let step = self.env.step(&action).map_err(env_error)?;
        self.actions.push(action.clone());
        self.episode_intra += step.intra_reward;
        self.episode_transition += step.transition_reward;
        self.episode_length += 1;
        let last = step.done || step.truncated;
        let b = &mut self.buffer;
        b.states.push(std::mem::take(&mut self.state));
        b.stages.push(self.stage);
        b.next_states.push(step.abstract_state.clone());
        b.next_stages.push(step.stage);
        b.actions.push(action);
        b.masks.push(mask);
        b.log_probs.push(log_prob);
        b.intra.push(step.intra_reward);
        b.transition.push(step.transition_reward);
        b.terminal.push(step.done);
        b.last.push(last);
        b.ended.push(last);
        b.env.push(k);
        if last {
            let success = step.done && self.env.machine().stage_name(step.stage) == "success";
            b.episodes.push(Episode {
                success,
                length: self.episode_length,
                total_return: self.episode_intra + self.episode_transition,
                intra_return: self.episode_intra,
                transition_return: self.episode_transition,
                tag: self.env.env().episode_tag(),
            });
            self.episode += 1;
            self.episode_intra = 0.0;
            self.episode_transition = 0.0;
            self.episode_length = 0;
            self.actions.clear();
            let seed = episode_seed(base_seed, k, self.episode);
            (self.stage, self.state) = self.env.reset(seed).map_err(env_error)?;
        } else {
            (self.stage, self.state) = (step.stage, step.abstract_state);
        }
        Ok(())
    }

    /// Puts the environment back at `state`: its episode's reset, then its actions again
    /// (the environment is deterministic per seed, so it arrives where it was, the machine's
    /// stage and history included), with the episode's returns summed as they were.
    fn replay(&mut self, k: usize, base_seed: u64, state: &EnvState) -> Result<()> {
        self.episode = state.episode;
        self.noise = Noise::new(state.noise);
        (self.stage, self.state) = self
            .env
            .reset(episode_seed(base_seed, k, self.episode))
            .map_err(env_error)?;
        (
            self.episode_intra,
            self.episode_transition,
            self.episode_length,
        ) = (0.0, 0.0, 0);
        self.actions.clear();
        for (n, action) in state.actions.iter().enumerate() {
            let step = self.env.step(action).map_err(env_error)?;
            if step.done || step.truncated {
                return Err(Error::Env(format!(
                    "environment {k}'s episode ended after {} of the {} steps it replays: the \
                     checkpoint was made by another build or on another CPU type",
                    n + 1,
                    state.actions.len()
                )));
            }
            self.episode_intra += step.intra_reward;
            self.episode_transition += step.transition_reward;
            self.episode_length += 1;
            self.actions.push(action.clone());
            (self.stage, self.state) = (step.stage, step.abstract_state);
        }
        Ok(())
    }
}

/// A policy the rollouts can ask for actions (PPO's and SAC's).
pub trait Actor {
    /// Whether [`Actor::act_one`] is implemented: the rollout then steps each environment
    /// on its own, without a barrier between steps.
    fn acts_alone(&self) -> bool {
        false
    }

    /// The action and its log-probability for one environment's abstract state, with that
    /// environment's `noise` (callable from several threads at once).
    fn act_one(
        &self,
        _state: &[f32],
        _stage: usize,
        _mask: &[f32],
        _noise: &mut Noise,
    ) -> Result<(Vec<f32>, f32)> {
        Err(Error::Env("this learner acts in batches only".into()))
    }

    /// Union-space actions (and their log-probabilities, where the learner needs them) for a
    /// batch of abstract states; noise drawn row by row in order.
    fn act_batch(
        &mut self,
        states: &[Vec<f32>],
        stages: &[usize],
        masks: &[Vec<f32>],
        deterministic: bool,
    ) -> Result<(Vec<Vec<f32>>, Vec<f32>)>;
}

/// Environments stepped together.
pub struct VecEnv<E> {
    slots: Vec<Slot<E>>,
    base_seed: u64,
}

fn episode_seed(base: u64, env: usize, episode: u64) -> u64 {
    base.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add((env as u64) << 40)
        .wrapping_add(episode)
}

fn env_error(err: crm::Error) -> Error {
    Error::Env(err.to_string())
}

impl<E: crm::Environment + Send> VecEnv<E> {
    /// Takes the environments and resets each with its first episode seed.
    pub fn new(envs: Vec<crm::CrmEnv<E>>, base_seed: u64) -> Result<Self> {
        if envs.is_empty() {
            return Err(Error::Length {
                what: "environments",
                expected: 1,
                got: 0,
            });
        }
        let slots = envs
            .into_iter()
            .enumerate()
            .map(|(k, mut env)| {
                let (stage, state) = env
                    .reset(episode_seed(base_seed, k, 0))
                    .map_err(env_error)?;
                Ok(Slot {
                    env,
                    stage,
                    state,
                    episode: 0,
                    episode_intra: 0.0,
                    episode_transition: 0.0,
                    episode_length: 0,
                    buffer: Rollout::default(),
                    noise: Noise::new(episode_seed(base_seed, k, u64::MAX)),
                    actions: Vec::new(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { slots, base_seed })
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The environments, in order (to change settings that apply from their next reset).
    pub fn envs_mut(&mut self) -> impl Iterator<Item = &mut crm::CrmEnv<E>> {
        self.slots.iter_mut().map(|s| &mut s.env)
    }

    /// The environments, in order.
    pub fn envs(&self) -> impl Iterator<Item = &crm::CrmEnv<E>> {
        self.slots.iter().map(|s| &s.env)
    }

    /// Where each environment stands (between collections: nothing is buffered then).
    pub fn states(&self) -> Vec<EnvState> {
        self.slots
            .iter()
            .map(|s| EnvState {
                episode: s.episode,
                noise: s.noise.state(),
                actions: s.actions.clone(),
            })
            .collect()
    }

    /// Puts every environment back where [`Self::states`] found it (one state per
    /// environment), replaying the running episodes in parallel.
    pub fn restore(&mut self, states: &[EnvState]) -> Result<()> {
        if states.len() != self.slots.len() {
            return Err(Error::Length {
                what: "environment states",
                expected: self.slots.len(),
                got: states.len(),
            });
        }
        let base_seed = self.base_seed;
        self.slots
            .par_iter_mut()
            .zip(states.par_iter())
            .enumerate()
            .try_for_each(|(k, (slot, state))| slot.replay(k, base_seed, state))
    }

    /// Steps every environment `steps_per_env` times with the policy of `actor`.
    ///
    /// A learner that can act for one environment at a time ([`Actor::act_one`]) is run
    /// without a barrier between steps: each environment takes its steps on its own (the
    /// pool steals whole environments), with its own noise generator, so an environment whose
    /// step runs the arm's scripted execution (hundreds of physics steps) does not hold the
    /// others up. Others are stepped in lock-step batches.
    pub fn collect<A: Actor + Sync>(
        &mut self,
        actor: &mut A,
        steps_per_env: usize,
    ) -> Result<Rollout> {
        let base_seed = self.base_seed;
        if actor.acts_alone() {
            let actor: &A = actor;
            self.slots
                .par_iter_mut()
                .enumerate()
                .try_for_each(|(k, slot)| -> Result<()> {
                    for _ in 0..steps_per_env {
                        let mask = slot.env.machine().action_mask(slot.stage);
                        let (action, log_prob) =
                            actor.act_one(&slot.state, slot.stage, &mask, &mut slot.noise)?;
                        slot.advance(k, base_seed, action, log_prob, mask)?;
                    }
                    Ok(())
                })?;
        } else {
            for _ in 0..steps_per_env {
                let states: Vec<Vec<f32>> = self.slots.iter().map(|s| s.state.clone()).collect();
                let stages: Vec<usize> = self.slots.iter().map(|s| s.stage).collect();
                let masks: Vec<Vec<f32>> = self
                    .slots
                    .iter()
                    .map(|s| s.env.machine().action_mask(s.stage))
                    .collect();
                let (actions, log_probs) = actor.act_batch(&states, &stages, &masks, false)?;
                self.slots
                    .par_iter_mut()
                    .enumerate()
                    .zip(
                        actions
                            .into_par_iter()
                            .zip(log_probs.into_par_iter())
                            .zip(masks.into_par_iter()),
                    )
                    .try_for_each(|((k, slot), ((action, log_prob), mask))| {
                        slot.advance(k, base_seed, action, log_prob, mask)
                    })?;
            }
        }
        let mut rollout = Rollout::default();
        for slot in &mut self.slots {
            rollout.append(std::mem::take(&mut slot.buffer));
        }
        Ok(rollout)
    }
}
