//! The scan-conversion renderer: flat, Gouraud and Phong shading on a tiled,
//! deferred z-buffer pipeline.
//!
//! Passes:
//! 1. *Vertex*: world positions of the [`PreparedScene`] to clip space.
//! 2. *Setup and binning* (parallel over fixed chunks of triangles): clipping,
//!    snapping, back-face culling, and a list of triangles per 64x64 tile.
//! 3. *Visibility* (parallel over tiles): every binned triangle is
//!    rasterized into a per-tile depth and item buffer, `samples` per pixel
//!    (early z: nothing is shaded here).
//! 4. *Vertex illumination* for Gouraud triangles that are visible
//!    somewhere, once per vertex. (Flat polygons are illuminated once per
//!    tile that shows them, when shading first meets them; so are the
//!    vertices of Gouraud triangles, instead of in this pass, when one
//!    untextured opaque material under point lights is all they use: see
//!    `PolyShading::on_demand`.)
//! 5. *Shading* (parallel over tiles): each visible sample is shaded once
//!    (deferred shading), the samples of a pixel are averaged (box filter)
//!    or, with `RenderSettings::filter = Tent`, resolved afterwards by the
//!    tent filter of [`crate::filter`] (the samples of a one-pixel border
//!    around the crop window are shaded too, so that a crop stays exact).
//!
//! Attributes are interpolated with *perspective-correct* barycentrics,
//! computed per sample by intersecting the sample's eye ray with the plane of
//! the visible triangle (the "visibility buffer" of Burns and Hunt 2013). For
//! the pixel-centre ray this is exactly the barycentric interpolation a ray
//! tracer performs, so Phong-mode images equal a ray-cast shading of the same
//! [`PreparedScene`] within float noise. The same intersection one pixel to
//! the right and below gives the screen-space uv derivatives for mip-mapping.
//!
//! Illumination is always [`shade_local`], area lights sampled at the strata
//! centres; the visibility of each light sample comes from the shadow method
//! ([`crate::shadow`]): shadow rays, shadow maps, or shadow volumes counted
//! per sample between steps 3 and 5 (Phong shading; flat and Gouraud shading
//! evaluate shadow rays and maps at their vertices or polygon centre, and
//! ignore shadow volumes, which only exist per sample).
//!
//! Transparency without refraction (the seeds' three models) is chosen per
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

use crate::clip::outcode;
use crate::raster::{
    DepthKey, RasterTri, Rect, Viewport, rasterize_window, rasterize_window_masked, sample_offsets,
};
use crate::shadow::{RayShadows, ShadowVolumes, Shadows, VolumeCounting};
use chiaro_core::accel::alpha::Coverage;
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, TilePixels, TileRect, tiles};
use chiaro_core::prepared::{PrepareOptions, PreparedScene, SurfaceHit};
use chiaro_core::progress::Progress;
#[cfg(test)]
use chiaro_core::scene::ShadowMethod;
use chiaro_core::scene::{AlphaMode, MaterialId, PixelFilter};
use chiaro_core::scene::{
    Material, RenderSettings, Scene, Severity, ShadeMode, Technique, TransparencyMode,
};
use chiaro_core::shading::texture::{background_radiance, environment_radiance};
use chiaro_core::shading::{
    EmitterGroup, LightSample, LocalLighting, ShadingPoint, SurfaceMaterial, depth_cue, reflect,
    samples_for_light, sanitize, shade_local, shade_local_split,
};
use chiaro_core::shading::{PointLighting, SampleKey, group_jitter};
use glam::{Mat4, Vec2, Vec3, Vec3A, Vec4};
use rayon::prelude::*;
use std::cell::Cell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

#[path = "exact.rs"]
mod exact;

/// Side of the square screen tiles, in pixels.
pub const TILE_SIZE: u32 = 64;
/// Id of samples no triangle covers.
const NONE: u32 = u32::MAX;

/// Renders `scene` by scan conversion with `settings.technique` (flat,
/// Gouraud or Phong; an object's `shade_mode` overrides it).
///
/// Returns the film: linear RGB radiance (the `samples` of each pixel
/// box- or tent-filtered, `settings.filter`), the distance from the eye to
/// the nearest surface along the pixel's sample ray (`INFINITY` on the
/// background) and the world-space shading normal (zero on the background).
///
/// # Errors
/// [`CoreError::Unsupported`] for a technique other than flat, Gouraud or
/// Phong; [`CoreError::InvalidScene`] when `Scene::validate` reports errors
/// or the image size is zero or too large; [`CoreError::Cancelled`] when the
/// progress asks to stop.
pub fn render(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    let mode = shade_mode_of(settings.technique)?;
    check_size(settings)?;
    let errors: Vec<String> = scene
        .validate()
        .into_iter()
        .filter(|i| i.severity == Severity::Error)
        .map(|i| format!("{}: {}", i.path, i.message))
        .collect();
    if !errors.is_empty() {
        return Err(CoreError::InvalidScene { issues: errors });
    }
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    render_prepared(&ps, settings, mode, progress)
}

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

/// [`render`], also counting its work into `work`.
///
/// # Errors
/// As [`render`].
pub fn render_counted(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    work: &RasterWork,
) -> Result<Film, CoreError> {
    let mode = shade_mode_of(settings.technique)?;
    check_size(settings)?;
    if scene
        .validate()
        .iter()
        .any(|i| i.severity == Severity::Error)
    {
        return render(scene, settings, progress);
    }
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    let mut film = Film::new(settings.width, settings.height);
    render_work(
        &ps,
        settings,
        mode,
        &RasterOptions::default(),
        progress,
        &mut film,
        work,
    )?;
    Ok(film)
}

/// The shading mode of a scan-conversion technique.
///
/// # Errors
/// [`CoreError::Unsupported`] for techniques that are not scan conversion.
pub fn shade_mode_of(technique: Technique) -> Result<ShadeMode, CoreError> {
    match technique {
        Technique::Flat => Ok(ShadeMode::Flat),
        Technique::Gouraud => Ok(ShadeMode::Gouraud),
        Technique::Phong => Ok(ShadeMode::Phong),
        other => Err(CoreError::Unsupported(format!(
            "the scan converter renders flat, gouraud and phong, not `{}`",
            other.name()
        ))),
    }
}

fn check_size(settings: &RenderSettings) -> Result<(), CoreError> {
    let (w, h) = (settings.width, settings.height);
    let max = chiaro_core::scene::MAX_IMAGE_SIDE;
    if w == 0
        || h == 0
        || w > max
        || h > max
        || u64::from(w) * u64::from(h) > chiaro_core::scene::MAX_IMAGE_PIXELS
    {
        return Err(CoreError::InvalidScene {
            issues: vec![format!(
                "render: image size {w}x{h} is outside 1x1..{max}x{max}"
            )],
        });
    }
    Ok(())
}

/// Primary rays exactly as [`chiaro_core::scene::Camera::ray_direction`]
/// computes them, with the camera frame computed once.
#[derive(Debug, Clone, Copy)]
struct Rays {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    tan_half: f32,
    aspect: f32,
    width: f32,
    height: f32,
}

impl Rays {
    fn new(scene: &Scene, width: u32, height: u32) -> Self {
        let cam = &scene.camera;
        let f = cam.frame();
        Self {
            eye: cam.eye,
            right: f.right,
            up: f.up,
            forward: f.forward,
            tan_half: (cam.fov_y_degrees.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
            width: width as f32,
            height: height as f32,
        }
    }

    /// Unit direction through film position `(x, y)` (pixels, top-left origin).
    #[inline]
    fn dir(&self, x: f32, y: f32) -> Vec3 {
        Self::dir_from(self.column(x), self.row(y)).into()
    }

    /// The part of the unnormalised direction through column `x` that does
    /// not depend on the row: `forward + ndc_x right`.
    #[inline]
    fn column(&self, x: f32) -> Vec3A {
        let ndc_x = (2.0 * x / self.width - 1.0) * self.tan_half * self.aspect;
        (self.forward + ndc_x * self.right).into()
    }

    /// The part that depends on the row `y` only: `ndc_y up`.
    #[inline]
    fn row(&self, y: f32) -> Vec3A {
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.tan_half;
        (ndc_y * self.up).into()
    }

    /// [`Rays::dir`] from its [`Rays::column`] and [`Rays::row`] parts
    /// (computed once per tile column and row by the shading pass).
    #[inline]
    fn dir_from(column: Vec3A, row: Vec3A) -> Vec3A {
        exact::normalize(column + row)
    }
}

/// Barycentrics `(u, v)` of vertices 1 and 2 where the ray `o + t d` meets the
/// plane of the triangle (Moller and Trumbore 1997, without the inside test):
/// the perspective-correct barycentrics of the sample. `None` when the ray
/// is parallel to the plane. The reference for [`TriData::bary`], which
/// shading uses.
#[cfg(test)]
fn ray_plane_bary(o: Vec3, d: Vec3, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<Vec2> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-30 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - p0;
    let u = s.dot(pv) * inv;
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    let r = Vec2::new(u, v);
    r.is_finite().then_some(r)
}

/// Illumination split into the part proportional to the diffuse colour and
/// the rest: the colour is `diffuse * texture + rest`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Split {
    diffuse: Vec3,
    rest: Vec3,
}

impl Split {
    #[inline]
    fn lerp3(s: [Split; 3], w: Vec3) -> Split {
        // On SSE vectors: the same operations lane by lane.
        let l = |f: fn(&Split) -> Vec3| {
            let [a, b, c] = [&s[0], &s[1], &s[2]].map(|x| Vec3A::from(f(x)));
            Vec3::from(a * w.x + b * w.y + c * w.z)
        };
        Split {
            diffuse: l(|x| x.diffuse),
            rest: l(|x| x.rest),
        }
    }
}

/// Everything the shading passes share.
struct Ctx<'a, 's> {
    ps: &'a PreparedScene<'s>,
    settings: &'a RenderSettings,
    rays: Rays,
    lighting: LocalLighting<'a>,
    object_mode: Vec<ShadeMode>,
    shadows: Shadows,
    /// Shadow rays for the samples of a grouped emissive mesh under shadow
    /// maps and the exact methods (its lights get no maps, volumes or
    /// fragments), and for lights whose volumes did not fit the budget.
    group_rays: Option<RayShadows>,
    /// Per material: how it is drawn ([`Class`]).
    class: Vec<Class>,
    /// `lighting` specialised, when there are no shadows and only point
    /// and ambient lights (bit-identical to `shade_local`).
    point_lighting: Option<PointLighting>,
    /// `SurfaceMaterial::from_material` of each scene material, by index.
    bases: Vec<SurfaceMaterial>,
    /// True when the frame allows [`lean_sample`]: no environment and no
    /// depth cueing (Phong samples also need `point_lighting`).
    lean_frame: bool,
    /// The shading mode of every object, when they all have the same one,
    /// and the material of every triangle, when it is the same: per-triangle
    /// lookups (cache misses) that the triangle cache then skips.
    one_mode: Option<ShadeMode>,
    one_material: Option<MaterialId>,
}

