//! The path-traced reference: an unbiased estimator of the rendering
//! equation that every other technique is measured against.
//!
//! - Next-event estimation at every vertex (one light chosen by power),
//!   combined with BSDF sampling by multiple importance sampling (power
//!   heuristic, Veach 1997) for emissive triangles and the environment
//!   map (one more light, sampled by its luminance through
//!   `texture::EnvironmentLight`); delta lights (point, spot, directional)
//!   and `Light::Area` quads, disks and spheres (not geometry) by
//!   next-event estimation only, with weight 1.
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
//! - Camera rays pass through film positions drawn from the reconstruction
//!   filter (`settings.filter`, filter importance sampling restricted to
//!   the film; the box filter is the uniform jitter inside the pixel).
//!
//! - Paths are traced sixteen samples of a pixel at a time by the lock-step
//!   kernel in `path/lanes.rs` (vectorised where the vertices are
//!   Lambertian, bit-identical to the scalar loop in
//!   `path/integrator.rs`, kept as [`Kernel::Scalar`]); next-event
//!   estimation and light selection are in `path/lights.rs`.
//!
//! Conventions: ambient lights are ignored (indirect light is computed);
//! `Scene::background` is what camera rays (and chains of mirror/glass
//! bounces) see where nothing is hit, but it does not light the scene;
//! an environment map, when present, does light it (found by next-event
//! estimation and by BSDF sampling, combined by MIS).
//! `Light::Area` lights are not geometry: they are reached by next-event
//! estimation only and are invisible to the camera; emissive triangles are
//! geometry and lights both.

use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::Result;
use chiaro_core::film::{Film, TilePixels, render_tiles};
use chiaro_core::sampling::{SobolSampler, pixel_rng, uniform2};
use chiaro_core::scene::Technique;
use chiaro_core::shading::sanitize;
use chiaro_core::technique::{Description, Feature};
use glam::{Vec2, Vec3};
use std::sync::atomic::{AtomicU64, Ordering};

#[cfg(test)]
mod blend_tests;
mod integrator;
mod lanes;
mod lights;
mod reference;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod texture_tests;

use integrator::{MAX_PASSES, MaterialInfo, PathState, PathTracer};
use lights::NO_LIGHT;

use chiaro_core::sampling::sobol::LANES;

/// Tile side in pixels.
const TILE: u32 = 16;

/// The path tracer, as the technique interface's [`Renderer`]: the film
/// holds the mean radiance of `settings.samples` paths per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PathTracing {
    /// The loop that traces the paths.
    pub kernel: Kernel,
}

impl PathTracing {
    /// The lock-step kernel: what every front renders with.
    pub const LANES: Self = Self {
        kernel: Kernel::Lanes,
    };
}

impl Default for PathTracing {
    fn default() -> Self {
        Self::LANES
    }
}

impl Renderer for PathTracing {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)> {
        let (film, rays) = render_impl(ctx, self.kernel, true)?;
        Ok((film, ctx.stats(rays)))
    }

    fn descriptions(&self) -> &'static [Description] {
        std::slice::from_ref(&DESCRIPTION)
    }
}

/// The path technique, described.
pub const DESCRIPTION: Description = Description {
    technique: Technique::Path,
    title: "path",
    method: "unbiased path tracing with next-event estimation and MIS, Owen-scrambled Sobol samples: the reference",
    shows: "all light transport: interreflection, soft shadows, glossy and mirror reflection, refraction, caustics (slowly), environment light",
    cannot_show: &[
        (
            Feature::AmbientLight,
            "ambient lights: interreflection is computed instead",
        ),
        (Feature::DepthCue, "depth cueing"),
    ],
};

/// The path tracer over `make_accel`'s accelerator with `kernel`, from a
/// scene: how the crate's tests drive it.
#[cfg(test)]
fn render_with_kernel(
    scene: &chiaro_core::scene::Scene,
    settings: &chiaro_core::scene::RenderSettings,
    progress: &dyn chiaro_core::progress::Progress,
    make_accel: &chiaro_core::context::AccelBuilder<'_>,
    kernel: Kernel,
) -> Result<(Film, u64)> {
    let ctx = RenderContext::new(scene, settings, progress)?.with_accelerator(make_accel);
    render_impl(&ctx, kernel, true)
}

/// Which loop traces the paths. `Lanes` and `Scalar` compute the same
/// image, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// The lock-step kernel (`path/lanes.rs`): a pixel's samples sixteen
    /// at a time, vectorised where their vertices are Lambertian (a scene
    /// with BLEND surfaces runs the scalar loop).
    Lanes,
    /// One path at a time.
    Scalar,
    /// The plain reference tracer (`path/reference.rs`): one path at a
    /// time on the BSDF layer with independent PCG numbers. Agrees with
    /// the others statistically, not bit for bit.
    Reference,
}

/// Renders `ctx` with `kernel`, the environment map sampled by next-event
/// estimation (`env_sampling`) or reached by BSDF sampling alone (the
/// tests' baseline for its variance). Returns the film and the rays traced.
fn render_impl(ctx: &RenderContext<'_>, kernel: Kernel, env_sampling: bool) -> Result<(Film, u64)> {
    let (settings, progress) = (ctx.settings(), ctx.progress());
    progress.begin("prepare", 1);
    let prepared = ctx.analytic();
    let accel = ctx.analytic_accel();
    let tracer = PathTracer::new(prepared, accel, settings, env_sampling);
    // Scenes with BLEND surfaces take the scalar loop: the lanes' shadow
    // rays know only opaque casters.
    let lanes = kernel == Kernel::Lanes && tracer.shadows.is_none();
    progress.advance(1);
    let rays = AtomicU64::new(0);
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.max(1);
    let cam = ctx.camera();
    // The camera's rays, its frame and field of view computed once.
    let pixel_rays = cam.pixel_rays(w, h);
    // Film positions drawn from the reconstruction filter (the box: the
    // uniform jitter inside the pixel).
    let filter = settings.filter;
    let film_pos = |px: u32, py: u32, j: Vec2| {
        (
            filter.sample_position(px, w, j.x),
            filter.sample_position(py, h, j.y),
        )
    };
    let film = render_tiles(w, h, settings.crop_rect(), TILE, "path", progress, |rect| {
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
                        let (x, y) = film_pos(px, py, uniform2(&mut rng));
                        let ray = pixel_rays.ray(x, y);
                        let (l, fh) = tracer.reference_radiance(ray, &mut rng, &mut count);
                        sum += sanitize(l);
                        if s == 0 {
                            first_hit = fh;
                        }
                    }
                } else if lanes {
                    let camera = |j: Vec2| {
                        let (x, y) = film_pos(px, py, j);
                        pixel_rays.ray(x, y)
                    };
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
                        let (x, y) = film_pos(px, py, rng.next_2d());
                        let ray = pixel_rays.ray(x, y);
                        let (l, fh) = tracer.radiance(ray, &mut rng, &mut count);
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
    Ok((film, rays.into_inner()))
}
