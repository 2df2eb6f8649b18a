//! What each technique cannot show of a scene, said once and by name.
//!
//! [`limitations`] lists, for a scene and a technique, the features the
//! scene has that the technique does not draw (radiosity's mirrors and
//! glass, scan conversion's refraction, ...), each with the objects that
//! have it. [`crate::render_with_stats`] emits each one as a
//! `Progress::warning`, `chiaro info` lists them per technique, and
//! [`markdown_table`] is the README's table of what each technique shows,
//! so the three say the same. [`CANNOT_SHOW`] holds the technique-feature
//! pairs, each checked against the technique's code.

use chiaro_core::scene::{
    AlphaMode, Geometry, Light, Material, MaterialId, RenderSettings, Scene, ShadowMethod,
    Technique,
};
use std::collections::HashMap;
use std::fmt;

/// Something a scene can have that some technique does not draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Feature {
    /// The scene's lights, shadows included (preview lights with an eye light).
    Lights,
    /// Ambient lights (`Ia ka kd`).
    AmbientLight,
    /// Light from the environment map falling on surfaces.
    EnvironmentLight,
    /// Mirror reflection of the scene (`reflect > 0`, or a Fresnel dielectric).
    Mirrors,
    /// Refraction: light bent through a transmitting surface with `ior != 1`.
    Refraction,
    /// Surfaces that let light through (`transmit > 0`, glTF `BLEND`).
    Transparency,
    /// Specular highlights (`specular > 0`).
    Highlights,
    /// Normal and bump maps.
    NormalMaps,
    /// Highlights and shadows that fall inside one large polygon.
    InsideLargePolygons,
    /// Light that mirrors and glass send onto other surfaces (caustics).
    SpecularIndirect,
    /// Depth cueing (`render.depth_cue`).
    DepthCue,
    /// Shadows with `shadows = "volume"` (the volumes exist per sample).
    VolumeShadows,
    /// Alpha-masked surfaces (glTF `alphaMode: MASK`): cut-out texels.
    AlphaMask,
    /// Alpha-masked shadow casters under `shadows` = volume, object or
    /// scanline (polygon shadows that do not cut texels).
    AlphaMaskShadows,
}

