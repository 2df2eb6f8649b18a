//! chiaro-py: the native part of the `chiaro` Python module (`chiaro._chiaro`).
//!
//! A thin adapter over the `chiaro` facade, with no rendering logic of its
//! own: it converts scenes, settings and films between Rust and Python
//! (numpy arrays), maps errors to Python exceptions, releases the GIL while
//! rendering, and lets Ctrl-C cancel a render. The user-facing API (keyword
//! settings, the `Image` type with `_repr_png_`, tqdm progress, distributed
//! rendering on Ray) is the pure-Python package in `python/chiaro/`.
//!
//! Glossary: a *film* is the renderer's linear-RGB `f32` image with depth
//! and normal buffers; an *override* is a dotted render-setting key and
//! value, as the CLI's `--set key=value`; a *region* is a pixel rectangle
//! `(x0, y0, x1, y1)` with exclusive ends.
//!
//! Build with `maturin develop --release` (see `pyproject.toml`, which turns
//! on PyO3's `extension-module` feature; plain `cargo test` links libpython
//! instead).

pub mod convert;
pub mod errors;
pub mod render;
pub mod scene;
pub mod solution;

use crate::errors::io_err;
use crate::scene::PyScene;
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use std::ffi::CString;
use std::path::PathBuf;

/// Emits each loader or render warning as a Python `UserWarning`.
pub(crate) fn warn_all(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    let category = py.get_type::<PyUserWarning>();
    for w in warnings {
        let msg = CString::new(w.replace('\0', " ")).unwrap_or_default();
        PyErr::warn(py, category.as_any(), &msg, 2)?;
    }
    Ok(())
}

/// Reads a scene file (`.toml`, `.xml` (Mitsuba 3), `.pbrt`, `.obj`, `.gltf`,
/// `.glb`, `.ply`); `defines` gives a Mitsuba scene's `$name` parameters
/// (as the CLI's `-D name=value`). Loader warnings become `UserWarning`s;
/// errors raise `SceneError` carrying `path`, `line` and `column`, or
/// `OSError` for a missing or unreadable file.
#[pyfunction]
#[pyo3(signature = (path, defines = None))]
fn load(
    py: Python<'_>,
    path: PathBuf,
    defines: Option<std::collections::BTreeMap<String, String>>,
) -> PyResult<PyScene> {
    let options = chiaro::io::LoadOptions {
        defines: defines.unwrap_or_default().into_iter().collect(),
    };
    let loaded = py
        .detach(|| chiaro::io::load_scene_with(&path, &options))
        .map_err(io_err)?;
    warn_all(py, &loaded.warnings)?;
    Ok(PyScene {
        inner: loaded.scene,
    })
}

/// Parses a `.toml` scene held in a string. Relative mesh and texture paths
/// resolve against `base_dir`; `name` stands for the file in error messages.
#[pyfunction]
#[pyo3(signature = (text, base_dir = None, name = "<string>"))]
fn loads(py: Python<'_>, text: &str, base_dir: Option<PathBuf>, name: &str) -> PyResult<PyScene> {
    let base = base_dir.unwrap_or_else(|| PathBuf::from("."));
    let loaded = chiaro::io::load_scene_str(text, &base, name).map_err(io_err)?;
    warn_all(py, &loaded.warnings)?;
    Ok(PyScene {
        inner: loaded.scene,
    })
}

/// The names of the techniques this build can render.
#[pyfunction]
fn techniques() -> Vec<&'static str> {
    chiaro::Technique::ALL.iter().map(|t| t.name()).collect()
}

/// Every dotted render-setting key accepted by `Scene.set` and `render`'s
/// settings, sorted.
#[pyfunction]
fn settings_keys() -> Vec<String> {
    chiaro::settings::known_keys()
}

/// Whether the renderer can render a region alone (a `crop` window in the
/// render settings); without it a region is cut out of a whole render.
#[pyfunction]
fn has_crop() -> bool {
    render::has_crop()
}

/// The native module.
#[pymodule]
fn _chiaro(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<PyScene>()?;
    m.add_class::<solution::PySolution>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(loads, m)?)?;
    m.add_function(wrap_pyfunction!(techniques, m)?)?;
    m.add_function(wrap_pyfunction!(settings_keys, m)?)?;
    m.add_function(wrap_pyfunction!(has_crop, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::compare, m)?)?;
    m.add_function(wrap_pyfunction!(render::metrics, m)?)?;
    m.add_function(wrap_pyfunction!(solution::solve_radiosity, m)?)?;
    m.add_function(wrap_pyfunction!(render::write, m)?)?;
    m.add_function(wrap_pyfunction!(render::resolve, m)?)?;
    m.add_function(wrap_pyfunction!(render::encode_png, m)?)?;
    m.add_function(wrap_pyfunction!(render::read_image, m)?)?;
    m.add("ChiaroError", py.get_type::<errors::ChiaroError>())?;
    m.add("SceneError", py.get_type::<errors::SceneError>())?;
    m.add("SettingsError", py.get_type::<errors::SettingsError>())?;
    m.add("RenderError", py.get_type::<errors::RenderError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
