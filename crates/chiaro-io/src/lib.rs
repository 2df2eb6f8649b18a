//! chiaro-io: everything that touches files.
//!
//! - [`scene_toml`]: the `.toml` scene format (README.md, "The scene format"), with
//!   `file:line:col` errors and unknown keys rejected.
//! - [`obj`]: Wavefront OBJ + MTL, read by our own parser (positions in errors).
//! - [`gltf_import`]: glTF 2.0 (`.gltf`, `.glb`, embedded) through the gltf crate.
//! - [`ply`]: Stanford PLY (ASCII and binary) through ply-rs-bw.
//! - [`mitsuba`]: Mitsuba 3 XML scenes (`.xml`) through roxmltree, mapped
//!   onto the same `Scene` (docs/import-mitsuba.md).
//! - [`pbrt`]: pbrt-v4 (and pbrt-v3) scenes (`.pbrt`), mapped onto the same
//!   `Scene` (docs/import-pbrt.md).
//! - [`images`]: decoding image textures (PNG, JPEG, HDR, EXR) to linear texels.
//! - [`output`]: writing films (PNG 8/16-bit, OpenEXR with depth and normal,
//!   Radiance HDR, PPM, palette PNG), always through a temporary file and a rename.
//! - [`studio`]: the neutral studio environment that lights a model file
//!   without lights.
//!
//! The entry point for scenes is [`load_scene`]: it reads a `.toml` scene,
//! or an `.obj` / `.gltf` / `.glb` file as a whole scene (with a camera
//! framing it, a light and default render settings when the file has none).
//!
//! # Glossary
//! - **whole-scene load**: a mesh file opened directly, not referenced from a
//!   `.toml` scene; missing camera and lights are supplied.
//! - **[`Imported`]**: what a mesh file contributes (meshes, materials,
//!   textures, placed objects, lights, cameras), with ids local to the file,
//!   merged into a [`Scene`] by [`Imported::merge_into`].

pub mod error;
pub mod export;
pub mod files;
pub mod gltf_import;
pub mod images;
pub mod mitsuba;
pub mod obj;
pub mod output;
pub mod pbrt;
pub mod plain;
pub mod ply;
pub mod scene_toml;
pub mod studio;
mod warnings;

pub use error::{IoError, Result};

pub use chiaro_core::framing::world_bounds;
use chiaro_core::framing::{self, Framing, Inside, UpAxis};
use chiaro_core::scene::{
    Camera, Geometry, Light, Material, MaterialId, Mesh, MeshId, NamedCamera, Object, Scene,
    Severity, Texture, TextureId, Transform,
};
use chiaro_core::scene::{Environment, ImageTexture};
use chiaro_core::shading::bsdf::luminance;
use chiaro_core::shading::texture::environment_mean_radiance;
use chiaro_core::{Mat4, Vec3};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A scene read from a file, with the warnings met on the way (unsupported
/// optional features, missing material libraries, `Scene::validate`
/// warnings). Warnings never stop a load; errors do.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// The scene, validated: `scene.validate()` reports no errors.
    pub scene: Scene,
    /// Human-readable warnings, each naming its file.
    pub warnings: Vec<String>,
}

/// The extension of `path` in lower case, or an empty string.
pub(crate) fn lowercase_extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// Reads a scene file, choosing the reader by extension (case-insensitive):
/// `.toml` (the chiaro scene format, see [`scene_toml`]), `.xml` (Mitsuba
/// 3, see [`mitsuba`]), `.pbrt` (pbrt-v4 or v3, see [`pbrt`]), `.obj` (with
/// its `.mtl`), `.gltf`, `.glb` or `.ply`.
///
/// A mesh file read this way becomes a whole scene: its first camera (or one
/// framing it from its front, `framing::frame_scene`), its lights (or the
/// neutral studio and a key light from over the camera's shoulder; in a
/// room, a ceiling panel and an ambient fill: [`framed_lights`]), and
/// default render settings. An OBJ or PLY file that looks Z-up gets a
/// warning naming `--up z`.
///
/// Returns an [`IoError`] naming the file (and the line and column, or the
/// glTF JSON path) when the file cannot be read, does not parse, or
/// describes a scene that `Scene::validate` rejects.
pub fn load_scene(path: &Path) -> Result<Loaded> {
    load_scene_with(path, &LoadOptions::default())
}

