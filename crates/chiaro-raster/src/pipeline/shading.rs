//! Step 4: deferred shading of the visible samples per tile, box-filtered:
//! what every shading method shares (the frame's lighting, the sample's
//! surface and side, the environment and reflection maps, depth cueing),
//! with each method's own step in its file: [`crate::flat`],
//! [`crate::gouraud`] and [`crate::phong`].

use crate::gouraud::PolyShading;
use crate::pipeline::Frame;
use crate::pipeline::NONE;
use crate::pipeline::triangles::TriData;
use crate::pipeline::vertex::Rays;
use crate::pipeline::visibility::{Class, TileVis};
use crate::shadows::Shadows;
use crate::shadows::rays::RayShadows;
use crate::{flat, gouraud, phong};
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, TileRect};
use chiaro_core::progress::Progress;
use chiaro_core::shading::EmitterGroup;
use rayon::prelude::*;
use std::sync::{Mutex, PoisonError};

use crate::pipeline::triangles::TriCache;

use crate::abuffer::composite;
use crate::pipeline::exact;
use chiaro_core::film::TilePixels;
use chiaro_core::prepared::{PreparedScene, SurfaceHit};
use chiaro_core::scene::MaterialId;
use chiaro_core::scene::{AlphaMode, Facing, Material, RenderSettings, ShadeMode};
use chiaro_core::shading::texture::{
    background_radiance, environment_diffuse, environment_radiance, environment_specular,
};
use chiaro_core::shading::{
    FactoredLight, LocalLighting, ShadingPoint, SurfaceMaterial, depth_cue, mirror_reflectance,
    reflect, sanitize, shade_local, shade_local_factored, shade_local_split,
};
use chiaro_core::shading::{LightSample, PointLighting, SampleKey, SampleShare, group_jitter};
use glam::{Vec2, Vec3, Vec3A};
use std::cell::Cell;

/// Illumination split into the part proportional to the diffuse colour and
/// the rest: the colour is `diffuse * texture + rest`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Split {
    pub(crate) diffuse: Vec3,
    pub(crate) rest: Vec3,
}

impl Split {
    #[inline]
    pub(crate) fn lerp3(s: [Split; 3], w: Vec3) -> Split {
        // On SSE vectors: the same operations lane by lane.
        let l = |f: fn(&Split) -> Vec3| {
            let [a, b, c] = [&s[0], &s[1], &s[2]].map(|x| Vec3A::from(f(x)));
            Vec3::from(a * w.x + b * w.y + c * w.z)
        };
        Split {
            diffuse: l(|x| x.diffuse),
            rest: l(|x| x.rest),
        }
    }
}

/// Everything the shading passes share.
pub(crate) struct Ctx<'a, 's> {
    pub(crate) ps: &'a PreparedScene<'s>,
    pub(crate) settings: &'a RenderSettings,
    pub(crate) rays: Rays,
    pub(crate) lighting: LocalLighting<'a>,
    pub(crate) object_mode: Vec<ShadeMode>,
    pub(crate) shadows: Shadows,
    /// Shadow rays for the samples of a grouped emissive mesh under shadow
    /// maps and the exact methods (its lights get no maps, volumes or
    /// fragments), and for lights whose volumes did not fit the budget.
    pub(crate) group_rays: Option<RayShadows>,
    /// Per material: how it is drawn ([`Class`]).
    pub(crate) class: Vec<Class>,
    /// `lighting` specialised, when there are no shadows and only point
    /// and ambient lights (bit-identical to `shade_local`).
    pub(crate) point_lighting: Option<PointLighting>,
    /// `SurfaceMaterial::from_material` of each scene material, by index.
    pub(crate) bases: Vec<SurfaceMaterial>,
    /// True when the frame allows [`lean_sample`]: no environment and no
    /// depth cueing (Phong samples also need `point_lighting`).
    pub(crate) lean_frame: bool,
    /// The shading mode of every object, when they all have the same one,
    /// and the material of every triangle, when it is the same: per-triangle
    /// lookups (cache misses) that the triangle cache then skips.
    pub(crate) one_mode: Option<ShadeMode>,
    pub(crate) one_material: Option<MaterialId>,
}

