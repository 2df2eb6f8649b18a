//! The scan-conversion renderer: flat, Gouraud and Phong shading on a tiled,
//! deferred z-buffer pipeline.
//!
//! The driver, `render_work` (called by [`crate::ScanConversion`]), reads as five steps, each in its file:
//! 1. *Vertex* ([`vertex`]): world positions of the [`PreparedScene`] to clip
//!    space, snapped once per vertex.
//! 2. *Binning* ([`binning`], parallel over fixed chunks of triangles):
//!    clipping, snapping, back-face culling, and a list of triangles per
//!    64x64 tile (and the shadow-volume polygons, [`crate::shadows::volumes`]).
//! 3. *Visibility* ([`visibility`], parallel over tiles): every binned
//!    triangle is rasterized into a per-tile depth and item buffer, `samples`
//!    per pixel (early z: nothing is shaded here), with the transparent
//!    fragments of [`crate::abuffer`].
//! 4. *Shading* ([`shading`]): first Gouraud's vertex illumination
//!    ([`crate::gouraud`]) for Gouraud triangles that are visible somewhere,
//!    once per vertex (flat polygons are illuminated once per tile that
//!    shows them, when shading first meets them; so are the vertices of
//!    Gouraud triangles, instead of in this pass, when one untextured opaque
//!    material under point lights is all they use: see
//!    `PolyShading::on_demand`); then, parallel over tiles, each visible
//!    sample is shaded once (deferred shading) and the samples of a pixel
//!    are averaged (box filter).
//! 5. *Resolve* ([`resolve`]): with `RenderSettings::filter = Tent`, the
//!    samples are resolved by the tent filter of [`crate::filter`] instead
//!    (the samples of a one-pixel border around the crop window are shaded
//!    too, so that a crop stays exact).
//!
//! Attributes are interpolated with *perspective-correct* barycentrics,
//! computed per sample by intersecting the sample's eye ray with the plane of
//! the visible triangle (the "visibility buffer" of Burns and Hunt 2013). For
//! the pixel-centre ray this is exactly the barycentric interpolation a ray
//! tracer performs, so Phong-mode images equal a ray-cast shading of the same
//! [`PreparedScene`] within float noise. The same intersection one pixel to
//! the right and below gives the screen-space uv derivatives for mip-mapping.
//!
//! Illumination is always
//! [`shade_local`](chiaro_core::shading::shade_local), area lights sampled
//! at the strata centres; the visibility of each light sample comes from
//! the shadow method ([`crate::shadows`]): shadow rays, shadow maps, or
//! shadow volumes counted per sample in step 3 (Phong shading; flat and
//! Gouraud shading evaluate shadow rays and maps at their vertices or
//! polygon centre, and ignore shadow volumes, which only exist per sample).
//!
//! Transparency without refraction (the lecture notes' three models) is chosen per
//! material (`Material::transparency`, overridden by
//! `RenderSettings::transparency`) for surfaces with `transmit > 0`:
//! - *screen-door*: an 8x8 ordered-dither mask (Bayer) keeps the surface in
//!   a fraction `1 - kt` of the samples, inside the ordinary z-buffer;
//! - *interpolated* and *filtered*: the visibility pass keeps, per sample,
//!   a list of every transparent fragment in front of the nearest opaque one
//!   (an A-buffer, Carpenter 1984), sorted by depth per sample, so the order
//!   is right even where transparent surfaces intersect; shading composites
//!   back to front with `I = (1 - kt) I_diffuse + I_specular + kt I_behind`
//!   (interpolated, the front surface's specular kept) or
//!   `I = I_front + kt I_behind` (filtered, `kt` the RGB transmit colour).
//!
//! Flat and Gouraud illumination is split into a part linear in the diffuse
//! colour and the rest (specular, emission), so that a diffuse texture can
//! modulate the interpolated diffuse light per pixel while the illumination
//! itself stays per polygon or per vertex (like OpenGL's separate specular
//! colour).

pub mod binning;
mod closed;
pub(crate) mod exact;
pub mod resolve;
pub mod shading;
pub(crate) mod triangles;
pub mod vertex;
pub mod visibility;

#[cfg(test)]
mod tests;

use crate::gouraud::poly_shading;
use crate::pipeline::binning::Binner;
use crate::pipeline::resolve::tent_filter;
use crate::pipeline::shading::Ctx;
use crate::pipeline::vertex::Rays;
use crate::pipeline::visibility::Class;
use crate::pipeline::visibility::Visibility;
use crate::raster::{DepthKey, sample_offsets};
pub use crate::screen_door::dither_threshold;
use crate::shadows::Shadows;
use crate::shadows::volumes::VolumeCounting;
use crate::shadows::volumes::bin_volumes;
#[cfg(test)]
pub(crate) use crate::technique::test_support::*;
use chiaro_core::accel::alpha::Coverage;
use chiaro_core::context::Derived;
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, tiles};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{Camera, RenderSettings, ShadeMode};
use chiaro_core::shading::EmitterGroup;
use std::sync::atomic::AtomicU64;

/// Side of the square screen tiles, in pixels.
pub const TILE_SIZE: u32 = 64;
/// Id of samples no triangle covers.
pub(crate) const NONE: u32 = u32::MAX;