/// Options of a scene load that the file format may use.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadOptions {
    /// `-D name=value` parameters: a Mitsuba scene's `$name` takes this
    /// value over its `<default>`. Other formats ignore them.
    pub defines: Vec<(String, String)>,
}

impl LoadOptions {
    /// Options from `name=value` strings (the CLI's `-D`); an error names
    /// the string without `=` or with an empty name.
    pub fn from_defines<S: AsRef<str>>(defines: &[S]) -> std::result::Result<Self, String> {
        let mut out = Vec::with_capacity(defines.len());
        for d in defines {
            let d = d.as_ref();
            match d.split_once('=') {
                Some((k, v)) if !k.trim().is_empty() => {
                    out.push((k.trim().to_owned(), v.to_owned()))
                }
                _ => return Err(format!("-D {d:?}: expected name=value")),
            }
        }
        Ok(Self { defines: out })
    }
}

/// [`load_scene`] with [`LoadOptions`]; `.xml` files are Mitsuba 3 scenes
/// ([`mitsuba`]).
pub fn load_scene_with(path: &Path, options: &LoadOptions) -> Result<Loaded> {
    let ext = lowercase_extension(path);
    match ext.as_str() {
        "toml" => {
            let text = files::read_text_file(path)?;
            let base = path.parent().unwrap_or_else(|| Path::new("."));
            scene_toml::parse_scene(&text, base, path)
        }
        "xml" => mitsuba::load(path, options),
        "pbrt" => pbrt::load(path),
        _ => match load_mesh_file(path) {
            Some(imported) => whole_scene(imported?, path),
            None => Err(IoError::format(
                path,
                format!(
                    "unknown scene file extension {ext:?}: expected .toml, .xml (Mitsuba 3), .pbrt, .obj, .gltf, .glb or .ply"
                ),
            )),
        },
    }
}

/// Reads a mesh file by its extension (`.obj`, `.gltf`, `.glb`, `.ply`);
/// `None` for another extension. Faces given twice are dropped with a
/// warning ([`dedupe_faces`]).
pub fn load_mesh_file(path: &Path) -> Option<Result<Imported>> {
    let imported = match lowercase_extension(path).as_str() {
        "obj" => obj::load_obj_meshes(path),
        "gltf" | "glb" => gltf_import::load_gltf(path),
        "ply" => ply::load_ply(path),
        _ => return None,
    };
    Some(imported.map(|mut i| {
        dedupe_faces(&mut i, path);
        i
    }))
}

/// Drops every triangle of a mesh that repeats an earlier one of the same
/// mesh: the same three positions in the same winding (a face given
/// twice), adding a warning per mesh that had any. Two coincident copies
/// light each other's neighbours twice over, which radiosity cannot
/// converge on (issue 47); a copy with the opposite winding (a two-sided
/// sheet made of two faces) is kept.
pub fn dedupe_faces(imported: &mut Imported, path: &Path) {
    for mesh in &mut imported.meshes {
        // The table of faces seen is the largest transient of a load (about
        // 64 bytes a triangle): where it cannot be had, the mesh keeps its
        // duplicates rather than the process aborting.
        let mut seen = std::collections::HashSet::new();
        let mut keep: Vec<bool> = Vec::new();
        if seen.try_reserve(mesh.indices.len()).is_err()
            || keep.try_reserve_exact(mesh.indices.len()).is_err()
        {
            imported.warnings.push(format!(
                "{}: mesh \"{}\": {} triangles, too many to look for faces given twice in the memory left; any are kept",
                path.display(),
                mesh.name,
                mesh.indices.len()
            ));
            continue;
        }
        let positions = &mesh.positions;
        let key = |t: &[u32; 3]| {
            let p = t.map(|i| {
                positions
                    .get(i as usize)
                    .map(|v| v.to_array().map(f32::to_bits))
            });
            // The rotation that starts at the smallest corner: the same
            // face whatever corner it was written from.
            let start = (0..3).min_by_key(|&k| p[k]).unwrap_or(0);
            [p[start], p[(start + 1) % 3], p[(start + 2) % 3]]
        };
        let has_materials = mesh.face_materials.len() == mesh.indices.len();
        for t in &mesh.indices {
            keep.push(seen.insert(key(t)));
        }
        let dropped = keep.iter().filter(|k| !**k).count();
        if dropped == 0 {
            continue;
        }
        let mut it = keep.iter();
        mesh.indices.retain(|_| *it.next().unwrap_or(&true));
        if has_materials {
            let mut it = keep.iter();
            mesh.face_materials.retain(|_| *it.next().unwrap_or(&true));
        }
        imported.warnings.push(format!(
            "{}: mesh \"{}\": {dropped} faces given twice were dropped (a face and its exact copy)",
            path.display(),
            mesh.name
        ));
    }
}

