//! Errors from reading and writing files. Every variant names the file and,
//! where there is one, the place in it (line and column, or JSON path).

use std::path::PathBuf;
use thiserror::Error;

/// A file could not be read, parsed, or written.
#[derive(Debug, Error)]
pub enum IoError {
    /// The operating system refused (missing file, permissions, disk full).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A syntax or semantic error at a known position in a text file.
    #[error("{}:{line}:{column}: {message}", path.display())]
    At {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What was wrong and what was expected.
        message: String,
    },
    /// An error in a structured file at a path inside it (glTF JSON path, OBJ element).
    #[error("{}: {location}: {message}", path.display())]
    In {
        /// The file.
        path: PathBuf,
        /// Where inside it (`meshes[2].primitives[0].indices`).
        location: String,
        /// What was wrong and what was expected.
        message: String,
    },
    /// The file is not in a format chiaro reads or writes.
    #[error("{}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
}

/// Result with [`IoError`].
pub type Result<T, E = IoError> = std::result::Result<T, E>;

impl IoError {
    /// Wraps an OS error with its path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        IoError::Io {
            path: path.into(),
            source,
        }
    }

    /// A format error with a message.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        IoError::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}
