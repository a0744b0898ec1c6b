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
//!
//! ```
//! let spec = crm::Spec::from_json(r#"{
//!   "name": "reach", "features": ["dist"], "action_dims": ["dx"],
//!   "events": ["arrive", "lost"], "initial": "approach",
//!   "stages": [
//!     {"name": "approach", "actions": [{"dim": "dx", "scale": 0.01}], "abstraction": ["dist"],
//!      "reward": [{"kind": "neg_exp_norm", "features": ["dist"]}]},
//!     {"name": "done", "terminal": true},
//!     {"name": "failed", "terminal": true}
//!   ],
//!   "transitions": [
//!     {"from": "approach", "event": "arrive", "to": "done", "reward": 10.0},
//!     {"from": "approach", "event": "lost", "to": "failed", "reward": -10.0}
//!   ]
//! }"#, "inline")?;
//! let machine = crm::Machine::from_spec(spec)?;
//! let mut episode = crm::Episode::new(&machine);
//! let arrive = machine.event_id("arrive").expect("declared");
//! let step = episode.advance(&machine, &[0.0], &[arrive])?;
//! assert_eq!(machine.stage_name(step.next), "done");
//! assert_eq!((step.intra_reward, step.transition_reward), (-1.0, 10.0));
//! assert!(step.done);
//! assert_eq!(episode.total_return(), 9.0);
//! # Ok::<(), crm::Error>(())
//! ```

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