/// How the visibility pass treats a material.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Class {
    /// Opaque (or `transmit = 0`).
    Opaque,
    /// Screen-door: covers the samples whose dither threshold is at least `kt`.
    ScreenDoor(f32),
    /// A fragment composited over what is behind it.
    Blend(TransparencyMode),
}

impl Class {
    fn of(m: &Material, settings: &RenderSettings) -> Class {
        if !m.is_transparent() {
            return Class::Opaque;
        }
        match settings.transparency.unwrap_or(m.transparency) {
            TransparencyMode::ScreenDoor => {
                let kt = m.transmit.clamp(Vec3::ZERO, Vec3::ONE);
                Class::ScreenDoor((kt.x + kt.y + kt.z) / 3.0)
            }
            mode => Class::Blend(mode),
        }
    }
}

/// The 8x8 ordered-dither (Bayer) threshold in `(0, 1)` of sample `s` of
/// pixel `(x, y)`: over any 8x8 block each of the 64 values occurs once, so
/// a surface drawn where `threshold >= kt` covers a fraction `1 - kt`.
#[inline]
pub fn dither_threshold(x: u32, y: u32, s: u32) -> f32 {
    const BAYER: [u8; 64] = [
        0, 32, 8, 40, 2, 34, 10, 42, 48, 16, 56, 24, 50, 18, 58, 26, 12, 44, 4, 36, 14, 46, 6, 38,
        60, 28, 52, 20, 62, 30, 54, 22, 3, 35, 11, 43, 1, 33, 9, 41, 51, 19, 59, 27, 49, 17, 57,
        25, 15, 47, 7, 39, 13, 45, 5, 37, 63, 31, 55, 23, 61, 29, 53, 21,
    ];
    // Samples of one pixel use shifted masks so they cover different levels.
    let (xs, ys) = (
        x.wrapping_add(s.wrapping_mul(5)),
        y.wrapping_add(s.wrapping_mul(3)),
    );
    (f32::from(BAYER[((ys % 8) * 8 + xs % 8) as usize]) + 0.5) / 64.0
}

impl Ctx<'_, '_> {
    fn mode(&self, t: u32) -> ShadeMode {
        if let Some(m) = self.one_mode {
            return m;
        }
        let o = self.ps.tri_object[t as usize] as usize;
        self.object_mode.get(o).copied().unwrap_or(ShadeMode::Phong)
    }

    fn material_of(&self, t: u32) -> &Material {
        self.ps.material(self.ps.tri_material[t as usize])
    }

    /// True if the viewer sees the back of a two-sided triangle `t` (its
    /// normals are then flipped).
    fn flipped(&self, t: u32) -> bool {
        if !self.material_of(t).two_sided {
            return false;
        }
        let p0 = self.ps.positions[self.ps.triangles[t as usize][0] as usize];
        self.ps.face_normal(t).dot(self.rays.eye - p0) < 0.0
    }

    /// `shade_local` with area lights sampled at the strata centres and the
    /// visibility of the shadow method; `counts` are the shadow-volume
    /// counts of this sample, one per light (absent: no volume shadows).
    #[inline]
    fn illuminate(
        &self,
        tri: u32,
        pixel: Option<(u32, u32)>,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
        counts: Option<&[i32]>,
    ) -> Vec3 {
        if let Some(pl) = &self.point_lighting {
            return pl.shade(m, sp);
        }
        let key = match pixel {
            Some((x, y)) => SampleKey::Pixel(x, y),
            None => SampleKey::Point(sp.p),
        };
        if matches!(self.shadows, Shadows::None) {
            // Every light sample is visible: closures the compiler inlines.
            return shade_local(
                m,
                sp,
                &self.lighting,
                |li, i| self.jitter(key, li, i),
                |_, _| Vec3::ONE,
            );
        }
        let current = Cell::new(0u32);
        shade_local(
            m,
            sp,
            &self.lighting,
            |li, i| {
                current.set(i);
                self.jitter(key, li, i)
            },
            |li, s| self.visibility(li, current.get(), tri, pixel, sp, s, counts),
        )
    }

    /// The jitter of sample `i` of light `li` at the shading point `key`:
    /// area lights at their strata centres, an emitter group's picks from
    /// the jitter sequence Whitted shares ([`group_jitter`]).
    #[inline]
    fn jitter(&self, key: SampleKey, li: usize, i: u32) -> Vec2 {
        match self.lighting.group {
            Some(g) if g.contains(li) => group_jitter(self.settings.seed, key, i),
            _ => Vec2::splat(0.5),
        }
    }

    /// Visibility of sample `i` of light `li` from the shading point.
    fn visibility(
        &self,
        li: usize,
        i: u32,
        tri: u32,
        pixel: Option<(u32, u32)>,
        sp: &ShadingPoint,
        s: &LightSample,
        counts: Option<&[i32]>,
    ) -> Vec3 {
        // An exact method's opaque-caster visibility times the tint of the
        // transparent casters, by shadow rays that see only them.
        let tinted = |lit: f32, transparent: &Option<RayShadows>| match transparent {
            Some(r) if lit > 0.0 => lit * r.visibility(sp.p, sp.ng, s),
            _ => Vec3::splat(lit),
        };
        match &self.shadows {
            Shadows::None => Vec3::ONE,
            Shadows::Ray(r) => r.visibility(sp.p, sp.ng, s),
            // A group's samples (all but rays) and lights whose volumes did
            // not fit: shadow rays (see `shadow::exact_lights`).
            _ if self.lighting.group.is_some_and(|g| g.contains(li))
                || matches!(&self.shadows, Shadows::Volume(v) if v.by_ray.get(li) == Some(&true)) =>
            {
                self.group_rays
                    .as_ref()
                    .map_or(Vec3::ONE, |r| r.visibility(sp.p, sp.ng, s))
            }
            Shadows::Map(m) => {
                let count = self
                    .ps
                    .lights
                    .get(li)
                    .map_or(1, |l| samples_for_light(l, self.lighting.area_samples));
                m.visibility(li, i, count, sp.p, sp.ng, s)
            }
            Shadows::Volume(v) => {
                let count = v
                    .slot
                    .get(li)
                    .copied()
                    .flatten()
                    .and_then(|k| counts.and_then(|c| c.get(k as usize)));
                match count {
                    Some(&c) if c != 0 => Vec3::ZERO,
                    _ => v
                        .transparent
                        .as_ref()
                        .map_or(Vec3::ONE, |r| r.visibility(sp.p, sp.ng, s)),
                }
            }
            Shadows::Object {
                lights,
                transparent,
            } => {
                let lit = match lights.get(li) {
                    Some(Some(o)) => o.lit_fraction(tri, sp.p),
                    _ => 1.0,
                };
                tinted(lit, transparent)
            }
            Shadows::Scanline {
                lines,
                fallback,
                transparent,
            } => {
                // The scan-line pass classified pixel centres; other points
                // (sub-samples, vertices) use the exact lit fragments.
                let centre = match (pixel, lines.get(li)) {
                    (Some((x, y)), Some(Some(l))) => {
                        let k = (y * l.width + x) as usize;
                        (l.visible.get(k) == Some(&tri)).then(|| l.lit[k])
                    }
                    _ => None,
                };
                let lit = centre.unwrap_or_else(|| match fallback.get(li) {
                    Some(Some(o)) => o.lit_fraction(tri, sp.p),
                    _ => 1.0,
                });
                tinted(lit, transparent)
            }
        }
    }

    /// The illumination split for flat and Gouraud shading: one evaluation
    /// of [`shade_local_split`], whose `rest` is exactly the illumination
    /// with `kd = 0`.
    fn illuminate_split(&self, tri: u32, m: &SurfaceMaterial, sp: &ShadingPoint) -> Split {
        if let Some(pl) = &self.point_lighting {
            let [total, rest] = pl.shade_split(m, sp);
            return Split {
                diffuse: total - rest,
                rest,
            };
        }
        let current = Cell::new(0u32);
        let [total, rest] = shade_local_split(
            m,
            sp,
            &self.lighting,
            |li, i| {
                current.set(i);
                self.jitter(SampleKey::Point(sp.p), li, i)
            },
            |li, s| self.visibility(li, current.get(), tri, None, sp, s, None),
        );
        Split {
            diffuse: total - rest,
            rest,
        }
    }

    /// Untextured material (vertex colour applied) at a surface point: the
    /// diffuse texture is applied per pixel by flat and Gouraud shading.
    fn untextured_material(&self, hit: &SurfaceHit) -> SurfaceMaterial {
        let m = self.ps.material(hit.material);
        let mut sm = SurfaceMaterial::with_vertex_color(m, hit.color);
        if let Some(t) = m.emission_texture {
            let tc = PreparedScene::tex_coord(hit, Vec2::ZERO, Vec2::ZERO);
            sm.emission *= self.ps.eval_texture(t, &tc).truncate();
        }
        sm
    }

    /// `SurfaceMaterial::from_material` of the triangle's material.
    #[inline]
    fn base(&self, td: &TriData<'_>) -> SurfaceMaterial {
        match self.bases.get(td.material_id.index()) {
            Some(b) => *b,
            None => SurfaceMaterial::from_material(td.material),
        }
    }

    /// Flat shading of triangle `td`: once, at the centroid, with the face
    /// normal. The same values as `surface` at the centroid, `flipped` and
    /// `untextured_material` give, from the cached triangle.
    fn flat_split(&self, td: &TriData<'_>) -> Split {
        let t = td.t;
        let third = 1.0 / 3.0;
        let (p, sm) = if td.textured {
            let hit = self.surface(td, third, third, true, true);
            (hit.p, self.untextured_material(&hit))
        } else {
            // surface(): w = 1 - u - v, then the same interpolations.
            let w = 1.0 - third - third;
            let mut sm = self.base(td);
            sm.kd *= Vec3::from(td.c[0] * w + td.c[1] * third + td.c[2] * third);
            (
                Vec3::from(td.p[0] * w + td.p[1] * third + td.p[2] * third),
                sm,
            )
        };
        let mut n = Vec3::from(td.ng);
        // flipped(t), with the cached face normal (PreparedScene::face_normal).
        if td.material.two_sided && td.ng.dot(Vec3A::from(self.rays.eye) - td.p[0]) < 0.0 {
            n = -n;
        }
        let wo = (self.rays.eye - p).normalize_or_zero();
        let sp = ShadingPoint { p, n, ng: n, wo };
        self.illuminate_split(t, &sm, &sp)
    }

    /// [`Ctx::corner_split`] at vertex `v` of an untextured material whose
    /// [`SurfaceMaterial`] is `base`, lit by the point-light model,
    /// for any corner of any triangle with that material at `v`: the
    /// model reads no geometric normal, and a corner's interpolated position
    /// and colour (weights 1, 0, 0) are the vertex's own but for the sign of
    /// a zero component, which changes no non-zero result (and the film's
    /// sanitising makes every zero positive).
    /// Requires `point_lighting` (without it the triangle would matter for
    /// shadows).
    fn vertex_split(&self, base: &SurfaceMaterial, v: usize, back: bool) -> Split {
        debug_assert!(self.point_lighting.is_some());
        let p = self.ps.positions[v];
        let mut n = self.ps.normals[v];
        if back {
            n = -n;
        }
        let mut sm = *base;
        sm.kd *= self.ps.colors[v];
        let wo = (self.rays.eye - p).normalize_or_zero();
        // No triangle: point lighting has no visibility to ask about.
        self.illuminate_split(u32::MAX, &sm, &ShadingPoint { p, n, ng: n, wo })
    }

