//! Per-triangle shading data and its cache, and the perspective-correct
//! barycentrics of an eye ray on a triangle's plane (Moller, Trumbore 1997).

use crate::gouraud::PolyShading;
use crate::pipeline::exact;
use crate::pipeline::shading::Ctx;
use crate::pipeline::shading::Split;
use crate::pipeline::vertex::Rays;
use chiaro_core::prepared::SurfaceHit;
use chiaro_core::scene::MaterialId;
use chiaro_core::scene::{Material, ShadeMode};
use chiaro_core::shading::FactoredLight;
use glam::{Mat2, Vec2, Vec3, Vec3A, Vec4};

/// Barycentrics `(u, v)` of vertices 1 and 2 where the ray `o + t d` meets the
/// plane of the triangle (Moller and Trumbore 1997, without the inside test):
/// the perspective-correct barycentrics of the sample. `None` when the ray
/// is parallel to the plane. The reference for [`TriData::bary`], which
/// shading uses.
#[cfg(test)]
pub(crate) fn ray_plane_bary(o: Vec3, d: Vec3, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<Vec2> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-30 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - p0;
    let u = s.dot(pv) * inv;
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    let r = Vec2::new(u, v);
    r.is_finite().then_some(r)
}

/// What shading needs of a visible triangle, fetched once per tile (see
/// [`TriCache`]).
#[derive(Clone, Copy)]
pub(crate) struct TriData<'a> {
    pub(crate) t: u32,
    pub(crate) idx: [usize; 3],
    /// The vertex positions (as SSE vectors, see [`exact`]).
    pub(crate) p: [Vec3A; 3],
    /// `PreparedScene::face_normal(t)`.
    pub(crate) ng: Vec3A,
    /// The vertex normals and colours (in [`TriCache`], zero where the
    /// triangle's samples do not read them: see [`Ctx::tri_geometry`]).
    pub(crate) n: [Vec3A; 3],
    pub(crate) c: [Vec3A; 3],
    pub(crate) mode: ShadeMode,
    pub(crate) material: &'a Material,
    pub(crate) material_id: MaterialId,
    /// True when the material has a texture, bump, normal or emission map
    /// (which need the uv footprint).
    pub(crate) textured: bool,
    /// The flat-shading illumination of the polygon (zero unless `mode` is
    /// flat): computed with the triangle's data, once per tile that shows it.
    pub(crate) flat: Split,
    /// The same for a textured triangle: its light without the colours
    /// (zero unless `mode` is flat and `textured`).
    pub(crate) flat_factored: FactoredLight,
    /// True when its opaque samples take [`lean_sample`] (set by
    /// [`Ctx::tri_data`]; false elsewhere).
    ///
    /// [`lean_sample`]: crate::pipeline::shading::lean_sample
    pub(crate) lean: bool,
    /// Lean Gouraud triangles: the vertex illumination of the three
    /// corners, `[diffuse, rest]` as SSE vectors (zero otherwise).
    pub(crate) corners: [[Vec3A; 2]; 3],
    /// The per-triangle terms of `ray_plane_bary` for rays from the eye:
    /// the edges `p1 - p0`, `p2 - p0`, `eye - p0` and `(eye - p0) x (p1 - p0)`.
    pub(crate) e1: Vec3A,
    pub(crate) e2: Vec3A,
    pub(crate) s: Vec3A,
    pub(crate) q: Vec3A,
}

impl TriData<'_> {
    /// `ray_plane_bary` for the eye ray with direction `d`: the same
    /// operations in the same order, with the terms that do not depend on
    /// `d` precomputed.
    #[inline]
    pub(crate) fn bary(&self, d: Vec3A) -> Option<Vec2> {
        let pv = exact::cross(d, self.e2);
        let det = self.e1.dot(pv);
        if det.abs() < 1e-30 {
            return None;
        }
        let inv = 1.0 / det;
        let u = self.s.dot(pv) * inv;
        let v = d.dot(self.q) * inv;
        let r = Vec2::new(u, v);
        r.is_finite().then_some(r)
    }

    /// The barycentrics of the sample at film position `(sx, sy)` whose
    /// eye ray has direction `d`: [`TriData::bary`], or for an orthographic
    /// camera, whose rays start on the film, the same Moller-Trumbore terms
    /// from the sample's own origin (affine in screen space: the
    /// perspective correction vanishes).
    #[inline]
    pub(crate) fn bary_at(&self, rays: &Rays, sx: f32, sy: f32, d: Vec3A) -> Option<Vec2> {
        if rays.ortho.is_none() {
            return self.bary(d);
        }
        let s = rays.origin(sx, sy) - self.p[0];
        let pv = exact::cross(d, self.e2);
        let det = self.e1.dot(pv);
        if det.abs() < 1e-30 {
            return None;
        }
        let inv = 1.0 / det;
        let u = s.dot(pv) * inv;
        let v = d.dot(exact::cross(s, self.e1)) * inv;
        let r = Vec2::new(u, v);
        r.is_finite().then_some(r)
    }
}

