//! Gouraud shading for the scan converter (Henri Gouraud, "Continuous
//! Shading of Curved Surfaces", IEEE Trans. Computers C-20(6), 1971; Foley
//! et al. 16.2.4): the illumination model evaluated at the vertices and
//! interpolated across the triangle. Here: which vertices are lit, once
//! each, the vertex cache the shading pass fills, and the interpolation at
//! a sample. The vertices of a textured surface are lit without its
//! colours (the light per unit of diffuse colour, ambient reflectance and
//! F0), which each sample then applies from its textures; the lobe's
//! roughness is the one at the vertex. The per-sample steps every method
//! shares are in [`crate::pipeline::shading`].

use crate::pipeline::NONE;
use crate::pipeline::shading::{Ctx, Lit, SampleAt, Split};
use crate::pipeline::triangles::TriData;
use crate::pipeline::triangles::needs_footprint;
use crate::pipeline::visibility::Class;
use crate::pipeline::visibility::TileVis;
use glam::{Vec2, Vec3, Vec3A};

use chiaro_core::prepared::SurfaceHit;
use chiaro_core::scene::ShadeMode;
use chiaro_core::shading::{FactoredLight, ShadingPoint, SurfaceMaterial};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};

/// Number of entries of the vertex illumination cache of [`TriCache`] (a
/// power of two): a few tiles' worth of vertices.
///
/// [`TriCache`]: crate::pipeline::triangles::TriCache
pub(crate) const VERTEX_CACHE_SIZE: usize = 4096;

/// Per-triangle results of the visibility pass that flat and Gouraud
/// shading need.
#[derive(Default)]
pub(crate) struct PolyShading {
    /// Gouraud: per vertex, front side.
    pub(crate) vertex_front: Vec<Split>,
    /// Gouraud: per vertex, back side (two-sided surfaces seen from behind).
    pub(crate) vertex_back: Vec<Split>,
    /// Gouraud triangles whose corners could not use shared vertex values
    /// (a vertex shared by faces of different materials).
    pub(crate) corners: HashMap<u32, [Split; 3]>,
    /// The same three tables for the vertices of textured materials: their
    /// light without the colours ([`Ctx::corner_factored`]), which the
    /// samples colour per pixel (empty when no textured Gouraud triangle
    /// is seen).
    pub(crate) factored_front: Vec<FactoredLight>,
    pub(crate) factored_back: Vec<FactoredLight>,
    pub(crate) factored_corners: HashMap<u32, [FactoredLight; 3]>,
    /// When every Gouraud sample is a [`lean_sample`] of one untextured
    /// material lit by `point_lighting` ([`on_demand_gouraud`]): that
    /// material, and the tables above stay empty. The shading pass then
    /// illuminates each vertex when a triangle using it is first fetched
    /// ([`TriCache`]), the same [`Ctx::vertex_split`] as
    /// [`uniform_vertex_shading`] gives it; this skips finding the
    /// visible vertices (a pass over every sample) and writing, then
    /// gathering back, a table of every vertex's illumination. A vertex
    /// is only illuminated again where the cache lost it (another shading
    /// thread, or a slot taken by another vertex).
    ///
    /// [`lean_sample`]: crate::pipeline::shading::lean_sample
    /// [`TriCache`]: crate::pipeline::triangles::TriCache
    pub(crate) on_demand: Option<SurfaceMaterial>,
}

impl Ctx<'_, '_> {
    /// [`Ctx::corner_split`] at vertex `v` of an untextured material whose
    /// [`SurfaceMaterial`] is `base`, lit by the point-light model,
    /// for any corner of any triangle with that material at `v`: the
    /// model reads no geometric normal, and a corner's interpolated position
    /// and colour (weights 1, 0, 0) are the vertex's own but for the sign of
    /// a zero component, which changes no non-zero result (and the film's
    /// sanitising makes every zero positive).
    /// Requires `point_lighting` (without it the triangle would matter for
    /// shadows).
    pub(crate) fn vertex_split(&self, base: &SurfaceMaterial, v: usize, back: bool) -> Split {
        debug_assert!(self.point_lighting.is_some());
        let p = self.ps.positions[v];
        let mut n = self.ps.normals[v];
        if back {
            n = -n;
        }
        let mut sm = *base;
        sm.kd *= self.ps.colors[v];
        let wo = self.rays.toward_viewer3(p).normalize_or_zero();
        // No triangle: point lighting has no visibility to ask about.
        self.illuminate_split(u32::MAX, &sm, &ShadingPoint { p, n, ng: n, wo })
    }