impl Ctx<'_, '_> {
    pub(crate) fn mode(&self, t: u32) -> ShadeMode {
        if let Some(m) = self.one_mode {
            return m;
        }
        let o = self.ps.tri_object[t as usize] as usize;
        self.object_mode.get(o).copied().unwrap_or(ShadeMode::Phong)
    }

    pub(crate) fn material_of(&self, t: u32) -> &Material {
        self.ps.material(self.ps.tri_material[t as usize])
    }

    /// True if the viewer sees the back of triangle `t` (its normals are
    /// then flipped; the back of a `Culled` material is never drawn).
    pub(crate) fn flipped(&self, t: u32) -> bool {
        if !self.material_of(t).sidedness.eye_sees_back() {
            return false;
        }
        let p0 = self.ps.positions[self.ps.triangles[t as usize][0] as usize];
        self.ps.face_normal(t).dot(self.rays.toward_viewer3(p0)) < 0.0
    }

    /// `shade_local` with area lights sampled at the strata centres and the
    /// visibility of the shadow method; `counts` are the shadow-volume
    /// counts of this sample, one per light (absent: no volume shadows);
    /// `share` the part of each light's samples this sub-sample takes.
    #[inline]
    pub(crate) fn illuminate(
        &self,
        tri: u32,
        pixel: Option<(u32, u32)>,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
        counts: Option<&[i32]>,
        share: SampleShare,
    ) -> Vec3 {
        let mut owned = None;
        let m = self.frame_material(m, &mut owned);
        if let Some(pl) = &self.point_lighting {
            return pl.shade(m, sp);
        }
        let key = match pixel {
            Some((x, y)) => SampleKey::Pixel(x, y),
            None => SampleKey::Point(sp.p),
        };
        let lighting = LocalLighting {
            share,
            ..self.lighting
        };
        if matches!(self.shadows, Shadows::None) {
            // Every light sample is visible: closures the compiler inlines.
            return shade_local(
                m,
                sp,
                &lighting,
                |li, i| self.jitter(key, li, i),
                |_, _| Vec3::ONE,
            );
        }
        let current = Cell::new(0u32);
        let (jitter, visibility) = self.sampling(tri, key, pixel, sp, counts, &current);
        shade_local(m, sp, &lighting, jitter, visibility)
    }

