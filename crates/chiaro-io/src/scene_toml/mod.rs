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
//! The `[render]` values are checked by `RenderSettings::validate`, the one
//! settings check that `--set`, Python and the web viewer share: every
//! error it finds is reported, each at its value and naming its setting
//! (`t.toml:5:23: render.radiosity.hemicube_resolution: expected 2..=4096, got 1`).
//! The ranges `Scene::validate` checks for every scene (camera, material,
//! spot cone) are its alone too, placed at the key they name.
//!
//! # Tables
//!
//! | table | keys |
//! | --- | --- |
//! | `[render]` | `technique` (`preview`, `flat`, `gouraud`, `phong`, `whitted`, `radiosity`, `hybrid`, `path`), `width`, `height` (1..=16384, at most 64 Mpixel), `samples`, `seed`, `shadows` (`none`, `map`, `volume`, `ray`, `object`, `scanline`), `transparency`, `aa` (`supersample`, `adaptive`, `post`), `filter` (`box`, `tent`: the reconstruction of the scan converter's supersamples), `light_samples`, `light_selection` (`auto`, `power`, `tree`: how lights are chosen among many), `tonemap` (`clamp`, `reinhard`, `filmic`), `exposure`, `cull_backfaces`, `memory_limit` (`"8G"`, `"512M"` or bytes: the memory this scene may use; by default half the process's memory limit, see `chiaro info --system`); sub-tables `shadow_map` {`resolution`, `bias`, `slope_bias`, `pcf_radius`}, `whitted` {`max_depth`, `min_weight`, `adaptive_threshold`, `adaptive_max_depth`}, `path` {`max_depth`, `rr_depth`}, `radiosity` {`solver` (`jacobi`, `gauss-seidel`, `progressive`, `hierarchical`), `formfactor` (`hemicube`, `raycast`, `analytic`), `patch_size`, `hemicube_resolution`, `tolerance`, `max_iterations`}, `depth_cue` {`color`, `near`, `far`, `max_scale`, `min_scale`} |
//! | `[camera]` | `eye`, `look_at`, `up`, `fov` (vertical, 0..180), `near`, `far`, `projection` (`perspective`, the default, or `orthographic`: parallel rays from a film centred on `eye`), `half_height` (orthographic only, and needed there: half the film's height in scene units; the width follows the image's aspect) |
//! | `[cameras.NAME]` | further cameras with the keys of `[camera]`, chosen with `chiaro render --camera NAME` |
//! | `[[light]]` | `type` = `ambient` {`color`, `intensity`}; `point` {+ `position`, `attenuation`}; `directional` {`direction`, the way the light travels}; `spot` {`position`, `direction` or `look_at`, `attenuation`, `exponent` (Warn's n, default 1), `cone` (half-angle, default 90), `cone_softness`, `flaps` = [{`axis`, `min`, `max`}]}; `area` {`shape` = `quad` {`corner`, `edge_u`, `edge_v`} / `disk` {`center`, `normal`, `radius`} / `sphere` {`center`, `radius`}, `two_sided`} |
//! | `[material.NAME]` | `ambient` (ka, relative to kd), `diffuse`, `specular`, `shininess`, `model` (`phong`, `blinn`, `torrance-sparrow`), `roughness`, `distribution` (`ggx`, `beckmann`), `reflect`, `transmit`, `ior`, `absorption`, `fresnel`, `conductor` (a metal: `"Au"`, `"Ag"`, `"Cu"`, ... (Mitsuba's named conductors) or `{ eta = [..], k = [..] }`, its complex IOR per channel; the mirror weight becomes `reflect` times the conductor's Fresnel reflectance and the Torrance-Sparrow lobe's Fresnel `specular` times it, instead of Schlick's), `transparency` (`interpolated`, `screen-door`, `filtered`), `texture`, `bump`, `normal_map`, `emission`, `emission_texture`, `sidedness` (`two-sided`, the default: both faces drawn and shaded facing the viewer; `one-sided`: the back is drawn black, as Mitsuba's; `culled`: invisible from behind to the eye in every technique, as glTF `doubleSided: false`), `emission_two_sided` (emits from both faces; default the front only); the older `two_sided = true` (two-sided, emitting from both faces), `two_sided = false` (one-sided) and `cull_backface = true` (culled) are still read |
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

mod camera;
mod lights;
mod materials;
mod objects;
mod raw;
mod render;
#[cfg(test)]
mod tests;

