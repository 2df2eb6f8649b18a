//! glTF 2.0 (`.gltf` with external or embedded base64 buffers, `.glb`) read
//! through the gltf crate into an [`Imported`] file.
//!
//! What is read: the default scene's node hierarchy (or every root node when
//! the file names no scene), each node's mesh primitives (triangles; strips
//! and fans are converted; points and lines are skipped with a warning) with
//! positions, normals, tangents (float, or normalized integers with
//! `KHR_mesh_quantization`), the two `TEXCOORD_n` sets a material's
//! textures read (the first into `Mesh::uvs`, a second into `uvs1`; each
//! texture names its set, a third set is one warning), `COLOR_0` and
//! sparse accessors, or the same from a `KHR_draco_mesh_compression`
//! stream; perspective cameras; `KHR_lights_punctual`; materials. A
//! skinned mesh is posed at its joints' rest transforms (the skinned
//! node's own transform ignored, glTF 2.0 section 3.7.3); morph targets
//! and animations are not applied, with one warning each.
//!
//! The file is checked before anything is read: JSON errors give the line
//! and column, schema errors the JSON path (`meshes[0].primitives[0].indices`),
//! a required extension chiaro does not implement (meshopt, ...) is an
//! error naming it, a file whose meshes hold no triangles is an error, and every accessor's type and byte range is checked
//! against its buffer, and every index against its vertex count, so a
//! malformed file gives an error, never a panic.
//!
//! # Materials (metallic-roughness to chiaro)
//!
//! Every material gets `model = torrance-sparrow` and a
//! [`MetallicRoughness`](chiaro_core::scene::MetallicRoughness) that
//! `PreparedScene::surface_material_lod`
//! evaluates per point (ARCHITECTURE.md, "glTF materials"): base colour =
//! `baseColorFactor * baseColorTexture * COLOR_0`, metallic and roughness =
//! factors times the B and G of `metallicRoughnessTexture`, then `kd =
//! base (1 - metallic)`, F0 `= mix(0.04, base, metallic)`, alpha =
//! roughness^2, `ka = 1` (the ambient term is `Ia ka (kd + F0)`, what a
//! uniform environment of radiance `Ia` gives). `occlusionTexture` (R, with
//! `strength`) scales the ambient term; `normalTexture` -> `normal_map`; `emissiveFactor *
//! KHR_materials_emissive_strength` -> `emission`, `emissiveTexture` ->
//! `emission_texture`; `KHR_materials_unlit` -> emission = base colour, no
//! reflection; `doubleSided: true` -> `Sidedness::TwoSided` (and emission
//! from both faces), `false` -> `Sidedness::Culled` (the backs invisible to
//! the eye); `alphaMode`/`alphaCutoff` ->
//! `alpha_mode`, and `BLEND` with a factor alpha below 1 -> `transmit = 1 -
//! alpha` (ior 1) drawn `interpolated`. Samplers give both wrap axes and
//! the min/mag/mip filters; `KHR_texture_transform` (and its `texCoord`
//! override) is applied to every texture slot, normal and occlusion
//! included.
//! `KHR_materials_transmission`, `_volume`, `_ior` and `_clearcoat` become
//! chiaro's glass (Fresnel dielectric, rough when the base is, Beer
//! absorption inside a volume, thin-walled without one) and clear coat
//! (`layers.rs`).
//!
//! # Lights
//!
//! glTF gives point and spot intensity in candela (lm/sr), so the
//! irradiance at distance d is `I cos(theta) / d^2`; chiaro's convention
//! (the radiometric convention, ARCHITECTURE.md) is `pi Ip cos(theta) / d^2`, hence `Ip = I / pi`
//! with inverse-square fall-off. Directional lights give illuminance in lux,
//! `E = pi Ip`, hence also `Ip = lux / pi`. Spot cones: `cone =
//! outerConeAngle`, `cone_softness = outer - inner` (degrees), Warn exponent
//! 0. `range` is ignored.

mod buffers;
mod draco;
mod extensions;
#[cfg(test)]
mod geometry_tests;
mod layers;
mod materials;
mod nodes;
mod primitives;
mod skins;
#[cfg(test)]
mod tests;
mod textures;

use crate::{Imported, IoError, Result};
use buffers::load_buffers;
use chiaro_core::Mat4;
use chiaro_core::budget::MemoryBudget;
use chiaro_core::scene::TextureId;
use extensions::unsupported_features;
use std::collections::{BTreeSet, HashMap};
use std::path::Path;

