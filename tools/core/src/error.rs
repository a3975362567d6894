use std::path::PathBuf;

/// Everything that can go wrong inside relevo-core. Each message is whole:
/// the underlying error is part of the text, not a separate source, so a
/// printer of the error chain (`{:#}`) does not repeat it.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {io}")]
    Io { path: PathBuf, io: std::io::Error },
    #[error("{path}: invalid manifest: {json}")]
    Manifest {
        path: PathBuf,
        json: serde_json::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{0}")]
    Input(String),
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            io: source,
        }
    }
    pub(crate) fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
