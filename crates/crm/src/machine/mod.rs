//! The validated machine: stages, events and edges resolved to indices, and its step.
//! Building and validating a machine from a spec lives in `build.rs`.

mod build;

use build::index_of;

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::reward::CompiledTerm;
use crate::spec::Spec;

/// Index of a stage in [`Machine::stage_names`].
pub type StageId = usize;

#[derive(Clone, Debug)]
struct Stage {
    name: String,
    terminal: bool,
    /// `(union action index, scale)` of each live dimension, in spec order.
    actions: Vec<(usize, f32)>,
    abstraction: Vec<usize>,
    reward: Vec<CompiledTerm>,
}

#[derive(Clone, Debug)]
struct Edge {
    to: StageId,
    reward: f32,
    bonus: Vec<(usize, f32)>,
}

/// A Contextual Reward Machine ready to run; build it with [`Machine::from_spec`].
#[derive(Clone, Debug)]
pub struct Machine {
    spec: Spec,
    stages: Vec<Stage>,
    initial: StageId,
    /// `edges[stage][event]`.
    edges: Vec<Vec<Option<Edge>>>,
}

/// What one step of the machine returns (DESIGN.md, "The CRM").
#[derive(Clone, Debug, PartialEq)]
pub struct StepOutcome {
    /// The stage the step was taken in (`T_i`).
    pub from: StageId,
    /// The stage after the step (`T_j`, equal to `from` when no edge fired).
    pub next: StageId,
    /// The event that moved the machine, if any.
    pub event: Option<usize>,
    /// `phi_j(u_{t+1})`: the next observation seen through the next stage's abstraction.
    pub abstract_state: Vec<f32>,
    /// `r^(i)(u'_t, a_t)`: the intra-stage reward of stage `i` on the step's outcome.
    pub intra_reward: f32,
    /// `R_T^{i->j}` (zero when no edge fired), including bonuses.
    pub transition_reward: f32,
    /// The next stage is terminal.
    pub done: bool,
}

impl Machine {
    /// The spec this machine was built from.
    pub fn spec(&self) -> &Spec {
        &self.spec
    }

    /// The initial stage `u0`.
    pub fn initial(&self) -> StageId {
        self.initial
    }

    pub fn stage_count(&self) -> usize {
        self.stages.len()
    }

    pub fn stage_name(&self, stage: StageId) -> &str {
        &self.stages[stage].name
    }

    pub fn stage_id(&self, name: &str) -> Option<StageId> {
        self.stages.iter().position(|s| s.name == name)
    }

    pub fn is_terminal(&self, stage: StageId) -> bool {
        self.stages[stage].terminal
    }

    pub fn event_id(&self, name: &str) -> Option<usize> {
        index_of(&self.spec.events, name)
    }

    pub fn event_name(&self, event: usize) -> &str {
        &self.spec.events[event]
    }

    /// Length of the global observation `u`.
    pub fn feature_count(&self) -> usize {
        self.spec.features.len()
    }

    /// Length of the union action space `A`.
    pub fn action_count(&self) -> usize {
        self.spec.action_dims.len()
    }

