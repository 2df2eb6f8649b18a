//! `chiaro export`: a scene written for another renderer, Mitsuba 3 XML
//! ([`mitsuba`]) or pbrt-v4 ([`pbrt`]), so that a peer renders the same
//! scene by construction.
//!
//! Only what maps exactly onto the path tracer's view of the scene is
//! written: the camera, the film size, the sample count, the path depth,
//! meshes (PLY files beside the output for Mitsuba, inline for pbrt),
//! analytic spheres, point, directional and hard-edged spot lights,
//! emissive surfaces, a lat-long environment (Mitsuba), and the materials
//! this module's `Surface` lists. Anything else is refused with an error
//! naming the scene object and the feature; the few approximations a peer
//! comparison can live with (a diffuse base under a glossy coat, a
//! mip-mapped texture, a soft spot edge) are written with a warning. The
//! files are written whole or not at all: every file is built in memory
//! first, companions are written through a temporary file and renamed,
//! and the scene file itself last.

pub mod mitsuba;
pub mod pbrt;

use crate::output::write_atomically;
use crate::{IoError, Result};
use chiaro_core::geometry::normals::vertex_normals;
use chiaro_core::scene::{
    Attenuation, Distribution, Geometry, Light, Material, Mesh, ReflectanceModel, Scene, Sidedness,
    Texture, TextureId, WrapMode,
};
use chiaro_core::{Mat4, Vec2, Vec3};
use std::f32::consts::PI;
use std::path::{Path, PathBuf};

/// The format [`export`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Mitsuba 3 XML (`scene.xml`, meshes as PLY files beside it).
    Mitsuba,
    /// pbrt-v4 (`scene.pbrt`, meshes inline).
    Pbrt,
}

impl std::str::FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "mitsuba" | "mitsuba3" | "xml" => Ok(Format::Mitsuba),
            "pbrt" | "pbrt-v4" | "pbrt4" => Ok(Format::Pbrt),
            other => Err(format!(
                "unknown export format \"{other}\" (expected mitsuba or pbrt)"
            )),
        }
    }
}

/// What [`export`] wrote.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Exported {
    /// Every file written, the scene file last.
    pub files: Vec<PathBuf>,
    /// One line per approximate mapping (naming the object and feature).
    pub warnings: Vec<String>,
}

/// Writes `scene` as a `format` scene file at `out` (meshes beside it for
/// Mitsuba, named after `out`). Returns the files written and the
/// warnings of approximate mappings.
///
/// # Errors
/// [`IoError::In`] naming the scene object and the feature that has no
/// exact counterpart (nothing is written then); [`IoError::Io`] when a file
/// cannot be written.
pub fn export(scene: &Scene, format: Format, out: &Path) -> Result<Exported> {
    let files = match format {
        Format::Mitsuba => mitsuba::write(scene, out)?,
        Format::Pbrt => pbrt::write(scene, out)?,
    };
    let mut exported = Exported {
        files: Vec::new(),
        warnings: files.warnings,
    };
    // Companions first, the scene file (which names them) last.
    for (path, bytes) in files.companions.iter().chain([&files.main]) {
        write_atomically(path, bytes)?;
        exported.files.push(path.clone());
    }
    Ok(exported)
}

/// The files of one export, built in memory before anything is written.
#[derive(Debug, Default)]
pub(crate) struct Files {
    /// The scene file.
    pub main: (PathBuf, Vec<u8>),
    /// Files it names (meshes).
    pub companions: Vec<(PathBuf, Vec<u8>)>,
    /// Approximate mappings.
    pub warnings: Vec<String>,
}

/// A refusal: `location` names the scene object, `message` the feature.
pub(crate) fn refuse(out: &Path, location: String, message: impl Into<String>) -> IoError {
    IoError::In {
        path: out.to_path_buf(),
        location,
        message: message.into(),
    }
}

/// `materials[i] ("name")`, `objects[i] ("name")`, `lights[i] (kind)`.
pub(crate) fn material_at(scene: &Scene, i: usize) -> String {
    format!("materials[{i}] (\"{}\")", scene.materials[i].name)
}
pub(crate) fn object_at(scene: &Scene, i: usize) -> String {
    format!("objects[{i}] (\"{}\")", scene.objects[i].name)
}

/// A colour parameter: a constant or an image texture.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Colour {
    Const(Vec3),
    Texture(TextureId),
}