/// True when `m` has a texture, bump, normal or emission map (which need
/// the uv footprint): [`TriData::textured`].
pub(crate) fn needs_footprint(m: &Material) -> bool {
    m.is_textured() || m.bump.is_some() || m.normal_map.is_some()
}

/// Number of entries of [`TriCache`] (a power of two).
pub(crate) const TRI_CACHE_SIZE: usize = 256;

/// A direct-mapped cache of [`TriData`] keyed by triangle id: a triangle
/// covers a few pixels on a few rows, and neighbouring triangles have
/// neighbouring ids, so most lookups hit. What it holds depends only on the
/// triangle, so one cache serves every tile a shading thread takes.
///
/// With [`PolyShading::on_demand`] it also caches the illumination of the
/// vertices the fetched Gouraud triangles use, keyed by vertex index.
pub(crate) struct TriCache<'a> {
    /// Index into `data` of each slot's entry (`u32::MAX`: empty).
    pub(crate) slots: [u32; TRI_CACHE_SIZE],
    pub(crate) data: Vec<TriData<'a>>,
    /// The vertex of each vertex slot (`u32::MAX`: empty; allocated on
    /// first use).
    pub(crate) vertex_ids: Vec<u32>,
    /// Its [`Ctx::vertex_split`], `[diffuse, rest]` as in [`TriData::corners`].
    pub(crate) vertex_splits: Vec<[Vec3A; 2]>,
}

impl TriCache<'_> {
    pub(crate) fn new() -> Self {
        Self {
            slots: [u32::MAX; TRI_CACHE_SIZE],
            data: Vec::with_capacity(TRI_CACHE_SIZE),
            vertex_ids: Vec::new(),
            vertex_splits: Vec::new(),
        }
    }
}