    /// Gouraud illumination at corner `k` of the untextured triangle `t`,
    /// on the front side or (for the back of a two-sided surface) the back
    /// side.
    pub(crate) fn corner_split(&self, t: u32, k: usize, back: bool) -> Split {
        let (hit, sp) = self.corner_point(t, k, back);
        self.illuminate_split(t, &self.untextured_material(&hit), &sp)
    }

    /// [`Ctx::corner_split`] of a textured triangle: the light without the
    /// colours, with the lobe of the material at the corner (its roughness
    /// textured), coloured per pixel by [`Ctx::factored_sample`].
    pub(crate) fn corner_factored(&self, t: u32, k: usize, back: bool) -> FactoredLight {
        let (hit, sp) = self.corner_point(t, k, back);
        let lobe = self.ps.surface_material_lod(&hit, Vec2::ZERO, Vec2::ZERO);
        self.illuminate_factored(t, &lobe, &sp)
    }

    /// The surface at corner `k` of triangle `t` and its shading point with
    /// the vertex normal, flipped for the `back` side.
    fn corner_point(&self, t: u32, k: usize, back: bool) -> (SurfaceHit, ShadingPoint) {
        let (u, v) = match k {
            0 => (0.0, 0.0),
            1 => (1.0, 0.0),
            _ => (0.0, 1.0),
        };
        let td = self.make_tri_data(t);
        let hit = self.surface(&td, u, v, td.textured, true);
        let vi = self.ps.triangles[t as usize][k] as usize;
        let mut n = self.ps.normals[vi];
        let mut ng = hit.ng;
        if back {
            n = -n;
            ng = -ng;
        }
        let wo = self.rays.toward_viewer3(hit.p).normalize_or_zero();
        let sp = ShadingPoint {
            p: hit.p,
            n,
            ng,
            wo,
        };
        (hit, sp)
    }
}

/// With the point-light model, the base material when every Gouraud
/// triangle has the same material and it is untextured (a textured one is
/// lit without its colours, by [`poly_shading`]'s general path).
pub(crate) fn uniform_gouraud<'c>(ctx: &'c Ctx<'_, '_>) -> Option<&'c SurfaceMaterial> {
    ctx.point_lighting.as_ref()?;
    let ps = ctx.ps;
    let is_gouraud = |t: usize| ctx.mode(t as u32) == ShadeMode::Gouraud;
    let first = (0..ps.triangles.len()).find(|&t| is_gouraud(t))?;
    let m = ps.tri_material[first];
    // (No scan when every triangle has the same material.)
    let uniform = ctx.one_material == Some(m)
        || ps
            .tri_material
            .par_iter()
            .enumerate()
            .all(|(t, &mt)| mt == m || !is_gouraud(t));
    let base = ctx.bases.get(m.index())?;
    (uniform && !needs_footprint(ps.material(m))).then_some(base)
}

/// With [`uniform_gouraud`]'s material, true when every sample of a
/// Gouraud triangle takes [`lean_sample`] (see [`Ctx::fetch_tri`]): a lean
/// frame, and the material untextured, one-sided and opaque (no fragment
/// is shaded by `shade_sample`), so its vertices are only ever needed on
/// the front side and can be illuminated on demand
/// ([`PolyShading::on_demand`]).
///
/// [`lean_sample`]: crate::pipeline::shading::lean_sample
pub(crate) fn on_demand_gouraud(ctx: &Ctx<'_, '_>) -> bool {
    let ps = ctx.ps;
    let Some(t) = (0..ps.triangles.len() as u32).find(|&t| ctx.mode(t) == ShadeMode::Gouraud)
    else {
        return false;
    };
    let id = ps.tri_material[t as usize];
    let m = ps.material(id);
    ctx.lean_frame
        && !needs_footprint(m)
        && !m.sidedness.eye_sees_back()
        && !matches!(ctx.class.get(id.index()), Some(Class::Blend(_)))
}

