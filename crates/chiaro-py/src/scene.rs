//! `chiaro.Scene`: the Python face of [`chiaro::Scene`], loadable from files
//! and buildable in code (camera, materials, lights, meshes from numpy
//! arrays, objects), picklable (so Ray can ship it through its object store).

use crate::convert::{json_to_py, merge_props, py_to_json, toml_literal};
use crate::errors::core_err;
use chiaro::scene::{
    Camera, Geometry, Light, Material, MaterialId, Mesh, MeshId, Object, Projection, Scene,
    Severity, Transform,
};
use chiaro::{Vec2, Vec3};
use numpy::{AllowTypeChange, PyArrayLike2};
use pyo3::exceptions::{PyIndexError, PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use serde_json::{Value, json};

/// A scene: camera, meshes, materials, lights, objects and render settings.
///
/// Build one with `chiaro.Scene()` and its `add_*` methods, or read one with
/// `chiaro.load(path)`. Scenes pickle (as JSON), so they can be sent to other
/// processes.
#[pyclass(name = "Scene", module = "chiaro._chiaro", from_py_object)]
#[derive(Debug, Clone, Default)]
pub struct PyScene {
    /// The Rust scene.
    pub inner: Scene,
}

/// Reads an `(N, k)` array-like of floats into rows of `k` values.
fn rows_f32<const K: usize>(
    arr: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
    what: &str,
    expect_rows: Option<usize>,
) -> PyResult<Vec<[f32; K]>> {
    let Some(arr) = arr else {
        return Ok(Vec::new());
    };
    let view = arr.as_array();
    let shape = view.shape();
    if shape[1] != K {
        return Err(PyValueError::new_err(format!(
            "{what}: expected an array of shape (N, {K}), got {shape:?}"
        )));
    }
    if let Some(n) = expect_rows
        && shape[0] != n
    {
        return Err(PyValueError::new_err(format!(
            "{what}: expected {n} rows (one per vertex), got {}",
            shape[0]
        )));
    }
    let mut out = Vec::with_capacity(shape[0]);
    for row in view.rows() {
        let mut r = [0.0f32; K];
        for (dst, src) in r.iter_mut().zip(row.iter()) {
            if !src.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "{what}: contains a non-finite value"
                )));
            }
            *dst = *src;
        }
        out.push(r);
    }
    Ok(out)
}

/// Reads a Python value giving three floats (tuple, list, array) or one
/// float broadcast to three.
fn vec3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec3> {
    if let Ok(f) = obj.extract::<f32>() {
        return Ok(Vec3::splat(f));
    }
    let v: Vec<f32> = match py_to_json(obj)? {
        Value::Array(a) => a
            .iter()
            .filter_map(|x| x.as_f64().map(|f| f as f32))
            .collect(),
        _ => Vec::new(),
    };
    if v.len() != 3 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected three numbers"
        )));
    }
    Ok(Vec3::new(v[0], v[1], v[2]))
}