    /// The live union-action indices of a stage's action set `A_i`, in spec order.
    pub fn action_dims(&self, stage: StageId) -> impl Iterator<Item = usize> + '_ {
        self.stages[stage].actions.iter().map(|&(dim, _)| dim)
    }

    /// A mask over the union action space: 1 for the stage's live dimensions.
    pub fn action_mask(&self, stage: StageId) -> Vec<f32> {
        let mut mask = vec![0.0; self.action_count()];
        for dim in self.action_dims(stage) {
            mask[dim] = 1.0;
        }
        mask
    }

    /// Size of the largest abstract state, for fixed-width networks.
    pub fn max_abstract_len(&self) -> usize {
        self.stages
            .iter()
            .map(|s| s.abstraction.len())
            .max()
            .unwrap_or(0)
    }

    /// `phi_i(u)`.
    pub fn abstract_state(&self, stage: StageId, observation: &[f32]) -> Result<Vec<f32>> {
        self.check_observation(observation)?;
        Ok(self.stages[stage]
            .abstraction
            .iter()
            .map(|&i| observation[i])
            .collect())
    }

    /// Turns a stage action in `[-1, 1]^{|A_i|}` (or a full union-space vector with masked
    /// dimensions ignored) into the environment's union action: values clipped to `[-1, 1]`,
    /// multiplied by the dimension's scale, masked dimensions zero. Returns the action and
    /// how many values were clipped; a non-finite value is refused naming its dimension.
    pub fn expand_action(&self, stage: StageId, action: &[f32]) -> Result<(Vec<f32>, usize)> {
        let live = &self.stages[stage].actions;
        let full = action.len() == self.action_count();
        if !full && action.len() != live.len() {
            return Err(Error::ActionLength {
                stage: self.stages[stage].name.clone(),
                expected: live.len(),
                got: action.len(),
            });
        }
        let mut out = vec![0.0; self.action_count()];
        let mut clipped = 0;
        for (k, &(dim, scale)) in live.iter().enumerate() {
            let value = if full { action[dim] } else { action[k] };
            if !value.is_finite() {
                return Err(Error::NonFiniteAction {
                    dimension: dim,
                    name: self.spec.action_dims[dim].clone(),
                    value,
                });
            }
            let bounded = value.clamp(-1.0, 1.0);
            if bounded != value {
                clipped += 1;
            }
            out[dim] = bounded * scale;
        }
        Ok((out, clipped))
    }

    fn check_observation(&self, observation: &[f32]) -> Result<()> {
        if observation.len() != self.feature_count() {
            return Err(Error::ObservationLength {
                expected: self.feature_count(),
                got: observation.len(),
            });
        }
        Ok(())
    }

    /// One step of `delta` from `stage`, given the next global observation `u_{t+1}` and the
    /// events that fired (indices into the spec's events, any order). Takes at most one edge:
    /// the first fired event, in the spec's priority order, with an edge out of `stage`.
    pub fn step(
        &self,
        stage: StageId,
        observation: &[f32],
        fired: &[usize],
    ) -> Result<StepOutcome> {
        self.check_observation(observation)?;
        if self.stages[stage].terminal {
            return Err(Error::EpisodeOver(self.stages[stage].name.clone()));
        }
        if let Some(&bad) = fired.iter().find(|&&e| e >= self.spec.events.len()) {
            return Err(Error::UnknownEvent(format!("#{bad}")));
        }
        let intra_reward = self.stages[stage]
            .reward
            .iter()
            .map(|term| term.evaluate(observation))
            .sum();
        let taken = (0..self.spec.events.len())
            .filter(|e| fired.contains(e))
            .find_map(|e| self.edges[stage][e].as_ref().map(|edge| (e, edge)));
        let (next, event, transition_reward) = match taken {
            Some((event, edge)) => {
                let bonus: f32 = edge
                    .bonus
                    .iter()
                    .filter(|&&(feature, _)| observation[feature] > 0.5)
                    .map(|&(_, reward)| reward)
                    .sum();
                (edge.to, Some(event), edge.reward + bonus)
            }
            None => (stage, None, 0.0),
        };
        Ok(StepOutcome {
            from: stage,
            next,
            event,
            abstract_state: self.stages[next]
                .abstraction
                .iter()
                .map(|&i| observation[i])
                .collect(),
            intra_reward,
            transition_reward,
            done: self.stages[next].terminal,
        })
    }

    /// The transition reward of the edge `(from, event)`, without bonuses.
    pub fn edge_reward(&self, from: StageId, event: usize) -> Option<f32> {
        self.edges.get(from)?.get(event)?.as_ref().map(|e| e.reward)
    }

    /// The best intra-stage reward a stage can give per step (an upper bound).
    pub fn best_intra_reward(&self, stage: StageId) -> f32 {
        self.stages[stage]
            .reward
            .iter()
            .map(CompiledTerm::upper_bound)
            .sum()
    }

    /// Edges as `(from, event, to)` names, sorted, for listings.
    pub fn edge_list(&self) -> BTreeMap<(String, String), String> {
        let mut out = BTreeMap::new();
        for (from, row) in self.edges.iter().enumerate() {
            for (event, edge) in row.iter().enumerate() {
                if let Some(edge) = edge {
                    out.insert(
                        (
                            self.stages[from].name.clone(),
                            self.spec.events[event].clone(),
                        ),
                        self.stages[edge.to].name.clone(),
                    );
                }
            }
        }
        out
    }
}