/// Step 4 when [`uniform_gouraud`] gives the base material: the vertices of
/// the visible Gouraud triangles, marked straight from the tiles' samples
/// (once per run of samples on one triangle, every mark a store of `true`
/// so that their order does not matter), each lit from its own position,
/// normal and colour ([`Ctx::vertex_split`]), the same values as the
/// general path of [`poly_shading`] gives them.
pub(crate) fn uniform_vertex_shading(
    ctx: &Ctx<'_, '_>,
    vis: &[TileVis],
    base: &SurfaceMaterial,
) -> PolyShading {
    let ps = ctx.ps;
    let nv = ps.positions.len();
    // Without materials whose back the eye sees, no back is seen (Ctx::flipped).
    let two_sided = ps
        .scene
        .materials
        .iter()
        .any(|m| m.sidedness.eye_sees_back());
    let flags = |n: usize| -> Vec<AtomicBool> { (0..n).map(|_| AtomicBool::new(false)).collect() };
    let front = flags(nv);
    let back = if two_sided { flags(nv) } else { Vec::new() };
    let (any_front, any_back) = vis
        .par_iter()
        .map(|tv| {
            let mut any = [false; 2];
            let mut mark = |id: u32| {
                if ctx.mode(id) != ShadeMode::Gouraud {
                    return;
                }
                let flip = two_sided && ctx.flipped(id);
                let side = if flip { &back } else { &front };
                for &v in &ps.triangles[id as usize] {
                    side[v as usize].store(true, Ordering::Relaxed);
                }
                any[usize::from(flip)] = true;
            };
            // A plain loop over the samples (an iterator chain costs more
            // per sample), once per run of samples on one triangle, and
            // not again for a triangle marked lately (its run on the row
            // above): a direct-mapped table of the last ids marked.
            let mut last = NONE;
            let mut recent = [NONE; 256];
            for &id in &tv.ids {
                if id != last {
                    last = id;
                    let r = &mut recent[id as usize & 255];
                    if id != NONE && *r != id {
                        *r = id;
                        mark(id);
                    }
                }
            }
            for f in &tv.frags {
                mark(f.0);
            }
            (any[0], any[1])
        })
        .reduce(|| (false, false), |a, b| (a.0 | b.0, a.1 | b.1));
    let shade_side = |need: &[AtomicBool], flip: bool| -> Vec<Split> {
        need.par_iter()
            .enumerate()
            .map(|(v, n)| {
                if n.load(Ordering::Relaxed) {
                    ctx.vertex_split(base, v, flip)
                } else {
                    Split::default()
                }
            })
            .collect()
    };
    let mut out = PolyShading::default();
    if any_front || any_back {
        out.vertex_front = shade_side(&front, false);
    }
    if any_back {
        out.vertex_back = shade_side(&back, true);
    }
    out
}