/// Extensions chiaro reads: a file may require them.
const SUPPORTED: &[&str] = &[
    "KHR_draco_mesh_compression",
    "KHR_lights_punctual",
    "KHR_materials_clearcoat",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_unlit",
    "KHR_materials_volume",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
];

/// Largest glTF file read (bytes); bigger inputs are refused.
const MAX_FILE_BYTES: u64 = 2 << 30;

/// Reads a `.gltf` or `.glb` file and the buffers and images it references
/// (relative to its directory, or embedded). Returns its meshes, materials,
/// textures, placed objects (node world matrices), lights and cameras, or an
/// [`IoError`] naming the file and what is wrong (with the JSON line and
/// column or the JSON path).
pub fn load_gltf(path: &Path) -> Result<Imported> {
    load_gltf_within(path, MemoryBudget::process())
}

/// [`load_gltf`] within `budget`: an accessor whose count no bytes back (it
/// has no buffer view) is refused when its decoded size exceeds it.
pub fn load_gltf_within(path: &Path, budget: MemoryBudget) -> Result<Imported> {
    let bytes = crate::files::read_file_within(path, budget, MAX_FILE_BYTES)?;
    let base = path.parent().unwrap_or_else(|| Path::new("."));
    load_gltf_slice_within(&bytes, Some(base), path, budget)
}

/// Reads glTF or GLB bytes held in memory. External files resolve against
/// `base` (none: only embedded data is allowed); `path` names the input in
/// messages. Returns what [`load_gltf`] returns.
pub fn load_gltf_slice(bytes: &[u8], base: Option<&Path>, path: &Path) -> Result<Imported> {
    load_gltf_slice_within(bytes, base, path, MemoryBudget::process())
}

/// [`load_gltf_slice`] within `budget` (see [`load_gltf_within`]).
pub fn load_gltf_slice_within(
    bytes: &[u8],
    base: Option<&Path>,
    path: &Path,
    budget: MemoryBudget,
) -> Result<Imported> {
    // Every known panic is prevented by the checks below; a panic inside the
    // gltf crate on input nobody foresaw is still turned into an error.
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read(bytes, base, path, budget)
    }));
    match result {
        Ok(r) => r,
        Err(_) => Err(IoError::format(
            path,
            "malformed glTF: the reader failed on this file",
        )),
    }
}

fn in_err(path: &Path, location: impl Into<String>, message: impl Into<String>) -> IoError {
    IoError::In {
        path: path.to_path_buf(),
        location: location.into(),
        message: message.into(),
    }
}

/// `<major>.<minor>` as numbers (glTF 2.0 section 3.2, `asset.version`).
fn parse_version(v: &str) -> Option<(u32, u32)> {
    let (major, minor) = v.split_once('.')?;
    Some((major.parse().ok()?, minor.parse().ok()?))
}

/// glTF 2.0 section 5.2: a reader loads any 2.x file (later minor
/// versions only add what it may ignore) unless `asset.minVersion` asks
/// for a later version than the one it implements, 2.0.
fn check_version(asset: &gltf::json::Asset, path: &Path) -> Result<()> {
    match parse_version(&asset.version) {
        Some((2, _)) => {}
        _ => {
            return Err(in_err(
                path,
                "asset.version",
                format!(
                    "the file is glTF {:?}; chiaro reads glTF 2.x",
                    asset.version
                ),
            ));
        }
    }
    if let Some(min) = &asset.min_version {
        let ok = parse_version(min).is_some_and(|v| v <= (2, 0));
        if !ok {
            return Err(in_err(
                path,
                "asset.minVersion",
                format!("the file requires glTF {min} or later; chiaro reads glTF 2.0"),
            ));
        }
    }
    Ok(())
}

