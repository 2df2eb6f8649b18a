//! Whitted recursive ray tracing (Whitted 1980, "An Improved Illumination
//! Model for Shaded Display"; Foley et al. section 16.12).
//!
//! At each hit the one local illumination function
//! ([`chiaro_core::shading::shade_local`]) gives the emitted, ambient and
//! direct light, with each light sample's visibility decided by a shadow
//! ray; shadow rays pass through transparent surfaces, tinted by their
//! transmit colour `kt`; under an environment map the map's diffuse light
//! and its prefiltered reflection by the glossy lobe are added
//! (`texture::environment_diffuse` and `environment_specular`, as the scan
//! converter does). Then
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
use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::Result;
use chiaro_core::film::{Film, TilePixels, TileRect, render_tiles};
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::prepared::{PreparedScene, RayDifferentials, SurfaceHit};
use chiaro_core::sampling::{Rng, pixel_rng, uniform, uniform2};
use chiaro_core::scene::{AaMode, Facing, PixelRays, RenderSettings, ShadowMethod, Technique};
use chiaro_core::shading::texture::{environment_diffuse, environment_specular, miss_radiance};
use chiaro_core::shading::{
    EmitterGroup, LightSample, LocalLighting, SampleKey, SampleShare, ShadingPoint,
    SurfaceMaterial, delta_split, depth_cue, group_jitter, sanitize, shade_local,
};
use chiaro_core::shadow::ShadowCasters;
use chiaro_core::technique::{
    COAT_REFLECTS_ENVIRONMENT, Description, ENVIRONMENT_UNOCCLUDED, Feature, ROUGH_AS_SMOOTH,
};
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

/// Tile side in pixels.
const TILE: u32 = 16;
/// Deepest adaptive subdivision accepted (2^8 x 2^8 corners per pixel).
const MAX_ADAPTIVE_DEPTH: u32 = 8;
/// Salt separating adaptive corner seeds from supersampling seeds.
const ADAPTIVE_SALT: u64 = 0xAD47_1BE5_0000_0001;

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
    /// Which of its pixel's samples this is: each takes its share of every
    /// area light's samples, so supersampling does not multiply them.
    pub share: SampleShare,
}