/// Keyword arguments as a JSON object (empty when absent).
fn kwargs_json(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Value> {
    match kwargs {
        Some(k) => py_to_json(k.as_any()),
        None => Ok(json!({})),
    }
}

/// Deserialises a merged JSON value into `T`, as a `ValueError` naming `what`.
fn from_json<T: serde::de::DeserializeOwned>(v: Value, what: &str) -> PyResult<T> {
    serde_json::from_value(v).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

/// The default properties of each light type, in the serde form of [`Light`].
fn light_defaults(kind: &str) -> Option<Value> {
    let white = json!([1.0, 1.0, 1.0]);
    Some(match kind {
        "ambient" => json!({"color": white, "intensity": 0.1}),
        "point" => json!({"position": [0.0, 0.0, 0.0], "color": white, "intensity": 1.0,
                          "attenuation": "inverse_square"}),
        "directional" => json!({"direction": [0.0, -1.0, 0.0], "color": white, "intensity": 1.0}),
        "spot" => json!({"position": [0.0, 0.0, 0.0], "direction": [0.0, -1.0, 0.0],
                         "color": white, "intensity": 1.0, "attenuation": "inverse_square",
                         "exponent": 1.0, "cone_degrees": 30.0, "cone_softness_degrees": 0.0,
                         "flaps": []}),
        "area" => json!({"shape": null, "color": white, "intensity": 1.0, "two_sided": false}),
        _ => return None,
    })
}

impl PyScene {
    /// Resolves a material given as an index or a name.
    fn material_id(&self, material: &Bound<'_, PyAny>) -> PyResult<MaterialId> {
        if let Ok(i) = material.extract::<u32>() {
            if (i as usize) < self.inner.materials.len() {
                return Ok(MaterialId(i));
            }
            return Err(PyIndexError::new_err(format!(
                "material {i} does not exist (the scene has {})",
                self.inner.materials.len()
            )));
        }
        let name: String = material.extract()?;
        self.inner.material_by_name(&name).ok_or_else(|| {
            let known: Vec<&str> = self
                .inner
                .materials
                .iter()
                .map(|m| m.name.as_str())
                .collect();
            PyKeyError::new_err(format!(
                "unknown material {name:?} (known: {})",
                known.join(", ")
            ))
        })
    }
}

#[pymethods]
impl PyScene {
    /// An empty scene with the default camera and render settings.
    #[new]
    fn new() -> Self {
        Self::default()
    }

    /// Sets the camera. `fov` is the vertical field of view in degrees of
    /// the pinhole (perspective) camera; `half_height` (scene units) makes
    /// it orthographic instead, with a film that high above and below
    /// `eye`; `near`/`far` are the scan converter's clip distances.
    #[pyo3(signature = (eye, look_at, up = None, fov = None, near = None, far = None, half_height = None))]
    #[allow(clippy::too_many_arguments)]
    fn set_camera(
        &mut self,
        eye: &Bound<'_, PyAny>,
        look_at: &Bound<'_, PyAny>,
        up: Option<&Bound<'_, PyAny>>,
        fov: Option<f32>,
        near: Option<f32>,
        far: Option<f32>,
        half_height: Option<f32>,
    ) -> PyResult<()> {
        if fov.is_some() && half_height.is_some() {
            return Err(PyValueError::new_err(
                "set_camera: give fov (perspective) or half_height (orthographic), not both",
            ));
        }
        let d = Camera::default();
        self.inner.camera = Camera {
            eye: vec3(eye, "eye")?,
            look_at: vec3(look_at, "look_at")?,
            up: up.map(|u| vec3(u, "up")).transpose()?.unwrap_or(d.up),
            fov_y_degrees: fov.unwrap_or(d.fov_y_degrees),
            near: near.unwrap_or(d.near),
            far: far.unwrap_or(d.far),
            projection: match half_height {
                Some(half_height) => Projection::Orthographic { half_height },
                None => Projection::Perspective,
            },
        };
        Ok(())
    }

    /// The camera as a dict (`eye`, `look_at`, `up`, `fov_y_degrees`, `near`,
    /// `far`, `projection`: `"perspective"` or
    /// `{"orthographic": {"half_height": h}}`).
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = camera_json(&self.inner.camera);
        json_to_py(py, &v)
    }

    /// Replaces the camera from a dict with the keys of the `camera` getter
    /// (missing keys keep their defaults).
    #[setter(camera)]
    fn set_camera_dict(&mut self, camera: &Bound<'_, PyAny>) -> PyResult<()> {
        let d = camera_json(&Camera::default());
        let merged =
            merge_props(&d, &py_to_json(camera)?, "camera").map_err(PyValueError::new_err)?;
        self.inner.camera = from_json(merged, "camera")?;
        Ok(())
    }

    /// Adds a material and returns its index. Properties are those of the
    /// scene format's `[material.NAME]` table under their Rust names:
    /// `ambient`, `diffuse`, `specular` (RGB or one number), `shininess`,
    /// `model` (`"phong"`, `"blinn"`, `"torrance-sparrow"`), `roughness`,
    /// `reflect`, `transmit`, `ior`, `absorption`, `fresnel`, `emission`,
    /// `sidedness` (`"two-sided"`, the default, `"one-sided"`, `"culled"`),
    /// `emission_two_sided`, ...
    #[pyo3(signature = (name, **props))]
    fn add_material(&mut self, name: &str, props: Option<&Bound<'_, PyDict>>) -> PyResult<u32> {
        let d = serde_json::to_value(Material::default()).unwrap_or(Value::Null);
        let mut merged = merge_props(&d, &kwargs_json(props)?, &format!("material {name:?}"))
            .map_err(PyValueError::new_err)?;
        merged["name"] = Value::String(name.to_owned());
        let m: Material = from_json(merged, &format!("material {name:?}"))?;
        Ok(self.inner.add_material(m).0)
    }

    /// Adds a light and returns its index. `kind` is `"ambient"`, `"point"`,
    /// `"directional"`, `"spot"` or `"area"`; properties are `color` (RGB or
    /// one number), `intensity`, and per kind `position`, `direction`,
    /// `attenuation` (`"none"`, `"inverse_square"` or
    /// `{"empirical": {"c1": .., "c2": .., "c3": ..}}`), `exponent`,
    /// `cone_degrees`, `cone_softness_degrees`, `flaps`, `two_sided`, and for
    /// area lights `shape`, e.g. `{"quad": {"corner": [..], "edge_u": [..],
    /// "edge_v": [..]}}`, `{"disk": {"center", "normal", "radius"}}`,
    /// `{"sphere": {"center", "radius"}}`.
    #[pyo3(signature = (kind, **props))]
    fn add_light(&mut self, kind: &str, props: Option<&Bound<'_, PyDict>>) -> PyResult<u32> {
        let d = light_defaults(kind).ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown light type {kind:?} (known: ambient, point, directional, spot, area)"
            ))
        })?;
        let merged = merge_props(&d, &kwargs_json(props)?, &format!("{kind} light"))
            .map_err(PyValueError::new_err)?;
        if kind == "area" && merged["shape"].is_null() {
            return Err(PyValueError::new_err(
                "area light: `shape` is required, e.g. shape={\"quad\": {\"corner\": [..], \"edge_u\": [..], \"edge_v\": [..]}}",
            ));
        }
        let light: Light = from_json(json!({ kind: merged }), &format!("{kind} light"))?;
        self.inner.lights.push(light);
        Ok(self.inner.lights.len() as u32 - 1)
    }

    /// Adds a triangle mesh from numpy arrays and returns its index:
    /// `positions` (N, 3) floats, `indices` (M, 3) integers in `0..N`
    /// (counter-clockwise seen from the front), optional `normals` (N, 3),
    /// `uvs` (N, 2) and linear-RGB vertex `colors` (N, 3).
    #[pyo3(signature = (positions, indices, normals = None, uvs = None, colors = None, name = ""))]
    fn add_mesh(
        &mut self,
        positions: PyArrayLike2<'_, f32, AllowTypeChange>,
        indices: PyArrayLike2<'_, i64, AllowTypeChange>,
        normals: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        uvs: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        colors: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        name: &str,
    ) -> PyResult<u32> {
        let p: Vec<[f32; 3]> = rows_f32(Some(positions), "positions", None)?;
        let n = p.len();
        let idx = indices.as_array();
        if idx.shape()[1] != 3 {
            return Err(PyValueError::new_err(format!(
                "indices: expected an array of shape (M, 3), got {:?}",
                idx.shape()
            )));
        }
        let mut tris = Vec::with_capacity(idx.shape()[0]);
        for (t, row) in idx.rows().into_iter().enumerate() {
            let mut tri = [0u32; 3];
            for (dst, &i) in tri.iter_mut().zip(row.iter()) {
                if i < 0 || i as usize >= n {
                    return Err(PyIndexError::new_err(format!(
                        "indices: triangle {t} refers to vertex {i}, but there are {n} vertices"
                    )));
                }
                *dst = i as u32;
            }
            tris.push(tri);
        }
        let mesh = Mesh {
            name: name.to_owned(),
            positions: p.into_iter().map(Vec3::from).collect(),
            normals: rows_f32::<3>(normals, "normals", Some(n))?
                .into_iter()
                .map(|v| Vec3::from(v).normalize_or_zero())
                .collect(),
            uvs: rows_f32::<2>(uvs, "uvs", Some(n))?
                .into_iter()
                .map(Vec2::from)
                .collect(),
            colors: rows_f32::<3>(colors, "colors", Some(n))?
                .into_iter()
                .map(Vec3::from)
                .collect(),
            indices: tris,
            ..Mesh::default()
        };
        Ok(self.inner.add_mesh(mesh).0)
    }

    /// Places geometry and returns the object's index: either `mesh` (an
    /// index from `add_mesh`) or `sphere` (a radius, an analytic sphere at
    /// the object origin). `material` is an index or a name. The transform
    /// is `scale`, then `rotate` (degrees about x, y, z), then `translate`,
    /// then the 4x4 `matrix` (row-major, as numpy writes it).
    #[pyo3(signature = (mesh = None, sphere = None, material = None, translate = None,
                        rotate = None, scale = None, matrix = None, smooth = true,
                        casts_shadows = true, name = ""))]
    fn add_object(
        &mut self,
        mesh: Option<u32>,
        sphere: Option<f32>,
        material: Option<&Bound<'_, PyAny>>,
        translate: Option<&Bound<'_, PyAny>>,
        rotate: Option<&Bound<'_, PyAny>>,
        scale: Option<&Bound<'_, PyAny>>,
        matrix: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        smooth: bool,
        casts_shadows: bool,
        name: &str,
    ) -> PyResult<u32> {
        let geometry = match (mesh, sphere) {
            (Some(m), None) => {
                if m as usize >= self.inner.meshes.len() {
                    return Err(PyIndexError::new_err(format!(
                        "mesh {m} does not exist (the scene has {})",
                        self.inner.meshes.len()
                    )));
                }
                Geometry::Mesh(MeshId(m))
            }
            (None, Some(r)) if r.is_finite() && r > 0.0 => Geometry::Sphere { radius: r },
            (None, Some(r)) => {
                return Err(PyValueError::new_err(format!(
                    "sphere radius must be positive, got {r}"
                )));
            }
            _ => {
                return Err(PyValueError::new_err(
                    "give exactly one of mesh=INDEX or sphere=RADIUS",
                ));
            }
        };
        let material = match material {
            Some(m) => self.material_id(m)?,
            None if !self.inner.materials.is_empty() => MaterialId(0),
            None => {
                return Err(PyValueError::new_err(
                    "the scene has no material yet: call add_material first",
                ));
            }
        };
        let mut transform = Transform::default();
        if let Some(t) = translate {
            transform.translate = vec3(t, "translate")?;
        }
        if let Some(r) = rotate {
            transform.rotate_degrees = vec3(r, "rotate")?;
        }
        if let Some(s) = scale {
            transform.scale = vec3(s, "scale")?;
        }
        if let Some(m) = matrix {
            let rows = rows_f32::<4>(Some(m), "matrix", Some(4))?;
            // numpy is row-major; glam's from_cols_array_2d takes columns.
            let mut cols = [[0.0f32; 4]; 4];
            for (r, row) in rows.iter().enumerate() {
                for (c, v) in row.iter().enumerate() {
                    cols[c][r] = *v;
                }
            }
            transform.matrix = chiaro_mat4(cols);
        }
        self.inner.objects.push(Object {
            name: name.to_owned(),
            geometry,
            material,
            transform,
            smooth,
            casts_shadows,
            ..Object::default()
        });
        Ok(self.inner.objects.len() as u32 - 1)
    }

    /// Sets a render setting by its dotted key (`"whitted.max_depth"`,
    /// `"technique"`, `"shadows"`), exactly as the CLI's `--set key=value`.
    fn set(&mut self, key: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let lit = toml_literal(&py_to_json(value)?);
        chiaro::settings::apply_override(&mut self.inner.render, key, &lit).map_err(core_err)
    }

    /// The scene's render settings as a nested dict.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = serde_json::to_value(&self.inner.render).unwrap_or(Value::Null);
        json_to_py(py, &v)
    }

    /// Background radiance (linear RGB) where no surface is hit.
    #[getter]
    fn background(&self) -> (f32, f32, f32) {
        let b = self.inner.background;
        (b.x, b.y, b.z)
    }

    /// Sets the background radiance (RGB or one number).
    #[setter]
    fn set_background(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.background = vec3(value, "background")?;
        Ok(())
    }

    /// Material names, in index order.
    #[getter]
    fn materials(&self) -> Vec<String> {
        self.inner
            .materials
            .iter()
            .map(|m| m.name.clone())
            .collect()
    }

    /// Number of meshes.
    #[getter]
    fn num_meshes(&self) -> usize {
        self.inner.meshes.len()
    }

    /// Number of placed objects.
    #[getter]
    fn num_objects(&self) -> usize {
        self.inner.objects.len()
    }

    /// Number of lights.
    #[getter]
    fn num_lights(&self) -> usize {
        self.inner.lights.len()
    }

    /// Triangles over all objects (analytic spheres count as zero).
    #[getter]
    fn triangle_count(&self) -> usize {
        self.inner.triangle_count()
    }

    /// Problems `render` would refuse (errors) or mention (warnings), as strings.
    fn validate(&self) -> Vec<String> {
        self.inner
            .validate()
            .iter()
            .map(ToString::to_string)
            .collect()
    }

    /// Whether the scene has no errors (warnings allowed).
    fn is_valid(&self) -> bool {
        !self
            .inner
            .validate()
            .iter()
            .any(|i| i.severity == Severity::Error)
    }

    /// An independent copy.
    fn copy(&self) -> Self {
        self.clone()
    }

    /// The whole scene as JSON (the serde form of the Rust `Scene`).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// A scene from [`to_json`]'s output.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let inner: Scene = serde_json::from_str(text)
            .map_err(|e| PyValueError::new_err(format!("scene JSON: {e}")))?;
        Ok(Self { inner })
    }

    fn __getstate__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes =
            serde_json::to_vec(&self.inner).map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(PyBytes::new(py, &bytes))
    }

    fn __setstate__(&mut self, state: &[u8]) -> PyResult<()> {
        self.inner = serde_json::from_slice(state)
            .map_err(|e| PyValueError::new_err(format!("scene state: {e}")))?;
        Ok(())
    }

    fn __repr__(&self) -> String {
        let r = &self.inner.render;
        format!(
            "<chiaro.Scene: {} objects, {} triangles, {} lights, {} materials; {} {}x{}>",
            self.inner.objects.len(),
            self.inner.triangle_count(),
            self.inner.lights.len(),
            self.inner.materials.len(),
            r.technique.name(),
            r.width,
            r.height
        )
    }
}

/// A matrix from four columns.
fn chiaro_mat4(cols: [[f32; 4]; 4]) -> chiaro_core::Mat4 {
    chiaro_core::Mat4::from_cols_array_2d(&cols)
}

/// `camera` as JSON with its `projection` always present (serde leaves
/// out the perspective default), so the dict lists every key.
fn camera_json(camera: &Camera) -> Value {
    let mut v = serde_json::to_value(camera).unwrap_or(Value::Null);
    if let Value::Object(map) = &mut v {
        map.entry("projection")
            .or_insert_with(|| Value::String("perspective".into()));
    }
    v
}
