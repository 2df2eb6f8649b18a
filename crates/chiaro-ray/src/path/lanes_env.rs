//! The lock-step kernel's environment work, lane-parallel: what escaping
//! lanes see of the map ([`PathTracer::escaped_lanes`]) and the
//! environment's next-event estimation at Lambert and mixture vertices
//! ([`PathTracer::direct_env_lanes`]).
//!
//! Both compute, lane by lane, the bits of the scalar loop's
//! [`PathTracer::escaped`] and [`PathTracer::direct_env`]: the map's
//! lookups and samples are `EnvironmentLight::radiance_pdf_lanes` and
//! `sample_lanes`, of which the scalar `radiance_pdf` and `sample` are the
//! one-lane case; the MIS rules are the functions both loops call. What
//! runs as lane loops: the lat-long mapping and its inverse (the
//! polynomial `atan2` and `sin_cos`), the unit directions, the bilinear
//! weights and blends, the densities' and MIS weights' arithmetic, the
//! Lambert terms. What stays lane by lane, batched so that the lanes'
//! memory reads overlap: the CDF searches, the texel and density reads,
//! the mixture lanes' `Bsdf::eval` and `Bsdf::pdf`, and the shadow rays.

// A lane loop indexes a dozen arrays by the lane number (as in `lanes.rs`).
#![allow(clippy::needless_range_loop)]

use super::PathTracer;
use super::integrator::MaterialInfo;
use super::lanes::{dot, passes, set_lanes};
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::sampling::cosine_hemisphere_pdf;
use chiaro_core::sampling::sobol::LANES;
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// One `f32` per lane.
type F = [f32; LANES];

/// A vector per lane, as three component arrays.
pub(super) type V = [F; 3];

/// Lane `i` of `v`.
#[inline(always)]
fn at(v: &V, i: usize) -> [f32; 3] {
    [v[0][i], v[1][i], v[2][i]]
}

/// Lane `i` of `v` as a `Vec3`.
#[inline(always)]
fn get(v: &V, i: usize) -> Vec3 {
    Vec3::from_array(at(v, i))
}

/// The lanes' vertices as the environment's next-event estimation needs
/// them: position, viewer-side shading and geometric normals, the
/// incoming ray's direction, Lambert's colour (`kd`), the mixture flag.
pub(super) struct EnvVertices<'v> {
    pub(super) p: &'v V,
    pub(super) n: &'v V,
    pub(super) ngs: &'v V,
    pub(super) dir: &'v V,
    pub(super) kd: &'v V,
    pub(super) glossy: &'v [bool; LANES],
}

impl PathTracer<'_, '_> {
    /// What the rays `(org[i], dir[i])` of the lanes set in `esc` see as
    /// they escape at segment `depth` after scatters of pdf `prev_pdf[i]`,
    /// each [`Self::escaped`] of its lane: where the map is seen
    /// ([`Self::sees_map`]), its radiance and density lane-parallel and the
    /// MIS weight ([`Self::escape_weight`]) per lane; elsewhere `escaped`
    /// itself.
    #[inline(never)]
    pub(super) fn escaped_lanes(
        &self,
        esc: &[bool; LANES],
        org: &V,
        dir: &V,
        depth: u32,
        prev_pdf: &F,
    ) -> V {
        let mut seen = [[0.0; LANES]; 3];
        let map: [bool; LANES] = std::array::from_fn(|i| esc[i] & self.sees_map(depth));
        let other: [bool; LANES] = std::array::from_fn(|i| esc[i] & !map[i]);
        for i in set_lanes(&other) {
            let c = self.escaped(&Ray::new(get(org, i), get(dir, i)), depth, prev_pdf[i]);
            (seen[0][i], seen[1][i], seen[2][i]) = (c.x, c.y, c.z);
        }
        let Some(env) = self.env.as_ref().filter(|_| map.iter().any(|&m| m)) else {
            return seen;
        };
        let (radiance, pdf) = env.radiance_pdf_lanes(dir, &map);
        for i in set_lanes(&map) {
            let l = get(&radiance, i);
            let c = if escape_mis(depth, prev_pdf[i]) {
                l * self.escape_weight(get(org, i), prev_pdf[i], pdf[i])
            } else {
                l
            };
            (seen[0][i], seen[1][i], seen[2][i]) = (c.x, c.y, c.z);
        }
        seen
    }

