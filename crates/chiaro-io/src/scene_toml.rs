//! The `.toml` scene format (README.md, "The scene format"): parsing, checking, and
//! building a [`Scene`].
//!
//! Every field has a default; lengths are scene units, angles degrees,
//! colours linear RGB. Unknown keys are errors, and every error names the
//! file, the 1-based line and column of the offending value, and what was
//! expected: `box.toml:14:12: unknown material "glas" (known: glass, matte)`.
//! NaN and infinite numbers are refused wherever they appear. Relative paths
//! (meshes, textures) resolve against the scene file's directory.
//!
//! # Tables
//!
//! | table | keys |
//! | --- | --- |
//! | `[render]` | `technique` (`preview`, `flat`, `gouraud`, `phong`, `whitted`, `radiosity`, `hybrid`, `path`), `width`, `height` (1..=16384, at most 64 Mpixel), `samples`, `seed`, `shadows` (`none`, `map`, `volume`, `ray`, `object`, `scanline`), `transparency`, `aa` (`supersample`, `adaptive`, `post`), `filter` (`box`, `tent`: the reconstruction of the scan converter's supersamples), `light_samples`, `tonemap` (`clamp`, `reinhard`, `filmic`), `exposure`, `cull_backfaces`, `memory_limit` (`"8G"`, `"512M"` or bytes: the memory this scene may use; by default half the machine's); sub-tables `shadow_map` {`resolution`, `bias`, `slope_bias`, `pcf_radius`}, `whitted` {`max_depth`, `min_weight`, `adaptive_threshold`, `adaptive_max_depth`}, `path` {`max_depth`, `rr_depth`}, `radiosity` {`solver` (`jacobi`, `gauss-seidel`, `progressive`, `hierarchical`), `formfactor` (`hemicube`, `raycast`, `analytic`), `patch_size`, `hemicube_resolution`, `tolerance`, `max_iterations`}, `depth_cue` {`color`, `near`, `far`, `max_scale`, `min_scale`} |
//! | `[camera]` | `eye`, `look_at`, `up`, `fov` (vertical, 0..180), `near`, `far` |
//! | `[cameras.NAME]` | further cameras with the keys of `[camera]`, chosen with `chiaro render --camera NAME` |
//! | `[[light]]` | `type` = `ambient` {`color`, `intensity`}; `point` {+ `position`, `attenuation`}; `directional` {`direction`, the way the light travels}; `spot` {`position`, `direction` or `look_at`, `attenuation`, `exponent` (Warn's n, default 1), `cone` (half-angle, default 90), `cone_softness`, `flaps` = [{`axis`, `min`, `max`}]}; `area` {`shape` = `quad` {`corner`, `edge_u`, `edge_v`} / `disk` {`center`, `normal`, `radius`} / `sphere` {`center`, `radius`}, `two_sided`} |
//! | `[material.NAME]` | `ambient` (ka, relative to kd), `diffuse`, `specular`, `shininess`, `model` (`phong`, `blinn`, `torrance-sparrow`), `roughness`, `distribution` (`ggx`, `beckmann`), `reflect`, `transmit`, `ior`, `absorption`, `fresnel`, `transparency` (`interpolated`, `screen-door`, `filtered`), `texture`, `bump`, `normal_map`, `emission`, `emission_texture`, `two_sided`, `cull_backface` (invisible from behind to the eye in every technique, as glTF `doubleSided: false`) |
//! | `[[object]]` | `name`, `mesh` (`.obj`, `.gltf`, `.glb`) or `primitive`, `material`, `transform`, `smooth`, `crease_angle`, `shade` (`flat`, `gouraud`, `phong`), `casts_shadows` |
//! | `[environment]` | `texture` (lat-long image), `intensity`, `rotate_y` (degrees, right-handed about +y like an object's), `background` (camera rays see it; reflections and lighting use it either way) |
//! | top level | `background` (colour where nothing is hit) |
//!
//! Colours and most RGB coefficients take a scalar or three numbers
//! (`ambient = 0.1` or `ambient = [0.1, 0.1, 0.12]`).
//! `attenuation` is `"none"`, `"inverse_square"` (the default, physical) or
//! `{ c1, c2, c3 }` for `min(1 / (c1 + c2 d + c3 d^2), 1)`.
//!
//! Primitives and their parameters: `sphere` {`radius` = 1} (analytic);
//! `plane` {`size` = 2 (side), `subdivisions` = 1} in the xz plane facing
//! +y; `quad` {`corner`, `edge_u`, `edge_v`}; `disk` {`radius` = 1,
//! `segments` = 64} facing +y; `box` {`size` = 2, scalar or `[x, y, z]`}
//! centred on the origin; `cylinder` {`radius` = 1, `height` = 2, `segments`
//! = 64} standing on y = 0; `teapot` {`subdivisions` = 8} on y = 0, 1 unit
//! tall.
//!
//! `transform = { translate, rotate_x, rotate_y, rotate_z, scale, matrix }`:
//! scale (scalar or per axis), then rotations about x, y, z in that order
//! (or `rotate = [x, y, z]`), then translation, then an optional 4x4
//! `matrix` (16 numbers, column-major as in glTF).
//!
//! Textures: `texture = "wood.png"` (decoded as sRGB), or
//! `{ image = "wood.png", wrap = "repeat" | "clamp" | "mirror" }` (both
//! axes; `wrap_t` sets v apart), or
//! `{ procedural = "checker" | "wood" | "marble" | "noise" | "dimples",
//! scale = 1, color_a = ..., color_b = ..., use_uv = false }`. Bump maps use
//! the same forms plus `height` (scene units of a texture value of 1,
//! default 0.02); normal maps are decoded as linear data.
//!
//! A mesh file adds all its meshes and materials; `material = "name"`
//! replaces the file's materials. The object's `transform` places the whole
//! file; a glTF file's node hierarchy and lights come along.
//!
//! # Example
//!
//! ```
//! let text = r#"
//! [render]
//! technique = "whitted"
//! width = 64
//! height = 48
//!
//! [camera]
//! eye = [0, 1, 5]
//! look_at = [0, 0.5, 0]
//! fov = 40
//!
//! [[light]]
//! type = "point"
//! position = [2, 4, 3]
//! intensity = 20
//!
//! [[light]]
//! type = "ambient"
//! intensity = 0.1
//!
//! [material.red]
//! diffuse = [0.7, 0.1, 0.1]
//! specular = 0.3
//! shininess = 40
//!
//! [material.floor]
//! diffuse = 0.8
//! texture = { procedural = "checker", scale = 2, color_a = 0.2, color_b = 0.9 }
//!
//! [[object]]
//! primitive = "sphere"
//! radius = 0.5
//! material = "red"
//! transform = { translate = [0, 0.5, 0] }
//!
//! [[object]]
//! primitive = "plane"
//! size = 10
//! material = "floor"
//! "#;
//! let loaded = chiaro_io::load_scene_str(text, std::path::Path::new("."), "demo.toml")?;
//! assert_eq!(loaded.scene.objects.len(), 2);
//! assert_eq!(loaded.scene.render.width, 64);
//! assert_eq!(loaded.scene.lights.len(), 2);
//! # Ok::<(), chiaro_io::IoError>(())
//! ```
//!
//! Errors point at the value:
//!
//! ```
//! let text = "[material.matte]\ndiffuse = 0.5\n\n[[object]]\nprimitive = \"sphere\"\nmaterial = \"glas\"\n";
//! let err = chiaro_io::load_scene_str(text, std::path::Path::new("."), "box.toml").unwrap_err();
//! assert_eq!(
//!     err.to_string(),
//!     r#"box.toml:6:12: unknown material "glas" (known: matte)"#
//! );
//! ```

