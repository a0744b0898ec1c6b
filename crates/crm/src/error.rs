//! The crate's error type.

use std::path::PathBuf;

/// Everything that can go wrong while loading a spec or stepping a machine.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The spec file could not be read.
    /// The cause is part of the message and not a `source()` too, so a chain printed with
    /// `{:#}` says it once.
    #[error("cannot read crm spec {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The spec is not valid JSON for [`crate::Spec`]; `path` is the file (or `<inline>`).
    #[error("malformed crm spec {path} at line {line}, column {column}: {message}")]
    Parse {
        path: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// The spec parsed but breaks a rule of the machine; `at` is a JSON-path-like location.
    #[error("invalid crm spec at {at}: {message}")]
    Invalid { at: String, message: String },
    /// A global observation of the wrong length reached the machine.
    #[error("observation has {got} values, the spec's features need {expected}")]
    ObservationLength { expected: usize, got: usize },
    /// A policy action of the wrong length for its stage.
    #[error(
        "action for stage {stage} has {got} values, the stage has {expected} action dimensions"
    )]
    ActionLength {
        stage: String,
        expected: usize,
        got: usize,
    },
    /// A non-finite action value; names the action dimension.
    #[error("action dimension {dimension} ({name}) is not finite: {value}")]
    NonFiniteAction {
        dimension: usize,
        name: String,
        value: f32,
    },
    /// The environment fired an event the spec does not know.
    #[error("unknown event {0}")]
    UnknownEvent(String),
    /// The episode already ended in a terminal stage.
    #[error("episode already ended in terminal stage {0}")]
    EpisodeOver(String),
    /// An error from the environment behind a [`crate::CrmEnv`].
    #[error("environment: {0}")]
    Env(String),
}

/// The crate's result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn invalid(at: impl Into<String>, message: impl Into<String>) -> Error {
    Error::Invalid {
        at: at.into(),
        message: message.into(),
    }
}