/// Parses a `.toml` scene held in memory (tests, Python). Relative mesh and
/// texture paths resolve against `base_dir`; `name` stands for the file in
/// error messages (`name:line:col: ...`).
///
/// Returns the scene and its warnings, or the first error met.
pub fn load_scene_str(toml_text: &str, base_dir: &Path, name: &str) -> Result<Loaded> {
    scene_toml::parse_scene(toml_text, base_dir, Path::new(name))
}

/// One placed mesh of an [`Imported`] file.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedObject {
    /// Name (file node or OBJ object name).
    pub name: String,
    /// Index into [`Imported::meshes`].
    pub mesh: usize,
    /// `file_from_object`: the node's world matrix inside the file.
    pub matrix: Mat4,
    /// Index into [`Imported::materials`] for faces without a per-face
    /// material; `None` for the default material.
    pub material: Option<usize>,
}

/// What a mesh file (OBJ or glTF) contributes to a scene. Ids are local to
/// the file: `Mesh::face_materials` index [`Imported::materials`], and the
/// texture ids in those materials index [`Imported::textures`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Imported {
    /// Meshes in object space.
    pub meshes: Vec<Mesh>,
    /// Materials of the file.
    pub materials: Vec<Material>,
    /// Decoded textures of the file.
    pub textures: Vec<Texture>,
    /// Placed meshes.
    pub objects: Vec<ImportedObject>,
    /// Lights, in the file's world space.
    pub lights: Vec<Light>,
    /// Cameras, in the file's world space, named (the first is the default view).
    pub cameras: Vec<NamedCamera>,
    /// Warnings met while reading, each naming the file.
    pub warnings: Vec<String>,
}

/// Where [`Imported::add_shared`] put a file's meshes and materials in a
/// scene: what [`Imported::place`] needs to place the file again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SharedImport {
    /// Scene id of the file's first mesh.
    pub mesh_base: u32,
    /// Scene id of the file's first material (unused with an override).
    pub mat_base: u32,
    /// The material that replaces the file's, if any.
    pub material_override: Option<MaterialId>,
    /// The material of objects that name none (the override if given).
    pub default_material: Option<MaterialId>,
}

impl Imported {
    /// Adds everything to `scene`, placing the file with `world_from_file`.
    ///
    /// `material_override` replaces every material of the file (per-face
    /// materials are dropped); otherwise the file's materials are appended
    /// (and a default material where a mesh has none). `template` supplies
    /// the other object settings (smooth, crease angle, shade mode, shadows);
    /// its name prefixes the object names when not empty. Lights and cameras
    /// are *not* added; the caller decides. Returns the indices of the new
    /// objects in `scene.objects`.
    ///
    /// Equivalent to [`Imported::add_shared`] followed by
    /// [`Imported::place`]; call those to place one file several times
    /// over one copy of its meshes and materials.
    pub fn merge_into(
        &self,
        scene: &mut Scene,
        world_from_file: Mat4,
        material_override: Option<MaterialId>,
        template: &Object,
    ) -> Vec<usize> {
        let shared = self.add_shared(scene, material_override);
        self.place(scene, &shared, world_from_file, template)
    }

