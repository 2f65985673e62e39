//! What can go wrong in fresco-pst, naming the file, the node or the value at fault.

use std::path::PathBuf;

use fresco_core::FormatError;

/// Errors of every pst operation. Libraries return these; the CLI prints them.
#[derive(Debug, thiserror::Error)]
pub enum PstError {
    /// An input or output file was malformed or could not be read or written.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The operating system refused an operation on a path (temporary folder, PST folder).
    #[error("{path}: {what}: {source}")]
    Io {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// A parameter was out of range (target size 0, k = 0, empty region, ...).
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
    pub(crate) fn io(path: impl Into<PathBuf>, what: &'static str, source: std::io::Error) -> Self {
        PstError::Io {
            path: path.into(),
            what,
            source,
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