/// Step 4: finds the visible Gouraud triangles and illuminates their
/// vertices (flat polygons are illuminated with their [`TriData`]).
pub(crate) fn poly_shading(ctx: &Ctx<'_, '_>, vis: &[TileVis]) -> PolyShading {
    let ps = ctx.ps;
    let mut out = PolyShading::default();
    if ctx.object_mode.iter().all(|&m| m != ShadeMode::Gouraud) {
        return out;
    }
    if let Some(base) = uniform_gouraud(ctx) {
        if on_demand_gouraud(ctx) {
            return PolyShading {
                on_demand: Some(*base),
                ..PolyShading::default()
            };
        }
        return uniform_vertex_shading(ctx, vis, base);
    }
    // Visible triangles, marked in parallel (every mark stores `true`, so
    // the order of the stores does not matter).
    let seen: Vec<AtomicBool> = (0..ps.triangles.len())
        .into_par_iter()
        .map(|_| AtomicBool::new(false))
        .collect();
    vis.par_iter().for_each(|tv| {
        let ids = tv.ids.iter().copied().filter(|&id| id != NONE);
        for id in ids.chain(tv.frags.iter().map(|f| f.0)) {
            seen[id as usize].store(true, Ordering::Relaxed);
        }
    });
    // The visible Gouraud triangles in id order (deterministic) and whether
    // their back is seen.
    let nv = ps.positions.len();
    let gouraud: Vec<(u32, bool)> = (0..ps.triangles.len() as u32)
        .into_par_iter()
        .filter(|&t| seen[t as usize].load(Ordering::Relaxed) && ctx.mode(t) == ShadeMode::Gouraud)
        .map(|t| (t, ctx.flipped(t)))
        .collect();
    drop(seen);
    if gouraud.is_empty() {
        return out;
    }
    let mut need = vec![0u8; nv];
    for &(t, back) in &gouraud {
        for &v in &ps.triangles[t as usize] {
            need[v as usize] |= if back { 2 } else { 1 };
        }
    }
    // A representative (triangle, corner) for each vertex: the first
    // Gouraud triangle using it, visible or not (so that a vertex's colour
    // does not depend on what else is on screen, e.g. on the crop window);
    // vertices shared by Gouraud faces of different materials are shaded
    // per corner instead.
    let mut rep = vec![(u32::MAX, 0u8); nv];
    let mut vmat = vec![u32::MAX; nv];
    let mut conflict = vec![false; nv];
    for t in 0..ps.triangles.len() as u32 {
        if ctx.mode(t) != ShadeMode::Gouraud {
            continue;
        }
        let m = ps.tri_material[t as usize].0;
        for (k, &v) in ps.triangles[t as usize].iter().enumerate() {
            let v = v as usize;
            if rep[v].0 == u32::MAX {
                rep[v] = (t, k as u8);
            }
            if vmat[v] == u32::MAX {
                vmat[v] = m;
            } else if vmat[v] != m {
                conflict[v] = true;
            }
        }
    }
    // A vertex is lit with its colours (untextured) or without them
    // (textured), by the material of its triangles.
    let textured = |t: u32| needs_footprint(ctx.material_of(t));
    let lit = |v: usize, side: u8, want_textured: bool| -> Option<(u32, usize)> {
        let (t, k) = rep[v];
        (need[v] & side != 0 && !conflict[v] && t != u32::MAX && textured(t) == want_textured)
            .then_some((t, k as usize))
    };
    let shade_side = |side: u8| {
        let lit = |v| lit(v, side, false);
        per_vertex(nv, lit, |t, k| ctx.corner_split(t, k, side == 2))
    };
    let factor_side = |side: u8| {
        let lit = |v| lit(v, side, true);
        per_vertex(nv, lit, |t, k| ctx.corner_factored(t, k, side == 2))
    };
    let any_back = need.iter().any(|&n| n & 2 != 0);
    out.vertex_front = shade_side(1);
    out.vertex_back = if any_back { shade_side(2) } else { Vec::new() };
    if gouraud.iter().any(|&(t, _)| textured(t)) {
        out.factored_front = factor_side(1);
        if any_back {
            out.factored_back = factor_side(2);
        }
    }
    let corner_triangles = || {
        gouraud.par_iter().filter(|(t, _)| {
            ps.triangles[*t as usize]
                .iter()
                .any(|&v| conflict[v as usize])
        })
    };
    out.corners = corner_triangles()
        .filter(|(t, _)| !textured(*t))
        .map(|&(t, back)| (t, [0, 1, 2].map(|k| ctx.corner_split(t, k, back))))
        .collect();
    out.factored_corners = corner_triangles()
        .filter(|(t, _)| textured(*t))
        .map(|&(t, back)| (t, [0, 1, 2].map(|k| ctx.corner_factored(t, k, back))))
        .collect();
    out
}

impl<'a> Ctx<'a, '_> {
    /// The Gouraud corners of a lean triangle `d` ([`TriData::corners`]):
    /// with [`PolyShading::on_demand`] each vertex lit when first met and
    /// kept in the triangle cache's vertex slots (`vertex_ids`,
    /// `vertex_splits`), else read from the vertex table of step 4.
    #[inline]
    pub(crate) fn lean_corners(
        &self,
        d: &mut TriData<'a>,
        vertex_ids: &mut Vec<u32>,
        vertex_splits: &mut Vec<[Vec3A; 2]>,
        poly: &PolyShading,
    ) {
        if let Some(base) = &poly.on_demand {
            if vertex_ids.is_empty() {
                *vertex_ids = vec![u32::MAX; VERTEX_CACHE_SIZE];
                *vertex_splits = vec![[Vec3A::ZERO; 2]; VERTEX_CACHE_SIZE];
            }
            let mut get = |i: usize| {
                let slot = i & (VERTEX_CACHE_SIZE - 1);
                if vertex_ids[slot] != i as u32 {
                    let s = self.vertex_split(base, i, false);
                    vertex_ids[slot] = i as u32;
                    vertex_splits[slot] = [s.diffuse.into(), s.rest.into()];
                }
                vertex_splits[slot]
            };
            d.corners = [get(d.idx[0]), get(d.idx[1]), get(d.idx[2])];
        } else {
            let get = |i: usize| {
                let s = poly.vertex_front.get(i).copied().unwrap_or_default();
                [s.diffuse.into(), s.rest.into()]
            };
            d.corners = [get(d.idx[0]), get(d.idx[1]), get(d.idx[2])];
        }
    }
}

