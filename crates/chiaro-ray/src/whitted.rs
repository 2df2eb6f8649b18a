//! Whitted recursive ray tracing (Whitted 1980, "An Improved Illumination
//! Model for Shaded Display"; Foley et al. section 16.12).
//!
//! At each hit the one local illumination function
//! ([`chiaro_core::shading::shade_local`]) gives the emitted, ambient and
//! direct light, with each light sample's visibility decided by a shadow
//! ray; shadow rays pass through transparent surfaces, tinted by their
//! transmit colour `kt`. Then
//! - a reflected ray is traced, weighted by `kr` (or by the Fresnel
//!   reflectance `F` for a dielectric: a material with `kt > 0` and
//!   `fresnel = true`),
//! - a refracted ray is traced by Snell's law with the material's `ior`,
//!   weighted by `kt` (or `(1 - F) kt`); past the critical angle there is no
//!   refracted ray and the reflection takes its weight (total internal
//!   reflection),
//! - light travelling inside a medium is attenuated by Beer's law
//!   `exp(-absorption * distance)`.
//!
//! Recursion stops at `settings.whitted.max_depth` or when a ray's weight
//! (the product of the weights along its path) falls below
//! `settings.whitted.min_weight`.
//!
//! Pixels are sampled either by stratified supersampling (`AaMode::Supersample`:
//! one ray through the pixel centre for one sample, with area lights sampled
//! at their strata centres as the scan converter samples them; N-rooks
//! stratified jitter and jittered light samples otherwise) or by Whitted's adaptive supersampling (`AaMode::Adaptive`:
//! rays at the pixel corners, squares subdivided where corner colours differ
//! by more than `adaptive_threshold`, down to `adaptive_max_depth`). Every
//! random number comes from [`pixel_rng`] seeded by (scene seed, pixel or
//! corner, sample), so images do not depend on the thread count.
//!
//! The [`Tracer`] is reusable: the hybrid technique installs an
//! indirect-diffuse lookup ([`Tracer::with_indirect`]) that replaces the
//! ambient term, and cross-technique tests call [`Tracer::light_visibility`].

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::instanced::build_accelerator;
use chiaro_core::error::{CoreError, Result};
use chiaro_core::film::{Film, TilePixels, TileRect, render_tiles_in};
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::prepared::{PrepareOptions, PreparedScene, RayDifferentials, SurfaceHit};
use chiaro_core::progress::Progress;
use chiaro_core::sampling::{Rng, pixel_rng, uniform, uniform2};
use chiaro_core::scene::{AaMode, RenderSettings, Scene, ShadowMethod};
use chiaro_core::shading::texture::miss_radiance;
use chiaro_core::shading::{
    EmitterGroup, LightSample, LocalLighting, SampleKey, ShadingPoint, SurfaceMaterial,
    delta_split, depth_cue, group_jitter, sanitize, shade_local,
};
use chiaro_core::shadow::ShadowCasters;
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

/// Tile side in pixels.
const TILE: u32 = 16;
/// Deepest adaptive subdivision accepted (2^8 x 2^8 corners per pixel).
const MAX_ADAPTIVE_DEPTH: u32 = 8;
/// Salt separating adaptive corner seeds from supersampling seeds.
const ADAPTIVE_SALT: u64 = 0xAD47_1BE5_0000_0001;

/// Counters of one render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderStats {
    /// Every ray traced: camera, reflected, refracted and shadow rays.
    pub rays: u64,
    /// Camera rays alone.
    pub primary_rays: u64,
}

/// An indirect-diffuse lookup: for a surface point, the indirect incident
/// light expressed as the radiance a white Lambertian surface would reflect
/// (irradiance / pi), so that the tracer adds `kd * indirect(hit)` in place
/// of the ambient term.
pub type IndirectFn<'a> = dyn Fn(&SurfaceHit) -> Vec3 + Send + Sync + 'a;

/// Per-thread state of a trace: the random generator of the current pixel
/// sample and the ray counter.
#[derive(Debug, Clone)]
pub struct TraceState {
    /// Generator for area-light jitter; seeded per pixel sample.
    pub rng: Rng,
    /// Rays traced so far (camera, secondary and shadow rays).
    pub rays: u64,
    /// The pixel whose centre the camera ray goes through, if it does: its
    /// primary hit keys the emitter group's picks as the scan converter's
    /// pixel-centre samples do.
    pub pixel: Option<(u32, u32)>,
}

impl TraceState {
    /// A state with a fresh generator and a zero count.
    pub fn new(rng: Rng) -> Self {
        Self {
            rng,
            rays: 0,
            pixel: None,
        }
    }
}

/// What a camera ray found, for the film's colour, depth and normal buffers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimarySample {
    /// Linear RGB radiance, sanitised (never NaN, never negative).
    pub color: Vec3,
    /// Distance to the first surface along the unit camera ray, infinite
    /// when nothing was hit.
    pub depth: f32,
    /// Unit shading normal at the first surface (facing the camera), zero
    /// when nothing was hit.
    pub normal: Vec3,
}

/// The specular continuation of a ray at a hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpecularRays {
    /// Reflected ray and its weight (zero weight when none).
    pub reflected: (Ray, Vec3),
    /// Refracted ray and its weight; `None` for opaque surfaces and under
    /// total internal reflection (whose weight went to `reflected`).
    pub refracted: Option<(Ray, Vec3)>,
}

/// Reflected and refracted rays at a surface point: the BSDF layer's
/// [`delta_split`] (directions, Fresnel, total internal reflection, the ior
/// rule) with rays offset from `p`; a refracted ray of zero weight is not
/// traced.
///
/// `n` and `ng` are the unit shading and geometric normals flipped to the
/// side of `wo` (the unit direction back along the incoming ray);
/// `entering` is true when `wo` is on the outside (front) of the surface.
/// Weights: `kr` and `kt`, or `F` and `(1 - F) kt` for a Fresnel
/// dielectric; under total internal reflection the reflection takes both.
pub fn specular_rays(
    m: &SurfaceMaterial,
    fresnel: bool,
    p: Vec3,
    n: Vec3,
    ng: Vec3,
    wo: Vec3,
    entering: bool,
) -> SpecularRays {
    let split = delta_split(m, fresnel, n, wo, entering);
    let ray = |dir: Vec3| Ray::new(offset_ray_origin(p, ng, dir), dir);
    let wt = split.refract_weight;
    SpecularRays {
        reflected: (ray(split.reflected), split.reflect_weight),
        refracted: split
            .refracted
            .filter(|_| wt.max_element() > 0.0)
            .map(|dir| (ray(dir), wt)),
    }
}

