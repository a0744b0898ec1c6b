//! The crate's error type.

/// Everything that can go wrong in a learner.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor operation failed.
    #[error("tensor: {0}")]
    Candle(#[from] candle_core::Error),
    /// A file is not a crm-grasp checkpoint, or one that does not fit.
    #[error("checkpoint {path}: {message}")]
    Checkpoint { path: String, message: String },
    /// Inputs of mismatched lengths reached a computation; names what and the lengths.
    #[error("{what}: expected {expected} values, got {got}")]
    Length {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// The environment or the machine refused a step.
    #[error("environment: {0}")]
    Env(String),
    /// A PPO setting out of its domain; names the field.
    #[error(transparent)]
    Settings(#[from] crm_api::ConfigError),
    /// A configuration value out of its domain; names the field.
    #[error("invalid config field {field}: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
}

/// The crate's result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;