/// A material as the path tracer sees it, in the terms both peers have.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Surface {
    /// Lambert.
    Diffuse(Colour),
    /// A conductor: the mirror (`rough` None) or a microfacet lobe, its
    /// Fresnel from `eta + i k` times `tint` (Mitsuba's
    /// `specular_reflectance`).
    Conductor {
        tint: Vec3,
        eta: Vec3,
        k: Vec3,
        rough: Option<(f32, Distribution)>,
    },
    /// A smooth Fresnel dielectric of relative IOR `ior`.
    Dielectric { ior: f32, transmittance: Vec3 },
    /// A diffuse base under a grey dielectric coat (approximate: chiaro
    /// adds the two lobes, the peers layer them).
    Plastic {
        diffuse: Colour,
        ior: f32,
        rough: Option<(f32, Distribution)>,
    },
}

/// The material's surface, whether the back reflects (two-sided), and its
/// emitted radiance (`None` for none).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Bsdf {
    pub surface: Surface,
    pub two_sided: bool,
    pub emission: Option<Vec3>,
}

/// Classifies material `i` for export, or refuses it naming the feature;
/// approximations push a warning.
pub(crate) fn bsdf_of(
    scene: &Scene,
    i: usize,
    out: &Path,
    warnings: &mut Vec<String>,
) -> Result<Bsdf> {
    let m: &Material = &scene.materials[i];
    let at = || material_at(scene, i);
    let no = |what: &str| {
        Err(refuse(
            out,
            at(),
            format!("{what} has no exact counterpart"),
        ))
    };
    if m.metallic_roughness.is_some() {
        return no("glTF metallic-roughness");
    }
    if m.bump.is_some() || m.normal_map.is_some() {
        return no("a bump or normal map");
    }
    if m.occlusion.is_some() {
        return no("an occlusion texture");
    }
    if m.alpha_mode != chiaro_core::scene::AlphaMode::Opaque {
        return no("alpha MASK or BLEND");
    }
    if m.emission_texture.is_some() {
        return no("an emission texture");
    }
    if m.absorption != Vec3::ZERO {
        return no("Beer absorption inside a dielectric");
    }
    if m.sidedness == Sidedness::Culled {
        return no("a culled back face (sidedness = \"culled\")");
    }
    let emission = if m.is_emissive() {
        if m.emission_two_sided {
            return no("emission from both faces (the peers' area emitters are one-sided)");
        }
        Some(m.emission)
    } else {
        None
    };
    let (kd, ks, kr, kt) = (m.diffuse, m.specular, m.reflect, m.transmit);
    let zero = |v: Vec3| v == Vec3::ZERO;
    let has_diffuse = !zero(kd) || m.texture.is_some();
    let diffuse = match m.texture {
        Some(t) if kd == Vec3::ONE => Colour::Texture(t),
        Some(_) => return no("a texture multiplied by a diffuse colour other than 1"),
        None => Colour::Const(kd),
    };
    let lobe = if zero(ks) {
        None
    } else if m.model == ReflectanceModel::TorranceSparrow {
        Some((m.roughness, m.distribution))
    } else {
        return no("a Phong or Blinn specular lobe");
    };
    let grey = |v: Vec3| v.x == v.y && v.y == v.z;
    let surface = if !zero(kt) {
        if !m.fresnel {
            return no("fixed-weight transmission (kt without fresnel = true)");
        }
        if has_diffuse || lobe.is_some() {
            return no("a diffuse or glossy lobe on a dielectric");
        }
        Surface::Dielectric {
            ior: m.ior,
            transmittance: kt,
        }
    } else if !has_diffuse {
        // Mitsuba's ideal mirror `none` (eta 0, k 1) reflects 1 at every
        // angle: a fixed kr and Schlick's F0 = 1 are that conductor.
        let (eta, k) = match m.conductor {
            Some(c) => (c.eta, c.k),
            None => (Vec3::ZERO, Vec3::ONE),
        };
        match (lobe, zero(kr)) {
            (None, false) => Surface::Conductor {
                tint: kr,
                eta,
                k,
                rough: None,
            },
            (Some(rough), true) if m.conductor.is_some() || ks == Vec3::ONE => Surface::Conductor {
                tint: if m.conductor.is_some() { ks } else { Vec3::ONE },
                eta,
                k,
                rough: Some(rough),
            },
            (Some(_), true) => {
                return no(
                    "Schlick's Fresnel with F0 = ks < 1 (give the material a conductor = { eta, k })",
                );
            }
            (Some(_), false) => return no("a mirror and a glossy lobe together"),
            (None, true) => Surface::Diffuse(Colour::Const(Vec3::ZERO)),
        }
    } else {
        match (lobe, zero(kr)) {
            (None, true) => Surface::Diffuse(diffuse),
            (coat, _) if m.conductor.is_none() => {
                let f0 = if coat.is_some() { ks } else { kr };
                if !grey(f0) || f0.x >= 1.0 || (coat.is_some() && !zero(kr)) {
                    return no("a diffuse base under a coloured or doubled specular coat");
                }
                let s = f0.x.sqrt();
                let ior = (1.0 + s) / (1.0 - s);
                warnings.push(format!(
                    "{}: approximate: a diffuse base plus a {} lobe of F0 {} is written as {} with IOR {ior} (the peer layers them with internal scattering)",
                    at(),
                    if coat.is_some() { "glossy" } else { "mirror" },
                    f0.x,
                    if coat.is_some() { "a rough plastic" } else { "a plastic" },
                ));
                Surface::Plastic {
                    diffuse,
                    ior,
                    rough: coat,
                }
            }
            _ => return no("a diffuse base under a conductor"),
        }
    };
    let two_sided = m.sidedness == Sidedness::TwoSided;
    Ok(Bsdf {
        surface,
        two_sided,
        emission,
    })
}