    /// Adds the file's meshes, and unless `material_override` is given its
    /// textures and materials (plus a default material if an object has
    /// none), to `scene`, without placing any object. The result says
    /// where they went; [`Imported::place`] places the file over them any
    /// number of times, so the placements share one object-space copy of
    /// each mesh (instances, for the two-level BVH).
    pub fn add_shared(
        &self,
        scene: &mut Scene,
        material_override: Option<MaterialId>,
    ) -> SharedImport {
        let tex_base = scene.textures.len() as u32;
        let shift_tex = |t: Option<TextureId>| t.map(|t| TextureId(t.0 + tex_base));
        let mat_base = scene.materials.len() as u32;
        let mesh_base = scene.meshes.len() as u32;
        if material_override.is_none() {
            scene.textures.extend(self.textures.iter().cloned());
            for m in &self.materials {
                let mut m = m.clone();
                m.texture = shift_tex(m.texture);
                m.normal_map = shift_tex(m.normal_map);
                m.emission_texture = shift_tex(m.emission_texture);
                if let Some(b) = &mut m.bump {
                    b.texture = TextureId(b.texture.0 + tex_base);
                }
                scene.materials.push(m);
            }
        }
        for mesh in &self.meshes {
            let mut mesh = mesh.clone();
            if material_override.is_some() {
                mesh.face_materials.clear();
            } else {
                for f in &mut mesh.face_materials {
                    f.0 += mat_base;
                }
            }
            scene.meshes.push(mesh);
        }
        let needs_default = self.objects.iter().any(|o| o.material.is_none());
        let default_material = match material_override {
            Some(m) => Some(m),
            None if needs_default => Some(scene.add_material(Material::default())),
            None => None,
        };
        SharedImport {
            mesh_base,
            mat_base,
            material_override,
            default_material,
        }
    }

    /// Places the file's objects with `world_from_file` over meshes and
    /// materials that [`Imported::add_shared`] added to this `scene`.
    /// `template` is as in [`Imported::merge_into`]. Returns the indices of
    /// the new objects in `scene.objects`.
    pub fn place(
        &self,
        scene: &mut Scene,
        shared: &SharedImport,
        world_from_file: Mat4,
        template: &Object,
    ) -> Vec<usize> {
        let mut out = Vec::with_capacity(self.objects.len());
        for o in &self.objects {
            let material = match (shared.material_override, o.material) {
                (Some(m), _) => m,
                (None, Some(local)) => MaterialId(shared.mat_base + local as u32),
                // `add_shared` made one when the file needs it; a
                // `SharedImport` of another file may lack it.
                (None, None) => match shared.default_material {
                    Some(m) => m,
                    None => scene.add_material(Material::default()),
                },
            };
            let name = if template.name.is_empty() {
                o.name.clone()
            } else {
                format!("{}/{}", template.name, o.name)
            };
            out.push(scene.objects.len());
            scene.objects.push(Object {
                name,
                geometry: Geometry::Mesh(MeshId(shared.mesh_base + o.mesh as u32)),
                material,
                transform: Transform::from_matrix(world_from_file * o.matrix),
                ..template.clone()
            });
        }
        out
    }
}

/// Builds a whole scene from one mesh file, as [`load_scene`] does: its
/// objects, its lights or default ones, its first camera or one framing the
/// bounds. `path` names the file in messages.
///
/// # Errors
/// [`IoError::Format`] when the file has no triangles (saying what was
/// skipped) or the scene does not validate.
pub fn whole_scene(imported: Imported, path: &Path) -> Result<Loaded> {
    if imported.meshes.iter().all(|m| m.indices.is_empty()) {
        let skipped = if imported.warnings.is_empty() {
            String::new()
        } else {
            format!(" ({})", imported.warnings.join("; "))
        };
        return Err(IoError::format(
            path,
            format!("nothing to render: the file has no triangles{skipped}"),
        ));
    }
    let mut scene = Scene::default();
    let template = Object::default();
    imported.merge_into(&mut scene, Mat4::IDENTITY, None, &template);
    let mut warnings = imported.warnings.clone();
    scene.cameras = imported.cameras.clone();
    let framed = match imported.cameras.first() {
        Some(c) => Framing {
            camera: c.camera,
            inside: None,
        },
        None => {
            // A vertex at 1e30 would overflow the framing into a NaN camera.
            framing::check_framable(&scene).map_err(|m| IoError::format(path, m))?;
            // OBJ and PLY do not say which axis is up (glTF is +y up).
            if matches!(lowercase_extension(path).as_str(), "obj" | "ply")
                && framing::looks_z_up(&scene)
            {
                warnings.push(format!(
                    "{}: the model looks Z-up (thinnest along y, resting on a flat base \
                     at its lowest z) and is shown with +y up: `--up z` stands it upright",
                    path.display()
                ));
            }
            framing::frame_scene(&scene, UpAxis::Y, scene.render.aspect(), None)
        }
    };
    scene.camera = framed.camera;
    scene.lights = imported.lights.clone();
    let has_emitters = scene.materials.iter().any(Material::is_emissive);
    if scene.lights.is_empty() {
        scene.lights = framed_lights(&framed);
        if framed.inside.is_none() {
            add_studio_environment(&mut scene);
        }
        if !has_emitters {
            let added = if framed.inside.is_none() {
                "the studio environment (lighting only, not the background) \
                 and a directional light"
            } else {
                "an ambient light and an area light under the ceiling"
            };
            warnings.push(format!(
                "{}: the file has no lights: added {added}",
                path.display()
            ));
        }
    }
    finish(scene, warnings, path)
}

