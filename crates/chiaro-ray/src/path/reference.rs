//! The plain reference path tracer ([`super::Kernel::Reference`]), kept
//! beside the fast one as pbrt-v4's `SimplePathIntegrator` is beside its
//! `PathIntegrator`: the shape of `PathIntegrator::Li`, built only on the
//! BSDF layer ([`Bsdf`]) and the light functions ([`sample_light`]), with
//! independent PCG numbers (`sampling::pixel_rng`), one path at a time,
//! no lanes and no per-triangle caches. It shares the fast tracer's light
//! selection (power CDF, emissive triangle to light index), its
//! environment sampling, its shadow rays (through BLEND surfaces) and its
//! escaped ray radiance. Tests compare the two statistically, not bit for bit.

use super::PathTracer;
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::sampling::{Rng, power_heuristic, uniform, uniform2};
use chiaro_core::scene::{AlphaMode, Facing};
use chiaro_core::shading::{Bsdf, sample_light, sample_light_pdf};
use glam::Vec3;

impl PathTracer<'_, '_> {
    /// Radiance along camera ray `ray`, and the first hit's distance and
    /// normal: an unbiased estimate with next-event estimation and BSDF
    /// sampling combined by the power heuristic, and Russian roulette.
    pub(super) fn reference_radiance(
        &self,
        mut ray: Ray,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        let (mut l, mut beta) = (Vec3::ZERO, Vec3::ONE);
        let mut first = None;
        // The previous bounce's solid-angle pdf (0: camera or delta) and point.
        let (mut prev_pdf, mut prev_p, mut prev_n) = (0.0f32, ray.origin, Vec3::ZERO);
        // A straight pass through a BLEND surface is not a bounce: `depth`
        // and the MIS state of the vertex before it stay.
        let (mut depth, mut passes) = (0, 0u32);
        while depth < self.max_depth {
            // Find the next vertex, or add what the escaped ray sees.
            *rays += 1;
            // Camera rays skip the backs of single-sided materials.
            let hit = if depth == 0 {
                self.accel.intersect_camera(&ray)
            } else {
                self.accel.intersect(&ray)
            };
            let Some(hit) = hit else {
                l += beta * self.escaped(&ray, depth, prev_pdf);
                break;
            };
            // The surface layer: maps, textured coefficients.
            let ss = self.prepared.shading_surface(&ray, &hit, None);
            let surf = ss.hit;
            let mat = self.prepared.material(surf.material);
            let wo = -ray.dir.normalize();
            if depth == 0 && first.is_none() {
                first = Some((hit.t * ray.dir.length(), ss.ns));
            }
            // Emission found by the path, MIS-weighted against next-event
            // estimation when the light could have been sampled.
            let cos_o = surf.ng.dot(wo);
            // The layer seen from the side of `wo` (a rough dielectric's eta).
            let bsdf = Bsdf::new(ss.material, mat.fresnel).seen_from(cos_o >= 0.0);
            // Beer's law inside an absorbing transmissive medium.
            if cos_o < 0.0 && bsdf.m.kt.max_element() > 0.0 {
                beta *= (-mat.absorption.max(Vec3::ZERO) * (hit.t * ray.dir.length())).exp();
            }
            let le = bsdf.m.emission;
            if le.max_element() > 0.0 && (mat.emission_two_sided || cos_o > 0.0) {
                let light_pdf = (prev_pdf > 0.0)
                    .then(|| self.triangle_light.get(hit.prim as usize))
                    .flatten()
                    .filter(|&&li| li != super::NO_LIGHT)
                    .and_then(|&li| {
                        let li = li as usize;
                        sample_light_pdf(self.lights[li], prev_p, surf.p)
                            .map(|pdf| pdf * self.light_pick_pdf(prev_p, prev_n, li))
                    });
                let w = light_pdf.map_or(1.0, |lp| power_heuristic(prev_pdf, lp));
                l += beta * le * w;
            }
            // The back of a one-sided surface reflects nothing.
            if ss.facing(wo) == Facing::BackBlack {
                break;
            }
            // The shading frame on the viewer's side.
            let front = cos_o >= 0.0;
            let side = if front { 1.0 } else { -1.0 };
            let (n, ng) = (ss.ns * side, surf.ng * side);
            let last = depth + 1 >= self.max_depth;
            // Next-event estimation.
            l += beta * self.reference_direct(surf.p, &bsdf, n, ng, wo, !last, rng, rays);
            let blend = mat.alpha_mode == AlphaMode::Blend;
            if last && !blend {
                break;
            }
            // Sample the BSDF for the next direction.
            let (u_lobe, u) = (uniform(rng), uniform2(rng));
            let Some(s) = bsdf.sample(n, ng, wo, front, u_lobe, u, || uniform(rng)) else {
                break;
            };
            // (BLEND's delta transmission, at ior 1, is the pass-through.)
            let pass = blend && s.delta && ng.dot(s.wi) < 0.0 && passes < super::MAX_PASSES;
            if last && !pass {
                break;
            }
            beta *= s.weight;
            if !beta.is_finite() || beta.max_element() <= 0.0 {
                break;
            }
            if !pass {
                // (Light behind the surface is not sampled by next-event estimation.)
                prev_pdf = if s.delta || ng.dot(s.wi) < 0.0 {
                    0.0
                } else {
                    s.pdf
                };
                prev_p = surf.p;
                prev_n = ng;
            }
            ray = Ray::new(offset_ray_origin(surf.p, surf.ng, s.wi), s.wi);
            // Russian roulette.
            if depth + 1 >= self.rr_depth {
                let q = beta.max_element().min(0.95);
                if uniform(rng) >= q {
                    break;
                }
                beta /= q;
            }
            if pass {
                passes += 1;
            } else {
                passes = 0;
                depth += 1;
            }
        }
        (l, first)
    }

