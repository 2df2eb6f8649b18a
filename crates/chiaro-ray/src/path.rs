//! The path-traced reference: an unbiased estimator of the rendering
//! equation that every other technique is measured against.
//!
//! - Next-event estimation at every vertex (one light chosen by power),
//!   combined with BSDF sampling by multiple importance sampling (power
//!   heuristic, Veach 1997) for area lights, emissive triangles and the
//!   environment map (one more light, sampled by its luminance through
//!   `texture::EnvironmentLight`); delta lights (point, spot, directional)
//!   by next-event estimation only.
//! - The BSDF is the shading layer's (`chiaro_core::shading::Bsdf`: the
//!   local model's Lambert plus Phong, Blinn or Torrance-Sparrow, sampled
//!   lobe by lobe, plus ideal mirror reflection (kr) and transmission (kt):
//!   a dielectric with Fresnel's equations and total internal reflection
//!   when the material has `fresnel = true`, fixed kr/kt weights otherwise).
//! - Russian roulette from `settings.path.rr_depth`; at most
//!   `settings.path.max_depth` scattering vertices (1 = direct light only).
//! - Random numbers from `chiaro_core::sampling::SobolSampler`: a pixel's
//!   samples take each decision (camera jitter, light choice and point,
//!   lobe choice and direction, Russian roulette) from its own shuffled,
//!   Owen-scrambled Sobol dimension pair, so they stratify every decision
//!   jointly; each draw is still uniform, so the estimator stays unbiased.
//!
//! - Paths are traced sixteen samples of a pixel at a time by the lock-step
//!   kernel in `path/lanes.rs` (vectorised where the vertices are
//!   Lambertian, bit-identical to the scalar loop kept here as
//!   [`Kernel::Scalar`]).
//!
//! Conventions: ambient lights are ignored (indirect light is computed);
//! `Scene::background` is what camera rays (and chains of mirror/glass
//! bounces) see where nothing is hit, but it does not light the scene;
//! an environment map, when present, does light it (found by next-event
//! estimation and by BSDF sampling, combined by MIS).
//! `Light::Area` lights are not geometry: they are reached by next-event
//! estimation only and are invisible to the camera; emissive triangles are
//! geometry and lights both.

use chiaro_core::accel::{Accelerator, Hit};
use chiaro_core::error::{CoreError, Result};
use chiaro_core::film::{Film, TilePixels, render_tiles_in};
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::Progress;
use chiaro_core::sampling::{
    SobolSampler, pixel_rng, power_heuristic, sample_uniform_triangle, uniform2,
};
use chiaro_core::scene::{AreaShape, Light, RenderSettings, Scene};
use chiaro_core::shading::texture::EnvironmentLight;
use chiaro_core::shading::{Bsdf, BsdfSample, SurfaceMaterial, sample_light, sanitize};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

mod lanes;
mod reference;

use chiaro_core::sampling::sobol::LANES;

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
    render_with_kernel(scene, settings, progress, make_accel, Kernel::Lanes)
}

/// Which loop traces the paths. `Lanes` and `Scalar` compute the same
/// image, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// The lock-step kernel (`path/lanes.rs`): a pixel's samples sixteen
    /// at a time, vectorised where their vertices are Lambertian.
    Lanes,
    /// One path at a time.
    Scalar,
    /// The plain reference tracer (`path/reference.rs`): one path at a
    /// time on the BSDF layer with independent PCG numbers. Agrees with
    /// the others statistically, not bit for bit.
    Reference,
}

