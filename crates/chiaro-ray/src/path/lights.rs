//! Next-event estimation: one light chosen by power, a sample on it and a
//! shadow ray, combined with BSDF sampling by the power heuristic (Veach 1997).

use super::integrator::{MaterialInfo, PathTracer, Vertex};
use super::lanes_env::env_weight;
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::sampling::{SobolSampler, power_heuristic};
use chiaro_core::scene::{AreaShape, Light};
use chiaro_core::shading::{Bsdf, LightSample, sample_light, sample_light_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// `PathTracer::triangle_light` entry of a triangle that is not a light.
pub(super) const NO_LIGHT: u32 = u32::MAX;

/// True for a light that paths can hit (an emissive triangle of the
/// prepared scene); `Light::Area` quads, disks and spheres are reached by
/// next-event estimation only.
#[inline]
fn is_geometry(light: &Light) -> bool {
    matches!(
        light,
        Light::Area {
            shape: AreaShape::Triangle { .. },
            ..
        }
    )
}

impl PathTracer<'_, '_> {
    /// The probability of choosing light `i` at the point `p` of normal `n`.
    #[inline]
    pub(super) fn light_pick_pdf(&self, p: Vec3, n: Vec3, i: usize) -> f32 {
        self.light_sampler.pmf(p, n, i)
    }

    /// The light for the number `u` at the point `p` of normal `n`: an
    /// index into `lights`, or `lights.len()` for the environment, and the
    /// probability of the choice.
    #[inline]
    pub(super) fn pick_light(&self, p: Vec3, n: Vec3, u: f32) -> Option<(usize, f32)> {
        self.light_sampler.sample(p, n, u)
    }

    /// The number of lights next-event estimation chooses from (the
    /// environment included).
    #[inline]
    pub(super) fn light_count(&self) -> usize {
        self.light_sampler.len()
    }

    /// What reaches the far end of shadow ray `ray`: `None` when it is
    /// blocked, else the transmittance of the BLEND surfaces crossed
    /// (`ShadowCasters::transmittance`, the shared rule: `1 - alpha` per
    /// crossing), 1 in a scene without them (which keeps the plain any-hit
    /// query). BSDF sampling passes a BLEND surface with probability
    /// proportional to `1 - alpha` and keeps the MIS state of the vertex
    /// before it (`radiance_from`), so both strategies estimate the same
    /// transmitted light and the power-heuristic weights stay as they are.
    #[inline]
    pub(super) fn shadow_pass(&self, ray: &Ray) -> Option<Vec3> {
        match &self.shadows {
            None => (!self.accel.occluded(ray)).then_some(Vec3::ONE),
            Some(c) => {
                let tr = c.transmittance(self.accel, ray);
                (tr != Vec3::ZERO).then_some(tr)
            }
        }
    }

    /// MIS weight of emission found by BSDF sampling from `from` (its
    /// point and normal) with pdf `bsdf_pdf`.
    pub(super) fn emitter_mis_weight(
        &self,
        prim: u32,
        (from, from_n): (Vec3, Vec3),
        surf: &Vertex,
        wo: Vec3,
        bsdf_pdf: f32,
    ) -> f32 {
        let Some(&li) = self.triangle_light.get(prim as usize) else {
            return 1.0;
        };
        let Some(Some(tl)) = self.tri_lights.get(li as usize) else {
            return 1.0;
        };
        let d2 = (surf.p - from).length_squared();
        let cos_l = surf.ng.dot(wo).abs();
        if cos_l <= 0.0 {
            return 1.0;
        }
        let light_pdf = self.light_pick_pdf(from, from_n, li as usize) * d2 / (cos_l * tl.area);
        power_heuristic(bsdf_pdf, light_pdf)
    }

    /// Next-event estimation: one light chosen by power, one sample on it,
    /// its visibility by a shadow ray; MIS-weighted against BSDF sampling
    /// when the path continues (`mis`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn direct(
        &self,
        p: Vec3,
        info: &MaterialInfo,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> Vec3 {
        // The light choice's number, unless there is only one light (then
        // its pair is skipped, which leaves every later number unchanged).
        let u_pick = if self.light_count() > 1 {
            rng.next_1d()
        } else {
            rng.skip(1);
            0.0
        };
        let u = rng.next_2d();
        let Some((li, pick)) = self.pick_light(p, ng, u_pick) else {
            return Vec3::ZERO;
        };
        self.direct_from((li, pick), p, info, n, ng, wo, mis, u, rays)
    }

    /// [`Self::direct`] with the light chosen (`li`, with probability
    /// `pick`) and its sample's numbers drawn (`u`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn direct_from(
        &self,
        (li, pick): (usize, f32),
        p: Vec3,
        info: &MaterialInfo,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        u: Vec2,
        rays: &mut u64,
    ) -> Vec3 {
        // (A dark material, a mirror or glass: `eval` would be zero for
        // any light sample, found before any shadow ray.)
        if pick <= 0.0 || info.dark {
            return Vec3::ZERO;
        }
        if let Some(tl) = &self.tri_lights[li] {
            // Emissive triangle: L = f cos Le / (pick * pdf_solid_angle).
            let Some(ts) = tl.sample(p, u) else {
                return Vec3::ZERO;
            };
            let (wi, q, light_pdf) = (ts.wi, ts.point, tl.pdf(&ts));
            if ng.dot(wi) <= 0.0 {
                return Vec3::ZERO;
            }
            let f_cos = info.bsdf.eval(n, wo, wi);
            if f_cos == Vec3::ZERO {
                return Vec3::ZERO;
            }
            *rays += 1;
            let Some(tr) = self.shadow_pass(&Ray::segment(offset_ray_origin(p, ng, wi), q)) else {
                return Vec3::ZERO;
            };
            let light_pdf = light_pdf * pick;
            // The power heuristic's weight over the light's pdf, in one
            // division: (l^2 / (l^2 + b^2)) / l = l / (l^2 + b^2).
            let w_over_pdf = if mis {
                let bsdf_pdf = info.bsdf.pdf(n, wo, wi);
                light_pdf / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf)
            } else {
                1.0 / light_pdf
            };
            return f_cos * tl.le * w_over_pdf * tr;
        }
        let Some(&light) = self.lights.get(li) else {
            return self.direct_env(pick, p, &info.bsdf, n, ng, wo, mis, u, rays);
        };
        let Some(s) = sample_light(light, p, u) else {
            return Vec3::ZERO;
        };
        let f_cos = info.bsdf.eval(n, wo, s.wi);
        if f_cos == Vec3::ZERO || ng.dot(s.wi) <= 0.0 {
            return Vec3::ZERO;
        }
        self.shadowed_light_sample(light, &s, f_cos, pick, p, &info.bsdf, n, ng, wo, mis, rays)
    }

    /// The contribution of sample `s` of `light` (picked with probability
    /// `pick`) at `p`, whose BSDF term is `f_cos`: a shadow ray, then `f cos
    /// Le / pdf`, MIS-weighted (`mis`) against BSDF sampling unless the
    /// light is a delta. The kernel's and the reference's point, spot,
    /// directional and area lights end here.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn shadowed_light_sample(
        &self,
        light: &Light,
        s: &LightSample,
        f_cos: Vec3,
        pick: f32,
        p: Vec3,
        bsdf: &Bsdf,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        rays: &mut u64,
    ) -> Vec3 {
        *rays += 1;
        let origin = offset_ray_origin(p, ng, s.wi);
        let shadow = if s.distance.is_finite() {
            Ray::segment(origin, s.point)
        } else {
            Ray::new(origin, s.wi)
        };
        let Some(tr) = self.shadow_pass(&shadow) else {
            return Vec3::ZERO;
        };
        // `pi * intensity` is the light sample's `Le / pdf` (see `LightSample`).
        // MIS only against what BSDF sampling can also find: emissive
        // triangles are geometry, a quad, disk or sphere area light is not
        // (module docs), so next-event estimation alone reaches it and keeps
        // weight 1 (the weights sum to one over the strategies that can make
        // the path, Veach 1997, section 9.2).
        let mut w = 1.0;
        if mis
            && !s.is_delta
            && is_geometry(light)
            && let Some(light_pdf) = sample_light_pdf(light, p, s.point)
        {
            w = power_heuristic(light_pdf * pick, bsdf.pdf(n, wo, s.wi));
        }
        PI * f_cos * s.intensity * (w / pick) * tr
    }

    /// Next-event estimation of the environment (light `lights.len()`,
    /// chosen with probability `pick`): a direction by its luminance, a
    /// shadow ray to infinity, `f cos L / pdf` MIS-weighted (`mis`) against
    /// BSDF sampling as [`Self::escaped`] weights the other strategy.
    /// (Not inlined: `direct_from` stays as small where there is no map.)
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub(super) fn direct_env(
        &self,
        pick: f32,
        p: Vec3,
        bsdf: &Bsdf,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        u: Vec2,
        rays: &mut u64,
    ) -> Vec3 {
        let Some(env) = &self.env else {
            return Vec3::ZERO;
        };
        if pick <= 0.0 {
            return Vec3::ZERO;
        }
        let Some(s) = env.sample(u) else {
            return Vec3::ZERO;
        };
        if ng.dot(s.wi) <= 0.0 || s.radiance == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let f_cos = bsdf.eval(n, wo, s.wi);
        if f_cos == Vec3::ZERO {
            return Vec3::ZERO;
        }
        *rays += 1;
        let Some(tr) = self.shadow_pass(&Ray::new(offset_ray_origin(p, ng, s.wi), s.wi)) else {
            return Vec3::ZERO;
        };
        let bsdf_pdf = if mis { bsdf.pdf(n, wo, s.wi) } else { 0.0 };
        f_cos * s.radiance * env_weight(s.pdf * pick, bsdf_pdf, mis) * tr
    }
}