/// An image texture's file, wrap and filter, checked for export.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Bitmap {
    pub path: PathBuf,
    pub wrap: WrapMode,
    pub nearest: bool,
}

/// The bitmap behind texture `t` used by material `i`, or a refusal.
pub(crate) fn bitmap_of(
    scene: &Scene,
    i: usize,
    t: TextureId,
    out: &Path,
    warnings: &mut Vec<String>,
) -> Result<Bitmap> {
    let at = || material_at(scene, i);
    let Some(tex) = scene.textures.get(t.index()) else {
        return Err(refuse(out, at(), "its texture index is out of range"));
    };
    let img = match tex {
        Texture::Image(img) => img,
        Texture::Procedural(_) => {
            return Err(refuse(
                out,
                at(),
                "a procedural texture has no exact counterpart",
            ));
        }
    };
    let path = PathBuf::from(&img.source);
    if !path.is_file() {
        return Err(refuse(
            out,
            at(),
            format!(
                "its texture \"{}\" is not a file the peer could read",
                img.source
            ),
        ));
    }
    if img.wrap_t.is_some_and(|w| w != img.wrap) {
        return Err(refuse(out, at(), "different wrap modes in u and v"));
    }
    let id = chiaro_core::scene::UvTransform::default();
    if img.uv_transform != id {
        return Err(refuse(out, at(), "a texture transform"));
    }
    if img.mip_filter.is_some() || img.mag_filter != img.min_filter {
        warnings.push(format!(
            "{}: approximate: texture \"{}\" is mip-mapped in chiaro; the peer filters level 0 only",
            at(),
            img.source
        ));
    }
    let path = std::fs::canonicalize(&path).unwrap_or(path);
    Ok(Bitmap {
        path,
        wrap: img.wrap,
        nearest: img.mag_filter == chiaro_core::scene::Filter::Nearest,
    })
}

/// A mesh ready to write: positions, normals (empty: face normals), uvs,
/// triangles; one per material of a mesh with per-face materials.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct OutMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub indices: Vec<[u32; 3]>,
}