    /// The jitter and visibility of the light samples at `sp` on triangle
    /// `tri`, for the local model: visibility takes the sample index from
    /// the jitter's last call, through `current`.
    #[inline]
    fn sampling<'s>(
        &'s self,
        tri: u32,
        key: SampleKey,
        pixel: Option<(u32, u32)>,
        sp: &'s ShadingPoint,
        counts: Option<&'s [i32]>,
        current: &'s Cell<u32>,
    ) -> (
        impl FnMut(usize, u32) -> Vec2 + 's,
        impl FnMut(usize, &LightSample) -> Vec3 + 's,
    ) {
        (
            move |li, i| {
                current.set(i);
                self.jitter(key, li, i)
            },
            move |li, s: &LightSample| {
                self.visibility(li, current.get(), tri, pixel, sp, s, counts)
            },
        )
    }

    /// `m` without the ambient stand-in for its specular lobe
    /// (`ks_ambient`) when the scene's environment map is reflected by that
    /// lobe instead ([`environment_specular`]); `None` when `m` is used as
    /// it is.
    #[inline]
    fn without_specular_ambient(&self, m: &SurfaceMaterial) -> Option<SurfaceMaterial> {
        (m.ks_ambient != Vec3::ZERO && self.ps.prefiltered_environment().is_some())
            .then(|| m.under_environment(true))
    }

    /// `m` as this frame lights it: [`Self::without_specular_ambient`]'s
    /// copy, kept in `owned`, or `m` itself.
    #[inline]
    fn frame_material<'m>(
        &self,
        m: &'m SurfaceMaterial,
        owned: &'m mut Option<SurfaceMaterial>,
    ) -> &'m SurfaceMaterial {
        match self.without_specular_ambient(m) {
            Some(o) => owned.insert(o),
            None => m,
        }
    }

    /// The jitter of sample `i` of light `li` at the shading point `key`:
    /// area lights at their strata centres, an emitter group's picks from
    /// the jitter sequence Whitted shares ([`group_jitter`]).
    #[inline]
    pub(crate) fn jitter(&self, key: SampleKey, li: usize, i: u32) -> Vec2 {
        match self.lighting.group {
            Some(g) if g.contains(li) => group_jitter(self.settings.seed, key, i),
            _ => Vec2::splat(0.5),
        }
    }

    /// The illumination split for flat and Gouraud shading: one evaluation
    /// of [`shade_local_split`], whose `rest` is exactly the illumination
    /// with `kd = 0`.
    pub(crate) fn illuminate_split(
        &self,
        tri: u32,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
    ) -> Split {
        let mut owned = None;
        let m = self.frame_material(m, &mut owned);
        if let Some(pl) = &self.point_lighting {
            let [total, rest] = pl.shade_split(m, sp);
            return Split {
                diffuse: total - rest,
                rest,
            };
        }
        let current = Cell::new(0u32);
        let (jitter, visibility) =
            self.sampling(tri, SampleKey::Point(sp.p), None, sp, None, &current);
        let [total, rest] = shade_local_split(m, sp, &self.lighting, jitter, visibility);
        Split {
            diffuse: total - rest,
            rest,
        }
    }

    /// The light for flat and Gouraud shading of a textured surface: one
    /// evaluation of [`shade_local_factored`] with the specular lobe of
    /// `lobe` (its colours unread), which [`Ctx::factored_sample`] colours
    /// per pixel.
    pub(crate) fn illuminate_factored(
        &self,
        tri: u32,
        lobe: &SurfaceMaterial,
        sp: &ShadingPoint,
    ) -> FactoredLight {
        let current = Cell::new(0u32);
        let (jitter, visibility) =
            self.sampling(tri, SampleKey::Point(sp.p), None, sp, None, &current);
        shade_local_factored(lobe, sp, &self.lighting, jitter, visibility)
    }

    /// Untextured material (vertex colour applied) at a surface point, as
    /// flat and Gouraud shading light an untextured surface.
    pub(crate) fn untextured_material(&self, hit: &SurfaceHit) -> SurfaceMaterial {
        SurfaceMaterial::with_vertex_color(self.ps.material(hit.material), hit.color)
    }

    /// `SurfaceMaterial::from_material` of the triangle's material.
    #[inline]
    pub(crate) fn base(&self, td: &TriData<'_>) -> SurfaceMaterial {
        match self.bases.get(td.material_id.index()) {
            Some(b) => *b,
            None => SurfaceMaterial::from_material(td.material),
        }
    }
}

/// What shading one sample produced.
#[derive(Clone, Copy)]
pub(crate) struct SampleResult {
    pub(crate) color: Vec3,
    pub(crate) depth: f32,
    pub(crate) normal: Vec3,
    /// The part of `color` from specular reflection (and emission), when
    /// asked for: what interpolated transparency keeps unattenuated.
    pub(crate) specular: Vec3,
    /// A BLEND point's straight-through transmission `1 - alpha` (its
    /// colour is premultiplied by alpha in the surface layer).
    pub(crate) coverage_kt: Option<Vec3>,
}