/// `light(t, k)` of each of the `nv` vertices at the corner `k` of
/// triangle `t` that `lit` gives it, the default where it gives none.
fn per_vertex<T: Default + Send>(
    nv: usize,
    lit: impl Fn(usize) -> Option<(u32, usize)> + Sync,
    light: impl Fn(u32, usize) -> T + Sync,
) -> Vec<T> {
    (0..nv)
        .into_par_iter()
        .map(|v| lit(v).map_or_else(T::default, |(t, k)| light(t, k)))
        .collect()
}

/// Gouraud shading of the sample `at` of triangle `td`: the illumination of
/// its corners (`poly`'s vertex tables, or the triangle's own corners where
/// a vertex is shared by different materials) interpolated at the sample,
/// with the interpolated normal; for a textured triangle the light without
/// the colours, which are applied per sample.
#[inline]
pub(crate) fn shade(ctx: &Ctx<'_, '_>, poly: &PolyShading, td: &TriData, at: &SampleAt) -> Lit {
    let b = at.b;
    let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
    let n = at.hit.ns * at.sign;
    if td.textured {
        let corners = corner_values(
            td,
            at,
            &poly.factored_corners,
            [&poly.factored_front, &poly.factored_back],
        );
        return ctx.factored_sample(td, at, &lerp_factored(corners, w), n);
    }
    let corners = corner_values(
        td,
        at,
        &poly.corners,
        [&poly.vertex_front, &poly.vertex_back],
    );
    ctx.split_sample(td, at, Split::lerp3(corners, w), n)
}

/// The values at the corners of triangle `td` for the sample `at`: its own
/// (`corners`, for triangles with a vertex shared by different materials)
/// or its vertices' in the table of the side seen (`tables`: front, back).
#[inline]
fn corner_values<T: Copy + Default>(
    td: &TriData,
    at: &SampleAt,
    corners: &HashMap<u32, [T; 3]>,
    [front, back]: [&Vec<T>; 2],
) -> [T; 3] {
    // (No hashing when no triangle needed per-corner values.)
    let own = if corners.is_empty() {
        None
    } else {
        corners.get(&td.t)
    };
    if let Some(c) = own {
        return *c;
    }
    let table = if at.sign < 0.0 { back } else { front };
    td.idx.map(|i| table.get(i).copied().unwrap_or_default())
}

/// The corners' light without colours interpolated at barycentric weights
/// `w`, part by part.
#[inline]
fn lerp_factored(c: [FactoredLight; 3], w: Vec3) -> FactoredLight {
    let l = |f: fn(&FactoredLight) -> Vec3| f(&c[0]) * w.x + f(&c[1]) * w.y + f(&c[2]) * w.z;
    FactoredLight {
        diffuse: l(|x| x.diffuse),
        ambient: l(|x| x.ambient),
        specular: l(|x| x.specular),
        specular_offset: l(|x| x.specular_offset),
    }
}

/// The colour of a [`TriData::lean`] Gouraud sample at barycentric weights
/// `w` of the three corners: the corners' illumination interpolated,
/// untextured. The same operations as [`shade`] for that case.
#[inline(always)]
pub(crate) fn lean_color(td: &TriData, [w, u, v]: [f32; 3]) -> Vec3 {
    // Split::lerp3 and `diffuse * 1 + rest` on the corners' SSE
    // vectors: the same operations lane by lane.
    let [a, b, c] = td.corners;
    let diffuse = a[0] * w + b[0] * u + c[0] * v;
    let rest = a[1] * w + b[1] * u + c[1] * v;
    (diffuse * Vec3A::ONE + rest).into()
}
