//! The crate's error type.

/// Everything that can go wrong while loading the benchmark or stepping the world.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A data file could not be read. The cause is part of the message and not a
    /// `source()` too, so a chain printed with `{:#}` says it once.
    #[error("cannot read {path}: {error}")]
    Io { path: String, error: std::io::Error },
    /// A data file is not valid JSON for its type.
    #[error("malformed {path} at line {line}, column {column}: {message}")]
    Parse {
        path: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// A data file parsed but a value is out of its domain; `at` locates it in the file.
    #[error("invalid {path} at {at}: {message}")]
    Invalid {
        path: String,
        at: String,
        message: String,
    },
    /// An action of the wrong length.
    #[error("action has {got} values, expected {expected}")]
    ActionLength { expected: usize, got: usize },
    /// A non-finite action value, naming its dimension.
    #[error("action dimension {dimension} ({name}) is not finite: {value}")]
    NonFiniteAction {
        dimension: usize,
        name: &'static str,
        value: f32,
    },
    /// A task id that is not in the benchmark.
    #[error("unknown task {0:?}")]
    UnknownTask(String),
    /// A task id a job named that its world lacks, with the world's task ids.
    #[error("unknown task {id:?} (the world {world:?} has {known})")]
    NoSuchTask {
        id: String,
        world: String,
        known: String,
    },

    #[error("task weights: {0}")]
    TaskWeights(String),
    /// The machine spec does not fit this environment.
    #[error("crm spec: {0}")]
    Crm(#[from] crm::Error),
    /// `step` before `reset`.
    #[error("the environment was stepped before reset")]
    NotReset,
    /// The physics produced a non-finite state (a diverged simulation).
    #[error("the simulation diverged: {0}")]
    Diverged(String),
}

/// The crate's result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A data file's text, or [`Error::Io`] naming it.
pub(crate) fn read_text(path: &std::path::Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|error| Error::Io {
        path: path.display().to_string(),
        error,
    })
}

/// [`Error::Invalid`] for the file `path` at `at`.
pub(crate) fn invalid_at(
    path: &std::path::Path,
    at: impl Into<String>,
    message: impl Into<String>,
) -> Error {
    Error::Invalid {
        path: path.display().to_string(),
        at: at.into(),
        message: message.into(),
    }
}

pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(text: &str, path: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|err| Error::Parse {
        path: path.to_string(),
        line: err.line(),
        column: err.column(),
        message: err.to_string(),
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_missing_file_says_its_cause_once() {
        let err = super::read_text(std::path::Path::new("/nonexistent/hand.json"))
            .expect_err("no such file");
        let chain = format!("{:#}", anyhow::Error::from(err));
        assert!(
            chain.starts_with("cannot read /nonexistent/hand.json: "),
            "{chain}"
        );
        assert_eq!(chain.matches("os error 2").count(), 1, "{chain}");
    }
}