/// Step 5 for one tile: the box-filtered pixels and, with `keep_samples`,
/// the colour of every sample of the window (indexed like `tv.ids`; empty
/// otherwise) for the tent filter.
pub(crate) fn shade_tile<'a>(
    ctx: &Ctx<'a, '_>,
    poly: &PolyShading,
    tv: &TileVis,
    offsets: &[[i32; 2]],
    keep_samples: bool,
    cache: &mut TriCache<'a>,
) -> (TilePixels, Vec<Vec3>) {
    let rect = tv.rect;
    let mut out = TilePixels::new(rect);
    let spp = offsets.len();
    let mut kept = if keep_samples {
        vec![Vec3::ZERO; tv.ids.len()]
    } else {
        Vec::new()
    };
    let inv_spp = 1.0 / spp as f32;
    let sub = crate::raster::SUBPIXEL as f32;
    let nl = match &ctx.shadows {
        Shadows::Volume(v) => v.slot.iter().flatten().count(),
        _ => 0,
    };
    let counts_of = |p: usize| {
        (nl > 0)
            .then(|| tv.counts.get(p * nl..(p + 1) * nl))
            .flatten()
    };
    let env_background = ctx
        .ps
        .scene
        .environment
        .as_ref()
        .is_some_and(|e| e.as_background);
    let win = tv.window;
    // The row- and column-only parts of the sample directions (Rays::dir),
    // per window column (or row) and sample.
    let sample_x = |px: u32, o: &[i32; 2]| (rect.x + px) as f32 + o[0] as f32 / sub;
    let sample_y = |py: u32, o: &[i32; 2]| (rect.y + py) as f32 + o[1] as f32 / sub;
    let (wx0, wy0) = (win.x0 - rect.x, win.y0 - rect.y);
    let columns: Vec<Vec3A> = (wx0..win.x1 - rect.x)
        .flat_map(|px| {
            offsets
                .iter()
                .map(move |o| ctx.rays.column(sample_x(px, o)))
        })
        .collect();
    let rows: Vec<Vec3A> = (wy0..win.y1 - rect.y)
        .flat_map(|py| offsets.iter().map(move |o| ctx.rays.row(sample_y(py, o))))
        .collect();
    if spp == 1 && !keep_samples && tv.start.is_empty() {
        // One opaque sample per pixel, none kept: the loop below with its
        // sum and nearest-depth choice folded (the sanitised colour c is
        // 0 + c times 1; the sample is nearest when its depth is below
        // infinity), and the direction made only where it is read.
        let background = sanitize(ctx.ps.scene.background);
        let tw = rect.width as usize;
        let o = &offsets[0];
        for (py, &row) in (wy0..win.y1 - rect.y).zip(&rows) {
            let line = py as usize * tw;
            for (px, &column) in (wx0..win.x1 - rect.x).zip(&columns) {
                let pi = line + px as usize;
                let id = tv.ids[pi];
                if id == NONE {
                    out.color[pi] = if env_background {
                        let dir = Rays::dir_from(column, row);
                        sanitize(background_radiance(ctx.ps.scene, dir.into()))
                    } else {
                        background
                    };
                    continue;
                }
                let dir = Rays::dir_from(column, row);
                let td = ctx.tri_data(id, cache, poly);
                let (sx, sy) = (sample_x(px, o), sample_y(py, o));
                let r = if td.lean {
                    lean_sample(ctx, td, sx, sy, dir)
                } else {
                    let whole = SampleShare::WHOLE;
                    shade_sample(ctx, poly, td, sx, sy, dir, counts_of(pi), false, whole)
                };
                out.color[pi] = sanitize(r.color);
                if r.depth < f32::INFINITY {
                    out.depth[pi] = r.depth;
                    out.normal[pi] = r.normal;
                }
            }
        }
        return (out, kept);
    }
    for (py, rows) in (wy0..win.y1 - rect.y).zip(rows.chunks_exact(spp)) {
        for (px, columns) in (wx0..win.x1 - rect.x).zip(columns.chunks_exact(spp)) {
            let pi = (py * rect.width + px) as usize;
            let mut sum = Vec3::ZERO;
            let mut best_depth = f32::INFINITY;
            let mut best_normal = Vec3::ZERO;
            for (s, ((o, &column), &row)) in offsets.iter().zip(columns).zip(rows).enumerate() {
                let sx = sample_x(px, o);
                let sy = sample_y(py, o);
                let dir = Rays::dir_from(column, row);
                let i = pi * spp + s;
                let id = tv.ids[i];
                // The pixel's light samples are spread over its sub-samples.
                let share = SampleShare::new(s as u32, spp as u32);
                let mut r = if id == NONE {
                    SampleResult {
                        color: if env_background {
                            background_radiance(ctx.ps.scene, dir.into())
                        } else {
                            ctx.ps.scene.background
                        },
                        depth: f32::INFINITY,
                        normal: Vec3::ZERO,
                        specular: Vec3::ZERO,
                        coverage_kt: None,
                    }
                } else {
                    let td = ctx.tri_data(id, cache, poly);
                    if td.lean {
                        lean_sample(ctx, td, sx, sy, dir)
                    } else {
                        shade_sample(ctx, poly, td, sx, sy, dir, counts_of(i), false, share)
                    }
                };
                // Transparent fragments, composited back to front.
                let at = (sx, sy, share);
                composite(ctx, poly, tv, i, at, dir, &mut r, cache, counts_of);
                let c = sanitize(r.color);
                if keep_samples {
                    kept[i] = c;
                }
                sum += c;
                if r.depth < best_depth {
                    best_depth = r.depth;
                    best_normal = r.normal;
                }
            }
            out.color[pi] = sum * inv_spp;
            out.depth[pi] = best_depth;
            out.normal[pi] = best_normal;
        }
    }
    (out, kept)
}