/// What each technique cannot show, in words: `(technique, feature, what
/// the picture shows instead)`. Each entry is what the technique's code
/// does (see the module docs of chiaro-ray, chiaro-raster, chiaro-radiosity
/// and `chiaro::hybrid`).
pub const CANNOT_SHOW: &[(Technique, Feature, &str)] = &[
    (
        Technique::Preview,
        Feature::Lights,
        "the scene's lights and shadows: preview lights every surface with an eye light",
    ),
    (
        Technique::Preview,
        Feature::Mirrors,
        "mirror reflections: mirrors show their own colour",
    ),
    (
        Technique::Preview,
        Feature::Transparency,
        "transparency and refraction: drawn opaque",
    ),
    (
        Technique::Preview,
        Feature::EnvironmentLight,
        "light from the environment map",
    ),
    (Technique::Preview, Feature::DepthCue, "depth cueing"),
    (
        Technique::Flat,
        Feature::Mirrors,
        "mirror reflections of other objects: only the environment map is reflected",
    ),
    (
        Technique::Flat,
        Feature::Refraction,
        "refraction: transparent surfaces do not bend light",
    ),
    (
        Technique::Flat,
        Feature::NormalMaps,
        "normal and bump maps: polygons are lit with the face normal",
    ),
    (
        Technique::Flat,
        Feature::InsideLargePolygons,
        "highlights and shadows inside a polygon: each polygon is lit once, at its centre",
    ),
    (
        Technique::Flat,
        Feature::EnvironmentLight,
        "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them",
    ),
    (
        Technique::Flat,
        Feature::VolumeShadows,
        "shadows with `shadows = \"volume\"`: the volumes exist per sample, not at polygon centres",
    ),
    (
        Technique::Gouraud,
        Feature::Mirrors,
        "mirror reflections of other objects: only the environment map is reflected",
    ),
    (
        Technique::Gouraud,
        Feature::Refraction,
        "refraction: transparent surfaces do not bend light",
    ),
    (
        Technique::Gouraud,
        Feature::NormalMaps,
        "normal and bump maps: vertices are lit with the interpolated normal",
    ),
    (
        Technique::Gouraud,
        Feature::InsideLargePolygons,
        "highlights and shadows inside a polygon: light is computed at the vertices only",
    ),
    (
        Technique::Gouraud,
        Feature::EnvironmentLight,
        "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them",
    ),
    (
        Technique::Gouraud,
        Feature::VolumeShadows,
        "shadows with `shadows = \"volume\"`: the volumes exist per sample, not at vertices",
    ),
    (
        Technique::Phong,
        Feature::Mirrors,
        "mirror reflections of other objects: only the environment map is reflected",
    ),
    (
        Technique::Phong,
        Feature::Refraction,
        "refraction: transparent surfaces do not bend light",
    ),
    (
        Technique::Phong,
        Feature::EnvironmentLight,
        "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them",
    ),
    (
        Technique::Whitted,
        Feature::EnvironmentLight,
        "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them",
    ),
    (
        Technique::Radiosity,
        Feature::Mirrors,
        "mirror reflections: mirrors are drawn matte",
    ),
    (
        Technique::Radiosity,
        Feature::Transparency,
        "transparency and refraction: drawn opaque",
    ),
    (
        Technique::Radiosity,
        Feature::Highlights,
        "specular highlights: surfaces are drawn diffuse",
    ),
    (
        Technique::Radiosity,
        Feature::NormalMaps,
        "normal and bump maps: patches are lit with their face normal",
    ),
    (
        Technique::Radiosity,
        Feature::AmbientLight,
        "ambient lights: interreflection is computed instead",
    ),
    (
        Technique::Radiosity,
        Feature::EnvironmentLight,
        "light from the environment map",
    ),
    (Technique::Radiosity, Feature::DepthCue, "depth cueing"),
    (
        Technique::Radiosity,
        Feature::AlphaMask,
        "cut-outs of alpha-masked (glTF MASK) surfaces: patches are drawn whole",
    ),
    (
        Technique::Hybrid,
        Feature::SpecularIndirect,
        "light that mirrors and glass send onto other surfaces (caustics): the radiosity pass sees them as matte and opaque",
    ),
    (
        Technique::Flat,
        Feature::AlphaMaskShadows,
        "shadows of alpha-masked cut-outs with `shadows` = volume, object or scanline: masked surfaces cast whole shadows (`shadows` = ray or map cut them)",
    ),
    (
        Technique::Gouraud,
        Feature::AlphaMaskShadows,
        "shadows of alpha-masked cut-outs with `shadows` = volume, object or scanline: masked surfaces cast whole shadows (`shadows` = ray or map cut them)",
    ),
    (
        Technique::Phong,
        Feature::AlphaMaskShadows,
        "shadows of alpha-masked cut-outs with `shadows` = volume, object or scanline: masked surfaces cast whole shadows (`shadows` = ray or map cut them)",
    ),
    (
        Technique::Hybrid,
        Feature::AlphaMask,
        "cut-outs of alpha-masked (glTF MASK) surfaces in the indirect light: the radiosity pass sees them whole",
    ),
    (
        Technique::Hybrid,
        Feature::AmbientLight,
        "ambient lights: interreflection is computed instead",
    ),
    (
        Technique::Hybrid,
        Feature::EnvironmentLight,
        "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them",
    ),
    (
        Technique::Path,
        Feature::AmbientLight,
        "ambient lights: interreflection is computed instead",
    ),
    (Technique::Path, Feature::DepthCue, "depth cueing"),
];

/// What each technique draws, for the README's table.
pub const SHOWS: &[(Technique, &str)] = &[
    (
        Technique::Preview,
        "surfaces, textures, normal maps and highlights under an eye light; the background",
    ),
    (
        Technique::Flat,
        "direct light and shadows per polygon, textures per pixel, non-refractive transparency, environment reflection maps and the environment's light",
    ),
    (
        Technique::Gouraud,
        "direct light and shadows per vertex, interpolated; textures per pixel, non-refractive transparency, environment reflection maps and the environment's light",
    ),
    (
        Technique::Phong,
        "direct light, highlights and shadows per pixel, textures, normal and bump maps, non-refractive transparency, environment reflection maps and the environment's light",
    ),
    (
        Technique::Whitted,
        "direct light with shadow rays (soft from area lights), highlights, mirror reflection, refraction, textures and normal maps; ambient light for the rest",
    ),
    (
        Technique::Radiosity,
        "diffuse interreflection and colour bleeding, soft shadows, textures (the texture times the patches' light)",
    ),
    (
        Technique::Hybrid,
        "Whitted's direct light, highlights, mirrors and glass, with radiosity's diffuse interreflection in place of ambient light",
    ),
    (
        Technique::Path,
        "all light transport: interreflection, soft shadows, glossy and mirror reflection, refraction, caustics (slowly), environment light",
    ),
];