mod raw;

use crate::{IoError, Loaded, Result};
use chiaro_core::Vec3;
use chiaro_core::budget::MemoryBudget;
use chiaro_core::geometry::primitives;
use chiaro_core::geometry::primitives::MeshSize;
use chiaro_core::glam::Mat4;
use chiaro_core::scene::{
    AreaShape, Attenuation, Bump, Camera, DepthCue, Environment, Flap, FormFactorMethod, Geometry,
    Light, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, MAX_SAMPLES, Material, MaterialId, Mesh, NamedCamera,
    Object, Procedural, ProceduralKind, RadiositySettings, RadiositySolver, RenderSettings, Scene,
    Severity, ShadowMapSettings, SpotLight, Texture, TextureId, Transform, WrapMode,
};
use raw::{
    AttenuationSpec, Opt, RawCamera, RawLight, RawMaterial, RawObject, RawRender, RawScene,
    RawTransform, Sp, Splat3, TextureSpec,
};
use serde::Deserialize;
use std::cell::Cell;
use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Largest accepted tessellation parameter (`segments`, `stacks`).
const MAX_SEGMENTS: u32 = 1 << 16;
/// Largest accepted `subdivisions` of a plane (a 4096^2-quad grid).
const MAX_PLANE_SUBDIVISIONS: u32 = 4096;
/// Largest accepted `subdivisions` of the teapot (per patch side).
const MAX_TEAPOT_SUBDIVISIONS: u32 = 128;

/// Parses the scene `text` (the contents of `path`, used in messages),
/// resolving relative paths against `base`. Returns the validated scene and
/// its warnings, or the first error, always as [`IoError::At`].
pub fn parse_scene(text: &str, base: &Path, path: &Path) -> Result<Loaded> {
    let mut ctx = Ctx {
        text,
        path,
        base,
        warnings: Vec::new(),
        images: HashMap::new(),
        primitive_meshes: HashMap::new(),
        mesh_files: HashMap::new(),
        spans: SpanIndex::default(),
        budget: MemoryBudget::process(),
        load_bytes: Cell::new(0),
    };
    // Parse once with spans, refuse NaN/Inf anywhere, then deserialize.
    let root = toml::de::DeTable::parse(text).map_err(|e| ctx.toml_err(&e))?;
    check_numbers(&ctx, root.get_ref())?;
    let raw =
        RawScene::deserialize(toml::de::Deserializer::from(root)).map_err(|e| ctx.toml_err(&e))?;
    let scene = ctx.build(raw)?;
    ctx.finish(scene)
}

/// Converts a byte offset into a 1-based line and column (in characters).
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().unwrap_or("").chars().count() + 1;
    (line, col)
}

/// Refuses NaN, infinities and floats outside the `f32` range, at their position.
fn check_numbers(ctx: &Ctx, table: &toml::de::DeTable) -> Result<()> {
    for v in table.values() {
        check_value(ctx, v)?;
    }
    Ok(())
}

fn check_value(ctx: &Ctx, v: &toml::Spanned<toml::de::DeValue>) -> Result<()> {
    use toml::de::DeValue;
    match v.get_ref() {
        DeValue::Float(f) => {
            let s = f.as_str().replace('_', "");
            let lower = s.to_ascii_lowercase();
            if lower.contains("nan") || lower.contains("inf") {
                return Err(ctx.at(v.span(), format!("expected a finite number, got {s}")));
            }
            if let Ok(x) = s.parse::<f64>()
                && x.abs() > f64::from(f32::MAX)
            {
                return Err(ctx.at(
                    v.span(),
                    format!("number {s} is too large (the limit is about 3.4e38)"),
                ));
            }
            Ok(())
        }
        DeValue::Array(a) => a.iter().try_for_each(|e| check_value(ctx, e)),
        DeValue::Table(t) => check_numbers(ctx, t),
        _ => Ok(()),
    }
}

/// Spans recorded while building, to place `Scene::validate` issues.
#[derive(Default)]
struct SpanIndex {
    materials: Vec<Range<usize>>,
    objects: Vec<Range<usize>>,
    lights: Vec<Range<usize>>,
    meshes: Vec<Range<usize>>,
    camera: Option<Range<usize>>,
}

struct Ctx<'a> {
    text: &'a str,
    path: &'a Path,
    base: &'a Path,
    warnings: Vec<String>,
    /// Decoded image files: (resolved path, sRGB) -> texture.
    images: HashMap<(PathBuf, bool, WrapMode, Option<WrapMode>), TextureId>,
    /// Tessellated primitives by their parameters: objects with the same
    /// primitive share one object-space mesh (instances, which the
    /// two-level BVH builds once).
    primitive_meshes: HashMap<String, chiaro_core::scene::MeshId>,
    /// Mesh files already read, by resolved path and material override:
    /// later objects naming the same file place it again over the same
    /// meshes and materials (instances) instead of reading it again.
    mesh_files: MeshFiles,
    spans: SpanIndex,
    /// The scene's memory budget (`render.memory_limit` or the process's).
    budget: MemoryBudget,
    /// Bytes the primitives' meshes and their prepared copies take so far.
    load_bytes: Cell<u64>,
}

/// See [`Ctx::mesh_files`].
type MeshFiles =
    HashMap<(PathBuf, Option<MaterialId>), (std::rc::Rc<crate::Imported>, crate::SharedImport)>;

/// A field name and the span of its value, for "does not apply" checks.
type Present<'r> = Vec<(&'static str, Option<Range<usize>>)>;

fn span_of<T>(v: &Opt<T>) -> Option<Range<usize>> {
    v.as_ref().map(Sp::span)
}

/// The key whose value starts at byte `at` of `text` (`width` in
/// `width = "256"` or `{ c1 = "x" }`), for messages about the value.
fn key_before(text: &str, at: usize) -> Option<&str> {
    let before = text.get(..at)?;
    let start = before.rfind(['\n', '{', ',']).map_or(0, |i| i + 1);
    let (key, value) = before[start..].rsplit_once('=')?;
    if !value.trim().is_empty() {
        return None;
    }
    let key = key.trim().trim_matches(['"', '\'']);
    let key = key.rsplit('.').next().unwrap_or(key).trim();
    (!key.is_empty()).then_some(key)
}