/// The meshes of object `i` by material index: its mesh split by face
/// material, with the normals chiaro shades it with (none when flat;
/// the crease-angle normals when the mesh has none).
pub(crate) fn meshes_of(scene: &Scene, i: usize, out: &Path) -> Result<Vec<(usize, OutMesh)>> {
    let o = &scene.objects[i];
    let at = || object_at(scene, i);
    let Geometry::Mesh(id) = o.geometry else {
        return Ok(Vec::new());
    };
    let Some(mesh) = scene.meshes.get(id.index()) else {
        return Err(refuse(out, at(), "its mesh index is out of range"));
    };
    if !mesh.colors.is_empty() {
        return Err(refuse(
            out,
            at(),
            "vertex colours have no exact counterpart",
        ));
    }
    let mesh: Mesh = if o.smooth && mesh.normals.is_empty() {
        // The normals chiaro derives (crease angle), made explicit.
        let s = vertex_normals(&mesh.positions, &mesh.indices, o.crease_angle_degrees);
        let pick = |v: &[Vec2]| -> Vec<Vec2> {
            if v.is_empty() {
                Vec::new()
            } else {
                s.source_vertex.iter().map(|&k| v[k as usize]).collect()
            }
        };
        Mesh {
            positions: s
                .source_vertex
                .iter()
                .map(|&k| mesh.positions[k as usize])
                .collect(),
            normals: s.normals.clone(),
            uvs: pick(&mesh.uvs),
            indices: s.indices.clone(),
            face_materials: mesh.face_materials.clone(),
            ..Mesh::default()
        }
    } else {
        mesh.clone()
    };
    let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
    for t in 0..mesh.indices.len() {
        let m = mesh
            .face_materials
            .get(t)
            .map_or(o.material.index(), |m| m.index());
        match groups.iter_mut().find(|(k, _)| *k == m) {
            Some((_, v)) => v.push(t),
            None => groups.push((m, vec![t])),
        }
    }
    if let [(m, _)] = groups.as_slice() {
        // One material: the mesh as it is, vertex order kept.
        if *m >= scene.materials.len() {
            return Err(refuse(out, at(), "its material index is out of range"));
        }
        if mesh
            .indices
            .iter()
            .flatten()
            .any(|&v| v as usize >= mesh.positions.len())
        {
            return Err(refuse(out, at(), "a vertex index is out of range"));
        }
        let keep_normals = o.smooth && mesh.normals.len() == mesh.positions.len();
        let keep_uvs = mesh.uvs.len() == mesh.positions.len();
        return Ok(vec![(
            *m,
            OutMesh {
                positions: mesh.positions.clone(),
                normals: if keep_normals {
                    mesh.normals.clone()
                } else {
                    Vec::new()
                },
                uvs: if keep_uvs {
                    mesh.uvs.clone()
                } else {
                    Vec::new()
                },
                indices: mesh.indices.clone(),
            },
        )]);
    }
    let mut outs = Vec::new();
    for (m, tris) in groups {
        if m >= scene.materials.len() {
            return Err(refuse(out, at(), "a face material index is out of range"));
        }
        let mut remap = vec![u32::MAX; mesh.positions.len()];
        let mut om = OutMesh::default();
        for &t in &tris {
            let mut tri = [0u32; 3];
            for (c, &v) in mesh.indices[t].iter().enumerate() {
                let v = v as usize;
                if v >= mesh.positions.len() {
                    return Err(refuse(out, at(), "a vertex index is out of range"));
                }
                if remap[v] == u32::MAX {
                    remap[v] = om.positions.len() as u32;
                    om.positions.push(mesh.positions[v]);
                    if o.smooth && mesh.normals.len() == mesh.positions.len() {
                        om.normals.push(mesh.normals[v]);
                    }
                    if mesh.uvs.len() == mesh.positions.len() {
                        om.uvs.push(mesh.uvs[v]);
                    }
                }
                tri[c] = remap[v];
            }
            om.indices.push(tri);
        }
        outs.push((m, om));
    }
    Ok(outs)
}

/// The world centre and radius of a sphere object placed by `m`, or a
/// refusal when `m` does not scale uniformly.
pub(crate) fn sphere_of(
    scene: &Scene,
    i: usize,
    radius: f32,
    m: Mat4,
    out: &Path,
) -> Result<(Vec3, f32)> {
    let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| m.transform_vector3(a).length());
    let s = axes[0];
    if axes.iter().any(|a| (a - s).abs() > 1e-5 * s.max(1e-12)) {
        return Err(refuse(
            out,
            object_at(scene, i),
            "a non-uniformly scaled sphere has no exact counterpart",
        ));
    }
    Ok((m.transform_point3(Vec3::ZERO), radius * s))
}

/// A number as the shortest text that reads back as the same `f32`.
/// A light as both writers write it, its radiant quantity times pi
/// (chiaro's irradiance is `pi I cos / d^2`).
pub(crate) enum OutLight {
    Point {
        position: Vec3,
        intensity: Vec3,
    },
    Directional {
        direction: Vec3,
        irradiance: Vec3,
    },
    Spot {
        position: Vec3,
        direction: Vec3,
        cone_degrees: f32,
        softness_degrees: f32,
        intensity: Vec3,
    },
}

