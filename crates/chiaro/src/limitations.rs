//! What each technique cannot show of a scene, said once and by name.
//!
//! [`limitations`] lists, for a scene and a technique, the features the
//! scene has that the technique does not draw (radiosity's mirrors and
//! glass, scan conversion's refraction, ...), each with the objects that
//! have it. [`crate::render_with`] emits each one as a
//! `Progress::warning`, `chiaro info` lists them per technique, and
//! [`markdown_table`] and [`methods_table`] are the README's tables of the
//! techniques, so all say the same. Each technique's features and words
//! come from its renderer's [`Description`] ([`crate::description`]),
//! written beside its code.

use chiaro_core::scene::{
    AlphaMode, Geometry, Light, Material, MaterialId, RenderSettings, Scene, ShadowMethod,
    Technique,
};
use chiaro_core::technique::Description;
use std::collections::HashMap;
use std::fmt;

pub use chiaro_core::technique::Feature;

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
/// its description's `cannot_show`, each with the objects that have it (with the scene's
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
    let technique = settings.technique;
    descriptions_of(technique)
        .flat_map(|d| d.cannot_show)
        .filter_map(|&(feature, text)| {
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

/// The description of `technique` (none only for a renderer that forgot
/// it, which the tests refuse).
fn descriptions_of(technique: Technique) -> impl Iterator<Item = &'static Description> {
    crate::description(technique).into_iter()
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
        Feature::RoughTransmission => named(objects.with(|m| {
            m.fresnel
                && m.is_transparent()
                && m.model == chiaro_core::scene::ReflectanceModel::TorranceSparrow
                && m.roughness >= chiaro_core::shading::dielectric::MIN_ROUGH_ALPHA
        })),
        Feature::ClearCoat => named(objects.with(|m| {
            m.clearcoat.is_some_and(|c| c.factor > 0.0)
        })),
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

/// The README's table of what each technique shows and what it cannot
/// (every `cannot_show` entry of its description).
pub fn markdown_table() -> String {
    let mut out = String::from("| technique | shows | cannot show |\n| --- | --- | --- |\n");
    for t in Technique::ALL {
        for d in descriptions_of(t) {
            let cannot: Vec<&str> = d.cannot_show.iter().map(|(_, text)| *text).collect();
            let cannot = if cannot.is_empty() {
                "-".to_string()
            } else {
                cannot.join("; ")
            };
            out += &format!("| {} | {} | {cannot} |\n", t.name(), d.shows);
        }
    }
    out
}

/// The README's table of what each technique is and its `--technique`
/// name.
pub fn methods_table() -> String {
    let mut out = String::from("| technique | `--technique` | what it is |\n| --- | --- | --- |\n");
    for t in Technique::ALL {
        for d in descriptions_of(t) {
            out += &format!("| {} | `{}` | {} |\n", d.title, t.name(), d.method);
        }
    }
    out
}