/// One feature of a scene that a technique does not draw, with the objects
/// (or lights) that have it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limitation {
    /// The technique.
    pub technique: Technique,
    /// What it does not draw.
    pub feature: Feature,
    /// What the picture shows instead, in words.
    pub text: &'static str,
    /// The objects (or lights) that have the feature; empty for a setting.
    pub objects: Vec<String>,
}

/// How many names a message lists before "and N more".
const NAMES_SHOWN: usize = 3;

impl fmt::Display for Limitation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} cannot show {}", self.technique.name(), self.text)?;
        if self.objects.is_empty() {
            return Ok(());
        }
        let shown: Vec<String> = self
            .objects
            .iter()
            .take(NAMES_SHOWN)
            .map(|n| format!("`{n}`"))
            .collect();
        write!(f, " ({}", shown.join(", "))?;
        let more = self.objects.len().saturating_sub(NAMES_SHOWN);
        if more > 0 {
            write!(f, " and {more} more")?;
        }
        write!(f, ")")
    }
}

/// The features of `scene` that `technique` does not draw, in the order of
/// [`CANNOT_SHOW`], each with the objects that have it (with the scene's
/// own render settings).
pub fn limitations(scene: &Scene, technique: Technique) -> Vec<Limitation> {
    let settings = RenderSettings {
        technique,
        ..scene.render.clone()
    };
    limitations_of_render(scene, &settings)
}

/// [`limitations`] of rendering `scene` with `settings` (its technique and
/// settings such as depth cueing).
pub fn limitations_of_render(scene: &Scene, settings: &RenderSettings) -> Vec<Limitation> {
    let objects = Objects::of(scene);
    CANNOT_SHOW
        .iter()
        .filter(|(t, _, _)| *t == settings.technique)
        .filter_map(|&(technique, feature, text)| {
            let (present, objects) = present(scene, settings, &objects, feature);
            present.then_some(Limitation {
                technique,
                feature,
                text,
                objects,
            })
        })
        .collect()
}

/// The scene's objects as the messages name them, with the materials each
/// uses.
struct Objects<'a> {
    /// Display names: the object's name (`object N` without one), with the
    /// material's name added where several objects share the name.
    names: Vec<String>,
    /// The materials each object uses (its own, or a mesh's per-face ones).
    materials: Vec<Vec<&'a Material>>,
}

impl<'a> Objects<'a> {
    fn of(scene: &'a Scene) -> Self {
        let mut count: HashMap<&str, usize> = HashMap::new();
        for o in &scene.objects {
            *count.entry(o.name.as_str()).or_default() += 1;
        }
        let names = (scene.objects.iter().enumerate())
            .map(|(i, o)| {
                let name = if o.name.is_empty() {
                    format!("object {i}")
                } else {
                    o.name.clone()
                };
                match scene.materials.get(o.material.index()) {
                    Some(m) if count[o.name.as_str()] > 1 && !o.name.is_empty() => {
                        format!("{name} ({})", m.name)
                    }
                    _ => name,
                }
            })
            .collect();
        let materials = scene
            .objects
            .iter()
            .map(|o| {
                let faces = match o.geometry {
                    Geometry::Mesh(m) => scene
                        .meshes
                        .get(m.index())
                        .map_or(&[][..], |mesh| &mesh.face_materials[..]),
                    Geometry::Sphere { .. } => &[],
                };
                let ids: &[MaterialId] = if faces.is_empty() {
                    std::slice::from_ref(&o.material)
                } else {
                    faces
                };
                let mut used = vec![false; scene.materials.len()];
                for id in ids {
                    if let Some(u) = used.get_mut(id.index()) {
                        *u = true;
                    }
                }
                (scene.materials.iter().zip(used))
                    .filter_map(|(m, u)| u.then_some(m))
                    .collect()
            })
            .collect();
        Self { names, materials }
    }

    /// The names of the objects with a material for which `has` holds.
    fn with(&self, has: impl Fn(&Material) -> bool) -> Vec<String> {
        (self.names.iter().zip(&self.materials))
            .filter(|(_, ms)| ms.iter().any(|m| has(m)))
            .map(|(n, _)| n.clone())
            .collect()
    }
}

fn transparent(m: &Material) -> bool {
    m.is_transparent() || (m.alpha_mode == AlphaMode::Blend && m.alpha < 1.0)
}