/// The work a scan-conversion render did, counted where it is cheap (per
/// tile), for tests that catch a render whose work grows out of proportion.
#[derive(Debug, Default)]
pub struct RasterWork {
    /// Screen triangles rasterized into tiles (a triangle once per tile it
    /// was binned to).
    pub tile_triangles: AtomicU64,
    /// Samples of the tiles (pixels x samples per pixel) rasterized.
    pub samples: AtomicU64,
    /// Transparent fragments kept in front of the opaque surface.
    pub fragments: AtomicU64,
    /// Shadow-volume polygons counted into tiles.
    pub volume_tile_polygons: AtomicU64,
}

/// Options of [`crate::ScanConversion`] that are not render settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RasterOptions {
    /// How shadow-volume faces are counted (z-fail by default).
    pub volume_counting: VolumeCounting,
}

/// What one frame of the scan converter sees the scene with: the validated
/// settings and the camera (the render context's, not the scene's).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame<'f> {
    pub(crate) settings: &'f RenderSettings,
    pub(crate) camera: &'f Camera,
    /// What the frame derives from the prepared scene alone, kept between
    /// frames by the render context.
    pub(crate) derived: &'f Derived,
}

/// Scan converts the prepared scene (spheres tessellated) with the default
/// shading `mode` into `film` (see [`crate::ScanConversion::render_into`]),
/// counting the work into `work`. The settings were validated by the
/// render context.
pub(crate) fn render_work(
    ps: &PreparedScene<'_>,
    frame: Frame<'_>,
    mode: ShadeMode,
    options: &RasterOptions,
    progress: &dyn Progress,
    film: &mut Film,
    work: &RasterWork,
) -> Result<(), CoreError> {
    let Frame {
        settings,
        camera,
        derived,
    } = frame;
    let n = settings.width as usize * settings.height as usize;
    if film.width != settings.width
        || film.height != settings.height
        || [film.color.len(), film.depth.len(), film.normal.len()] != [n; 3]
    {
        *film = Film::new(settings.width, settings.height);
    }
    progress.begin("shadows", 1);
    let mut shadows = Shadows::new(ps, frame, progress)?;
    progress.advance(1);
    let scene = ps.scene;
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.clamp(1, 64);
    let offsets = sample_offsets(spp);
    let clip_from_world = camera.projection_matrix(w as f32 / h as f32) * camera.view_matrix();

    // 1. Vertex: the scene's vertices to clip space, snapped and keyed.
    progress.begin("vertex", 1);
    let rects = tiles(w, h, TILE_SIZE);
    let tiles_x = w.div_ceil(TILE_SIZE);
    let (vp_cull, vp_all) = vertex::viewports(w, h, DepthKey::of_camera(camera));
    let verts = vertex::screen_vertices(ps, clip_from_world, &vp_all);
    progress.advance(1);

    // 2. Binning: setup of the screen triangles, binned to the tiles that
    // meet the crop window; the shadow-volume polygons likewise.
    let (out_crop, crop, tent) = binning::crop_windows(settings, spp);
    // `cull_backfaces`: also the backs no camera ray reaches (a speed option).
    let hidden = if settings.cull_backfaces {
        let closed = derived.get_or_build(|| closed::closed_objects(ps));
        closed::hidden_backs(&closed, camera, w.max(1) as f32 / h.max(1) as f32)
    } else {
        Vec::new()
    };
    let binner = Binner {
        crop,
        tiles_x,
        ntiles: rects.len(),
    };
    progress.begin("setup", 1);
    let chunks = binning::bin_triangles(
        ps,
        &hidden,
        &verts,
        &binner,
        &vp_cull,
        &vp_all,
        clip_from_world,
    );
    drop(verts);
    let class: Vec<Class> = scene
        .materials
        .iter()
        .map(|m| Class::of(m, settings))
        .collect();
    let all_opaque = class.iter().all(|&c| c == Class::Opaque);
    // MASK: a fragment of a masked triangle whose alpha (at the sample's
    // point of the triangle) is below the cutoff is discarded.
    let coverage = Coverage::new(ps);
    let sample_rays = Rays::new(camera, w, h);
    let (vol_bins, nl) = bin_volumes(
        &mut shadows,
        ps,
        settings,
        &binner,
        &vp_all,
        clip_from_world,
        spp,
        progress,
    );
    progress.advance(1);

    // 3. Visibility per tile: the z-buffer and item buffer of each tile that
    // meets the crop window, its A-buffer fragments and volume counts.
    let active = visibility::active_tiles(&rects, crop);
    resolve::clear_undrawn(film, &rects, &active);
    progress.begin("raster", active.len() as u64);
    let vis = Visibility {
        ps,
        chunks: &chunks,
        class: &class,
        all_opaque,
        coverage,
        sample_rays,
        offsets: &offsets,
        spp: spp as usize,
        vol_bins,
        nl,
        counting: options.volume_counting,
        work,
    }
    .run(&active, progress);
    drop(chunks);
    let vis = vis?;

    // 4. Shading: Gouraud's vertex lighting of the visible triangles (flat
    // polygons are lit with their `TriData`), then every visible sample.
    let emitters = EmitterGroup::for_render(ps, settings);
    let ctx = Ctx::new(ps, frame, mode, &emitters, shadows, class);
    progress.begin("poly", 1);
    let poly = poly_shading(&ctx, &vis);
    progress.advance(1);
    progress.begin("shade", vis.len() as u64);
    let kept = shading::shade_tiles(&ctx, &poly, &vis, &offsets, tent, film, progress)?;

    // 5. Resolve: the box filter was applied per tile; the tent filter
    // resolves the kept samples of the crop window.
    if tent {
        tent_filter(film, &kept, crop, out_crop, &offsets);
    }
    Ok(())
}