/// [`shade_sample`] of an opaque sample (no specular part asked for) of a
/// [`TriData::lean`] triangle: untextured, one-sided, without reflection
/// map or depth cueing, and for Phong lit by `point_lighting` (flat and
/// Gouraud samples only interpolate what was lit with any lights and
/// shadows). The same
/// floating-point operations in the same order as `shade_sample` for that
/// case, without what it does not read (uv footprint, the view direction
/// of flat and Gouraud samples, per-corner lookups).
#[inline(always)]
pub(crate) fn lean_sample(
    ctx: &Ctx<'_, '_>,
    td: &TriData,
    sx: f32,
    sy: f32,
    dir: Vec3A,
) -> SampleResult {
    let b = td
        .bary_at(&ctx.rays, sx, sy, dir)
        .unwrap_or(Vec2::splat(1.0 / 3.0));
    let (u, v) = (b.x, b.y);
    // Ctx::surface: w = 1 - u - v and the same interpolations.
    let w = 1.0 - u - v;
    let p = td.p[0] * w + td.p[1] * u + td.p[2] * v;
    let depth = ctx.rays.distance(p);
    let ng = td.ng;
    let ns = || {
        let ns = exact::try_normalize(td.n[0] * w + td.n[1] * u + td.n[2] * v).unwrap_or(ng);
        if ns.dot(ng) < 0.0 { ng } else { ns }
    };
    let (color, normal) = match td.mode {
        ShadeMode::Phong => {
            let ns = ns();
            (phong::lean_color(ctx, td, [w, u, v], p, depth, ns), ns)
        }
        ShadeMode::Gouraud => (gouraud::lean_color(td, [w, u, v]), ns()),
        ShadeMode::Flat => (flat::lean_color(td), ng),
    };
    SampleResult {
        color,
        depth,
        normal: normal.into(),
        specular: Vec3::ZERO,
        coverage_kt: None,
    }
}

/// A visible sample as every shading method reads it.
pub(crate) struct SampleAt {
    /// The surface at the sample (shading normal only for Gouraud and Phong).
    pub(crate) hit: SurfaceHit,
    /// Perspective-correct barycentrics `(u, v)` of the sample.
    pub(crate) b: Vec2,
    /// The uv footprint of one pixel, along x and y (zero for untextured
    /// triangles).
    pub(crate) duv: [Vec2; 2],
    /// Unit direction to the eye (zero where the method does not read it).
    pub(crate) wo: Vec3,
    /// -1 where the back of a two-sided surface is seen (the normals'
    /// factor), else 1.
    pub(crate) sign: f32,
    /// Film position of the sample.
    pub(crate) film: Vec2,
    /// Which of its pixel's sub-samples it is, for the light samples it
    /// takes.
    pub(crate) share: SampleShare,
}