impl<'a> Ctx<'a, '_> {
    /// The data of triangle `t`, from `cache` when it holds `t` (the
    /// cache then holds `t`), with [`TriData::lean`] and the Gouraud
    /// corners from `poly` set.
    #[inline(always)]
    pub(crate) fn tri_data<'c>(
        &self,
        t: u32,
        cache: &'c mut TriCache<'a>,
        poly: &PolyShading,
    ) -> &'c TriData<'a> {
        // The hit, inlined into the sample loops; the miss is a call.
        let k = cache.slots[t as usize & (TRI_CACHE_SIZE - 1)] as usize;
        if k < cache.data.len() && cache.data[k].t == t {
            return &cache.data[k];
        }
        self.fetch_tri(t, cache, poly)
    }

    /// [`Ctx::tri_data`] of a triangle that `cache` does not hold: fetched
    /// into its slot.
    #[inline(never)]
    pub(crate) fn fetch_tri<'c>(
        &self,
        t: u32,
        cache: &'c mut TriCache<'a>,
        poly: &PolyShading,
    ) -> &'c TriData<'a> {
        let slot = t as usize & (TRI_CACHE_SIZE - 1);
        let k = cache.slots[slot] as usize;
        let k = if k < cache.data.len() {
            // Built in place (inlined), not copied in.
            cache.data[k] = self.tri_geometry(t, false);
            k
        } else {
            cache.slots[slot] = cache.data.len() as u32;
            cache.data.push(self.tri_geometry(t, false));
            cache.data.len() - 1
        };
        let TriCache {
            data,
            vertex_ids,
            vertex_splits,
            ..
        } = cache;
        let d = &mut data[k];
        self.light_flat(d);
        // The cases shade_sample handles without textures, two-sided
        // flips, reflection maps, depth cueing or per-corner values.
        d.lean = self.lean_frame
            && !d.textured
            && !(d.material.sidedness.eye_sees_back()
                && d.ng.dot(self.rays.toward_viewer(d.p[0])) < 0.0)
            && match d.mode {
                ShadeMode::Phong => {
                    self.point_lighting.is_some() && self.bases.get(d.material_id.index()).is_some()
                }
                ShadeMode::Gouraud => poly.corners.is_empty() || !poly.corners.contains_key(&t),
                ShadeMode::Flat => true,
            };
        if d.lean && d.mode == ShadeMode::Gouraud {
            self.lean_corners(d, vertex_ids, vertex_splits, poly);
        }
        d
    }

    /// The [`TriData`] of triangle `t`, computed.
    pub(crate) fn make_tri_data(&self, t: u32) -> TriData<'a> {
        let mut d = self.tri_geometry(t, true);
        self.light_flat(&mut d);
        d
    }

    /// Sets the illumination of a flat triangle `d`: [`TriData::flat`], or
    /// [`TriData::flat_factored`] where textured.
    #[inline]
    fn light_flat(&self, d: &mut TriData<'a>) {
        if d.mode == ShadeMode::Flat {
            if d.textured {
                d.flat_factored = self.flat_factored(d);
            } else {
                d.flat = self.flat_split(d);
            }
        }
    }

    /// [`Ctx::make_tri_data`] without the flat-shading illumination; unless
    /// `all`, without the vertex data its samples do not read (the normals
    /// of a flat triangle, the colours of an untextured Gouraud one: zero), which
    /// the triangle cache then need not fetch.
    #[inline(always)]
    pub(crate) fn tri_geometry(&self, t: u32, all: bool) -> TriData<'a> {
        let mode = self.mode(t);
        // (Arrays written out rather than `map`ped: cheaper per fetch.)
        let [i0, i1, i2] = self.ps.triangles[t as usize];
        let idx = [i0 as usize, i1 as usize, i2 as usize];
        let pos = &self.ps.positions;
        let p: [Vec3A; 3] = [pos[idx[0]].into(), pos[idx[1]].into(), pos[idx[2]].into()];
        // PreparedScene::face_normal(t), from the positions at hand.
        let ng = exact::face_normal(p[0], p[1], p[2]).unwrap_or(Vec3A::Z);
        let of =
            |a: &[Vec3]| -> [Vec3A; 3] { [a[idx[0]].into(), a[idx[1]].into(), a[idx[2]].into()] };
        let e1 = p[1] - p[0];
        let s = Vec3A::from(self.rays.eye) - p[0];
        let material_id = self
            .one_material
            .unwrap_or_else(|| self.ps.tri_material[t as usize]);
        let material = self.ps.material(material_id);
        let textured = needs_footprint(material);
        TriData {
            t,
            idx,
            p,
            ng,
            n: if all || mode != ShadeMode::Flat {
                of(&self.ps.normals)
            } else {
                [Vec3A::ZERO; 3]
            },
            // (A textured Gouraud sample takes its colours per sample.)
            c: if all || mode != ShadeMode::Gouraud || textured {
                of(&self.ps.colors)
            } else {
                [Vec3A::ZERO; 3]
            },
            mode,
            material,
            material_id,
            textured,
            e1,
            e2: p[2] - p[0],
            s,
            q: exact::cross(s, e1),
            flat: Split::default(),
            flat_factored: FactoredLight::default(),
            lean: false,
            corners: [[Vec3A::ZERO; 2]; 3],
        }
    }

    /// [`PreparedScene::triangle_surface`] at barycentrics `(u, v)`, the
    /// same expressions on the cached triangle; the uv, object-space point
    /// and tangent (which only textures, bump and normal maps read) are
    /// computed only when `textured`, zero otherwise.
    ///
    /// With `shading` false (flat-shaded samples, which read neither) the
    /// shading normal is the face normal and the vertex colour zero.
    ///
    /// [`PreparedScene::triangle_surface`]: chiaro_core::prepared::PreparedScene::triangle_surface
    #[inline(always)]
    pub(crate) fn surface(
        &self,
        td: &TriData<'_>,
        u: f32,
        v: f32,
        textured: bool,
        shading: bool,
    ) -> SurfaceHit {
        let ps = self.ps;
        let [i0, i1, i2] = td.idx;
        let w = 1.0 - u - v;
        let lerp3 = |a: &[Vec3]| a[i0] * w + a[i1] * u + a[i2] * v;
        let ng = td.ng;
        let (ns, color) = if shading {
            let mut ns =
                exact::try_normalize(td.n[0] * w + td.n[1] * u + td.n[2] * v).unwrap_or(ng);
            if ns.dot(ng) < 0.0 {
                // Interpolated normals may point away from a thin face; keep the front side.
                ns = ng;
            }
            (ns, td.c[0] * w + td.c[1] * u + td.c[2] * v)
        } else {
            (ng, Vec3A::ZERO)
        };
        let color_alpha = if textured {
            ps.color_alphas[i0] * w + ps.color_alphas[i1] * u + ps.color_alphas[i2] * v
        } else {
            1.0
        };
        let (uv, p_object, tangent) = if textured {
            let tan = ps.tangents[i0] * w + ps.tangents[i1] * u + ps.tangents[i2] * v;
            (
                ps.uvs[i0] * w + ps.uvs[i1] * u + ps.uvs[i2] * v,
                lerp3(&ps.object_positions),
                tan.truncate()
                    .normalize_or_zero()
                    .extend(if tan.w < 0.0 { -1.0 } else { 1.0 }),
            )
        } else {
            (Vec2::ZERO, Vec3::ZERO, Vec4::ZERO)
        };
        let (uv1, uv1_from_uv) = if textured {
            ps.second_uv([i0, i1, i2], u, v, uv)
        } else {
            (Vec2::ZERO, Mat2::IDENTITY)
        };
        SurfaceHit {
            p: (td.p[0] * w + td.p[1] * u + td.p[2] * v).into(),
            ng: ng.into(),
            ns: ns.into(),
            uv,
            uv1,
            uv1_from_uv,
            p_object,
            tangent,
            color: color.into(),
            color_alpha,
            material: td.material_id,
            object: ps.tri_object[td.t as usize],
        }
    }
}
