//! glTF 2.0 (`.gltf` with external or embedded base64 buffers, `.glb`) read
//! through the gltf crate into an [`Imported`] file.
//!
//! What is read: the default scene's node hierarchy (or every root node when
//! the file names no scene), each node's mesh primitives (triangles; strips
//! and fans are converted; points and lines are skipped with a warning) with
//! positions, normals, tangents (float, or normalized integers with
//! `KHR_mesh_quantization`), the material's `TEXCOORD_n`, `COLOR_0` and
//! sparse accessors; perspective cameras; `KHR_lights_punctual`; materials.
//! Skins, morph targets and animations are not applied: the bind pose is
//! loaded and a warning given.
//!
//! The file is checked before anything is read: JSON errors give the line
//! and column, schema errors the JSON path (`meshes[0].primitives[0].indices`),
//! a required extension chiaro does not implement (Draco, meshopt, ...) is an
//! error naming it, a file whose meshes hold no triangles is an error, and every accessor's type and byte range is checked
//! against its buffer, and every index against its vertex count, so a
//! malformed file gives an error, never a panic.
//!
//! # Materials (metallic-roughness to chiaro)
//!
//! Every material gets `model = torrance-sparrow` and a
//! [`MetallicRoughness`] that `PreparedScene::surface_material_lod`
//! evaluates per point (ARCHITECTURE.md, "glTF materials"): base colour =
//! `baseColorFactor * baseColorTexture * COLOR_0`, metallic and roughness =
//! factors times the B and G of `metallicRoughnessTexture`, then `kd =
//! base (1 - metallic)`, F0 `= mix(0.04, base, metallic)`, alpha =
//! roughness^2, `ka = 1` (the ambient term is `Ia ka (kd + F0)`, what a
//! uniform environment of radiance `Ia` gives). `occlusionTexture` (R, with
//! `strength`) scales the ambient term; `normalTexture` -> `normal_map`; `emissiveFactor *
//! KHR_materials_emissive_strength` -> `emission`, `emissiveTexture` ->
//! `emission_texture`; `KHR_materials_unlit` -> emission = base colour, no
//! reflection; `doubleSided` -> `two_sided`, and `false` -> `cull_backface`
//! (the backs invisible to the eye); `alphaMode`/`alphaCutoff` ->
//! `alpha_mode`, and `BLEND` with a factor alpha below 1 -> `transmit = 1 -
//! alpha` (ior 1) drawn `interpolated`. Samplers give both wrap axes and
//! the min/mag/mip filters; `KHR_texture_transform` is applied to the base
//! colour, metallic-roughness and emissive textures; the mesh carries the
//! one `TEXCOORD_n` set its material's textures use.
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

use crate::{Imported, ImportedObject, IoError, Result};
use chiaro_core::budget::MemoryBudget;
use chiaro_core::scene::{
    AlphaMode, Camera, Filter, Light, Material, Mesh, MetallicRoughness, NamedCamera, Occlusion,
    ReflectanceModel, SpotLight, Texture, TextureId, TransparencyMode, UvTransform, WrapMode,
};
use chiaro_core::scene::{Attenuation, ImageTexture};
use chiaro_core::{Mat4, Vec2, Vec3, Vec4};
use gltf::accessor::util::{Item, Iter};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use std::collections::{BTreeSet, HashMap};
use std::path::Path;

