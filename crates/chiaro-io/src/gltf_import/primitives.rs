//! Mesh primitives: accessors checked against their buffers and the budget,
//! read (quantized, sparse) into a chiaro [`Mesh`].

use super::textures::UvSlots;
use super::{Builder, ConvertedPrimitive, in_err};
use crate::Result;
use chiaro_core::scene::Mesh;
use chiaro_core::{Vec2, Vec3, Vec4};
use gltf::accessor::util::{Item, Iter};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

impl Builder<'_> {
    /// Checks an accessor: element type among `allowed`, count >= 1, every
    /// byte it reads inside its buffer view and buffer (so its count is
    /// backed by bytes), the sparse count within the count, and its
    /// decoded size, added to the accessors' before it, within the memory
    /// budget (an accessor without a buffer view holds zeros whose count
    /// nothing backs).
    pub(super) fn check_accessor(
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
        // Decoded, a component takes 4 bytes (f32 or u32), and a position
        // stands for a whole mesh vertex (the normals and tangents made for
        // it too); the scene holds a second copy of the import. The total
        // of every accessor decoded so far is checked: accessors that each
        // fit must not together exceed the budget (nor zeros that no
        // buffer view backs).
        let each = if what == "POSITION" {
            chiaro_core::budget::MESH_VERTEX_BYTES
        } else {
            4 * acc.dimensions().multiplicity() as u64
        };
        let decoded = chiaro_core::budget::bytes_of(acc.count() as u64, 2 * each);
        let total = self.decoded_bytes.get().saturating_add(decoded);
        let unbacked = if acc.view().is_none() {
            " without a buffer view"
        } else {
            ""
        };
        self.budget
            .check(
                &format!(
                    "{what}: {} elements{unbacked}, with the accessors before it,",
                    acc.count()
                ),
                total,
            )
            .map_err(|m| in_err(self.path, loc.clone(), m))?;
        self.decoded_bytes.set(total);
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

    /// Converts one primitive and adds its mesh to the output; `None` when
    /// it is skipped (not triangles, no positions).
    pub(super) fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
    ) -> Result<Option<ConvertedPrimitive>> {
        let Some((m, material)) = self.read_primitive(mesh, prim)? else {
            return Ok(None);
        };
        self.out.meshes.push(m);
        Ok(Some((self.out.meshes.len() - 1, material)))
    }

    /// Reads one primitive into a mesh (not yet added) and its material;
    /// `None` when it is skipped (not triangles, no positions).
    pub(super) fn read_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
    ) -> Result<Option<(Mesh, Option<usize>)>> {
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
        let name = format!(
            "{}:{}#{}",
            self.path
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            mesh.name().unwrap_or("mesh"),
            prim.index()
        );
        if let Some(ext) = self.draco_extension(mesh, prim) {
            // The accessors give the counts (checked against the budget);
            // the geometry is in the Draco stream.
            let max_faces = match prim.indices() {
                Some(acc) => {
                    self.check_accessor(
                        &acc,
                        "indices",
                        &[Dimensions::Scalar],
                        &[DataType::U8, DataType::U16, DataType::U32],
                    )?;
                    acc.count() / 3
                }
                None => pos_acc.count() / 3,
            };
            let mut m = Mesh {
                name,
                ..Mesh::default()
            };
            let slots = UvSlots::of(&self.json, prim.material().index());
            self.decode_draco(&mut m, &ext, &loc, slots, pos_acc.count(), max_faces)?;
            let material = match prim.material().index() {
                Some(i) => Some(self.material(i)?),
                None => None,
            };
            return Ok(Some((m, material)));
        }
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
            name,
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
        // The texCoord sets the material's textures read: the first into
        // `uvs`, a second into `uvs1` (textures name their slot).
        let slots = UvSlots::of(&self.json, prim.material().index());
        let wanted = [Some(slots.primary), slots.secondary];
        for (slot, set) in wanted.into_iter().enumerate() {
            let Some(set) = set else {
                continue;
            };
            let Some(acc) = prim.get(&gltf::Semantic::TexCoords(set)) else {
                if set != 0 {
                    self.note(format!(
                        "{loc}: the material uses TEXCOORD_{set}, which is missing"
                    ));
                }
                continue;
            };
            self.check_accessor(
                &acc,
                &format!("TEXCOORD_{set}"),
                &[Dimensions::Vec2],
                QUANTIZED,
            )?;
            if let Some(v) = read_f32::<2>(&acc, buffers) {
                let v: Vec<Vec2> = v.into_iter().map(Vec2::from).collect();
                if v.len() == n && v.iter().all(|x| x.is_finite()) {
                    if slot == 0 {
                        m.uvs = v;
                    } else {
                        m.uvs1 = v;
                    }
                }
            }
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
        Ok(Some((m, material)))
    }
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
