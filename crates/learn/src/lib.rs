//! Learners on candle for the Contextual Reward Machine (paper, section III-B): the
//! actor-critic networks with the stage's action mask, GAE with the transition reward inside
//! the TD error, PPO with vectorized rollouts, the paper's learning-rate steps and early-stop
//! rule, the grasp-topology network (section II-B), and checkpoints
//! (safetensors with a JSON header). Synchronous; no I/O but checkpoint files.

pub mod checkpoint;
pub mod curriculum;
pub mod early_stop;
pub mod error;
pub mod folded;
mod fused;
pub mod gae;
pub mod imitation;
pub mod kernels;
pub mod layers;
pub mod lineage;
pub mod network;
pub mod noise;
pub mod normalize;
pub mod onnx;
pub mod optim;
pub mod ppo;
pub mod replay;
pub mod rollout;
pub mod sac;
pub mod state;
pub mod topology;

pub use checkpoint::{Checkpoint, CheckpointHeader};
pub use crm_api::PpoConfig;
pub use curriculum::TaskCurriculum;
pub use early_stop::EarlyStop;
pub use error::{Error, Result};
pub use imitation::Demos;
pub use lineage::LineageStage;
pub use network::{ActorCritic, Layout};
pub use noise::Noise;
pub use normalize::{ObsNorm, RewardScaler};
pub use ppo::{Ppo, PpoState, UpdateEngine, UpdateStats, UpdateTiming};
pub use rollout::{Actor, EnvState, Episode, Rollout, VecEnv};
pub use sac::{Sac, SacNets, SacStats};
pub use topology::{Example, TopologyNet};
