//! Rendering from Python: settings resolved exactly as the CLI resolves
//! them, the render run on its own thread with the GIL released, and the
//! calling thread polling Python every [`POLL`] for signals (Ctrl-C) and the
//! progress callback; the film comes back as numpy arrays.

use crate::convert::{json_to_py, merge_props, py_to_json, toml_literal};
use crate::errors::{RenderError, SettingsError, core_err, io_err, to_pyerr};
use crate::scene::PyScene;
use crate::solution::PySolution;
use chiaro::io::output::{ImageFormat, OutputOptions, encode_film, write_film};
use chiaro::scene::{Scene, ToneMap};
use chiaro::{Film, Progress, RenderSettings, Technique, Vec3};
use numpy::ndarray::{Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike2, PyArrayLike3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use serde_json::Value;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How often the calling thread wakes up during a render to check for
/// signals and report progress.
pub const POLL: Duration = Duration::from_millis(50);

/// A [`Progress`] that records the stage and counts, and can be cancelled;
/// read by the polling thread.
#[derive(Debug, Default)]
pub struct PollProgress {
    stage: Mutex<String>,
    total: AtomicU64,
    done: AtomicU64,
    cancel: AtomicBool,
    warnings: Mutex<Vec<String>>,
}

impl PollProgress {
    /// `(stage, done, total)` now.
    pub fn snapshot(&self) -> (String, u64, u64) {
        let stage = self.stage.lock().map(|s| s.clone()).unwrap_or_default();
        (
            stage,
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }

    /// The warnings the render gave so far, taken out.
    pub fn take_warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .map(|mut w| std::mem::take(&mut *w))
            .unwrap_or_default()
    }

    /// Asks the render to stop at its next poll.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

impl Progress for PollProgress {
    fn begin(&self, stage: &str, total: u64) {
        if let Ok(mut s) = self.stage.lock() {
            *s = stage.to_owned();
        }
        self.total.store(total, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
    }
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
    fn warning(&self, text: &str) {
        if let Ok(mut w) = self.warnings.lock() {
            w.push(text.to_owned());
        }
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// A pixel rectangle `x0..x1` × `y0..y1` (exclusive ends).
pub type Region = (u32, u32, u32, u32);

/// The scene's settings with the options applied in the CLI's order:
/// technique, width, height, samples, seed, then each `--set` override.
///
/// # Errors
/// `SettingsError` for an unknown technique or key, or a bad value.
pub fn resolve_settings(
    scene: &Scene,
    technique: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
    samples: Option<u32>,
    seed: Option<u64>,
    overrides: &[(String, Value)],
) -> PyResult<RenderSettings> {
    let mut s = scene.render.clone();
    if let Some(t) = technique {
        s.technique = Technique::from_name(t).ok_or_else(|| {
            SettingsError::new_err(format!(
                "unknown technique `{t}` (available: {})",
                chiaro::technique_list()
            ))
        })?;
    }
    if let Some(w) = width {
        s.width = w;
    }
    if let Some(h) = height {
        s.height = h;
    }
    if let Some(n) = samples {
        s.samples = n;
    }
    if let Some(seed) = seed {
        s.seed = seed;
    }
    for (k, v) in overrides {
        chiaro::settings::apply_override(&mut s, k, &toml_literal(v)).map_err(core_err)?;
    }
    chiaro::check_settings(&s).map_err(core_err)?;
    Ok(s)
}

/// Whether this build's [`RenderSettings`] has a `crop` window, so that a
/// region can be rendered without rendering the whole film.
pub fn has_crop() -> bool {
    serde_json::to_value(RenderSettings::default())
        .map(|v| v.get("crop").is_some())
        .unwrap_or(false)
}

/// Sets the `crop` window `[x0, y0, x1, y1]` when the settings have one;
/// returns whether they did.
fn apply_crop(settings: &mut RenderSettings, r: Region) -> bool {
    let Ok(mut v) = serde_json::to_value(&*settings) else {
        return false;
    };
    if v.get("crop").is_none() {
        return false;
    }
    v["crop"] = serde_json::json!([r.0, r.1, r.2, r.3]);
    match serde_json::from_value(v) {
        Ok(s) => {
            *settings = s;
            true
        }
        Err(_) => false,
    }
}

/// Runs `job` on a worker thread (inside a rayon pool of `threads` threads
/// when given) while the calling thread, with the GIL released, wakes every
/// [`POLL`] to check Python's signals and call `callback(stage, done,
/// total)`, and once more at the end. An exception from either cancels the
/// job (through the [`PollProgress`] it receives) and is returned instead
/// of the job's result.
///
/// # Errors
/// The interrupting exception, or `RenderError` if the pool cannot be made
/// or the job panics.
pub fn run_polling<R, F>(
    py: Python<'_>,
    callback: Option<Py<PyAny>>,
    threads: Option<usize>,
    job: F,
) -> PyResult<R>
where
    R: Send,
    F: FnOnce(&PollProgress) -> R + Send,
{
    let progress = PollProgress::default();
    let pool = match threads {
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| RenderError::new_err(format!("thread pool: {e}")))?,
        ),
        None => None,
    };
    let (result, interrupt) = py.detach(|| {
        std::thread::scope(|s| {
            let (tx, rx) = mpsc::channel::<()>();
            let (progress_ref, pool) = (&progress, &pool);
            let worker = s.spawn(move || {
                let run = || job(progress_ref);
                let r = match pool {
                    Some(p) => p.install(run),
                    None => run(),
                };
                // A failed send only means the poller stopped listening.
                let _ = tx.send(());
                r
            });
            let mut interrupt: Option<PyErr> = None;
            let poll = |interrupt: &mut Option<PyErr>| {
                Python::attach(|py| {
                    if let Err(e) = py.check_signals() {
                        *interrupt = Some(e);
                    } else if let Some(cb) = &callback
                        && let Err(e) = cb.call1(py, progress.snapshot())
                    {
                        *interrupt = Some(e);
                    }
                });
                if interrupt.is_some() {
                    progress.cancel();
                }
            };
            loop {
                match rx.recv_timeout(POLL) {
                    Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
                    Err(mpsc::RecvTimeoutError::Timeout) => {
                        if interrupt.is_none() {
                            poll(&mut interrupt);
                        }
                    }
                }
            }
            if interrupt.is_none() {
                poll(&mut interrupt);
            }
            (worker.join(), interrupt)
        })
    });
    if let Some(e) = interrupt {
        return Err(e);
    }
    // The render's warnings (what the technique cannot show, fallbacks)
    // take the loader warnings' path: Python `UserWarning`s.
    crate::warn_all(py, &progress.take_warnings())?;
    result.map_err(|_| {
        RenderError::new_err("the render thread panicked (a bug in chiaro; please report it)")
    })
}

/// `chiaro._chiaro.compare`: see `chiaro.compare` in
/// python/chiaro/__init__.py. Returns the facade's JSON report as a dict.
#[pyfunction]
#[pyo3(signature = (scene, techniques, reference = "path:auto", cache_dir = None,
                    name = "scene", width = None, height = None, samples = None,
                    seed = None, overrides = None, progress = None))]