/// The lights added to a file that has none, for the camera `framed`:
/// [`default_lights`] outside; inside an interior (where a directional
/// light or the studio would be shut out by the walls), [`room_lights`].
pub fn framed_lights(framed: &Framing) -> Vec<Light> {
    match framed.inside {
        Some(inside) => room_lights(&inside),
        None => default_lights(&framed.camera),
    }
}

/// The ambient fill of [`room_lights`]: with the default ambient
/// reflectance (0.1 of the diffuse), what a wall in shadow keeps in the
/// local techniques, which have no interreflection.
pub const ROOM_AMBIENT: f32 = 0.5;

/// The radiance a white (albedo 0.8) floor straight under the ceiling
/// panel of [`room_lights`] reflects by direct light. The path tracer adds
/// the room's interreflection (about 1.8x in a closed white room), so a
/// table under the panel stays under 1 there (`automatic_view.rs`).
pub const ROOM_FLOOR_RADIANCE: f32 = 0.4;

/// The lights of an interior without its own: an ambient fill
/// ([`ROOM_AMBIENT`]) and a ceiling panel, a downward area light a little
/// under the ceiling above the interior's open point, as wide as the
/// height it hangs at (at most half the room each way), so that the light
/// falls evenly and a table under it gets no more than about 1.5 times
/// what the floor gets. Its radiance makes a white floor straight below
/// reflect [`ROOM_FLOOR_RADIANCE`] (by the point-to-rectangle form factor).
pub fn room_lights(inside: &Inside) -> Vec<Light> {
    use chiaro_core::scene::AreaShape;
    let up = inside.up.vector();
    let front = inside.up.front();
    let side = front.cross(up);
    let below_ceiling = 0.95 * inside.to_ceiling.max(0.0);
    let height = (below_ceiling + inside.to_floor.max(0.0)).max(1e-6);
    let [front_ext, side_ext] = inside.horizontal_extent;
    let (half_f, half_s) = (
        (0.25 * front_ext).min(height).max(1e-3 * height),
        (0.25 * side_ext).min(height).max(1e-3 * height),
    );
    let centre = inside.point + up * below_ceiling;
    // edge_u x edge_v = front x side = -up: the panel shines down.
    let shape = AreaShape::Quad {
        corner: centre - front * half_f - side * half_s,
        edge_u: front * (2.0 * half_f),
        edge_v: side * (2.0 * half_s),
    };
    let f = centre_form_factor(half_f / height, half_s / height);
    let radiance = ROOM_FLOOR_RADIANCE / (0.8 * f.max(1e-4));
    vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: ROOM_AMBIENT,
        },
        Light::Area {
            shape,
            color: Vec3::ONE,
            intensity: radiance,
            two_sided: false,
        },
    ]
}