    /// One light chosen by power, one [`sample_light`] sample on it and a
    /// shadow ray: `f cos Le / pdf`, MIS-weighted against BSDF sampling
    /// (`mis`) for emissive triangles (the lights paths can hit).
    #[allow(clippy::too_many_arguments)]
    fn reference_direct(
        &self,
        p: Vec3,
        bsdf: &Bsdf,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        let (u_pick, u) = (uniform(rng), uniform2(rng));
        let Some((li, pick)) = self.pick_light(p, ng, u_pick) else {
            return Vec3::ZERO;
        };
        let Some(&light) = self.lights.get(li) else {
            // The environment (the light after `lights`).
            return self.direct_env(pick, p, bsdf, n, ng, wo, mis, u, rays);
        };
        let Some(s) = sample_light(light, p, u) else {
            return Vec3::ZERO;
        };
        let f_cos = bsdf.eval(n, wo, s.wi);
        if pick <= 0.0 || f_cos == Vec3::ZERO || ng.dot(s.wi) <= 0.0 {
            return Vec3::ZERO;
        }
        self.shadowed_light_sample(light, &s, f_cos, pick, p, bsdf, n, ng, wo, mis, rays)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Kernel, render_with_kernel};
    use chiaro_core::accel::Accelerator;
    use chiaro_core::accel::bvh::SceneBvh;
    use chiaro_core::prepared::PreparedScene;
    use chiaro_core::progress::NoProgress;
    use chiaro_core::scene::{Distribution, ReflectanceModel, Scene};
    use glam::Vec3;

    fn bvh(p: &PreparedScene<'_>) -> Box<dyn Accelerator> {
        Box::new(SceneBvh::new(p))
    }

    /// The shipped scene `scenes/NAME.toml` at `size` x `size` pixels and
    /// `spp` samples per pixel.
    fn shipped(name: &str, size: u32, spp: u32) -> Scene {
        let mut s = chiaro_testkit::scenes::shipped(name, size);
        s.render.samples = spp;
        s
    }

