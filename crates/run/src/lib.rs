//! The experiment runtime: what a job does, whoever starts it (the `crm` command line, the
//! service's worker, a benchmark). [`env`] makes a run's environments from a world and a
//! job's settings; [`train`] runs a training job one iteration at a time with checkpoints and
//! their lineage; [`eval`] evaluates a checkpoint over tasks (the paper's Table I); [`demos`]
//! and [`anchors`] make behaviour cloning's rows from the scripted oracle and a policy, and
//! [`imitation`] runs a job's cloning stage with them;
//! [`topology`] is the grasp-topology network's picks; [`record`] is how a job's episodes are
//! recorded, behind traits (rerun lives in the binary). Nothing here parses a command line or
//! talks to the network.

pub mod anchors;
pub mod choice;
pub mod demos;
pub mod env;
pub mod error;
pub mod eval;
pub mod export;
pub mod fit;
pub mod imitation;
pub mod record;
pub mod topology;
pub mod train;

pub use choice::{EnvChoice, check_world, reward_mode};
pub use env::{Env, EnvSpec};
pub use error::{Context, Error, Result};
pub use eval::{EpisodeRecord, LoadedPolicy, evaluate, evaluate_in};
pub use record::{Recorded, SharedRecorder};
pub use train::{Init, Trainer};