    /// Gouraud illumination at corner `k` of triangle `t`, on the front side
    /// or (for the back of a two-sided surface) the back side.
    fn corner_split(&self, t: u32, k: usize, back: bool) -> Split {
        let (u, v) = match k {
            0 => (0.0, 0.0),
            1 => (1.0, 0.0),
            _ => (0.0, 1.0),
        };
        let td = self.make_tri_data(t);
        let hit = self.surface(&td, u, v, td.textured, true);
        let vi = self.ps.triangles[t as usize][k] as usize;
        let mut n = self.ps.normals[vi];
        let mut ng = hit.ng;
        if back {
            n = -n;
            ng = -ng;
        }
        let wo = (self.rays.eye - hit.p).normalize_or_zero();
        let sp = ShadingPoint {
            p: hit.p,
            n,
            ng,
            wo,
        };
        self.illuminate_split(t, &self.untextured_material(&hit), &sp)
    }
}

/// What shading needs of a visible triangle, fetched once per tile (see
/// [`TriCache`]).
#[derive(Clone, Copy)]
struct TriData<'a> {
    t: u32,
    idx: [usize; 3],
    /// The vertex positions (as SSE vectors, see [`exact`]).
    p: [Vec3A; 3],
    /// `PreparedScene::face_normal(t)`.
    ng: Vec3A,
    /// The vertex normals and colours (in [`TriCache`], zero where the
    /// triangle's samples do not read them: see [`Ctx::tri_geometry`]).
    n: [Vec3A; 3],
    c: [Vec3A; 3],
    mode: ShadeMode,
    material: &'a Material,
    material_id: MaterialId,
    /// True when the material has a texture, bump, normal or emission map
    /// (which need the uv footprint).
    textured: bool,
    /// The flat-shading illumination of the polygon (zero unless `mode` is
    /// flat): computed with the triangle's data, once per tile that shows it.
    flat: Split,
    /// True when its opaque samples take [`lean_sample`] (set by
    /// [`Ctx::tri_data`]; false elsewhere).
    lean: bool,
    /// Lean Gouraud triangles: the vertex illumination of the three
    /// corners, `[diffuse, rest]` as SSE vectors (zero otherwise).
    corners: [[Vec3A; 2]; 3],
    /// The per-triangle terms of `ray_plane_bary` for rays from the eye:
    /// the edges `p1 - p0`, `p2 - p0`, `eye - p0` and `(eye - p0) x (p1 - p0)`.
    e1: Vec3A,
    e2: Vec3A,
    s: Vec3A,
    q: Vec3A,
}

impl TriData<'_> {
    /// `ray_plane_bary` for the eye ray with direction `d`: the same
    /// operations in the same order, with the terms that do not depend on
    /// `d` precomputed.
    #[inline]
    fn bary(&self, d: Vec3A) -> Option<Vec2> {
        let pv = exact::cross(d, self.e2);
        let det = self.e1.dot(pv);
        if det.abs() < 1e-30 {
            return None;
        }
        let inv = 1.0 / det;
        let u = self.s.dot(pv) * inv;
        let v = d.dot(self.q) * inv;
        let r = Vec2::new(u, v);
        r.is_finite().then_some(r)
    }
}

/// True when `m` has a texture, bump, normal or emission map (which need
/// the uv footprint): [`TriData::textured`].
fn needs_footprint(m: &Material) -> bool {
    m.is_textured() || m.bump.is_some() || m.normal_map.is_some()
}

/// Number of entries of [`TriCache`] (a power of two).
const TRI_CACHE_SIZE: usize = 256;

/// Number of entries of the vertex illumination cache of [`TriCache`] (a
/// power of two): a few tiles' worth of vertices.
const VERTEX_CACHE_SIZE: usize = 4096;

/// A direct-mapped cache of [`TriData`] keyed by triangle id: a triangle
/// covers a few pixels on a few rows, and neighbouring triangles have
/// neighbouring ids, so most lookups hit. What it holds depends only on the
/// triangle, so one cache serves every tile a shading thread takes.
///
/// With [`PolyShading::on_demand`] it also caches the illumination of the
/// vertices the fetched Gouraud triangles use, keyed by vertex index.
struct TriCache<'a> {
    /// Index into `data` of each slot's entry (`u32::MAX`: empty).
    slots: [u32; TRI_CACHE_SIZE],
    data: Vec<TriData<'a>>,
    /// The vertex of each vertex slot (`u32::MAX`: empty; allocated on
    /// first use).
    vertex_ids: Vec<u32>,
    /// Its [`Ctx::vertex_split`], `[diffuse, rest]` as in [`TriData::corners`].
    vertex_splits: Vec<[Vec3A; 2]>,
}

impl TriCache<'_> {
    fn new() -> Self {
        Self {
            slots: [u32::MAX; TRI_CACHE_SIZE],
            data: Vec::with_capacity(TRI_CACHE_SIZE),
            vertex_ids: Vec::new(),
            vertex_splits: Vec::new(),
        }
    }
}

impl<'a> Ctx<'a, '_> {
    /// The data of triangle `t`, from `cache` when it holds `t` (the
    /// cache then holds `t`), with [`TriData::lean`] and the Gouraud
    /// corners from `poly` set.
    #[inline(always)]
    fn tri_data<'c>(
        &self,
        t: u32,
        cache: &'c mut TriCache<'a>,
        poly: &PolyShading,
    ) -> &'c TriData<'a> {
        // The hit, inlined into the sample loops; the miss is a call.
        let k = cache.slots[t as usize & (TRI_CACHE_SIZE - 1)] as usize;
        if k < cache.data.len() && cache.data[k].t == t {
            return &cache.data[k];
        }
        self.fetch_tri(t, cache, poly)
    }

    /// [`Ctx::tri_data`] of a triangle that `cache` does not hold: fetched
    /// into its slot.
    #[inline(never)]
    fn fetch_tri<'c>(
        &self,
        t: u32,
        cache: &'c mut TriCache<'a>,
        poly: &PolyShading,
    ) -> &'c TriData<'a> {
        let slot = t as usize & (TRI_CACHE_SIZE - 1);
        let k = cache.slots[slot] as usize;
        let k = if k < cache.data.len() {
            // Built in place (inlined), not copied in.
            cache.data[k] = self.tri_geometry(t, false);
            k
        } else {
            cache.slots[slot] = cache.data.len() as u32;
            cache.data.push(self.tri_geometry(t, false));
            cache.data.len() - 1
        };
        let TriCache {
            data,
            vertex_ids,
            vertex_splits,
            ..
        } = cache;
        let d = &mut data[k];
        if d.mode == ShadeMode::Flat {
            d.flat = self.flat_split(d);
        }
        // The cases shade_sample handles without textures, two-sided
        // flips, reflection maps, depth cueing or per-corner values.
        d.lean = self.lean_frame
            && !d.textured
            && !d.material.two_sided
            && match d.mode {
                ShadeMode::Phong => {
                    self.point_lighting.is_some() && self.bases.get(d.material_id.index()).is_some()
                }
                ShadeMode::Gouraud => poly.corners.is_empty() || !poly.corners.contains_key(&t),
                ShadeMode::Flat => true,
            };
        if d.lean && d.mode == ShadeMode::Gouraud {
            if let Some(base) = &poly.on_demand {
                if vertex_ids.is_empty() {
                    *vertex_ids = vec![u32::MAX; VERTEX_CACHE_SIZE];
                    *vertex_splits = vec![[Vec3A::ZERO; 2]; VERTEX_CACHE_SIZE];
                }
                let mut get = |i: usize| {
                    let slot = i & (VERTEX_CACHE_SIZE - 1);
                    if vertex_ids[slot] != i as u32 {
                        let s = self.vertex_split(base, i, false);
                        vertex_ids[slot] = i as u32;
                        vertex_splits[slot] = [s.diffuse.into(), s.rest.into()];
                    }
                    vertex_splits[slot]
                };
                d.corners = [get(d.idx[0]), get(d.idx[1]), get(d.idx[2])];
            } else {
                let get = |i: usize| {
                    let s = poly.vertex_front.get(i).copied().unwrap_or_default();
                    [s.diffuse.into(), s.rest.into()]
                };
                d.corners = [get(d.idx[0]), get(d.idx[1]), get(d.idx[2])];
            }
        }
        d
    }

    /// The [`TriData`] of triangle `t`, computed.
    fn make_tri_data(&self, t: u32) -> TriData<'a> {
        let mut d = self.tri_geometry(t, true);
        if d.mode == ShadeMode::Flat {
            d.flat = self.flat_split(&d);
        }
        d
    }

    /// [`Ctx::make_tri_data`] without the flat-shading illumination; unless
    /// `all`, without the vertex data its samples do not read (the normals
    /// of a flat triangle, the colours of a Gouraud one: zero), which
    /// the triangle cache then need not fetch.
    #[inline(always)]
    fn tri_geometry(&self, t: u32, all: bool) -> TriData<'a> {
        let mode = self.mode(t);
        // (Arrays written out rather than `map`ped: cheaper per fetch.)
        let [i0, i1, i2] = self.ps.triangles[t as usize];
        let idx = [i0 as usize, i1 as usize, i2 as usize];
        let pos = &self.ps.positions;
        let p: [Vec3A; 3] = [pos[idx[0]].into(), pos[idx[1]].into(), pos[idx[2]].into()];
        // PreparedScene::face_normal(t), from the positions at hand.
        let ng = exact::face_normal(p[0], p[1], p[2]).unwrap_or(Vec3A::Z);
        let of =
            |a: &[Vec3]| -> [Vec3A; 3] { [a[idx[0]].into(), a[idx[1]].into(), a[idx[2]].into()] };
        let e1 = p[1] - p[0];
        let s = Vec3A::from(self.rays.eye) - p[0];
        let material_id = self
            .one_material
            .unwrap_or_else(|| self.ps.tri_material[t as usize]);
        let material = self.ps.material(material_id);
        TriData {
            t,
            idx,
            p,
            ng,
            n: if all || mode != ShadeMode::Flat {
                of(&self.ps.normals)
            } else {
                [Vec3A::ZERO; 3]
            },
            c: if all || mode != ShadeMode::Gouraud {
                of(&self.ps.colors)
            } else {
                [Vec3A::ZERO; 3]
            },
            mode,
            material,
            material_id,
            textured: needs_footprint(material),
            e1,
            e2: p[2] - p[0],
            s,
            q: exact::cross(s, e1),
            flat: Split::default(),
            lean: false,
            corners: [[Vec3A::ZERO; 2]; 3],
        }
    }

    /// [`PreparedScene::triangle_surface`] at barycentrics `(u, v)`, the
    /// same expressions on the cached triangle; the uv, object-space point
    /// and tangent (which only textures, bump and normal maps read) are
    /// computed only when `textured`, zero otherwise.
    ///
    /// With `shading` false (flat-shaded samples, which read neither) the
    /// shading normal is the face normal and the vertex colour zero.
    #[inline(always)]
    fn surface(
        &self,
        td: &TriData<'_>,
        u: f32,
        v: f32,
        textured: bool,
        shading: bool,
    ) -> SurfaceHit {
        let ps = self.ps;
        let [i0, i1, i2] = td.idx;
        let w = 1.0 - u - v;
        let lerp3 = |a: &[Vec3]| a[i0] * w + a[i1] * u + a[i2] * v;
        let ng = td.ng;
        let (ns, color) = if shading {
            let mut ns =
                exact::try_normalize(td.n[0] * w + td.n[1] * u + td.n[2] * v).unwrap_or(ng);
            if ns.dot(ng) < 0.0 {
                // Interpolated normals may point away from a thin face; keep the front side.
                ns = ng;
            }
            (ns, td.c[0] * w + td.c[1] * u + td.c[2] * v)
        } else {
            (ng, Vec3A::ZERO)
        };
        let color_alpha = if textured {
            ps.color_alphas[i0] * w + ps.color_alphas[i1] * u + ps.color_alphas[i2] * v
        } else {
            1.0
        };
        let (uv, p_object, tangent) = if textured {
            let tan = ps.tangents[i0] * w + ps.tangents[i1] * u + ps.tangents[i2] * v;
            (
                ps.uvs[i0] * w + ps.uvs[i1] * u + ps.uvs[i2] * v,
                lerp3(&ps.object_positions),
                tan.truncate()
                    .normalize_or_zero()
                    .extend(if tan.w < 0.0 { -1.0 } else { 1.0 }),
            )
        } else {
            (Vec2::ZERO, Vec3::ZERO, Vec4::ZERO)
        };
        SurfaceHit {
            p: (td.p[0] * w + td.p[1] * u + td.p[2] * v).into(),
            ng: ng.into(),
            ns: ns.into(),
            uv,
            p_object,
            tangent,
            color: color.into(),
            color_alpha,
            material: td.material_id,
            object: ps.tri_object[td.t as usize],
        }
    }
}