/// The Whitted ray tracer over one prepared scene: the flattened scene, its
/// accelerator, the settings, and optionally an indirect-diffuse lookup.
pub struct Tracer<'s> {
    /// The flattened scene (analytic spheres kept).
    pub prepared: PreparedScene<'s>,
    /// The accelerator over `prepared`: the flat BVH, or the two-level BVH
    /// when meshes are shared enough ([`build_accelerator`]).
    pub accel: Box<dyn Accelerator>,
    /// The render settings.
    pub settings: RenderSettings,
    indirect: Option<Box<IndirectFn<'s>>>,
    /// How each primitive affects shadow rays.
    casters: ShadowCasters,
    /// The emissive triangles sampled as one light, when there are many.
    emitters: Option<EmitterGroup>,
    /// One sample per pixel (the pixel-centre ray): light samples at their
    /// strata centres, as the scan converter takes them, so that both
    /// techniques estimate direct light with the same samples.
    centre_light_samples: bool,
}

impl std::fmt::Debug for Tracer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tracer")
            .field("triangles", &self.prepared.triangles.len())
            .field("spheres", &self.prepared.spheres.len())
            .field("indirect", &self.indirect.is_some())
            .finish_non_exhaustive()
    }
}

impl<'s> Tracer<'s> {
    /// Flattens `scene` (analytic spheres) and builds its accelerator.
    pub fn new(scene: &'s Scene, settings: &RenderSettings) -> Self {
        let prepared = PreparedScene::new(
            scene,
            PrepareOptions {
                analytic_spheres: true,
                ..PrepareOptions::default()
            },
        );
        Self::from_prepared(prepared, settings)
    }

    /// A tracer over an already prepared scene.
    pub fn from_prepared(prepared: PreparedScene<'s>, settings: &RenderSettings) -> Self {
        let accel = build_accelerator(&prepared);
        let casters = ShadowCasters::new(&prepared);
        let emitters = EmitterGroup::of_scene(&prepared, settings.light_samples.max(1));
        Self {
            prepared,
            accel,
            settings: settings.clone(),
            indirect: None,
            casters,
            emitters,
            centre_light_samples: settings.aa == AaMode::Supersample && settings.samples <= 1,
        }
    }

    /// Replaces the accelerator (built by [`build_accelerator`]) with
    /// `accel`, which must be built over this tracer's `prepared` scene.
    pub fn with_accelerator(mut self, accel: Box<dyn Accelerator>) -> Self {
        self.accel = accel;
        self
    }

    /// Installs an indirect-diffuse lookup (see [`IndirectFn`]): at every hit
    /// the ambient lights are ignored and `kd * indirect(hit)` is added
    /// instead. Used by the hybrid radiosity + ray tracing technique.
    pub fn with_indirect(mut self, f: impl Fn(&SurfaceHit) -> Vec3 + Send + Sync + 's) -> Self {
        self.indirect = Some(Box::new(f));
        self
    }

    /// RGB transmittance from the surface point `p` (unit geometric normal
    /// `ng`, either side) to the light sample: 0 when an opaque surface is in
    /// between, the product of the transmit colours of the transparent
    /// surfaces crossed otherwise (1 when nothing is in between), by the
    /// one rule of [`chiaro_core::shadow`]. Always 1 with
    /// `settings.shadows == ShadowMethod::None`.
    pub fn light_visibility(&self, p: Vec3, ng: Vec3, sample: &LightSample) -> Vec3 {
        let mut rays = 0;
        self.light_visibility_counted(p, ng, sample, &mut rays)
    }

    fn light_visibility_counted(
        &self,
        p: Vec3,
        ng: Vec3,
        sample: &LightSample,
        rays: &mut u64,
    ) -> Vec3 {
        if self.settings.shadows == ShadowMethod::None {
            return Vec3::ONE;
        }
        self.casters
            .light_transmittance(&*self.accel, p, ng, sample, rays)
    }

    /// The radiance arriving along `ray` (any direction length), traced
    /// recursively: `depth` is the recursion depth of this ray (0 for camera
    /// rays) and `weight` the product of the weights on its path, used for
    /// the cutoff. Counts every ray it traces in `state.rays`.
    pub fn trace(&self, ray: &Ray, depth: u32, weight: Vec3, state: &mut TraceState) -> Vec3 {
        self.trace_hit(ray, None, depth, weight, state).0
    }

    /// What a ray that hits nothing sees (`texture::miss_radiance`): camera
    /// rays see the background (the environment map when it is drawn as
    /// background); reflected and refracted rays see the environment map
    /// when the scene has one, the background colour otherwise.
    fn miss_radiance(&self, dir: Vec3, depth: u32) -> Vec3 {
        miss_radiance(self.prepared.scene, dir, depth == 0)
    }