pub fn compare<'py>(
    py: Python<'py>,
    scene: &PyScene,
    techniques: Vec<String>,
    reference: &str,
    cache_dir: Option<std::path::PathBuf>,
    name: &str,
    width: Option<u32>,
    height: Option<u32>,
    samples: Option<u32>,
    seed: Option<u64>,
    overrides: Option<Vec<(String, Bound<'py, PyAny>)>>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let overrides = overrides_json(overrides)?;
    let base = resolve_settings(&scene.inner, None, width, height, samples, seed, &overrides)?;
    let techs = techniques
        .iter()
        .map(|t| {
            Technique::from_name(t).ok_or_else(|| {
                SettingsError::new_err(format!(
                    "unknown technique `{t}` (available: {})",
                    chiaro::technique_list()
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let spec = chiaro_tools::compare::ReferenceSpec::parse(reference).map_err(core_err)?;
    let inner = &scene.inner;
    let comparison = run_polling(py, progress.map(Bound::unbind), None, |p| {
        chiaro_tools::compare::compare(inner, &base, &techs, &spec, cache_dir.as_deref(), p)
    })?
    .map_err(to_pyerr)?;
    let report = serde_json::to_value(comparison.report(name))
        .map_err(|e| RenderError::new_err(format!("report: {e}")))?;
    json_to_py(py, &report)
}

/// `chiaro._chiaro.metrics`: the numbers `chiaro compare` reports for the
/// linear-RGB `(H, W, 3)` image `test` against `reference` (same shape),
/// from the same code (`chiaro_tools::metrics`), as a dict; an infinite
/// PSNR (identical images) is `None`.
#[pyfunction]
pub fn metrics<'py>(
    py: Python<'py>,
    test: PyArrayLike3<'_, f32, AllowTypeChange>,
    reference: PyArrayLike3<'_, f32, AllowTypeChange>,
) -> PyResult<Bound<'py, PyAny>> {
    let test = film_from_arrays(test, None, None)?;
    let reference = film_from_arrays(reference, None, None)?;
    let m = py
        .detach(|| chiaro_tools::metrics::measure(&test, &reference))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let value = serde_json::to_value(m).map_err(|e| RenderError::new_err(e.to_string()))?;
    json_to_py(py, &value)
}

/// `chiaro._chiaro.resolve_settings`: the settings `render` would use for
/// these arguments, as a dict (checked: raises `SettingsError` as `render`
/// would).
#[pyfunction]
#[pyo3(name = "resolve_settings", signature = (scene, technique = None, width = None,
       height = None, samples = None, seed = None, overrides = None))]
pub fn resolve<'py>(
    py: Python<'py>,
    scene: &PyScene,
    technique: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
    samples: Option<u32>,
    seed: Option<u64>,
    overrides: Option<Vec<(String, Bound<'py, PyAny>)>>,
) -> PyResult<Bound<'py, PyAny>> {
    let overrides = overrides_json(overrides)?;
    let s = resolve_settings(
        &scene.inner,
        technique,
        width,
        height,
        samples,
        seed,
        &overrides,
    )?;
    json_to_py(py, &serde_json::to_value(&s).unwrap_or(Value::Null))
}

