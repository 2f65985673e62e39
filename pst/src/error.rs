//! What can go wrong in fresco-pst, naming the file, the node or the value at fault.

use std::path::PathBuf;

use fresco_core::{ConfigError, FormatError};

/// Errors of every pst operation. Libraries return these; the CLI prints them.
#[derive(Debug, thiserror::Error)]
pub enum PstError {
    /// An input or output file was malformed or could not be read or written.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The operating system refused an operation on a path (temporary folder, PST folder).
    /// The OS error is part of the message, so it is not also the `source` (see
    /// `FormatError::Io`).
    #[error("{path}: {what}: {error}")]
    Io {
        path: PathBuf,
        what: &'static str,
        error: std::io::Error,
    },
    /// A field of a `Config` is out of range (target size 0, k = 0, ...).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An argument of an operation is unusable (an empty region, a missing channel, ...).
    #[error("invalid parameter: {0}")]
    Parameter(String),
    /// The input holds no usable point (empty file, only non-finite coordinates).
    #[error("{path}: {message}")]
    EmptyInput { path: PathBuf, message: String },
    /// A PST folder is missing a file or holds inconsistent data.
    #[error("PST folder {path}: {message}")]
    Store { path: PathBuf, message: String },
    /// An editing script (ops JSON) is malformed.
    #[error("{path}: operation {index}: {message}")]
    Op {
        path: PathBuf,
        index: usize,
        message: String,
    },
}

impl PstError {
    pub(crate) fn io(path: impl Into<PathBuf>, what: &'static str, error: std::io::Error) -> Self {
        PstError::Io {
            path: path.into(),
            what,
            error,
        }
    }
    pub(crate) fn store(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        PstError::Store {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, PstError>;