/// Per-triangle results of the visibility pass that flat and Gouraud
/// shading need.
#[derive(Default)]
struct PolyShading {
    /// Gouraud: per vertex, front side.
    vertex_front: Vec<Split>,
    /// Gouraud: per vertex, back side (two-sided surfaces seen from behind).
    vertex_back: Vec<Split>,
    /// Gouraud triangles whose corners could not use shared vertex values
    /// (a vertex shared by faces of different materials).
    corners: HashMap<u32, [Split; 3]>,
    /// When every Gouraud sample is a [`lean_sample`] of one untextured
    /// material lit by `point_lighting` ([`on_demand_gouraud`]): that
    /// material, and the tables above stay empty. The shading pass then
    /// illuminates each vertex when a triangle using it is first fetched
    /// ([`TriCache`]), the same [`Ctx::vertex_split`] as
    /// [`uniform_vertex_shading`] gives it; this skips finding the
    /// visible vertices (a pass over every sample) and writing, then
    /// gathering back, a table of every vertex's illumination. A vertex
    /// is only illuminated again where the cache lost it (another shading
    /// thread, or a slot taken by another vertex).
    on_demand: Option<SurfaceMaterial>,
}

/// One tile's visibility: the nearest opaque triangle of each sample, the
/// transparent fragments in front of it, and the shadow-volume counts.
struct TileVis {
    rect: TileRect,
    /// The part of the tile inside the crop window: the only pixels drawn.
    window: Rect,
    /// Nearest opaque (or screen-door) triangle per sample.
    ids: Vec<u32>,
    /// Transparent fragments of sample `i`: `frags[start[i]..start[i + 1]]`,
    /// nearest first (empty `start` when there are none).
    start: Vec<u32>,
    /// `(triangle, key)` of each transparent fragment.
    frags: Vec<(u32, f32)>,
    /// Shadow-volume counts, `lights` per point: points are the samples,
    /// then the fragments (empty without shadow volumes).
    counts: Vec<i32>,
}

impl TileVis {
    fn frag_range(&self, i: usize) -> std::ops::Range<usize> {
        if self.start.is_empty() {
            0..0
        } else {
            self.start[i] as usize..self.start[i + 1] as usize
        }
    }
}

/// Options of [`render_prepared_with`] that are not render settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RasterOptions {
    /// How shadow-volume faces are counted (z-fail by default).
    pub volume_counting: VolumeCounting,
}

/// Renders an already prepared scene with the default shading `mode`.
/// See [`render`]; the prepared scene must come from
/// `PrepareOptions { analytic_spheres: false, .. }` (spheres tessellated).
///
/// # Errors
/// [`CoreError::Cancelled`] when the progress asks to stop;
/// [`CoreError::InvalidScene`] for a bad image size;
/// [`CoreError::Unsupported`] for `shadows = object | scanline`.
pub fn render_prepared(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    mode: ShadeMode,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    render_prepared_with(ps, settings, mode, &RasterOptions::default(), progress)
}

/// [`render_prepared`] with extra `options` (the shadow-volume counting).
///
/// # Errors
/// As [`render_prepared`].
pub fn render_prepared_with(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    mode: ShadeMode,
    options: &RasterOptions,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    check_size(settings)?;
    let mut film = Film::new(settings.width, settings.height);
    render_prepared_into(ps, settings, mode, options, progress, &mut film)?;
    Ok(film)
}

/// [`render_prepared_with`] into `film`, whose buffers are reused when it
/// already has the image's size (so that frames rendered one after another
/// neither allocate nor fault in a new film each time, as a GPU's
/// framebuffer is reused); it is resized otherwise. On success `film` holds
/// exactly the picture [`render_prepared_with`] returns, whatever it held
/// before; on an error its pixels are unspecified.
///
/// # Errors
/// As [`render_prepared`].
pub fn render_prepared_into(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    mode: ShadeMode,
    options: &RasterOptions,
    progress: &dyn Progress,
    film: &mut Film,
) -> Result<(), CoreError> {
    render_work(
        ps,
        settings,
        mode,
        options,
        progress,
        film,
        &RasterWork::default(),
    )
}

