//! CRM-SAC's replay buffer: a ring of raw transitions, and its form inside a checkpoint, so
//! that a resumed run samples from the same buffer, row for row, as the run never stopped.
//!
//! In a checkpoint the rows are tensors in ring order (`state.replay.*`): the states
//! `[n, width]`, the actions `[n, actions]`, the rewards, the stages and next stages (`u32`)
//! and the terminal flags (`u8`). A row's next state is almost always the state of the row
//! after it (a rollout stores each environment's steps in order), so it is written only
//! where it is not, bit for bit: `state.replay.next_follows` (`u8`, 1 where row `i`'s next
//! state is row `i + 1`'s state) and `state.replay.next_states` `[k, width]` for the others,
//! in order. With SB3's 1,000,000 transitions of the built-in world (38 features, 8 actions)
//! that is about 200 MB. States shorter than the widest stage's are zero-padded, with their
//! lengths beside (`state.replay.state_lens`, `state.replay.next_state_lens`). The action
//! masks follow from the stages and are not stored.

use std::collections::HashMap;

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// One stored transition (raw: observations are normalized when sampled).
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    pub state: Vec<f32>,
    pub stage: usize,
    pub action: Vec<f32>,
    pub reward: f32,
    pub next_state: Vec<f32>,
    pub next_stage: usize,
    pub terminal: bool,
}

/// The header's part of a replay buffer: where the ring stands.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplayRecord {
    /// Rows held (the tensors' first dimension).
    pub len: usize,
    /// The row the next transition overwrites once the ring is full.
    pub next_slot: usize,
    /// Transitions stored over the whole run.
    pub seen: usize,
}

/// A ring of at most `capacity` transitions.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    capacity: usize,
    rows: Vec<Transition>,
    next_slot: usize,
    seen: usize,
}

const STATES: &str = "state.replay.states";
const ACTIONS: &str = "state.replay.actions";
const REWARDS: &str = "state.replay.rewards";
const STAGES: &str = "state.replay.stages";
const NEXT_STAGES: &str = "state.replay.next_stages";
const TERMINAL: &str = "state.replay.terminal";
const NEXT_FOLLOWS: &str = "state.replay.next_follows";
const NEXT_STATES: &str = "state.replay.next_states";
const STATE_LENS: &str = "state.replay.state_lens";
const NEXT_LENS: &str = "state.replay.next_state_lens";

fn missing(name: &str) -> Error {
    Error::Config {
        field: "state",
        message: format!("the checkpoint's training state lacks tensor {name}"),
    }
}