/// [`render_with`] with the path loop chosen: for tests and benchmarks
/// that compare the two.
pub fn render_with_kernel(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    make_accel: &dyn Fn(&PreparedScene<'_>) -> Box<dyn Accelerator>,
    kernel: Kernel,
) -> Result<(Film, PathStats)> {
    render_impl(scene, settings, progress, make_accel, kernel, true)
}

/// [`render_with_kernel`], with the environment map sampled by next-event
/// estimation (`env_sampling`) or reached by BSDF sampling alone (the
/// tests' baseline for its variance).
fn render_impl(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    make_accel: &dyn Fn(&PreparedScene<'_>) -> Box<dyn Accelerator>,
    kernel: Kernel,
    env_sampling: bool,
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
    let tracer = PathTracer::new(&prepared, accel.as_ref(), settings, env_sampling);
    let lanes = kernel == Kernel::Lanes;
    progress.advance(1);
    let rays = AtomicU64::new(0);
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.max(1);
    let cam = &scene.camera;
    // `Camera::ray_direction` with the frame and field of view computed once.
    let frame = cam.frame();
    let tan_half = (cam.fov_y_degrees.to_radians() * 0.5).tan();
    let aspect = w as f32 / h as f32;
    // (Multiplications by 2 / w and 2 / h, exact for power-of-two sizes and
    // within an ulp otherwise.)
    let (two_over_w, two_over_h) = (2.0 / w as f32, 2.0 / h as f32);
    let camera_dir = |x: f32, y: f32| {
        let ndc_x = (x * two_over_w - 1.0) * tan_half * aspect;
        let ndc_y = (1.0 - y * two_over_h) * tan_half;
        (frame.forward + ndc_x * frame.right + ndc_y * frame.up).normalize()
    };
    let film = render_tiles_in(w, h, settings.crop_rect(), TILE, "path", progress, |rect| {
        let mut tile = TilePixels::new(rect);
        let mut count = 0u64;
        let mut rng = SobolSampler::new(settings.seed, rect.x, rect.y, 0, spp);
        for ty in 0..rect.height {
            for tx in 0..rect.width {
                let (px, py) = (rect.x + tx, rect.y + ty);
                let mut sum = Vec3::ZERO;
                rng.set_pixel(px, py);
                let mut first_hit = None;
                if kernel == Kernel::Reference {
                    for s in 0..spp {
                        let mut rng = pixel_rng(settings.seed, px, py, s);
                        let j = uniform2(&mut rng);
                        let dir = camera_dir(px as f32 + j.x, py as f32 + j.y);
                        let ray = Ray::new(cam.eye, dir);
                        let (l, fh) = tracer.reference_radiance(ray, &mut rng, &mut count);
                        sum += sanitize(l);
                        if s == 0 {
                            first_hit = fh;
                        }
                    }
                } else if lanes {
                    let camera =
                        |j: Vec2| Ray::new(cam.eye, camera_dir(px as f32 + j.x, py as f32 + j.y));
                    for first in (0..spp).step_by(LANES) {
                        let n = ((spp - first) as usize).min(LANES);
                        let (ls, fh) =
                            tracer.radiance_lanes(first, n, &camera, &mut rng, &mut count);
                        for l in &ls[..n] {
                            sum += sanitize(*l);
                        }
                        if first == 0 {
                            first_hit = fh;
                        }
                    }
                } else {
                    for s in 0..spp {
                        rng.set_sample(s);
                        let j = rng.next_2d();
                        let dir = camera_dir(px as f32 + j.x, py as f32 + j.y);
                        let (l, fh) = tracer.radiance(Ray::new(cam.eye, dir), &mut rng, &mut count);
                        sum += sanitize(l);
                        if s == 0 {
                            first_hit = fh;
                        }
                    }
                }
                if let Some((t, n)) = first_hit {
                    let i = (ty * rect.width + tx) as usize;
                    tile.depth[i] = t;
                    tile.normal[i] = n;
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
    /// The environment map as a light: light number `lights.len()`, after
    /// `lights` (`None` without a map, or when it is black).
    env: Option<EnvironmentLight<'s>>,
    /// Cumulative selection probabilities of `lights` and then `env`.
    light_cdf: Vec<f32>,
    /// Selection probability of each light (`light_cdf[i] - light_cdf[i - 1]`).
    light_pick: Vec<f32>,
    /// Sampling data of each light in `lights` that is an emissive triangle
    /// (`None` for the others, sampled through `sample_light`, and for the
    /// environment).
    tri_lights: Vec<Option<TriLight>>,
    /// `tri_lights` without the `Option`s when every light is an emissive
    /// triangle and there are at most `lanes::SELECT_LIGHTS` of them (the
    /// lock-step kernel then gathers each lane's light by selects over
    /// this list); empty otherwise.
    select_lights: Vec<TriLight>,
    /// Light index (in `lights`) of each triangle, `NO_LIGHT` when it does not emit.
    triangle_light: Vec<u32>,
    /// Per-triangle geometry cached for the common untextured case.
    tris: Vec<TriInfo>,
    /// Per-material constants, by material id.
    materials: Vec<MaterialInfo>,
    max_depth: u32,
    rr_depth: u32,
}

/// Largest difference in any coordinate between the unit vertex normals of
/// a triangle whose shading normal is taken as constant (16 float ulps at
/// 1: far below any intended smoothing, far above rounding).
const FLAT_NORMAL_TOLERANCE: f32 = 1e-6;

/// `PathTracer::triangle_light` entry of a triangle that is not a light.
const NO_LIGHT: u32 = u32::MAX;

/// An emissive triangle as next-event estimation samples it.
#[derive(Clone, Copy)]
struct TriLight {
    a: Vec3,
    b: Vec3,
    c: Vec3,
    /// Unit normal (counter-clockwise front).
    n: Vec3,
    area: f32,
    le: Vec3,
    two_sided: bool,
}

/// What shading needs of a triangle whose material has no texture and whose
/// vertices have no colours (`plain`): the surface is then its position,
/// normals and the material's constants.
#[derive(Clone, Copy)]
struct TriInfo {
    ng: Vec3,
    /// The shading normal when the three vertex normals are equal (within
    /// `FLAT_NORMAL_TOLERANCE`).
    flat_ns: Option<Vec3>,
    plain: bool,
}

/// A material's parameters and the constants derived from them: per
/// material for the untextured case, per hit point otherwise.
struct MaterialInfo {
    /// The parameters and their lobe choice.
    bsdf: Bsdf,
    two_sided: bool,
    /// True when the emission is positive in some channel.
    emissive: bool,
    /// True when textures, a bump map or a normal map change the
    /// parameters or the shading normal per point.
    textured: bool,
    /// True when the only lobe is Lambert's (no glossy, mirror or
    /// transmission lobe), chosen with probability 1 and weighted by `kd`:
    /// the vertices that [`lanes`] shades.
    lambert: bool,
}

impl MaterialInfo {
    fn new(surface: SurfaceMaterial, m: &chiaro_core::scene::Material) -> Self {
        let bsdf = Bsdf::new(surface, m.fresnel);
        let lobes = &bsdf.lobes;
        let [wd, ws, wr, wt] = lobes.weights;
        // (The lone lobe's probability is wd / wd = 1 and its weight kd / 1
        // = kd exactly; the kernel relies on both.)
        let lambert = wd > 0.0 && ws == 0.0 && wr == 0.0 && wt == 0.0 && !lobes.specular;
        Self {
            lambert: lambert && lobes.p_diffuse == 1.0 && lobes.lambert_weight == surface.kd,
            emissive: surface.emission.max_element() > 0.0,
            bsdf,
            two_sided: m.two_sided,
            textured: m.is_textured() || m.bump.is_some() || m.normal_map.is_some(),
        }
    }
}

/// The geometry of a path vertex.
#[derive(Clone, Copy)]
struct Vertex {
    /// Position, world space.
    p: Vec3,
    /// Unit geometric normal (front side).
    ng: Vec3,
    /// Unit shading normal (front side).
    ns: Vec3,
}

/// A path between two bounces: what the scalar loop carries from one
/// vertex to the next.
#[derive(Clone, Copy)]
struct PathState {
    /// The ray to trace next.
    ray: Ray,
    /// Its segment number (0 = the camera ray).
    depth: u32,
    /// Throughput.
    beta: Vec3,
    /// Radiance gathered so far.
    l: Vec3,
    /// MIS state of the previous bounce: its pdf (0 = delta or camera).
    prev_pdf: f32,
    /// The previous vertex (the camera for a camera ray).
    prev_p: Vec3,
}

impl PathState {
    fn camera(ray: Ray) -> Self {
        Self {
            ray,
            depth: 0,
            beta: Vec3::ONE,
            l: Vec3::ZERO,
            prev_pdf: 0.0,
            prev_p: ray.origin,
        }
    }
}

impl<'a, 's> PathTracer<'a, 's> {
    fn new(
        prepared: &'a PreparedScene<'s>,
        accel: &'a dyn Accelerator,
        settings: &RenderSettings,
        env_sampling: bool,
    ) -> Self {
        let lights: Vec<&Light> = prepared
            .lights
            .iter()
            .filter(|l| !matches!(l, Light::Ambient { .. }))
            .collect();
        // Select lights in proportion to a rough power estimate.
        let scene_radius = 0.5 * prepared.bounds.diagonal().max(1e-3);
        let mut power: Vec<f32> = lights
            .iter()
            .map(|l| chiaro_core::shading::light_power(l, scene_radius))
            .collect();
        let env = env_sampling
            .then(|| EnvironmentLight::new(prepared.scene))
            .flatten();
        if let Some(env) = &env {
            // What enters a sphere of the scene's radius (pbrt-v4's
            // `ImageInfiniteLight::Phi`): 4 pi^2 r^2 times the mean radiance.
            power.push(4.0 * PI * PI * scene_radius * scene_radius * env.mean_luminance());
        }
        let n_lights = power.len();
        let total: f32 = power.iter().sum();
        let mut acc = 0.0;
        let light_cdf: Vec<f32> = power
            .iter()
            .map(|&p| {
                acc += if total > 0.0 {
                    p / total
                } else {
                    1.0 / n_lights as f32
                };
                acc
            })
            .collect();
        let light_pick = (0..light_cdf.len())
            .map(|i| {
                let prev = if i == 0 { 0.0 } else { light_cdf[i - 1] };
                light_cdf[i] - prev
            })
            .collect();
        let mut tri_lights: Vec<Option<TriLight>> = lights
            .iter()
            .map(|l| match l {
                Light::Area {
                    shape: AreaShape::Triangle { a, b, c },
                    two_sided,
                    ..
                } => {
                    let cr = (*b - *a).cross(*c - *a);
                    let len = cr.length();
                    (len > 0.0).then(|| TriLight {
                        a: *a,
                        b: *b,
                        c: *c,
                        n: cr / len,
                        area: 0.5 * len,
                        le: l.power_rgb(),
                        two_sided: *two_sided,
                    })
                }
                _ => None,
            })
            .collect();
        if env.is_some() {
            tri_lights.push(None);
        }
        // Emissive triangle lights follow the scene's lights in `prepared.lights`,
        // in the order of `prepared.emissive_triangles` (skipping degenerate ones).
        let mut triangle_light = vec![NO_LIGHT; prepared.triangles.len()];
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
                    if let Some(slot) = triangle_light.get_mut(t as usize) {
                        *slot = k as u32;
                    }
                    k += 1;
                }
            }
        }
        let materials: Vec<MaterialInfo> = prepared
            .scene
            .materials
            .iter()
            .map(|m| MaterialInfo::new(SurfaceMaterial::from_material(m), m))
            .collect();
        let tris = prepared
            .triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let [i0, i1, i2] = tri.map(|i| i as usize);
                let ng = prepared.face_normal(t as u32);
                let n0 = prepared.normals[i0];
                // Vertex normals equal within `FLAT_NORMAL_TOLERANCE` (a faceted
                // quad's two triangles' face normals, averaged onto shared
                // vertices, differ in their last bit): the interpolated normal
                // is then `n0` within the tolerance everywhere on the triangle.
                let close = |n: Vec3| (n - n0).abs().max_element() <= FLAT_NORMAL_TOLERANCE;
                let same_normals = close(prepared.normals[i1]) && close(prepared.normals[i2]);
                // What `triangle_surface` computes for equal vertex normals.
                let flat_ns = same_normals.then(|| {
                    let ns = n0.try_normalize().unwrap_or(ng);
                    if ns.dot(ng) < 0.0 { ng } else { ns }
                });
                let white = [i0, i1, i2]
                    .iter()
                    .all(|&i| prepared.colors[i] == Vec3::ONE);
                let untextured = materials
                    .get(prepared.tri_material[t].index())
                    .is_some_and(|m| !m.textured);
                TriInfo {
                    ng,
                    flat_ns,
                    plain: white && untextured,
                }
            })
            .collect();
        let select_lights = if tri_lights.len() <= lanes::SELECT_LIGHTS {
            // (`None` if any light is not a triangle.)
            let all: Option<Vec<TriLight>> = tri_lights.iter().copied().collect();
            all.unwrap_or_default()
        } else {
            Vec::new()
        };
        Self {
            prepared,
            accel,
            lights,
            env,
            light_cdf,
            light_pick,
            tri_lights,
            select_lights,
            triangle_light,
            tris,
            materials,
            max_depth: settings.path.max_depth,
            rr_depth: settings.path.rr_depth.max(1),
        }
    }

    fn light_pick_pdf(&self, i: usize) -> f32 {
        self.light_pick[i]
    }

    /// The light for the number `u`: an index into `lights`, or
    /// `lights.len()` for the environment.
    fn pick_light(&self, u: f32) -> Option<usize> {
        if self.light_cdf.is_empty() {
            return None;
        }
        let i = self.light_cdf.partition_point(|&c| c <= u);
        Some(i.min(self.light_cdf.len() - 1))
    }

    /// The number of lights next-event estimation chooses from (the
    /// environment included).
    #[inline]
    fn light_count(&self) -> usize {
        self.light_cdf.len()
    }

    /// The vertex at `hit` and its cached material when `hit` is on a plain
    /// triangle (`None`: evaluate it through the surface layer,
    /// `PreparedScene::shading_surface`).
    #[inline(always)]
    fn plain_surface(&self, prim: u32, u: f32, v: f32) -> Option<(Vertex, &MaterialInfo)> {
        let t = prim as usize;
        let info = self.tris.get(t).filter(|info| info.plain)?;
        let [i0, i1, i2] = self.prepared.triangles[t].map(|i| i as usize);
        let pos = &self.prepared.positions;
        let w = 1.0 - u - v;
        // As `PreparedScene::triangle_surface` interpolates it.
        // (A `match`, not `unwrap_or_else`: the closure's captures were
        // stored for every hit, flat or not.)
        let ns = match info.flat_ns {
            Some(ns) => ns,
            None => {
                let nrm = &self.prepared.normals;
                let ns = (nrm[i0] * w + nrm[i1] * u + nrm[i2] * v)
                    .try_normalize()
                    .unwrap_or(info.ng);
                if ns.dot(info.ng) < 0.0 { info.ng } else { ns }
            }
        };
        let v = Vertex {
            p: pos[i0] * w + pos[i1] * u + pos[i2] * v,
            ng: info.ng,
            ns,
        };
        let material = self.materials.get(self.prepared.tri_material[t].index())?;
        Some((v, material))
    }

    /// Radiance along camera ray `ray`, and the first hit's distance and normal.
    fn radiance(
        &self,
        ray: Ray,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        self.radiance_from(PathState::camera(ray), None, rng, rays)
    }

    /// The rest of the path from `state` (whose ray is about to be traced,
    /// or has been: `traced` is then its hit, already counted in `rays`):
    /// its radiance estimate (`state.l` included), and the first hit's
    /// distance and normal when `state.depth` is 0. `rng` must be at the
    /// pair the scalar loop would have reached.
    fn radiance_from(
        &self,
        state: PathState,
        mut traced: Option<Hit>,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        let PathState {
            mut ray,
            depth: start,
            mut beta,
            mut l,
            mut prev_pdf,
            mut prev_p,
        } = state;
        let mut first = None;
        let mut owned;
        for depth in start..self.max_depth {
            let hit = match traced.take() {
                Some(hit) => Some(hit),
                None => {
                    *rays += 1;
                    // Camera rays skip the backs of single-sided materials.
                    if depth == 0 {
                        self.accel.intersect_camera(&ray)
                    } else {
                        self.accel.intersect(&ray)
                    }
                }
            };
            let Some(hit) = hit else {
                l += beta * self.escaped(&ray, depth, prev_pdf);
                break;
            };
            // The hit is used field by field: a copy of the whole struct
            // would load 16 bytes that `intersect` stored in pieces, which
            // stalls store-to-load forwarding.
            let Hit { t, prim, u, v: hv } = hit;
            let (v, info) = match self.plain_surface(prim, u, hv) {
                Some(plain) => plain,
                None => {
                    let hit = Hit { t, prim, u, v: hv };
                    // The surface layer, base level of textures.
                    let ss = self.prepared.shading_surface(&ray, &hit, None);
                    let mat = self.prepared.material(ss.hit.material);
                    owned = MaterialInfo::new(ss.material, mat);
                    let v = Vertex {
                        p: ss.hit.p,
                        ng: ss.hit.ng,
                        ns: ss.ns,
                    };
                    (v, &owned)
                }
            };
            // Every ray's direction is unit: the camera's are normalised,
            // and sampled directions are unit vectors (up to rounding).
            let wo = -ray.dir;
            if depth == 0 {
                first = Some((t * ray.dir.length(), v.ns));
            }
            let m = &info.bsdf.m;
            let cos_o = v.ng.dot(wo);
            // Emission seen along the path (one-sided unless two-sided).
            if info.emissive && (info.two_sided || cos_o > 0.0) {
                let w = if prev_pdf == 0.0 {
                    1.0
                } else {
                    self.emitter_mis_weight(prim, prev_p, &v, wo, prev_pdf)
                };
                l += beta * m.emission * w;
            }
            // Shading frame on the side of the viewer.
            let front = cos_o >= 0.0;
            // (A multiplication by the side's sign: the same values, no branch.)
            let side = if front { 1.0 } else { -1.0 };
            let (n, ng) = (v.ns * side, v.ng * side);
            let last = depth + 1 >= self.max_depth;
            // Next-event estimation.
            l += beta * self.direct(v.p, info, n, ng, wo, !last, rng, rays);
            if last {
                break;
            }
            // Continue the path.
            let Some(s) = Self::sample_bsdf(&info.bsdf, n, ng, wo, front, rng) else {
                break;
            };
            beta *= s.weight;
            if !beta.is_finite() || beta.max_element() <= 0.0 {
                break;
            }
            prev_pdf = if s.delta { 0.0 } else { s.pdf };
            prev_p = v.p;
            ray = Ray::new(offset_ray_origin(v.p, v.ng, s.wi), s.wi);
            // Russian roulette.
            if depth + 1 >= self.rr_depth {
                let q = beta.max_element().min(0.95);
                if rng.next_1d() >= q {
                    break;
                }
                beta /= q;
            }
        }
        (l, first)
    }

    /// Radiance of a ray that escaped at path depth `depth` after a scatter
    /// of pdf `prev_pdf` (0: a delta lobe): `miss_radiance`'s rule (the
    /// camera sees the background, other rays the environment map, which
    /// lights the scene), MIS-weighted against the environment's next-event
    /// estimation after a non-delta scatter; without a map the plain
    /// background is seen only directly (camera or delta chains) and lights
    /// nothing.
    #[inline]
    fn escaped(&self, ray: &Ray, depth: u32, prev_pdf: f32) -> Vec3 {
        let scene = self.prepared.scene;
        if scene.environment.is_some() || depth == 0 || prev_pdf == 0.0 {
            let l = chiaro_core::shading::texture::miss_radiance(scene, ray.dir, depth == 0);
            match &self.env {
                Some(env) if depth > 0 && prev_pdf > 0.0 => {
                    let light_pdf = self.light_pick_pdf(self.lights.len()) * env.pdf(ray.dir);
                    l * power_heuristic(prev_pdf, light_pdf)
                }
                _ => l,
            }
        } else {
            Vec3::ZERO
        }
    }

    /// MIS weight of emission found by BSDF sampling from `from` with pdf `bsdf_pdf`.
    fn emitter_mis_weight(
        &self,
        prim: u32,
        from: Vec3,
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
        let light_pdf = self.light_pick_pdf(li as usize) * d2 / (cos_l * tl.area);
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

    /// A sample of emissive triangle `tl` seen from `p`: the direction, the
    /// point, and `(Le, solid-angle pdf)`, following `sample_light`'s
    /// area-light case (uniform in area, converted by `d^2 / cos_l`).
    fn sample_tri_light(tl: &TriLight, p: Vec3, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        let bary = sample_uniform_triangle(u);
        let q = tl.a * bary.x + tl.b * bary.y + tl.c * (1.0 - bary.x - bary.y);
        let d = q - p;
        let dist2 = d.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let wi = d * (1.0 / dist2.sqrt());
        let mut cos_l = -tl.n.dot(wi);
        if tl.two_sided {
            cos_l = cos_l.abs();
        }
        if cos_l <= 0.0 {
            return None;
        }
        Some((wi, q, dist2 / (cos_l * tl.area)))
    }

    /// Next-event estimation: one light chosen by power, one sample on it,
    /// its visibility by a shadow ray; MIS-weighted against BSDF sampling
    /// when the path continues (`mis`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn direct(
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
        let Some(li) = self.pick_light(u_pick) else {
            return Vec3::ZERO;
        };
        self.direct_from(li, p, info, n, ng, wo, mis, u, rays)
    }

    /// [`Self::direct`] with the light chosen (`li`) and its sample's
    /// numbers drawn (`u`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn direct_from(
        &self,
        li: usize,
        p: Vec3,
        info: &MaterialInfo,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        mis: bool,
        u: Vec2,
        rays: &mut u64,
    ) -> Vec3 {
        let pick = self.light_pick_pdf(li);
        if pick <= 0.0 {
            return Vec3::ZERO;
        }
        if let Some(tl) = &self.tri_lights[li] {
            // Emissive triangle: L = f cos Le / (pick * pdf_solid_angle).
            let Some((wi, q, light_pdf)) = Self::sample_tri_light(tl, p, u) else {
                return Vec3::ZERO;
            };
            if ng.dot(wi) <= 0.0 {
                return Vec3::ZERO;
            }
            let f_cos = info.bsdf.eval(n, wo, wi);
            if f_cos == Vec3::ZERO {
                return Vec3::ZERO;
            }
            *rays += 1;
            if self
                .accel
                .occluded(&Ray::segment(offset_ray_origin(p, ng, wi), q))
            {
                return Vec3::ZERO;
            }
            let light_pdf = light_pdf * pick;
            // The power heuristic's weight over the light's pdf, in one
            // division: (l^2 / (l^2 + b^2)) / l = l / (l^2 + b^2).
            let w_over_pdf = if mis {
                let bsdf_pdf = info.bsdf.pdf(n, wo, wi);
                light_pdf / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf)
            } else {
                1.0 / light_pdf
            };
            return f_cos * tl.le * w_over_pdf;
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
        *rays += 1;
        let origin = offset_ray_origin(p, ng, s.wi);
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
            && let Some(light_pdf) = Self::light_solid_angle_pdf(light, p, s.point)
        {
            let bsdf_pdf = info.bsdf.pdf(n, wo, s.wi);
            w = power_heuristic(light_pdf * pick, bsdf_pdf);
        }
        PI * f_cos * s.intensity * (w / pick)
    }

    /// Next-event estimation of the environment (light `lights.len()`,
    /// chosen with probability `pick`): a direction by its luminance, a
    /// shadow ray to infinity, `f cos L / pdf` MIS-weighted (`mis`) against
    /// BSDF sampling as [`Self::escaped`] weights the other strategy.
    /// (Not inlined: `direct_from` stays as small where there is no map.)
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn direct_env(
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
        if self
            .accel
            .occluded(&Ray::new(offset_ray_origin(p, ng, s.wi), s.wi))
        {
            return Vec3::ZERO;
        }
        let light_pdf = s.pdf * pick;
        let w_over_pdf = if mis {
            let bsdf_pdf = bsdf.pdf(n, wo, s.wi);
            light_pdf / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf)
        } else {
            1.0 / light_pdf
        };
        f_cos * s.radiance * w_over_pdf
    }

    /// Samples the next direction through [`Bsdf::sample`], drawing its
    /// numbers in the order the lock-step kernel follows: the lobe choice's
    /// (its pair skipped when there is one lobe), the direction's pair, and
    /// the Fresnel choice's only when the layer asks for it.
    #[inline]
    fn sample_bsdf(
        bsdf: &Bsdf,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        front: bool,
        rng: &mut SobolSampler,
    ) -> Option<BsdfSample> {
        if !bsdf.scatters() {
            return None;
        }
        let u_lobe = if bsdf.needs_lobe_number() {
            rng.next_1d()
        } else {
            rng.skip(1);
            0.0
        };
        let u = rng.next_2d();
        bsdf.sample(n, ng, wo, front, u_lobe, u, || rng.next_1d())
    }
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

    /// Mean and standard error of the mean of one channel over all pixels.
    fn mean_and_stderr(film: &Film, channel: usize) -> (f32, f32) {
        let values: Vec<f32> = film.color.iter().map(|c| c[channel]).collect();
        let n = values.len() as f32;
        let mean = values.iter().sum::<f32>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / (n - 1.0);
        (mean, (var / n).sqrt())
    }

    #[test]
    fn diffuse_sphere_inside_emitting_sphere_reflects_rho_times_le() {
        // Closed form. A convex Lambertian body of albedo rho inside a closed
        // enclosure whose inner surface emits radiance Le and reflects nothing
        // (albedo 0). A convex body cannot see itself, so every direction of
        // the outer hemisphere at any of its points meets the enclosure: the
        // incident radiance is Le over the whole hemisphere, the irradiance
        // E = integral Le cos(theta) dw = pi Le, and the reflected radiance is
        // L = (rho / pi) E = rho Le. Nothing else contributes (the enclosure
        // reflects nothing), so this holds at every max_depth >= 1, wherever
        // the inner sphere sits and whatever the enclosure's shape.
        // The enclosure is a tessellated sphere, so its triangles are lights:
        // depth 1 tests next-event estimation alone, depth 4 its MIS with
        // BSDF sampling.
        let le = 1.5;
        let rho = Vec3::new(0.8, 0.5, 0.2);
        let mut s = Scene::default();
        let emitter = s.add_material(Material {
            emission: Vec3::splat(le),
            two_sided: true,
            ..Material::diffuse("enclosure", Vec3::ZERO)
        });
        let inner = s.add_material(Material::diffuse("inner", rho));
        let shell = s.add_mesh(primitives::uv_sphere(10.0, 32, 16));
        s.objects.push(Object {
            geometry: Geometry::Mesh(shell),
            material: emitter,
            smooth: false,
            ..Default::default()
        });
        let center = Vec3::new(1.0, 0.5, 0.0);
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 1.0 },
            material: inner,
            transform: chiaro_core::scene::Transform {
                translate: center,
                ..Default::default()
            },
            ..Default::default()
        });
        // A narrow view whose every pixel lands on the inner sphere.
        s.camera = Camera {
            eye: center + Vec3::new(0.5, 1.0, -4.0),
            look_at: center,
            fov_y_degrees: 10.0,
            ..Camera::default()
        };
        s.render.width = 16;
        s.render.height = 16;
        s.render.samples = 64;
        for depth in [1, 4] {
            s.render.path.max_depth = depth;
            let (film, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
            for c in 0..3 {
                let (mean, stderr) = mean_and_stderr(&film, c);
                let expect = rho[c] * le;
                // The estimate must be noisy but informative for this to test anything.
                assert!(
                    stderr < 0.02 * expect,
                    "depth {depth} ch {c}: stderr {stderr}"
                );
                assert!(
                    (mean - expect).abs() < 4.0 * stderr,
                    "depth {depth} channel {c}: mean {mean} vs rho Le = {expect} (stderr {stderr})"
                );
            }
        }
    }

    #[test]
    fn images_do_not_depend_on_the_thread_count() {
        // Random numbers come from (seed, pixel, sample): 1 and 3 threads agree bit for bit.
        let mut s = furnace(Some(12));
        s.render.path.rr_depth = 2;
        s.render.samples = 2;
        let render = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool");
            pool.install(|| render_with(&s, &s.render, &NoProgress, &bvh))
                .expect("renders")
                .0
        };
        let (one, three) = (render(1), render(3));
        assert!(
            one.color
                .iter()
                .any(|c| (c.x - one.color[0].x).abs() > 1e-3)
        );
        assert_eq!(one.color, three.color);
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

    /// The shipped scene `scenes/NAME.toml` at `size` x `size` pixels.
    fn shipped(name: &str, size: u32) -> Scene {
        let path = format!("{}/../../scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
        let mut s = chiaro_io::load_scene(std::path::Path::new(&path))
            .expect("the shipped scene loads")
            .scene;
        s.render.width = size;
        s.render.height = size;
        s
    }

    /// Mitsuba's Cornell box as shipped (`scenes/mitsuba-cbox.toml`).
    fn mitsuba_cbox(size: u32) -> Scene {
        shipped("mitsuba-cbox", size)
    }

    /// Renders `scene` with both loops and asserts the films and ray
    /// counts are equal bit for bit.
    fn assert_kernels_agree(scene: &Scene, what: &str) {
        let settings = &scene.render;
        let render =
            |k| render_with_kernel(scene, settings, &NoProgress, &bvh, k).expect("renders");
        let (a, ra) = render(Kernel::Scalar);
        let (b, rb) = render(Kernel::Lanes);
        assert_eq!(ra, rb, "{what}: ray counts");
        let bits = |v: &[Vec3]| {
            v.iter()
                .flat_map(|c| c.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert!(bits(&a.color) == bits(&b.color), "{what}: colours differ");
        assert!(bits(&a.normal) == bits(&b.normal), "{what}: normals differ");
        let depth = |f: &Film| f.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        assert!(depth(&a) == depth(&b), "{what}: depths differ");
        assert!(
            a.color.iter().any(|c| c.max_element() > 0.0),
            "{what}: black image"
        );
    }

    #[test]
    fn lock_step_kernel_equals_the_scalar_loop_on_a_diffuse_box() {
        // Sample counts below, at and between multiples of the lane count;
        // depths that end at the first vertex and before Russian roulette.
        let lanes = LANES as u32;
        for (spp, max_depth, rr_depth) in [(lanes, 7, 5), (5, 7, 5), (lanes + 5, 3, 1), (3, 1, 5)] {
            let mut s = mitsuba_cbox(12);
            s.render.samples = spp;
            s.render.path.max_depth = max_depth;
            s.render.path.rr_depth = rr_depth;
            assert_kernels_agree(&s, &format!("spp {spp} depth {max_depth} rr {rr_depth}"));
        }
    }

    #[test]
    fn lock_step_kernel_hands_other_surfaces_to_the_scalar_loop() {
        let mut s = mitsuba_cbox(12);
        s.render.samples = 11;
        // A glossy wall, a mirror wall, and a glass sphere (analytic): lanes
        // meeting them finish in the scalar loop.
        let id = |s: &Scene, n: &str| s.material_by_name(n).expect("a shipped material").index();
        let red = id(&s, "red");
        s.materials[red].specular = Vec3::splat(0.4);
        s.materials[red].shininess = 20.0;
        let green = id(&s, "green");
        s.materials[green].reflect = Vec3::splat(0.6);
        let glass = s.add_material(Material {
            transmit: Vec3::splat(0.9),
            ior: 1.5,
            fresnel: true,
            ..Material::diffuse("glass", Vec3::ZERO)
        });
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 0.25 },
            material: glass,
            transform: chiaro_core::scene::Transform {
                translate: Vec3::new(-0.3, -0.2, 0.4),
                ..Default::default()
            },
            ..Default::default()
        });
        assert_kernels_agree(&s, "mixed materials");
    }

    #[test]
    fn lock_step_kernel_equals_the_scalar_loop_on_the_shipped_scenes() {
        // Area, point, spot and directional lights (sampled by the scalar
        // loop's code), mirrors, glass, glossy and textured surfaces.
        for name in [
            "cornell-box",
            "whitted",
            "spotlights",
            "transparency",
            "teapot",
        ] {
            let mut s = shipped(name, 10);
            s.render.samples = 6;
            s.render.path.max_depth = 6;
            s.render.path.rr_depth = 2;
            assert_kernels_agree(&s, name);
        }
    }

    #[test]
    fn lock_step_kernel_with_area_lights() {
        // Quad, disk and sphere area lights beside the emissive triangles:
        // next-event estimation with MIS through the scalar loop's code.
        let mut s = mitsuba_cbox(12);
        s.render.samples = 7;
        let area = |shape| Light::Area {
            shape,
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 3.0,
            two_sided: false,
        };
        s.lights.push(area(AreaShape::Quad {
            corner: Vec3::new(-0.9, 0.5, -0.9),
            edge_u: Vec3::new(0.0, 0.0, 0.3),
            edge_v: Vec3::new(0.0, 0.3, 0.0),
        }));
        s.lights.push(area(AreaShape::Disk {
            center: Vec3::new(0.6, 0.6, -0.6),
            normal: Vec3::new(-1.0, -1.0, 1.0).normalize(),
            radius: 0.15,
        }));
        s.lights.push(area(AreaShape::Sphere {
            center: Vec3::new(0.0, 0.2, 0.5),
            radius: 0.1,
        }));
        assert_kernels_agree(&s, "area lights");
    }

    #[test]
    fn lock_step_kernel_with_one_light() {
        // One emissive triangle: the light choice's pair is skipped.
        let mut s = mitsuba_cbox(12);
        s.render.samples = 9;
        replace_emitter(
            &mut s,
            vec![
                Vec3::new(-0.3, 0.98, -0.3),
                Vec3::new(0.3, 0.98, -0.3),
                Vec3::new(0.0, 0.98, 0.3),
            ],
            vec![[0, 1, 2]],
        );
        assert_kernels_agree(&s, "one light");
    }

    /// Mitsuba's box with its emitter (the object `light`) replaced by the
    /// triangles `indices` of `positions`, in world space.
    fn replace_emitter(s: &mut Scene, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) {
        let mesh = s.add_mesh(chiaro_core::scene::Mesh {
            name: "emitter triangles".into(),
            positions,
            indices,
            ..Default::default()
        });
        let light = s
            .objects
            .iter_mut()
            .find(|o| o.name == "light")
            .expect("the light");
        light.geometry = Geometry::Mesh(mesh);
        light.transform = Default::default();
    }

    #[test]
    fn lock_step_kernel_with_several_triangle_lights() {
        // The emitter as 3, 4 (gathered by selects over the lights, up to
        // `lanes::SELECT_LIGHTS`), 5 and 9 triangles (gathered lane by
        // lane) of unequal areas, so the picks differ between lights.
        for n in [3u32, 4, 5, 9] {
            let mut s = mitsuba_cbox(12);
            s.render.samples = 9;
            let mut positions = Vec::new();
            let mut indices = Vec::new();
            for k in 0..n {
                let (x, w) = (-0.6 + 0.13 * k as f32, 0.05 + 0.02 * k as f32);
                let base = positions.len() as u32;
                positions.extend([
                    Vec3::new(x, 0.98, -0.3),
                    Vec3::new(x + w, 0.98, -0.3),
                    Vec3::new(x, 0.98, 0.3),
                ]);
                // (Counter-clockwise seen from below: facing down.)
                indices.push([base, base + 1, base + 2]);
            }
            replace_emitter(&mut s, positions, indices);
            let prepared = PreparedScene::new(&s, PrepareOptions::default());
            let accel = bvh(&prepared);
            let tracer = PathTracer::new(&prepared, accel.as_ref(), &s.render, true);
            assert_eq!(tracer.lights.len(), n as usize, "{n} lights");
            assert_eq!(
                tracer.select_lights.len(),
                if n as usize <= lanes::SELECT_LIGHTS {
                    n as usize
                } else {
                    0
                },
                "{n} lights: the select list"
            );
            assert_kernels_agree(&s, &format!("{n} triangle lights"));
        }
    }

    #[test]
    fn lock_step_kernel_with_only_an_environment() {
        // No lights but the environment (the box's emitter made plain
        // white, the front open): lanes sample it through the scalar
        // loop's code, and still draw each bounce's pairs.
        let mut s = mitsuba_cbox(12);
        s.render.samples = 8;
        let light = s.material_by_name("light").expect("the light").index();
        s.materials[light].emission = Vec3::ZERO;
        let env = s.add_texture(chiaro_core::scene::Texture::Image(
            chiaro_core::scene::ImageTexture {
                source: "env".into(),
                width: 8,
                height: 4,
                texels: (0..32)
                    .map(|i| [0.2, 0.4 + (i / 8) as f32 * 0.1, 0.9, 1.0])
                    .collect(),
                wrap: chiaro_core::scene::WrapMode::Repeat,
                ..Default::default()
            },
        ));
        s.environment = Some(chiaro_core::scene::Environment {
            texture: env,
            intensity: 2.0,
            rotate_y_degrees: 0.0,
            as_background: true,
        });
        assert_kernels_agree(&s, "environment only");
    }

    #[test]
    fn lock_step_kernel_with_an_environment_and_lights() {
        // The box's two emitter triangles and the environment: lanes that
        // pick the environment take the scalar loop's code.
        let mut s = mitsuba_cbox(12);
        s.render.samples = 11;
        s.render.path.max_depth = 5;
        s.render.path.rr_depth = 2;
        let env = s.add_texture(chiaro_core::scene::Texture::Image(spot_map(
            16,
            8,
            (5, 3),
            50.0,
        )));
        s.environment = Some(chiaro_core::scene::Environment {
            texture: env,
            intensity: 1.0,
            rotate_y_degrees: 200.0,
            as_background: false,
        });
        let prepared = PreparedScene::new(&s, PrepareOptions::default());
        let accel = bvh(&prepared);
        let tracer = PathTracer::new(&prepared, accel.as_ref(), &s.render, true);
        assert_eq!(tracer.light_count(), tracer.lights.len() + 1);
        assert!(tracer.env.is_some());
        assert_kernels_agree(&s, "environment and lights");
    }

    /// A `w x h` lat-long map of 0.05 with the texel `spot` at `value`.
    fn spot_map(w: u32, h: u32, spot: (u32, u32), value: f32) -> chiaro_core::scene::ImageTexture {
        chiaro_core::scene::ImageTexture {
            source: "spot".into(),
            width: w,
            height: h,
            texels: (0..w * h)
                .map(|i| {
                    let v = if (i % w, i / w) == spot { value } else { 0.05 };
                    [v, v, v, 1.0]
                })
                .collect(),
            wrap: chiaro_core::scene::WrapMode::Repeat,
            ..Default::default()
        }
    }

    /// Mean and unbiased variance of channel 0 over the film's pixels.
    fn mean_and_variance(film: &Film) -> (f32, f32) {
        let n = film.color.len() as f32;
        let mean = film.color.iter().map(|c| c.x).sum::<f32>() / n;
        let var = film.color.iter().map(|c| (c.x - mean).powi(2)).sum::<f32>() / (n - 1.0);
        (mean, var)
    }

    #[test]
    fn diffuse_sphere_under_a_white_environment_reflects_its_albedo() {
        // Furnace: a convex Lambertian body of albedo rho under a constant
        // environment L sees L over every outward hemisphere, so it
        // reflects rho L at any depth. Depth 1 is the environment's
        // next-event estimation alone; depth 4 its MIS with BSDF sampling.
        // A faceted mesh sphere (the lock-step kernel) and an analytic one
        // (the scalar loop), each filling the frame; and the reference.
        let (rho, le) = (0.6, 1.5);
        for analytic in [false, true] {
            let mut s = Scene::default();
            s.add_material(Material::diffuse("white", Vec3::splat(rho)));
            let geometry = if analytic {
                Geometry::Sphere { radius: 1.0 }
            } else {
                Geometry::Mesh(s.add_mesh(primitives::uv_sphere(1.0, 24, 12)))
            };
            s.objects.push(Object {
                geometry,
                smooth: false,
                ..Default::default()
            });
            let env = s.add_texture(chiaro_core::scene::Texture::Image(spot_map(
                8,
                4,
                (0, 0),
                0.05,
            )));
            s.environment = Some(chiaro_core::scene::Environment {
                texture: env,
                intensity: le / 0.05,
                rotate_y_degrees: 10.0,
                as_background: false,
            });
            s.camera = Camera {
                eye: Vec3::new(0.3, 0.4, -4.0),
                look_at: Vec3::new(0.0, 0.2, 0.0),
                fov_y_degrees: 8.0,
                ..Camera::default()
            };
            s.render.width = 16;
            s.render.height = 16;
            s.render.samples = 64;
            s.render.path.rr_depth = 2;
            for (depth, kernel) in [
                (1, Kernel::Lanes),
                (4, Kernel::Lanes),
                (4, Kernel::Reference),
            ] {
                s.render.path.max_depth = depth;
                let (film, _) =
                    render_with_kernel(&s, &s.render, &NoProgress, &bvh, kernel).expect("renders");
                let (mean, var) = mean_and_variance(&film);
                let stderr = (var / film.color.len() as f32).sqrt();
                let expect = rho * le;
                eprintln!(
                    "analytic {analytic} depth {depth} {kernel:?}: {mean} +- {stderr} vs {expect}"
                );
                assert!(
                    (mean - expect).abs() < 4.0 * stderr + 1e-4,
                    "analytic {analytic}, depth {depth}, {kernel:?}: mean {mean} stderr {stderr}, expected {expect}"
                );
            }
        }
    }

    #[test]
    fn environment_sampling_cuts_the_variance_of_a_small_bright_spot() {
        // A diffuse plane under a dim map with one texel 40000 times as
        // bright (about 48 degrees from the zenith). Its radiance is
        // rho / pi times the irradiance E = integral L cos over the upper
        // hemisphere, computed here by quadrature of the lookup. With the
        // environment sampled and without (BSDF sampling alone) the mean
        // must be that; at equal samples the variance must be far lower.
        let rho = 0.5;
        let mut s = Scene::default();
        s.add_material(Material::diffuse("grey", Vec3::splat(rho)));
        let plane = s.add_mesh(primitives::plane(400.0, 1));
        s.objects.push(Object {
            geometry: Geometry::Mesh(plane),
            smooth: false,
            ..Default::default()
        });
        let env = s.add_texture(chiaro_core::scene::Texture::Image(spot_map(
            64,
            32,
            (40, 8),
            2000.0,
        )));
        s.environment = Some(chiaro_core::scene::Environment {
            texture: env,
            intensity: 1.0,
            rotate_y_degrees: 25.0,
            as_background: false,
        });
        s.camera = Camera {
            eye: Vec3::new(0.0, 1.0, -0.001),
            look_at: Vec3::ZERO,
            fov_y_degrees: 30.0,
            ..Camera::default()
        };
        s.render.width = 16;
        s.render.height = 16;
        s.render.samples = 64;
        s.render.path.max_depth = 2;
        // E by the midpoint rule over the upper hemisphere.
        let (nt, np) = (1024, 4096);
        let mut e = 0.0f64;
        for i in 0..nt {
            let theta = (i as f32 + 0.5) / nt as f32 * 0.5 * PI;
            let (st, ct) = theta.sin_cos();
            let mut row = 0.0f64;
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                let d = Vec3::new(st * phi.cos(), ct, st * phi.sin());
                row += f64::from(chiaro_core::shading::texture::environment_radiance(&s, d).x);
            }
            e += row * f64::from(st * ct);
        }
        let e = e as f32 * (0.5 * PI / nt as f32) * (2.0 * PI / np as f32);
        let expect = rho / PI * e;
        let mut variance = [0.0; 2];
        for (k, env_sampling) in [true, false].into_iter().enumerate() {
            let (film, _) = render_impl(
                &s,
                &s.render,
                &NoProgress,
                &bvh,
                Kernel::Lanes,
                env_sampling,
            )
            .expect("renders");
            assert!(film.is_clean());
            let (mean, var) = mean_and_variance(&film);
            let stderr = (var / film.color.len() as f32).sqrt();
            eprintln!(
                "environment sampling {env_sampling}: mean {mean} stderr {stderr} variance {var}, expected {expect}"
            );
            assert!(
                (mean - expect).abs() < 4.0 * stderr + 2e-3 * expect,
                "environment sampling {env_sampling}: mean {mean} stderr {stderr}, expected {expect}"
            );
            variance[k] = var;
        }
        assert!(
            variance[0] * 50.0 < variance[1],
            "variance with environment sampling {} against {} without",
            variance[0],
            variance[1]
        );
    }

    #[test]
    fn lanes_pick_the_lights_the_scalar_pick_does() {
        // Counting CDF entries (up to 16 lights) and the binary search
        // (more) against `pick_light`, at and beside every CDF entry.
        for k in [1usize, 2, 3, 16, 17, 40] {
            let mut s = mitsuba_cbox(4);
            for j in 0..k {
                s.lights.push(Light::Point {
                    position: Vec3::new(0.0, 0.5, 0.0),
                    color: Vec3::ONE,
                    intensity: 1.0 + (j % 5) as f32,
                    attenuation: Attenuation::InverseSquare,
                });
            }
            let prepared = PreparedScene::new(&s, PrepareOptions::default());
            let accel = SceneBvh::new(&prepared);
            let tracer = PathTracer::new(&prepared, &accel, &s.render, true);
            let mut us = vec![0.0, 0.5, 0.999_999_94, 1.0];
            for &c in &tracer.light_cdf {
                us.extend([c.next_down(), c, c.next_up()]);
            }
            for chunk in us.chunks(LANES) {
                let mut u = [0.0; LANES];
                u[..chunk.len()].copy_from_slice(chunk);
                let lanes = tracer.pick_lights(&u).expect("lights");
                for i in 0..LANES {
                    let want = tracer.pick_light(u[i]).expect("lights") as u32;
                    assert_eq!(lanes[i], want, "{k} lights, u = {}", u[i]);
                }
            }
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
        // Shadow rays are blocked by glass (no caustics through NEE), so the
        // sphere's shadow on the plane darkens; every other pixel must be
        // unchanged. A pixel is classified by where its centre ray meets the
        // plane: in the shadow (the segment to the light passes the sphere's
        // centre closer than r - 0.1), clear of it (farther than r + 0.15, a
        // margin for the pixel footprint), or on the edge (not checked).
        let (with, _) = render_with(&s, &s.render, &NoProgress, &bvh).expect("renders");
        let (centre, r, light) = (Vec3::new(0.0, 0.8, -0.5), 0.7, Vec3::new(0.0, 4.0, 0.0));
        let (w, h) = (s.render.width, s.render.height);
        let (mut shadowed, mut clear) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let d = s.camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
                let q = s.camera.eye + d * (-s.camera.eye.y / d.y);
                // Distance from the sphere's centre to the segment q -> light.
                let seg = light - q;
                let t = ((centre - q).dot(seg) / seg.length_squared()).clamp(0.0, 1.0);
                let dist = (q + seg * t - centre).length();
                let i = (y * w + x) as usize;
                let (a, b) = (without.color[i].x, with.color[i].x);
                if dist > r + 0.15 {
                    clear += 1;
                    assert!(
                        (a - b).abs() <= 1e-3,
                        "pixel ({x}, {y}) changed: {a} -> {b}"
                    );
                } else if dist < r - 0.1 {
                    shadowed += 1;
                    assert!(
                        a > 0.1 && b < 0.3 * a,
                        "pixel ({x}, {y}) not shadowed: {a} -> {b}"
                    );
                }
            }
        }
        assert!(
            clear > 80 && shadowed > 10,
            "clear {clear} shadowed {shadowed}"
        );
    }
}
