//! The path-traced reference: an unbiased estimator of the rendering
//! equation that every other technique is measured against.
//!
//! - Next-event estimation at every vertex (one light chosen by power),
//!   combined with BSDF sampling by multiple importance sampling (power
//!   heuristic, Veach 1997) for area lights and emissive triangles; delta
//!   lights (point, spot, directional) by next-event estimation only.
//! - The BSDF is the local model's (`chiaro_core::shading::eval_brdf_cos`:
//!   Lambert plus Phong, Blinn or Torrance-Sparrow), sampled lobe by lobe,
//!   plus ideal mirror reflection (kr) and transmission (kt): a dielectric
//!   with Fresnel's equations and total internal reflection when the
//!   material has `fresnel = true`, fixed kr/kt weights otherwise.
//! - Russian roulette from `settings.path.rr_depth`; at most
//!   `settings.path.max_depth` scattering vertices (1 = direct light only).
//!
//! Conventions: ambient lights are ignored (indirect light is computed);
//! `Scene::background` is what camera rays (and chains of mirror/glass
//! bounces) see where nothing is hit, but it does not light the scene;
//! an environment map, when present, does light it (found by BSDF sampling).
//! `Light::Area` lights are not geometry: they are reached by next-event
//! estimation only and are invisible to the camera; emissive triangles are
//! geometry and lights both.

use chiaro_core::accel::Accelerator;
use chiaro_core::error::{CoreError, Result};
use chiaro_core::film::{Film, TilePixels, render_tiles_in};
use chiaro_core::geometry::{Frame, Ray, offset_ray_origin};
use chiaro_core::prepared::{PrepareOptions, PreparedScene, SurfaceHit};
use chiaro_core::progress::Progress;
use chiaro_core::sampling::{
    Rng, cosine_hemisphere_pdf, phong_lobe_pdf, pixel_rng, power_heuristic,
    sample_cosine_hemisphere, sample_phong_lobe, uniform, uniform2,
};
use chiaro_core::scene::{AreaShape, Distribution, Light, ReflectanceModel, RenderSettings, Scene};
use chiaro_core::shading::brdf::eval_brdf_cos;
use chiaro_core::shading::microfacet;
use chiaro_core::shading::{
    SurfaceMaterial, fresnel_dielectric, reflect, refract, sample_light, sanitize,
};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

/// Tile side in pixels.
const TILE: u32 = 16;

/// Counts from a path-traced render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PathStats {
    /// Rays traced (camera, bounce and shadow rays).
    pub rays: u64,
}