fn bits_equal(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

impl Replay {
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            rows: Vec::new(),
            next_slot: 0,
            seen: 0,
        }
    }

    /// Stores a transition, overwriting the oldest once full.
    pub fn push(&mut self, row: Transition) {
        if self.rows.len() < self.capacity {
            self.rows.push(row);
        } else {
            self.rows[self.next_slot] = row;
        }
        self.next_slot = (self.next_slot + 1) % self.capacity;
        self.seen += 1;
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Transitions stored over the whole run.
    pub fn seen(&self) -> usize {
        self.seen
    }

    pub fn get(&self, i: usize) -> &Transition {
        &self.rows[i]
    }

    /// The buffer as a checkpoint keeps it: the header's record and the tensors.
    pub fn to_state(
        &self,
        width: usize,
        actions: usize,
    ) -> Result<(ReplayRecord, Vec<(String, Tensor)>)> {
        let n = self.rows.len();
        let mut states = Vec::with_capacity(n * width);
        let mut lens = Vec::with_capacity(n);
        let mut next_lens = Vec::new();
        let mut acts = Vec::with_capacity(n * actions);
        let mut rewards = Vec::with_capacity(n);
        let mut stages = Vec::with_capacity(n);
        let mut next_stages = Vec::with_capacity(n);
        let mut terminal = Vec::with_capacity(n);
        let mut follows = Vec::with_capacity(n);
        let mut next_states = Vec::new();
        for (i, row) in self.rows.iter().enumerate() {
            if row.state.len() > width || row.next_state.len() > width {
                return Err(Error::Length {
                    what: "a stored state",
                    expected: width,
                    got: row.state.len().max(row.next_state.len()),
                });
            }
            if row.action.len() != actions {
                return Err(Error::Length {
                    what: "a stored action",
                    expected: actions,
                    got: row.action.len(),
                });
            }
            padded(&mut states, &row.state, width);
            lens.push(row.state.len() as u32);
            acts.extend_from_slice(&row.action);
            rewards.push(row.reward);
            stages.push(stage_u32(row.stage)?);
            next_stages.push(stage_u32(row.next_stage)?);
            terminal.push(u8::from(row.terminal));
            let following = &self.rows[(i + 1) % n].state;
            if n > 1 && bits_equal(&row.next_state, following) {
                follows.push(1u8);
            } else {
                follows.push(0u8);
                padded(&mut next_states, &row.next_state, width);
                next_lens.push(row.next_state.len() as u32);
            }
        }
        let cpu = &Device::Cpu;
        let k = next_states.len() / width.max(1);
        let tensors = vec![
            (STATES.into(), Tensor::from_vec(states, (n, width), cpu)?),
            (STATE_LENS.into(), Tensor::from_vec(lens, n, cpu)?),
            (ACTIONS.into(), Tensor::from_vec(acts, (n, actions), cpu)?),
            (REWARDS.into(), Tensor::from_vec(rewards, n, cpu)?),
            (STAGES.into(), Tensor::from_vec(stages, n, cpu)?),
            (NEXT_STAGES.into(), Tensor::from_vec(next_stages, n, cpu)?),
            (TERMINAL.into(), Tensor::from_vec(terminal, n, cpu)?),
            (NEXT_FOLLOWS.into(), Tensor::from_vec(follows, n, cpu)?),
            (
                NEXT_STATES.into(),
                Tensor::from_vec(next_states, (k, width), cpu)?,
            ),
            (NEXT_LENS.into(), Tensor::from_vec(next_lens, k, cpu)?),
        ];
        let record = ReplayRecord {
            len: n,
            next_slot: self.next_slot,
            seen: self.seen,
        };
        Ok((record, tensors))
    }

    /// The buffer of `record` with its rows from `tensors`, in a ring of `capacity`.
    pub fn from_state(
        capacity: usize,
        record: &ReplayRecord,
        tensors: &HashMap<String, Tensor>,
    ) -> Result<Self> {
        let get = |name: &str| tensors.get(name).ok_or_else(|| missing(name));
        let n = record.len;
        if n > capacity.max(1) || record.next_slot >= capacity.max(1) {
            return Err(Error::Config {
                field: "state",
                message: format!(
                    "the checkpoint's replay buffer ({n} rows, next slot {}) does not fit \
                     buffer_size {capacity}",
                    record.next_slot
                ),
            });
        }
        let states = unpadded(get(STATES)?, get(STATE_LENS)?)?;
        let actions = get(ACTIONS)?.to_vec2::<f32>()?;
        let rewards = get(REWARDS)?.to_vec1::<f32>()?;
        let stages = get(STAGES)?.to_vec1::<u32>()?;
        let next_stages = get(NEXT_STAGES)?.to_vec1::<u32>()?;
        let terminal = get(TERMINAL)?.to_vec1::<u8>()?;
        let follows = get(NEXT_FOLLOWS)?.to_vec1::<u8>()?;
        let mut explicit = unpadded(get(NEXT_STATES)?, get(NEXT_LENS)?)?.into_iter();
        for (what, got) in [
            ("the replay buffer's states", states.len()),
            ("the replay buffer's actions", actions.len()),
            ("the replay buffer's rewards", rewards.len()),
            ("the replay buffer's stages", stages.len()),
            ("the replay buffer's next stages", next_stages.len()),
            ("the replay buffer's terminal flags", terminal.len()),
            ("the replay buffer's next-state flags", follows.len()),
        ] {
            if got != n {
                return Err(Error::Length {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        let mut rows = Vec::with_capacity(n);
        for i in 0..n {
            let next_state = if follows[i] == 1 {
                states[(i + 1) % n].clone()
            } else {
                explicit.next().ok_or_else(|| missing(NEXT_STATES))?
            };
            rows.push(Transition {
                state: states[i].clone(),
                stage: stages[i] as usize,
                action: actions[i].clone(),
                reward: rewards[i],
                next_state,
                next_stage: next_stages[i] as usize,
                terminal: terminal[i] == 1,
            });
        }
        Ok(Self {
            capacity: capacity.max(1),
            rows,
            next_slot: record.next_slot,
            seen: record.seen,
        })
    }
}

/// Appends `row` to `out`, zero-padded to `width`.
fn padded(out: &mut Vec<f32>, row: &[f32], width: usize) {
    out.extend_from_slice(row);
    out.resize(out.len() + width - row.len(), 0.0);
}

/// The rows of a padded `[n, width]` tensor cut to their lengths.
fn unpadded(padded: &Tensor, lens: &Tensor) -> Result<Vec<Vec<f32>>> {
    let rows = padded.to_vec2::<f32>()?;
    let lens = lens.to_vec1::<u32>()?;
    if lens.len() != rows.len() {
        return Err(Error::Length {
            what: "the replay buffer's state lengths",
            expected: rows.len(),
            got: lens.len(),
        });
    }
    rows.into_iter()
        .zip(lens)
        .map(|(mut row, len)| {
            if len as usize > row.len() {
                return Err(Error::Length {
                    what: "a stored state",
                    expected: row.len(),
                    got: len as usize,
                });
            }
            row.truncate(len as usize);
            Ok(row)
        })
        .collect()
}

fn stage_u32(stage: usize) -> Result<u32> {
    u32::try_from(stage).map_err(|_| Error::Config {
        field: "state",
        message: format!("stage {stage} does not fit a checkpoint's u32"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(k: u32, next_follows: bool) -> Transition {
        let mut state = vec![k as f32, -(k as f32) * 0.5];
        if k == 6 {
            state.pop();
        }
        let next_state = if next_follows {
            vec![(k + 1) as f32, -((k + 1) as f32) * 0.5]
        } else {
            vec![f32::from_bits(0x7fc0_0001), 1e-30 * k as f32]
        };
        Transition {
            state,
            stage: (k % 3) as usize,
            action: vec![0.1 * k as f32, -0.25, 3.0],
            reward: k as f32 * 0.01,
            next_state,
            next_stage: ((k + 1) % 3) as usize,
            terminal: k.is_multiple_of(4),
        }
    }

    #[test]
    fn a_ring_reads_back_from_its_tensors_row_for_row() {
        let mut replay = Replay::new(5);
        for k in 0..8 {
            replay.push(row(k, !k.is_multiple_of(3)));
        }
        assert_eq!((replay.len(), replay.seen(), replay.next_slot), (5, 8, 3));
        let (record, tensors) = replay.to_state(2, 3).expect("state");
        let tensors: HashMap<String, Tensor> = tensors.into_iter().collect();
        let back = Replay::from_state(5, &record, &tensors).expect("restore");
        // NaN payloads included: equality of the rows is by bits.
        for i in 0..replay.len() {
            let (a, b) = (replay.get(i), back.get(i));
            assert!(bits_equal(&a.next_state, &b.next_state), "row {i}");
            assert!(bits_equal(&a.state, &b.state), "row {i}");
            assert_eq!(
                (
                    a.stage,
                    a.next_stage,
                    a.terminal,
                    a.reward.to_bits(),
                    &a.action
                ),
                (
                    b.stage,
                    b.next_stage,
                    b.terminal,
                    b.reward.to_bits(),
                    &b.action
                )
            );
        }
        assert_eq!((back.next_slot, back.seen, back.capacity), (3, 8, 5));
        // Only the rows whose next state is not the following row's state carry their own.
        let explicit = tensors[NEXT_STATES].dims()[0];
        assert!(explicit < 5, "{explicit}");

        let refused = Replay::from_state(4, &record, &tensors).expect_err("a smaller ring");
        assert!(refused.to_string().contains("buffer_size 4"), "{refused}");
        let mut partial = tensors.clone();
        partial.remove(ACTIONS);
        let refused = Replay::from_state(5, &record, &partial).expect_err("no actions");
        assert!(refused.to_string().contains(ACTIONS), "{refused}");
    }

    #[test]
    fn an_empty_buffer_round_trips() {
        let replay = Replay::new(4);
        let (record, tensors) = replay.to_state(2, 3).expect("state");
        let tensors: HashMap<String, Tensor> = tensors.into_iter().collect();
        assert_eq!(
            Replay::from_state(4, &record, &tensors).expect("restore"),
            replay
        );
    }
}
