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
//! 4. *Vertex and polygon illumination* for flat and Gouraud triangles that
//!    are visible somewhere, once per vertex (Gouraud) or per polygon (flat).
//! 5. *Shading* (parallel over tiles): each visible sample is shaded once
//!    (deferred shading), the samples of a pixel are averaged (box filter).
//!
//! Attributes are interpolated with *perspective-correct* barycentrics,
//! computed per sample by intersecting the sample's eye ray with the plane of
//! the visible triangle (the "visibility buffer" of Burns and Hunt 2013). For
//! the pixel-centre ray this is exactly the barycentric interpolation a ray
//! tracer performs, so Phong-mode images equal a ray-cast shading of the same
//! [`PreparedScene`] within float noise. The same intersection one pixel to
//! the right and below gives the screen-space uv derivatives for mip-mapping.
//!
//! Illumination is always [`shade_local`] with every light sample visible
//! (no shadows yet), area lights sampled at the strata centres.
//! Flat and Gouraud illumination is split into a part linear in the diffuse
//! colour and the rest (specular, emission), so that a diffuse texture can
//! modulate the interpolated diffuse light per pixel while the illumination
//! itself stays per polygon or per vertex (like OpenGL's separate specular
//! colour).

use crate::raster::{DepthKey, RasterTri, Rect, Viewport, rasterize, sample_offsets};
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, TilePixels, TileRect, tiles};
use chiaro_core::prepared::{PrepareOptions, PreparedScene, SurfaceHit};
use chiaro_core::progress::Progress;
use chiaro_core::scene::{Material, RenderSettings, Scene, Severity, ShadeMode, Technique};
use chiaro_core::shading::texture::{background_radiance, environment_radiance};
use chiaro_core::shading::{
    LocalLighting, ShadingPoint, SurfaceMaterial, depth_cue, reflect, sanitize, shade_local,
};
use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::collections::HashMap;

/// Side of the square screen tiles, in pixels.
pub const TILE_SIZE: u32 = 64;
/// Id of samples no triangle covers.
const NONE: u32 = u32::MAX;

/// Renders `scene` by scan conversion with `settings.technique` (flat,
/// Gouraud or Phong; an object's `shade_mode` overrides it).
///
/// Returns the film: linear RGB radiance (the `samples` of each pixel
/// box-filtered), the distance from the eye to the nearest surface along the
/// pixel's sample ray (`INFINITY` on the background) and the world-space
/// shading normal (zero on the background).
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
        let ndc_x = (2.0 * x / self.width - 1.0) * self.tan_half * self.aspect;
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.tan_half;
        (self.forward + ndc_x * self.right + ndc_y * self.up).normalize()
    }
}

/// Barycentrics `(u, v)` of vertices 1 and 2 where the ray `o + t d` meets the
/// plane of the triangle (Moller and Trumbore 1997, without the inside test):
/// the perspective-correct barycentrics of the sample. `None` when the ray
/// is parallel to the plane.
#[inline]
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
        Split {
            diffuse: s[0].diffuse * w.x + s[1].diffuse * w.y + s[2].diffuse * w.z,
            rest: s[0].rest * w.x + s[1].rest * w.y + s[2].rest * w.z,
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
}