fn read(bytes: &[u8], base: Option<&Path>, path: &Path, budget: MemoryBudget) -> Result<Imported> {
    let is_glb = bytes.starts_with(b"glTF");
    // The gltf crate subtracts the 12-byte header from the declared length unchecked.
    if is_glb {
        let declared = bytes
            .get(8..12)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        match declared {
            Some(n) if n >= 12 => {}
            _ => {
                return Err(IoError::format(
                    path,
                    "malformed GLB header: the declared length is shorter than the header",
                ));
            }
        }
    }
    // Parse without validation, check extensions, then validate.
    let gltf = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| match e {
        gltf::Error::Deserialize(j) if !is_glb => IoError::At {
            path: path.to_path_buf(),
            line: j.line(),
            column: j.column(),
            message: format!("invalid glTF JSON: {j}"),
        },
        gltf::Error::Deserialize(j) => in_err(
            path,
            format!("JSON chunk line {} column {}", j.line(), j.column()),
            format!("invalid glTF JSON: {j}"),
        ),
        other => IoError::format(path, format!("not a readable glTF/GLB file: {other}")),
    })?;
    let doc = &gltf.document;
    check_version(&doc.as_json().asset, path)?;
    for (i, ext) in doc.extensions_required().enumerate() {
        if !SUPPORTED.contains(&ext) {
            return Err(in_err(
                path,
                format!("extensionsRequired[{i}]"),
                format!(
                    "the file requires extension {ext}, which chiaro does not support{}",
                    match ext {
                        "EXT_meshopt_compression" => " (meshopt-compressed buffers)",
                        _ => "",
                    }
                ),
            ));
        }
    }
    // The validator itself indexes `accessors` with each POSITION index unchecked.
    let root = doc.as_json();
    for (i, mesh) in root.meshes.iter().enumerate() {
        for (j, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &prim.attributes {
                if index.value() >= root.accessors.len() {
                    return Err(in_err(
                        path,
                        format!("meshes[{i}].primitives[{j}].attributes"),
                        format!(
                            "{} refers to accessor {} but there are {}",
                            semantic.to_string(),
                            index.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    let json_bytes = if is_glb {
        gltf::Glb::from_slice(bytes)
            .map(|g| g.json.into_owned())
            .unwrap_or_default()
    } else {
        bytes.to_vec()
    };
    let json = serde_json::from_slice::<serde_json::Value>(&json_bytes).unwrap_or_default();
    // Draco primitives' accessors have no buffer view: the stream holds their data.
    let draco_accessors: BTreeSet<String> = draco_accessors(&json)
        .into_iter()
        .map(|i| format!("accessors[{i}].bufferView"))
        .collect();
    {
        use gltf::json::validation::Validate;
        let mut errors = Vec::new();
        let root = doc.as_json();
        root.validate(root, gltf::json::Path::new, &mut |p, e| {
            let p = p();
            // The validator knows only the extensions of the crate's features.
            let s = p.to_string();
            let ours = (s.starts_with("extensions") && SUPPORTED.iter().any(|x| s.contains(x)))
                || draco_accessors.contains(&s);
            if !ours {
                errors.push((p, e));
            }
        });
        if let Some((p, e)) = errors.first() {
            let more = if errors.len() > 1 {
                format!(" (and {} more problems)", errors.len() - 1)
            } else {
                String::new()
            };
            return Err(in_err(path, p.to_string(), format!("{e}{more}")));
        }
    }
    let warnings = unsupported_features(&json, path);
    let material_extensions = layers::material_extensions(Some(&json));

    let buffers = load_buffers(doc, base, gltf.blob.clone(), path, budget)?;
    let node_world = rest_world_matrices(doc);
    let mut b = Builder {
        doc,
        buffers: &buffers,
        base,
        path,
        out: Imported::default(),
        mesh_cache: HashMap::new(),
        material_map: HashMap::new(),
        texture_map: HashMap::new(),
        noted: BTreeSet::new(),
        node_world,
        json,
        uv_slots: textures::UvSlots::default(),
        budget,
        decoded_bytes: std::cell::Cell::new(0),
        material_extensions,
    };
    b.out.warnings = warnings;
    // The default scene, else the first, else every root node.
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let roots: Vec<gltf::Node> = match scene {
        Some(s) => s.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    let mut visited = vec![false; doc.nodes().len()];
    // Reversed so that popping visits nodes in document order.
    let mut stack: Vec<(gltf::Node, Mat4)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Mat4::IDENTITY))
        .collect();
    // Depth-first with an explicit stack; a node is visited once even if a
    // (malformed) file makes it the child of several parents or of itself.
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            b.note("a node is reachable twice (cycle or shared child): visited once");
            continue;
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if !world.is_finite() {
            b.note("a node has a non-finite transform: skipped");
            continue;
        }
        b.node(&node, world)?;
        let children: Vec<gltf::Node> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world));
        }
    }
    if b.out.objects.is_empty() && doc.meshes().len() > 0 {
        let mut msg = String::from("nothing to render: the file has no triangle primitives");
        for w in &b.out.warnings {
            msg.push_str("\n  ");
            msg.push_str(w);
        }
        return Err(IoError::format(path, msg));
    }
    Ok(b.out)
}

/// The accessors that `KHR_draco_mesh_compression` primitives of the
/// document `json` name (attributes and indices): the Draco stream holds
/// their data, so they have no buffer view.
fn draco_accessors(json: &serde_json::Value) -> BTreeSet<u64> {
    let mut out = BTreeSet::new();
    let meshes = json.get("meshes").and_then(serde_json::Value::as_array);
    for mesh in meshes.into_iter().flatten() {
        let prims = mesh.get("primitives").and_then(serde_json::Value::as_array);
        for prim in prims.into_iter().flatten() {
            if prim
                .pointer("/extensions/KHR_draco_mesh_compression")
                .is_none()
            {
                continue;
            }
            let attrs = prim
                .get("attributes")
                .and_then(serde_json::Value::as_object);
            let named = attrs.into_iter().flat_map(|a| a.values());
            out.extend(
                named
                    .chain(prim.get("indices"))
                    .filter_map(serde_json::Value::as_u64),
            );
        }
    }
    out
}

/// The world matrix of every node at its rest (non-animated) transform:
/// the product of its own and its ancestors' local matrices (glTF 2.0
/// section 3.5.3). A node reached through a cycle, or whose product is not
/// finite, gets the identity (the traversal skips it with a warning).
fn rest_world_matrices(doc: &gltf::Document) -> Vec<Mat4> {
    let n = doc.nodes().len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for node in doc.nodes() {
        for c in node.children() {
            // The first parent wins, as in the traversal.
            parent[c.index()].get_or_insert(node.index());
        }
    }
    let local: Vec<Mat4> = doc
        .nodes()
        .map(|node| Mat4::from_cols_array_2d(&node.transform().matrix()))
        .collect();
    let mut world: Vec<Option<Mat4>> = vec![None; n];
    // `walk[i] == start + 1` marks the nodes of the current walk (cycles).
    let mut walk = vec![0usize; n];
    for start in 0..n {
        // Walk up to a node whose matrix is known (or a root), then down.
        let mut chain = vec![start];
        walk[start] = start + 1;
        while let Some(&top) = chain.last() {
            match parent[top] {
                Some(p) if world[p].is_none() && walk[p] != start + 1 => {
                    walk[p] = start + 1;
                    chain.push(p);
                }
                _ => break,
            }
        }
        for &i in chain.iter().rev() {
            if world[i].is_some() {
                continue;
            }
            let above = parent[i].and_then(|p| world[p]).unwrap_or(Mat4::IDENTITY);
            let m = above * local[i];
            world[i] = Some(if m.is_finite() { m } else { Mat4::IDENTITY });
        }
    }
    world
        .into_iter()
        .map(|m| m.unwrap_or(Mat4::IDENTITY))
        .collect()
}

/// A texture reference: image, colour space, sampler, the bits of its
/// uv transform (offset, rotation, scale) and its uv slot.
type TextureKey = (usize, bool, Option<usize>, [u32; 5], u8);

/// A converted primitive: its mesh index in the output and its material.
type ConvertedPrimitive = (usize, Option<usize>);

struct Builder<'a> {
    doc: &'a gltf::Document,
    buffers: &'a [gltf::buffer::Data],
    base: Option<&'a Path>,
    path: &'a Path,
    out: Imported,
    /// (mesh, primitive) -> (mesh index in out, material) or None when skipped.
    mesh_cache: HashMap<(usize, usize), Option<ConvertedPrimitive>>,
    material_map: HashMap<usize, usize>,
    texture_map: HashMap<TextureKey, Option<TextureId>>,
    noted: BTreeSet<String>,
    /// Every node's world matrix at rest (skins read their joints' from it).
    node_world: Vec<Mat4>,
    /// The document's JSON (what the gltf crate does not expose).
    json: serde_json::Value,
    /// The uv slots of the material being converted.
    uv_slots: textures::UvSlots,
    /// Bounds what the accessors decode to, together.
    budget: MemoryBudget,
    /// Bytes the accessors checked so far decode to.
    decoded_bytes: std::cell::Cell<u64>,
    /// Each material's `extensions` object (JSON null where it has none):
    /// the layers `layers.rs` reads.
    material_extensions: Vec<serde_json::Value>,
}

impl Builder<'_> {
    /// Records a warning once per file.
    fn note(&mut self, msg: impl Into<String>) {
        let msg = msg.into();
        if self.noted.insert(msg.clone()) {
            self.out
                .warnings
                .push(format!("{}: {msg}", self.path.display()));
        }
    }
}
