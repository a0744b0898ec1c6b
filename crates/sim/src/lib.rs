//! The rapier3d grasping world of the paper's sections II and IV: a five-finger hand with the
//! paper's joint coupling, the benchmark's objects and tasks, the observation vector from real
//! contact impulses, the CRM events with per-objective success tests, and domain randomization,
//! all from one seed per episode. Synchronous, no I/O beyond reading data files.
//!
//! ```
//! use std::sync::Arc;
//! use grasp_sim::{Benchmark, GraspEnv, SimConfig, TaskChoice};
//!
//! let benchmark = Arc::new(Benchmark::builtin());
//! let mut env = GraspEnv::new(benchmark, SimConfig::default());
//! env.set_task_choice(TaskChoice::Fixed(0))?;
//! let machine = grasp_sim::spec::grasping_machine();
//! let mut episode = crm::CrmEnv::new(machine, env, crm::RewardMode::Crm);
//! let (stage, state) = episode.reset(7)?;
//! assert_eq!(episode.machine().stage_name(stage), "approach");
//! // The approach stage sees 8 features and moves the palm along x, y and z.
//! assert_eq!(state.len(), 8);
//! let step = episode.step(&[0.0, 0.0, -1.0])?;
//! assert!(step.intra_reward < 0.0 && !step.done);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod assets;
pub mod benchmark;
pub mod config;
pub mod contacts;
pub mod corrections;
pub mod env;
pub mod error;
pub mod events;
pub mod hand;
pub mod import;
pub mod init;
pub mod observation;
pub mod oracle;
pub mod ready;
pub mod render;
pub mod scene;
pub mod setup;
pub mod spec;
mod staging;
pub mod stiction;
pub mod taxonomy;
pub mod view;
pub mod world;

pub use benchmark::Benchmark;
pub use config::{Approach, FingerActions, Protocol, Randomization, SimConfig};
pub use env::{GraspEnv, TaskChoice};
pub use error::{Error, Result};
pub use setup::EnvSettings;
pub use world::World;

/// Version of the environment's dynamics and observation layout; checkpoints record it.
/// `v2`: the paper's ready test and scripted objective execution, and policies that carry
/// their observation normalizer. `v4`: friction anchors between the hand and the object
/// (`stiction.rs`). (`v3` was a finger-range candidate, never shipped.)
pub const ENV_VERSION: &str = concat!("grasp-sim/", env!("CARGO_PKG_VERSION"), "/obs38/v4");