/// Renders `scene` with the path tracer. `make_accel` builds the ray
/// accelerator over the prepared scene (the BVH normally, the brute-force
/// list in tests). Returns the film (mean radiance of `settings.samples`
/// paths per pixel) and the ray count.
pub fn render_with(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    make_accel: &dyn Fn(&PreparedScene<'_>) -> Box<dyn Accelerator>,
) -> Result<(Film, PathStats)> {
    if settings.path.max_depth == 0 {
        return Err(CoreError::BadSetting {
            key: "path.max_depth".into(),
            message: "must be at least 1".into(),
        });
    }
    progress.begin("prepare", 1);
    let prepared = PreparedScene::new(
        scene,
        PrepareOptions {
            analytic_spheres: true,
            ..PrepareOptions::default()
        },
    );
    let accel = make_accel(&prepared);
    let tracer = PathTracer::new(&prepared, accel.as_ref(), settings);
    progress.advance(1);
    let rays = AtomicU64::new(0);
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.max(1);
    let cam = &scene.camera;
    let film = render_tiles_in(w, h, settings.crop_rect(), TILE, "path", progress, |rect| {
        let mut tile = TilePixels::new(rect);
        let mut count = 0u64;
        for ty in 0..rect.height {
            for tx in 0..rect.width {
                let (px, py) = (rect.x + tx, rect.y + ty);
                let mut sum = Vec3::ZERO;
                for s in 0..spp {
                    let mut rng = pixel_rng(settings.seed, px, py, s);
                    let j = uniform2(&mut rng);
                    let dir = cam.ray_direction(px as f32 + j.x, py as f32 + j.y, w, h);
                    let (l, first) = tracer.radiance(Ray::new(cam.eye, dir), &mut rng, &mut count);
                    sum += sanitize(l);
                    if s == 0
                        && let Some((t, n)) = first
                    {
                        let i = (ty * rect.width + tx) as usize;
                        tile.depth[i] = t;
                        tile.normal[i] = n;
                    }
                }
                tile.color[(ty * rect.width + tx) as usize] = sum / spp as f32;
            }
        }
        rays.fetch_add(count, Ordering::Relaxed);
        tile
    })?;
    Ok((
        film,
        PathStats {
            rays: rays.into_inner(),
        },
    ))
}

/// The path tracer over one prepared scene.
struct PathTracer<'a, 's> {
    prepared: &'a PreparedScene<'s>,
    accel: &'a dyn Accelerator,
    /// Lights that next-event estimation samples (not ambient).
    lights: Vec<&'a Light>,
    /// Cumulative selection probabilities of `lights`.
    light_cdf: Vec<f32>,
    /// Light index (in `lights`) of each emissive triangle, by triangle id.
    triangle_light: std::collections::HashMap<u32, usize>,
    max_depth: u32,
    rr_depth: u32,
}

/// One sampled scattering direction.
struct ScatterSample {
    wi: Vec3,
    /// Throughput multiplier `f cos / pdf` (or the delta lobe's weight).
    weight: Vec3,
    /// Solid-angle pdf of the non-delta mixture, for MIS; 0 for delta lobes.
    pdf: f32,
    /// True for mirror and refraction lobes.
    delta: bool,
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

impl<'a, 's> PathTracer<'a, 's> {
    fn new(
        prepared: &'a PreparedScene<'s>,
        accel: &'a dyn Accelerator,
        settings: &RenderSettings,
    ) -> Self {
        let lights: Vec<&Light> = prepared
            .lights
            .iter()
            .filter(|l| !matches!(l, Light::Ambient { .. }))
            .collect();
        // Select lights in proportion to a rough power estimate.
        let scene_radius = 0.5 * prepared.bounds.diagonal().max(1e-3);
        let power: Vec<f32> = lights
            .iter()
            .map(|l| {
                let p = luminance(l.power_rgb()).max(0.0);
                match l {
                    Light::Area {
                        shape, two_sided, ..
                    } => p * shape.area() * PI * if *two_sided { 2.0 } else { 1.0 },
                    Light::Directional { .. } => p * PI * scene_radius * scene_radius,
                    _ => p * 4.0 * PI,
                }
            })
            .collect();
        let total: f32 = power.iter().sum();
        let mut acc = 0.0;
        let light_cdf = power
            .iter()
            .map(|&p| {
                acc += if total > 0.0 {
                    p / total
                } else {
                    1.0 / lights.len() as f32
                };
                acc
            })
            .collect();
        // Emissive triangle lights follow the scene's lights in `prepared.lights`,
        // in the order of `prepared.emissive_triangles` (skipping degenerate ones).
        let mut triangle_light = std::collections::HashMap::new();
        let first_tri_light = lights.iter().position(|l| {
            matches!(
                l,
                Light::Area {
                    shape: AreaShape::Triangle { .. },
                    ..
                }
            )
        });
        if let Some(first) = first_tri_light {
            let mut k = first;
            for &t in &prepared.emissive_triangles {
                let [a, b, c] =
                    prepared.triangles[t as usize].map(|i| prepared.positions[i as usize]);
                if chiaro_core::geometry::face_normal(a, b, c).is_some() && k < lights.len() {
                    triangle_light.insert(t, k);
                    k += 1;
                }
            }
        }
        Self {
            prepared,
            accel,
            lights,
            light_cdf,
            triangle_light,
            max_depth: settings.path.max_depth,
            rr_depth: settings.path.rr_depth.max(1),
        }
    }

    fn light_pick_pdf(&self, i: usize) -> f32 {
        let prev = if i == 0 { 0.0 } else { self.light_cdf[i - 1] };
        self.light_cdf[i] - prev
    }

    fn pick_light(&self, u: f32) -> Option<usize> {
        if self.lights.is_empty() {
            return None;
        }
        let i = self.light_cdf.partition_point(|&c| c <= u);
        Some(i.min(self.lights.len() - 1))
    }

    /// Radiance along `ray`, and the first hit's distance and normal.
    fn radiance(&self, mut ray: Ray, rng: &mut Rng, rays: &mut u64) -> (Vec3, Option<(f32, Vec3)>) {
        let mut l = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        let mut first = None;
        // MIS state of the previous bounce: its pdf (0 = delta or camera).
        let mut prev_pdf = 0.0f32;
        let mut prev_p = ray.origin;
        for depth in 0..self.max_depth {
            *rays += 1;
            let Some(hit) = self.accel.intersect(&ray) else {
                l += beta * self.escaped(&ray, depth == 0 || prev_pdf == 0.0);
                break;
            };
            let surf = self.prepared.surface(&ray, &hit);
            let wo = -ray.dir.normalize();
            if depth == 0 {
                first = Some((hit.t * ray.dir.length(), surf.ns));
            }
            let m = self.prepared.surface_material(&surf);
            let mat = self.prepared.material(surf.material);
            // Emission seen along the path (one-sided unless two-sided).
            if m.emission.max_element() > 0.0 && (mat.two_sided || surf.ng.dot(wo) > 0.0) {
                let w = if prev_pdf == 0.0 {
                    1.0
                } else {
                    self.emitter_mis_weight(hit.prim, prev_p, &surf, wo, prev_pdf)
                };
                l += beta * m.emission * w;
            }
            // Shading frame on the side of the viewer.
            let front = surf.ng.dot(wo) >= 0.0;
            let (n, ng) = if front {
                (surf.ns, surf.ng)
            } else {
                (-surf.ns, -surf.ng)
            };
            let last = depth + 1 >= self.max_depth;
            // Next-event estimation.
            l += beta * self.direct(&surf, &m, n, ng, wo, !last, rng, rays);
            if last {
                break;
            }
            // Continue the path.
            let Some(s) = self.sample_scatter(&m, mat.fresnel, n, ng, wo, front, rng) else {
                break;
            };
            beta *= s.weight;
            if !beta.is_finite() || beta.max_element() <= 0.0 {
                break;
            }
            prev_pdf = if s.delta { 0.0 } else { s.pdf };
            prev_p = surf.p;
            ray = Ray::new(offset_ray_origin(surf.p, surf.ng, s.wi), s.wi);
            // Russian roulette.
            if depth + 1 >= self.rr_depth {
                let q = beta.max_element().min(0.95);
                if uniform(rng) >= q {
                    break;
                }
                beta /= q;
            }
        }
        (l, first)
    }

    /// Radiance of an escaped ray: the environment map lights the scene; the
    /// plain background is seen only directly (camera or delta chains).
    fn escaped(&self, ray: &Ray, direct_view: bool) -> Vec3 {
        let scene = self.prepared.scene;
        if let Some(env) = &scene.environment {
            return environment_radiance(scene, env, ray.dir.normalize());
        }
        if direct_view {
            scene.background
        } else {
            Vec3::ZERO
        }
    }

    /// MIS weight of emission found by BSDF sampling from `from` with pdf `bsdf_pdf`.
    fn emitter_mis_weight(
        &self,
        prim: u32,
        from: Vec3,
        surf: &SurfaceHit,
        wo: Vec3,
        bsdf_pdf: f32,
    ) -> f32 {
        let Some(&li) = self.triangle_light.get(&prim) else {
            return 1.0;
        };
        let Light::Area { shape, .. } = self.lights[li] else {
            return 1.0;
        };
        let d2 = (surf.p - from).length_squared();
        let cos_l = surf.ng.dot(wo).abs();
        if cos_l <= 0.0 {
            return 1.0;
        }
        let light_pdf = self.light_pick_pdf(li) * d2 / (cos_l * shape.area());
        power_heuristic(bsdf_pdf, light_pdf)
    }

    /// Solid-angle pdf of sampling direction `wi` towards sample point `q`
    /// (normal `nl`) on area light `light` from `p`; `None` for delta lights.
    fn light_solid_angle_pdf(light: &Light, p: Vec3, q: Vec3) -> Option<f32> {
        let Light::Area { shape, .. } = light else {
            return None;
        };
        match *shape {
            AreaShape::Sphere { center, radius } => {
                let dc2 = (center - p).length_squared();
                let cos_max = (1.0 - radius * radius / dc2).max(0.0).sqrt();
                Some(1.0 / (2.0 * PI * (1.0 - cos_max)).max(1e-12))
            }
            _ => {
                let nl = match *shape {
                    AreaShape::Quad { edge_u, edge_v, .. } => {
                        edge_u.cross(edge_v).normalize_or_zero()
                    }
                    AreaShape::Disk { normal, .. } => normal.normalize_or_zero(),
                    AreaShape::Triangle { a, b, c } => (b - a).cross(c - a).normalize_or_zero(),
                    AreaShape::Sphere { .. } => Vec3::ZERO,
                };
                let d = q - p;
                let d2 = d.length_squared();
                let cos_l = nl.dot(d / d2.sqrt()).abs();
                (cos_l > 0.0).then(|| d2 / (cos_l * shape.area()))
            }
        }
    }

    /// Next-event estimation: one light chosen by power, one sample on it,
    /// its visibility by a shadow ray; MIS-weighted against BSDF sampling
    /// when the path continues (`mis`).
    #[allow(clippy::too_many_arguments)]
    fn direct(
        &self,
        surf: &SurfaceHit,
        m: &SurfaceMaterial,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        let u_pick = uniform(rng);
        let u = uniform2(rng);
        let Some(li) = self.pick_light(u_pick) else {
            return Vec3::ZERO;
        };
        let light = self.lights[li];
        let pick = self.light_pick_pdf(li);
        if pick <= 0.0 {
            return Vec3::ZERO;
        }
        let Some(s) = sample_light(light, surf.p, u) else {
            return Vec3::ZERO;
        };
        let f_cos = eval_brdf_cos(m, n, wo, s.wi);
        if f_cos == Vec3::ZERO || ng.dot(s.wi) <= 0.0 {
            return Vec3::ZERO;
        }
        *rays += 1;
        let origin = offset_ray_origin(surf.p, ng, s.wi);
        let shadow = if s.distance.is_finite() {
            Ray::segment(origin, s.point)
        } else {
            Ray::new(origin, s.wi)
        };
        if self.accel.occluded(&shadow) {
            return Vec3::ZERO;
        }
        let mut w = 1.0;
        if mis
            && !s.is_delta
            && let Some(light_pdf) = Self::light_solid_angle_pdf(light, surf.p, s.point)
        {
            let bsdf_pdf = self.scatter_pdf(m, n, wo, s.wi);
            w = power_heuristic(light_pdf * pick, bsdf_pdf);
        }
        PI * f_cos * s.intensity * (w / pick)
    }

    /// Lobe selection weights: diffuse, glossy, mirror, transmission.
    fn lobe_weights(m: &SurfaceMaterial, fresnel: bool) -> [f32; 4] {
        let t = luminance(m.kt);
        let r = if fresnel && t > 0.0 {
            0.0
        } else {
            luminance(m.kr)
        };
        [luminance(m.kd), luminance(m.ks), r, t]
    }

    /// Solid-angle pdf with which [`Self::sample_scatter`] picks `wi` through
    /// its non-delta lobes (for MIS).
    fn scatter_pdf(&self, m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        let [wd, ws, wr, wt] = Self::lobe_weights(m, false);
        let total = wd + ws + wr + wt;
        if total <= 0.0 {
            return 0.0;
        }
        let cos_i = n.dot(wi);
        if cos_i <= 0.0 {
            return 0.0;
        }
        let mut pdf = wd / total * cosine_hemisphere_pdf(cos_i);
        if ws > 0.0 {
            pdf += ws / total * glossy_pdf(m, n, wo, wi);
        }
        pdf
    }

    /// Samples the next direction.
    #[allow(clippy::too_many_arguments)]
    fn sample_scatter(
        &self,
        m: &SurfaceMaterial,
        fresnel: bool,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        front: bool,
        rng: &mut Rng,
    ) -> Option<ScatterSample> {
        let weights = Self::lobe_weights(m, fresnel);
        let total: f32 = weights.iter().sum();
        if total <= 0.0 {
            return None;
        }
        let pick = uniform(rng) * total;
        let u = uniform2(rng);
        let (wd, ws, wr, wt) = (weights[0], weights[1], weights[2], weights[3]);
        if pick < wd + ws {
            // A non-delta lobe: sample one, weight by the mixture pdf.
            let frame = Frame::from_normal(n);
            let wi = if pick < wd {
                frame.to_world(sample_cosine_hemisphere(u))
            } else {
                sample_glossy(m, n, wo, u)?
            };
            if n.dot(wi) <= 0.0 || ng.dot(wi) <= 0.0 {
                return None;
            }
            let pdf = self.scatter_pdf(m, n, wo, wi);
            if pdf <= 0.0 {
                return None;
            }
            let f_cos = eval_brdf_cos(m, n, wo, wi);
            return Some(ScatterSample {
                wi,
                weight: f_cos / pdf,
                pdf,
                delta: false,
            });
        }
        let p_r = wr / total;
        let p_t = wt / total;
        if pick < wd + ws + wr {
            // Fixed-weight mirror.
            let wi = reflect(wo, n);
            return Some(ScatterSample {
                wi,
                weight: m.kr / p_r,
                pdf: 0.0,
                delta: true,
            });
        }
        // Transmission: entering when on the front side.
        let (n1, n2) = if front { (1.0, m.ior) } else { (m.ior, 1.0) };
        let cos_o = n.dot(wo).clamp(0.0, 1.0);
        let refracted = refract(wo, n, n1 / n2);
        if fresnel {
            // A dielectric: reflect with probability F (1 under total
            // internal reflection), else refract tinted by kt.
            let f = fresnel_dielectric(cos_o, n1, n2);
            return match refracted {
                Some(wi) if uniform(rng) >= f => Some(ScatterSample {
                    wi,
                    weight: m.kt / p_t,
                    pdf: 0.0,
                    delta: true,
                }),
                _ => Some(ScatterSample {
                    wi: reflect(wo, n),
                    weight: Vec3::ONE / p_t,
                    pdf: 0.0,
                    delta: true,
                }),
            };
        }
        match refracted {
            Some(wi) => Some(ScatterSample {
                wi,
                weight: m.kt / p_t,
                pdf: 0.0,
                delta: true,
            }),
            // Total internal reflection: the reflection takes everything.
            None => Some(ScatterSample {
                wi: reflect(wo, n),
                weight: m.kt / p_t,
                pdf: 0.0,
                delta: true,
            }),
        }
    }
}

/// Samples the glossy lobe of `m` around its peak.
fn sample_glossy(m: &SurfaceMaterial, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
    match m.model {
        ReflectanceModel::Phong => {
            let r = reflect(wo, n);
            Some(Frame::from_normal(r).to_world(sample_phong_lobe(u, m.shininess)))
        }
        ReflectanceModel::Blinn => {
            let h = Frame::from_normal(n).to_world(sample_phong_lobe(u, m.shininess));
            let wi = reflect(wo, h);
            Some(wi)
        }
        ReflectanceModel::TorranceSparrow => {
            let alpha = m.roughness.max(1e-3);
            let h =
                Frame::from_normal(n).to_world(sample_microfacet_normal(m.distribution, alpha, u));
            Some(reflect(wo, h))
        }
    }
}

/// Solid-angle pdf of [`sample_glossy`].
fn glossy_pdf(m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
    match m.model {
        ReflectanceModel::Phong => phong_lobe_pdf(reflect(wo, n).dot(wi), m.shininess),
        ReflectanceModel::Blinn | ReflectanceModel::TorranceSparrow => {
            let Some(h) = (wo + wi).try_normalize() else {
                return 0.0;
            };
            let cos_h = n.dot(h);
            let o_h = wo.dot(h);
            if cos_h <= 0.0 || o_h <= 0.0 {
                return 0.0;
            }
            let pdf_h = if m.model == ReflectanceModel::Blinn {
                phong_lobe_pdf(cos_h, m.shininess)
            } else {
                microfacet::d(m.distribution, cos_h, m.roughness.max(1e-3)) * cos_h
            };
            pdf_h / (4.0 * o_h)
        }
    }
}

/// Samples a microfacet normal about +z with density `D(h) cos_theta_h`
/// (Walter et al. 2007, eqs. 28, 35).
fn sample_microfacet_normal(dist: Distribution, alpha: f32, u: Vec2) -> Vec3 {
    let tan2 = match dist {
        Distribution::Ggx => alpha * alpha * u.x / (1.0 - u.x).max(1e-7),
        Distribution::Beckmann => -alpha * alpha * (1.0 - u.x).max(1e-7).ln(),
    };
    let cos_t = 1.0 / (1.0 + tan2).sqrt();
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Radiance of the lat-long environment map in direction `d` (unit): `+y` is
/// up and `u = 0.5` looks down `-z` (see [`chiaro_core::scene::Environment`]).
fn environment_radiance(scene: &Scene, env: &chiaro_core::scene::Environment, d: Vec3) -> Vec3 {
    let Some(chiaro_core::scene::Texture::Image(img)) = scene.textures.get(env.texture.index())
    else {
        return Vec3::ZERO;
    };
    let phi = d.x.atan2(-d.z) - env.rotate_y_degrees.to_radians();
    let u = (0.5 + phi / (2.0 * PI)).rem_euclid(1.0);
    let v = d.y.clamp(-1.0, 1.0).acos() / PI;
    chiaro_core::shading::texture::bilinear(img, Vec2::new(u, v)).truncate() * env.intensity
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::accel::bvh::SceneBvh;
    use chiaro_core::geometry::primitives;
    use chiaro_core::progress::NoProgress;
    use chiaro_core::scene::{Attenuation, Camera, Geometry, Material, Object, Technique};

    fn bvh(p: &PreparedScene<'_>) -> Box<dyn Accelerator> {
        Box::new(SceneBvh::new(p))
    }

    fn furnace(geometry: Option<u32>) -> Scene {
        let mut s = Scene::default();
        s.add_material(Material {
            emission: Vec3::splat(1.0),
            two_sided: true,
            ..Material::diffuse("furnace", Vec3::splat(0.5))
        });
        let geometry = match geometry {
            None => Geometry::Sphere { radius: 10.0 },
            Some(slices) => {
                Geometry::Mesh(s.add_mesh(primitives::uv_sphere(10.0, slices, slices / 2)))
            }
        };
        s.objects.push(Object {
            geometry,
            ..Default::default()
        });
        s.camera = Camera {
            eye: Vec3::new(0.0, 1.0, 0.0),
            look_at: Vec3::new(0.0, 0.0, 5.0),
            ..Camera::default()
        };
        s.render.technique = Technique::Path;
        s.render.width = 16;
        s.render.height = 16;
        s.render.samples = 4;
        s.render.path.max_depth = 64;
        s.render.path.rr_depth = 64;
        s
    }

    #[test]
    fn analytic_furnace_is_exact() {
        // Inside a closed sphere of albedo rho and emission E, L = E / (1 - rho);
        // with cosine sampling every path carries exactly sum rho^k E.
        let s = furnace(None);
        let (film, stats) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        let expect = (1.0 - 0.5f32.powi(64)) / (1.0 - 0.5);
        for c in &film.color {
            assert!((c.x - expect).abs() < 1e-3, "{c} vs {expect}");
        }
        assert!(stats.rays > 0);
    }

    #[test]
    fn triangle_furnace_with_mis_is_unbiased() {
        // Same furnace tessellated: every triangle is now a light, so
        // next-event estimation and MIS are exercised; the mean must stay E / (1 - rho)
        // (a wrong MIS weight or pdf biases it).
        let mut s = furnace(Some(24));
        s.render.path.max_depth = 40;
        s.render.path.rr_depth = 3;
        s.render.samples = 16;
        let (film, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        let n = film.color.len() as f32;
        let mean = film.mean().x;
        let var = film.color.iter().map(|c| (c.x - mean).powi(2)).sum::<f32>() / (n - 1.0);
        let stderr = (var / n).sqrt();
        assert!(
            (mean - 2.0).abs() < 4.0 * stderr + 0.01,
            "mean {mean} stderr {stderr}"
        );
    }

    #[test]
    fn depth_one_point_light_is_the_lambert_term() {
        // A plane under a point light: L = kd Ip cos / d^2 exactly at depth 1.
        let mut s = Scene::default();
        s.add_material(Material::diffuse("grey", Vec3::splat(0.5)));
        let plane = s.add_mesh(primitives::plane(2.0, 1));
        s.objects.push(Object {
            geometry: Geometry::Mesh(plane),
            smooth: false,
            ..Default::default()
        });
        s.lights.push(Light::Point {
            position: Vec3::new(0.0, 2.0, 0.0),
            color: Vec3::ONE,
            intensity: 8.0,
            attenuation: Attenuation::InverseSquare,
        });
        s.lights.push(Light::Ambient {
            color: Vec3::ONE,
            intensity: 1.0,
        });
        s.camera = Camera {
            eye: Vec3::new(0.0, 3.0, -0.001),
            look_at: Vec3::ZERO,
            fov_y_degrees: 1.0,
            ..Camera::default()
        };
        s.render.width = 4;
        s.render.height = 4;
        s.render.samples = 4;
        s.render.path.max_depth = 1;
        let (film, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        // Straight below the light: cos = 1, d = 2, ambient ignored.
        let expect = 0.5 * 8.0 / 4.0;
        for c in &film.color {
            assert!((c.x - expect).abs() < 0.01 * expect, "{c} vs {expect}");
        }
    }

    #[test]
    fn glass_sphere_of_ior_one_is_invisible() {
        // A non-absorbing dielectric with ior 1 refracts straight through:
        // the image equals the image without it (up to ray offsets).
        let mut s = Scene::default();
        s.add_material(Material::diffuse("grey", Vec3::splat(0.5)));
        let glass = s.add_material(Material {
            diffuse: Vec3::ZERO,
            transmit: Vec3::ONE,
            ior: 1.0,
            fresnel: true,
            ..Material::default()
        });
        let plane = s.add_mesh(primitives::plane(5.0, 1));
        s.objects.push(Object {
            geometry: Geometry::Mesh(plane),
            smooth: false,
            ..Default::default()
        });
        s.lights.push(Light::Point {
            position: Vec3::new(0.0, 4.0, 0.0),
            color: Vec3::ONE,
            intensity: 10.0,
            attenuation: Attenuation::InverseSquare,
        });
        s.camera = Camera {
            eye: Vec3::new(0.0, 3.0, -3.0),
            look_at: Vec3::ZERO,
            ..Camera::default()
        };
        s.render.width = 12;
        s.render.height = 12;
        s.render.samples = 2;
        s.render.path.max_depth = 4;
        let (without, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 0.7 },
            material: glass,
            transform: chiaro_core::scene::Transform {
                translate: Vec3::new(0.0, 0.8, -0.5),
                ..Default::default()
            },
            ..Default::default()
        });
        // Shadow rays are blocked by glass (no caustics through NEE), so look only at
        // pixels whose camera ray passes through the sphere and lands outside its shadow:
        // compare the means instead of pixels, restricted to the lit far region.
        let (with, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        let mut diffs = 0;
        for (a, b) in without.color.iter().zip(&with.color) {
            if (a.x - b.x).abs() > 1e-3 {
                diffs += 1;
            }
        }
        // Only the shadow of the sphere differs (glass blocks next-event shadow rays).
        assert!(diffs < without.color.len() / 4, "{diffs} pixels differ");
    }
}