use crate::{IoError, Loaded, Result};
use chiaro_core::Vec3;
use chiaro_core::budget::MemoryBudget;
use chiaro_core::scene::{
    Environment, MaterialId, NamedCamera, Scene, Severity, TextureId, WrapMode,
};
use raw::{Opt, RawScene, Sp, Splat3};
use serde::Deserialize;
use std::cell::Cell;
use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

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
    ctx.spans.keys = key_spans(root.get_ref());
    let raw =
        RawScene::deserialize(toml::de::Deserializer::from(root)).map_err(|e| ctx.toml_err(&e))?;
    let scene = ctx.build(raw)?;
    ctx.finish(scene)
}

/// The key (table header or the key of `key = value`) with the most dotted
/// parts in `text`, as its span and its number of parts; `None` when no
/// line has one. Quoted parts are skipped over, so a dot inside quotes is
/// not counted.
fn deepest_key(text: &str) -> Option<(Range<usize>, usize)> {
    let mut best: Option<(Range<usize>, usize)> = None;
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_start();
        let start = offset + (line.len() - trimmed.len());
        offset += line.len();
        let key = trimmed.trim_start_matches('[');
        let mut parts = 1;
        let mut quote = None;
        let mut end = key.len();
        for (i, c) in key.char_indices() {
            match (quote, c) {
                (Some(q), c) if c == q => quote = None,
                (Some(_), _) => {}
                (None, '"' | '\'') => quote = Some(c),
                (None, '.') => parts += 1,
                (None, ']' | '=' | '#') => {
                    end = i;
                    break;
                }
                _ => {}
            }
        }
        if parts > 1 && best.as_ref().is_none_or(|b| parts > b.1) {
            let key_start = start + (trimmed.len() - key.len());
            best = Some((key_start..key_start + end, parts));
        }
    }
    best
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
    /// How many materials the file's `[material.NAME]` tables made (the
    /// first ones of the scene).
    file_materials: usize,
    /// Every key of the file, by dotted path (`material.glass.roughness`,
    /// `light[2].cone`): its value's span, or a table's header or key.
    keys: HashMap<String, Range<usize>>,
}