/// Python `(key, value)` overrides as JSON.
pub fn overrides_json(
    overrides: Option<Vec<(String, Bound<'_, PyAny>)>>,
) -> PyResult<Vec<(String, Value)>> {
    overrides
        .unwrap_or_default()
        .iter()
        .map(|(k, v)| Ok((k.clone(), py_to_json(v)?)))
        .collect()
}

/// Copies the rectangle `r` of `film` into numpy arrays: colour `(h, w, 3)`
/// and, when `aovs`, depth `(h, w)` and normal `(h, w, 3)`.
fn film_arrays<'py>(
    py: Python<'py>,
    film: &Film,
    r: Region,
    aovs: bool,
    out: &Bound<'py, PyDict>,
) -> PyResult<()> {
    let (w, h) = ((r.2 - r.0) as usize, (r.3 - r.1) as usize);
    let mut color = Vec::with_capacity(w * h * 3);
    let mut depth = Vec::with_capacity(if aovs { w * h } else { 0 });
    let mut normal = Vec::with_capacity(if aovs { w * h * 3 } else { 0 });
    for y in r.1..r.3 {
        for x in r.0..r.2 {
            let i = film.index(x, y);
            color.extend_from_slice(&film.color[i].to_array());
            if aovs {
                depth.push(film.depth[i]);
                normal.extend_from_slice(&film.normal[i].to_array());
            }
        }
    }
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    out.set_item(
        "color",
        Array3::from_shape_vec((h, w, 3), color)
            .map_err(shape_err)?
            .into_pyarray(py),
    )?;
    if aovs {
        out.set_item(
            "depth",
            Array2::from_shape_vec((h, w), depth)
                .map_err(shape_err)?
                .into_pyarray(py),
        )?;
        out.set_item(
            "normal",
            Array3::from_shape_vec((h, w, 3), normal)
                .map_err(shape_err)?
                .into_pyarray(py),
        )?;
    }
    Ok(())
}

/// `chiaro._chiaro.render`: see `chiaro.render` (python/chiaro/__init__.py)
/// for the user-facing documentation. Returns a dict with `color` (float32
/// `(H, W, 3)` linear RGB, or the region's `(y1-y0, x1-x0, 3)`), `depth` and
/// `normal` when `aovs`, `seconds`, `rays`, `triangles`, `settings` (the
/// resolved settings as a dict) and `cropped` (whether the region was
/// rendered alone rather than cut out of a whole film). With `solution`
/// (techniques `radiosity` and `hybrid` only), renders from that radiosity
/// solution instead of solving.
#[pyfunction]
#[pyo3(signature = (scene, technique = None, width = None, height = None, samples = None,
                    seed = None, overrides = None, camera = None, region = None,
                    progress = None, threads = None, aovs = false, solution = None))]