/// The form factor from a small area facing a parallel rectangle, to the
/// rectangle, straight under its centre: four corner terms of half-sizes
/// `a`, `b` (in units of the distance), `F = (1 / 2 pi) [X / sqrt(1 + X^2)
/// atan(Y / sqrt(1 + X^2)) + (X <-> Y)]` each (Howell's catalogue of
/// configuration factors, B-3).
fn centre_form_factor(a: f32, b: f32) -> f32 {
    let corner = |x: f32, y: f32| {
        let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
        (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / std::f32::consts::TAU
    };
    4.0 * corner(a, b)
}

/// The mean radiance (luminance) the studio environment is scaled to,
/// with the key light [`KEY_LIGHT_INTENSITY`] chosen with it so that a
/// white (albedo 0.8) Lambertian model is not clipped anywhere (its
/// brightest point, facing both the brightest part of the dome and the
/// key, stays below 1: `studio_and_key_leave_white_unclipped`), while the
/// soft dome, not the key, lights most of what a mirror-like metal shows.
pub const STUDIO_MEAN_LUMINANCE: f32 = 0.5;

/// The intensity of the directional key light added to a model without
/// lights ([`default_lights`]).
pub const KEY_LIGHT_INTENSITY: f32 = 0.3;

/// The size of the baked studio map: enough for the softboxes' edges.
const STUDIO_SIZE: (u32, u32) = (256, 128);

/// The neutral studio map ([`studio::neutral_studio_texture`]), its
/// intensity (scaling it to [`STUDIO_MEAN_LUMINANCE`]) and its mean
/// radiance at that intensity ([`environment_mean_radiance`]), computed
/// once.
fn studio() -> &'static (ImageTexture, f32, Vec3) {
    static STUDIO: OnceLock<(ImageTexture, f32, Vec3)> = OnceLock::new();
    if let Some(s) = STUDIO.get() {
        return s;
    }
    // Computed outside the lock, which rayon work inside `get_or_init`
    // could deadlock (see `albedo_tables` in chiaro-core).
    let computed = {
        let texture = studio::neutral_studio_texture(STUDIO_SIZE.0, STUDIO_SIZE.1);
        let mut scene = Scene::default();
        let id = scene.add_texture(Texture::Image(texture.clone()));
        scene.environment = Some(studio_env(id, 1.0));
        let raw = environment_mean_radiance(&scene);
        let lum = luminance(raw);
        let intensity = if lum > 0.0 {
            STUDIO_MEAN_LUMINANCE / lum
        } else {
            1.0
        };
        (texture, intensity, raw * intensity)
    };
    STUDIO.get_or_init(|| computed)
}

/// The studio environment with texture `id`: lighting and reflections only,
/// the camera keeps seeing `scene.background` (a model is shown against its
/// usual plain background; `background = true` in a TOML scene shows a map).
fn studio_env(texture: TextureId, intensity: f32) -> Environment {
    Environment {
        texture,
        intensity,
        rotate_y_degrees: 0.0,
        as_background: false,
    }
}

/// Adds the studio environment to `scene` (its texture and
/// `scene.environment`), as the automatic lighting of a model without
/// lights does: the map lights the model in every technique but radiosity
/// (the local techniques through its prefiltered table, the path tracer
/// integrating it).
pub fn add_studio_environment(scene: &mut Scene) {
    let (texture, intensity, _) = studio();
    let id = scene.add_texture(Texture::Image(texture.clone()));
    scene.environment = Some(studio_env(id, *intensity));
}

/// The mean radiance of the studio environment as added by
/// [`add_studio_environment`].
pub fn studio_ambient() -> Vec3 {
    studio().2
}

/// The light added to a file that has none, besides the studio
/// environment: a white directional light of intensity
/// [`KEY_LIGHT_INTENSITY`] shining from above the camera's right shoulder
/// (where the studio's key softbox is, for a camera framing the front). (No ambient light: the map's
/// diffuse light reaches the local techniques through its spherical
/// harmonics, `texture::environment_diffuse`.)
pub fn default_lights(camera: &Camera) -> Vec<Light> {
    let f = camera.frame();
    let direction = (f.forward - 0.5 * f.up - 0.3 * f.right).normalize_or_zero();
    let direction = if direction == Vec3::ZERO {
        Vec3::NEG_Y
    } else {
        direction
    };
    vec![Light::Directional {
        direction,
        color: Vec3::ONE,
        intensity: KEY_LIGHT_INTENSITY,
    }]
}

/// Runs `Scene::validate`: errors become one [`IoError::Format`] listing
/// them, warnings follow the loader's `warnings`, each kind said once
/// (`warnings::summarize`).
fn finish(scene: Scene, warnings: Vec<String>, path: &Path) -> Result<Loaded> {
    let mut errors = Vec::new();
    let mut issues = Vec::new();
    for issue in scene.validate() {
        match issue.severity {
            Severity::Error => errors.push(format!("{}: {}", issue.path, issue.message)),
            Severity::Warning => issues.push((issue.path, issue.message)),
        }
    }
    let warnings = warnings::summarize(warnings, path, issues);
    if !errors.is_empty() {
        return Err(IoError::format(
            path,
            format!("invalid scene: {}", errors.join("; ")),
        ));
    }
    Ok(Loaded { scene, warnings })
}

