//! Errors for reading and writing files: every variant names the file and, where it applies,
//! the line (text formats) or byte offset (binary formats) and what was expected there.

use std::path::PathBuf;

/// What was wrong with a file, and where.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The operating system refused (missing file, permissions, disk full).
    ///
    /// The OS error is part of the message and deliberately not also exposed as
    /// `Error::source`: anyhow's `{:#}` prints the whole source chain, so a source here
    /// made every CLI message say the OS error twice.
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// A text format did not parse at a line (1-based).
    #[error("{path}:{line}: {message}")]
    Text {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A binary format did not parse at a byte offset.
    #[error("{path}: at byte {offset}: {message}")]
    Binary {
        path: PathBuf,
        offset: u64,
        message: String,
    },
    /// The file parsed but its content is inconsistent (counts, indices out of range, NaN).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

impl FormatError {
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        FormatError::Io {
            path: path.into(),
            error,
        }
    }
    pub fn text(path: impl Into<PathBuf>, line: usize, message: impl Into<String>) -> Self {
        FormatError::Text {
            path: path.into(),
            line,
            message: message.into(),
        }
    }
    pub fn binary(path: impl Into<PathBuf>, offset: u64, message: impl Into<String>) -> Self {
        FormatError::Binary {
            path: path.into(),
            offset,
            message: message.into(),
        }
    }
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        FormatError::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}
