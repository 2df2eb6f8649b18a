//! `KHR_draco_mesh_compression`: a primitive whose geometry is a Draco
//! bitstream in a buffer view, decoded by the pure-Rust `draco-core`
//! decoder (its accessors give only counts and types).

use super::textures::UvSlots;
use super::{Builder, in_err};
use crate::Result;
use chiaro_core::scene::Mesh;
use chiaro_core::{Vec2, Vec3};
use draco_core::{DataType, DecodeLimits, DecoderBuffer, MeshDecoder, PointAttribute};

impl Builder<'_> {
    /// The JSON of primitive `prim`'s `KHR_draco_mesh_compression`, if any.
    pub(super) fn draco_extension(
        &self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
    ) -> Option<serde_json::Value> {
        self.json
            .pointer(&format!(
                "/meshes/{}/primitives/{}/extensions/KHR_draco_mesh_compression",
                mesh.index(),
                prim.index()
            ))
            .cloned()
    }

    /// Decodes the Draco geometry `ext` of a triangle primitive at `loc`
    /// into `m` (which holds its name): positions, normals, tangents, the
    /// material's uv sets (`slots`), `COLOR_0` and the triangles. Every
    /// count is bounded by the primitive's accessors (`points` vertices,
    /// `max_faces` triangles), which the caller checked against the memory
    /// budget; the decoded vertex count must equal `points`. Returns an
    /// error naming the file and the extension when the stream is bad.
    pub(super) fn decode_draco(
        &mut self,
        m: &mut Mesh,
        ext: &serde_json::Value,
        loc: &str,
        slots: UvSlots,
        points: usize,
        max_faces: usize,
    ) -> Result<()> {
        let at = format!("{loc}.extensions.KHR_draco_mesh_compression");
        let fail = |what: String| in_err(self.path, at.clone(), what);
        let view = ext
            .get("bufferView")
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| self.doc.views().nth(usize::try_from(v).ok()?))
            .ok_or_else(|| fail("bufferView is missing or out of range".into()))?;
        let data = view
            .offset()
            .checked_add(view.length())
            .and_then(|end| {
                self.buffers
                    .get(view.buffer().index())?
                    .0
                    .get(view.offset()..end)
            })
            .ok_or_else(|| fail("the Draco data lies outside its buffer".into()))?;
        let Some(attributes) = ext.get("attributes").and_then(serde_json::Value::as_object) else {
            return Err(fail("attributes is missing".into()));
        };
        // A float of up to four components (or a wider type) per attribute
        // and point, and three indices per face, at most.
        let bytes = (points as u64)
            .saturating_mul(32)
            .saturating_mul(attributes.len().max(1) as u64)
            .saturating_add((max_faces as u64).saturating_mul(12));
        let limits = DecodeLimits::default()
            .with_max_points(points as u64)
            .with_max_faces(max_faces as u64)
            .with_max_decoded_bytes(bytes);
        let mut buffer = DecoderBuffer::new(data).with_limits(limits);
        let mut dm = draco_core::Mesh::new();
        MeshDecoder::new()
            .decode(&mut buffer, &mut dm)
            .map_err(|e| fail(format!("the Draco data could not be decoded: {e}")))?;
        let n = dm.num_points();
        if n != points {
            return Err(fail(format!(
                "the Draco data holds {n} vertices but the POSITION accessor says {points}"
            )));
        }
        // Each glTF attribute named by the extension, read as floats.
        let read = |name: &str, components: usize| -> Option<Vec<f32>> {
            let id = attributes.get(name)?.as_u64()?;
            let attr = dm.attribute_by_unique_id(u32::try_from(id).ok()?)?;
            let mut v = attr.read_f32s(n, components);
            normalize(attr, &mut v);
            Some(v)
        };
        let position = read("POSITION", 3)
            .ok_or_else(|| fail("no POSITION attribute in the Draco data".into()))?;
        m.positions = position
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
        if !m.positions.iter().all(|p| p.is_finite()) {
            return Err(fail("a decoded vertex position is not finite".into()));
        }
        if let Some(v) = read("NORMAL", 3) {
            let normals: Vec<Vec3> = v
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]).normalize_or_zero())
                .collect();
            if normals.iter().all(|x| x.is_finite() && *x != Vec3::ZERO) {
                m.normals = normals;
            } else {
                self.note(format!(
                    "{loc}: invalid Draco NORMAL data: normals will be computed"
                ));
            }
        }
        if let Some(v) = read("TANGENT", 4) {
            let t: Vec<chiaro_core::Vec4> = v
                .chunks_exact(4)
                .map(|c| chiaro_core::Vec4::new(c[0], c[1], c[2], c[3]))
                .collect();
            if t.iter().all(|x| x.is_finite()) {
                m.tangents = t;
            }
        }
        for (slot, set) in [Some(slots.primary), slots.secondary]
            .into_iter()
            .enumerate()
        {
            let Some(set) = set else {
                continue;
            };
            let Some(v) = read(&format!("TEXCOORD_{set}"), 2) else {
                continue;
            };
            let uvs: Vec<Vec2> = v.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect();
            if uvs.iter().all(|x| x.is_finite()) {
                if slot == 0 {
                    m.uvs = uvs;
                } else {
                    m.uvs1 = uvs;
                }
            }
        }
        if let Some(v) = read("COLOR_0", 4) {
            let has_alpha = attributes
                .get("COLOR_0")
                .and_then(serde_json::Value::as_u64)
                .and_then(|id| dm.attribute_by_unique_id(u32::try_from(id).ok()?))
                .is_some_and(|a| a.num_components() >= 4);
            let c: Vec<[f32; 4]> = v
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], if has_alpha { c[3] } else { 1.0 }])
                .collect();
            if c.iter().flatten().all(|x| x.is_finite()) {
                m.colors = c.iter().map(|c| Vec3::new(c[0], c[1], c[2])).collect();
                if c.iter().any(|c| c[3] < 1.0) {
                    m.color_alphas = c.iter().map(|c| c[3]).collect();
                }
            }
        }
        if attributes.keys().any(|k| k.starts_with("JOINTS_")) {
            self.note(format!(
                "{loc}: Draco-compressed joints and weights are not read: drawn unskinned"
            ));
        }
        m.indices = dm
            .faces()
            .iter()
            .map(|f| [f[0].0, f[1].0, f[2].0])
            .collect();
        if let Some(bad) = m.indices.iter().flatten().find(|&&i| i as usize >= n) {
            return Err(fail(format!("index {bad} out of range ({n} vertices)")));
        }
        Ok(())
    }
}

/// Integer attributes the file marks normalized (colours as bytes, for
/// instance) to `[0, 1]` / `[-1, 1]`, as glTF's normalized accessors.
fn normalize(attr: &PointAttribute, values: &mut [f32]) {
    if !attr.normalized() {
        return;
    }
    let scale = match attr.data_type() {
        DataType::Uint8 => 255.0,
        DataType::Int8 => 127.0,
        DataType::Uint16 => 65535.0,
        DataType::Int16 => 32767.0,
        _ => return,
    };
    for v in values {
        *v = (*v / scale).max(-1.0);
    }
}