/// Extensions chiaro reads: a file may require them.
const SUPPORTED: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_unlit",
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
    let meta = std::fs::metadata(path).map_err(|e| IoError::io(path, e))?;
    if meta.len() > MAX_FILE_BYTES {
        return Err(IoError::format(path, "file too large"));
    }
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
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
                        "KHR_draco_mesh_compression" => " (Draco-compressed meshes)",
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
                            "{semantic:?} refers to accessor {} but there are {}",
                            index.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    {
        use gltf::json::validation::Validate;
        let mut errors = Vec::new();
        let root = doc.as_json();
        root.validate(root, gltf::json::Path::new, &mut |p, e| {
            let p = p();
            // The validator knows only the extensions of the crate's features.
            let s = p.to_string();
            let ours = s.starts_with("extensions") && SUPPORTED.iter().any(|x| s.contains(x));
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
    let json_bytes = if is_glb {
        gltf::Glb::from_slice(bytes)
            .map(|g| g.json.into_owned())
            .unwrap_or_default()
    } else {
        bytes.to_vec()
    };
    let warnings = serde_json::from_slice::<serde_json::Value>(&json_bytes)
        .map(|json| unsupported_features(&json, path))
        .unwrap_or_default();

    let buffers = load_buffers(doc, base, gltf.blob.clone(), path)?;
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
        budget,
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

/// Loads every buffer, checking URIs before handing them to the gltf crate.
fn load_buffers(
    doc: &gltf::Document,
    base: Option<&Path>,
    mut blob: Option<Vec<u8>>,
    path: &Path,
) -> Result<Vec<gltf::buffer::Data>> {
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let loc = format!("buffers[{}]", buffer.index());
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            check_uri(uri).map_err(|m| in_err(path, format!("{loc}.uri"), m))?;
            if !uri.starts_with("data:") && base.is_none() {
                return Err(in_err(
                    path,
                    format!("{loc}.uri"),
                    "external buffer without a directory",
                ));
            }
        }
        let data = gltf::buffer::Data::from_source_and_blob(buffer.source(), base, &mut blob)
            .map_err(|e| in_err(path, loc.clone(), format!("cannot load buffer: {e}")))?;
        if data.len() < buffer.length() {
            return Err(in_err(
                path,
                loc,
                format!(
                    "buffer holds {} bytes but byteLength says {}",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// A relative URI must percent-decode to UTF-8 (the gltf crate would panic otherwise).
fn check_uri(uri: &str) -> std::result::Result<(), String> {
    if uri.contains(':') {
        return Ok(());
    }
    String::from_utf8(percent_decode_bytes(uri))
        .map(|_| ())
        .map_err(|_| format!("URI {uri:?} does not decode to UTF-8"))
}

/// A texture reference: image, colour space, sampler and the bits of its
/// uv transform (offset, rotation, scale).
type TextureKey = (usize, bool, Option<usize>, [u32; 5]);

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
    /// Bounds what accessors without a buffer view may expand to.
    budget: MemoryBudget,
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

    fn node(&mut self, node: &gltf::Node, world: Mat4) -> Result<()> {
        if let Some(cam) = node.camera() {
            match cam.projection() {
                gltf::camera::Projection::Perspective(p) => {
                    let eye = world.transform_point3(Vec3::ZERO);
                    let forward = world.transform_vector3(Vec3::NEG_Z).try_normalize();
                    let up = world.transform_vector3(Vec3::Y).try_normalize();
                    let fov = p.yfov().to_degrees();
                    match (forward, up) {
                        (Some(f), Some(u)) if fov > 0.0 && fov < 180.0 && eye.is_finite() => {
                            let near = if p.znear() > 0.0 { p.znear() } else { 0.01 };
                            let far = p
                                .zfar()
                                .filter(|f| f.is_finite() && *f > near)
                                .unwrap_or(near * 1.0e7);
                            // Named after the camera, else its node, else its index.
                            let name = cam
                                .name()
                                .or(node.name())
                                .map_or_else(|| format!("camera{}", cam.index()), str::to_owned);
                            self.out.cameras.push(NamedCamera {
                                name,
                                camera: Camera {
                                    eye,
                                    look_at: eye + f,
                                    up: u,
                                    fov_y_degrees: fov,
                                    near,
                                    far,
                                },
                            });
                        }
                        _ => self.note("a camera with a degenerate transform or fov was skipped"),
                    }
                }
                // Warned about once, by `unsupported_features`.
                gltf::camera::Projection::Orthographic(_) => {}
            }
        }
        if let Some(light) = node.light() {
            self.light(&light, world);
        }
        let Some(mesh) = node.mesh() else {
            return Ok(());
        };
        for prim in mesh.primitives() {
            let key = (mesh.index(), prim.index());
            let entry = match self.mesh_cache.get(&key) {
                Some(e) => *e,
                None => {
                    let e = self.primitive(&mesh, &prim)?;
                    self.mesh_cache.insert(key, e);
                    e
                }
            };
            if let Some((mesh_index, material)) = entry {
                let name = match (node.name(), mesh.name()) {
                    (Some(n), _) => format!("{n}#{}", prim.index()),
                    (None, Some(m)) => format!("{m}#{}", prim.index()),
                    (None, None) => format!("node{}#{}", node.index(), prim.index()),
                };
                self.out.objects.push(ImportedObject {
                    name,
                    mesh: mesh_index,
                    matrix: world,
                    material,
                });
            }
        }
        Ok(())
    }

    fn light(&mut self, light: &gltf::khr_lights_punctual::Light, world: Mat4) {
        use gltf::khr_lights_punctual::Kind;
        let color = Vec3::from(light.color());
        // Candela (or lux) to chiaro's Ip: divide by pi (module docs).
        let intensity = light.intensity() / std::f32::consts::PI;
        if !(color.is_finite() && intensity.is_finite() && intensity >= 0.0) {
            self.note("a light with invalid colour or intensity was skipped");
            return;
        }
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world.transform_vector3(Vec3::NEG_Z).try_normalize();
        let Some(direction) = direction else {
            self.note("a light with a degenerate transform was skipped");
            return;
        };
        let l = match light.kind() {
            Kind::Directional => Light::Directional {
                direction,
                color,
                intensity,
            },
            Kind::Point => Light::Point {
                position,
                color,
                intensity,
                attenuation: Attenuation::InverseSquare,
            },
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let outer = outer_cone_angle.to_degrees().clamp(1e-3, 90.0);
                let inner = inner_cone_angle.to_degrees().clamp(0.0, outer);
                Light::Spot(SpotLight {
                    position,
                    direction,
                    color,
                    intensity,
                    attenuation: Attenuation::InverseSquare,
                    exponent: 0.0,
                    cone_degrees: outer,
                    cone_softness_degrees: outer - inner,
                    flaps: Vec::new(),
                })
            }
        };
        self.out.lights.push(l);
    }

    /// Checks an accessor: element type among `allowed`, count >= 1, every
    /// byte it reads inside its buffer view and buffer (so its count is
    /// backed by bytes), the sparse count within the count, and, for an
    /// accessor without a buffer view (zeros, whose count nothing backs),
    /// its decoded size within the memory budget.
    fn check_accessor(
        &self,
        acc: &gltf::Accessor,
        what: &str,
        dims: &[Dimensions],
        types: &[DataType],
    ) -> Result<()> {
        let loc = format!("accessors[{}]", acc.index());
        if !dims.contains(&acc.dimensions()) || !types.contains(&acc.data_type()) {
            return Err(in_err(
                self.path,
                loc,
                format!(
                    "{what}: unsupported element type {:?} of {:?}",
                    acc.dimensions(),
                    acc.data_type()
                ),
            ));
        }
        if acc.count() == 0 {
            return Err(in_err(self.path, loc, format!("{what}: count is 0")));
        }
        if acc.view().is_none() {
            // Decoded, an element takes at most 16 bytes (a `Vec4` of f32).
            let bytes = chiaro_core::budget::bytes_of(acc.count() as u64, 16);
            self.budget
                .check(
                    &format!("{what}: {} elements without a buffer view", acc.count()),
                    bytes,
                )
                .map_err(|m| in_err(self.path, loc.clone(), m))?;
        }
        let elem = acc.size();
        let check_view =
            |view: &gltf::buffer::View, offset: usize, count: usize, elem: usize, vloc: &str| {
                let stride = view.stride().unwrap_or(elem);
                let data_len = self
                    .buffers
                    .get(view.buffer().index())
                    .map_or(0, |d| d.len());
                let view_end = view.offset().checked_add(view.length());
                let need = stride
                    .checked_mul(count - 1)
                    .and_then(|x| x.checked_add(elem))
                    .and_then(|x| x.checked_add(offset));
                match (view_end, need) {
                    (Some(end), Some(need))
                        if stride >= elem && end <= data_len && need <= view.length() =>
                    {
                        Ok(())
                    }
                    _ => Err(in_err(
                        self.path,
                        vloc.to_string(),
                        format!("{what}: data lies outside its buffer view or buffer"),
                    )),
                }
            };
        if let Some(view) = acc.view() {
            check_view(&view, acc.offset(), acc.count(), elem, &loc)?;
        }
        if let Some(sparse) = acc.sparse() {
            let sloc = format!("{loc}.sparse");
            let n = sparse.count();
            if n == 0 {
                return Err(in_err(
                    self.path,
                    sloc,
                    format!("{what}: sparse count is 0"),
                ));
            }
            if n > acc.count() {
                return Err(in_err(
                    self.path,
                    sloc,
                    format!(
                        "{what}: sparse count {n} exceeds the accessor's count {}",
                        acc.count()
                    ),
                ));
            }
            let idx = sparse.indices();
            check_view(
                &idx.view(),
                idx.offset(),
                n,
                idx.index_type().size(),
                &format!("{sloc}.indices"),
            )?;
            let vals = sparse.values();
            check_view(
                &vals.view(),
                vals.offset(),
                n,
                elem,
                &format!("{sloc}.values"),
            )?;
        }
        Ok(())
    }

    /// Converts one primitive; `None` when it is skipped (not triangles, no positions).
    fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
    ) -> Result<Option<ConvertedPrimitive>> {
        let loc = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
        let mode = prim.mode();
        if matches!(
            mode,
            Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
        ) {
            self.note(format!(
                "{loc}: {mode:?} primitives are skipped (only triangles are drawn)"
            ));
            return Ok(None);
        }
        let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
            self.note(format!("{loc}: no POSITION attribute: skipped"));
            return Ok(None);
        };
        const QUANTIZED: &[DataType] = &[
            DataType::F32,
            DataType::I8,
            DataType::U8,
            DataType::I16,
            DataType::U16,
        ];
        const SIGNED: &[DataType] = &[DataType::F32, DataType::I8, DataType::I16];
        self.check_accessor(&pos_acc, "POSITION", &[Dimensions::Vec3], QUANTIZED)?;
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = match read_f32::<3>(&pos_acc, buffers) {
            Some(v) => v.into_iter().map(Vec3::from).collect(),
            None => vec![Vec3::ZERO; pos_acc.count()],
        };
        let n = positions.len();
        if n != pos_acc.count() {
            return Err(in_err(
                self.path,
                loc,
                "POSITION data is shorter than its count",
            ));
        }
        if !positions.iter().all(|p| p.is_finite()) {
            return Err(in_err(
                self.path,
                format!("{loc}.attributes.POSITION"),
                "a vertex position is not finite",
            ));
        }
        let mut m = Mesh {
            name: format!(
                "{}:{}#{}",
                self.path
                    .file_name()
                    .map(|f| f.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                mesh.name().unwrap_or("mesh"),
                prim.index()
            ),
            positions,
            ..Mesh::default()
        };
        if let Some(acc) = prim.get(&gltf::Semantic::Normals) {
            self.check_accessor(&acc, "NORMAL", &[Dimensions::Vec3], SIGNED)?;
            if let Some(v) = read_f32::<3>(&acc, buffers) {
                let v: Vec<Vec3> = v
                    .into_iter()
                    .map(|x| Vec3::from(x).normalize_or_zero())
                    .collect();
                if v.len() == n && v.iter().all(|x| x.is_finite() && *x != Vec3::ZERO) {
                    m.normals = v;
                } else {
                    self.note(format!(
                        "{loc}: invalid NORMAL data: normals will be computed"
                    ));
                }
            }
        }
        if let Some(acc) = prim.get(&gltf::Semantic::Tangents) {
            self.check_accessor(&acc, "TANGENT", &[Dimensions::Vec4], SIGNED)?;
            if let Some(v) = read_f32::<4>(&acc, buffers) {
                let v: Vec<Vec4> = v.into_iter().map(Vec4::from).collect();
                if v.len() == n && v.iter().all(|x| x.is_finite()) {
                    m.tangents = v;
                }
            }
        }
        // The one uv set the material's textures use (chiaro meshes carry one).
        let set = prim.material().index().map_or(0, |_| {
            // Mixed sets are warned about once, by `unsupported_features`.
            uv_set(&prim.material()).0
        });
        if let Some(acc) = prim.get(&gltf::Semantic::TexCoords(set)) {
            self.check_accessor(
                &acc,
                &format!("TEXCOORD_{set}"),
                &[Dimensions::Vec2],
                QUANTIZED,
            )?;
            if let Some(v) = read_f32::<2>(&acc, buffers) {
                let v: Vec<Vec2> = v.into_iter().map(Vec2::from).collect();
                if v.len() == n && v.iter().all(|x| x.is_finite()) {
                    m.uvs = v;
                }
            }
        } else if set != 0 {
            self.note(format!(
                "{loc}: the material uses TEXCOORD_{set}, which is missing"
            ));
        }
        if let Some(acc) = prim.get(&gltf::Semantic::Colors(0)) {
            self.check_accessor(
                &acc,
                "COLOR_0",
                &[Dimensions::Vec3, Dimensions::Vec4],
                &[DataType::F32, DataType::U8, DataType::U16],
            )?;
            if let Some(it) = reader.read_colors(0) {
                let v: Vec<Vec4> = it.into_rgba_f32().map(Vec4::from).collect();
                if v.len() == n && v.iter().all(|x| x.is_finite()) {
                    m.colors = v.iter().map(|c| c.truncate()).collect();
                    // The alpha is kept only where it is not all 1 (RGB colours read as 1).
                    if v.iter().any(|c| c.w < 1.0) {
                        m.color_alphas = v.iter().map(|c| c.w).collect();
                    }
                }
            }
        }
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    "indices",
                    &[Dimensions::Scalar],
                    &[DataType::U8, DataType::U16, DataType::U32],
                )?;
                let v: Vec<u32> = reader
                    .read_indices()
                    .map(|it| it.into_u32().collect())
                    .unwrap_or_else(|| vec![0; acc.count()]);
                if let Some(bad) = v.iter().find(|&&i| i as usize >= n) {
                    return Err(in_err(
                        self.path,
                        format!("{loc}.indices"),
                        format!("index {bad} out of range ({n} vertices)"),
                    ));
                }
                v
            }
            None => (0..n as u32).collect(),
        };
        m.indices = match mode {
            Mode::TriangleStrip => (2..indices.len())
                .map(|i| {
                    let (a, b, c) = (indices[i - 2], indices[i - 1], indices[i]);
                    if i % 2 == 0 { [a, b, c] } else { [b, a, c] }
                })
                .collect(),
            Mode::TriangleFan => (2..indices.len())
                .map(|i| [indices[i - 1], indices[i], indices[0]])
                .collect(),
            _ => {
                if !indices.len().is_multiple_of(3) {
                    self.note(format!(
                        "{loc}: index count is not a multiple of 3: the rest is ignored"
                    ));
                }
                indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect()
            }
        };
        let material = match prim.material().index() {
            Some(i) => Some(self.material(i)?),
            None => None,
        };
        self.out.meshes.push(m);
        Ok(Some((self.out.meshes.len() - 1, material)))
    }

    fn material(&mut self, index: usize) -> Result<usize> {
        if let Some(&i) = self.material_map.get(&index) {
            return Ok(i);
        }
        let Some(gm) = self.doc.materials().nth(index) else {
            return Err(in_err(
                self.path,
                format!("materials[{index}]"),
                "missing material",
            ));
        };
        let pbr = gm.pbr_metallic_roughness();
        let base = Vec4::from(pbr.base_color_factor());
        let base_rgb = if base.is_finite() {
            base.truncate().max(Vec3::ZERO)
        } else {
            Vec3::ONE
        };
        let mr = MetallicRoughness {
            base_color: base_rgb,
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            texture: None,
        };
        let (diffuse, specular, roughness) =
            MetallicRoughness::coefficients(mr.base_color, mr.metallic, mr.roughness);
        let strength = gm.emissive_strength().unwrap_or(1.0).max(0.0);
        let mut mat = Material {
            name: gm
                .name()
                .map_or_else(|| format!("material{index}"), str::to_string),
            diffuse,
            specular,
            model: ReflectanceModel::TorranceSparrow,
            roughness,
            // Physically based: uniform ambient radiance Ia is reflected as
            // Ia kd (and Ia F0 off the specular lobe), not a tenth of it.
            ambient: Vec3::ONE,
            emission: Vec3::from(gm.emissive_factor()).max(Vec3::ZERO) * strength,
            two_sided: gm.double_sided(),
            // glTF 2.0 3.9.5: a single-sided material's back faces are culled.
            cull_backface: !gm.double_sided(),
            metallic_roughness: Some(mr),
            ..Material::default()
        };
        if let Some(info) = pbr.base_color_texture() {
            mat.texture = self.info_texture(&info, true);
        }
        if let Some(info) = pbr.metallic_roughness_texture() {
            let t = self.info_texture(&info, false);
            if let Some(m) = mat.metallic_roughness.as_mut() {
                m.texture = t;
            }
        }
        if let Some(info) = gm.emissive_texture() {
            mat.emission_texture = self.info_texture(&info, true);
        }
        if let Some(nt) = gm.normal_texture() {
            mat.normal_map = self.texture_info(nt.texture(), UvTransform::default(), false);
        }
        if let Some(ot) = gm.occlusion_texture() {
            mat.occlusion = self
                .texture_info(ot.texture(), UvTransform::default(), false)
                .map(|texture| Occlusion {
                    texture,
                    strength: ot.strength().clamp(0.0, 1.0),
                });
        }
        mat.alpha = if base.w.is_finite() {
            base.w.clamp(0.0, 1.0)
        } else {
            1.0
        };
        mat.alpha_mode = match gm.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: gm.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        if mat.alpha_mode == AlphaMode::Blend {
            // The techniques draw the coverage as straight-through transmission
            // (per point in the surface layer: factor x texture x vertex alpha).
            mat.transmit = Vec3::splat(1.0 - mat.alpha);
            mat.ior = 1.0;
            mat.transparency = TransparencyMode::Interpolated;
        }
        if gm.unlit() {
            // KHR_materials_unlit: the base colour is emitted, nothing reflected.
            mat.emission = base_rgb;
            mat.emission_texture = mat.texture.take();
            mat.diffuse = Vec3::ZERO;
            mat.specular = Vec3::ZERO;
            mat.ambient = Vec3::ZERO;
            mat.metallic_roughness = None;
            mat.occlusion = None;
        }
        for c in [&mut mat.diffuse, &mut mat.specular, &mut mat.emission] {
            if !c.is_finite() {
                *c = Vec3::ZERO;
            }
        }
        self.out.materials.push(mat);
        let i = self.out.materials.len() - 1;
        self.material_map.insert(index, i);
        Ok(i)
    }

    /// The texture of a `textureInfo` (base colour, metallic-roughness,
    /// emissive), with its sampler and `KHR_texture_transform`.
    fn info_texture(&mut self, info: &gltf::texture::Info, srgb: bool) -> Option<TextureId> {
        let transform = info.texture_transform().map(|t| UvTransform {
            offset: Vec2::from(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from(t.scale()),
        });
        self.texture_info(info.texture(), transform.unwrap_or_default(), srgb)
    }

    fn texture_info(
        &mut self,
        tex: gltf::Texture,
        transform: UvTransform,
        srgb: bool,
    ) -> Option<TextureId> {
        let image = tex.source();
        let sampler = tex.sampler();
        let tb = [
            transform.offset.x,
            transform.offset.y,
            transform.rotation,
            transform.scale.x,
            transform.scale.y,
        ]
        .map(f32::to_bits);
        let key = (image.index(), srgb, sampler.index(), tb);
        if let Some(t) = self.texture_map.get(&key) {
            return *t;
        }
        if !(transform.offset.is_finite()
            && transform.rotation.is_finite()
            && transform.scale.is_finite())
        {
            self.note("a non-finite KHR_texture_transform was ignored");
        }
        let wrap = |w| match w {
            gltf::texture::WrappingMode::ClampToEdge => WrapMode::Clamp,
            gltf::texture::WrappingMode::MirroredRepeat => WrapMode::Mirror,
            gltf::texture::WrappingMode::Repeat => WrapMode::Repeat,
        };
        use gltf::texture::{MagFilter, MinFilter};
        let mag_filter = match sampler.mag_filter() {
            Some(MagFilter::Nearest) => Filter::Nearest,
            _ => Filter::Linear,
        };
        // Unset: trilinear (the spec leaves it to the implementation).
        let (min_filter, mip_filter) = match sampler.min_filter() {
            Some(MinFilter::Nearest) => (Filter::Nearest, None),
            Some(MinFilter::Linear) => (Filter::Linear, None),
            Some(MinFilter::NearestMipmapNearest) => (Filter::Nearest, Some(Filter::Nearest)),
            Some(MinFilter::LinearMipmapNearest) => (Filter::Linear, Some(Filter::Nearest)),
            Some(MinFilter::NearestMipmapLinear) => (Filter::Nearest, Some(Filter::Linear)),
            Some(MinFilter::LinearMipmapLinear) | None => (Filter::Linear, Some(Filter::Linear)),
        };
        let id = match self.decode_image(&image, srgb) {
            Ok(mut img) => {
                img.wrap = wrap(sampler.wrap_s());
                img.wrap_t = Some(wrap(sampler.wrap_t()));
                img.mag_filter = mag_filter;
                img.min_filter = min_filter;
                img.mip_filter = mip_filter;
                if transform.offset.is_finite()
                    && transform.rotation.is_finite()
                    && transform.scale.is_finite()
                {
                    img.uv_transform = transform;
                }
                self.out.textures.push(Texture::Image(img));
                Some(TextureId(self.out.textures.len() as u32 - 1))
            }
            Err(msg) => {
                self.note(format!("images[{}]: {msg}: texture ignored", image.index()));
                None
            }
        };
        self.texture_map.insert(key, id);
        id
    }

    fn decode_image(
        &self,
        image: &gltf::Image,
        srgb: bool,
    ) -> std::result::Result<ImageTexture, String> {
        // The gltf crate's `source()` unwraps these (found by fuzzing).
        if let Some(json) = self.doc.as_json().images.get(image.index()) {
            if json.buffer_view.is_some() && json.mime_type.is_none() {
                return Err("an image in a buffer view needs a mimeType".into());
            }
            if json.buffer_view.is_none() && json.uri.is_none() {
                return Err("an image needs a uri or a bufferView".into());
            }
        }
        let (bytes, source): (Vec<u8>, String) = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let data = self
                    .buffers
                    .get(view.buffer().index())
                    .ok_or("buffer missing")?;
                let end = view.offset().checked_add(view.length()).ok_or("bad view")?;
                let slice = data
                    .0
                    .get(view.offset()..end)
                    .ok_or("image view outside its buffer")?;
                (
                    slice.to_vec(),
                    format!("{}#images[{}]", self.path.display(), image.index()),
                )
            }
            gltf::image::Source::Uri { uri, .. } => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let b64 = rest
                        .split_once(";base64,")
                        .map(|(_, b)| b)
                        .ok_or("data URI is not base64")?;
                    (
                        decode_base64(b64)?,
                        format!("{}#images[{}]", self.path.display(), image.index()),
                    )
                } else {
                    check_uri(uri)?;
                    let base = self.base.ok_or("external image without a directory")?;
                    let rel = percent_decode(uri);
                    let p = base.join(&rel);
                    let bytes = std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))?;
                    (bytes, p.display().to_string())
                }
            }
        };
        crate::images::load_texture_bytes_within(&bytes, &source, srgb, self.budget)
            .map_err(|e| e.to_string())
    }
}