impl TraceState {
    /// A state with a fresh generator and a zero count.
    pub fn new(rng: Rng) -> Self {
        Self {
            rng,
            rays: 0,
            pixel: None,
            share: SampleShare::WHOLE,
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

/// The Whitted ray tracing technique, as the technique interface's
/// [`Renderer`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Whitted;

impl Renderer for Whitted {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)> {
        let progress = ctx.progress();
        progress.begin("prepare", 1);
        let tracer = Tracer::new(ctx);
        progress.advance(1);
        tracer.render(ctx)
    }

    fn descriptions(&self) -> &'static [Description] {
        std::slice::from_ref(&DESCRIPTION)
    }
}

/// The Whitted technique, described.
pub const DESCRIPTION: Description = Description {
    technique: Technique::Whitted,
    title: "Whitted",
    method: "recursive ray tracing: shadow rays, mirror reflection, refraction with total internal reflection, soft shadows from area lights, adaptive anti-aliasing",
    shows: "direct light with shadow rays (soft from area lights), highlights, mirror reflection, refraction, textures and normal maps; ambient light for the rest",
    cannot_show: &[
        (Feature::EnvironmentLight, ENVIRONMENT_UNOCCLUDED),
        (Feature::RoughTransmission, ROUGH_AS_SMOOTH),
        (Feature::ClearCoat, COAT_REFLECTS_ENVIRONMENT),
    ],
};

/// The Whitted ray tracer over one prepared scene: the context's flattened
/// scene and accelerator, the settings, and optionally an indirect-diffuse
/// lookup.
pub struct Tracer<'s> {
    /// The flattened scene (analytic spheres kept).
    pub prepared: &'s PreparedScene<'s>,
    /// The accelerator over `prepared`.
    pub accel: &'s dyn Accelerator,
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
    /// The camera's rays at the settings' image size.
    pixel_rays: PixelRays,
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
    /// A tracer over the context's analytic prepared scene and its
    /// accelerator (built on first use), with the context's settings.
    pub fn new<'a: 's>(ctx: &'s RenderContext<'a>) -> Self {
        let prepared: &'s PreparedScene<'s> = ctx.analytic();
        let accel = ctx.analytic_accel();
        let settings = ctx.settings();
        let casters = ShadowCasters::new(prepared);
        let emitters = EmitterGroup::for_render(prepared, settings);
        // The prefiltered environment is built here, before the parallel
        // tiles, so that the workers do not each build it at their first hit.
        prepared.prefiltered_environment();
        Self {
            prepared,
            accel,
            settings: settings.clone(),
            indirect: None,
            casters,
            emitters,
            centre_light_samples: settings.aa != AaMode::Adaptive && settings.samples <= 1,
            pixel_rays: ctx
                .camera()
                .pixel_rays(settings.width.max(1), settings.height.max(1)),
        }
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
            .light_transmittance(self.accel, p, ng, sample, rays)
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
        // The sidedness rule: a back is shaded on the side the ray arrives
        // from, or reflects nothing on a one-sided surface.
        let facing = ss.facing(wo);
        let (n, ng) = if facing == Facing::Back {
            (-ss.ns, -sh.ng)
        } else {
            (ss.ns, sh.ng)
        };
        if facing == Facing::BackBlack {
            sm = sm.without_reflection();
        }
        if !front && !material.emission_two_sided {
            // One-sided emitters emit from their front only.
            sm.emission = Vec3::ZERO;
        }
        let sp = ShadingPoint { p: sh.p, n, ng, wo };
        // The environment's diffuse light and its reflection by the glossy
        // lobe (the split sum), in place of the specular lobe's ambient
        // stand-in.
        let prefiltered = self.prepared.prefiltered_environment();
        let sm = sm.under_environment(prefiltered.is_some());
        // Local illumination through the one shading function; the tracer
        // supplies only the visibility of each light sample.
        let lighting = LocalLighting {
            lights: &self.prepared.lights,
            area_samples: self.settings.light_samples.max(1),
            ambient: self.indirect.is_none(),
            group: self.emitters.as_ref(),
            share: state.share,
        };
        let TraceState {
            rng, rays, pixel, ..
        } = state;
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
        if let Some(table) = prefiltered {
            color += environment_diffuse(table, sm.kd, n)
                + environment_specular(table, self.prepared.scene, &sm, n, wo);
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
    /// the top-left corner) with the generator `rng`, as its pixel's
    /// sample `share`.
    pub fn trace_camera(
        &self,
        film: Vec2,
        rng: Rng,
        share: SampleShare,
        rays: &mut u64,
    ) -> PrimarySample {
        let scene = self.prepared.scene;
        let pr = &self.pixel_rays;
        let ray = pr.ray(film.x, film.y);
        // The rays through the neighbouring pixels, for texture filtering.
        let differentials = (!scene.textures.is_empty()).then(|| RayDifferentials {
            origin_dx: pr.origin(film.x + 1.0, film.y),
            origin_dy: pr.origin(film.x, film.y + 1.0),
            dir_dx: pr.direction(film.x + 1.0, film.y),
            dir_dy: pr.direction(film.x, film.y + 1.0),
        });
        let mut state = TraceState::new(rng);
        state.share = share;
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
    /// black) with the tracer's settings, tiles in parallel, reporting to
    /// `ctx`, the context the tracer was made from. Returns the film
    /// (colour, plus depth and normal of the first sample of each pixel, or
    /// of its top-left corner for adaptive sampling) and the statistics,
    /// with every ray and the camera rays counted.
    pub fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)> {
        let (s, progress) = (&self.settings, ctx.progress());
        let rays = AtomicU64::new(0);
        let primary = AtomicU64::new(0);
        // Tiles are cut to the crop window; every pixel depends only on its
        // own position, so a cropped render equals the full one inside it.
        let film = render_tiles(
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
        let mut stats = ctx.stats(rays.into_inner());
        stats.camera_rays = primary.into_inner();
        Ok((film, stats))
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
                    let share = SampleShare::new(k, n);
                    let ps = self.trace_camera(film, rng, share, &mut count.0);
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
    /// exactly; within a tile each is traced once (a corner on the edge
    /// between two subdivided pixels serves both), across tiles twice.
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
        // Subdivision corners traced so far in this tile.
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
        // Corners are shared between pixels: each takes every light sample.
        self.trace_camera(film, rng, SampleShare::WHOLE, &mut count.0)
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

#[cfg(test)]
mod tests;