    /// [`Self::direct_env`] at the vertices `vx` of the lanes set in `m`,
    /// which chose the environment with probability `pick[i]` and whose
    /// light sample's pair is `(u[0][i], u[1][i])`; MIS-weighted when
    /// `mis`. Each lane's `f cos L w / pdf` (zero where the sample finds
    /// nothing), as the scalar loop computes it. The samples and lookups
    /// lane-parallel (`EnvironmentLight::sample_lanes`), the Lambert lanes'
    /// terms in lane loops (the kernel's spelling of `Bsdf::eval` and
    /// `Bsdf::pdf` for Lambert, as its triangle-light sample), the mixture
    /// lanes' through the BSDF lane by lane, shadow rays one at a time.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub(super) fn direct_env_lanes(
        &self,
        m: &[bool; LANES],
        pick: &F,
        vx: &EnvVertices<'_>,
        info: &[Option<&MaterialInfo>; LANES],
        mis: bool,
        u: &[F; 2],
        rays: &mut u64,
    ) -> V {
        let mut out = [[0.0; LANES]; 3];
        let Some(env) = &self.env else {
            return out;
        };
        // `direct_from`'s and `direct_env`'s first tests.
        let ask: [bool; LANES] =
            std::array::from_fn(|i| m[i] & passes(pick[i]) & info[i].is_some_and(|mi| !mi.dark));
        let s = env.sample_lanes(&u[0], &u[1], &ask);
        // The sample's tests and the Lambert lanes' `f cos` and BSDF pdf.
        let mut ok = s.ok;
        let mut f = [[0.0; LANES]; 3];
        let mut bsdf_pdf: F = [0.0; LANES];
        for i in 0..LANES {
            let (wi, rad) = (at(&s.wi, i), at(&s.radiance, i));
            let c_i = dot(at(vx.n, i), wi);
            let kd = at(vx.kd, i);
            let f_cos = lambert_f_cos(kd, c_i);
            (f[0][i], f[1][i], f[2][i]) = (f_cos[0], f_cos[1], f_cos[2]);
            bsdf_pdf[i] = cosine_hemisphere_pdf(c_i);
            // (`&` rather than `&&`: no branches in the lane loop.)
            ok[i] = ok[i]
                & passes(dot(at(vx.ngs, i), wi))
                & ((rad[0] != 0.0) | (rad[1] != 0.0) | (rad[2] != 0.0))
                & (vx.glossy[i] | (passes(c_i) & nonzero(f_cos)));
        }
        // The mixture lanes' BSDF, lane by lane.
        let mixture: [bool; LANES] = std::array::from_fn(|i| ok[i] & vx.glossy[i]);
        for i in set_lanes(&mixture) {
            let Some(mi) = info[i] else { continue };
            let (n, wo, wi) = (get(vx.n, i), -get(vx.dir, i), get(&s.wi, i));
            let f_cos = mi.bsdf.eval(n, wo, wi);
            (f[0][i], f[1][i], f[2][i]) = (f_cos.x, f_cos.y, f_cos.z);
            ok[i] = f_cos != Vec3::ZERO;
            if ok[i] && mis {
                bsdf_pdf[i] = mi.bsdf.pdf(n, wo, wi);
            }
        }
        // Shadow rays, one at a time.
        let mut tr = [[0.0; LANES]; 3];
        for i in set_lanes(&ok) {
            *rays += 1;
            let (p, ng, wi) = (get(vx.p, i), get(vx.ngs, i), get(&s.wi, i));
            match self.shadow_pass(&Ray::new(offset_ray_origin(p, ng, wi), wi)) {
                Some(t) => (tr[0][i], tr[1][i], tr[2][i]) = (t.x, t.y, t.z),
                None => ok[i] = false,
            }
        }
        // `f cos L w / pdf`, lane-parallel.
        for i in 0..LANES {
            let w = env_weight(s.pdf[i] * pick[i], bsdf_pdf[i], mis);
            let (f_cos, rad, t) = (at(&f, i), at(&s.radiance, i), at(&tr, i));
            for k in 0..3 {
                let c = f_cos[k] * rad[k] * w * t[k];
                out[k][i] = if ok[i] { c } else { 0.0 };
            }
        }
        out
    }
}

/// True when a scattered ray's escape is weighted against the
/// environment's next-event estimation: after a non-delta scatter.
#[inline(always)]
pub(super) fn escape_mis(depth: u32, prev_pdf: f32) -> bool {
    depth > 0 && prev_pdf > 0.0
}

/// The environment sample's weight over its pdf `light_pdf` (the choice
/// included) against BSDF sampling's `bsdf_pdf`: the power heuristic's
/// `(l^2 / (l^2 + b^2)) / l` in one division with `mis`, else `1 / l`.
#[inline(always)]
pub(super) fn env_weight(light_pdf: f32, bsdf_pdf: f32, mis: bool) -> f32 {
    if mis {
        light_pdf / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf)
    } else {
        1.0 / light_pdf
    }
}

/// `Bsdf::eval` of a Lambertian material of colour `kd` where the cosine
/// `c_i` is positive (`eval_brdf_cos`'s expression, spelled per component
/// so that lane loops vectorise; the kernel-vs-scalar tests hold the two
/// to the same bits).
#[inline(always)]
pub(super) fn lambert_f_cos(kd: [f32; 3], c_i: f32) -> [f32; 3] {
    kd.map(|k| k * (FRAC_1_PI * c_i))
}

/// `v != Vec3::ZERO`, without branches.
#[inline(always)]
fn nonzero(v: [f32; 3]) -> bool {
    (v[0] != 0.0) | (v[1] != 0.0) | (v[2] != 0.0)
}