/// [`render_prepared_into`], counting the work into `work`.
fn render_work(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    mode: ShadeMode,
    options: &RasterOptions,
    progress: &dyn Progress,
    film: &mut Film,
    work: &RasterWork,
) -> Result<(), CoreError> {
    check_size(settings)?;
    let n = settings.width as usize * settings.height as usize;
    if film.width != settings.width
        || film.height != settings.height
        || [film.color.len(), film.depth.len(), film.normal.len()] != [n; 3]
    {
        *film = Film::new(settings.width, settings.height);
    }
    progress.begin("shadows", 1);
    let mut shadows = Shadows::new(ps, settings, progress)?;
    progress.advance(1);
    let scene = ps.scene;
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.clamp(1, 64);
    let offsets = sample_offsets(spp);
    let cam = &scene.camera;
    let clip_from_world = cam.projection_matrix(w as f32 / h as f32) * cam.view_matrix();

    // 1. Vertices to clip space; those inside the clip volume are also
    // snapped and keyed here, once, instead of once per triangle.
    progress.begin("vertex", 1);
    let rects = tiles(w, h, TILE_SIZE);
    let tiles_x = w.div_ceil(TILE_SIZE);
    let vp_cull = Viewport {
        width: w,
        height: h,
        cull_back: true,
        depth_key: DepthKey::InvW,
    };
    let vp_all = Viewport {
        cull_back: false,
        ..vp_cull
    };
    let verts: Vec<ScreenVertex> = ps
        .positions
        .par_iter()
        .map(|p| {
            let clip = clip_from_world * p.extend(1.0);
            let inside = outcode(clip) == 0;
            ScreenVertex {
                inside,
                xy: if inside { vp_all.snap(clip) } else { [0; 2] },
                // The key `Viewport::setup` gives an unclipped vertex:
                // its barycentric (a unit vector) dotted with (1, 1, 1),
                // exactly 1, over w.
                key: 1.0 / clip.w,
            }
        })
        .collect();
    progress.advance(1);

    // 2. Setup and binning over fixed chunks (deterministic order), into
    // the tiles that meet the crop window.
    let [cx0, cy0, cx1, cy1] = settings.crop_rect();
    let out_crop = Rect {
        x0: cx0,
        y0: cy0,
        x1: cx1,
        y1: cy1,
    };
    // The tent filter reads the samples of the pixels around each pixel:
    // shade a one-pixel border around the crop window too, so that a pixel
    // of a crop window has its value in the full image.
    let tent = settings.filter == PixelFilter::Tent && spp > 1;
    let crop = if tent && out_crop.x0 < out_crop.x1 && out_crop.y0 < out_crop.y1 {
        Rect {
            x0: out_crop.x0.saturating_sub(1),
            y0: out_crop.y0.saturating_sub(1),
            x1: (out_crop.x1 + 1).min(w),
            y1: (out_crop.y1 + 1).min(h),
        }
    } else {
        out_crop
    };
    let binner = Binner {
        crop,
        tiles_x,
        ntiles: rects.len(),
    };
    let cull_material: Vec<bool> = scene
        .materials
        .iter()
        // A single-sided glTF material (`cull_backface`) is culled whatever the setting.
        .map(|m| (settings.cull_backfaces && !m.two_sided) || m.cull_backface)
        .collect();
    let nt = ps.triangles.len();
    let chunk = nt.div_ceil(256).max(4096);
    progress.begin("setup", 1);
    let chunks: Vec<Bins> = if crop.x0 >= crop.x1 || crop.y0 >= crop.y1 {
        Vec::new()
    } else {
        ps.triangles
            .par_chunks(chunk)
            .enumerate()
            .map(|(ci, tris)| {
                // The screen triangles of one source triangle.
                let mut out = Vec::new();
                let mut scratch = Vec::new();
                let mut bins = binner.empty();
                for (k, tri) in tris.iter().enumerate() {
                    out.clear();
                    let t = (ci * chunk + k) as u32;
                    let cull = cull_material
                        .get(ps.tri_material[t as usize].index())
                        .copied()
                        .unwrap_or(settings.cull_backfaces);
                    let vp = if cull { &vp_cull } else { &vp_all };
                    let v = tri.map(|i| &verts[i as usize]);
                    if v[0].inside && v[1].inside && v[2].inside {
                        vp.emit(
                            [v[0].xy, v[1].xy, v[2].xy],
                            [v[0].key, v[1].key, v[2].key],
                            t,
                            &mut out,
                        );
                    } else {
                        // The clip-space corners again (the vertex pass's
                        // product, bit for bit) for the clipper: few
                        // triangles get here, so the vertices do not keep them.
                        let clip =
                            tri.map(|i| clip_from_world * ps.positions[i as usize].extend(1.0));
                        vp.setup(clip, t, &mut scratch, &mut out);
                    }
                    for rt in &out {
                        binner.bin(rt, &mut bins);
                    }
                }
                Bins { bins }
            })
            .collect()
    };
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
    let sample_rays = Rays::new(scene, w, h);
    let sub = crate::raster::SUBPIXEL as f32;
    let cut_out = |t: u32, x: u32, y: u32, o: &[i32; 2]| {
        let Some(c) = &coverage else { return false };
        let dir = sample_rays.dir(x as f32 + o[0] as f32 / sub, y as f32 + o[1] as f32 / sub);
        let [a, b, d] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
        let ray = chiaro_core::geometry::Ray::new(sample_rays.eye, dir);
        match chiaro_core::accel::intersect_triangle(&ray, a, b, d) {
            Some((t_hit, u, v)) => !c.covers(&chiaro_core::accel::Hit {
                t: t_hit,
                prim: t,
                u,
                v,
            }),
            None => false,
        }
    };
    let class_of = |t: u32| {
        class
            .get(ps.tri_material[t as usize].index())
            .copied()
            .unwrap_or(Class::Opaque)
    };
    // Shadow-volume polygons, clipped and binned like the scene's triangles
    // (their id is the light's slot among the per-sample counts).
    let (vol_bins, nl) = match &mut shadows {
        Shadows::Volume(v) => {
            let (bins, slots) =
                volume_bins(ps, settings, v, &binner, &vp_all, clip_from_world, spp);
            for w in bins.1.iter().flatten() {
                progress.warning(w);
            }
            (Some(bins.0), slots)
        }
        _ => (None, 0),
    };
    let counting = options.volume_counting;
    progress.advance(1);

    // 3. Visibility per tile.
    // Only the tiles that meet the crop window, and only their part of it.
    let active: Vec<(usize, TileRect, Rect)> = rects
        .iter()
        .enumerate()
        .filter_map(|(ti, &rect)| {
            let win = Rect {
                x0: rect.x.max(crop.x0),
                y0: rect.y.max(crop.y0),
                x1: (rect.x + rect.width).min(crop.x1),
                y1: (rect.y + rect.height).min(crop.y1),
            };
            (win.x0 < win.x1 && win.y0 < win.y1).then_some((ti, rect, win))
        })
        .collect();
    // Tiles outside the crop window stay black with infinite depth (the
    // shaded tiles overwrite every pixel of theirs).
    let mut drawn = vec![false; rects.len()];
    for &(ti, ..) in &active {
        drawn[ti] = true;
    }
    for (&rect, _) in rects.iter().zip(&drawn).filter(|(_, d)| !**d) {
        film.write_tile(&TilePixels::new(rect));
    }
    progress.begin("raster", active.len() as u64);
    let spp_us = spp as usize;
    // The depth buffer is only read while its tile is rasterized (and its
    // shadow volumes counted): one per job, reused from tile to tile, stays
    // in cache instead of a fresh one per tile being written out to memory.
    let vis: Vec<Option<TileVis>> = active
        .par_iter()
        .map_init(Vec::new, |key: &mut Vec<f32>, &(ti, rect, win)| {
            if progress.cancelled() {
                return None;
            }
            // Keys are interpolated from the tile's origin whatever the window.
            let r = Rect {
                x0: rect.x,
                y0: rect.y,
                x1: rect.x + rect.width,
                y1: rect.y + rect.height,
            };
            let n = (rect.width * rect.height) as usize * spp_us;
            key.clear();
            key.resize(n, f32::NEG_INFINITY);
            let mut ids = vec![NONE; n];
            let tw = rect.width as usize;
            let index = |x: u32, y: u32, s: usize| {
                (((y - rect.y) as usize) * tw + (x - rect.x) as usize) * spp_us + s
            };
            // Opaque and screen-door surfaces: the z-buffer.
            let mut blend: Vec<&RasterTri> = Vec::new();
            for c in &chunks {
                for rt in &c.bins[ti] {
                    // (No per-triangle material lookup when all are opaque.)
                    let class = if all_opaque {
                        Class::Opaque
                    } else {
                        class_of(rt.id)
                    };
                    let masked = coverage.as_ref().is_some_and(|c| c.is_masked(rt.id));
                    match class {
                        Class::Opaque if masked => {
                            rasterize_window(rt, r, win, &offsets, |x, y, s, k| {
                                let i = index(x, y, s);
                                if k > key[i] && !cut_out(rt.id, x, y, &offsets[s]) {
                                    key[i] = k;
                                    ids[i] = rt.id;
                                }
                            })
                        }
                        // The depth test as selects, not a branch (see
                        // rasterize_window_masked).
                        Class::Opaque => {
                            rasterize_window_masked(rt, r, win, &offsets, |x, y, s, k, covered| {
                                let i = index(x, y, s);
                                let nearer = covered & (k > key[i]);
                                key[i] = if nearer { k } else { key[i] };
                                ids[i] = if nearer { rt.id } else { ids[i] };
                            })
                        }
                        Class::ScreenDoor(kt) => {
                            rasterize_window(rt, r, win, &offsets, |x, y, s, k| {
                                let i = index(x, y, s);
                                if k > key[i] && dither_threshold(x, y, s as u32) >= kt {
                                    key[i] = k;
                                    ids[i] = rt.id;
                                }
                            })
                        }
                        Class::Blend(_) => blend.push(rt),
                    }
                }
            }
            // Transparent fragments in front of the opaque surface, sorted
            // per sample nearest first.
            let (start, frags) = if blend.is_empty() {
                (Vec::new(), Vec::new())
            } else {
                let mut list: Vec<(u32, f32, u32)> = Vec::new();
                for rt in blend {
                    rasterize_window(rt, r, win, &offsets, |x, y, s, k| {
                        let i = index(x, y, s);
                        if k > key[i] {
                            list.push((i as u32, k, rt.id));
                        }
                    });
                }
                list.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
                let mut start = vec![0u32; n + 1];
                for e in &list {
                    start[e.0 as usize + 1] += 1;
                }
                for i in 0..n {
                    start[i + 1] += start[i];
                }
                (start, list.into_iter().map(|e| (e.2, e.1)).collect())
            };
            let binned: usize = chunks.iter().map(|c| c.bins[ti].len()).sum();
            work.tile_triangles
                .fetch_add(binned as u64, Ordering::Relaxed);
            work.samples.fetch_add(n as u64, Ordering::Relaxed);
            work.fragments
                .fetch_add(frags.len() as u64, Ordering::Relaxed);
            let mut tv = TileVis {
                rect,
                window: win,
                ids,
                start,
                frags,
                counts: Vec::new(),
            };
            if let Some(vb) = &vol_bins {
                work.volume_tile_polygons
                    .fetch_add(vb.bins[ti].len() as u64, Ordering::Relaxed);
                count_volumes(&mut tv, key, vb, ti, r, &offsets, nl, counting);
            }
            progress.advance(1);
            Some(tv)
        })
        .collect();
    drop(chunks);
    let vis: Vec<TileVis> = vis
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or(CoreError::Cancelled)?;

    let object_mode: Vec<ShadeMode> = scene
        .objects
        .iter()
        .map(|o| o.shade_mode.unwrap_or(mode))
        .collect();
    let emitters = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
    let group_rays = (emitters.is_some() && !matches!(shadows, Shadows::None | Shadows::Ray(_))
        || matches!(&shadows, Shadows::Volume(v) if v.by_ray.contains(&true)))
    .then(|| RayShadows::new(ps));
    let ctx = Ctx {
        ps,
        settings,
        rays: Rays::new(scene, w, h),
        lighting: LocalLighting {
            lights: &ps.lights,
            area_samples: settings.light_samples.max(1),
            ambient: true,
            group: emitters.as_ref(),
        },
        group_rays,
        one_mode: object_mode
            .first()
            .copied()
            .filter(|&m| object_mode.iter().all(|&o| o == m)),
        object_mode,
        point_lighting: if matches!(shadows, Shadows::None) {
            PointLighting::new(&ps.lights, true)
        } else {
            None
        },
        bases: ps
            .scene
            .materials
            .iter()
            .map(SurfaceMaterial::from_material)
            .collect(),
        lean_frame: scene.environment.is_none() && settings.depth_cue.is_none(),
        one_material: ps.tri_material.first().copied().filter(|&m| {
            // Parallel, and stops at the first other material.
            ps.tri_material.par_iter().all(|&mt| mt == m)
        }),
        shadows,
        class,
    };

    // 4. Per-polygon and per-vertex illumination of visible flat/Gouraud triangles.
    progress.begin("poly", 1);
    let poly = poly_shading(&ctx, &vis);
    progress.advance(1);

    // 5. Shading. Each tile is written into the film as soon as it is
    // shaded, so that its buffers are freed and reused by the next tile
    // instead of every tile's pixels being alive (and fresh pages) at once.
    progress.begin("shade", vis.len() as u64);
    let film = Mutex::new(film);
    let kept: Mutex<Vec<(TileRect, Vec<Vec3>)>> = Mutex::new(Vec::new());
    // One triangle cache per shading job, kept from tile to tile.
    let finished = vis
        .par_iter()
        .try_for_each_init(TriCache::new, |cache, tv| {
            if progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            let (pixels, samples) = shade_tile(&ctx, &poly, tv, &offsets, tent, cache);
            film.lock()
                .unwrap_or_else(PoisonError::into_inner)
                .write_tile(&pixels);
            if tent {
                kept.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push((pixels.rect, samples));
            }
            progress.advance(1);
            Ok(())
        });
    finished?;
    let film = film.into_inner().unwrap_or_else(PoisonError::into_inner);
    let kept = kept.into_inner().unwrap_or_else(PoisonError::into_inner);
    if tent {
        tent_filter(film, &kept, crop, out_crop, &offsets);
    }
    Ok(())
}

/// Replaces the box-filtered colours of the pixels of `out` (the crop
/// window) by the tent filter of the samples of `region` (the crop window
/// and a one-pixel border, see [`crate::filter::tent_resolve`]); the pixels
/// of the border outside `out` are reset to black with infinite depth.
/// `tiles` are the shaded tiles with their sample colours (indexed like
/// [`TileVis::ids`]).
fn tent_filter(
    film: &mut Film,
    tiles: &[(TileRect, Vec<Vec3>)],
    region: Rect,
    out: Rect,
    offsets: &[[i32; 2]],
) {
    let spp = offsets.len();
    let rw = (region.x1 - region.x0) as usize;
    let rh = (region.y1 - region.y0) as usize;
    let mut samples = vec![Vec3::ZERO; rw * rh * spp];
    for (rect, colors) in tiles {
        let x0 = rect.x.max(region.x0);
        let x1 = (rect.x + rect.width).min(region.x1);
        let y0 = rect.y.max(region.y0);
        let y1 = (rect.y + rect.height).min(region.y1);
        if x0 >= x1 {
            continue;
        }
        let n = (x1 - x0) as usize * spp;
        for y in y0..y1 {
            let src = (((y - rect.y) * rect.width + (x0 - rect.x)) as usize) * spp;
            let dst = (((y - region.y0) as usize) * rw + (x0 - region.x0) as usize) * spp;
            if let (Some(d), Some(s)) = (samples.get_mut(dst..dst + n), colors.get(src..src + n)) {
                d.copy_from_slice(s);
            }
        }
    }
    let sub = crate::raster::SUBPIXEL as f32;
    let pos: Vec<[f32; 2]> = offsets
        .iter()
        .map(|o| [o[0] as f32 / sub, o[1] as f32 / sub])
        .collect();
    let colors = crate::filter::tent_resolve(&samples, region, &pos, out);
    let ow = (out.x1 - out.x0) as usize;
    for y in region.y0..region.y1 {
        for x in region.x0..region.x1 {
            let k = film.index(x, y);
            if (out.x0..out.x1).contains(&x) && (out.y0..out.y1).contains(&y) {
                film.color[k] = colors[((y - out.y0) as usize) * ow + (x - out.x0) as usize];
            } else {
                film.color[k] = Vec3::ZERO;
                film.depth[k] = f32::INFINITY;
                film.normal[k] = Vec3::ZERO;
            }
        }
    }
}