impl Ctx<'_, '_> {
    fn mode(&self, t: u32) -> ShadeMode {
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

    /// `shade_local` with every light visible and area lights sampled at the
    /// strata centres.
    #[inline]
    fn illuminate(&self, m: &SurfaceMaterial, sp: &ShadingPoint) -> Vec3 {
        shade_local(
            m,
            sp,
            &self.lighting,
            |_, _| Vec2::splat(0.5),
            |_, _| Vec3::ONE,
        )
    }

    /// The illumination split for flat and Gouraud shading.
    fn illuminate_split(&self, m: &SurfaceMaterial, sp: &ShadingPoint) -> Split {
        let total = self.illuminate(m, sp);
        let no_diffuse = SurfaceMaterial {
            kd: Vec3::ZERO,
            ..*m
        };
        let rest = self.illuminate(&no_diffuse, sp);
        Split {
            diffuse: total - rest,
            rest,
        }
    }

    /// Untextured material (vertex colour applied) at a surface point: the
    /// diffuse texture is applied per pixel by flat and Gouraud shading.
    fn untextured_material(&self, hit: &SurfaceHit) -> SurfaceMaterial {
        let m = self.ps.material(hit.material);
        let mut sm = SurfaceMaterial::from_material(m);
        sm.kd *= hit.color;
        if let Some(t) = m.emission_texture {
            let tc = PreparedScene::tex_coord(hit, Vec2::ZERO, Vec2::ZERO);
            sm.emission *= self.ps.eval_texture(t, &tc).truncate();
        }
        sm
    }

    /// Flat shading of triangle `t`: once, at the centroid, with the face normal.
    fn flat_split(&self, t: u32) -> Split {
        let third = 1.0 / 3.0;
        let hit = self.ps.triangle_surface(t, third, third);
        let mut n = hit.ng;
        if self.flipped(t) {
            n = -n;
        }
        let wo = (self.rays.eye - hit.p).normalize_or_zero();
        let sp = ShadingPoint {
            p: hit.p,
            n,
            ng: n,
            wo,
        };
        self.illuminate_split(&self.untextured_material(&hit), &sp)
    }

    /// Gouraud illumination at corner `k` of triangle `t`, on the front side
    /// or (for the back of a two-sided surface) the back side.
    fn corner_split(&self, t: u32, k: usize, back: bool) -> Split {
        let (u, v) = match k {
            0 => (0.0, 0.0),
            1 => (1.0, 0.0),
            _ => (0.0, 1.0),
        };
        let hit = self.ps.triangle_surface(t, u, v);
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
        self.illuminate_split(&self.untextured_material(&hit), &sp)
    }
}

/// Per-triangle results of the visibility pass that flat and Gouraud
/// shading need.
#[derive(Default)]
struct PolyShading {
    /// Flat: one split per triangle (only visible ones are computed).
    flat: HashMap<u32, Split>,
    /// Gouraud: per vertex, front side.
    vertex_front: Vec<Split>,
    /// Gouraud: per vertex, back side (two-sided surfaces seen from behind).
    vertex_back: Vec<Split>,
    /// Gouraud triangles whose corners could not use shared vertex values
    /// (a vertex shared by faces of different materials).
    corners: HashMap<u32, [Split; 3]>,
}

/// One tile's visibility: the triangle id of each sample.
struct TileVis {
    rect: TileRect,
    ids: Vec<u32>,
}

/// Renders an already prepared scene with the default shading `mode`.
/// See [`render`]; the prepared scene must come from
/// `PrepareOptions { analytic_spheres: false, .. }` (spheres tessellated).
///
/// # Errors
/// [`CoreError::Cancelled`] when the progress asks to stop;
/// [`CoreError::InvalidScene`] for a bad image size.
pub fn render_prepared(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    mode: ShadeMode,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    check_size(settings)?;
    let scene = ps.scene;
    let (w, h) = (settings.width, settings.height);
    let spp = settings.samples.clamp(1, 64);
    let offsets = sample_offsets(spp);
    let cam = &scene.camera;
    let clip_from_world = cam.projection_matrix(w as f32 / h as f32) * cam.view_matrix();

    // 1. Vertices to clip space.
    let clip: Vec<Vec4> = ps
        .positions
        .par_iter()
        .map(|p| clip_from_world * p.extend(1.0))
        .collect();

    // 2. Setup and binning over fixed chunks (deterministic order).
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
    let cull_material: Vec<bool> = scene
        .materials
        .iter()
        .map(|m| settings.cull_backfaces && !m.two_sided)
        .collect();
    let nt = ps.triangles.len();
    let chunk = nt.div_ceil(256).max(4096);
    struct Bins {
        tris: Vec<RasterTri>,
        bins: Vec<Vec<u32>>,
    }
    progress.begin("setup", 1);
    let chunks: Vec<Bins> = ps
        .triangles
        .par_chunks(chunk)
        .enumerate()
        .map(|(ci, tris)| {
            let mut out = Vec::with_capacity(tris.len());
            let mut scratch = Vec::new();
            let mut bins: Vec<Vec<u32>> = vec![Vec::new(); rects.len()];
            for (k, tri) in tris.iter().enumerate() {
                let t = (ci * chunk + k) as u32;
                let cull = cull_material
                    .get(ps.tri_material[t as usize].index())
                    .copied()
                    .unwrap_or(settings.cull_backfaces);
                let vp = if cull { &vp_cull } else { &vp_all };
                let c = tri.map(|i| clip[i as usize]);
                let first = out.len();
                vp.setup(c, t, &mut scratch, &mut out);
                for (j, rt) in out.iter().enumerate().skip(first) {
                    let b = rt.pixel_bounds();
                    if b[2] < 0 || b[3] < 0 || b[0] >= w as i32 || b[1] >= h as i32 {
                        continue;
                    }
                    let tx0 = (b[0].max(0) as u32) / TILE_SIZE;
                    let ty0 = (b[1].max(0) as u32) / TILE_SIZE;
                    let tx1 = (b[2].min(w as i32 - 1) as u32) / TILE_SIZE;
                    let ty1 = (b[3].min(h as i32 - 1) as u32) / TILE_SIZE;
                    for ty in ty0..=ty1 {
                        for tx in tx0..=tx1 {
                            bins[(ty * tiles_x + tx) as usize].push(j as u32);
                        }
                    }
                }
            }
            Bins { tris: out, bins }
        })
        .collect();
    drop(clip);
    progress.advance(1);

    // 3. Visibility per tile.
    progress.begin("raster", rects.len() as u64);
    let spp_us = spp as usize;
    let vis: Vec<Option<TileVis>> = rects
        .par_iter()
        .enumerate()
        .map(|(ti, &rect)| {
            if progress.cancelled() {
                return None;
            }
            let n = (rect.width * rect.height) as usize * spp_us;
            let mut key = vec![f32::NEG_INFINITY; n];
            let mut ids = vec![NONE; n];
            let r = Rect {
                x0: rect.x,
                y0: rect.y,
                x1: rect.x + rect.width,
                y1: rect.y + rect.height,
            };
            let tw = rect.width as usize;
            for c in &chunks {
                for &j in &c.bins[ti] {
                    let rt = &c.tris[j as usize];
                    rasterize(rt, r, &offsets, |x, y, s, k| {
                        let i = (((y - rect.y) as usize) * tw + (x - rect.x) as usize) * spp_us + s;
                        if k > key[i] {
                            key[i] = k;
                            ids[i] = rt.id;
                        }
                    });
                }
            }
            progress.advance(1);
            Some(TileVis { rect, ids })
        })
        .collect();
    drop(chunks);
    let vis: Vec<TileVis> = vis
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or(CoreError::Cancelled)?;

    let ctx = Ctx {
        ps,
        settings,
        rays: Rays::new(scene, w, h),
        lighting: LocalLighting {
            lights: &ps.lights,
            area_samples: settings.light_samples.max(1),
            ambient: true,
        },
        object_mode: scene
            .objects
            .iter()
            .map(|o| o.shade_mode.unwrap_or(mode))
            .collect(),
    };

    // 4. Per-polygon and per-vertex illumination of visible flat/Gouraud triangles.
    let poly = poly_shading(&ctx, &vis);

    // 5. Shading.
    progress.begin("shade", vis.len() as u64);
    let shaded: Vec<Option<TilePixels>> = vis
        .par_iter()
        .map(|tv| {
            if progress.cancelled() {
                return None;
            }
            let t = shade_tile(&ctx, &poly, tv, &offsets);
            progress.advance(1);
            Some(t)
        })
        .collect();
    let mut film = Film::new(w, h);
    for t in shaded {
        film.write_tile(&t.ok_or(CoreError::Cancelled)?);
    }
    Ok(film)
}

/// Step 4: finds the visible flat and Gouraud triangles and illuminates their
/// polygons or vertices.
fn poly_shading(ctx: &Ctx<'_, '_>, vis: &[TileVis]) -> PolyShading {
    let ps = ctx.ps;
    let mut out = PolyShading::default();
    if ctx.object_mode.iter().all(|&m| m == ShadeMode::Phong) {
        return out;
    }
    // Visible triangles (deduplicated, sorted: deterministic).
    let mut seen = vec![false; ps.triangles.len()];
    for tv in vis {
        for &id in &tv.ids {
            if id != NONE {
                seen[id as usize] = true;
            }
        }
    }
    let visible: Vec<u32> = (0..ps.triangles.len() as u32)
        .filter(|&t| seen[t as usize])
        .collect();
    drop(seen);
    // Flat: one illumination per polygon.
    out.flat = visible
        .par_iter()
        .filter(|&&t| ctx.mode(t) == ShadeMode::Flat)
        .map(|&t| (t, ctx.flat_split(t)))
        .collect();
    // Gouraud: which vertex sides are needed, and vertices shared across materials.
    let nv = ps.positions.len();
    let mut need = vec![0u8; nv];
    let mut vmat = vec![u32::MAX; nv];
    let mut conflict = vec![false; nv];
    let gouraud: Vec<(u32, bool)> = visible
        .iter()
        .filter(|&&t| ctx.mode(t) == ShadeMode::Gouraud)
        .map(|&t| (t, ctx.flipped(t)))
        .collect();
    for &(t, back) in &gouraud {
        let m = ps.tri_material[t as usize].0;
        for &v in &ps.triangles[t as usize] {
            let v = v as usize;
            need[v] |= if back { 2 } else { 1 };
            if vmat[v] == u32::MAX {
                vmat[v] = m;
            } else if vmat[v] != m {
                conflict[v] = true;
            }
        }
    }
    if gouraud.is_empty() {
        return out;
    }
    // A representative (triangle, corner) for each vertex, for its material.
    let mut rep = vec![(u32::MAX, 0u8); nv];
    for &(t, _) in &gouraud {
        for (k, &v) in ps.triangles[t as usize].iter().enumerate() {
            if rep[v as usize].0 == u32::MAX {
                rep[v as usize] = (t, k as u8);
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
}

/// Step 5 for one tile.
fn shade_tile(
    ctx: &Ctx<'_, '_>,
    poly: &PolyShading,
    tv: &TileVis,
    offsets: &[[i32; 2]],
) -> TilePixels {
    let rect = tv.rect;
    let mut out = TilePixels::new(rect);
    let spp = offsets.len();
    let inv_spp = 1.0 / spp as f32;
    let sub = crate::raster::SUBPIXEL as f32;
    for py in 0..rect.height {
        for px in 0..rect.width {
            let pi = (py * rect.width + px) as usize;
            let mut sum = Vec3::ZERO;
            let mut best_depth = f32::INFINITY;
            let mut best_normal = Vec3::ZERO;
            for (s, o) in offsets.iter().enumerate() {
                let sx = (rect.x + px) as f32 + o[0] as f32 / sub;
                let sy = (rect.y + py) as f32 + o[1] as f32 / sub;
                let id = tv.ids[pi * spp + s];
                let dir = ctx.rays.dir(sx, sy);
                let r = if id == NONE {
                    SampleResult {
                        color: background_radiance(ctx.ps.scene, dir),
                        depth: f32::INFINITY,
                        normal: Vec3::ZERO,
                    }
                } else {
                    shade_sample(ctx, poly, id, sx, sy, dir)
                };
                sum += sanitize(r.color);
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
    out
}

/// Shades the sample at film position `(sx, sy)` (direction `dir`) where
/// triangle `t` is visible, by the triangle's shading mode.
fn shade_sample(
    ctx: &Ctx<'_, '_>,
    poly: &PolyShading,
    t: u32,
    sx: f32,
    sy: f32,
    dir: Vec3,
) -> SampleResult {
    let ps = ctx.ps;
    let eye = ctx.rays.eye;
    let [i0, i1, i2] = ps.triangles[t as usize].map(|i| i as usize);
    let (p0, p1, p2) = (ps.positions[i0], ps.positions[i1], ps.positions[i2]);
    // Perspective-correct barycentrics of the sample and of its neighbours.
    let third = Vec2::splat(1.0 / 3.0);
    let b = ray_plane_bary(eye, dir, p0, p1, p2).unwrap_or(third);
    let hit = ps.triangle_surface(t, b.x, b.y);
    let material = ps.material(hit.material);
    let needs_footprint = material.texture.is_some()
        || material.bump.is_some()
        || material.normal_map.is_some()
        || material.emission_texture.is_some();
    let (duv_dx, duv_dy) = if needs_footprint {
        let uv_at = |x: f32, y: f32| {
            let bb = ray_plane_bary(eye, ctx.rays.dir(x, y), p0, p1, p2).unwrap_or(b);
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
    let wo = (eye - hit.p).normalize_or_zero();
    let flip = material.two_sided && hit.ng.dot(wo) < 0.0;
    let sign = if flip { -1.0 } else { 1.0 };
    let (color, n, kr) = match ctx.mode(t) {
        ShadeMode::Phong => {
            let sm = ps.surface_material_lod(&hit, duv_dx, duv_dy);
            let mut n = hit.ns;
            if material.bump.is_some() || material.normal_map.is_some() {
                let (dpdu, dpdv) = ps.triangle_dpduv(t);
                n = ps.perturbed_normal(&hit, n, dpdu, dpdv, duv_dx, duv_dy);
            }
            let n = n * sign;
            let sp = ShadingPoint {
                p: hit.p,
                n,
                ng: hit.ng * sign,
                wo,
            };
            (ctx.illuminate(&sm, &sp), n, sm.kr)
        }
        ShadeMode::Gouraud => {
            let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
            let split = match poly.corners.get(&t) {
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
            let tc = PreparedScene::tex_coord(&hit, duv_dx, duv_dy);
            let tex = ps.diffuse_texture_factor(hit.material, &tc);
            (
                split.diffuse * tex + split.rest,
                hit.ns * sign,
                material.reflect,
            )
        }
        ShadeMode::Flat => {
            let split = poly.flat.get(&t).copied().unwrap_or_default();
            let tex = if material.texture.is_some() {
                let tc = PreparedScene::tex_coord(&hit, duv_dx, duv_dy);
                ps.diffuse_texture_factor(hit.material, &tc)
            } else {
                Vec3::ONE
            };
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
    let depth = (hit.p - eye).length();
    if let Some(cue) = &ctx.settings.depth_cue {
        color = depth_cue(color, depth, cue);
    }
    SampleResult {
        color,
        depth,
        normal: n,
    }
}

#[cfg(test)]
#[path = "render_tests.rs"]
mod tests;