    /// Like [`Tracer::trace`], also returning the hit distance (in units of
    /// `ray.dir`) and the facing shading normal, for the film's buffers.
    /// A camera ray's `differentials` give the pixel footprint over which
    /// image textures are filtered, as the scan converter filters them.
    fn trace_hit(
        &self,
        ray: &Ray,
        differentials: Option<&RayDifferentials>,
        depth: u32,
        weight: Vec3,
        state: &mut TraceState,
    ) -> (Vec3, f32, Vec3) {
        state.rays += 1;
        // Camera rays skip the backs of single-sided materials.
        let hit = if depth == 0 {
            self.accel.intersect_camera(ray)
        } else {
            self.accel.intersect(ray)
        };
        let Some(hit) = hit else {
            return (
                self.miss_radiance(ray.dir, depth),
                f32::INFINITY,
                Vec3::ZERO,
            );
        };
        let ss = self.prepared.shading_surface(ray, &hit, differentials);
        let sh = ss.hit;
        let material = self.prepared.material(sh.material);
        let mut sm = ss.material;
        let Some(wo) = (-ray.dir).try_normalize() else {
            return (Vec3::ZERO, hit.t, Vec3::ZERO);
        };
        let front = sh.ng.dot(wo) >= 0.0;
        let transmissive = sm.kt.max_element() > 0.0;
        // Two-sided materials and the insides of refracting objects are
        // shaded on the side the ray arrives from.
        let flip = !front && (material.two_sided || transmissive);
        let (n, ng) = if flip {
            (-ss.ns, -sh.ng)
        } else {
            (ss.ns, sh.ng)
        };
        if !front && !material.two_sided {
            // One-sided emitters emit from their front only.
            sm.emission = Vec3::ZERO;
        }
        let sp = ShadingPoint { p: sh.p, n, ng, wo };
        // Local illumination through the one shading function; the tracer
        // supplies only the visibility of each light sample.
        let lighting = LocalLighting {
            lights: &self.prepared.lights,
            area_samples: self.settings.light_samples.max(1),
            ambient: self.indirect.is_none(),
            group: self.emitters.as_ref(),
        };
        let TraceState { rng, rays, pixel } = state;
        let key = match *pixel {
            Some((x, y)) if depth == 0 => SampleKey::Pixel(x, y),
            _ => SampleKey::Point(sh.p),
        };
        let mut color = shade_local(
            &sm,
            &sp,
            &lighting,
            |li, i| {
                if !self.centre_light_samples {
                    uniform2(rng)
                } else if self.emitters.as_ref().is_some_and(|g| g.contains(li)) {
                    // The scan converter's per-pixel group picks.
                    group_jitter(self.settings.seed, key, i)
                } else {
                    Vec2::splat(0.5)
                }
            },
            |_, s| self.light_visibility_counted(sp.p, sp.ng, s, rays),
        );
        if let Some(indirect) = &self.indirect {
            color += sm.kd * indirect(&sh);
        }
        // Recursive rays: mirror reflection and refraction.
        if depth < self.settings.whitted.max_depth {
            let min_w = self.settings.whitted.min_weight;
            let spec = specular_rays(&sm, material.fresnel, sh.p, n, ng, wo, front);
            let (r_ray, wr) = spec.reflected;
            if wr.max_element() > 0.0 && (weight * wr).max_element() >= min_w {
                color += wr * self.trace(&r_ray, depth + 1, weight * wr, state);
            }
            if let Some((t_ray, wt)) = spec.refracted
                && (weight * wt).max_element() >= min_w
            {
                color += wt * self.trace(&t_ray, depth + 1, weight * wt, state);
            }
        }
        // Beer's law: the light from an exit point travelled inside the medium.
        if !front && transmissive && material.absorption.max_element() > 0.0 {
            let dist = hit.t * ray.dir.length();
            color *= (-material.absorption.max(Vec3::ZERO) * dist).exp();
        }
        (sanitize(color), hit.t, n)
    }

    /// Traces the camera ray through film position `film` (pixels, from
    /// the top-left corner) with the generator `rng`.
    pub fn trace_camera(&self, film: Vec2, rng: Rng, rays: &mut u64) -> PrimarySample {
        let scene = self.prepared.scene;
        let (w, h) = (self.settings.width.max(1), self.settings.height.max(1));
        let dir = scene.camera.ray_direction(film.x, film.y, w, h);
        let ray = Ray::new(scene.camera.eye, dir);
        // The rays through the neighbouring pixels, for texture filtering.
        let differentials = (!scene.textures.is_empty()).then(|| RayDifferentials {
            origin: ray.origin,
            dir_dx: scene.camera.ray_direction(film.x + 1.0, film.y, w, h),
            dir_dy: scene.camera.ray_direction(film.x, film.y + 1.0, w, h),
        });
        let mut state = TraceState::new(rng);
        // A pixel-centre ray names its pixel (the scan converter's rule).
        if film.x.fract() == 0.5 && film.y.fract() == 0.5 && film.x >= 0.0 && film.y >= 0.0 {
            state.pixel = Some((film.x as u32, film.y as u32));
        }
        let (mut color, depth, normal) =
            self.trace_hit(&ray, differentials.as_ref(), 0, Vec3::ONE, &mut state);
        *rays += state.rays;
        if let Some(cue) = &self.settings.depth_cue
            && depth.is_finite()
        {
            color = depth_cue(color, depth, cue);
        }
        PrimarySample {
            color: sanitize(color),
            depth,
            normal,
        }
    }

    /// Renders the image (or its `settings.crop` window; pixels outside stay
    /// black) with the tracer's settings, tiles in parallel. Returns the film (colour, plus depth and normal of the
    /// first sample of each pixel, or of its top-left corner for adaptive
    /// sampling) and the ray counts.
    pub fn render(&self, progress: &dyn Progress) -> Result<(Film, RenderStats)> {
        let s = &self.settings;
        if s.width == 0 || s.height == 0 {
            return Err(CoreError::BadSetting {
                key: "width/height".into(),
                message: "image size must be at least 1x1".into(),
            });
        }
        if s.aa == AaMode::Post {
            return Err(CoreError::Unsupported(
                "aa = \"post\" is a scan-conversion filter; the Whitted ray tracer supports \
                 \"supersample\" and \"adaptive\""
                    .into(),
            ));
        }
        let rays = AtomicU64::new(0);
        let primary = AtomicU64::new(0);
        // Tiles are cut to the crop window; every pixel depends only on its
        // own position, so a cropped render equals the full one inside it.
        let film = render_tiles_in(
            s.width,
            s.height,
            s.crop_rect(),
            TILE,
            "whitted",
            progress,
            |rect| {
                let mut count = (0u64, 0u64);
                let tile = match s.aa {
                    AaMode::Adaptive => self.adaptive_tile(rect, &mut count),
                    _ => self.supersample_tile(rect, &mut count),
                };
                rays.fetch_add(count.0, Ordering::Relaxed);
                primary.fetch_add(count.1, Ordering::Relaxed);
                tile
            },
        )?;
        Ok((
            film,
            RenderStats {
                rays: rays.into_inner(),
                primary_rays: primary.into_inner(),
            },
        ))
    }