impl Ctx<'_, '_> {
    /// The sample `at` of an untextured flat or Gouraud triangle, whose
    /// illumination `split` (colours included) is constant or
    /// interpolated, shaded with the normal `n`.
    #[inline]
    pub(crate) fn split_sample(&self, td: &TriData, at: &SampleAt, split: Split, n: Vec3) -> Lit {
        let ps = self.ps;
        let b = at.b;
        // The material with the vertex colour at the sample (flat and
        // Gouraud triangles do not carry it), for the environment terms.
        let vertex_lobe = || {
            let [i0, i1, i2] = td.idx;
            let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
            let color = ps.colors[i0] * w.x + ps.colors[i1] * w.y + ps.colors[i2] * w.z;
            SurfaceMaterial::with_vertex_color(td.material, color)
        };
        let lobe = ps.prefiltered_environment().map(|_| vertex_lobe());
        Lit {
            color: split.diffuse + split.rest,
            n,
            specular: split.rest,
            coverage_kt: None,
            reflects: (td.material.reflect, lobe),
        }
    }

    /// The sample `at` of a textured flat or Gouraud triangle, whose light
    /// without colours `light` is constant or interpolated, shaded with the
    /// normal `n`: the colours of the surface layer at the sample (textures
    /// filtered over its footprint, the vertex colour, alpha), applied to
    /// `light` by the one local model ([`FactoredLight::radiance`]), so a
    /// textured metal's F0 and a textured base colour show as in Phong
    /// shading.
    #[inline]
    pub(crate) fn factored_sample(
        &self,
        td: &TriData,
        at: &SampleAt,
        light: &FactoredLight,
        n: Vec3,
    ) -> Lit {
        let sm = self.ps.surface_material_lod(&at.hit, at.duv[0], at.duv[1]);
        let mut owned = None;
        let m = self.frame_material(&sm, &mut owned);
        let color = light.radiance(m);
        // What does not scale with the diffuse colour (as `Split::rest`).
        let specular = light.radiance(&SurfaceMaterial {
            kd: Vec3::ZERO,
            ..*m
        });
        Lit {
            color,
            n,
            specular,
            coverage_kt: (td.material.alpha_mode == AlphaMode::Blend).then_some(sm.kt),
            reflects: (sm.kr, self.ps.prefiltered_environment().map(|_| sm)),
        }
    }
}

/// What a shading method gives a sample, before the terms every method
/// shares (environment light, reflection map, depth cueing).
pub(crate) struct Lit {
    pub(crate) color: Vec3,
    /// The normal the sample is shaded with (flipped to the viewer's side).
    pub(crate) n: Vec3,
    /// The part of `color` from specular reflection and emission.
    pub(crate) specular: Vec3,
    /// A BLEND point's straight-through transmission (see [`SampleResult`]).
    pub(crate) coverage_kt: Option<Vec3>,
    /// What reflects the environment: the reflection map's weight `kr`, and
    /// the lobe that reflects the prefiltered environment when there is one.
    pub(crate) reflects: (Vec3, Option<SurfaceMaterial>),
}

