//! Python exceptions for chiaro's errors.
//!
//! - `chiaro.ChiaroError` — base of everything below.
//! - `chiaro.SceneError` — a scene file that does not parse or a scene that
//!   does not validate; carries `path`, `line`, `column` (1-based, `None`
//!   when the error has no position) and `location` (a glTF JSON path) as
//!   attributes, and `str(e)` is `path:line:col: message`.
//! - `chiaro.SettingsError` — an unknown or ill-typed render setting.
//! - `chiaro.RenderError` — a technique refused the scene.
//! - Missing or unreadable files raise the built-in `OSError` subclasses
//!   (`FileNotFoundError`, ...); a cancelled render re-raises whatever
//!   interrupted it (normally `KeyboardInterrupt`).

use chiaro::io::IoError;
use chiaro_core::error::CoreError;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError};
use pyo3::prelude::*;

create_exception!(
    _chiaro,
    ChiaroError,
    PyException,
    "Base class of chiaro's errors."
);
create_exception!(
    _chiaro,
    SceneError,
    ChiaroError,
    "A scene file that does not parse, or a scene that does not validate. Attributes: path, line, column, location."
);
create_exception!(
    _chiaro,
    SettingsError,
    ChiaroError,
    "An unknown or ill-typed render setting."
);
create_exception!(
    _chiaro,
    RenderError,
    ChiaroError,
    "A technique refused the scene or the render was cancelled."
);

/// Builds a `SceneError` with its position attributes set.
fn scene_error(
    message: String,
    path: Option<String>,
    line: Option<usize>,
    column: Option<usize>,
    location: Option<String>,
) -> PyErr {
    Python::attach(|py| {
        let err = SceneError::new_err(message);
        let value = err.value(py);
        // Setting attributes on a fresh exception instance cannot fail in
        // practice; if it does, the message still carries the position.
        let _ = value.setattr("path", path);
        let _ = value.setattr("line", line);
        let _ = value.setattr("column", column);
        let _ = value.setattr("location", location);
        err
    })
}

/// Maps a file error to a Python exception.
pub fn io_err(e: IoError) -> PyErr {
    let message = e.to_string();
    match e {
        IoError::Io { path, source } => {
            let errno = source.raw_os_error().unwrap_or(0);
            PyOSError::new_err((errno, message, path.display().to_string()))
        }
        IoError::At {
            path, line, column, ..
        } => scene_error(
            message,
            Some(path.display().to_string()),
            Some(line),
            Some(column),
            None,
        ),
        IoError::In { path, location, .. } => scene_error(
            message,
            Some(path.display().to_string()),
            None,
            None,
            Some(location),
        ),
        IoError::Format { path, .. } => {
            scene_error(message, Some(path.display().to_string()), None, None, None)
        }
    }
}

/// Maps a scene/settings/technique error to a Python exception.
pub fn core_err(e: CoreError) -> PyErr {
    let message = e.to_string();
    match e {
        CoreError::UnknownSetting { .. } | CoreError::BadSetting { .. } => {
            SettingsError::new_err(message)
        }
        CoreError::UnknownTechnique { .. } => SettingsError::new_err(message),
        CoreError::InvalidScene { .. } => scene_error(message, None, None, None, None),
        _ => RenderError::new_err(message),
    }
}

/// Maps any facade error to a Python exception.
pub fn to_pyerr(e: chiaro::Error) -> PyErr {
    match e {
        chiaro::Error::Core(c) => core_err(c),
        chiaro::Error::Io(i) => io_err(i),
    }
}