/// The uv set the textures of `gm` use (after `KHR_texture_transform`'s
/// `texCoord` override), the base colour's when they differ, and whether they do.
fn uv_set(gm: &gltf::Material) -> (u32, bool) {
    let info_set = |i: &gltf::texture::Info| {
        i.texture_transform()
            .and_then(|t| t.tex_coord())
            .unwrap_or(i.tex_coord())
    };
    let pbr = gm.pbr_metallic_roughness();
    let sets: Vec<u32> = [
        pbr.base_color_texture().map(|i| info_set(&i)),
        pbr.metallic_roughness_texture().map(|i| info_set(&i)),
        gm.emissive_texture().map(|i| info_set(&i)),
        gm.normal_texture().map(|t| t.tex_coord()),
        gm.occlusion_texture().map(|t| t.tex_coord()),
    ]
    .into_iter()
    .flatten()
    .collect();
    let first = sets.first().copied().unwrap_or(0);
    (first, sets.iter().any(|&s| s != first))
}

/// Reads an accessor of `N` components as floats: floats as they are,
/// integers (`KHR_mesh_quantization`) normalized to `[0, 1]` / `[-1, 1]` when
/// the accessor says so, else converted. `None` for other component types.
fn read_f32<const N: usize>(
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
) -> Option<Vec<[f32; N]>>
where
    [f32; N]: Item,
    [i8; N]: Item,
    [u8; N]: Item,
    [i16; N]: Item,
    [u16; N]: Item,
{
    fn conv<T: Copy + Into<f32>, const N: usize>(a: [T; N], scale: Option<f32>) -> [f32; N] {
        a.map(|c| {
            let v: f32 = c.into();
            scale.map_or(v, |s| (v / s).max(-1.0))
        })
    }
    let get = |b: gltf::Buffer| buffers.get(b.index()).map(|d| &d.0[..]);
    let norm = |s: f32| acc.normalized().then_some(s);
    let a = acc.clone();
    Some(match acc.data_type() {
        DataType::F32 => Iter::<[f32; N]>::new(a, get)?.collect(),
        DataType::I8 => Iter::<[i8; N]>::new(a, get)?
            .map(|x| conv(x, norm(127.0)))
            .collect(),
        DataType::U8 => Iter::<[u8; N]>::new(a, get)?
            .map(|x| conv(x, norm(255.0)))
            .collect(),
        DataType::I16 => Iter::<[i16; N]>::new(a, get)?
            .map(|x| conv(x, norm(32767.0)))
            .collect(),
        DataType::U16 => Iter::<[u16; N]>::new(a, get)?
            .map(|x| conv(x, norm(65535.0)))
            .collect(),
        DataType::U32 => return None,
    })
}

