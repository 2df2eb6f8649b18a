//! Skins posed at rest: a skinned mesh's vertices are in its skin's bind
//! space and are carried to the world by their joints' rest transforms
//! (glTF 2.0 section 3.7.3); animations are not applied.

use super::{Builder, in_err};
use crate::Result;
use chiaro_core::scene::Mesh;
use chiaro_core::{Mat3, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};

/// Most `JOINTS_n`/`WEIGHTS_n` pairs read (four influences each).
const MAX_INFLUENCE_SETS: u32 = 8;

impl Builder<'_> {
    /// Poses `m`, read from primitive `prim` of a node with `skin`, in world
    /// space: vertex `v` goes to `S v` with `S = sum_k w_k world(joint_k)
    /// inverseBindMatrix_k` over its `JOINTS_n`/`WEIGHTS_n` influences
    /// (weights normalised to sum 1; glTF 2.0 section 3.7.3.3), normals
    /// by `S`'s inverse transpose, tangents by `S`. The joints' world
    /// matrices are their rest transforms; the skinned node's own transform
    /// is not applied (the spec says it is ignored). Returns false, leaving
    /// `m` as it is, when the primitive has no `JOINTS_0`/`WEIGHTS_0`.
    pub(super) fn pose_skin(
        &mut self,
        m: &mut Mesh,
        prim: &gltf::Primitive,
        skin: &gltf::Skin,
        loc: &str,
    ) -> Result<bool> {
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let buffers = self.buffers;
        let get = |b: gltf::Buffer| buffers.get(b.index()).map(|d| &d.0[..]);
        let inverse_bind: Vec<Mat4> = match skin.inverse_bind_matrices() {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    "inverseBindMatrices",
                    &[Dimensions::Mat4],
                    &[DataType::F32],
                )?;
                let v: Vec<Mat4> = skin
                    .reader(get)
                    .read_inverse_bind_matrices()
                    .map(|it| it.map(|a| Mat4::from_cols_array_2d(&a)).collect())
                    .unwrap_or_default();
                if v.len() < joints.len() {
                    return Err(in_err(
                        self.path,
                        format!("skins[{}].inverseBindMatrices", skin.index()),
                        format!("{} matrices for {} joints", v.len(), joints.len()),
                    ));
                }
                v
            }
            None => vec![Mat4::IDENTITY; joints.len()],
        };
        let joint_matrices: Vec<Mat4> = joints
            .iter()
            .zip(&inverse_bind)
            .map(|(&j, ib)| {
                let w = self.node_world.get(j).copied().unwrap_or(Mat4::IDENTITY) * *ib;
                if w.is_finite() { w } else { Mat4::IDENTITY }
            })
            .collect();
        let n = m.positions.len();
        // Weighted sums of the joint matrices and of the weights, per vertex.
        let mut sum = vec![Mat4::ZERO; n];
        let mut total = vec![0.0f32; n];
        let mut bad_joint = false;
        let mut sets = 0;
        while sets < MAX_INFLUENCE_SETS {
            let (Some(jacc), Some(wacc)) = (
                prim.get(&gltf::Semantic::Joints(sets)),
                prim.get(&gltf::Semantic::Weights(sets)),
            ) else {
                break;
            };
            self.check_accessor(
                &jacc,
                &format!("JOINTS_{sets}"),
                &[Dimensions::Vec4],
                &[DataType::U8, DataType::U16],
            )?;
            self.check_accessor(
                &wacc,
                &format!("WEIGHTS_{sets}"),
                &[Dimensions::Vec4],
                &[DataType::F32, DataType::U8, DataType::U16],
            )?;
            let reader = prim.reader(get);
            let js: Vec<[u16; 4]> = reader
                .read_joints(sets)
                .map(|r| r.into_u16().collect())
                .unwrap_or_default();
            let ws: Vec<[f32; 4]> = reader
                .read_weights(sets)
                .map(|r| r.into_f32().collect())
                .unwrap_or_default();
            if js.len() != n || ws.len() != n {
                return Err(in_err(
                    self.path,
                    format!("{loc}.attributes"),
                    format!("JOINTS_{sets} or WEIGHTS_{sets} has not one element per vertex"),
                ));
            }
            for v in 0..n {
                for k in 0..4 {
                    let w = ws[v][k];
                    if !(w.is_finite() && w > 0.0) {
                        continue;
                    }
                    match joint_matrices.get(usize::from(js[v][k])) {
                        Some(j) => {
                            sum[v] += *j * w;
                            total[v] += w;
                        }
                        None => bad_joint = true,
                    }
                }
            }
            sets += 1;
        }
        if sets == 0 {
            self.note(format!(
                "{loc}: a skinned node's primitive has no JOINTS_0/WEIGHTS_0: drawn unskinned"
            ));
            return Ok(false);
        }
        if bad_joint {
            self.note(format!(
                "{loc}: a JOINTS index beyond skins[{}].joints is ignored",
                skin.index()
            ));
        }
        let mut mirrored = 0usize;
        let mut normals_ok = true;
        for v in 0..n {
            // A vertex that no joint moves stays where it is.
            let s = if total[v] > 0.0 {
                sum[v] * (1.0 / total[v])
            } else {
                Mat4::IDENTITY
            };
            let linear = Mat3::from_mat4(s);
            if linear.determinant() < 0.0 {
                mirrored += 1;
            }
            let p = s.transform_point3(m.positions[v]);
            m.positions[v] = if p.is_finite() { p } else { Vec3::ZERO };
            if let Some(nv) = m.normals.get_mut(v) {
                let t = (linear.inverse().transpose() * *nv).normalize_or_zero();
                normals_ok &= t.is_finite() && t != Vec3::ZERO;
                *nv = t;
            }
            if let Some(tv) = m.tangents.get_mut(v) {
                let t = (linear * tv.truncate()).normalize_or_zero();
                *tv = t.extend(tv.w);
            }
        }
        if !normals_ok {
            self.note(format!(
                "{loc}: the posed normals are degenerate: normals will be computed"
            ));
            m.normals.clear();
        }
        if mirrored > 0 {
            // Mirrored vertices flip the bitangent: tangents are derived again.
            m.tangents.clear();
        }
        if 2 * mirrored > n {
            // Mostly mirrored: the front side follows the mirror (as for a
            // node with a negative determinant).
            for t in &mut m.indices {
                t.swap(1, 2);
            }
        }
        Ok(true)
    }
}
