//! Radiosity solutions from Python: `chiaro.solve_radiosity` solves a
//! scene's radiosity once and returns an opaque [`PySolution`], which
//! `chiaro.render(..., solution=)` displays (technique `radiosity`) or uses
//! for the diffuse interreflection of the hybrid technique, without solving
//! again. A solution is view independent, so one serves every camera and
//! every tile of a distributed render; it travels as bytes (the JSON of
//! `RadiositySolution::save`) and pickles.

use crate::errors::{RenderError, core_err, to_pyerr};
use crate::render::{overrides_json, resolve_settings, run_polling};
use crate::scene::PyScene;
use chiaro::RadiositySolution;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use std::sync::Arc;

/// A view-independent radiosity solution of one scene (Python
/// `chiaro.RadiositySolution`). Immutable; shared, not copied, between
/// renders.
#[pyclass(name = "RadiositySolution", module = "chiaro._chiaro", frozen)]
#[derive(Debug, Clone)]
pub struct PySolution {
    /// The solution.
    pub inner: Arc<RadiositySolution>,
}

/// Encodes `s` as the bytes of `RadiositySolution::save` (JSON).
fn encode(s: &RadiositySolution) -> PyResult<Vec<u8>> {
    let mut bytes = Vec::new();
    s.save(&mut bytes).map_err(core_err)?;
    Ok(bytes)
}

#[pymethods]
impl PySolution {
    /// The solution as bytes (JSON, the format of `chiaro render
    /// --save-solution`), for `from_bytes`, a file or Ray's object store.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let inner = Arc::clone(&self.inner);
        let bytes = py.detach(move || encode(&inner))?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Reads bytes written by `to_bytes` (or a `--save-solution` file) and
    /// checks that the solution belongs to `scene`: raises `RenderError`
    /// when it was solved for another scene (different geometry, materials,
    /// lights or patch size) or the data is unreadable.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, scene: &PyScene, data: &[u8]) -> PyResult<Self> {
        let scene = &scene.inner;
        let s = py
            .detach(|| RadiositySolution::load(data, scene))
            .map_err(core_err)?;
        Ok(Self { inner: Arc::new(s) })
    }

    /// Raises `RenderError` unless the solution belongs to `scene` (same
    /// geometry, materials, lights and patch size; the camera may differ).
    fn check_scene(&self, scene: &PyScene) -> PyResult<()> {
        self.inner.check_scene(&scene.inner).map_err(core_err)
    }

    /// Unpickles: decodes the bytes without a scene. Rendering checks the
    /// solution against the scene it is rendered with.
    #[staticmethod]
    fn _from_state(py: Python<'_>, data: &[u8]) -> PyResult<Self> {
        let s: RadiositySolution = py
            .detach(|| serde_json::from_slice(data))
            .map_err(|e| RenderError::new_err(format!("cannot read radiosity solution: {e}")))?;
        Ok(Self { inner: Arc::new(s) })
    }

    /// Pickle support: `(RadiositySolution._from_state, (bytes,))`.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let ctor = slf.get_type().getattr("_from_state")?;
        let bytes = slf.get().to_bytes(py)?;
        PyTuple::new(py, [ctor.into_any(), PyTuple::new(py, [bytes])?.into_any()])
    }

    /// How it was computed: `solver`, `formfactor`, `patch_size` (scene
    /// units), `elements`, `iterations`, `unshot`, `nodes`, `leaves`,
    /// `links`, `seconds` (of the solve).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.inner.stats;
        let d = PyDict::new(py);
        d.set_item("solver", &s.solver)?;
        d.set_item("formfactor", &s.formfactor)?;
        d.set_item("patch_size", s.patch_size)?;
        d.set_item("elements", s.elements)?;
        d.set_item("iterations", s.iterations)?;
        d.set_item("unshot", s.unshot)?;
        d.set_item("nodes", s.nodes)?;
        d.set_item("leaves", s.leaves)?;
        d.set_item("links", s.links)?;
        d.set_item("seconds", s.seconds)?;
        Ok(d)
    }

    /// Display elements (triangles) of the solution's mesh.
    #[getter]
    fn element_count(&self) -> usize {
        self.inner.element_count()
    }

    fn __repr__(&self) -> String {
        format!(
            "<chiaro.RadiositySolution {} elements, {} solver>",
            self.inner.element_count(),
            self.inner.stats.solver
        )
    }
}