/// Shades the sample at film position `(sx, sy)` (direction `dir`) where
/// triangle `t` is visible, by the triangle's shading mode. `counts` are the
/// point's shadow-volume counts per light; with `want_specular` the result
/// also holds its non-diffuse part; `share` is the sample's place among its
/// pixel's sub-samples.
#[allow(clippy::too_many_arguments)]
pub(crate) fn shade_sample(
    ctx: &Ctx<'_, '_>,
    poly: &PolyShading,
    td: &TriData,
    sx: f32,
    sy: f32,
    dir: Vec3A,
    counts: Option<&[i32]>,
    want_specular: bool,
    share: SampleShare,
) -> SampleResult {
    let ps = ctx.ps;
    let [i0, i1, i2] = td.idx;
    // Perspective-correct barycentrics of the sample and of its neighbours.
    let third = Vec2::splat(1.0 / 3.0);
    let b = td.bary_at(&ctx.rays, sx, sy, dir).unwrap_or(third);
    let material = td.material;
    let needs_footprint = td.textured;
    // Flat samples read no shading normal or vertex colour, unless
    // textured (the colours are then applied per sample).
    let shading = td.mode != ShadeMode::Flat || needs_footprint;
    let hit = ctx.surface(td, b.x, b.y, needs_footprint, shading);
    let (duv_dx, duv_dy) = if needs_footprint {
        let uv_at = |x: f32, y: f32| {
            let bb = td
                .bary_at(&ctx.rays, x, y, ctx.rays.dir(x, y).into())
                .unwrap_or(b);
            ps.uvs[i0] * (1.0 - bb.x - bb.y) + ps.uvs[i1] * bb.x + ps.uvs[i2] * bb.y
        };
        let dx = uv_at(sx + 1.0, sy) - hit.uv;
        let dy = uv_at(sx, sy + 1.0) - hit.uv;
        if dx.is_finite() && dy.is_finite() {
            (dx, dy)
        } else {
            (Vec2::ZERO, Vec2::ZERO)
        }
    } else {
        (Vec2::ZERO, Vec2::ZERO)
    };
    let p_a = Vec3A::from(hit.p);
    // Flat and Gouraud samples read the view direction only to tell the
    // back of a two-sided surface and for the reflection map.
    let wo = if td.mode == ShadeMode::Phong
        || material.sidedness.eye_sees_back()
        || ctx.ps.scene.environment.is_some()
    {
        Vec3::from(exact::normalize_or_zero(ctx.rays.toward_viewer(p_a)))
    } else {
        Vec3::ZERO
    };
    let flip = material.sidedness.eye_sees_back() && hit.ng.dot(wo) < 0.0;
    let at = SampleAt {
        hit,
        b,
        duv: [duv_dx, duv_dy],
        wo,
        sign: if flip { -1.0 } else { 1.0 },
        film: Vec2::new(sx, sy),
        share,
    };
    // The method's own step.
    let Lit {
        mut color,
        n,
        mut specular,
        coverage_kt,
        reflects: (kr, lobe),
    } = match td.mode {
        ShadeMode::Phong => phong::shade(ctx, td, &at, counts, want_specular),
        ShadeMode::Gouraud => gouraud::shade(ctx, poly, td, &at),
        ShadeMode::Flat => flat::shade(ctx, td, &at),
    };
    let (kr, lobe) = if flip {
        back_face(ctx, material, &hit, &mut color, &mut specular, (kr, lobe))
    } else {
        (kr, lobe)
    };
    // The environment's diffuse light and its reflection by the glossy
    // lobe (the split sum).
    if let (Some(table), Some(lobe)) = (ps.prefiltered_environment(), lobe) {
        let glossy = environment_specular(table, ps.scene, &lobe, n, wo);
        color += environment_diffuse(table, lobe.kd, n) + glossy;
        specular += glossy;
    }
    // Reflection map: the environment in the mirror direction, weighted by
    // kr (times a conductor's Fresnel reflectance).
    if ctx.ps.scene.environment.is_some() && kr.max_element() > 0.0 {
        let kr = mirror_reflectance(kr, material.conductor, n.dot(wo));
        color += kr * environment_radiance(ctx.ps.scene, reflect(wo, n));
    }
    let depth = ctx.rays.distance(p_a);
    if let Some(cue) = &ctx.settings.depth_cue {
        color = depth_cue(color, depth, cue);
    }
    SampleResult {
        color,
        depth,
        normal: n,
        specular,
        coverage_kt,
    }
}

/// The sidedness rule on a back face the method has shaded with flipped
/// normals (ARCHITECTURE.md, "Sidedness"): the back of a one-sided surface
/// reflects nothing, and an emitter emits from its back only when
/// `emission_two_sided`. Returns what reflects the environment.
fn back_face(
    ctx: &Ctx<'_, '_>,
    material: &Material,
    hit: &SurfaceHit,
    color: &mut Vec3,
    specular: &mut Vec3,
    reflects: (Vec3, Option<SurfaceMaterial>),
) -> (Vec3, Option<SurfaceMaterial>) {
    let transmissive = material.transmit.max_element() > 0.0;
    if material.sidedness.seen_from(-1.0, transmissive) == Facing::BackBlack {
        *color = Vec3::ZERO;
        *specular = Vec3::ZERO;
        return (Vec3::ZERO, None);
    }
    if !material.emission_two_sided
        && (material.emission != Vec3::ZERO || material.emission_texture.is_some())
    {
        // The methods add the emission once (`shade_local`): take it out.
        let e = ctx.untextured_material(hit).emission;
        *color = (*color - e).max(Vec3::ZERO);
        *specular = (*specular - e).max(Vec3::ZERO);
    }
    reflects
}