pub fn render<'py>(
    py: Python<'py>,
    scene: &PyScene,
    technique: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
    samples: Option<u32>,
    seed: Option<u64>,
    overrides: Option<Vec<(String, Bound<'py, PyAny>)>>,
    camera: Option<&Bound<'py, PyAny>>,
    region: Option<Region>,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
    aovs: bool,
    solution: Option<&PySolution>,
) -> PyResult<Bound<'py, PyDict>> {
    let overrides = overrides_json(overrides)?;
    let mut settings = resolve_settings(
        &scene.inner,
        technique,
        width,
        height,
        samples,
        seed,
        &overrides,
    )?;
    if solution.is_some() {
        chiaro::check_solution_technique(settings.technique).map_err(core_err)?;
    }
    let resolved = serde_json::to_value(&settings).unwrap_or(Value::Null);
    let full = (0, 0, settings.width, settings.height);
    let r = region.unwrap_or(full);
    if r.0 >= r.2 || r.1 >= r.3 || r.2 > settings.width || r.3 > settings.height {
        return Err(PyValueError::new_err(format!(
            "region ({}, {}, {}, {}) is not a non-empty rectangle inside the {}x{} image",
            r.0, r.1, r.2, r.3, settings.width, settings.height
        )));
    }
    let cropped = r != full && apply_crop(&mut settings, r);
    let moved;
    let scene_ref = match camera {
        Some(c) => {
            let base = serde_json::to_value(scene.inner.camera).unwrap_or(Value::Null);
            let merged =
                merge_props(&base, &py_to_json(c)?, "camera").map_err(PyValueError::new_err)?;
            let mut s = scene.inner.clone();
            s.camera = serde_json::from_value(merged)
                .map_err(|e| PyValueError::new_err(format!("camera: {e}")))?;
            moved = s;
            &moved
        }
        None => &scene.inner,
    };
    let callback = progress.map(Bound::unbind);
    let solution = solution.map(|s| Arc::clone(&s.inner));
    let (film, stats) = run_polling(py, callback, threads, |p| {
        let mut ctx = chiaro::RenderContext::new(scene_ref, &settings, p)?;
        if let Some(solution) = solution {
            ctx = ctx.with_solution(solution);
        }
        chiaro::render_with(&ctx, chiaro::renderer(settings.technique))
    })?
    .map_err(to_pyerr)?;
    let out = PyDict::new(py);
    film_arrays(py, &film, r, aovs, &out)?;
    out.set_item("seconds", stats.elapsed.as_secs_f64())?;
    out.set_item("rays", stats.rays)?;
    out.set_item("triangles", stats.triangles)?;
    out.set_item("settings", json_to_py(py, &resolved)?)?;
    out.set_item("cropped", cropped)?;
    Ok(out)
}

/// Builds a film from a float `(H, W, 3)` colour array and optional depth
/// `(H, W)` and normal `(H, W, 3)` arrays. Non-finite values are sanitised
/// by [`Film::set`].
fn film_from_arrays(
    color: PyArrayLike3<'_, f32, AllowTypeChange>,
    depth: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
    normal: Option<PyArrayLike3<'_, f32, AllowTypeChange>>,
) -> PyResult<Film> {
    let c = color.as_array();
    let [h, w, k] = [c.shape()[0], c.shape()[1], c.shape()[2]];
    if k != 3 || h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!(
            "image: expected a non-empty array of shape (H, W, 3), got {:?}",
            c.shape()
        )));
    }
    let (Ok(wu), Ok(hu)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(PyValueError::new_err("image: too large"));
    };
    let mut film = Film::new(wu, hu);
    for y in 0..h {
        for x in 0..w {
            film.set(
                x as u32,
                y as u32,
                Vec3::new(c[[y, x, 0]], c[[y, x, 1]], c[[y, x, 2]]),
            );
        }
    }
    if let Some(d) = depth {
        let d = d.as_array();
        if d.shape() != [h, w] {
            return Err(PyValueError::new_err(format!(
                "depth: expected shape ({h}, {w}), got {:?}",
                d.shape()
            )));
        }
        for (dst, src) in film.depth.iter_mut().zip(d.iter()) {
            *dst = if src.is_nan() { f32::INFINITY } else { *src };
        }
    }
    if let Some(n) = normal {
        let n = n.as_array();
        if n.shape() != [h, w, 3] {
            return Err(PyValueError::new_err(format!(
                "normal: expected shape ({h}, {w}, 3), got {:?}",
                n.shape()
            )));
        }
        for (i, dst) in film.normal.iter_mut().enumerate() {
            let (y, x) = (i / w, i % w);
            let v = Vec3::new(n[[y, x, 0]], n[[y, x, 1]], n[[y, x, 2]]);
            *dst = if v.is_finite() { v } else { Vec3::ZERO };
        }
    }
    Ok(film)
}