/// A vertex of the scene on the screen, when it is inside the clip volume
/// (16 bytes: the vertex pass writes and setup reads half a million).
struct ScreenVertex {
    /// Inside the near plane and the guard band: `xy` and `key` are valid.
    inside: bool,
    /// Snapped screen position (see [`Viewport::snap`]).
    xy: [i32; 2],
    /// Closeness key `1 / w`.
    key: f32,
}

/// Bins screen triangles into the tiles that meet the crop window.
#[derive(Clone, Copy)]
struct Binner {
    crop: Rect,
    tiles_x: u32,
    ntiles: usize,
}

impl Binner {
    fn empty(&self) -> Vec<Vec<RasterTri>> {
        vec![Vec::new(); self.ntiles]
    }

    /// The number of bins [`Self::bin`] puts `rt` in.
    fn copies(&self, rt: &RasterTri) -> u64 {
        match self.tile_range(rt) {
            Some([tx0, ty0, tx1, ty1]) => u64::from(tx1 - tx0 + 1) * u64::from(ty1 - ty0 + 1),
            None => 0,
        }
    }

    /// The tiles `[tx0, ty0, tx1, ty1]` (inclusive) whose part of the crop
    /// window the bounding box of `rt` meets, if any.
    #[inline]
    fn tile_range(&self, rt: &RasterTri) -> Option<[u32; 4]> {
        let b = rt.pixel_bounds();
        let c = self.crop;
        if b[2] < c.x0 as i32 || b[3] < c.y0 as i32 || b[0] >= c.x1 as i32 || b[1] >= c.y1 as i32 {
            return None;
        }
        Some([
            (b[0].max(c.x0 as i32) as u32) / TILE_SIZE,
            (b[1].max(c.y0 as i32) as u32) / TILE_SIZE,
            (b[2].min(c.x1 as i32 - 1) as u32) / TILE_SIZE,
            (b[3].min(c.y1 as i32 - 1) as u32) / TILE_SIZE,
        ])
    }

    /// Appends a copy of `rt` to the bin of every tile whose part of the
    /// crop window the bounding box of `rt` meets.
    #[inline]
    fn bin(&self, rt: &RasterTri, bins: &mut [Vec<RasterTri>]) {
        let Some([tx0, ty0, tx1, ty1]) = self.tile_range(rt) else {
            return;
        };
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                bins[(ty * self.tiles_x + tx) as usize].push(*rt);
            }
        }
    }
}

/// Triangles binned to tiles: `bins[tile]` holds, in setup order, a copy
/// of every triangle that meets the tile. Copies rather than indices into
/// one array of the chunk's triangles: the visibility pass then reads each
/// tile's triangles as one contiguous run, where through indices it
/// gathered every few triangles of an array of them all (set up long before
/// and no longer in cache), a cache miss per triangle. Most triangles of a
/// large mesh meet one tile, so the copies cost little more memory.
struct Bins {
    bins: Vec<Vec<RasterTri>>,
}

/// Relative tolerance of the shadow-volume depth comparison: a volume face
/// within it of a sample's depth counts as behind the sample, so the front
/// cap lying on a lit surface does not shadow it.
const VOLUME_EPS: f32 = 2e-5;

/// The bins of the shadow-volume triangles of the lights of `v` that fit
/// in the shadow share of the memory budget
/// ([`chiaro_core::budget::MemoryBudget::shadow_map_bytes`], the share the
/// shadow maps use), with the warnings to give, and the number of count
/// slots. Each light's volumes are counted before any is stored: its
/// binned copies plus one `i32` count per sample of the image; lights in
/// light order take what is left, and a light that does not fit uses
/// shadow rays (`v.by_ray`), named in a warning.
#[allow(clippy::too_many_arguments)]
fn volume_bins(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    v: &mut crate::shadow::VolumeShadows,
    binner: &Binner,
    vp: &Viewport,
    clip_from_world: Mat4,
    spp: u32,
) -> ((Bins, [Option<String>; 2]), usize) {
    let group = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
    let exact = crate::shadow::exact_lights(ps, group.as_ref());
    let vols = ShadowVolumes::new(ps, &exact);
    let nl = ps.lights.len();
    let points = u64::from(settings.width) * u64::from(settings.height) * u64::from(spp);
    // Per light: the binned copies its volumes would take.
    let needs: Vec<Option<u64>> = (0..nl)
        .into_par_iter()
        .map_init(Vec::new, |scratch, li| {
            if !vols.has_volumes(li) {
                return None;
            }
            let mut copies = 0u64;
            let mut out = Vec::new();
            vols.extrude_light(ps, li, &mut |tri| {
                let c = tri.map(|p| clip_from_world * p);
                out.clear();
                vp.setup_homogeneous(c, tri.map(|p| p.w), li as u32, scratch, &mut out);
                copies += out.iter().map(|rt| binner.copies(rt)).sum::<u64>();
            });
            Some(copies * std::mem::size_of::<RasterTri>() as u64 + points * 4)
        })
        .collect();
    let budget = settings.memory_budget().shadow_map_bytes();
    let (by_ray, bytes) = crate::shadow::plan_budget(&needs, budget);
    let refused: Vec<usize> = (0..nl).filter(|&li| by_ray[li]).collect();
    let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
    let over = (!refused.is_empty()).then(|| {
        let names: Vec<String> = refused.iter().map(usize::to_string).collect();
        let largest = refused.iter().filter_map(|&li| needs[li]).max().unwrap_or(0);
        format!(
            "shadow volumes: light{} {} use{} shadow rays: {} volumes ({:.1} MiB for the largest, binned at {}x{}) do not fit in the {:.1} MiB shadow budget (a quarter of the memory limit, at most 512 MiB) after the {:.1} MiB of the lights before them",
            if refused.len() > 1 { "s" } else { "" },
            names.join(", "),
            if refused.len() > 1 { "" } else { "s" },
            if refused.len() > 1 { "their" } else { "its" },
            mib(largest),
            settings.width,
            settings.height,
            mib(budget),
            mib(bytes),
        )
    });
    let mut slots = 0u32;
    for li in 0..nl {
        v.slot[li] = (needs[li].is_some() && !by_ray[li]).then(|| {
            slots += 1;
            slots - 1
        });
    }
    v.by_ray = by_ray;
    let mut out = Vec::new();
    let mut scratch = Vec::new();
    let mut bins = binner.empty();
    for li in 0..nl {
        let Some(slot) = v.slot[li] else { continue };
        vols.extrude_light(ps, li, &mut |tri| {
            let c = tri.map(|p| clip_from_world * p);
            out.clear();
            vp.setup_homogeneous(c, tri.map(|p| p.w), slot, &mut scratch, &mut out);
            for rt in &out {
                binner.bin(rt, &mut bins);
            }
        });
    }
    ((Bins { bins }, [vols.warning, over]), slots as usize)
}

/// Counts, per point of the tile (opaque samples and transparent
/// fragments) and per light, the shadow-volume faces between the eye and
/// the point (z-pass) or between the point and infinity (z-fail); a point
/// is in shadow where its count is not zero. `keys` is the tile's depth
/// buffer (the closeness key of each sample's nearest opaque surface,
/// `NEG_INFINITY` on the background), indexed like `tv.ids`.
#[allow(clippy::too_many_arguments)]
fn count_volumes(
    tv: &mut TileVis,
    keys: &[f32],
    vb: &Bins,
    ti: usize,
    r: Rect,
    offsets: &[[i32; 2]],
    nl: usize,
    counting: VolumeCounting,
) {
    let spp = offsets.len();
    let n = tv.ids.len();
    let points = n + tv.frags.len();
    let mut counts = vec![0i32; points * nl];
    let tw = tv.rect.width as usize;
    for rt in &vb.bins[ti] {
        let li = rt.id as usize;
        rasterize_window(rt, r, tv.window, offsets, |x, y, s, k| {
            let i = (((y - r.y0) as usize) * tw + (x - r.x0) as usize) * spp + s;
            let mut bump = |p: usize, key: f32| {
                if key == f32::NEG_INFINITY {
                    return;
                }
                let behind = k <= key * (1.0 + VOLUME_EPS);
                let d =
                    match (counting, behind, rt.back) {
                        (VolumeCounting::ZFail, true, true)
                        | (VolumeCounting::ZPass, false, false) => 1,
                        (VolumeCounting::ZFail, true, false)
                        | (VolumeCounting::ZPass, false, true) => -1,
                        _ => 0,
                    };
                counts[p * nl + li] += d;
            };
            bump(i, keys[i]);
            for f in tv.frag_range(i) {
                bump(n + f, tv.frags[f].1);
            }
        });
    }
    tv.counts = counts;
}

/// With the point-light model, the base material when every Gouraud
/// triangle has the same material and it has no emission texture (the one
/// texture vertex illumination reads).
fn uniform_gouraud<'c>(ctx: &'c Ctx<'_, '_>) -> Option<&'c SurfaceMaterial> {
    ctx.point_lighting.as_ref()?;
    let ps = ctx.ps;
    let is_gouraud = |t: usize| ctx.mode(t as u32) == ShadeMode::Gouraud;
    let first = (0..ps.triangles.len()).find(|&t| is_gouraud(t))?;
    let m = ps.tri_material[first];
    // (No scan when every triangle has the same material.)
    let uniform = ctx.one_material == Some(m)
        || ps
            .tri_material
            .par_iter()
            .enumerate()
            .all(|(t, &mt)| mt == m || !is_gouraud(t));
    let base = ctx.bases.get(m.index())?;
    (uniform && ps.material(m).emission_texture.is_none()).then_some(base)
}

/// With [`uniform_gouraud`]'s material, true when every sample of a
/// Gouraud triangle takes [`lean_sample`] (see [`Ctx::fetch_tri`]): a lean
/// frame, and the material untextured, one-sided and opaque (no fragment
/// is shaded by `shade_sample`), so its vertices are only ever needed on
/// the front side and can be illuminated on demand
/// ([`PolyShading::on_demand`]).
fn on_demand_gouraud(ctx: &Ctx<'_, '_>) -> bool {
    let ps = ctx.ps;
    let Some(t) = (0..ps.triangles.len() as u32).find(|&t| ctx.mode(t) == ShadeMode::Gouraud)
    else {
        return false;
    };
    let id = ps.tri_material[t as usize];
    let m = ps.material(id);
    ctx.lean_frame
        && !needs_footprint(m)
        && !m.two_sided
        && !matches!(ctx.class.get(id.index()), Some(Class::Blend(_)))
}