impl<'a, 's> Ctx<'a, 's> {
    /// The shading context of a frame: `mode` is the default shading mode,
    /// `emitters` the grouped emissive meshes, `class` how each material is
    /// drawn.
    pub(crate) fn new(
        ps: &'a PreparedScene<'s>,
        frame: Frame<'a>,
        mode: ShadeMode,
        emitters: &'a Option<EmitterGroup>,
        shadows: Shadows,
        class: Vec<Class>,
    ) -> Self {
        let Frame {
            settings,
            camera,
            derived,
        } = frame;
        let scene = ps.scene;
        let (w, h) = (settings.width, settings.height);
        let object_mode: Vec<ShadeMode> = scene
            .objects
            .iter()
            .map(|o| o.shade_mode.unwrap_or(mode))
            .collect();
        let group_rays = (emitters.is_some()
            && !matches!(shadows, Shadows::None | Shadows::Ray(_))
            || matches!(&shadows, Shadows::Volume(v) if v.by_ray.contains(&true)))
        .then(|| RayShadows::kept(ps, derived));
        Ctx {
            ps,
            settings,
            rays: Rays::new(camera, w, h),
            lighting: LocalLighting {
                lights: &ps.lights,
                area_samples: settings.light_samples.max(1),
                ambient: true,
                group: emitters.as_ref(),
                share: SampleShare::WHOLE,
            },
            group_rays,
            one_mode: object_mode
                .first()
                .copied()
                .filter(|&m| object_mode.iter().all(|&o| o == m)),
            object_mode,
            point_lighting: if matches!(shadows, Shadows::None) {
                PointLighting::new(&ps.lights, true)
            } else {
                None
            },
            bases: {
                // Under a reflected environment the specular lobe's
                // ambient stand-in is dropped (`without_specular_ambient`).
                let reflected = ps.prefiltered_environment().is_some();
                ps.scene
                    .materials
                    .iter()
                    .map(|m| SurfaceMaterial::from_material(m).under_environment(reflected))
                    .collect()
            },
            lean_frame: scene.environment.is_none() && settings.depth_cue.is_none(),
            one_material: ps.tri_material.first().copied().filter(|&m| {
                // Parallel, and stops at the first other material.
                ps.tri_material.par_iter().all(|&mt| mt == m)
            }),
            shadows,
            class,
        }
    }
}

/// Step 4 over the tiles of `vis`: each tile is written into the film as
/// soon as it is shaded, so that its buffers are freed and reused by the
/// next tile instead of every tile's pixels being alive (and fresh pages)
/// at once. With `tent`, returns the sample colours of every tile for the
/// resolve.
pub(crate) fn shade_tiles(
    ctx: &Ctx<'_, '_>,
    poly: &PolyShading,
    vis: &[TileVis],
    offsets: &[[i32; 2]],
    tent: bool,
    film: &mut Film,
    progress: &dyn Progress,
) -> Result<Vec<(TileRect, Vec<Vec3>)>, CoreError> {
    let film = Mutex::new(film);
    let kept: Mutex<Vec<(TileRect, Vec<Vec3>)>> = Mutex::new(Vec::new());
    // One triangle cache per shading job, kept from tile to tile.
    let finished = vis
        .par_iter()
        .try_for_each_init(TriCache::new, |cache, tv| {
            if progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            let (pixels, samples) = shade_tile(ctx, poly, tv, offsets, tent, cache);
            film.lock()
                .unwrap_or_else(PoisonError::into_inner)
                .write_tile(&pixels);
            if tent {
                kept.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push((pixels.rect, samples));
            }
            progress.advance(1);
            Ok(())
        });
    finished?;
    let kept = kept.into_inner().unwrap_or_else(PoisonError::into_inner);
    Ok(kept)
}