impl Ctx<'_> {
    fn at(&self, span: Range<usize>, message: impl Into<String>) -> IoError {
        let (line, column) = line_col(self.text, span.start);
        IoError::At {
            path: self.path.to_path_buf(),
            line,
            column,
            message: message.into(),
        }
    }

    fn toml_err(&self, e: &toml::de::Error) -> IoError {
        let span = e.span().unwrap_or(0..0);
        let key = key_before(self.text, span.start);
        self.at(span, crate::plain::plain_serde_message(e.message(), key))
    }

    /// Rejects the first present field that is not in `allowed`.
    fn only(&self, what: &str, present: &Present, allowed: &[&str]) -> Result<()> {
        for (name, span) in present {
            if let Some(span) = span
                && !allowed.contains(name)
            {
                return Err(self.at(
                    span.clone(),
                    format!(
                        "`{name}` does not apply to {what} (it takes: {})",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    fn finite_positive(&self, v: &Sp<f32>, what: &str) -> Result<f32> {
        let x = *v.get_ref();
        if x > 0.0 && x.is_finite() {
            Ok(x)
        } else {
            Err(self.at(v.span(), format!("{what}: expected a number > 0, got {x}")))
        }
    }

    fn non_negative(&self, v: &Sp<f32>, what: &str) -> Result<f32> {
        let x = *v.get_ref();
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(self.at(v.span(), format!("{what}: expected a number >= 0, got {x}")))
        }
    }

    fn non_negative3(&self, v: &Sp<Splat3>, what: &str) -> Result<Vec3> {
        let x = v.get_ref().vec3();
        if x.min_element() >= 0.0 {
            Ok(x)
        } else {
            Err(self.at(v.span(), format!("{what}: expected values >= 0, got {x}")))
        }
    }

    fn in_range_u32(&self, v: &Sp<u32>, what: &str, lo: u32, hi: u32) -> Result<u32> {
        let x = *v.get_ref();
        if (lo..=hi).contains(&x) {
            Ok(x)
        } else {
            Err(self.at(v.span(), format!("{what}: expected {lo}..={hi}, got {x}")))
        }
    }

    fn build(&mut self, raw: RawScene) -> Result<Scene> {
        let mut scene = Scene {
            render: self.render(raw.render)?,
            ..Scene::default()
        };
        self.budget = scene.render.memory_budget();
        if let Some(cam) = raw.camera {
            self.spans.camera = Some(cam.span());
            scene.camera = self.camera(cam)?;
        }
        // Named cameras in file order (the map is sorted by name).
        let mut cameras: Vec<_> = raw.cameras.into_iter().collect();
        cameras.sort_by_key(|(k, _)| k.span().start);
        for (name, cam) in cameras {
            scene.cameras.push(NamedCamera {
                name: name.into_inner(),
                camera: self.camera(cam)?,
            });
        }
        if let Some(bg) = &raw.background {
            scene.background = self.non_negative3(bg, "background")?;
        }

        // Materials in file order (the map is sorted by name).
        let mut materials: Vec<_> = raw.material.into_iter().collect();
        materials.sort_by_key(|(k, _)| k.span().start);
        let mut names: HashMap<String, MaterialId> = HashMap::new();
        let mut known: Vec<String> = Vec::new();
        for (name, m) in &materials {
            let span = m.span();
            let mat = self.material(&mut scene, name.get_ref(), m.get_ref())?;
            let id = scene.add_material(mat);
            self.spans.materials.push(span);
            names.insert(name.get_ref().clone(), id);
            known.push(name.get_ref().clone());
        }

        for l in &raw.light {
            let light = self.light(l.get_ref())?;
            scene.lights.push(light);
            self.spans.lights.push(l.span());
        }

        let mut default_material = None;
        for o in &raw.object {
            self.object(&mut scene, o, &names, &known, &mut default_material)?;
        }

        if let Some(env) = &raw.environment {
            let e = env.get_ref();
            let file = e.texture.get_ref();
            let ext = Path::new(file)
                .extension()
                .and_then(|x| x.to_str())
                .map(str::to_ascii_lowercase)
                .unwrap_or_default();
            let srgb = !matches!(ext.as_str(), "hdr" | "exr");
            let texture = self.image(&mut scene, &e.texture, srgb, WrapMode::Repeat, None)?;
            let intensity = e.intensity.unwrap_or(1.0);
            if intensity < 0.0 {
                return Err(self.at(env.span(), "environment intensity must be >= 0"));
            }
            scene.environment = Some(Environment {
                texture,
                intensity,
                rotate_y_degrees: e.rotate_y.unwrap_or(0.0),
                as_background: e.background.unwrap_or(true),
            });
        }
        Ok(scene)
    }

    fn render(&self, raw: Option<RawRender>) -> Result<RenderSettings> {
        let mut r = RenderSettings::default();
        let Some(raw) = raw else { return Ok(r) };
        r.memory_limit = raw.memory_limit;
        if let Some(t) = raw.technique {
            r.technique = t;
        }
        if let Some(w) = &raw.width {
            r.width = self.in_range_u32(w, "render.width", 1, MAX_IMAGE_SIDE)?;
        }
        if let Some(h) = &raw.height {
            r.height = self.in_range_u32(h, "render.height", 1, MAX_IMAGE_SIDE)?;
        }
        if u64::from(r.width) * u64::from(r.height) > MAX_IMAGE_PIXELS {
            let span = span_of(&raw.height).or(span_of(&raw.width)).unwrap_or(0..0);
            return Err(self.at(
                span,
                format!(
                    "image {}x{} has more than {MAX_IMAGE_PIXELS} pixels",
                    r.width, r.height
                ),
            ));
        }
        if let Some(s) = &raw.samples {
            r.samples = self.in_range_u32(s, "render.samples", 1, MAX_SAMPLES)?;
        }
        if let Some(s) = &raw.light_samples {
            r.light_samples = self.in_range_u32(s, "render.light_samples", 1, MAX_SAMPLES)?;
        }
        if let Some(s) = raw.seed {
            r.seed = s;
        }
        if let Some(s) = raw.shadows {
            r.shadows = s;
        }
        r.transparency = raw.transparency;
        if let Some(a) = raw.aa {
            r.aa = a;
        }
        if let Some(f) = raw.filter {
            r.filter = f;
        }
        if let Some(t) = raw.tonemap {
            r.tonemap = t;
        }
        if let Some(e) = raw.exposure {
            r.exposure = e;
        }
        if let Some(c) = raw.cull_backfaces {
            r.cull_backfaces = c;
        }
        if let Some(dc) = raw.depth_cue {
            let d = DepthCue::default();
            let cue = DepthCue {
                color: dc.color.map_or(d.color, Splat3::vec3),
                near: dc.near.unwrap_or(d.near),
                far: dc.far.as_ref().map_or(d.far, |f| *f.get_ref()),
                max_scale: dc.max_scale.unwrap_or(d.max_scale),
                min_scale: dc.min_scale.unwrap_or(d.min_scale),
            };
            if cue.far <= cue.near {
                return Err(self.at(
                    span_of(&dc.far).unwrap_or(0..0),
                    format!(
                        "render.depth_cue: expected far > near, got near {} far {}",
                        cue.near, cue.far
                    ),
                ));
            }
            r.depth_cue = Some(cue);
        }
        if let Some(sm) = raw.shadow_map {
            let d = ShadowMapSettings::default();
            r.shadow_map = ShadowMapSettings {
                resolution: match &sm.resolution {
                    Some(v) => {
                        self.in_range_u32(v, "render.shadow_map.resolution", 1, MAX_IMAGE_SIDE)?
                    }
                    None => d.resolution,
                },
                bias: sm.bias.unwrap_or(d.bias),
                slope_bias: sm.slope_bias.unwrap_or(d.slope_bias),
                pcf_radius: sm.pcf_radius.unwrap_or(d.pcf_radius),
            };
        }
        if let Some(w) = raw.whitted {
            r.whitted = w;
        }
        if let Some(p) = raw.path {
            r.path = p;
        }
        if let Some(rad) = raw.radiosity {
            let d = RadiositySettings::default();
            // A name from `names` (the valid ones, for the message), parsed by `parse`.
            let pick = |v: &Opt<String>, what: &str, names: &[&str]| match v {
                None => Ok(None),
                Some(s) if names.contains(&s.get_ref().as_str()) => Ok(Some(s.get_ref().clone())),
                Some(s) => Err(self.at(
                    s.span(),
                    format!(
                        "{what}: unknown {:?}, expected one of: {}",
                        s.get_ref(),
                        names.join(", ")
                    ),
                )),
            };
            let solvers = RadiositySolver::ALL.map(RadiositySolver::name);
            let methods = FormFactorMethod::ALL.map(FormFactorMethod::name);
            r.radiosity = RadiositySettings {
                solver: pick(&rad.solver, "render.radiosity.solver", &solvers)?
                    .and_then(|n| RadiositySolver::from_name(&n))
                    .unwrap_or(d.solver),
                formfactor: pick(&rad.formfactor, "render.radiosity.formfactor", &methods)?
                    .and_then(|n| FormFactorMethod::from_name(&n))
                    .unwrap_or(d.formfactor),
                patch_size: match &rad.patch_size {
                    Some(v) => self.non_negative(v, "render.radiosity.patch_size")?,
                    None => d.patch_size,
                },
                hemicube_resolution: match &rad.hemicube_resolution {
                    Some(v) => self.in_range_u32(
                        v,
                        "render.radiosity.hemicube_resolution",
                        1,
                        MAX_IMAGE_SIDE,
                    )?,
                    None => d.hemicube_resolution,
                },
                tolerance: match &rad.tolerance {
                    Some(v) => self.finite_positive(v, "render.radiosity.tolerance")?,
                    None => d.tolerance,
                },
                max_iterations: rad.max_iterations.unwrap_or(d.max_iterations),
            };
        }
        Ok(r)
    }

    fn camera(&self, raw: Sp<RawCamera>) -> Result<Camera> {
        let span = raw.span();
        let c = raw.into_inner();
        let d = Camera::default();
        let v3 =
            |v: &Opt<[f32; 3]>, def: Vec3| v.as_ref().map_or(def, |v| Vec3::from(*v.get_ref()));
        let cam = Camera {
            eye: v3(&c.eye, d.eye),
            look_at: v3(&c.look_at, d.look_at),
            up: v3(&c.up, d.up),
            fov_y_degrees: c.fov.as_ref().map_or(d.fov_y_degrees, |f| *f.get_ref()),
            near: match &c.near {
                Some(n) => self.finite_positive(n, "camera.near")?,
                None => d.near,
            },
            far: c.far.as_ref().map_or(d.far, |f| *f.get_ref()),
        };
        if let Some(f) = &c.fov
            && !(cam.fov_y_degrees > 0.0 && cam.fov_y_degrees < 180.0)
        {
            return Err(self.at(
                f.span(),
                format!(
                    "camera.fov: expected 0 < fov < 180 degrees, got {}",
                    cam.fov_y_degrees
                ),
            ));
        }
        if cam.far <= cam.near {
            return Err(self.at(
                span_of(&c.far).unwrap_or(span),
                format!(
                    "camera: expected far > near, got near {} far {}",
                    cam.near, cam.far
                ),
            ));
        }
        if cam.eye == cam.look_at {
            return Err(self.at(
                span_of(&c.look_at).unwrap_or(span),
                "camera: eye and look_at are the same point",
            ));
        }
        if cam.up.cross(cam.look_at - cam.eye).length_squared() == 0.0 {
            return Err(self.at(
                span_of(&c.up).unwrap_or(span),
                "camera: `up` is zero or parallel to the viewing direction",
            ));
        }
        Ok(cam)
    }

    fn material(&mut self, scene: &mut Scene, name: &str, m: &RawMaterial) -> Result<Material> {
        let d = Material::default();
        let rgb = |ctx: &Self, v: &Opt<Splat3>, what: &str, def: Vec3| -> Result<Vec3> {
            match v {
                Some(v) => ctx.non_negative3(v, &format!("material.{name}.{what}")),
                None => Ok(def),
            }
        };
        let mut mat = Material {
            name: name.to_string(),
            ambient: rgb(self, &m.ambient, "ambient", d.ambient)?,
            diffuse: rgb(self, &m.diffuse, "diffuse", d.diffuse)?,
            specular: rgb(self, &m.specular, "specular", d.specular)?,
            shininess: match &m.shininess {
                Some(v) => self.non_negative(v, &format!("material.{name}.shininess"))?,
                None => d.shininess,
            },
            model: m.model.unwrap_or(d.model),
            roughness: d.roughness,
            distribution: m.distribution.unwrap_or(d.distribution),
            reflect: rgb(self, &m.reflect, "reflect", d.reflect)?,
            transmit: rgb(self, &m.transmit, "transmit", d.transmit)?,
            ior: match &m.ior {
                Some(v) => self.finite_positive(v, &format!("material.{name}.ior"))?,
                None => d.ior,
            },
            absorption: rgb(self, &m.absorption, "absorption", d.absorption)?,
            fresnel: m.fresnel.unwrap_or(d.fresnel),
            transparency: m.transparency.unwrap_or(d.transparency),
            emission: rgb(self, &m.emission, "emission", d.emission)?,
            two_sided: m.two_sided.unwrap_or(d.two_sided),
            cull_backface: m.cull_backface.unwrap_or(d.cull_backface),
            ..d
        };
        if let Some(r) = &m.roughness {
            let x = *r.get_ref();
            if !(x > 0.0 && x <= 1.0) {
                return Err(self.at(
                    r.span(),
                    format!("material.{name}.roughness: expected 0 < roughness <= 1, got {x}"),
                ));
            }
            mat.roughness = x;
        }
        if let Some(t) = &m.texture {
            mat.texture = Some(self.texture(scene, t, true, false)?.0);
        }
        if let Some(t) = &m.emission_texture {
            mat.emission_texture = Some(self.texture(scene, t, true, false)?.0);
        }
        if let Some(t) = &m.normal_map {
            mat.normal_map = Some(self.texture(scene, t, false, false)?.0);
        }
        if let Some(t) = &m.bump {
            let (texture, height) = self.texture(scene, t, false, true)?;
            mat.bump = Some(Bump {
                texture,
                height: height.unwrap_or(0.02),
            });
        }
        Ok(mat)
    }

    /// Builds a texture from its spec; returns its id and the bump `height`
    /// when given (only accepted when `allow_height`).
    fn texture(
        &mut self,
        scene: &mut Scene,
        spec: &Sp<TextureSpec>,
        srgb: bool,
        allow_height: bool,
    ) -> Result<(TextureId, Option<f32>)> {
        let span = spec.span();
        match spec.get_ref() {
            TextureSpec::Path(p) => {
                let id = self.image(
                    scene,
                    &Sp::new(span, p.clone()),
                    srgb,
                    WrapMode::Repeat,
                    None,
                )?;
                Ok((id, None))
            }
            TextureSpec::Table(t) => {
                if t.height.is_some() && !allow_height {
                    return Err(self.at(span, "`height` applies only to `bump` textures"));
                }
                if let Some(h) = t.height
                    && !h.is_finite()
                {
                    return Err(self.at(span, "bump height must be a finite number"));
                }
                match (&t.procedural, &t.image) {
                    (Some(_), Some(_)) | (None, None) => Err(self.at(
                        span,
                        "a texture table needs exactly one of `procedural` or `image`",
                    )),
                    (None, Some(path)) => {
                        if t.scale.is_some()
                            || t.color_a.is_some()
                            || t.color_b.is_some()
                            || t.use_uv.is_some()
                        {
                            return Err(self.at(
                                span,
                                "`scale`, `color_a`, `color_b` and `use_uv` apply only to procedural textures",
                            ));
                        }
                        let id = self.image(
                            scene,
                            &Sp::new(span, path.clone()),
                            srgb,
                            t.wrap.unwrap_or_default(),
                            t.wrap_t,
                        )?;
                        Ok((id, t.height))
                    }
                    (Some(kind), None) => {
                        if t.wrap.is_some() || t.wrap_t.is_some() {
                            return Err(
                                self.at(span, "`wrap` and `wrap_t` apply only to image textures")
                            );
                        }
                        let scale = t.scale.unwrap_or(1.0);
                        if scale <= 0.0 {
                            return Err(self.at(
                                span,
                                format!("texture scale: expected a number > 0, got {scale}"),
                            ));
                        }
                        let (a, b) = default_colors(*kind);
                        let color_a = t.color_a.map_or(a, Splat3::vec3);
                        let color_b = t.color_b.map_or(b, Splat3::vec3);
                        if color_a.min_element() < 0.0 || color_b.min_element() < 0.0 {
                            return Err(self.at(span, "texture colours must be >= 0"));
                        }
                        let id = scene.add_texture(Texture::Procedural(Procedural {
                            kind: *kind,
                            scale,
                            color_a,
                            color_b,
                            use_uv: t.use_uv.unwrap_or(false),
                        }));
                        Ok((id, t.height))
                    }
                }
            }
        }
    }

    /// Loads (once) the image file named by `rel`, relative to the scene file.
    fn image(
        &mut self,
        scene: &mut Scene,
        rel: &Sp<String>,
        srgb: bool,
        wrap: WrapMode,
        wrap_t: Option<WrapMode>,
    ) -> Result<TextureId> {
        let path = crate::resolve(self.base, rel.get_ref());
        let key = (path.clone(), srgb, wrap, wrap_t);
        if let Some(id) = self.images.get(&key) {
            return Ok(*id);
        }
        if !path.is_file() {
            return Err(self.at(
                rel.span(),
                format!(
                    "texture file {:?} not found (looked for {})",
                    rel.get_ref(),
                    path.display()
                ),
            ));
        }
        let mut img = crate::images::load_texture_within(&path, srgb, self.budget)
            .map_err(|e| self.at(rel.span(), format!("cannot load texture: {e}")))?;
        img.wrap = wrap;
        img.wrap_t = wrap_t;
        let id = scene.add_texture(Texture::Image(img));
        self.images.insert(key, id);
        Ok(id)
    }

    fn light(&self, l: &RawLight) -> Result<Light> {
        let present: Present = vec![
            ("color", span_of(&l.color)),
            ("intensity", span_of(&l.intensity)),
            ("position", span_of(&l.position)),
            ("direction", span_of(&l.direction)),
            ("look_at", span_of(&l.look_at)),
            ("attenuation", span_of(&l.attenuation)),
            ("exponent", span_of(&l.exponent)),
            ("cone", span_of(&l.cone)),
            ("cone_softness", span_of(&l.cone_softness)),
            ("flaps", span_of(&l.flaps)),
            ("shape", span_of(&l.shape)),
            ("corner", span_of(&l.corner)),
            ("edge_u", span_of(&l.edge_u)),
            ("edge_v", span_of(&l.edge_v)),
            ("center", span_of(&l.center)),
            ("normal", span_of(&l.normal)),
            ("radius", span_of(&l.radius)),
            ("two_sided", span_of(&l.two_sided)),
        ];
        let kind = l.kind.get_ref().as_str();
        let tspan = l.kind.span();
        let color = match &l.color {
            Some(c) => self.non_negative3(c, "light color")?,
            None => Vec3::ONE,
        };
        let intensity = match &l.intensity {
            Some(i) => self.non_negative(i, "light intensity")?,
            None => 1.0,
        };
        let need = |v: &Opt<[f32; 3]>, what: &str| -> Result<Vec3> {
            v.as_ref()
                .map(|v| Vec3::from(*v.get_ref()))
                .ok_or_else(|| self.at(tspan.clone(), format!("a {kind} light needs `{what}`")))
        };
        let nonzero = |v: &Opt<[f32; 3]>, x: Vec3, what: &str| -> Result<Vec3> {
            x.try_normalize().ok_or_else(|| {
                self.at(
                    span_of(v).unwrap_or(tspan.clone()),
                    format!("`{what}` must not be the zero vector"),
                )
            })
        };
        let attenuation = match &l.attenuation {
            None => Attenuation::InverseSquare,
            Some(a) => match *a.get_ref() {
                AttenuationSpec::None => Attenuation::None,
                AttenuationSpec::InverseSquare => Attenuation::InverseSquare,
                AttenuationSpec::Empirical(e) => {
                    if e.c1 < 0.0 || e.c2 < 0.0 || e.c3 < 0.0 {
                        return Err(self.at(a.span(), "attenuation coefficients must be >= 0"));
                    }
                    Attenuation::Empirical {
                        c1: e.c1,
                        c2: e.c2,
                        c3: e.c3,
                    }
                }
            },
        };
        let common = ["color", "intensity"];
        match kind {
            "ambient" => {
                self.only("an ambient light", &present, &common)?;
                Ok(Light::Ambient { color, intensity })
            }
            "point" => {
                self.only(
                    "a point light",
                    &present,
                    &["color", "intensity", "position", "attenuation"],
                )?;
                Ok(Light::Point {
                    position: need(&l.position, "position")?,
                    color,
                    intensity,
                    attenuation,
                })
            }
            "directional" => {
                self.only(
                    "a directional light",
                    &present,
                    &["color", "intensity", "direction"],
                )?;
                let d = need(&l.direction, "direction")?;
                Ok(Light::Directional {
                    direction: nonzero(&l.direction, d, "direction")?,
                    color,
                    intensity,
                })
            }
            "spot" => {
                self.only(
                    "a spot light",
                    &present,
                    &[
                        "color",
                        "intensity",
                        "position",
                        "direction",
                        "look_at",
                        "attenuation",
                        "exponent",
                        "cone",
                        "cone_softness",
                        "flaps",
                    ],
                )?;
                let position = need(&l.position, "position")?;
                let (dir_field, dir) = match (&l.direction, &l.look_at) {
                    (Some(_), Some(b)) => {
                        return Err(self.at(
                            b.span(),
                            "give either `direction` or `look_at`, not both",
                        ));
                    }
                    (Some(_), None) => (&l.direction, need(&l.direction, "direction")?),
                    (None, Some(_)) => (&l.look_at, need(&l.look_at, "look_at")? - position),
                    (None, None) => {
                        return Err(self.at(tspan, "a spot light needs `direction` or `look_at`"));
                    }
                };
                let direction = nonzero(dir_field, dir, "direction")?;
                let exponent = match &l.exponent {
                    Some(e) => self.non_negative(e, "spot exponent")?,
                    None => 1.0,
                };
                let cone = match &l.cone {
                    Some(c) => {
                        let x = *c.get_ref();
                        if !(x > 0.0 && x <= 180.0) {
                            return Err(self.at(
                                c.span(),
                                format!("spot cone: expected 0 < cone <= 180 degrees, got {x}"),
                            ));
                        }
                        x
                    }
                    None => 90.0,
                };
                let softness = match &l.cone_softness {
                    Some(s) => {
                        let x = self.non_negative(s, "spot cone_softness")?;
                        if x > cone {
                            return Err(self.at(
                                s.span(),
                                format!("spot cone_softness {x} exceeds the cone {cone}"),
                            ));
                        }
                        x
                    }
                    None => 0.0,
                };
                let mut flaps = Vec::new();
                if let Some(fs) = &l.flaps {
                    for f in fs.get_ref() {
                        let Some(axis) = Vec3::from(f.axis).try_normalize() else {
                            return Err(self.at(fs.span(), "a flap `axis` must not be zero"));
                        };
                        if f.min > f.max {
                            return Err(self.at(
                                fs.span(),
                                format!("a flap needs min <= max, got {} > {}", f.min, f.max),
                            ));
                        }
                        flaps.push(Flap {
                            axis,
                            min: f.min,
                            max: f.max,
                        });
                    }
                }
                Ok(Light::Spot(SpotLight {
                    position,
                    direction,
                    color,
                    intensity,
                    attenuation,
                    exponent,
                    cone_degrees: cone,
                    cone_softness_degrees: softness,
                    flaps,
                }))
            }
            "area" => {
                let Some(shape) = &l.shape else {
                    return Err(self.at(
                        tspan,
                        "an area light needs `shape` = \"quad\", \"disk\" or \"sphere\"",
                    ));
                };
                let two_sided = l.two_sided.as_ref().is_some_and(|t| *t.get_ref());
                let shape = match shape.get_ref().as_str() {
                    "quad" => {
                        self.only(
                            "a quad area light",
                            &present,
                            &["color", "intensity", "shape", "corner", "edge_u", "edge_v", "two_sided"],
                        )?;
                        let edge_u = need(&l.edge_u, "edge_u")?;
                        let edge_v = need(&l.edge_v, "edge_v")?;
                        if edge_u.cross(edge_v).length_squared() == 0.0 {
                            return Err(self.at(
                                span_of(&l.edge_v).unwrap_or(tspan),
                                "edge_u and edge_v are parallel: the quad has no area",
                            ));
                        }
                        AreaShape::Quad {
                            corner: need(&l.corner, "corner")?,
                            edge_u,
                            edge_v,
                        }
                    }
                    "disk" => {
                        self.only(
                            "a disk area light",
                            &present,
                            &["color", "intensity", "shape", "center", "normal", "radius", "two_sided"],
                        )?;
                        let n = need(&l.normal, "normal")?;
                        AreaShape::Disk {
                            center: need(&l.center, "center")?,
                            normal: nonzero(&l.normal, n, "normal")?,
                            radius: self.radius(&l.radius, &tspan)?,
                        }
                    }
                    "sphere" => {
                        self.only(
                            "a sphere area light",
                            &present,
                            &["color", "intensity", "shape", "center", "radius", "two_sided"],
                        )?;
                        AreaShape::Sphere {
                            center: need(&l.center, "center")?,
                            radius: self.radius(&l.radius, &tspan)?,
                        }
                    }
                    other => {
                        return Err(self.at(
                            shape.span(),
                            format!(
                                "unknown area light shape {other:?}, expected one of: quad, disk, sphere"
                            ),
                        ));
                    }
                };
                Ok(Light::Area {
                    shape,
                    color,
                    intensity,
                    two_sided,
                })
            }
            other => Err(self.at(
                tspan,
                format!(
                    "unknown light type {other:?}, expected one of: ambient, point, directional, spot, area"
                ),
            )),
        }
    }

    fn radius(&self, r: &Opt<f32>, fallback: &Range<usize>) -> Result<f32> {
        match r {
            Some(r) => self.finite_positive(r, "radius"),
            None => Err(self.at(fallback.clone(), "needs `radius`")),
        }
    }

    fn transform(&self, t: &Opt<RawTransform>) -> Result<Transform> {
        let mut out = Transform::default();
        let Some(t) = t else { return Ok(out) };
        let raw = t.get_ref();
        if let Some(v) = raw.translate {
            out.translate = Vec3::from(v);
        }
        let axes = [&raw.rotate_x, &raw.rotate_y, &raw.rotate_z];
        if let Some(r) = &raw.rotate {
            if let Some(a) = axes.iter().find_map(|a| a.as_ref()) {
                return Err(self.at(
                    a.span(),
                    "give either `rotate = [x, y, z]` or `rotate_x/y/z`, not both",
                ));
            }
            out.rotate_degrees = Vec3::from(*r.get_ref());
        } else {
            let g = |a: &Opt<f32>| a.as_ref().map_or(0.0, |a| *a.get_ref());
            out.rotate_degrees = Vec3::new(g(&raw.rotate_x), g(&raw.rotate_y), g(&raw.rotate_z));
        }
        if let Some(s) = &raw.scale {
            let v = s.get_ref().vec3();
            if v.x == 0.0 || v.y == 0.0 || v.z == 0.0 {
                return Err(self.at(s.span(), format!("scale must not be zero, got {v}")));
            }
            out.scale = v;
        }
        if let Some(m) = &raw.matrix {
            let mat = Mat4::from_cols_array(m.get_ref());
            if mat.determinant().abs() < 1e-20 {
                return Err(self.at(m.span(), "matrix is singular"));
            }
            out.matrix = mat;
        }
        Ok(out)
    }

    fn object(
        &mut self,
        scene: &mut Scene,
        o: &Sp<RawObject>,
        names: &HashMap<String, MaterialId>,
        known: &[String],
        default_material: &mut Option<MaterialId>,
    ) -> Result<()> {
        let span = o.span();
        let r = o.get_ref();
        let material = match &r.material {
            None => None,
            Some(m) => match names.get(m.get_ref()) {
                Some(id) => Some(*id),
                None => {
                    let list = if known.is_empty() {
                        "no materials are defined".to_string()
                    } else {
                        format!("known: {}", known.join(", "))
                    };
                    return Err(self.at(
                        m.span(),
                        format!("unknown material {:?} ({list})", m.get_ref()),
                    ));
                }
            },
        };
        let crease = match &r.crease_angle {
            Some(c) => {
                let x = *c.get_ref();
                if !(0.0..=180.0).contains(&x) {
                    return Err(self.at(
                        c.span(),
                        format!("crease_angle: expected 0..=180 degrees, got {x}"),
                    ));
                }
                x
            }
            None => Object::default().crease_angle_degrees,
        };
        let template = Object {
            name: r.name.clone().unwrap_or_default(),
            transform: self.transform(&r.transform)?,
            smooth: r.smooth.unwrap_or(true),
            crease_angle_degrees: crease,
            shade_mode: r.shade,
            casts_shadows: r.casts_shadows.unwrap_or(true),
            ..Object::default()
        };
        let present: Present = vec![
            ("radius", span_of(&r.radius)),
            ("size", span_of(&r.size)),
            ("height", span_of(&r.height)),
            ("segments", span_of(&r.segments)),
            ("stacks", span_of(&r.stacks)),
            ("subdivisions", span_of(&r.subdivisions)),
            ("corner", span_of(&r.corner)),
            ("edge_u", span_of(&r.edge_u)),
            ("edge_v", span_of(&r.edge_v)),
        ];
        match (&r.mesh, &r.primitive) {
            (Some(_), Some(p)) => Err(self.at(
                p.span(),
                "an object takes either `mesh` or `primitive`, not both",
            )),
            (None, None) => Err(self.at(
                span,
                "an object needs `mesh = \"file\"` or `primitive = \"sphere\"` (or plane, quad, disk, box, cylinder, teapot)",
            )),
            (Some(file), None) => {
                self.only("a mesh file object", &present, &[])?;
                self.mesh_file(scene, file, material, &template, span)
            }
            (None, Some(prim)) => {
                let material = match material {
                    Some(m) => m,
                    None => match *default_material {
                        Some(m) => m,
                        None => {
                            let m = scene.add_material(Material::default());
                            self.spans.materials.push(span.clone());
                            *default_material = Some(m);
                            m
                        }
                    },
                };
                // Same primitive, same parameters: the same mesh.
                let key = format!(
                    "{}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
                    prim.get_ref(),
                    r.stacks.as_ref().map(|v| *v.get_ref()),
                    r.radius.as_ref().map(|v| v.get_ref().to_bits()),
                    r.size.as_ref().map(|v| *v.get_ref()),
                    r.height.as_ref().map(|v| v.get_ref().to_bits()),
                    r.segments.as_ref().map(|v| *v.get_ref()),
                    r.subdivisions.as_ref().map(|v| *v.get_ref()),
                    r.corner.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                    r.edge_u.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                    r.edge_v.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                );
                let geometry = match self.primitive_meshes.get(&key) {
                    Some(&mesh) => {
                        let size = MeshSize::of(&scene.meshes[mesh.index()]);
                        self.account(None, size, prim, prim.span())?;
                        Geometry::Mesh(mesh)
                    }
                    None => {
                        let geometry = self.primitive(scene, r, prim, &present)?;
                        if let Geometry::Mesh(mesh) = geometry {
                            self.spans.meshes.push(span.clone());
                            self.primitive_meshes.insert(key, mesh);
                        }
                        geometry
                    }
                };
                scene.objects.push(Object {
                    name: if template.name.is_empty() {
                        prim.get_ref().clone()
                    } else {
                        template.name.clone()
                    },
                    geometry,
                    material,
                    ..template
                });
                self.spans.objects.push(span);
                Ok(())
            }
        }
    }

    fn primitive(
        &self,
        scene: &mut Scene,
        r: &RawObject,
        prim: &Sp<String>,
        present: &Present,
    ) -> Result<Geometry> {
        let f = |v: &Opt<f32>, what: &str, def: f32| -> Result<f32> {
            match v {
                Some(v) => self.finite_positive(v, what),
                None => Ok(def),
            }
        };
        let count = |v: &Opt<u32>, what: &str, lo: u32, hi: u32, def: u32| -> Result<u32> {
            match v {
                Some(v) => self.in_range_u32(v, what, lo, hi),
                None => Ok(def),
            }
        };
        let v3 =
            |v: &Opt<[f32; 3]>, def: Vec3| v.as_ref().map_or(def, |v| Vec3::from(*v.get_ref()));
        let name = prim.get_ref().as_str();
        let what = format!("primitive {name:?}");
        let mesh: Mesh = match name {
            "sphere" => {
                self.only(&what, present, &["radius"])?;
                return Ok(Geometry::Sphere {
                    radius: f(&r.radius, "radius", 1.0)?,
                });
            }
            "plane" => {
                self.only(&what, present, &["size", "subdivisions"])?;
                let span = span_of(&r.subdivisions).unwrap_or(prim.span());
                let size = match &r.size {
                    None => 2.0,
                    Some(s) => match *s.get_ref() {
                        Splat3::Scalar(x) if x > 0.0 => x,
                        _ => {
                            return Err(self.at(
                                s.span(),
                                "plane size: expected one number > 0 (the side length)",
                            ));
                        }
                    },
                };
                let n = count(
                    &r.subdivisions,
                    "subdivisions",
                    1,
                    MAX_PLANE_SUBDIVISIONS,
                    1,
                )?;
                let m = MeshSize::plane(n);
                self.account(Some(m), m, prim, span)?;
                primitives::plane(0.5 * size, n)
            }
            "quad" => {
                self.only(&what, present, &["corner", "edge_u", "edge_v"])?;
                let corner = v3(&r.corner, Vec3::new(-1.0, 0.0, 1.0));
                let edge_u = v3(&r.edge_u, Vec3::new(2.0, 0.0, 0.0));
                let edge_v = v3(&r.edge_v, Vec3::new(0.0, 0.0, -2.0));
                if edge_u.cross(edge_v).length_squared() == 0.0 {
                    return Err(self.at(
                        span_of(&r.edge_v)
                            .or(span_of(&r.edge_u))
                            .unwrap_or(prim.span()),
                        "edge_u and edge_v are parallel: the quad has no area",
                    ));
                }
                primitives::quad(corner, edge_u, edge_v)
            }
            "disk" => {
                self.only(&what, present, &["radius", "segments"])?;
                let segments = count(&r.segments, "segments", 3, MAX_SEGMENTS, 64)?;
                let m = MeshSize::disk(segments);
                self.account(Some(m), m, prim, prim.span())?;
                primitives::disk(f(&r.radius, "radius", 1.0)?, segments)
            }
            "box" => {
                self.only(&what, present, &["size"])?;
                let size = match &r.size {
                    None => Vec3::splat(2.0),
                    Some(s) => {
                        let v = s.get_ref().vec3();
                        if v.min_element() <= 0.0 {
                            return Err(self.at(s.span(), format!("box size must be > 0, got {v}")));
                        }
                        v
                    }
                };
                primitives::box_mesh(0.5 * size)
            }
            "cylinder" => {
                self.only(&what, present, &["radius", "height", "segments"])?;
                let segments = count(&r.segments, "segments", 3, MAX_SEGMENTS, 64)?;
                let m = MeshSize::cylinder(segments);
                self.account(Some(m), m, prim, prim.span())?;
                primitives::cylinder(
                    f(&r.radius, "radius", 1.0)?,
                    f(&r.height, "height", 2.0)?,
                    segments,
                )
            }
            "teapot" => {
                self.only(&what, present, &["subdivisions"])?;
                let n = count(
                    &r.subdivisions,
                    "subdivisions",
                    1,
                    MAX_TEAPOT_SUBDIVISIONS,
                    8,
                )?;
                let m = MeshSize::teapot(n);
                self.account(Some(m), m, prim, prim.span())?;
                chiaro_core::geometry::teapot::teapot(n)
            }
            other => {
                return Err(self.at(
                    prim.span(),
                    format!(
                        "unknown primitive {other:?}, expected one of: sphere, plane, quad, disk, box, cylinder, teapot"
                    ),
                ));
            }
        };
        Ok(Geometry::Mesh(scene.add_mesh(mesh)))
    }

    fn mesh_file(
        &mut self,
        scene: &mut Scene,
        file: &Sp<String>,
        material: Option<MaterialId>,
        template: &Object,
        span: Range<usize>,
    ) -> Result<()> {
        let path = crate::resolve(self.base, file.get_ref());
        if !path.is_file() {
            return Err(self.at(
                file.span(),
                format!(
                    "mesh file {:?} not found (looked for {})",
                    file.get_ref(),
                    path.display()
                ),
            ));
        }
        let key = (
            std::fs::canonicalize(&path).unwrap_or(path.clone()),
            material,
        );
        let (imported, shared) = match self.mesh_files.get(&key) {
            Some((imported, shared)) => (imported.clone(), *shared),
            None => {
                let imported = std::rc::Rc::new(self.read_mesh_file(&path, file)?);
                let mesh_start = scene.meshes.len();
                let mat_start = scene.materials.len();
                let shared = imported.add_shared(scene, material);
                for _ in mat_start..scene.materials.len() {
                    self.spans.materials.push(file.span());
                }
                for _ in mesh_start..scene.meshes.len() {
                    self.spans.meshes.push(span.clone());
                }
                self.warnings.extend(imported.warnings.iter().cloned());
                self.mesh_files.insert(key, (imported.clone(), shared));
                (imported, shared)
            }
        };
        if imported.objects.is_empty() {
            self.warnings.push(format!(
                "{}: mesh file {:?} contains no triangles",
                self.where_(file.span()),
                file.get_ref()
            ));
        }
        let world_from_file = template.transform.world_from_object();
        let mut tmpl = template.clone();
        tmpl.transform = Transform::default();
        if tmpl.name.is_empty() {
            tmpl.name = file.get_ref().clone();
        }
        let new = imported.place(scene, &shared, world_from_file, &tmpl);
        for _ in new {
            self.spans.objects.push(span.clone());
        }
        for l in &imported.lights {
            scene
                .lights
                .push(crate::transform_light(l, world_from_file));
            self.spans.lights.push(file.span());
        }
        Ok(())
    }

    /// Reads an OBJ or glTF file (`path`, resolved from `file`).
    fn read_mesh_file(&self, path: &Path, file: &Sp<String>) -> Result<crate::Imported> {
        // glTF is read within the scene's memory budget; other formats as
        // `load_mesh_file` reads them.
        let loaded = match crate::lowercase_extension(path).as_str() {
            "gltf" | "glb" => Some(crate::gltf_import::load_gltf_within(path, self.budget)),
            _ => crate::load_mesh_file(path),
        };
        loaded
            .ok_or_else(|| {
                self.at(
                    file.span(),
                    format!(
                        "mesh file {:?}: expected a .obj, .gltf, .glb or .ply file",
                        file.get_ref()
                    ),
                )
            })?
            .map_err(|e| self.at(file.span(), format!("cannot load mesh file: {e}")))
    }

    /// Adds a primitive object's memory (a `new` mesh, if it is tessellated
    /// for it, and the prepared copy of `instance`) to the scene's total,
    /// refused at `span` when the total exceeds the budget.
    fn account(
        &self,
        new: Option<MeshSize>,
        instance: MeshSize,
        prim: &Sp<String>,
        span: Range<usize>,
    ) -> Result<()> {
        let total = self
            .load_bytes
            .get()
            .saturating_add(new.map_or(0, |m| m.mesh_bytes()))
            .saturating_add(instance.prepared_bytes());
        self.budget
            .check(
                &format!(
                    "primitive {:?} ({} triangles), with the primitives before it,",
                    prim.get_ref(),
                    instance.triangles
                ),
                total,
            )
            .map_err(|m| self.at(span, m))?;
        self.load_bytes.set(total);
        Ok(())
    }

    fn where_(&self, span: Range<usize>) -> String {
        let (l, c) = line_col(self.text, span.start);
        format!("{}:{l}:{c}", self.path.display())
    }

    /// Runs `Scene::validate`, placing each issue at the span of the item it names.
    fn finish(mut self, scene: Scene) -> Result<Loaded> {
        for issue in scene.validate() {
            let span = self.issue_span(&issue.path);
            match issue.severity {
                Severity::Error => {
                    return Err(self.at(span, format!("{}: {}", issue.path, issue.message)));
                }
                Severity::Warning => {
                    let w = format!(
                        "{}: warning: {}: {}",
                        self.where_(span),
                        issue.path,
                        issue.message
                    );
                    self.warnings.push(w);
                }
            }
        }
        Ok(Loaded {
            scene,
            warnings: self.warnings,
        })
    }

    fn issue_span(&self, path: &str) -> Range<usize> {
        let index = |prefix: &str| -> Option<usize> {
            let rest = path.strip_prefix(prefix)?.strip_prefix('[')?;
            rest.split(']').next()?.parse().ok()
        };
        let pick = |v: &Vec<Range<usize>>, i: Option<usize>| i.and_then(|i| v.get(i).cloned());
        pick(&self.spans.materials, index("materials"))
            .or_else(|| pick(&self.spans.objects, index("objects")))
            .or_else(|| pick(&self.spans.lights, index("lights")))
            .or_else(|| pick(&self.spans.meshes, index("meshes")))
            .or_else(|| {
                path.starts_with("camera")
                    .then(|| self.spans.camera.clone())
                    .flatten()
            })
            .unwrap_or(0..0)
    }
}

/// Default colours of the procedural textures.
fn default_colors(kind: ProceduralKind) -> (Vec3, Vec3) {
    match kind {
        ProceduralKind::Wood => (Vec3::new(0.55, 0.33, 0.15), Vec3::new(0.3, 0.16, 0.06)),
        ProceduralKind::Marble => (Vec3::new(0.9, 0.9, 0.88), Vec3::new(0.25, 0.25, 0.3)),
        _ => (Vec3::splat(0.1), Vec3::splat(0.9)),
    }
}

#[cfg(test)]
mod filter_tests {
    use super::parse_scene;
    use chiaro_core::scene::PixelFilter;
    use std::path::Path;

    fn filter_of(text: &str) -> Result<PixelFilter, String> {
        parse_scene(text, Path::new("."), Path::new("t.toml"))
            .map(|l| l.scene.render.filter)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn render_filter_parses_box_and_tent_and_defaults_to_box() {
        assert_eq!(filter_of("[render]\nwidth = 8\n"), Ok(PixelFilter::Box));
        assert_eq!(
            filter_of("[render]\nfilter = \"box\"\n"),
            Ok(PixelFilter::Box)
        );
        assert_eq!(
            filter_of("[render]\nfilter = \"tent\"\n"),
            Ok(PixelFilter::Tent)
        );
        let e = filter_of("[render]\nfilter = \"gauss\"\n").expect_err("unknown filter");
        assert!(e.contains("tent"), "{e}");
    }
}

#[cfg(test)]
mod instancing_tests {
    use super::parse_scene;
    use chiaro_core::scene::Geometry;
    use std::path::Path;

    /// Objects with the same tessellated primitive and parameters share one
    /// mesh (instances); other parameters, or analytic spheres, do not.
    #[test]
    fn identical_primitives_share_one_mesh() {
        let text = r#"
[[object]]
primitive = "box"
size = [1, 2, 3]
[[object]]
primitive = "box"
size = [1, 2, 3]
transform = { translate = [4, 0, 0] }
[[object]]
primitive = "box"
size = [1, 2, 4]
[[object]]
primitive = "cylinder"
radius = 0.5
[[object]]
primitive = "cylinder"
radius = 0.5
transform = { rotate = [0, 90, 0] }
[[object]]
primitive = "sphere"
radius = 1
"#;
        let scene = parse_scene(text, Path::new("."), Path::new("t.toml"))
            .expect("parses")
            .scene;
        let meshes: Vec<Option<usize>> = scene
            .objects
            .iter()
            .map(|o| match o.geometry {
                Geometry::Mesh(m) => Some(m.index()),
                _ => None,
            })
            .collect();
        assert_eq!(meshes[0], meshes[1]);
        assert_ne!(meshes[0], meshes[2]);
        assert_eq!(meshes[3], meshes[4]);
        assert_ne!(meshes[0], meshes[3]);
        assert_eq!(meshes[5], None);
        assert_eq!(scene.meshes.len(), 3);
    }
}