/// Step 4 when [`uniform_gouraud`] gives the base material: the vertices of
/// the visible Gouraud triangles, marked straight from the tiles' samples
/// (once per run of samples on one triangle, every mark a store of `true`
/// so that their order does not matter), each lit from its own position,
/// normal and colour ([`Ctx::vertex_split`]), the same values as the
/// general path of [`poly_shading`] gives them.
fn uniform_vertex_shading(
    ctx: &Ctx<'_, '_>,
    vis: &[TileVis],
    base: &SurfaceMaterial,
) -> PolyShading {
    let ps = ctx.ps;
    let nv = ps.positions.len();
    // Without two-sided materials no back is seen (Ctx::flipped).
    let two_sided = ps.scene.materials.iter().any(|m| m.two_sided);
    let flags = |n: usize| -> Vec<AtomicBool> { (0..n).map(|_| AtomicBool::new(false)).collect() };
    let front = flags(nv);
    let back = if two_sided { flags(nv) } else { Vec::new() };
    let (any_front, any_back) = vis
        .par_iter()
        .map(|tv| {
            let mut any = [false; 2];
            let mut mark = |id: u32| {
                if ctx.mode(id) != ShadeMode::Gouraud {
                    return;
                }
                let flip = two_sided && ctx.flipped(id);
                let side = if flip { &back } else { &front };
                for &v in &ps.triangles[id as usize] {
                    side[v as usize].store(true, Ordering::Relaxed);
                }
                any[usize::from(flip)] = true;
            };
            // A plain loop over the samples (an iterator chain costs more
            // per sample), once per run of samples on one triangle, and
            // not again for a triangle marked lately (its run on the row
            // above): a direct-mapped table of the last ids marked.
            let mut last = NONE;
            let mut recent = [NONE; 256];
            for &id in &tv.ids {
                if id != last {
                    last = id;
                    let r = &mut recent[id as usize & 255];
                    if id != NONE && *r != id {
                        *r = id;
                        mark(id);
                    }
                }
            }
            for f in &tv.frags {
                mark(f.0);
            }
            (any[0], any[1])
        })
        .reduce(|| (false, false), |a, b| (a.0 | b.0, a.1 | b.1));
    let shade_side = |need: &[AtomicBool], flip: bool| -> Vec<Split> {
        need.par_iter()
            .enumerate()
            .map(|(v, n)| {
                if n.load(Ordering::Relaxed) {
                    ctx.vertex_split(base, v, flip)
                } else {
                    Split::default()
                }
            })
            .collect()
    };
    let mut out = PolyShading::default();
    if any_front || any_back {
        out.vertex_front = shade_side(&front, false);
    }
    if any_back {
        out.vertex_back = shade_side(&back, true);
    }
    out
}

/// Step 4: finds the visible Gouraud triangles and illuminates their
/// vertices (flat polygons are illuminated with their [`TriData`]).
fn poly_shading(ctx: &Ctx<'_, '_>, vis: &[TileVis]) -> PolyShading {
    let ps = ctx.ps;
    let mut out = PolyShading::default();
    if ctx.object_mode.iter().all(|&m| m != ShadeMode::Gouraud) {
        return out;
    }
    if let Some(base) = uniform_gouraud(ctx) {
        if on_demand_gouraud(ctx) {
            return PolyShading {
                on_demand: Some(*base),
                ..PolyShading::default()
            };
        }
        return uniform_vertex_shading(ctx, vis, base);
    }
    // Visible triangles, marked in parallel (every mark stores `true`, so
    // the order of the stores does not matter).
    let seen: Vec<AtomicBool> = (0..ps.triangles.len())
        .into_par_iter()
        .map(|_| AtomicBool::new(false))
        .collect();
    vis.par_iter().for_each(|tv| {
        let ids = tv.ids.iter().copied().filter(|&id| id != NONE);
        for id in ids.chain(tv.frags.iter().map(|f| f.0)) {
            seen[id as usize].store(true, Ordering::Relaxed);
        }
    });
    // The visible Gouraud triangles in id order (deterministic) and whether
    // their back is seen.
    let nv = ps.positions.len();
    let gouraud: Vec<(u32, bool)> = (0..ps.triangles.len() as u32)
        .into_par_iter()
        .filter(|&t| seen[t as usize].load(Ordering::Relaxed) && ctx.mode(t) == ShadeMode::Gouraud)
        .map(|t| (t, ctx.flipped(t)))
        .collect();
    drop(seen);
    if gouraud.is_empty() {
        return out;
    }
    let mut need = vec![0u8; nv];
    for &(t, back) in &gouraud {
        for &v in &ps.triangles[t as usize] {
            need[v as usize] |= if back { 2 } else { 1 };
        }
    }
    // A representative (triangle, corner) for each vertex: the first
    // Gouraud triangle using it, visible or not (so that a vertex's colour
    // does not depend on what else is on screen, e.g. on the crop window);
    // vertices shared by Gouraud faces of different materials are shaded
    // per corner instead.
    let mut rep = vec![(u32::MAX, 0u8); nv];
    let mut vmat = vec![u32::MAX; nv];
    let mut conflict = vec![false; nv];
    for t in 0..ps.triangles.len() as u32 {
        if ctx.mode(t) != ShadeMode::Gouraud {
            continue;
        }
        let m = ps.tri_material[t as usize].0;
        for (k, &v) in ps.triangles[t as usize].iter().enumerate() {
            let v = v as usize;
            if rep[v].0 == u32::MAX {
                rep[v] = (t, k as u8);
            }
            if vmat[v] == u32::MAX {
                vmat[v] = m;
            } else if vmat[v] != m {
                conflict[v] = true;
            }
        }
    }
    let shade_side = |side: u8| -> Vec<Split> {
        (0..nv)
            .into_par_iter()
            .map(|v| {
                let (t, k) = rep[v];
                if need[v] & side == 0 || conflict[v] || t == u32::MAX {
                    Split::default()
                } else {
                    ctx.corner_split(t, k as usize, side == 2)
                }
            })
            .collect()
    };
    out.vertex_front = shade_side(1);
    out.vertex_back = if need.iter().any(|&n| n & 2 != 0) {
        shade_side(2)
    } else {
        Vec::new()
    };
    out.corners = gouraud
        .par_iter()
        .filter(|(t, _)| {
            ps.triangles[*t as usize]
                .iter()
                .any(|&v| conflict[v as usize])
        })
        .map(|&(t, back)| (t, [0, 1, 2].map(|k| ctx.corner_split(t, k, back))))
        .collect();
    out
}

/// What shading one sample produced.
#[derive(Clone, Copy)]
struct SampleResult {
    color: Vec3,
    depth: f32,
    normal: Vec3,
    /// The part of `color` from specular reflection (and emission), when
    /// asked for: what interpolated transparency keeps unattenuated.
    specular: Vec3,
    /// A BLEND point's straight-through transmission `1 - alpha` (its
    /// colour is premultiplied by alpha in the surface layer).
    coverage_kt: Option<Vec3>,
}

/// Step 5 for one tile: the box-filtered pixels and, with `keep_samples`,
/// the colour of every sample of the window (indexed like `tv.ids`; empty
/// otherwise) for the tent filter.
fn shade_tile<'a>(
    ctx: &Ctx<'a, '_>,
    poly: &PolyShading,
    tv: &TileVis,
    offsets: &[[i32; 2]],
    keep_samples: bool,
    cache: &mut TriCache<'a>,
) -> (TilePixels, Vec<Vec3>) {
    let rect = tv.rect;
    let mut out = TilePixels::new(rect);
    let spp = offsets.len();
    let mut kept = if keep_samples {
        vec![Vec3::ZERO; tv.ids.len()]
    } else {
        Vec::new()
    };
    let inv_spp = 1.0 / spp as f32;
    let sub = crate::raster::SUBPIXEL as f32;
    let nl = match &ctx.shadows {
        Shadows::Volume(v) => v.slot.iter().flatten().count(),
        _ => 0,
    };
    let counts_of = |p: usize| {
        (nl > 0)
            .then(|| tv.counts.get(p * nl..(p + 1) * nl))
            .flatten()
    };
    let env_background = ctx
        .ps
        .scene
        .environment
        .as_ref()
        .is_some_and(|e| e.as_background);
    let win = tv.window;
    // The row- and column-only parts of the sample directions (Rays::dir),
    // per window column (or row) and sample.
    let sample_x = |px: u32, o: &[i32; 2]| (rect.x + px) as f32 + o[0] as f32 / sub;
    let sample_y = |py: u32, o: &[i32; 2]| (rect.y + py) as f32 + o[1] as f32 / sub;
    let (wx0, wy0) = (win.x0 - rect.x, win.y0 - rect.y);
    let columns: Vec<Vec3A> = (wx0..win.x1 - rect.x)
        .flat_map(|px| {
            offsets
                .iter()
                .map(move |o| ctx.rays.column(sample_x(px, o)))
        })
        .collect();
    let rows: Vec<Vec3A> = (wy0..win.y1 - rect.y)
        .flat_map(|py| offsets.iter().map(move |o| ctx.rays.row(sample_y(py, o))))
        .collect();
    if spp == 1 && !keep_samples && tv.start.is_empty() {
        // One opaque sample per pixel, none kept: the loop below with its
        // sum and nearest-depth choice folded (the sanitised colour c is
        // 0 + c times 1; the sample is nearest when its depth is below
        // infinity), and the direction made only where it is read.
        let background = sanitize(ctx.ps.scene.background);
        let tw = rect.width as usize;
        let o = &offsets[0];
        for (py, &row) in (wy0..win.y1 - rect.y).zip(&rows) {
            let line = py as usize * tw;
            for (px, &column) in (wx0..win.x1 - rect.x).zip(&columns) {
                let pi = line + px as usize;
                let id = tv.ids[pi];
                if id == NONE {
                    out.color[pi] = if env_background {
                        let dir = Rays::dir_from(column, row);
                        sanitize(background_radiance(ctx.ps.scene, dir.into()))
                    } else {
                        background
                    };
                    continue;
                }
                let dir = Rays::dir_from(column, row);
                let td = ctx.tri_data(id, cache, poly);
                let r = if td.lean {
                    lean_sample(ctx, td, dir)
                } else {
                    let (sx, sy) = (sample_x(px, o), sample_y(py, o));
                    shade_sample(ctx, poly, td, sx, sy, dir, counts_of(pi), false)
                };
                out.color[pi] = sanitize(r.color);
                if r.depth < f32::INFINITY {
                    out.depth[pi] = r.depth;
                    out.normal[pi] = r.normal;
                }
            }
        }
        return (out, kept);
    }
    for (py, rows) in (wy0..win.y1 - rect.y).zip(rows.chunks_exact(spp)) {
        for (px, columns) in (wx0..win.x1 - rect.x).zip(columns.chunks_exact(spp)) {
            let pi = (py * rect.width + px) as usize;
            let mut sum = Vec3::ZERO;
            let mut best_depth = f32::INFINITY;
            let mut best_normal = Vec3::ZERO;
            for (s, ((o, &column), &row)) in offsets.iter().zip(columns).zip(rows).enumerate() {
                let sx = sample_x(px, o);
                let sy = sample_y(py, o);
                let dir = Rays::dir_from(column, row);
                let i = pi * spp + s;
                let id = tv.ids[i];
                let mut r = if id == NONE {
                    SampleResult {
                        color: if env_background {
                            background_radiance(ctx.ps.scene, dir.into())
                        } else {
                            ctx.ps.scene.background
                        },
                        depth: f32::INFINITY,
                        normal: Vec3::ZERO,
                        specular: Vec3::ZERO,
                        coverage_kt: None,
                    }
                } else {
                    let td = ctx.tri_data(id, cache, poly);
                    if td.lean {
                        lean_sample(ctx, td, dir)
                    } else {
                        shade_sample(ctx, poly, td, sx, sy, dir, counts_of(i), false)
                    }
                };
                // Transparent fragments, composited back to front.
                let n = tv.ids.len();
                for f in tv.frag_range(i).rev() {
                    let t = tv.frags[f].0;
                    let m = ctx.material_of(t);
                    let kt = m.transmit.clamp(Vec3::ZERO, Vec3::ONE);
                    let interpolated = ctx.class.get(ctx.ps.tri_material[t as usize].index())
                        == Some(&Class::Blend(TransparencyMode::Interpolated));
                    let td = ctx.tri_data(t, cache, poly);
                    let front =
                        shade_sample(ctx, poly, td, sx, sy, dir, counts_of(n + f), interpolated);
                    let behind = sanitize(r.color);
                    r.color = if let Some(kt) = front.coverage_kt {
                        // BLEND: I = alpha I_surface + (1 - alpha) I_behind, the
                        // first term already premultiplied.
                        front.color + kt * behind
                    } else if interpolated {
                        // Foley et al. 16.5.1: I = (1 - kt) I_front + kt I_behind,
                        // with the front surface's specular highlight kept whole.
                        (Vec3::ONE - kt) * (front.color - front.specular)
                            + front.specular
                            + kt * behind
                    } else {
                        // Filtered: I = I_front + kt Ot I_behind.
                        front.color + kt * behind
                    };
                    r.depth = front.depth;
                    r.normal = front.normal;
                }
                let c = sanitize(r.color);
                if keep_samples {
                    kept[i] = c;
                }
                sum += c;
                if r.depth < best_depth {
                    best_depth = r.depth;
                    best_normal = r.normal;
                }
            }
            out.color[pi] = sum * inv_spp;
            out.depth[pi] = best_depth;
            out.normal[pi] = best_normal;
        }
    }
    (out, kept)
}