fn percent_decode(s: &str) -> String {
    String::from_utf8_lossy(&percent_decode_bytes(s)).into_owned()
}

/// Decodes `%XX` escapes (RFC 3986); malformed escapes are kept as they are.
fn percent_decode_bytes(s: &str) -> Vec<u8> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let Some(v) = std::str::from_utf8(&bytes[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    out
}

/// Standard base64 (RFC 4648), padding optional.
fn decode_base64(s: &str) -> std::result::Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return Err("invalid base64 data".into()),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Ok(out)
}

// ---------------------------------------------------------------------------
// Unsupported features: one warning each, naming the file and a JSON pointer.

/// The features of the glTF JSON `json` that chiaro ignores or drops, one
/// warning per feature naming `path`, the JSON pointer of its first
/// occurrence and how many more there are: extensions chiaro does not
/// implement (wherever an `extensions` object names one, else their place
/// in `extensionsUsed`), skins, animations, morph targets and weights,
/// orthographic cameras, a light's `range`, scenes other than the one
/// loaded, and materials whose textures use different `texCoord` sets.
fn unsupported_features(json: &serde_json::Value, path: &Path) -> Vec<String> {
    use serde_json::Value;
    // (feature, pointers), in the order first met.
    let mut found: Vec<(String, Vec<String>)> = Vec::new();
    let mut add = |feature: String, pointer: String| match found.iter_mut().find(|f| f.0 == feature)
    {
        Some(f) => f.1.push(pointer),
        None => found.push((feature, vec![pointer])),
    };
    fn walk(v: &Value, ptr: &str, add: &mut dyn FnMut(String, String)) {
        match v {
            Value::Object(map) => {
                if let Some(Value::Object(exts)) = map.get("extensions") {
                    for k in exts.keys() {
                        if !SUPPORTED.contains(&k.as_str()) {
                            add(
                                format!("extension {k} is not supported and is ignored"),
                                format!("{ptr}/extensions/{}", escape(k)),
                            );
                        }
                    }
                }
                for (k, child) in map {
                    walk(child, &format!("{ptr}/{}", escape(k)), add);
                }
            }
            Value::Array(items) => {
                for (i, child) in items.iter().enumerate() {
                    walk(child, &format!("{ptr}/{i}"), add);
                }
            }
            _ => {}
        }
    }
    /// RFC 6901 escaping of one pointer token.
    fn escape(k: &str) -> String {
        k.replace('~', "~0").replace('/', "~1")
    }
    let array = |key: &str| {
        json.get(key)
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    walk(json, "", &mut add);
    for (i, ext) in array("extensionsUsed").iter().enumerate() {
        if let Some(ext) = ext.as_str().filter(|e| !SUPPORTED.contains(e)) {
            add(
                format!("extension {ext} is not supported and is ignored"),
                format!("/extensionsUsed/{i}"),
            );
        }
    }
    for (i, _) in array("skins").iter().enumerate() {
        add(
            "skins are not applied (the bind pose is loaded)".into(),
            format!("/skins/{i}"),
        );
    }
    for (i, _) in array("animations").iter().enumerate() {
        add("animations are ignored".into(), format!("/animations/{i}"));
    }
    let morph = "morph targets are ignored (the base shape is loaded)";
    for (m, mesh) in array("meshes").iter().enumerate() {
        if let Some(prims) = mesh.get("primitives").and_then(Value::as_array) {
            for (p, prim) in prims.iter().enumerate() {
                if prim.get("targets").is_some() {
                    add(morph.into(), format!("/meshes/{m}/primitives/{p}/targets"));
                }
            }
        }
        if mesh.get("weights").is_some() {
            add(morph.into(), format!("/meshes/{m}/weights"));
        }
    }
    for (n, node) in array("nodes").iter().enumerate() {
        if node.get("weights").is_some() {
            add(morph.into(), format!("/nodes/{n}/weights"));
        }
    }
    for (c, cam) in array("cameras").iter().enumerate() {
        if cam.get("type").and_then(Value::as_str) == Some("orthographic") {
            add(
                "orthographic cameras are skipped".into(),
                format!("/cameras/{c}"),
            );
        }
    }
    let lights = json
        .pointer("/extensions/KHR_lights_punctual/lights")
        .and_then(Value::as_array);
    for (l, light) in lights.into_iter().flatten().enumerate() {
        if light.get("range").is_some() {
            add(
                "light `range` is ignored (inverse-square fall-off everywhere)".into(),
                format!("/extensions/KHR_lights_punctual/lights/{l}/range"),
            );
        }
    }
    let loaded = json.get("scene").and_then(Value::as_u64).unwrap_or(0) as usize;
    for (s, _) in array("scenes").iter().enumerate() {
        if s != loaded {
            add(
                "scenes other than the default one are not loaded".into(),
                format!("/scenes/{s}"),
            );
        }
    }
    // texCoord of each textureInfo (KHR_texture_transform's override first).
    let slots = [
        "/pbrMetallicRoughness/baseColorTexture",
        "/pbrMetallicRoughness/metallicRoughnessTexture",
        "/emissiveTexture",
        "/normalTexture",
        "/occlusionTexture",
    ];
    for (m, mat) in array("materials").iter().enumerate() {
        let mut first: Option<u64> = None;
        for slot in slots {
            let Some(info) = mat.pointer(slot) else {
                continue;
            };
            let (set, at) = match info.pointer("/extensions/KHR_texture_transform/texCoord") {
                Some(v) => (v.as_u64(), "/extensions/KHR_texture_transform/texCoord"),
                None => (info.get("texCoord").and_then(Value::as_u64), "/texCoord"),
            };
            let set = set.unwrap_or(0);
            match first {
                None => first = Some(set),
                Some(f) if f != set => add(
                    "textures of one material on different texCoord sets \
                     (the first texture's set is used for all)"
                        .into(),
                    format!("/materials/{m}{slot}{at}"),
                ),
                Some(_) => {}
            }
        }
    }
    found
        .into_iter()
        .map(|(feature, ptrs)| {
            let more = match ptrs.len() {
                1 => String::new(),
                n => format!(" (and {} more)", n - 1),
            };
            format!("{}: {feature}: at {}{more}", path.display(), ptrs[0])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A triangle, a perspective camera, a point and a spot light, a
    /// metallic material, all in one embedded file.
    const SCENE: &str = r#"{
      "asset": {"version": "2.0"},
      "extensionsUsed": ["KHR_lights_punctual"],
      "extensions": {"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 3.14159265, "color": [1, 0.5, 0.25]},
        {"type": "spot", "intensity": 6.2831853,
         "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}}
      ]}},
      "scene": 0,
      "scenes": [{"nodes": [0, 1, 2, 3]}],
      "nodes": [
        {"mesh": 0, "translation": [0, 0, -2]},
        {"camera": 0, "translation": [0, 0, 3]},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 4, 0]},
        {"extensions": {"KHR_lights_punctual": {"light": 1}},
         "rotation": [-0.7071068, 0, 0, 0.7071068], "translation": [0, 5, 0]}
      ],
      "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0, 1],
        "metallicFactor": 1.0, "roughnessFactor": 0.5}, "doubleSided": true}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
    }"#;

    /// Each unsupported feature is one warning naming the file and the JSON
    /// pointer of its first occurrence, with the count of the others.
    #[test]
    fn unsupported_features_are_one_warning_each_with_a_json_pointer() {
        let json: serde_json::Value = serde_json::from_str(
            r#"{
              "extensionsUsed": ["KHR_materials_clearcoat", "KHR_texture_transform", "EXT_foo"],
              "scene": 1,
              "scenes": [{"nodes": []}, {"nodes": [0]}],
              "nodes": [{"mesh": 0, "skin": 0, "weights": [0.5]}],
              "skins": [{"joints": [0]}],
              "animations": [{"channels": [], "samplers": []}],
              "cameras": [{"type": "orthographic"}],
              "materials": [
                {"name": "a"},
                {"extensions": {"KHR_materials_clearcoat": {}}},
                {"extensions": {"KHR_materials_clearcoat": {}, "KHR_materials_sheen": {}},
                 "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                   "metallicRoughnessTexture": {"index": 0, "texCoord": 1}}}
              ],
              "meshes": [{"primitives": [{"attributes": {}, "targets": [{}]},
                                         {"attributes": {}, "targets": [{}]}]}],
              "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "range": 2}]}}
            }"#,
        )
        .expect("json");
        let w = unsupported_features(&json, Path::new("m.gltf"));
        let has = |s: &str| w.iter().filter(|x| x.contains(s)).count();
        for expected in [
            "m.gltf: extension KHR_materials_clearcoat is not supported and is ignored: \
             at /materials/1/extensions/KHR_materials_clearcoat (and 2 more)",
            "m.gltf: extension KHR_materials_sheen is not supported and is ignored: \
             at /materials/2/extensions/KHR_materials_sheen",
            "m.gltf: extension EXT_foo is not supported and is ignored: at /extensionsUsed/2",
            "m.gltf: skins are not applied (the bind pose is loaded): at /skins/0",
            "m.gltf: animations are ignored: at /animations/0",
            "m.gltf: morph targets are ignored (the base shape is loaded): \
             at /meshes/0/primitives/0/targets (and 2 more)",
            "m.gltf: orthographic cameras are skipped: at /cameras/0",
            "m.gltf: light `range` is ignored (inverse-square fall-off everywhere): \
             at /extensions/KHR_lights_punctual/lights/0/range",
            "m.gltf: scenes other than the default one are not loaded: at /scenes/0",
            "/materials/2/pbrMetallicRoughness/metallicRoughnessTexture/texCoord",
        ] {
            assert_eq!(has(expected), 1, "{expected} in {w:#?}");
        }
        // Supported extensions are not warned about; nothing else is.
        assert_eq!(has("KHR_texture_transform"), 0, "{w:#?}");
        assert_eq!(w.len(), 10, "{w:#?}");
    }

    /// Through the loader: the warning reaches `Imported::warnings` once.
    #[test]
    fn an_unsupported_material_extension_is_warned_about_with_its_path() {
        let file = SCENE
            .replace(
                r#""extensionsUsed": ["KHR_lights_punctual"],"#,
                r#""extensionsUsed": ["KHR_lights_punctual", "KHR_materials_clearcoat"],"#,
            )
            .replace(
                r#""doubleSided": true}"#,
                r#""doubleSided": true, "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1}}}"#,
            );
        let imp = load_gltf_slice(file.as_bytes(), None, Path::new("s.gltf")).expect("loads");
        let w: Vec<_> = imp
            .warnings
            .iter()
            .filter(|w| w.contains("KHR_materials_clearcoat"))
            .collect();
        assert_eq!(w.len(), 1, "{:#?}", imp.warnings);
        assert!(
            w[0].starts_with("s.gltf: ")
                && w[0].contains("at /materials/0/extensions/KHR_materials_clearcoat"),
            "{}",
            w[0]
        );
    }

    #[test]
    fn cameras_lights_and_materials_convert() {
        let imp = load_gltf_slice(SCENE.as_bytes(), None, Path::new("s.gltf")).expect("loads");
        assert_eq!(imp.meshes.len(), 1);
        assert_eq!(imp.meshes[0].indices, vec![[0, 1, 2]]);
        let o = &imp.objects[0];
        assert!(
            (o.matrix.transform_point3(Vec3::ZERO) - Vec3::new(0.0, 0.0, -2.0)).length() < 1e-6
        );
        // yfov in radians becomes degrees; the camera looks down -z from z = 3.
        assert_eq!(imp.cameras[0].name, "camera0");
        let c = imp.cameras[0].camera;
        assert!((c.fov_y_degrees - 0.5f32.to_degrees()).abs() < 1e-4);
        assert!((c.eye - Vec3::new(0.0, 0.0, 3.0)).length() < 1e-6);
        assert!((c.look_at - c.eye - Vec3::NEG_Z).length() < 1e-6);
        // Candela / pi = Ip.
        match &imp.lights[0] {
            Light::Point {
                position,
                color,
                intensity,
                ..
            } => {
                assert!((*intensity - 1.0).abs() < 1e-6);
                assert_eq!(*color, Vec3::new(1.0, 0.5, 0.25));
                assert!((*position - Vec3::new(0.0, 4.0, 0.0)).length() < 1e-6);
            }
            other => panic!("{other:?}"),
        }
        match &imp.lights[1] {
            Light::Spot(s) => {
                assert!((s.intensity - 2.0).abs() < 1e-6);
                // Rotated -90 degrees about x: -z turns into -y.
                assert!(
                    (s.direction - Vec3::NEG_Y).length() < 1e-5,
                    "{}",
                    s.direction
                );
                assert!((s.cone_degrees - 0.5f32.to_degrees()).abs() < 1e-4);
                assert!((s.cone_softness_degrees - 0.3f32.to_degrees()).abs() < 1e-4);
            }
            other => panic!("{other:?}"),
        }
        // Metal: no diffuse, F0 = base colour, alpha = roughness^2.
        let m = &imp.materials[0];
        assert_eq!(m.diffuse, Vec3::ZERO);
        assert_eq!(m.specular, Vec3::new(1.0, 0.5, 0.0));
        assert_eq!(m.roughness, 0.25);
        assert!(m.two_sided);
    }

    #[test]
    fn out_of_range_index_is_an_error_not_a_panic() {
        // u8 indices 0, 1, 7 in a second buffer: 7 is past the 3 vertices.
        let bad = SCENE
            .replace(
                r#""attributes": {"POSITION": 0}, "material": 0"#,
                r#""attributes": {"POSITION": 0}, "material": 0, "indices": 1"#,
            )
            .replace(
                r#""bufferViews": [{"buffer": 0, "byteLength": 36}]"#,
                r#""bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 1, "byteLength": 3}]"#,
            )
            .replace(
                r#""min": [0, 0, 0], "max": [1, 1, 0]}]"#,
                r#""min": [0, 0, 0], "max": [1, 1, 0]},
                   {"bufferView": 1, "componentType": 5121, "count": 3, "type": "SCALAR"}]"#,
            )
            .replace(
                r#"AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]"#,
                r#"AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"},
                   {"byteLength": 4, "uri": "data:application/octet-stream;base64,AAEHAA=="}]"#,
            );
        let e = load_gltf_slice(bad.as_bytes(), None, Path::new("bad.gltf")).expect_err("index 7");
        let msg = e.to_string();
        assert!(
            msg.contains("meshes[0].primitives[0].indices") && msg.contains("index 7"),
            "{msg}"
        );
        // An accessor that claims more data than its buffer view holds.
        let short = SCENE.replace(
            r#""count": 3, "type": "VEC3""#,
            r#""count": 300, "type": "VEC3""#,
        );
        let e = load_gltf_slice(short.as_bytes(), None, Path::new("g.gltf")).expect_err("short");
        assert!(e.to_string().contains("accessors[0]"), "{e}");
        // Bad JSON gives line and column.
        let e =
            load_gltf_slice(b"{\n  \"asset\": ,\n}", None, Path::new("j.gltf")).expect_err("json");
        assert!(matches!(e, IoError::At { line: 2, .. }), "{e}");
        // A truncated GLB header.
        let e = load_gltf_slice(
            b"glTF\x02\x00\x00\x00\x04\x00\x00\x00",
            None,
            Path::new("h.glb"),
        );
        assert!(e.is_err());
    }

    /// A later 2.x file loads; one whose minVersion is above 2.0, or that
    /// is not glTF 2, is refused naming the file and the version.
    #[test]
    fn min_version_above_2_0_is_refused() {
        let with = |asset: &str| SCENE.replace(r#""asset": {"version": "2.0"}"#, asset);
        for ok in [
            r#""asset": {"version": "2.1"}"#,
            r#""asset": {"version": "2.1", "minVersion": "2.0"}"#,
        ] {
            load_gltf_slice(with(ok).as_bytes(), None, Path::new("v.gltf")).expect(ok);
        }
        for (bad, want) in [
            (
                r#""asset": {"version": "2.1", "minVersion": "2.1"}"#,
                "v.gltf: asset.minVersion: the file requires glTF 2.1 or later",
            ),
            (
                r#""asset": {"version": "3.0", "minVersion": "3.0"}"#,
                "v.gltf: asset.version",
            ),
            (
                r#""asset": {"version": "2.0", "minVersion": "two"}"#,
                "asset.minVersion",
            ),
        ] {
            let e = load_gltf_slice(with(bad).as_bytes(), None, Path::new("v.gltf"))
                .expect_err(bad)
                .to_string();
            assert!(e.contains(want), "{bad}: {e}");
        }
    }

    #[test]
    fn supported_required_extensions_load_and_points_only_is_an_error() {
        let req = SCENE.replace(
            r#""extensionsUsed": ["KHR_lights_punctual"],"#,
            r#""extensionsUsed": ["KHR_lights_punctual", "KHR_mesh_quantization",
                "KHR_texture_transform"],
              "extensionsRequired": ["KHR_mesh_quantization", "KHR_texture_transform"],"#,
        );
        let imp = load_gltf_slice(req.as_bytes(), None, Path::new("q.gltf")).expect("loads");
        assert_eq!(imp.meshes.len(), 1);
        // The default metallic (1) keeps the base colour on ks.
        let mr = imp.materials[0].metallic_roughness.expect("pbr");
        assert_eq!(mr.base_color, Vec3::new(1.0, 0.5, 0.0));
        // Quantized positions: i16 normalized (32767 = 1.0), 3 vertices.
        let q = SCENE
            .replace(
                r#""componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 0]}"#,
                r#""componentType": 5122, "normalized": true, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [32767, 32767, 0]}"#,
            )
            .replace(r#""byteLength": 36}]"#, r#""byteLength": 24, "byteStride": 8}]"#)
            .replace(
                r#""byteLength": 36,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]"#,
                r#""byteLength": 24,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAD/fwAAAAAAAAAA/38AAAAA"}]"#,
            );
        let imp = load_gltf_slice(q.as_bytes(), None, Path::new("q.gltf")).expect("quantized");
        assert_eq!(
            imp.meshes[0].positions,
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            "quantized positions"
        );
        // Points only: nothing to render is an error naming the primitive.
        let pts = SCENE.replace(
            r#""attributes": {"POSITION": 0}, "material": 0"#,
            r#""attributes": {"POSITION": 0}, "material": 0, "mode": 0"#,
        );
        let e = load_gltf_slice(pts.as_bytes(), None, Path::new("p.gltf")).expect_err("points");
        assert!(e.to_string().contains("nothing to render"), "{e}");
        assert!(e.to_string().contains("meshes[0].primitives[0]"), "{e}");
    }

    #[test]
    fn base64_round_trip() {
        assert_eq!(decode_base64("aGVsbG8=").unwrap_or_default(), b"hello");
        assert_eq!(decode_base64("aGk").unwrap_or_default(), b"hi");
        assert!(decode_base64("a*b").is_err());
    }

    #[test]
    fn bad_percent_encoding_is_refused() {
        assert!(check_uri("a%20b.bin").is_ok());
        assert!(check_uri("a%ff.bin").is_err());
    }

    /// A sparse POSITION accessor of count 2^31 without a buffer view: its
    /// zeros would take 24 GiB, refused before anything is sized by it.
    #[test]
    fn unbacked_accessor_counts_are_checked_against_the_budget() {
        let scene = |count: u64, sparse: u64| {
            format!(
                r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
                "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
                "accessors": [{{"componentType": 5126, "count": {count}, "type": "VEC3",
                  "min": [0, 0, 0], "max": [1, 2, 3],
                  "sparse": {{"count": {sparse}, "indices": {{"bufferView": 0, "componentType": 5125}},
                    "values": {{"bufferView": 1}}}}}}],
                "bufferViews": [{{"buffer": 0, "byteLength": 4}}, {{"buffer": 0, "byteOffset": 4, "byteLength": 12}}],
                "buffers": [{{"byteLength": 16, "uri": "data:application/octet-stream;base64,AQAAAAAAgD8AAABAAABAQA=="}}]}}"#
            )
        };
        let budget = MemoryBudget::new(1 << 30);
        let huge = scene(1 << 31, 1);
        assert!(huge.len() < 1000, "{} bytes", huge.len());
        let e = load_gltf_slice_within(huge.as_bytes(), None, Path::new("sparse.gltf"), budget)
            .expect_err("2^31 zeros");
        let msg = e.to_string();
        assert!(
            msg.contains("sparse.gltf")
                && msg.contains("accessors[0]")
                && msg.contains("2147483648 elements")
                && msg.contains("memory limit is 1.0 GiB"),
            "{msg}"
        );
        // The same accessor with a count that fits: zeros and the one value.
        let small =
            load_gltf_slice_within(scene(3, 1).as_bytes(), None, Path::new("s.gltf"), budget)
                .expect("loads");
        assert_eq!(
            small.meshes[0].positions,
            vec![Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO]
        );
        // More sparse entries than elements.
        let e = load_gltf_slice_within(scene(1, 2).as_bytes(), None, Path::new("s.gltf"), budget)
            .expect_err("sparse count");
        assert!(e.to_string().contains("sparse count 2 exceeds"), "{e}");
    }
}
