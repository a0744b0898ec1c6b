//! Vectorized rollouts: several `crm::CrmEnv`s stepped in parallel, the policy evaluated on
//! all of them in one batch. Deterministic per seed whatever the thread count: each
//! environment's episode seeds depend only on the base seed, its index and its episode count,
//! and the policy's noise is drawn in environment order on the calling thread.

use rayon::prelude::*;

use crate::error::{Error, Result};

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
    /// Episodes that ended in this rollout: (success, length, return).
    pub episodes: Vec<(bool, usize, f32)>,
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
    episode_return: f32,
    episode_length: usize,
    buffer: Rollout,
}

/// A policy the rollouts can ask for actions (PPO's and SAC's).
pub trait Actor {
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
                    episode_return: 0.0,
                    episode_length: 0,
                    buffer: Rollout::default(),
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

    /// Steps every environment `steps_per_env` times with the policy of `actor`.
    pub fn collect<A: Actor>(&mut self, actor: &mut A, steps_per_env: usize) -> Result<Rollout> {
        let base_seed = self.base_seed;
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
                .try_for_each(|((k, slot), ((action, log_prob), mask))| -> Result<()> {
                    let step = slot.env.step(&action).map_err(env_error)?;
                    slot.episode_return += step.intra_reward + step.transition_reward;
                    slot.episode_length += 1;
                    let last = step.done || step.truncated;
                    let b = &mut slot.buffer;
                    b.states.push(std::mem::take(&mut slot.state));
                    b.stages.push(slot.stage);
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
                        let success =
                            step.done && slot.env.machine().stage_name(step.stage) == "success";
                        b.episodes
                            .push((success, slot.episode_length, slot.episode_return));
                        slot.episode += 1;
                        slot.episode_return = 0.0;
                        slot.episode_length = 0;
                        let seed = episode_seed(base_seed, k, slot.episode);
                        (slot.stage, slot.state) = slot.env.reset(seed).map_err(env_error)?;
                    } else {
                        (slot.stage, slot.state) = (step.stage, step.abstract_state);
                    }
                    Ok(())
                })?;
        }
        let mut rollout = Rollout::default();
        for slot in &mut self.slots {
            rollout.append(std::mem::take(&mut slot.buffer));
        }
        Ok(rollout)
    }
}