/// [`shade_sample`] of an opaque sample (no specular part asked for) of a
/// [`TriData::lean`] triangle: untextured, one-sided, without reflection
/// map or depth cueing, and for Phong lit by `point_lighting` (flat and
/// Gouraud samples only interpolate what was lit with any lights and
/// shadows). The same
/// floating-point operations in the same order as `shade_sample` for that
/// case, without what it does not read (uv footprint, the view direction
/// of flat and Gouraud samples, per-corner lookups).
#[inline(always)]
fn lean_sample(ctx: &Ctx<'_, '_>, td: &TriData, dir: Vec3A) -> SampleResult {
    let b = td.bary(dir).unwrap_or(Vec2::splat(1.0 / 3.0));
    let (u, v) = (b.x, b.y);
    // Ctx::surface: w = 1 - u - v and the same interpolations.
    let w = 1.0 - u - v;
    let p = td.p[0] * w + td.p[1] * u + td.p[2] * v;
    let eye = Vec3A::from(ctx.rays.eye);
    let depth = (p - eye).length();
    let ng = td.ng;
    let ns = || {
        let ns = exact::try_normalize(td.n[0] * w + td.n[1] * u + td.n[2] * v).unwrap_or(ng);
        if ns.dot(ng) < 0.0 { ng } else { ns }
    };
    let (color, normal) = match td.mode {
        ShadeMode::Phong => {
            let ns = ns();
            let color = td.c[0] * w + td.c[1] * u + td.c[2] * v;
            // exact::normalize_or_zero(eye - p): |eye - p| is `depth`, bit
            // for bit (the same squares summed in the same order).
            let rcp = 1.0 / depth;
            let wo = if rcp.is_finite() && rcp > 0.0 {
                (eye - p) * rcp
            } else {
                Vec3A::ZERO
            };
            let sp = ShadingPoint {
                p: p.into(),
                n: ns.into(),
                ng: ng.into(),
                wo: wo.into(),
            };
            let c = match (&ctx.point_lighting, ctx.bases.get(td.material_id.index())) {
                (Some(pl), Some(base)) => pl.shade_kd(base, base.kd * Vec3::from(color), &sp),
                // Not reached: TriData::lean checked both.
                _ => Vec3::ZERO,
            };
            (c, ns)
        }
        ShadeMode::Gouraud => {
            // Split::lerp3 and `diffuse * 1 + rest` on the corners' SSE
            // vectors: the same operations lane by lane.
            let [a, b, c] = td.corners;
            let diffuse = a[0] * w + b[0] * u + c[0] * v;
            let rest = a[1] * w + b[1] * u + c[1] * v;
            ((diffuse * Vec3A::ONE + rest).into(), ns())
        }
        ShadeMode::Flat => (td.flat.diffuse * Vec3::ONE + td.flat.rest, ng),
    };
    SampleResult {
        color,
        depth,
        normal: normal.into(),
        specular: Vec3::ZERO,
        coverage_kt: None,
    }
}

/// Shades the sample at film position `(sx, sy)` (direction `dir`) where
/// triangle `t` is visible, by the triangle's shading mode. `counts` are the
/// point's shadow-volume counts per light; with `want_specular` the result
/// also holds its non-diffuse part.
#[allow(clippy::too_many_arguments)]
fn shade_sample(
    ctx: &Ctx<'_, '_>,
    poly: &PolyShading,
    td: &TriData,
    sx: f32,
    sy: f32,
    dir: Vec3A,
    counts: Option<&[i32]>,
    want_specular: bool,
) -> SampleResult {
    let ps = ctx.ps;
    let eye = ctx.rays.eye;
    let t = td.t;
    let [i0, i1, i2] = td.idx;
    // Perspective-correct barycentrics of the sample and of its neighbours.
    let third = Vec2::splat(1.0 / 3.0);
    let b = td.bary(dir).unwrap_or(third);
    let material = td.material;
    let needs_footprint = td.textured;
    let hit = ctx.surface(td, b.x, b.y, needs_footprint, td.mode != ShadeMode::Flat);
    let (duv_dx, duv_dy) = if needs_footprint {
        let uv_at = |x: f32, y: f32| {
            let bb = td.bary(ctx.rays.dir(x, y).into()).unwrap_or(b);
            ps.uvs[i0] * (1.0 - bb.x - bb.y) + ps.uvs[i1] * bb.x + ps.uvs[i2] * bb.y
        };
        let dx = uv_at(sx + 1.0, sy) - hit.uv;
        let dy = uv_at(sx, sy + 1.0) - hit.uv;
        if dx.is_finite() && dy.is_finite() {
            (dx, dy)
        } else {
            (Vec2::ZERO, Vec2::ZERO)
        }
    } else {
        (Vec2::ZERO, Vec2::ZERO)
    };
    let (eye_a, p_a) = (Vec3A::from(eye), Vec3A::from(hit.p));
    // Flat and Gouraud samples read the view direction only to tell the
    // back of a two-sided surface and for the reflection map.
    let wo = if td.mode == ShadeMode::Phong
        || material.two_sided
        || ctx.ps.scene.environment.is_some()
    {
        Vec3::from(exact::normalize_or_zero(eye_a - p_a))
    } else {
        Vec3::ZERO
    };
    let flip = material.two_sided && hit.ng.dot(wo) < 0.0;
    let sign = if flip { -1.0 } else { 1.0 };
    let mut specular = Vec3::ZERO;
    let mut coverage_kt = None;
    let (color, n, kr) = match td.mode {
        ShadeMode::Phong if !needs_footprint && !want_specular && ctx.point_lighting.is_some() => {
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
                // Not reached: the arm's guard checked `point_lighting`.
                None => ctx.illuminate(
                    t,
                    None,
                    &SurfaceMaterial {
                        kd: base.kd * hit.color,
                        ..*base
                    },
                    &sp,
                    counts,
                ),
            };
            (c, n, base.kr)
        }
        ShadeMode::Phong => {
            let (sm, n) = if needs_footprint {
                // The surface layer: textures, normal and bump maps.
                let (dpdu, dpdv) = ps.triangle_dpduv(t);
                let ss = ps.shading_surface_at(hit, dpdu, dpdv, duv_dx, duv_dy);
                if material.alpha_mode == AlphaMode::Blend {
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
            let pixel = (sx.fract() == 0.5 && sy.fract() == 0.5 && sx >= 0.0 && sy >= 0.0)
                .then_some((sx as u32, sy as u32));
            let c = ctx.illuminate(t, pixel, &sm, &sp, counts);
            if want_specular {
                let diffuse_only = SurfaceMaterial {
                    ks: Vec3::ZERO,
                    emission: Vec3::ZERO,
                    ..sm
                };
                specular = c - ctx.illuminate(t, pixel, &diffuse_only, &sp, counts);
            }
            (c, n, sm.kr)
        }
        ShadeMode::Gouraud => {
            let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
            // (No hashing when no triangle needed per-corner values.)
            let corners = if poly.corners.is_empty() {
                None
            } else {
                poly.corners.get(&t)
            };
            let split = match corners {
                Some(c) => Split::lerp3(*c, w),
                None => {
                    let table = if flip {
                        &poly.vertex_back
                    } else {
                        &poly.vertex_front
                    };
                    let get = |i: usize| table.get(i).copied().unwrap_or_default();
                    Split::lerp3([get(i0), get(i1), get(i2)], w)
                }
            };
            // diffuse_texture_factor: one without a texture.
            let tex = if material.texture.is_some() {
                let tc = PreparedScene::tex_coord(&hit, duv_dx, duv_dy);
                ps.diffuse_texture_factor(hit.material, &tc)
            } else {
                Vec3::ONE
            };
            specular = split.rest;
            (
                split.diffuse * tex + split.rest,
                hit.ns * sign,
                material.reflect,
            )
        }
        ShadeMode::Flat => {
            let split = td.flat;
            let tex = if material.texture.is_some() {
                let tc = PreparedScene::tex_coord(&hit, duv_dx, duv_dy);
                ps.diffuse_texture_factor(hit.material, &tc)
            } else {
                Vec3::ONE
            };
            specular = split.rest;
            (
                split.diffuse * tex + split.rest,
                hit.ng * sign,
                material.reflect,
            )
        }
    };
    let mut color = color;
    // Reflection map: the environment in the mirror direction, weighted by kr.
    if ctx.ps.scene.environment.is_some() && kr.max_element() > 0.0 {
        color += kr * environment_radiance(ctx.ps.scene, reflect(wo, n));
    }
    let depth = (p_a - eye_a).length();
    if let Some(cue) = &ctx.settings.depth_cue {
        color = depth_cue(color, depth, cue);
    }
    SampleResult {
        color,
        depth,
        normal: n,
        specular,
        coverage_kt,
    }
}

#[cfg(test)]
#[path = "render_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "shadow_tests.rs"]
mod shadow_tests;
