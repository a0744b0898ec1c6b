//! The Contextual Reward Machine (CRM) of the paper's section III.
//!
//! A machine `M = (U, u0, Sigma, delta, T, R_T)` is data: a JSON [`Spec`] lists the stages
//! (each with its action set, state abstraction and intra-stage reward), the events, the
//! transition table `(stage, event) -> stage` and the transition reward of each edge.
//! [`Machine::from_spec`] validates a spec and names what is wrong; [`Machine::step`] moves at
//! most one edge per control step and returns the next stage, the abstract state, the
//! intra-stage reward and the transition reward separately, so a learner can compute the
//! advantage of section III-B exactly. [`Episode`] keeps the transition history `H`.
//!
//! The crate does no I/O beyond reading a spec file and never links an async runtime.

mod env;
mod episode;
mod error;
mod machine;
mod reward;
mod spec;

pub use env::{CrmEnv, CrmStep, EnvStep, Environment};
pub use episode::{Episode, Transition};
pub use error::{Error, Result};
pub use machine::{Machine, StageId, StepOutcome};
pub use reward::{RewardMode, RewardTerm};
pub use spec::{ActionSpec, BonusSpec, EdgeSpec, Spec, StageSpec};