/// `chiaro._chiaro.solve_radiosity`: see `chiaro.solve_radiosity`
/// (python/chiaro/__init__.py). Solves with the scene's settings
/// overridden as `render` overrides them (only the `radiosity.*` keys
/// matter), with the GIL released and Ctrl-C / `progress` polled.
#[pyfunction]
#[pyo3(signature = (scene, overrides = None, progress = None, threads = None))]
pub fn solve_radiosity<'py>(
    py: Python<'py>,
    scene: &PyScene,
    overrides: Option<Vec<(String, Bound<'py, PyAny>)>>,
    progress: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<PySolution> {
    let overrides = overrides_json(overrides)?;
    let settings = resolve_settings(&scene.inner, None, None, None, None, None, &overrides)?;
    let inner = &scene.inner;
    let inner = run_polling(py, progress.map(Bound::unbind), threads, |p| {
        chiaro::radiosity_solution(&chiaro::RenderContext::new(inner, &settings, p)?)
    })?
    .map_err(to_pyerr)?;
    Ok(PySolution { inner })
}

#[cfg(test)]
mod tests {
    use chiaro::{
        Film, NoProgress, RenderContext, RenderSettings, RenderStats, Scene, Technique, Vec3,
    };
    use std::sync::Arc;

    fn solve(scene: &Scene, s: &RenderSettings) -> Arc<chiaro::RadiositySolution> {
        let ctx = RenderContext::new(scene, s, &NoProgress).expect("valid");
        chiaro::radiosity_solution(&ctx).expect("solve")
    }

    /// What `render(..., solution=)` does: the technique checked, the
    /// context given the solution, one render path.
    fn from_solution(
        scene: &Scene,
        s: &RenderSettings,
        sol: &Arc<chiaro::RadiositySolution>,
    ) -> chiaro::Result<(Film, RenderStats)> {
        chiaro::check_solution_technique(s.technique)?;
        let ctx = RenderContext::new(scene, s, &NoProgress)?.with_solution(Arc::clone(sol));
        chiaro::render_with(&ctx, chiaro::renderer(s.technique))
    }

    fn cornell() -> Scene {
        chiaro_testkit::scenes::cornell_box(24)
    }

    fn settings(scene: &Scene, technique: Technique) -> RenderSettings {
        let mut s = chiaro_testkit::scenes::settings(scene, technique, 24, 20, 4);
        s.radiosity.solver = chiaro::scene::RadiositySolver::Hierarchical;
        s
    }

    #[test]
    fn a_crop_window_equals_the_full_render_inside_and_is_black_outside() {
        let scene = cornell();
        let base = settings(&scene, Technique::Radiosity);
        let sol = solve(&scene, &base);
        for technique in [Technique::Radiosity, Technique::Hybrid] {
            let s = settings(&scene, technique);
            let (full, _) = from_solution(&scene, &s, &sol).expect("full");
            let cropped_s = RenderSettings {
                crop: Some([5, 3, 17, 14]),
                ..s.clone()
            };
            let (crop, _) = from_solution(&scene, &cropped_s, &sol).expect("crop");
            let mut lit = 0;
            for y in 0..s.height {
                for x in 0..s.width {
                    let i = full.index(x, y);
                    if (5..17).contains(&x) && (3..14).contains(&y) {
                        assert_eq!(crop.color[i], full.color[i], "{technique:?} ({x}, {y})");
                        assert_eq!(crop.depth[i].to_bits(), full.depth[i].to_bits());
                        lit += usize::from(full.color[i].max_element() > 0.0);
                    } else {
                        assert_eq!(crop.color[i], Vec3::ZERO);
                        assert!(crop.depth[i].is_infinite());
                    }
                }
            }
            assert!(
                lit > 50,
                "{technique:?}: the window is mostly lit ({lit} pixels)"
            );
        }
    }

    #[test]
    fn a_solution_of_another_scene_is_refused() {
        let scene = cornell();
        let s = settings(&scene, Technique::Radiosity);
        let sol = solve(&scene, &s);
        let mut other = scene.clone();
        other.objects.pop();
        for technique in [Technique::Radiosity, Technique::Hybrid] {
            let r = from_solution(&other, &settings(&other, technique), &sol);
            let msg = r.err().map(|e| e.to_string()).unwrap_or_default();
            assert!(
                msg.contains("does not match this scene"),
                "{technique:?}: {msg}"
            );
        }
        let r = from_solution(&scene, &settings(&scene, Technique::Phong), &sol);
        assert!(r.is_err(), "phong cannot render from a solution");
    }
}