/// A polygon is large when its longest edge is at least this fraction of the
/// scene's bounding-box diagonal: a highlight or a shadow edge can then fall
/// inside it, between the points where flat and Gouraud shading light it.
const LARGE_POLYGON: f32 = 0.1;

/// The names of the mesh objects with a large polygon (see [`LARGE_POLYGON`]).
fn objects_with_large_polygons(scene: &Scene, objects: &Objects<'_>) -> Vec<String> {
    let mut longest = vec![0.0f32; scene.objects.len()];
    for (i, o) in scene.objects.iter().enumerate() {
        let Geometry::Mesh(id) = o.geometry else {
            continue;
        };
        let Some(mesh) = scene.meshes.get(id.index()) else {
            continue;
        };
        let m = o.transform.world_from_object();
        let world: Vec<_> = mesh
            .positions
            .iter()
            .map(|p| m.transform_point3(*p))
            .collect();
        for t in &mesh.indices {
            let Some(c) = t
                .iter()
                .map(|&v| world.get(v as usize))
                .collect::<Option<Vec<_>>>()
            else {
                continue;
            };
            for k in 0..3 {
                let e = (*c[(k + 1) % 3] - *c[k]).length();
                if e.is_finite() {
                    longest[i] = longest[i].max(e);
                }
            }
        }
    }
    let d = chiaro_io::world_bounds(scene).diagonal();
    if !(d.is_finite() && d > 0.0) {
        return Vec::new();
    }
    (objects.names.iter().zip(longest))
        .filter(|(_, l)| *l >= LARGE_POLYGON * d)
        .map(|(n, _)| n.clone())
        .collect()
}

/// Whether `scene` has `feature`, and the objects (or lights) that have it.
fn present(
    scene: &Scene,
    settings: &RenderSettings,
    objects: &Objects<'_>,
    feature: Feature,
) -> (bool, Vec<String>) {
    let named = |names: Vec<String>| (!names.is_empty(), names);
    match feature {
        Feature::Lights => {
            let mut names: Vec<String> = scene
                .lights
                .iter()
                .filter(|l| !matches!(l, Light::Ambient { .. }))
                .map(|l| format!("{} light", l.kind()))
                .collect();
            names.extend(objects.with(Material::is_emissive));
            named(names)
        }
        Feature::AmbientLight => named(
            scene
                .lights
                .iter()
                .filter(|l| matches!(l, Light::Ambient { intensity, color } if *intensity > 0.0 && color.max_element() > 0.0))
                .map(|l| format!("{} light", l.kind()))
                .collect(),
        ),
        Feature::EnvironmentLight => (scene.environment.is_some(), Vec::new()),
        Feature::Mirrors => named(objects.with(Material::is_reflective)),
        Feature::Refraction => named(objects.with(|m| {
            m.is_transparent() && m.ior != 1.0
        })),
        Feature::Transparency => named(objects.with(transparent)),
        Feature::Highlights => named(objects.with(|m| {
            m.specular.max_element() > 0.0
        })),
        Feature::NormalMaps => named(objects.with(|m| {
            m.normal_map.is_some() || m.bump.is_some()
        })),
        Feature::InsideLargePolygons => named(objects_with_large_polygons(scene, objects)),
        Feature::SpecularIndirect => named(objects.with(|m| {
            m.is_reflective() || transparent(m)
        })),
        Feature::DepthCue => (settings.depth_cue.is_some(), Vec::new()),
        Feature::VolumeShadows => (settings.shadows == ShadowMethod::Volume, Vec::new()),
        Feature::AlphaMask => named(objects.with(Material::is_masked)),
        Feature::AlphaMaskShadows => {
            if matches!(
                settings.shadows,
                ShadowMethod::Volume
                    | ShadowMethod::Object
                    | ShadowMethod::Scanline
            ) {
                named(objects.with(Material::is_masked))
            } else {
                (false, Vec::new())
            }
        }
    }
}

/// The README's table: for each technique, what it shows and what it
/// cannot (every entry of [`CANNOT_SHOW`]).
pub fn markdown_table() -> String {
    let mut out = String::from("| technique | shows | cannot show |\n| --- | --- | --- |\n");
    for &(t, shows) in SHOWS {
        let cannot: Vec<&str> = CANNOT_SHOW
            .iter()
            .filter(|(u, _, _)| *u == t)
            .map(|(_, _, text)| *text)
            .collect();
        let cannot = if cannot.is_empty() {
            "-".to_string()
        } else {
            cannot.join("; ")
        };
        out += &format!("| {} | {shows} | {cannot} |\n", t.name());
    }
    out
}