/// Records the span of every key in `root` by dotted path, array elements
/// as `name[i]`.
fn key_spans(root: &toml::de::DeTable) -> HashMap<String, Range<usize>> {
    use toml::de::DeValue;
    fn walk(
        path: String,
        key: Range<usize>,
        v: &toml::Spanned<DeValue>,
        out: &mut HashMap<String, Range<usize>>,
    ) {
        let span = match v.get_ref() {
            // A table's span may be empty (dotted keys): its key then.
            DeValue::Table(_) if v.span().is_empty() => key.clone(),
            _ => v.span(),
        };
        out.insert(path.clone(), span);
        match v.get_ref() {
            DeValue::Table(t) => {
                for (k, v) in t {
                    walk(format!("{path}.{}", k.get_ref()), k.span(), v, out);
                }
            }
            DeValue::Array(a) => {
                for (i, v) in a.iter().enumerate() {
                    walk(format!("{path}[{i}]"), key.clone(), v, out);
                }
            }
            _ => {}
        }
    }
    let mut out = HashMap::new();
    for (k, v) in root {
        walk(k.get_ref().to_string(), k.span(), v, &mut out);
    }
    out
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
    /// Refuses `path`, the file `rel` names, unless it is an existing
    /// regular file, with an error at `rel`: `cannot` starts the message
    /// for a device, FIFO or folder, `kind` names the missing file.
    fn check_file(&self, rel: &Sp<String>, path: &Path, kind: &str, cannot: &str) -> Result<()> {
        if let Some(e) = crate::files::refuse_special(path) {
            return Err(self.at(rel.span(), format!("{cannot}: {e}")));
        }
        if !path.is_file() {
            return Err(self.at(
                rel.span(),
                format!(
                    "{kind} {:?} not found (looked for {})",
                    rel.get_ref(),
                    path.display()
                ),
            ));
        }
        Ok(())
    }

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
        // The reader's nesting limits: a dotted key of 80 parts or more
        // comes without a position (found at the key here), and arrays or
        // inline tables nested too deeply.
        if e.message().contains("recursion limit")
            && let Some((span, parts)) = deepest_key(self.text)
        {
            return self.at(
                span,
                format!(
                    "a key nested {parts} levels deep: chiaro's TOML reader allows fewer \
                     than 80 dotted parts in a key or table header"
                ),
            );
        }
        if e.message().contains("max recursion depth") {
            let span = e.span().unwrap_or(0..0);
            return self.at(
                span,
                "lists or inline tables nested too deeply for chiaro's TOML reader",
            );
        }
        let span = e.span().unwrap_or(0..0);
        let key = key_before(self.text, span.start);
        let message =
            crate::plain::plain_serde_message(&crate::plain::third_party(e.message()), key);
        // A render setting's value is named by its setting path.
        let setting = self
            .spans
            .keys
            .iter()
            .find(|(k, s)| **s == span && render::is_setting(k));
        match setting {
            Some((setting, _)) => self.at(span, format!("{setting}: {message}")),
            None => self.at(span, message),
        }
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

        self.spans.file_materials = scene.materials.len();
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

    fn where_(&self, span: Range<usize>) -> String {
        let (l, c) = line_col(self.text, span.start);
        format!("{}:{l}:{c}", self.path.display())
    }

    /// Runs `Scene::validate`, placing each issue at the span of the key or
    /// item it names; refuses the scene with every error.
    fn finish(mut self, scene: Scene) -> Result<Loaded> {
        // The settings' issues were reported by `render` (errors) and are
        // left to the render context (warnings).
        let (errors, warnings): (Vec<_>, Vec<_>) = scene
            .validate()
            .into_iter()
            .filter(|i| !render::is_setting(&i.path))
            .partition(|i| i.severity == Severity::Error);
        self.refuse(errors.iter().map(|i| {
            let span = self.issue_span(&scene, &i.path);
            (span, format!("{}: {}", i.path, i.message))
        }))?;
        for i in warnings {
            let span = self.issue_span(&scene, &i.path);
            let w = format!("{}: warning: {}: {}", self.where_(span), i.path, i.message);
            self.warnings.push(w);
        }
        Ok(Loaded {
            scene,
            warnings: self.warnings,
        })
    }

    /// An error listing every `(span, message)` of `errors`, each with its
    /// line and column (the first one's are the error's), or `Ok` for none.
    fn refuse(&self, mut errors: impl Iterator<Item = (Range<usize>, String)>) -> Result<()> {
        let Some((span, mut message)) = errors.next() else {
            return Ok(());
        };
        for (span, m) in errors {
            message.push_str(&format!("\n{}: {m}", self.where_(span)));
        }
        Err(self.at(span, message))
    }

    /// The span of the key at dotted `path` in the file, else of its
    /// nearest parent that is there, else the file's start.
    fn key_span(&self, path: &str) -> Range<usize> {
        let mut p = path;
        loop {
            if let Some(s) = self.spans.keys.get(p) {
                return s.clone();
            }
            match p.rsplit_once('.') {
                Some((parent, _)) => p = parent,
                None => return 0..0,
            }
        }
    }

    /// The key in the file that an issue path of `Scene::validate` names
    /// (`materials[1] (glass).roughness` is `material.glass.roughness`), for
    /// the items the file itself made.
    fn file_key(&self, scene: &Scene, path: &str) -> Option<String> {
        let index = |prefix: &str| -> Option<(usize, &str)> {
            let rest = path.strip_prefix(prefix)?.strip_prefix('[')?;
            let (i, rest) = rest.split_once(']')?;
            // `[3] (name).field` or `[3].field`: the `.field` part.
            let rest = rest
                .strip_prefix(" (")
                .and_then(|r| r.rfind(')').map(|k| &r[k + 1..]))
                .unwrap_or(rest);
            let field = rest.find('.').map_or("", |k| &rest[k..]);
            Some((i.parse().ok()?, field))
        };
        if path == "camera" || path.starts_with("camera.") {
            return Some(path.to_string());
        }
        if let Some((i, field)) = index("cameras") {
            let name = &scene.cameras.get(i)?.name;
            return Some(format!("cameras.{name}{field}"));
        }
        if let Some((i, field)) = index("materials")
            && i < self.spans.file_materials
        {
            let name = &scene.materials.get(i)?.name;
            return Some(format!("material.{name}{field}"));
        }
        if let Some((i, field)) = index("lights")
            && i < self.spans.lights.len()
        {
            return Some(format!("light[{i}]{field}"));
        }
        None
    }

    /// Where an issue of `Scene::validate` is placed: the key it names, else
    /// the item it names, else the file's start.
    fn issue_span(&self, scene: &Scene, path: &str) -> Range<usize> {
        if let Some(key) = self.file_key(scene, path) {
            return self.key_span(&key);
        }
        self.item_span(path)
    }

    fn item_span(&self, path: &str) -> Range<usize> {
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
