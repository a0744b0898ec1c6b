//! The contract between the crm-grasp coordinator (`crm-server`) and its workers (`crm`):
//! job specifications and reports as serde types, the PPO configuration with the paper's
//! defaults, the benchmark catalog (task ids, objectives, topologies) read from the
//! benchmark's data file. Light on purpose (serde, no async runtime): the coordinator, the
//! workers and the learners all link it. The gRPC protocol is in `crm-proto`.

pub mod algorithm;
pub mod catalog;
pub mod checkpoint;
pub mod config;
pub mod document;
pub mod fields;
pub mod imitation;
pub mod jobs;
pub mod names;
pub mod record;
pub mod tensorboard;
pub mod validate;
pub mod worlds;

pub use algorithm::Algorithm;
pub use catalog::Catalog;
pub use checkpoint::{CheckpointError, CheckpointInfo};
pub use config::{ConfigError, LrSchedule, PpoConfig, SacConfig};
pub use document::{EnvSpec, EvalDocument, TrainDocument};
pub use imitation::{ImitationSpec, parse_shift};
pub use jobs::{EvalReport, EvalSpec, Iteration, ObjectiveMode, Row, TrainSpec};
pub use names::check_name;
pub use record::{RecordSpec, VideoSpec};
pub use validate::SpecError;
