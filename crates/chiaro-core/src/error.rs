//! Errors raised by the core: settings that cannot be applied and scenes that
//! cannot be prepared for rendering.

use thiserror::Error;

/// An error from the core library. Every variant names what was wrong and,
/// where it has one, the place in the input.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// A `key=value` override named no known setting.
    #[error("unknown setting `{key}`{hint} (known: {known})")]
    UnknownSetting {
        key: String,
        /// A "did you mean" for a near miss, or empty.
        hint: String,
        known: String,
    },
    /// A setting was given a value of the wrong kind.
    #[error("setting `{key}`: {message}")]
    BadSetting { key: String, message: String },
    /// The scene has problems that make it impossible to render.
    #[error("invalid scene:\n{}", issues.join("\n"))]
    InvalidScene { issues: Vec<String> },
    /// The technique asked for does not exist (yet) in this build.
    #[error("technique `{name}` is not available (available: {available})")]
    UnknownTechnique { name: String, available: String },
    /// The render was cancelled through its [`crate::progress::Progress`].
    #[error("render cancelled")]
    Cancelled,
    /// Anything else a renderer must refuse, with the reason.
    #[error("{0}")]
    Unsupported(String),
}

/// Result with [`CoreError`].
pub type Result<T, E = CoreError> = std::result::Result<T, E>;
