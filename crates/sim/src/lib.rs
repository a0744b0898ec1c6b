//! The rapier3d grasping world of the paper's sections II and IV: a five-finger hand with the
//! paper's joint coupling, the benchmark's objects and tasks, the observation vector from real
//! contact impulses, the CRM events with per-objective success tests, and domain randomization,
//! all from one seed per episode. Synchronous, no I/O beyond reading data files.

pub mod benchmark;
pub mod config;
pub mod contacts;
pub mod env;
pub mod error;
pub mod events;
pub mod hand;
pub mod observation;
pub mod oracle;
pub mod scene;
pub mod spec;

pub use benchmark::Benchmark;
pub use config::{Randomization, SimConfig};
pub use env::{GraspEnv, TaskChoice};
pub use error::{Error, Result};

/// Version of the environment's dynamics and observation layout; checkpoints record it.
pub const ENV_VERSION: &str = concat!("grasp-sim/", env!("CARGO_PKG_VERSION"), "/obs38");