    /// Stratified supersampling: one ray through the centre for one
    /// sample; otherwise N-rooks (Latin hypercube) strata with jitter
    /// (Shirley 1991), which stratifies both axes for any sample count.
    fn supersample_tile(&self, rect: TileRect, count: &mut (u64, u64)) -> TilePixels {
        let s = &self.settings;
        let n = s.samples.max(1);
        let mut tile = TilePixels::new(rect);
        let mut perm: Vec<u32> = Vec::with_capacity(n as usize);
        for ty in 0..rect.height {
            for tx in 0..rect.width {
                let (px, py) = (rect.x + tx, rect.y + ty);
                if n > 1 {
                    // The y strata are shuffled per pixel (Fisher-Yates).
                    perm.clear();
                    perm.extend(0..n);
                    let mut prng = pixel_rng(s.seed, px, py, u32::MAX);
                    for i in (1..n as usize).rev() {
                        let j = ((uniform(&mut prng) * (i + 1) as f32) as usize).min(i);
                        perm.swap(i, j);
                    }
                }
                let mut sum = Vec3::ZERO;
                let idx = (ty * rect.width + tx) as usize;
                for k in 0..n {
                    let mut rng = pixel_rng(s.seed, px, py, k);
                    let off = if n == 1 {
                        Vec2::splat(0.5)
                    } else {
                        let j = uniform2(&mut rng);
                        Vec2::new(
                            (k as f32 + j.x) / n as f32,
                            (perm[k as usize] as f32 + j.y) / n as f32,
                        )
                    };
                    let film = Vec2::new(px as f32, py as f32) + off;
                    let ps = self.trace_camera(film, rng, &mut count.0);
                    count.1 += 1;
                    if k == 0 {
                        tile.depth[idx] = ps.depth;
                        tile.normal[idx] = ps.normal;
                    }
                    sum += ps.color;
                }
                tile.color[idx] = sum / n as f32;
            }
        }
        tile
    }

    /// Whitted's adaptive supersampling: rays at the four corners of each
    /// pixel; where their colours differ by more than the threshold the
    /// square is divided into four and the test repeats on each quarter, down
    /// to `adaptive_max_depth`; a square's value is the mean of its
    /// corners (sub-squares averaged). Corners are keyed by their position
    /// on the finest grid, so neighbouring pixels and tiles share them
    /// exactly.
    fn adaptive_tile(&self, rect: TileRect, count: &mut (u64, u64)) -> TilePixels {
        let s = &self.settings;
        let max_depth = s.whitted.adaptive_max_depth.min(MAX_ADAPTIVE_DEPTH);
        let fine = 1u32 << max_depth;
        let threshold = s.whitted.adaptive_threshold.max(0.0);
        let mut tile = TilePixels::new(rect);
        let cw = rect.width as usize + 1;
        // Pixel-corner samples of the tile, traced once.
        let mut corners = Vec::with_capacity(cw * (rect.height as usize + 1));
        for cy in 0..=rect.height {
            for cx in 0..=rect.width {
                corners.push(self.corner_sample(
                    (rect.x + cx) * fine,
                    (rect.y + cy) * fine,
                    fine,
                    count,
                ));
            }
        }
        let mut cache: HashMap<(u32, u32), Vec3> = HashMap::new();
        for ty in 0..rect.height {
            for tx in 0..rect.width {
                let (tx_, ty_) = (tx as usize, ty as usize);
                let c = [
                    corners[ty_ * cw + tx_],
                    corners[ty_ * cw + tx_ + 1],
                    corners[(ty_ + 1) * cw + tx_],
                    corners[(ty_ + 1) * cw + tx_ + 1],
                ];
                let idx = ty_ * rect.width as usize + tx_;
                tile.depth[idx] = c[0].depth;
                tile.normal[idx] = c[0].normal;
                cache.clear();
                let x0 = (rect.x + tx) * fine;
                let y0 = (rect.y + ty) * fine;
                let colors = c.map(|p| p.color);
                tile.color[idx] = self.subdivide(
                    x0, y0, fine, colors, max_depth, threshold, fine, &mut cache, count,
                );
            }
        }
        tile
    }

    /// The sample at fine-grid corner `(fx, fy)` (`fine` cells per pixel).
    fn corner_sample(&self, fx: u32, fy: u32, fine: u32, count: &mut (u64, u64)) -> PrimarySample {
        let film = Vec2::new(fx as f32 / fine as f32, fy as f32 / fine as f32);
        let rng = pixel_rng(self.settings.seed ^ ADAPTIVE_SALT, fx, fy, 0);
        count.1 += 1;
        self.trace_camera(film, rng, &mut count.0)
    }

    /// Mean colour of the square at fine-grid `(x0, y0)` of side `size`
    /// with corner colours `c` (top-left, top-right, bottom-left,
    /// bottom-right), subdivided while `levels` remain and the corners
    /// differ by more than `threshold` in some channel.
    fn subdivide(
        &self,
        x0: u32,
        y0: u32,
        size: u32,
        c: [Vec3; 4],
        levels: u32,
        threshold: f32,
        fine: u32,
        cache: &mut HashMap<(u32, u32), Vec3>,
        count: &mut (u64, u64),
    ) -> Vec3 {
        let lo = c[0].min(c[1]).min(c[2]).min(c[3]);
        let hi = c[0].max(c[1]).max(c[2]).max(c[3]);
        if levels == 0 || size < 2 || (hi - lo).max_element() <= threshold {
            return (c[0] + c[1] + c[2] + c[3]) * 0.25;
        }
        let h = size / 2;
        let mut at = |fx: u32, fy: u32| {
            *cache
                .entry((fx, fy))
                .or_insert_with(|| self.corner_sample(fx, fy, fine, count).color)
        };
        let top = at(x0 + h, y0);
        let left = at(x0, y0 + h);
        let mid = at(x0 + h, y0 + h);
        let right = at(x0 + size, y0 + h);
        let bottom = at(x0 + h, y0 + size);
        let quads = [
            (x0, y0, [c[0], top, left, mid]),
            (x0 + h, y0, [top, c[1], mid, right]),
            (x0, y0 + h, [left, mid, c[2], bottom]),
            (x0 + h, y0 + h, [mid, right, bottom, c[3]]),
        ];
        let mut sum = Vec3::ZERO;
        for (qx, qy, qc) in quads {
            sum += self.subdivide(qx, qy, h, qc, levels - 1, threshold, fine, cache, count);
        }
        sum * 0.25
    }
}

/// Renders `scene` by Whitted ray tracing. See [`render_with_stats`].
pub fn render(scene: &Scene, settings: &RenderSettings, progress: &dyn Progress) -> Result<Film> {
    render_with_stats(scene, settings, progress).map(|(film, _)| film)
}

