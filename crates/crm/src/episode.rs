//! One episode through a machine: the current stage, returns and the transition history `H`.

use crate::error::Result;
use crate::machine::{Machine, StageId, StepOutcome};

/// One element of the transition history `H`: `(T_i, T_j)` with its event and reward.
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    /// Control step (0-based) whose outcome fired the edge.
    pub step: usize,
    pub from: StageId,
    pub to: StageId,
    pub event: usize,
    /// `R_T^{i->j}` including bonuses.
    pub reward: f32,
}

/// The running state of one episode.
#[derive(Clone, Debug)]
pub struct Episode {
    stage: StageId,
    steps: usize,
    history: Vec<Transition>,
    intra_return: f64,
    transition_return: f64,
}

impl Episode {
    /// Starts in the machine's initial stage (entered without a reward, paper section IV-A).
    pub fn new(machine: &Machine) -> Self {
        Self {
            stage: machine.initial(),
            steps: 0,
            history: Vec::new(),
            intra_return: 0.0,
            transition_return: 0.0,
        }
    }

    pub fn stage(&self) -> StageId {
        self.stage
    }

    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The transition history `H`, in order.
    pub fn history(&self) -> &[Transition] {
        &self.history
    }

    /// Sum of the intra-stage rewards so far (all modes' raw values).
    pub fn intra_return(&self) -> f64 {
        self.intra_return
    }

    /// Sum of the transition rewards of the edges in `H`.
    pub fn transition_return(&self) -> f64 {
        self.transition_return
    }

    /// The paper's cumulative reward `R` (section III-A).
    pub fn total_return(&self) -> f64 {
        self.intra_return + self.transition_return
    }

    /// Steps the machine and records the edge taken, if any.
    pub fn advance(
        &mut self,
        machine: &Machine,
        observation: &[f32],
        fired: &[usize],
    ) -> Result<StepOutcome> {
        let outcome = machine.step(self.stage, observation, fired)?;
        self.intra_return += f64::from(outcome.intra_reward);
        if let Some(event) = outcome.event {
            self.transition_return += f64::from(outcome.transition_reward);
            self.history.push(Transition {
                step: self.steps,
                from: outcome.from,
                to: outcome.next,
                event,
                reward: outcome.transition_reward,
            });
        }
        self.stage = outcome.next;
        self.steps += 1;
        Ok(outcome)
    }
}
