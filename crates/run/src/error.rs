//! The crate's error type.

/// Everything that can stop a run, an evaluation or the making of its environments.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A job's setting out of its domain, or a request the run cannot serve; the message
    /// names the field.
    #[error("{0}")]
    Invalid(String),
    /// The caller asked to stop.
    #[error("cancelled after {done} of {total} episodes")]
    Cancelled { done: u64, total: u64 },
    /// A file could not be read or written. The cause is part of the message and not a
    /// `source()` too, so a chain printed with `{:#}` says it once.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    /// The world refused (loading it, a task, a step).
    #[error(transparent)]
    World(#[from] grasp_sim::Error),
    /// The learner refused (a checkpoint, a setting, a tensor operation).
    #[error(transparent)]
    Learn(#[from] crm_learn::Error),
    /// The machine refused (its spec, a step).
    #[error(transparent)]
    Crm(#[from] crm::Error),
    #[error("tensor: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// What was being done when `inner` happened (printed once, as `context: inner`).
    #[error("{context}: {inner}")]
    Context { context: String, inner: Box<Error> },
}

/// The crate's result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `Error::Invalid` from a format string: `invalid!("envs must be at least 1")`.
macro_rules! invalid {
    ($($arg:tt)*) => {
        $crate::Error::Invalid(format!($($arg)*))
    };
}
pub(crate) use invalid;

/// Says what was being done when a result failed.
pub trait Context<T> {
    fn context(self, context: impl Into<String>) -> Result<T>;
    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, context: impl Into<String>) -> Result<T> {
        self.map_err(|inner| Error::Context {
            context: context.into(),
            inner: Box::new(inner.into()),
        })
    }

    fn with_context<S: Into<String>>(self, context: impl FnOnce() -> S) -> Result<T> {
        self.map_err(|inner| Error::Context {
            context: context().into(),
            inner: Box::new(inner.into()),
        })
    }
}

/// A file's bytes, or [`Error::Io`] naming it.
pub(crate) fn read(path: &std::path::Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|error| Error::Io {
        path: path.display().to_string(),
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_context_prints_its_cause_once() {
        let err = read(std::path::Path::new("/no/such/file"))
            .context("loading the model")
            .expect_err("missing");
        let text = format!("{err}");
        assert!(
            text.starts_with("loading the model: /no/such/file: "),
            "{text}"
        );
        assert_eq!(text.matches("No such file").count(), 1, "{text}");
        assert!(std::error::Error::source(&err).is_none());
    }
}
