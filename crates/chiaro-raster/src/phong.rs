//! Phong (1975) shading for the scan converter: the normal interpolated
//! across the triangle and the illumination model evaluated at every
//! sample (Bui Tuong Phong, "Illumination for Computer Generated
//! Pictures", CACM 18(6), 1975; Foley et al. 16.2.5). The per-sample steps every method shares
//! are in [`crate::pipeline::shading`].

use crate::pipeline::shading::{Ctx, Lit, SampleAt};
use crate::pipeline::triangles::TriData;
use chiaro_core::scene::AlphaMode;
use chiaro_core::shading::{ShadingPoint, SurfaceMaterial};
use glam::{Vec3, Vec3A};

/// Phong shading of the sample `at` of triangle `td`: the material (with
/// textures, normal and bump maps where the triangle is textured) lit at
/// the interpolated normal. `counts` are the sample's shadow-volume counts
/// per light; with `want_specular` the result also holds its non-diffuse
/// part.
#[inline]
pub(crate) fn shade(
    ctx: &Ctx<'_, '_>,
    td: &TriData,
    at: &SampleAt,
    counts: Option<&[i32]>,
    want_specular: bool,
) -> Lit {
    let (ps, t, hit, wo, sign) = (ctx.ps, td.t, &at.hit, at.wo, at.sign);
    let needs_footprint = td.textured;
    let prefiltered = ps.prefiltered_environment();
    if !needs_footprint && !want_specular && ctx.point_lighting.is_some() {
        // The common case without copying the material: untextured (so
        // no bump or normal map), the point-light model, no pixel index.
        let base = ctx.bases.get(td.material_id.index());
        let owned;
        let base = match base {
            Some(b) => b,
            None => {
                owned = ctx.base(td);
                &owned
            }
        };
        let n = hit.ns * sign;
        let sp = ShadingPoint {
            p: hit.p,
            n,
            ng: hit.ng * sign,
            wo,
        };
        let c = match &ctx.point_lighting {
            Some(pl) => pl.shade_kd(base, base.kd * hit.color, &sp),
            // Not reached: the condition above checked `point_lighting`.
            None => ctx.illuminate(
                t,
                None,
                &SurfaceMaterial {
                    kd: base.kd * hit.color,
                    ..*base
                },
                &sp,
                counts,
                at.share,
            ),
        };
        let lobe = prefiltered.map(|_| SurfaceMaterial {
            kd: base.kd * hit.color,
            ..*base
        });
        return Lit {
            color: c,
            n,
            specular: Vec3::ZERO,
            coverage_kt: None,
            reflects: (base.kr, lobe),
        };
    }
    let mut coverage_kt = None;
    let (sm, n) = if needs_footprint {
        // The surface layer: textures, normal and bump maps.
        let (dpdu, dpdv) = ps.triangle_dpduv(t);
        let ss = ps.shading_surface_at(*hit, dpdu, dpdv, at.duv[0], at.duv[1]);
        if td.material.alpha_mode == AlphaMode::Blend {
            coverage_kt = Some(ss.material.kt);
        }
        (ss.material, ss.ns)
    } else {
        // The layer without textures or maps: the vertex colour only.
        let mut sm = ctx.base(td);
        sm.kd *= hit.color;
        (sm, hit.ns)
    };
    let n = n * sign;
    let sp = ShadingPoint {
        p: hit.p,
        n,
        ng: hit.ng * sign,
        wo,
    };
    // A sample at a pixel centre (one sample per pixel) names its pixel.
    let (sx, sy) = (at.film.x, at.film.y);
    let pixel = (sx.fract() == 0.5 && sy.fract() == 0.5 && sx >= 0.0 && sy >= 0.0)
        .then_some((sx as u32, sy as u32));
    let c = ctx.illuminate(t, pixel, &sm, &sp, counts, at.share);
    let mut specular = Vec3::ZERO;
    if want_specular {
        let diffuse_only = SurfaceMaterial {
            ks: Vec3::ZERO,
            emission: Vec3::ZERO,
            ..sm
        };
        specular = c - ctx.illuminate(t, pixel, &diffuse_only, &sp, counts, at.share);
    }
    Lit {
        color: c,
        n,
        specular,
        coverage_kt,
        reflects: (sm.kr, prefiltered.map(|_| sm)),
    }
}

/// The colour of a [`TriData::lean`] Phong sample at barycentric weights
/// `w` (of the three corners), position `p`, distance `depth` from the eye
/// and unit shading normal `ns`: the point-light model on the untextured
/// material. The same operations as [`shade`] for that case.
#[inline(always)]
pub(crate) fn lean_color(
    ctx: &Ctx<'_, '_>,
    td: &TriData,
    [w, u, v]: [f32; 3],
    p: Vec3A,
    depth: f32,
    ns: Vec3A,
) -> Vec3 {
    let eye = Vec3A::from(ctx.rays.eye);
    let color = td.c[0] * w + td.c[1] * u + td.c[2] * v;
    // exact::normalize_or_zero(eye - p): |eye - p| is `depth`, bit
    // for bit (the same squares summed in the same order).
    let rcp = 1.0 / depth;
    let wo = if ctx.rays.ortho.is_some() {
        // Parallel rays: the view direction is the same everywhere.
        ctx.rays.toward_viewer(p)
    } else if rcp.is_finite() && rcp > 0.0 {
        (eye - p) * rcp
    } else {
        Vec3A::ZERO
    };
    let sp = ShadingPoint {
        p: p.into(),
        n: ns.into(),
        ng: td.ng.into(),
        wo: wo.into(),
    };
    match (&ctx.point_lighting, ctx.bases.get(td.material_id.index())) {
        (Some(pl), Some(base)) => pl.shade_kd(base, base.kd * Vec3::from(color), &sp),
        // Not reached: TriData::lean checked both.
        _ => Vec3::ZERO,
    }
}