/// Renders `scene` by Whitted ray tracing with `settings` (image size,
/// samples, `aa`, `shadows`, `light_samples`, `whitted.*`, `seed`,
/// `depth_cue`) and returns the film with the number of rays traced.
///
/// Errors: a zero image size ([`CoreError::BadSetting`]), `aa = post`
/// ([`CoreError::Unsupported`]), cancellation ([`CoreError::Cancelled`]).
pub fn render_with_stats(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats)> {
    progress.begin("prepare", 1);
    let tracer = Tracer::new(scene, settings);
    progress.advance(1);
    tracer.render(progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::geometry::primitives;
    use chiaro_core::progress::{CountingProgress, NoProgress};
    use chiaro_core::scene::{
        AreaShape, Attenuation, Geometry, Light, Material, MaterialId, Mesh, Object, Transform,
    };
    use chiaro_core::shading::{fresnel_dielectric, refract};

    fn lambert(kd: f32) -> Material {
        Material {
            diffuse: Vec3::splat(kd),
            ..Material::default()
        }
    }

    fn glass(ior: f32, fresnel: bool) -> Material {
        Material {
            diffuse: Vec3::ZERO,
            specular: Vec3::ZERO,
            transmit: Vec3::ONE,
            reflect: Vec3::ZERO,
            ior,
            fresnel,
            ..Material::default()
        }
    }

    fn add(s: &mut Scene, mesh: Mesh, m: MaterialId, translate: Vec3) {
        let id = s.add_mesh(mesh);
        s.objects.push(Object {
            geometry: Geometry::Mesh(id),
            material: m,
            smooth: false,
            transform: Transform {
                translate,
                ..Default::default()
            },
            ..Default::default()
        });
    }

    fn add_sphere(s: &mut Scene, c: Vec3, r: f32, m: MaterialId) {
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: r },
            material: m,
            transform: Transform {
                translate: c,
                ..Default::default()
            },
            ..Default::default()
        });
    }

    fn settings(w: u32, h: u32) -> RenderSettings {
        RenderSettings {
            width: w,
            height: h,
            samples: 1,
            ..RenderSettings::default()
        }
    }

    #[test]
    fn an_emissive_mesh_costs_light_samples_shadow_rays_per_point() {
        // 3,200 emissive triangles (a two-sided panel above the floor) and
        // light_samples = 4: at most 4 shadow rays per camera hit, not one
        // per triangle and sample.
        let mut s = floor_scene();
        s.lights.clear();
        let panel = s.add_material(Material {
            emission: Vec3::splat(2.0),
            two_sided: true,
            ..lambert(0.5)
        });
        add(
            &mut s,
            primitives::plane(1.0, 40),
            panel,
            Vec3::new(0.0, 2.0, 0.0),
        );
        let mut st = settings(40, 30);
        st.light_samples = 4;
        st.whitted.max_depth = 0;
        let (film, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
        assert_eq!(stats.primary_rays, 40 * 30);
        let shadow_rays = stats.rays - stats.primary_rays;
        assert!(shadow_rays > 0);
        assert!(
            shadow_rays <= 4 * stats.primary_rays,
            "{shadow_rays} shadow rays for {} camera rays",
            stats.primary_rays
        );
        // The floor is lit by the panel, and no pixel is NaN.
        assert!(film.color.iter().all(|c| c.is_finite()));
        let lit = film.color.iter().filter(|c| c.x > 0.05).count();
        assert!(lit > 40 * 30 / 4, "{lit} lit pixels");
    }

    /// A floor (y = 0, kd 0.5) lit by a point light at (0, 4, 0) of
    /// intensity 16 (inverse square) and an ambient light of 1.
    fn floor_scene() -> Scene {
        let mut s = Scene::default();
        let floor = s.add_material(lambert(0.5));
        add(&mut s, primitives::plane(20.0, 1), floor, Vec3::ZERO);
        s.lights.push(Light::Ambient {
            color: Vec3::ONE,
            intensity: 1.0,
        });
        s.lights.push(Light::Point {
            position: Vec3::new(0.0, 4.0, 0.0),
            color: Vec3::ONE,
            intensity: 16.0,
            attenuation: Attenuation::InverseSquare,
        });
        s.background = Vec3::new(0.1, 0.2, 0.3);
        s.camera.eye = Vec3::new(0.0, 3.0, 6.0);
        s.camera.look_at = Vec3::ZERO;
        s
    }

    /// The radiance seen along a ray from `from` towards `to`.
    fn look(t: &Tracer<'_>, from: Vec3, to: Vec3) -> Vec3 {
        let mut st = TraceState::new(pixel_rng(0, 0, 0, 0));
        t.trace(&Ray::new(from, to - from), 0, Vec3::ONE, &mut st)
    }

    fn max_diff(a: &Film, b: &Film) -> f32 {
        a.color
            .iter()
            .zip(&b.color)
            .map(|(x, y)| (*x - *y).abs().max_element())
            .fold(0.0, f32::max)
    }

    #[test]
    fn snell_tir_and_fresnel_closed_forms() {
        // Snell: n1 sin(theta_i) = n2 sin(theta_t) at known angles.
        for (n1, n2) in [(1.0f32, 1.5f32), (1.0, 1.33), (1.5, 1.0), (2.4, 1.0)] {
            let crit = if n1 > n2 { (n2 / n1).asin() } else { 10.0 };
            for deg in [0.0f32, 15.0, 30.0, 45.0, 60.0, 80.0] {
                let th = deg.to_radians();
                let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
                match refract(wo, Vec3::Y, n1 / n2) {
                    Some(wt) => {
                        assert!(th < crit);
                        let sin_t = wt.x;
                        assert!(
                            (n1 * th.sin() - n2 * sin_t).abs() < 1e-5,
                            "{n1}->{n2} at {deg}"
                        );
                        assert!(wt.y < 0.0);
                        // Fresnel: R + T = 1 with T from the transmission
                        // amplitudes (Hecht, Optics, eqs. 4.43-4.44, 4.62).
                        let (ci, ct) = (th.cos(), (-wt.y));
                        let ts = 2.0 * n1 * ci / (n1 * ci + n2 * ct);
                        let tp = 2.0 * n1 * ci / (n2 * ci + n1 * ct);
                        let t = (n2 * ct) / (n1 * ci) * 0.5 * (ts * ts + tp * tp);
                        let r = fresnel_dielectric(ci, n1, n2);
                        assert!((r + t - 1.0).abs() < 1e-5, "R {r} + T {t}");
                    }
                    None => assert!(th > crit, "{n1}->{n2}: TIR at {deg} below critical"),
                }
            }
            // Normal incidence: ((n1 - n2) / (n1 + n2))^2.
            let r0 = ((n1 - n2) / (n1 + n2)).powi(2);
            assert!((fresnel_dielectric(1.0, n1, n2) - r0).abs() < 1e-6);
            // TIR exactly past asin(n2 / n1).
            if n1 > n2 {
                let dir = |a: f32| Vec3::new(-a.sin(), a.cos(), 0.0);
                assert!(refract(dir(crit - 1e-4), Vec3::Y, n1 / n2).is_some());
                assert!(refract(dir(crit + 1e-4), Vec3::Y, n1 / n2).is_none());
                assert_eq!(fresnel_dielectric((crit + 1e-4).cos(), n1, n2), 1.0);
                assert!(fresnel_dielectric((crit - 1e-4).cos(), n1, n2) < 1.0);
            }
        }
    }

    #[test]
    fn total_internal_reflection_reflects_everything() {
        let m = SurfaceMaterial::from_material(&Material {
            reflect: Vec3::splat(0.1),
            ..glass(1.5, false)
        });
        let th = 60f32.to_radians(); // past the critical angle 41.8 degrees
        let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
        let r = specular_rays(&m, false, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
        assert!(r.refracted.is_none());
        assert!((r.reflected.1 - Vec3::splat(1.1)).abs().max_element() < 1e-6);
        let rf = specular_rays(&m, true, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
        assert!(rf.refracted.is_none());
        assert!((rf.reflected.1 - Vec3::ONE).abs().max_element() < 1e-6);
        // Below the critical angle both rays exist and a Fresnel glass splits
        // F / (1 - F).
        let th = 20f32.to_radians();
        let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
        let r = specular_rays(&m, true, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
        let (_, wt) = r.refracted.expect("no TIR at 20 degrees");
        assert!((r.reflected.1.x + wt.x - 1.0).abs() < 1e-6);
    }

    #[test]
    fn slab_exit_is_parallel_with_closed_form_shift() {
        let mut s = Scene::default();
        let g = s.add_material(glass(1.5, true));
        add(
            &mut s,
            primitives::box_mesh(Vec3::new(10.0, 0.5, 10.0)),
            g,
            Vec3::ZERO,
        );
        let t = Tracer::new(&s, &settings(8, 8));
        for deg in [0.0f32, 20.0, 45.0, 70.0, 85.0] {
            let th = deg.to_radians();
            let d_in = Vec3::new(th.sin(), -th.cos(), 0.0);
            let mut ray = Ray::new(Vec3::new(0.0, 0.5, 0.0) - 2.0 * d_in, d_in);
            let mut points = Vec::new();
            for _ in 0..2 {
                let hit = t.accel.intersect(&ray).expect("slab face");
                let sh = t.prepared.surface(&ray, &hit);
                let wo = -ray.dir.normalize();
                let front = sh.ng.dot(wo) >= 0.0;
                let (n, ng) = if front {
                    (sh.ns, sh.ng)
                } else {
                    (-sh.ns, -sh.ng)
                };
                let m = t.prepared.surface_material(&sh);
                let sr = specular_rays(&m, true, sh.p, n, ng, wo, front);
                ray = sr.refracted.expect("no TIR in a slab").0;
                points.push(sh.p);
            }
            assert!(
                (ray.dir.normalize() - d_in).length() < 1e-5,
                "{deg}: exits along {} not {d_in}",
                ray.dir
            );
            // Inside, the ray runs at theta_t = asin(sin(theta) / 1.5):
            // the exit is tan(theta_t) * thickness further along x.
            let th_t = (th.sin() / 1.5).asin();
            assert!((points[1].y + 0.5).abs() < 1e-5);
            assert!(
                (points[1].x - points[0].x - th_t.tan()).abs() < 1e-4,
                "{deg}: shift {}",
                points[1].x - points[0].x
            );
        }
    }

    #[test]
    fn beer_absorption_through_slab() {
        let mut s = Scene {
            background: Vec3::new(1.0, 0.5, 0.25),
            ..Scene::default()
        };
        let g = s.add_material(Material {
            absorption: Vec3::new(0.5, 1.0, 0.0),
            ..glass(1.5, false)
        });
        add(
            &mut s,
            primitives::box_mesh(Vec3::new(10.0, 0.75, 10.0)),
            g,
            Vec3::ZERO,
        );
        let t = Tracer::new(&s, &settings(8, 8));
        let c = look(&t, Vec3::new(0.0, 3.0, 0.0), Vec3::ZERO);
        let expect = s.background * (-Vec3::new(0.5, 1.0, 0.0) * 1.5).exp();
        assert!((c - expect).abs().max_element() < 1e-4, "{c} vs {expect}");
    }

    #[test]
    fn local_shading_with_and_without_shadow_rays() {
        let mut s = floor_scene();
        let black = s.add_material(lambert(0.0));
        add_sphere(&mut s, Vec3::new(0.0, 2.0, 0.0), 0.5, black);
        // Looking at the origin from the side, under the occluder.
        let from = Vec3::new(3.0, 1.0, 0.0);
        let ambient = 0.1 * 0.5; // Ia ka kd
        let lit = 0.5 * 16.0 / 16.0; // kd Ip / d^2, normal incidence
        let t = Tracer::new(&s, &settings(8, 8));
        let c = look(&t, from, Vec3::ZERO);
        assert!((c.x - ambient).abs() < 1e-5, "shadowed: {c}");
        let none = RenderSettings {
            shadows: ShadowMethod::None,
            ..settings(8, 8)
        };
        let t = Tracer::new(&s, &none);
        let c = look(&t, from, Vec3::ZERO);
        assert!((c.x - ambient - lit).abs() < 1e-4, "unshadowed: {c}");
        // The same through the public visibility query.
        let sample = LightSample {
            wi: Vec3::Y,
            distance: 4.0,
            point: Vec3::new(0.0, 4.0, 0.0),
            intensity: Vec3::ONE,
            is_delta: true,
        };
        assert_eq!(t.light_visibility(Vec3::ZERO, Vec3::Y, &sample), Vec3::ONE);
        let t = Tracer::new(&s, &settings(8, 8));
        assert_eq!(t.light_visibility(Vec3::ZERO, Vec3::Y, &sample), Vec3::ZERO);
    }

    #[test]
    fn shadow_rays_are_tinted_by_transparent_surfaces() {
        let mut s = floor_scene();
        let filter = s.add_material(Material {
            transmit: Vec3::new(0.5, 0.25, 1.0),
            ..glass(1.0, false)
        });
        // A thin filter quad between the light and the floor (one crossing).
        add(
            &mut s,
            primitives::quad(
                Vec3::new(-1.0, 2.0, 1.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, -2.0),
            ),
            filter,
            Vec3::ZERO,
        );
        let t = Tracer::new(&s, &settings(8, 8));
        let sample = LightSample {
            wi: Vec3::Y,
            distance: 4.0,
            point: Vec3::new(0.0, 4.0, 0.0),
            intensity: Vec3::ONE,
            is_delta: true,
        };
        let v = t.light_visibility(Vec3::ZERO, Vec3::Y, &sample);
        assert!(
            (v - Vec3::new(0.5, 0.25, 1.0)).abs().max_element() < 1e-6,
            "{v}"
        );
    }

    #[test]
    fn two_level_bvh_renders_like_the_flat_bvh() {
        use chiaro_core::accel::bvh::SceneBvh;
        use chiaro_core::accel::instanced::{
            InstancedBvh, MIN_DUPLICATED_TRIANGLES, duplicated_triangles,
        };
        let mut s = floor_scene();
        let opaque = s.add_material(lambert(0.7));
        let tinted = s.add_material(Material {
            transmit: Vec3::new(0.6, 0.4, 0.8),
            ..glass(1.0, false)
        });
        // Eight placements of one 5120-triangle sphere, half of them
        // transparent filters (their shadow rays visit every hit).
        let ball = s.add_mesh(primitives::icosphere(0.45, 4));
        for i in 0..8 {
            s.objects.push(Object {
                geometry: Geometry::Mesh(ball),
                material: if i % 2 == 0 { opaque } else { tinted },
                smooth: true,
                transform: Transform {
                    translate: Vec3::new(i as f32 - 3.5, 0.6 + 0.3 * (i % 3) as f32, -0.5),
                    scale: Vec3::new(1.0, 1.0 + 0.1 * i as f32, 1.0),
                    ..Default::default()
                },
                ..Default::default()
            });
        }
        let mut st = settings(48, 32);
        st.light_samples = 1;
        let flat_tracer = Tracer::new(&s, &st);
        assert!(duplicated_triangles(&flat_tracer.prepared) >= MIN_DUPLICATED_TRIANGLES);
        let flat = SceneBvh::new(&flat_tracer.prepared);
        let flat_tracer = flat_tracer.with_accelerator(Box::new(flat));
        let two_level_tracer = Tracer::new(&s, &st);
        let two_level = InstancedBvh::new(&two_level_tracer.prepared);
        assert_eq!(two_level.instance_count(), 8 + 1);
        let two_level_tracer = two_level_tracer.with_accelerator(Box::new(two_level));
        let (a, _) = flat_tracer.render(&NoProgress).expect("flat render");
        let (b, _) = two_level_tracer
            .render(&NoProgress)
            .expect("two-level render");
        // Tinted shadows and tinted views through the filters are present.
        let tinted_px = a
            .color
            .iter()
            .filter(|c| (c.x - c.y).abs() > 0.02 && c.z > c.y)
            .count();
        assert!(tinted_px > 20, "{tinted_px} tinted pixels");
        // Object-space rounding may move a silhouette or a shadow edge by a
        // pixel; everything else is the same up to float noise.
        let differ = a
            .color
            .iter()
            .zip(&b.color)
            .filter(|(x, y)| (**x - **y).abs().max_element() > 1e-3)
            .count();
        assert!(differ * 100 <= a.color.len(), "{differ} pixels differ");
    }

    #[test]
    fn soft_shadow_has_umbra_and_penumbra() {
        let mut s = floor_scene();
        s.lights.truncate(1);
        s.lights.push(Light::Area {
            shape: AreaShape::Quad {
                corner: Vec3::new(-0.5, 4.0, -0.5),
                edge_u: Vec3::new(1.0, 0.0, 0.0),
                edge_v: Vec3::new(0.0, 0.0, 1.0),
            },
            color: Vec3::ONE,
            intensity: 10.0,
            two_sided: false,
        });
        let black = s.add_material(lambert(0.0));
        add_sphere(&mut s, Vec3::new(0.0, 2.0, 0.0), 0.5, black);
        let mut st = settings(8, 8);
        st.light_samples = 64;
        let t = Tracer::new(&s, &st);
        let mut open = s.clone();
        open.objects.pop();
        let t_open = Tracer::new(&open, &st);
        let ambient = 0.05;
        let (mut umbra, mut penumbra, mut lit) = (false, false, false);
        for i in 0..=40 {
            let x = i as f32 * 0.05;
            let p = Vec3::new(x, 0.0, 0.0);
            let from = Vec3::new(x, 0.6, 5.0);
            let c = look(&t, from, p).x;
            let full = look(&t_open, from, p).x;
            assert!(c <= full + 1e-5 && c >= ambient - 1e-5);
            let f = (c - ambient) / (full - ambient);
            umbra |= f < 1e-6;
            penumbra |= f > 0.2 && f < 0.8;
            lit |= f > 1.0 - 1e-6;
        }
        assert!(umbra && penumbra && lit, "{umbra} {penumbra} {lit}");
    }

    #[test]
    fn mirror_reflects_kr_of_what_it_sees_up_to_the_depth_limit() {
        let mut s = Scene {
            background: Vec3::new(0.2, 0.4, 0.8),
            ..Scene::default()
        };
        let mirror = s.add_material(Material {
            diffuse: Vec3::ZERO,
            reflect: Vec3::splat(0.75),
            ..Material::default()
        });
        add(&mut s, primitives::plane(5.0, 1), mirror, Vec3::ZERO);
        {
            let t = Tracer::new(&s, &settings(8, 8));
            let c = look(&t, Vec3::new(1.0, 2.0, 0.0), Vec3::ZERO);
            assert!((c - 0.75 * s.background).abs().max_element() < 1e-6, "{c}");
            let mut st = settings(8, 8);
            st.whitted.max_depth = 0;
            let t = Tracer::new(&s, &st);
            assert_eq!(look(&t, Vec3::new(1.0, 2.0, 0.0), Vec3::ZERO), Vec3::ZERO);
        }
        // Two facing mirrors: the weight cutoff ends the recursion.
        let mut st = settings(8, 8);
        st.whitted.max_depth = 1000;
        st.whitted.min_weight = 0.01;
        add(
            &mut s,
            primitives::quad(
                Vec3::new(-5.0, 1.0, -5.0),
                Vec3::new(0.0, 0.0, 10.0),
                Vec3::new(10.0, 0.0, 0.0),
            ),
            mirror,
            Vec3::ZERO,
        );
        let t = Tracer::new(&s, &st);
        let mut state = TraceState::new(pixel_rng(0, 0, 0, 0));
        let ray = Ray::new(Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.01, -1.0, 0.0));
        let c = t.trace(&ray, 0, Vec3::ONE, &mut state);
        // 0.75^k >= 0.01 for k <= 16: 17 rays in all.
        assert_eq!(state.rays, 17);
        assert!(c.is_finite());
    }

    #[test]
    fn glass_sphere_of_ior_one_is_invisible() {
        let mut s = floor_scene();
        let st = settings(32, 24);
        let without = render(&s, &st, &NoProgress).expect("render");
        let g = s.add_material(glass(1.0, true));
        add_sphere(&mut s, Vec3::new(0.3, 1.0, 0.5), 0.8, g);
        let (with, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
        assert!(
            max_diff(&with, &without) < 1e-4,
            "{}",
            max_diff(&with, &without)
        );
        assert!(stats.rays > stats.primary_rays);
        // ... and a real glass sphere is visible.
        s.materials[g.index()].ior = 1.5;
        let real = render(&s, &st, &NoProgress).expect("render");
        assert!(max_diff(&real, &without) > 0.05);
    }

    #[test]
    fn render_is_clean_and_independent_of_thread_count() {
        let mut s = floor_scene();
        s.lights.push(Light::Area {
            shape: AreaShape::Quad {
                corner: Vec3::new(-1.0, 3.0, -1.0),
                edge_u: Vec3::new(2.0, 0.0, 0.0),
                edge_v: Vec3::new(0.0, 0.0, 2.0),
            },
            color: Vec3::ONE,
            intensity: 2.0,
            two_sided: false,
        });
        let g = s.add_material(Material {
            specular: Vec3::splat(0.5),
            absorption: Vec3::splat(0.3),
            ..glass(1.5, true)
        });
        let m = s.add_material(Material {
            reflect: Vec3::splat(0.5),
            ..lambert(0.2)
        });
        add_sphere(&mut s, Vec3::new(-0.6, 0.7, 0.0), 0.7, g);
        add_sphere(&mut s, Vec3::new(0.9, 0.5, -0.5), 0.5, m);
        for aa in [AaMode::Supersample, AaMode::Adaptive] {
            let st = RenderSettings {
                samples: 3,
                light_samples: 4,
                aa,
                ..settings(24, 20)
            };
            let (a, sa) = render_with_stats(&s, &st, &NoProgress).expect("render");
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("pool");
            let (b, sb) = pool
                .install(|| render_with_stats(&s, &st, &NoProgress))
                .expect("render");
            assert_eq!(a, b, "{aa:?}");
            assert_eq!(sa, sb);
            assert!(a.is_clean());
            assert!(a.depth.iter().any(|d| d.is_finite()));
        }
    }

    #[test]
    fn adaptive_sampling_refines_only_where_corners_differ() {
        // Nothing but background: exactly one ray per pixel corner of each
        // tile (tiles trace their own border corners).
        let s = Scene::default();
        let st = RenderSettings {
            aa: AaMode::Adaptive,
            ..settings(20, 10)
        };
        let (_, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
        let corners: u64 = chiaro_core::film::tiles(20, 10, TILE)
            .iter()
            .map(|r| u64::from((r.width + 1) * (r.height + 1)))
            .sum();
        assert_eq!(stats.primary_rays, corners);
        // An edge: more rays, and intermediate values along it.
        let mut s = floor_scene();
        s.camera.eye = Vec3::new(0.0, 0.2, 6.0);
        let (f, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
        assert!(stats.primary_rays > 21 * 11);
        let bg = s.background;
        let column: Vec<Vec3> = (0..10).map(|y| f.get(10, y)).collect();
        assert!(column.iter().any(|c| (*c - bg).abs().max_element() < 1e-6));
        assert!(column.iter().any(|c| (*c - bg).abs().max_element() > 1e-3));
    }

    #[test]
    fn crop_window_matches_the_full_render() {
        let mut s = floor_scene();
        let g = s.add_material(glass(1.5, true));
        add_sphere(&mut s, Vec3::new(0.0, 1.0, 0.0), 0.8, g);
        for aa in [AaMode::Supersample, AaMode::Adaptive] {
            let full_s = RenderSettings {
                aa,
                samples: 2,
                ..settings(40, 30)
            };
            let crop_s = RenderSettings {
                crop: Some([7, 5, 29, 23]),
                ..full_s.clone()
            };
            let full = render(&s, &full_s, &NoProgress).expect("render");
            let crop = render(&s, &crop_s, &NoProgress).expect("render");
            for y in 5..23 {
                for x in 7..29 {
                    assert_eq!(full.get(x, y), crop.get(x, y), "{aa:?} at {x},{y}");
                }
            }
            assert_eq!(crop.get(0, 0), Vec3::ZERO);
        }
    }

    #[test]
    fn errors_and_cancellation() {
        let s = floor_scene();
        assert!(matches!(
            render(&s, &settings(0, 4), &NoProgress),
            Err(CoreError::BadSetting { .. })
        ));
        let post = RenderSettings {
            aa: AaMode::Post,
            ..settings(4, 4)
        };
        assert!(matches!(
            render(&s, &post, &NoProgress),
            Err(CoreError::Unsupported(_))
        ));
        let p = CountingProgress::default();
        p.cancel.store(true, Ordering::Relaxed);
        assert!(matches!(
            render(&s, &settings(4, 4), &p),
            Err(CoreError::Cancelled)
        ));
    }

    #[test]
    fn indirect_hook_replaces_the_ambient_term() {
        let s = floor_scene();
        let st = RenderSettings {
            shadows: ShadowMethod::None,
            ..settings(8, 8)
        };
        let from = Vec3::new(3.0, 1.0, 0.0);
        let plain = look(&Tracer::new(&s, &st), from, Vec3::ZERO);
        let t = Tracer::new(&s, &st).with_indirect(|_| Vec3::new(0.2, 0.0, 0.0));
        let hooked = look(&t, from, Vec3::ZERO);
        // Ambient 0.1 * 0.5 removed, kd * 0.2 = 0.1 added (red only).
        assert!((hooked.x - (plain.x - 0.05 + 0.1)).abs() < 1e-5);
        assert!((hooked.y - (plain.y - 0.05)).abs() < 1e-5);
    }
}