    /// Per-pixel means over `seeds` renders of `kernel` and the variance of
    /// each pixel's single-render value (unbiased, across seeds).
    fn renders(scene: &Scene, kernel: Kernel, seeds: u64) -> (Vec<Vec3>, Vec<Vec3>) {
        let films: Vec<_> = (0..seeds)
            .map(|k| {
                let mut settings = scene.render.clone();
                settings.seed = 1000 + k;
                let (film, _) = render_with_kernel(scene, &settings, &NoProgress, &bvh, kernel)
                    .expect("renders");
                assert!(film.is_clean(), "{kernel:?}: NaN or negative pixels");
                film.color
            })
            .collect();
        chiaro_testkit::stats::pixel_mean_and_variance(&films)
    }

    /// The fast tracer and the reference agree per 8x8 block within four
    /// standard errors (each estimated from the per-pixel variance across
    /// seeds; the pixels of a block are independent).
    fn assert_tracers_agree(scene: &Scene, what: &str) {
        const SEEDS: u64 = 6;
        let size = scene.render.width;
        let (fast, fast_var) = renders(scene, Kernel::Lanes, SEEDS);
        let (reference, ref_var) = renders(scene, Kernel::Reference, SEEDS);
        let worst = chiaro_testkit::stats::worst_block(
            (&fast, &fast_var),
            (&reference, &ref_var),
            size,
            size,
            8,
            SEEDS,
        );
        assert!(
            worst.z <= 4.0,
            "{what}: block {:?} channel {}: difference {} is {:.1} standard errors {}",
            worst.block,
            worst.channel,
            worst.difference,
            worst.z,
            worst.stderr
        );
        assert!(
            fast.iter().any(|c| c.max_element() > 0.0),
            "{what}: black image"
        );
        eprintln!(
            "{what}: largest block difference {:.2} standard errors",
            worst.z
        );
    }

    #[test]
    fn reference_agrees_with_the_fast_tracer_under_an_environment() {
        // Mitsuba's box with glossy walls, its light and an environment
        // with a bright patch, seen through the open front.
        let mut s = shipped("mitsuba-cbox", 32, 8);
        for (k, m) in s.materials.iter_mut().enumerate() {
            if k % 2 == 0 {
                m.model = ReflectanceModel::TorranceSparrow;
                m.distribution = Distribution::Ggx;
                m.roughness = 0.3;
                m.specular = Vec3::splat(0.4);
            }
        }
        let (w, h) = (16u32, 8u32);
        let env = chiaro_core::scene::ImageTexture {
            source: "patch".into(),
            width: w,
            height: h,
            texels: (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let v = if (7..=9).contains(&x) && (2..=3).contains(&y) {
                        20.0
                    } else {
                        0.2
                    };
                    [v, v * 0.8, v * 0.6, 1.0]
                })
                .collect(),
            ..Default::default()
        };
        chiaro_testkit::scenes::set_environment(&mut s, env, 1.0, 0.0, true);
        assert_tracers_agree(&s, "environment");
    }

    #[test]
    fn reference_agrees_with_the_fast_tracer_on_the_cornell_box() {
        assert_tracers_agree(&shipped("mitsuba-cbox", 32, 8), "Mitsuba's box");
    }

    #[test]
    fn reference_agrees_with_the_fast_tracer_on_glossy_mirror_and_glass() {
        // The Whitted scene (checker, mirror, Fresnel glass, point lights).
        assert_tracers_agree(&shipped("whitted", 32, 8), "whitted.toml");
        // Mitsuba's box with glossy walls under its area light (MIS).
        let mut s = shipped("mitsuba-cbox", 32, 8);
        for (k, m) in s.materials.iter_mut().enumerate() {
            match k % 3 {
                0 => {
                    m.model = ReflectanceModel::TorranceSparrow;
                    m.distribution = Distribution::Ggx;
                    m.roughness = 0.25;
                    m.specular = Vec3::splat(0.5);
                }
                1 => {
                    m.model = ReflectanceModel::Blinn;
                    m.shininess = 30.0;
                    m.specular = Vec3::splat(0.3);
                }
                _ => {}
            }
        }
        assert_tracers_agree(&s, "glossy box");
    }
}