/// Resolves `rel` against `base` (absolute paths are kept).
pub(crate) fn resolve(base: &Path, rel: &str) -> PathBuf {
    let p = Path::new(rel);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

/// `light` moved by the affine transform `m` (positions as points,
/// directions as vectors, renormalised; sizes scaled by the cube root of
/// the determinant for area lights).
pub fn transform_light(light: &Light, m: Mat4) -> Light {
    use chiaro_core::scene::AreaShape;
    let dir = |d: Vec3| m.transform_vector3(d).try_normalize().unwrap_or(d);
    let scale = m.determinant().abs().cbrt();
    match light.clone() {
        Light::Ambient { .. } => light.clone(),
        Light::Point {
            position,
            color,
            intensity,
            attenuation,
        } => Light::Point {
            position: m.transform_point3(position),
            color,
            intensity,
            attenuation,
        },
        Light::Directional {
            direction,
            color,
            intensity,
        } => Light::Directional {
            direction: dir(direction),
            color,
            intensity,
        },
        Light::Spot(mut s) => {
            s.position = m.transform_point3(s.position);
            s.direction = dir(s.direction);
            for f in &mut s.flaps {
                f.axis = dir(f.axis);
            }
            Light::Spot(s)
        }
        Light::Area {
            shape,
            color,
            intensity,
            two_sided,
        } => {
            let shape = match shape {
                AreaShape::Quad {
                    corner,
                    edge_u,
                    edge_v,
                } => AreaShape::Quad {
                    corner: m.transform_point3(corner),
                    edge_u: m.transform_vector3(edge_u),
                    edge_v: m.transform_vector3(edge_v),
                },
                AreaShape::Disk {
                    center,
                    normal,
                    radius,
                } => AreaShape::Disk {
                    center: m.transform_point3(center),
                    normal: dir(normal),
                    radius: radius * scale,
                },
                AreaShape::Sphere { center, radius } => AreaShape::Sphere {
                    center: m.transform_point3(center),
                    radius: radius * scale,
                },
                AreaShape::Triangle { a, b, c } => AreaShape::Triangle {
                    a: m.transform_point3(a),
                    b: m.transform_point3(b),
                    c: m.transform_point3(c),
                },
            };
            Light::Area {
                shape,
                color,
                intensity,
                two_sided,
            }
        }
    }
}

#[cfg(test)]
mod studio_tests {
    use super::*;

    /// The computed map is finite and is scaled to the stated mean
    /// luminance; `default_lights` adds no ambient stand-in for it.
    #[test]
    fn studio_environment_is_scaled_to_its_mean() {
        let (t, intensity, mean) = studio();
        assert_eq!((t.width, t.height), (256, 128));
        assert!(
            t.texels
                .iter()
                .flatten()
                .all(|v| v.is_finite() && *v >= 0.0)
        );
        assert!(intensity.is_finite() && *intensity > 0.0);
        assert!(
            (luminance(*mean) - STUDIO_MEAN_LUMINANCE).abs() < 1e-3,
            "{mean}"
        );
        let lights = default_lights(&Camera::default());
        assert!(
            lights.iter().all(|l| !matches!(l, Light::Ambient { .. })),
            "{lights:?}"
        );
        let mut scene = Scene::default();
        add_studio_environment(&mut scene);
        let env = scene.environment.clone().expect("environment");
        assert!(!env.as_background);
        let again = environment_mean_radiance(&scene);
        assert!(
            (again - *mean).abs().max_element() < 1e-4,
            "{again} vs {mean}"
        );
    }

    /// The brightest a white (albedo 0.8) Lambertian surface gets under
    /// the automatic lights, over 400 normals: `0.8 (E(n) / pi + key)`
    /// with `E(n)` the map's irradiance summed over its texels, stays below
    /// 0.95 (no clipping at exposure 0), and the darkest (facing the floor,
    /// away from the key) above 0.25 (no black side).
    #[test]
    fn studio_and_key_leave_white_unclipped() {
        let (t, intensity, _) = studio();
        let (w, h) = (t.width as usize, t.height as usize);
        let pi = std::f32::consts::PI;
        // Texel directions and solid angles (rows weighted by sin(theta)).
        let mut texels = Vec::with_capacity(w * h);
        for j in 0..h {
            let theta = (j as f32 + 0.5) / h as f32 * pi;
            let dw = (2.0 * pi / w as f32) * (pi / h as f32) * theta.sin();
            for i in 0..w {
                let phi = ((i as f32 + 0.5) / w as f32 - 0.5) * 2.0 * pi;
                let d = Vec3::new(
                    theta.sin() * phi.sin(),
                    theta.cos(),
                    -theta.sin() * phi.cos(),
                );
                texels.push((d, t.texels[j * w + i][0] * intensity * dw));
            }
        }
        let key = default_lights(&Camera::default());
        let Some(Light::Directional { direction, .. }) = key.first() else {
            panic!("a directional key light: {key:?}");
        };
        let (mut brightest, mut darkest) = (0.0f32, f32::INFINITY);
        let golden = pi * (3.0 - 5f32.sqrt());
        for k in 0..400 {
            let y = 1.0 - (2.0 * k as f32 + 1.0) / 400.0;
            let r = (1.0 - y * y).sqrt();
            let n = Vec3::new(
                r * (golden * k as f32).cos(),
                y,
                r * (golden * k as f32).sin(),
            );
            let e: f32 = texels.iter().map(|(d, l)| l * n.dot(*d).max(0.0)).sum();
            let white = 0.8 * (e / pi + KEY_LIGHT_INTENSITY * n.dot(-*direction).max(0.0));
            brightest = brightest.max(white);
            darkest = darkest.min(white);
        }
        eprintln!("white under the automatic lights: {darkest} to {brightest}");
        assert!(brightest < 0.95, "{brightest}");
        assert!(darkest > 0.25, "{darkest}");
    }

    /// The ceiling panel of a room faces down from just under the ceiling,
    /// and its radiance makes the white floor below reflect
    /// ROOM_FLOOR_RADIANCE: checked against the form factor summed over a
    /// fine grid of the panel.
    #[test]
    fn the_room_panel_shines_down_on_the_floor() {
        use chiaro_core::scene::AreaShape;
        let inside = Inside {
            point: Vec3::new(1.0, 1.2, -2.0),
            mean_distance: 3.0,
            to_ceiling: 1.8,
            to_floor: 1.2,
            horizontal_extent: [10.0, 4.0],
            up: UpAxis::Y,
        };
        let lights = room_lights(&inside);
        let Some(Light::Area {
            shape:
                AreaShape::Quad {
                    corner,
                    edge_u,
                    edge_v,
                },
            intensity,
            ..
        }) = lights
            .iter()
            .find(|l| matches!(l, Light::Area { .. }))
            .cloned()
        else {
            panic!("a quad area light: {lights:?}");
        };
        let n = edge_u.cross(edge_v).normalize();
        assert!((n - Vec3::NEG_Y).length() < 1e-6, "{n}");
        assert!((corner.y - (1.2 + 0.95 * 1.8)).abs() < 1e-5);
        // A quarter of the room's extent each way, at most the height.
        assert!((edge_v.length() - 2.0).abs() < 1e-5, "{edge_v}");
        assert!((edge_u.length() - 5.0).abs() < 1e-5, "{edge_u}");
        // Irradiance / pi at the floor below the centre, by a 200 x 200 sum.
        let floor = inside.point - Vec3::Y * inside.to_floor;
        let mut f = 0.0;
        let k = 200;
        let da = edge_u.length() * edge_v.length() / (k * k) as f32;
        for i in 0..k {
            for j in 0..k {
                let q = corner
                    + edge_u * ((i as f32 + 0.5) / k as f32)
                    + edge_v * ((j as f32 + 0.5) / k as f32);
                let d = q - floor;
                let r2 = d.length_squared();
                let cos = d.y / r2.sqrt();
                f += cos * cos / (std::f32::consts::PI * r2) * da;
            }
        }
        let floor_radiance = 0.8 * intensity * f;
        assert!(
            (floor_radiance - ROOM_FLOOR_RADIANCE).abs() < 2e-3,
            "{floor_radiance}"
        );
        assert!((centre_form_factor(1e4, 1e4) - 1.0).abs() < 1e-3);
    }
}