/// Parses a tone-map name.
fn tonemap(name: &str) -> PyResult<ToneMap> {
    match name {
        "clamp" => Ok(ToneMap::Clamp),
        "reinhard" => Ok(ToneMap::Reinhard),
        "filmic" => Ok(ToneMap::Filmic),
        _ => Err(PyValueError::new_err(format!(
            "unknown tone map {name:?} (known: clamp, reinhard, filmic)"
        ))),
    }
}

/// `chiaro._chiaro.write`: writes a linear-RGB image (and optional depth and
/// normal, kept by `.exr`) to `path` in the format of its extension (`.png`,
/// `.exr`, `.hdr`, `.ppm`), with the CLI's encoders.
#[pyfunction]
#[pyo3(signature = (path, image, depth = None, normal = None, tonemap = "clamp",
                    exposure = 0.0, bit_depth16 = false))]
pub fn write(
    py: Python<'_>,
    path: std::path::PathBuf,
    image: PyArrayLike3<'_, f32, AllowTypeChange>,
    depth: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
    normal: Option<PyArrayLike3<'_, f32, AllowTypeChange>>,
    tonemap: &str,
    exposure: f32,
    bit_depth16: bool,
) -> PyResult<()> {
    let film = film_from_arrays(image, depth, normal)?;
    let opts = OutputOptions {
        tonemap: self::tonemap(tonemap)?,
        exposure,
        bit_depth16,
        palette: None,
    };
    py.detach(|| write_film(&film, &path, &opts))
        .map_err(io_err)
}

/// `chiaro._chiaro.encode_png`: the 8-bit sRGB PNG bytes of a linear-RGB
/// `(H, W, 3)` image (used by `Image._repr_png_` for Jupyter).
#[pyfunction]
#[pyo3(signature = (image, tonemap = "clamp", exposure = 0.0))]
pub fn encode_png<'py>(
    py: Python<'py>,
    image: PyArrayLike3<'_, f32, AllowTypeChange>,
    tonemap: &str,
    exposure: f32,
) -> PyResult<Bound<'py, PyBytes>> {
    let film = film_from_arrays(image, None, None)?;
    let opts = OutputOptions {
        tonemap: self::tonemap(tonemap)?,
        exposure,
        ..OutputOptions::default()
    };
    let bytes = encode_film(&film, ImageFormat::Png, &opts).map_err(RenderError::new_err)?;
    Ok(PyBytes::new(py, &bytes))
}

/// `chiaro._chiaro.read_image`: reads an image file (`.exr`, `.hdr`, `.png`,
/// ...) as linear RGB float32 `(H, W, 3)`.
#[pyfunction]
pub fn read_image<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let film = py
        .detach(|| chiaro::io::output::read_image_as_film(Path::new(&path)))
        .map_err(io_err)?;
    let out = PyDict::new(py);
    film_arrays(py, &film, (0, 0, film.width, film.height), false, &out)?;
    out.get_item("color")?
        .ok_or_else(|| PyValueError::new_err("internal: no colour"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_testkit::scenes::white_sphere;

    #[test]
    fn progress_records_stage_and_counts() {
        let p = PollProgress::default();
        p.begin("tiles", 10);
        p.advance(3);
        p.advance(2);
        assert_eq!(p.snapshot(), ("tiles".to_owned(), 5, 10));
        assert!(!p.cancelled());
        p.cancel();
        assert!(p.cancelled());
    }

    #[test]
    fn a_cancelled_progress_stops_the_render() {
        let scene = white_sphere();
        let mut s = scene.render.clone();
        s.technique = Technique::Preview;
        s.width = 32;
        s.height = 32;
        let p = PollProgress::default();
        p.cancel();
        let r = chiaro::render(&scene, &s, &p);
        assert!(
            r.is_err(),
            "a render cancelled before it starts must not return a film"
        );
    }

    #[test]
    fn crop_is_applied_only_when_settings_have_it() {
        let mut s = RenderSettings::default();
        let before = s.clone();
        let applied = apply_crop(&mut s, (1, 2, 3, 4));
        assert_eq!(applied, has_crop());
        if !applied {
            assert_eq!(s, before);
        }
    }
}