/// What a format calls the parts its light messages name.
pub(crate) struct LightWords {
    /// The parameter a spot's soft edge is written as ("pbrt's conedelta").
    pub soft_edge: &'static str,
    /// Whose area lights are surfaces ("pbrt's").
    pub surfaces: &'static str,
}

/// Light `i` of `scene` as the writers write it: `None` for an ambient light
/// (with a warning), an error for one that has no exact counterpart.
pub(crate) fn light_of(
    scene: &Scene,
    i: usize,
    out: &Path,
    words: &LightWords,
    w: &mut Vec<String>,
) -> Result<Option<OutLight>> {
    let l = &scene.lights[i];
    let at = format!("lights[{i}] ({})", l.kind());
    Ok(Some(match l {
        Light::Ambient { .. } => {
            w.push(format!(
                "{at}: ignored: an ambient light (the path tracer ignores it too)"
            ));
            return Ok(None);
        }
        Light::Point {
            position,
            color,
            intensity,
            attenuation,
        } => {
            if *attenuation != Attenuation::InverseSquare {
                return Err(refuse(
                    out,
                    at,
                    "attenuation other than inverse_square has no exact counterpart",
                ));
            }
            OutLight::Point {
                position: *position,
                intensity: PI * *color * *intensity,
            }
        }
        Light::Directional {
            direction,
            color,
            intensity,
        } => OutLight::Directional {
            direction: *direction,
            irradiance: PI * *color * *intensity,
        },
        Light::Spot(s) => {
            if s.attenuation != Attenuation::InverseSquare
                || s.exponent != 0.0
                || !s.flaps.is_empty()
            {
                return Err(refuse(
                    out,
                    at,
                    "a spot with Warn's exponent, flaps or a non-physical attenuation has no exact counterpart",
                ));
            }
            if s.cone_softness_degrees > 0.0 {
                w.push(format!(
                    "{at}: approximate: the cone's soft edge is written as {} (its fall-off curve differs)",
                    words.soft_edge
                ));
            }
            OutLight::Spot {
                position: s.position,
                direction: s.direction,
                cone_degrees: s.cone_degrees,
                softness_degrees: s.cone_softness_degrees,
                intensity: PI * s.color * s.intensity,
            }
        }
        Light::Area { .. } => {
            return Err(refuse(
                out,
                at,
                format!(
                    "chiaro's area lights are invisible and reached by light sampling only, {} are surfaces: write it as an object with an emissive material",
                    words.surfaces
                ),
            ));
        }
    }))
}

pub(crate) fn num(x: f32) -> String {
    format!("{x}")
}

/// Three numbers separated by `sep`.
pub(crate) fn nums(v: Vec3, sep: &str) -> String {
    [v.x, v.y, v.z].map(num).join(sep)
}

/// The path of a companion file: `out`'s stem, `suffix`, beside `out`.
pub(crate) fn companion(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "scene".to_owned(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}{suffix}"))
}

/// Binary little-endian PLY bytes of `m` (`x y z`, `nx ny nz` when it
/// has normals, `u v` when it has uvs; triangles as `vertex_indices`).
pub(crate) fn ply_bytes(m: &OutMesh) -> Vec<u8> {
    let mut head =
        String::from("ply\nformat binary_little_endian 1.0\ncomment written by chiaro export\n");
    head += &format!("element vertex {}\n", m.positions.len());
    head += "property float x\nproperty float y\nproperty float z\n";
    if !m.normals.is_empty() {
        head += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if !m.uvs.is_empty() {
        head += "property float u\nproperty float v\n";
    }
    head += &format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        m.indices.len()
    );
    let mut bytes = head.into_bytes();
    for (k, p) in m.positions.iter().enumerate() {
        let mut put = |v: f32| bytes.extend_from_slice(&v.to_le_bytes());
        put(p.x);
        put(p.y);
        put(p.z);
        if let Some(n) = m.normals.get(k) {
            put(n.x);
            put(n.y);
            put(n.z);
        }
        if let Some(uv) = m.uvs.get(k) {
            put(uv.x);
            put(uv.y);
        }
    }
    for t in &m.indices {
        bytes.push(3);
        for v in t {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

#[cfg(test)]
mod tests;
