//! Light visibility for the scan converter: the one thing a technique
//! supplies to [`chiaro_core::shading::shade_local`].
//!
//! Three methods, chosen by [`ShadowMethod`]:
//! - **Shadow rays** ([`ShadowMethod::Ray`]): a segment from the point to the
//!   light sample against the scene BVH; transparent surfaces multiply the
//!   light by their transmit colour, by the one query the Whitted tracer
//!   also calls ([`chiaro_core::shadow`]).
//! - **Shadow z-buffers** ([`ShadowMethod::Map`], Williams 1978, the seeds'
//!   "two-pass z-buffer"): a depth image of the scene from each light
//!   (orthographic for directional lights, perspective for narrow spots, a
//!   cube of six 90-degree views for point lights and wide spots), and for
//!   area lights one cube map per light sample so that the penumbra is the
//!   average of several hard shadows (the "several shadow maps over the
//!   light's area" of Heckbert and Herf 1997). See [`ShadowMaps`].
//! - **Shadow volumes** ([`ShadowMethod::Volume`], Crow 1977): built here
//!   ([`ShadowVolumes`]) and counted per visible sample by the renderer;
//!   transparent casters tint by shadow rays that see only them.
//!
//! Shadow maps are sized against the job's shadow-map share
//! ([`chiaro_core::budget::MemoryBudget::shadow_map_bytes`] of
//! [`RenderSettings::memory_budget`]) before anything is allocated; lights
//! past it use shadow rays, and a warning says which.
//!
//! Objects with `casts_shadows = false` cast no shadow in any method.

use crate::raster::{DepthKey, RasterTri, Rect, Viewport, rasterize};
use chiaro_core::accel::Accelerator;
use chiaro_core::accel::alpha::{AlphaTested, Coverage};
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::accel::{Hit, intersect_triangle};
use chiaro_core::geometry::{Frame, Ray, offset_ray_origin};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{
    AreaShape, Light, RenderSettings, SHADOW_MAP_RESOLUTIONS, ShadeMode, ShadowMapSettings,
    ShadowMethod,
};
use chiaro_core::shading::{EmitterGroup, LightSample, samples_for_light, stratum};
pub(crate) use chiaro_core::shadow::Blocker;
use chiaro_core::shadow::ShadowCasters;
use glam::{Mat4, Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::collections::HashMap;

/// Per-triangle blocker classes of a prepared scene (the classes of the
/// shared shadow-ray query, [`ShadowCasters`]).
pub(crate) fn blockers(ps: &PreparedScene<'_>) -> Vec<Blocker> {
    let casters = ShadowCasters::new(ps);
    (0..ps.triangles.len() as u32)
        .map(|t| casters.blocker(t))
        .collect()
}

/// The light visibility of one render.
pub(crate) enum Shadows {
    /// Every light sample is visible.
    None,
    /// Shadow rays through the BVH.
    Ray(RayShadows),
    /// Shadow z-buffers.
    Map(ShadowMaps),
    /// Shadow volumes of the opaque casters: the per-sample counts live in
    /// the renderer's tiles. Transparent casters (a count cannot carry a
    /// colour) tint by shadow rays that see only them, when there are any.
    Volume(VolumeShadows),
    /// Atherton-Weiler-Greenberg object-precision shadows of the opaque
    /// casters: the lit fragments of every triangle, one set per light
    /// (`None` for ambient lights). Transparent casters tint as in `Volume`.
    Object {
        /// Per light (`None` for ambient lights).
        lights: Vec<Option<crate::object_shadows::ObjectShadows>>,
        /// Shadow rays that see only the transparent casters, if any.
        transparent: Option<RayShadows>,
    },
    /// Bouknight-Kelley scan-line shadows of the opaque casters: per light,
    /// the lit/shadowed classification of every pixel centre from the
    /// scan-line pass, with object-precision fragments for samples that are
    /// not pixel centres (supersampling, vertices) — both exact, so they
    /// agree. Transparent casters tint as in `Volume`.
    Scanline {
        /// Per light (`None` for ambient lights).
        lines: Vec<Option<crate::scanline_shadows::ScanlineShadows>>,
        /// Per light (`None` for ambient lights).
        fallback: Vec<Option<ExactFallback>>,
        /// Shadow rays that see only the transparent casters, if any.
        transparent: Option<RayShadows>,
    },
}

/// Where scan-line shadows get the visibility of a point that is not the
/// pixel centre the scan-line pass classified (sub-samples, flat and
/// Gouraud illumination points, or a pixel whose centre the scan-line
/// pass saw on another triangle than the rasterizer did, at a tie on a
/// shared edge).
pub(crate) enum ExactFallback {
    /// The Atherton-Weiler-Greenberg lit fragments of every triangle: built
    /// when a render shades points other than pixel centres.
    Fragments(crate::object_shadows::ObjectShadows),
    /// A shadow ray from the point to the light's shadow-casting point (or
    /// along its direction), blocked by any shadow-casting triangle: the
    /// same exact point classification as the fragments, for the few
    /// tie pixels of a one-sample Phong render, without building
    /// fragments for every triangle (the most expensive part of the
    /// method on large scenes).
    Ray {
        /// The scene's BVH, shared by the lights.
        bvh: std::sync::Arc<SceneBvh>,
        /// Per triangle: whether it casts shadows, and its face normal.
        tris: std::sync::Arc<Vec<(bool, Vec3)>>,
        /// The light's shadow-casting point or direction.
        light: crate::object_shadows::LightGeom,
    },
}

impl ExactFallback {
    /// 1 if world point `p` on triangle `tri` sees the light, else 0.
    pub(crate) fn lit_fraction(&self, tri: u32, p: Vec3) -> f32 {
        match self {
            ExactFallback::Fragments(o) => o.lit_fraction(tri, p),
            ExactFallback::Ray { bvh, tris, light } => {
                let Some(&(_, ng)) = tris.get(tri as usize) else {
                    return 1.0;
                };
                let ray = match *light {
                    crate::object_shadows::LightGeom::Point(q) => {
                        let q = Vec3::from(q);
                        Ray::segment(offset_ray_origin(p, ng, q - p), q)
                    }
                    crate::object_shadows::LightGeom::Directional(d) => {
                        let d = Vec3::from(d);
                        Ray::new(offset_ray_origin(p, ng, d), d)
                    }
                };
                let blocked = bvh.visit_hits(&ray, |h| {
                    h.prim != tri && tris.get(h.prim as usize).is_none_or(|t| t.0)
                });
                if blocked { 0.0 } else { 1.0 }
            }
        }
    }
}

/// True if a render of `settings` shades points other than pixel centres
/// (several samples per pixel, or flat or Gouraud shading anywhere).
fn shades_off_centre(ps: &PreparedScene<'_>, settings: &RenderSettings) -> bool {
    let mode = crate::render::shade_mode_of(settings.technique).unwrap_or(ShadeMode::Flat);
    settings.samples > 1
        || mode != ShadeMode::Phong
        || ps
            .scene
            .objects
            .iter()
            .any(|o| o.shade_mode.is_some_and(|m| m != ShadeMode::Phong))
}

/// The [`ExactFallback`] of every light of a scan-line render.
fn scanline_fallbacks(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
) -> Result<Vec<Option<ExactFallback>>, chiaro_core::error::CoreError> {
    let group = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
    let exact = exact_lights(ps, group.as_ref());
    if shades_off_centre(ps, settings) {
        return Ok(object_shadows_per_light(ps, &exact)?
            .into_iter()
            .map(|o| o.map(ExactFallback::Fragments))
            .collect());
    }
    let bvh = std::sync::Arc::new(SceneBvh::new(ps));
    let opaque = crate::object_shadows::opaque_casters(ps);
    let tris = std::sync::Arc::new(
        (0..ps.triangles.len())
            .map(|t| (opaque[t], ps.face_normal(t as u32)))
            .collect::<Vec<_>>(),
    );
    (0..ps.lights.len())
        .map(|li| match exact.get(li) {
            Some(true) => Ok(Some(ExactFallback::Ray {
                bvh: bvh.clone(),
                tris: tris.clone(),
                light: crate::object_shadows::LightGeom::of(ps, li)?,
            })),
            _ => Ok(None),
        })
        .collect()
}

/// The object-precision fragments of every light an exact method handles
/// itself ([`exact_lights`]); `None` for the others. The casters' BVH is
/// built once and shared by the lights.
fn object_shadows_per_light(
    ps: &PreparedScene<'_>,
    exact: &[bool],
) -> Result<Vec<Option<crate::object_shadows::ObjectShadows>>, chiaro_core::error::CoreError> {
    let casters = crate::object_shadows::Casters::new(ps);
    (0..ps.lights.len())
        .map(|li| match exact.get(li) {
            Some(true) => {
                crate::object_shadows::ObjectShadows::build_with(ps, li, &casters).map(Some)
            }
            _ => Ok(None),
        })
        .collect()
}

/// Per light, whether an exact polygon method (volumes, object-precision,
/// scan-line) or a shadow map builds its own structure for it: every light
/// but ambient lights and the lights of an emitter group
/// ([`EmitterGroup`]). A group's samples pick their triangles per shading
/// point, so one structure per triangle would be needed (memory quadratic
/// in the group's size; BENCHMARKS.md, "DamagedHelmet under the exact
/// shadow methods"); they get shadow rays instead, which classify a point exactly as those structures
/// would, and [`group_warning`] says so.
pub(crate) fn exact_lights(ps: &PreparedScene<'_>, group: Option<&EmitterGroup>) -> Vec<bool> {
    ps.lights
        .iter()
        .enumerate()
        .map(|(li, l)| {
            !matches!(l, Light::Ambient { .. }) && !group.is_some_and(|g| g.contains(li))
        })
        .collect()
}

/// The warning of a shadow method whose emitter-group samples use shadow
/// rays (see [`exact_lights`]); `None` without a group or for rays.
pub(crate) fn group_warning(method: ShadowMethod, group: Option<&EmitterGroup>) -> Option<String> {
    let g = group?;
    let what = match method {
        ShadowMethod::Map => "shadow maps",
        ShadowMethod::Volume => "shadow volumes",
        ShadowMethod::Object => "object-precision shadows",
        ShadowMethod::Scanline => "scan-line shadows",
        ShadowMethod::None | ShadowMethod::Ray => return None,
    };
    let n = g.range.len();
    Some(format!(
        "{what}: the {n} emissive triangles sampled as one light (each shading point picks its own) use shadow rays: {what} would need one structure per triangle; the scene's other lights use {what}"
    ))
}

impl Shadows {
    /// Builds the structures of `settings.shadows` for `ps`.
    ///
    /// # Errors
    /// [`chiaro_core::error::CoreError::Unsupported`] for object-precision
    /// and scan-line shadows of lights they cannot handle (see
    /// [`crate::object_shadows`]).
    /// Fallbacks (lights past the shadow-map budget) are reported through
    /// `progress.warning`.
    pub(crate) fn new(
        ps: &PreparedScene<'_>,
        settings: &RenderSettings,
        progress: &dyn chiaro_core::progress::Progress,
    ) -> Result<Self, chiaro_core::error::CoreError> {
        let group = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
        if let Some(w) = group_warning(settings.shadows, group.as_ref()) {
            progress.warning(&w);
        }
        let exact = exact_lights(ps, group.as_ref());
        Ok(match settings.shadows {
            ShadowMethod::None => Shadows::None,
            ShadowMethod::Ray => Shadows::Ray(RayShadows::new(ps)),
            ShadowMethod::Map => {
                let maps = ShadowMaps::new(
                    ps,
                    &settings.shadow_map,
                    settings.light_samples.max(1),
                    settings.memory_budget().shadow_map_bytes(),
                );
                progress.message(&format!(
                    "shadow maps: {} MiB",
                    maps.bytes.div_ceil(1 << 20)
                ));
                if let Some(w) = &maps.warning {
                    progress.warning(w);
                }
                Shadows::Map(maps)
            }
            ShadowMethod::Volume => Shadows::Volume(VolumeShadows {
                slot: vec![None; ps.lights.len()],
                by_ray: vec![false; ps.lights.len()],
                transparent: RayShadows::transparent_only(ps),
            }),
            ShadowMethod::Object => Shadows::Object {
                lights: object_shadows_per_light(ps, &exact)?,
                transparent: RayShadows::transparent_only(ps),
            },
            ShadowMethod::Scanline => Shadows::Scanline {
                lines: crate::scanline_shadows::scanline_visibility_per_light(
                    ps,
                    &ps.scene.camera,
                    settings.width,
                    settings.height,
                    &exact,
                )?,
                fallback: scanline_fallbacks(ps, settings)?,
                transparent: RayShadows::transparent_only(ps),
            },
        })
    }
}

/// Shadow rays against a BVH of the scene's triangles.
pub(crate) struct RayShadows {
    /// The BVH, alpha-tested when the scene has masked materials.
    bvh: Box<dyn Accelerator>,
    casters: ShadowCasters,
}

/// The scene's BVH; shadow rays pass through cut-out texels of masked materials.
fn shadow_bvh(ps: &PreparedScene<'_>) -> Box<dyn Accelerator> {
    AlphaTested::wrap(ps, Box::new(SceneBvh::new(ps)))
}

impl RayShadows {
    pub(crate) fn new(ps: &PreparedScene<'_>) -> Self {
        Self {
            bvh: shadow_bvh(ps),
            casters: ShadowCasters::new(ps),
        }
    }

    /// Shadow rays that see only the transparent casters (`None` when
    /// there are none): the tint that shadow volumes cannot count.
    fn transparent_only(ps: &PreparedScene<'_>) -> Option<Self> {
        let casters = ShadowCasters::new(ps).transparent_only()?;
        Some(Self {
            bvh: shadow_bvh(ps),
            casters,
        })
    }

    /// RGB transmittance from `p` (unit geometric normal `ng`) to the
    /// sample, by the shared query of [`chiaro_core::shadow`] (the Whitted
    /// tracer's): 0 behind an opaque caster, the product of the transmit
    /// colours of the transparent surfaces crossed otherwise.
    pub(crate) fn visibility(&self, p: Vec3, ng: Vec3, s: &LightSample) -> Vec3 {
        self.casters
            .light_transmittance(&*self.bvh, p, ng, s, &mut 0)
    }
}

/// One depth image from a light position (or direction).
struct MapView {
    /// `view_from_world`: the light looks down `-z`.
    view: Mat4,
    /// `clip_from_world`.
    clip_from_world: Mat4,
    /// Orthographic half-extent in scene units; 0 for a perspective view.
    ortho_half: f32,
    /// `tan(fov / 2)` of a perspective view.
    tan_half: f32,
    /// Texels per side.
    res: u32,
    /// Distance along the view axis of the nearest opaque caster, per texel
    /// (`INFINITY` where none).
    depth: Vec<f32>,
    /// Distance of the nearest transparent caster in front of the opaque
    /// one, and the product of the transmit colours of all transparent
    /// casters in front of it (empty when the scene has none).
    trans_depth: Vec<f32>,
    trans_tint: Vec<Vec3>,
}

impl MapView {
    fn perspective(eye: Vec3, forward: Vec3, up_hint: Vec3, fov_deg: f32, res: u32) -> Self {
        let cam = chiaro_core::scene::Camera {
            eye,
            look_at: eye + forward,
            up: up_hint,
            fov_y_degrees: fov_deg,
            near: 1e-4,
            far: 1e30,
        };
        let view = cam.view_matrix();
        Self {
            view,
            clip_from_world: cam.projection_matrix(1.0) * view,
            ortho_half: 0.0,
            tan_half: (fov_deg.to_radians() * 0.5).tan(),
            res,
            depth: Vec::new(),
            trans_depth: Vec::new(),
            trans_tint: Vec::new(),
        }
    }

    fn orthographic(center: Vec3, dir: Vec3, radius: f32, res: u32) -> Self {
        let eye = center - dir * (2.0 * radius);
        let cam = chiaro_core::scene::Camera {
            eye,
            look_at: center,
            ..Default::default()
        };
        let view = cam.view_matrix();
        let s = 1.0 / radius;
        // x, y scaled to [-1, 1]; z_clip = -z_view (the distance along the
        // axis, >= 0 in front), w = 1.
        let proj = Mat4::from_cols(
            Vec4::new(s, 0.0, 0.0, 0.0),
            Vec4::new(0.0, s, 0.0, 0.0),
            Vec4::new(0.0, 0.0, -1.0, 0.0),
            Vec4::new(0.0, 0.0, 0.0, 1.0),
        );
        Self {
            view,
            clip_from_world: proj * view,
            ortho_half: radius,
            tan_half: 0.0,
            res,
            depth: Vec::new(),
            trans_depth: Vec::new(),
            trans_tint: Vec::new(),
        }
    }

    /// Rasterizes the casters, one sample at each texel centre.
    fn render(&mut self, ps: &PreparedScene<'_>, blockers: &[Blocker], any_filter: bool) {
        let res = self.res;
        let n = (res * res) as usize;
        let ortho = self.ortho_half > 0.0;
        let vp = Viewport {
            width: res,
            height: res,
            cull_back: false,
            depth_key: if ortho {
                DepthKey::ZOverW
            } else {
                DepthKey::InvW
            },
        };
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: res,
            y1: res,
        };
        let centre = [[
            (crate::raster::SUBPIXEL / 2) as i32,
            (crate::raster::SUBPIXEL / 2) as i32,
        ]];
        let m = self.clip_from_world;
        let mut key = vec![f32::NEG_INFINITY; n];
        let mut scratch = Vec::new();
        let mut tris: Vec<RasterTri> = Vec::new();
        let mut filters: Vec<(u32, Vec3)> = Vec::new();
        // MASK: a texel whose centre ray meets a masked caster on a cut-out
        // point is not covered by it (the same `Coverage` as the ray tracers).
        let coverage = Coverage::new(ps);
        let clip_to_world = m.inverse();
        let cut_out = |c: &Coverage, t: u32, x: u32, y: u32| {
            let nx = 2.0 * (x as f32 + 0.5) / res as f32 - 1.0;
            let ny = 1.0 - 2.0 * (y as f32 + 0.5) / res as f32;
            let a = clip_to_world * Vec4::new(nx, ny, 0.25, 1.0);
            let b = clip_to_world * Vec4::new(nx, ny, 0.75, 1.0);
            let (a, b) = (a.truncate() / a.w, b.truncate() / b.w);
            let mut ray = Ray::new(a, b - a);
            ray.t_min = f32::NEG_INFINITY;
            ray.t_max = f32::INFINITY;
            let [p0, p1, p2] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
            intersect_triangle(&ray, p0, p1, p2).is_some_and(|(th, u, v)| {
                !c.covers(&Hit {
                    t: th,
                    prim: t,
                    u,
                    v,
                })
            })
        };
        for (t, tri) in ps.triangles.iter().enumerate() {
            let b = blockers[t];
            if b == Blocker::Ignore {
                continue;
            }
            let c = tri.map(|i| m * ps.positions[i as usize].extend(1.0));
            tris.clear();
            vp.setup(c, t as u32, &mut scratch, &mut tris);
            match b {
                Blocker::Opaque => {
                    let masked = coverage.as_ref().filter(|c| c.is_masked(t as u32));
                    for rt in &tris {
                        rasterize(rt, rect, &centre, |x, y, _, k| {
                            if masked.is_some_and(|c| cut_out(c, t as u32, x, y)) {
                                return;
                            }
                            let i = (y * res + x) as usize;
                            if k > key[i] {
                                key[i] = k;
                            }
                        });
                    }
                }
                Blocker::Filter(kt) => {
                    // Deferred until the opaque depth is complete.
                    filters.push((t as u32, kt));
                }
                Blocker::Ignore => {}
            }
        }
        let to_depth = |k: f32| {
            if k == f32::NEG_INFINITY {
                f32::INFINITY
            } else if ortho {
                -k
            } else {
                1.0 / k
            }
        };
        if any_filter && !filters.is_empty() {
            let mut tkey = vec![f32::NEG_INFINITY; n];
            let mut tint = vec![Vec3::ONE; n];
            for &(t, kt) in &filters {
                let c = ps.triangles[t as usize].map(|i| m * ps.positions[i as usize].extend(1.0));
                tris.clear();
                vp.setup(c, t, &mut scratch, &mut tris);
                for rt in &tris {
                    rasterize(rt, rect, &centre, |x, y, _, k| {
                        let i = (y * res + x) as usize;
                        if k > key[i] {
                            tint[i] *= kt;
                            if k > tkey[i] {
                                tkey[i] = k;
                            }
                        }
                    });
                }
            }
            self.trans_depth = tkey.into_iter().map(to_depth).collect();
            self.trans_tint = tint;
        }
        self.depth = key.into_iter().map(to_depth).collect();
    }

    /// Percentage-closer filtered visibility (Reeves, Salesin and Cook 1987)
    /// of the point `p` with unit geometric normal `ng`. Each tap compares
    /// the stored depth with the depth of the receiver's tangent plane along
    /// the tap's own light ray ("receiver plane depth bias"), plus a
    /// constant and a slope-scaled bias in texels of world size.
    fn lookup(&self, p: Vec3, ng: Vec3, wi: Vec3, sm: &ShadowMapSettings) -> Vec3 {
        let pv = self.view.transform_point3(p);
        let nv = self.view.transform_vector3(ng);
        let depth = -pv.z;
        if depth <= 0.0 {
            return Vec3::ONE;
        }
        let res = self.res as f32;
        let ortho = self.ortho_half > 0.0;
        // Position in texel units, and the world size of one texel there.
        let (ndc, texel) = if ortho {
            (
                Vec2::new(pv.x, pv.y) / self.ortho_half,
                2.0 * self.ortho_half / res,
            )
        } else {
            (
                Vec2::new(pv.x, pv.y) / (depth * self.tan_half),
                2.0 * depth * self.tan_half / res,
            )
        };
        let tx = (ndc.x * 0.5 + 0.5) * res;
        let ty = (0.5 - ndc.y * 0.5) * res;
        if !(tx.is_finite() && ty.is_finite()) {
            return Vec3::ONE;
        }
        let cos = ng.dot(wi).abs().max(0.05);
        let tan = (1.0 - cos * cos).max(0.0).sqrt() / cos;
        let bias = texel * (sm.bias + sm.slope_bias * tan.min(10.0));
        let r = sm.pcf_radius.min(8) as i32;
        let (cx, cy) = (tx.floor() as i32, ty.floor() as i32);
        let nz = nv.dot(pv);
        let mut sum = Vec3::ZERO;
        let mut taps = 0.0f32;
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (cx + dx, cy + dy);
                let (xc, yc) = (
                    x.clamp(0, self.res as i32 - 1),
                    y.clamp(0, self.res as i32 - 1),
                );
                // Receiver plane depth along the ray through the texel centre.
                let u = Vec2::new(
                    (x as f32 + 0.5) / res * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / res * 2.0,
                );
                let d = if ortho {
                    let o = Vec3::new(u.x * self.ortho_half, u.y * self.ortho_half, 0.0);
                    let denom = -nv.z;
                    let t = nv.dot(pv - o) / denom;
                    if denom.abs() > 1e-6 && t.is_finite() {
                        t
                    } else {
                        depth
                    }
                } else {
                    let dir = Vec3::new(u.x * self.tan_half, u.y * self.tan_half, -1.0);
                    let denom = nv.dot(dir);
                    let t = nz / denom;
                    if denom.abs() > 1e-6 && t.is_finite() && t > 0.0 {
                        t
                    } else {
                        depth
                    }
                };
                // Never trust the plane more than a few texels away.
                let d = d.clamp(depth - 4.0 * bias - texel, depth + 4.0 * bias + texel);
                let i = (yc as u32 * self.res + xc as u32) as usize;
                let lit_opaque = d - bias <= self.depth[i];
                sum += if !lit_opaque {
                    Vec3::ZERO
                } else if !self.trans_depth.is_empty() && d - bias > self.trans_depth[i] {
                    self.trans_tint[i]
                } else {
                    Vec3::ONE
                };
                taps += 1.0;
            }
        }
        sum / taps
    }
}

/// The shadow maps of one light: a single view (directional light, narrow
/// spot), a cube (six views: point light, wide spot), or for an area light
/// several cubes over its surface.
struct LightMaps {
    /// Views, grouped by 6 for cubes.
    views: Vec<MapView>,
    /// Cube centres (one per group of six views); empty for a single view.
    cube_centres: Vec<Vec3>,
    /// For area lights: samples per side of the map grid (`k x k` maps).
    grid: u32,
}

/// Shadow z-buffers of every light of a scene.
pub(crate) struct ShadowMaps {
    /// Per light: its maps (`None` for ambient lights and for lights past
    /// the budget).
    lights: Vec<Option<LightMaps>>,
    /// Per light: true when it uses shadow rays (its maps did not fit the
    /// budget).
    by_ray: Vec<bool>,
    /// The shadow rays of the lights in `by_ray`, built when there is one.
    rays: Option<RayShadows>,
    settings: ShadowMapSettings,
    /// Bytes of the maps built (depth and transparency buffers).
    pub(crate) bytes: u64,
    /// Which lights fell back to shadow rays and why, when any did.
    pub(crate) warning: Option<String>,
}

/// Which lights get their shadow maps within `budget` bytes: `needs[i]` is
/// light `i`'s bytes (`None`: it has no maps). Lights are taken in order,
/// each if it fits in what is left. Returns per light whether it falls
/// back to shadow rays, and the bytes of the maps kept.
pub(crate) fn plan_budget(needs: &[Option<u64>], budget: u64) -> (Vec<bool>, u64) {
    let mut bytes = 0u64;
    let by_ray = needs
        .iter()
        .map(|need| match *need {
            Some(n) if bytes.saturating_add(n) <= budget => {
                bytes += n;
                false
            }
            Some(_) => true,
            None => false,
        })
        .collect();
    (by_ray, bytes)
}

/// Bytes per texel of a shadow-map view: the opaque depth (`f32`), and with
/// transparent casters their depth and tint (`f32` + `Vec3`).
fn texel_bytes(any_filter: bool) -> u64 {
    if any_filter { 4 + 4 + 12 } else { 4 }
}

/// The most cube maps built over one area light.
const MAX_AREA_MAPS_PER_SIDE: u32 = 4;
/// The most area-light cube maps built in total (beyond that, one per light).
const MAX_AREA_MAPS: usize = 64;

/// A point of an area light's surface for the 2D sample `u` (the same
/// parameterisation as [`chiaro_core::shading::sample_light`]; a sphere
/// gives its centre).
fn area_point(shape: &AreaShape, u: Vec2) -> Vec3 {
    match *shape {
        AreaShape::Quad {
            corner,
            edge_u,
            edge_v,
        } => corner + u.x * edge_u + u.y * edge_v,
        AreaShape::Disk {
            center,
            normal,
            radius,
        } => {
            let d = chiaro_core::sampling::sample_concentric_disk(u) * radius;
            let f = Frame::from_normal(normal.normalize_or_zero());
            center + f.to_world(Vec3::new(d.x, d.y, 0.0))
        }
        AreaShape::Sphere { center, .. } => center,
        AreaShape::Triangle { a, b, c } => {
            let bary = chiaro_core::sampling::sample_uniform_triangle(u);
            a * bary.x + b * bary.y + c * (1.0 - bary.x - bary.y)
        }
    }
}

/// The six 90-degree views of a cube map centred at `c`, in the order
/// `+x, -x, +y, -y, +z, -z` (see [`cube_face`]).
fn cube_views(c: Vec3, res: u32) -> Vec<MapView> {
    let faces = [
        (Vec3::X, Vec3::Y),
        (Vec3::NEG_X, Vec3::Y),
        (Vec3::Y, Vec3::Z),
        (Vec3::NEG_Y, Vec3::Z),
        (Vec3::Z, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y),
    ];
    faces
        .iter()
        .map(|&(f, up)| MapView::perspective(c, f, up, 90.0, res))
        .collect()
}

/// The cube face whose view contains direction `d`.
fn cube_face(d: Vec3) -> usize {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if d.y >= 0.0 { 2 } else { 3 }
    } else if d.z >= 0.0 {
        4
    } else {
        5
    }
}

impl ShadowMaps {
    /// Builds (in parallel over views) the maps of every light of `ps`.
    /// `area_samples` is the `light_samples` setting: an area light gets a
    /// grid of up to 4 x 4 cube maps at the strata of its samples, at a
    /// quarter of `settings.resolution`.
    ///
    /// Before anything is allocated, the lights' maps are sized in light
    /// order against `budget` bytes; a light whose maps do not fit in what
    /// is left uses shadow rays instead, and [`ShadowMaps::warning`] names
    /// those lights.
    pub(crate) fn new(
        ps: &PreparedScene<'_>,
        settings: &ShadowMapSettings,
        area_samples: u32,
        budget: u64,
    ) -> Self {
        let res = settings.resolution.clamp(
            *SHADOW_MAP_RESOLUTIONS.start(),
            *SHADOW_MAP_RESOLUTIONS.end(),
        );
        let centre = (ps.bounds.min + ps.bounds.max) * 0.5;
        let radius = ((ps.bounds.max - ps.bounds.min).length() * 0.5).max(1e-3);
        let radius = if radius.is_finite() { radius } else { 1.0 };
        // The lights of a grouped emissive mesh get no maps: the renderer
        // gives their samples shadow rays.
        let group = chiaro_core::shading::EmitterGroup::of_scene(ps, area_samples);
        let grouped = |li: usize| group.as_ref().is_some_and(|g| g.contains(li));
        let area_lights = ps
            .lights
            .iter()
            .enumerate()
            .filter(|&(li, l)| matches!(l, Light::Area { .. }) && !grouped(li))
            .count();
        let mut lights: Vec<Option<LightMaps>> = ps
            .lights
            .iter()
            .enumerate()
            .map(|(li, light)| match light {
                _ if grouped(li) => None,
                Light::Ambient { .. } => None,
                Light::Directional { direction, .. } => Some(LightMaps {
                    views: vec![MapView::orthographic(
                        centre,
                        direction.normalize_or(Vec3::NEG_Y),
                        radius,
                        res,
                    )],
                    cube_centres: Vec::new(),
                    grid: 0,
                }),
                Light::Point { position, .. } => Some(LightMaps {
                    views: cube_views(*position, res),
                    cube_centres: vec![*position],
                    grid: 0,
                }),
                Light::Spot(s) if s.cone_degrees <= 60.0 => Some(LightMaps {
                    views: vec![MapView::perspective(
                        s.position,
                        s.direction.normalize_or(Vec3::NEG_Y),
                        if s.direction.normalize_or(Vec3::NEG_Y).y.abs() > 0.9 {
                            Vec3::Z
                        } else {
                            Vec3::Y
                        },
                        2.0 * s.cone_degrees + 2.0,
                        res,
                    )],
                    cube_centres: Vec::new(),
                    grid: 0,
                }),
                Light::Spot(s) => Some(LightMaps {
                    views: cube_views(s.position, res),
                    cube_centres: vec![s.position],
                    grid: 0,
                }),
                Light::Area { shape, .. } => {
                    let count = samples_for_light(light, area_samples);
                    let k = (count as f32).sqrt().round().max(1.0) as u32;
                    let mut g = k.min(MAX_AREA_MAPS_PER_SIDE);
                    if matches!(shape, AreaShape::Sphere { .. })
                        || area_lights * (g * g) as usize > MAX_AREA_MAPS
                    {
                        g = 1;
                    }
                    let ares = (res / 4).max(64);
                    let mut views = Vec::new();
                    let mut cube_centres = Vec::new();
                    for j in 0..g * g {
                        let c = area_point(shape, stratum(j, g * g, Vec2::splat(0.5)));
                        cube_centres.push(c);
                        views.extend(cube_views(c, ares));
                    }
                    Some(LightMaps {
                        views,
                        cube_centres,
                        grid: g,
                    })
                }
            })
            .collect();
        let blockers = blockers(ps);
        let any_filter = blockers.iter().any(|b| matches!(b, Blocker::Filter(_)));
        // The budget, in light order.
        let per_texel = texel_bytes(any_filter);
        let needs: Vec<Option<u64>> = lights
            .iter()
            .map(|l| {
                l.as_ref().map(|l| {
                    l.views
                        .iter()
                        .map(|v| u64::from(v.res) * u64::from(v.res) * per_texel)
                        .sum()
                })
            })
            .collect();
        let (by_ray, bytes) = plan_budget(&needs, budget);
        let mut refused = Vec::new();
        for (li, slot) in lights.iter_mut().enumerate() {
            if by_ray[li] {
                *slot = None;
                refused.push((li, needs[li].unwrap_or(0)));
            }
        }
        let warning = (!refused.is_empty()).then(|| {
            let names: Vec<String> = refused.iter().map(|(li, _)| li.to_string()).collect();
            let largest = refused.iter().map(|r| r.1).max().unwrap_or(0);
            format!(
                "shadow maps: light{} {} use{} shadow rays: their maps ({} MiB for the largest, at {res} texels per side) do not fit in the {} MiB shadow-map budget (a quarter of the memory limit, at most 512 MiB) after the {} MiB of the lights before them",
                if refused.len() > 1 { "s" } else { "" },
                names.join(", "),
                if refused.len() > 1 { "" } else { "s" },
                largest.div_ceil(1 << 20),
                budget >> 20,
                bytes.div_ceil(1 << 20),
            )
        });
        let rays = (!refused.is_empty()).then(|| RayShadows::new(ps));
        lights
            .par_iter_mut()
            .flatten()
            .flat_map(|l| l.views.par_iter_mut())
            .for_each(|v| v.render(ps, &blockers, any_filter));
        Self {
            lights,
            by_ray,
            rays,
            settings: *settings,
            bytes,
            warning,
        }
    }

    /// Visibility of sample `sample` (of `count`) of light `li` from the
    /// point `p` with unit geometric normal `ng`.
    pub(crate) fn visibility(
        &self,
        li: usize,
        sample: u32,
        count: u32,
        p: Vec3,
        ng: Vec3,
        s: &LightSample,
    ) -> Vec3 {
        if self.by_ray.get(li) == Some(&true)
            && let Some(r) = &self.rays
        {
            return r.visibility(p, ng, s);
        }
        let Some(Some(maps)) = self.lights.get(li) else {
            return Vec3::ONE;
        };
        if maps.cube_centres.is_empty() {
            return maps.views[0].lookup(p, ng, s.wi, &self.settings);
        }
        // The cube of this sample's stratum (area lights), else the only one.
        let cube = if maps.grid > 1 {
            let k = (count as f32).sqrt().round().max(1.0) as u32;
            let (sx, sy) = (sample % k, sample / k);
            let g = maps.grid;
            ((sy * g / k) * g + sx * g / k) as usize
        } else {
            0
        };
        let c = maps.cube_centres[cube.min(maps.cube_centres.len() - 1)];
        let face = cube_face(p - c);
        maps.views[cube * 6 + face].lookup(p, ng, s.wi, &self.settings)
    }
}

/// How shadow-volume faces are counted per sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VolumeCounting {
    /// Crow's count from the eye to the sample: +1 for each front face of a
    /// volume in front of the sample, -1 for each back face (the seeds'
    /// parity count). Wrong when the eye is itself inside a shadow volume.
    ZPass,
    /// Carmack's reverse (Everitt and Kilgard 2002): count from the sample
    /// to infinity, +1 for each back face behind the sample, -1 for each
    /// front face. Needs capped volumes; right wherever the eye is.
    #[default]
    ZFail,
}

/// What the renderer needs of shadow volumes while shading: which count
/// belongs to which light, and which lights use shadow rays instead.
pub(crate) struct VolumeShadows {
    /// Per light, its index among the per-sample counts (`None`: no volume).
    pub(crate) slot: Vec<Option<u32>>,
    /// Per light, true where its volumes did not fit in the shadow share of
    /// the memory budget: its samples use shadow rays.
    pub(crate) by_ray: Vec<bool>,
    /// Shadow rays that see only the transparent casters, if any.
    pub(crate) transparent: Option<RayShadows>,
}

/// The shadow-volume polygons of the lights, as triangles with homogeneous
/// world vertices (`w = 0` at infinity), outward-facing (counter-clockwise
/// seen from outside the volume), extruded light by light on demand so
/// that they can be counted (and sized against the memory budget) before
/// any is stored.
pub(crate) struct ShadowVolumes {
    /// Opaque caster triangles per object.
    by_object: Vec<Vec<u32>>,
    /// Per object: whether it is a closed mesh.
    closed: Vec<bool>,
    /// Per light: its homogeneous position (`w = 0`: a direction towards
    /// the light), `None` for lights without volumes.
    from: Vec<Option<Vec4>>,
    /// Objects with opaque triangles that are not closed meshes, which get
    /// one volume per triangle; `None` when every caster is closed.
    pub(crate) warning: Option<String>,
}

impl ShadowVolumes {
    /// The capped shadow volumes of every opaque caster for the lights with
    /// `lights[li]` true (area lights from their centre).
    ///
    /// A mesh object whose edges are each shared by exactly two triangles
    /// with opposite orientations is *closed*: only its silhouette edges
    /// (between a triangle facing the light and one facing away) are
    /// extruded, capped by its light-facing triangles (front cap) and those
    /// triangles projected to infinity (back cap). Any other object is open
    /// (a wall quad, a mesh with holes): as a fallback every triangle is its
    /// own occluder (turned to face the light), with its own three sides and
    /// two caps, so a sample behind several counts each and stays shadowed;
    /// this costs more fill than silhouettes, and [`ShadowVolumes::warning`]
    /// names such objects. Triangles edge-on to the light (the light in
    /// their plane, within rounding) cast no volume. Transparent casters
    /// cast no volume (a count cannot carry a colour).
    pub(crate) fn new(ps: &PreparedScene<'_>, lights: &[bool]) -> Self {
        let blockers = blockers(ps);
        // Triangles per object, and whether each object is closed.
        let nobj = ps.scene.objects.len().max(1);
        let mut by_object: Vec<Vec<u32>> = vec![Vec::new(); nobj];
        for (t, &o) in ps.tri_object.iter().enumerate() {
            if blockers[t] == Blocker::Opaque {
                by_object[(o as usize).min(nobj - 1)].push(t as u32);
            }
        }
        let closed: Vec<bool> = by_object.iter().map(|tris| is_closed(ps, tris)).collect();
        let open: Vec<String> = by_object
            .iter()
            .enumerate()
            .filter(|&(o, tris)| !tris.is_empty() && !closed[o])
            .map(|(o, _)| match ps.scene.objects.get(o) {
                Some(obj) if !obj.name.is_empty() => format!("\"{}\"", obj.name),
                _ => format!("objects[{o}]"),
            })
            .collect();
        let warning = (!open.is_empty()).then(|| {
            let one = open.len() == 1;
            format!(
                "shadow volumes: {} {} {}: each of {} triangles casts its own capped volume (the same shadow, with more fill than a silhouette volume)",
                if one { "object" } else { "objects" },
                open.join(", "),
                if one { "is not a closed mesh" } else { "are not closed meshes" },
                if one { "its" } else { "their" },
            )
        });
        let from = ps
            .lights
            .iter()
            .enumerate()
            .map(|(li, light)| {
                if lights.get(li) != Some(&true) {
                    return None;
                }
                match light {
                    Light::Ambient { .. } => None,
                    Light::Point { position, .. } => Some(position.extend(1.0)),
                    Light::Spot(s) => Some(s.position.extend(1.0)),
                    Light::Directional { direction, .. } => {
                        Some((-direction.normalize_or(Vec3::NEG_Y)).extend(0.0))
                    }
                    Light::Area { shape, .. } => Some(shape.center().extend(1.0)),
                }
            })
            .collect();
        Self {
            by_object,
            closed,
            from,
            warning,
        }
    }

    /// Whether light `li` has volumes.
    pub(crate) fn has_volumes(&self, li: usize) -> bool {
        self.from.get(li).is_some_and(Option::is_some)
    }

    /// Calls `sink` with every volume triangle of light `li`, in a fixed
    /// order (nothing for a light without volumes).
    pub(crate) fn extrude_light(
        &self,
        ps: &PreparedScene<'_>,
        li: usize,
        sink: &mut impl FnMut([Vec4; 3]),
    ) {
        let Some(Some(from)) = self.from.get(li) else {
            return;
        };
        for (o, tris) in self.by_object.iter().enumerate() {
            extrude(ps, tris, self.closed[o], *from, sink);
        }
    }

    /// Every light's volume triangles, stored (tests).
    #[cfg(test)]
    pub(crate) fn per_light(&self, ps: &PreparedScene<'_>) -> Vec<Vec<[Vec4; 3]>> {
        (0..self.from.len())
            .map(|li| {
                let mut out = Vec::new();
                self.extrude_light(ps, li, &mut |t| out.push(t));
                out
            })
            .collect()
    }
}

/// True if every edge of `tris` is shared by exactly two of them, in
/// opposite directions (a closed, consistently oriented 2-manifold).
fn is_closed(ps: &PreparedScene<'_>, tris: &[u32]) -> bool {
    if tris.is_empty() {
        return false;
    }
    // Vertices are welded by position: meshes split at seams for uvs or
    // creases still close.
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut vid = |p: Vec3| {
        let k = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let n = ids.len() as u32;
        *ids.entry(k).or_insert(n)
    };
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    for &t in tris {
        let v = ps.triangles[t as usize].map(|i| vid(ps.positions[i as usize]));
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            if a == b {
                return false;
            }
            *edges.entry((a, b)).or_insert(0) += 1;
        }
    }
    edges
        .iter()
        .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
}

/// Which side of a triangle a light is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Facing {
    /// On the side of the counter-clockwise normal.
    Towards,
    /// On the other side.
    Away,
    /// In the triangle's plane, within rounding (or the triangle is
    /// degenerate): the triangle is edge-on to the light.
    EdgeOn,
}

/// Relative tolerance of [`facing_light`]: a light nearer the triangle's
/// plane than this times the scene's coordinate scale is in the plane (the
/// plane distance itself is computed with an error of a few ulps of the
/// coordinates).
const EDGE_ON_EPS: f32 = 1e-5;

/// Which side of triangle `(a, b, c)` the light at homogeneous position
/// `from` is on (`w = 0`: a direction towards the light).
fn facing_light(a: Vec3, b: Vec3, c: Vec3, from: Vec4) -> Facing {
    let Some(n) = (b - a).cross(c - a).try_normalize() else {
        return Facing::EdgeOn;
    };
    let l = from.truncate();
    let (h, tol) = if from.w == 0.0 {
        (n.dot(l.normalize_or_zero()), EDGE_ON_EPS)
    } else {
        let scale = a.abs().max(l.abs()).max_element().max(1.0);
        (n.dot(l - a), EDGE_ON_EPS * scale)
    };
    if h > tol {
        Facing::Towards
    } else if h < -tol {
        Facing::Away
    } else {
        Facing::EdgeOn
    }
}

/// Appends the shadow volume of the triangles `tris` (one object) for a light
/// at homogeneous position `from` (`w = 0`: a direction towards the light).
fn extrude(
    ps: &PreparedScene<'_>,
    tris: &[u32],
    closed: bool,
    from: Vec4,
    out: &mut impl FnMut([Vec4; 3]),
) {
    let l3 = from.truncate();
    // Direction of extrusion of a point away from the light, as a point at infinity.
    let inf = |p: Vec3| -> Vec4 {
        if from.w == 0.0 {
            (-l3).extend(0.0)
        } else {
            (p - l3).extend(0.0)
        }
    };
    let facing = |a: Vec3, b: Vec3, c: Vec3| facing_light(a, b, c, from);
    let tri = |t: u32| ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
    let push_cap_and_back = |a: Vec3, b: Vec3, c: Vec3, out: &mut dyn FnMut([Vec4; 3])| {
        out([a.extend(1.0), b.extend(1.0), c.extend(1.0)]);
        out([inf(a), inf(c), inf(b)]);
    };
    let side = |a: Vec3, b: Vec3, out: &mut dyn FnMut([Vec4; 3])| {
        // Edge a -> b of a light-facing triangle: the quad (b, a, a_inf, b_inf).
        let (ai, bi) = (inf(a), inf(b));
        out([b.extend(1.0), a.extend(1.0), ai]);
        out([b.extend(1.0), ai, bi]);
    };
    if !closed {
        // The scene's bounding box: a triangle with all of it on the
        // light's side of its plane has nothing behind it to shadow.
        let (lo, hi) = (ps.bounds.min, ps.bounds.max);
        let eps = 1e-5 * (hi - lo).length();
        let corners: Vec<Vec3> = (0..8)
            .map(|k| {
                Vec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect();
        let all_finite = corners.iter().all(|c| c.is_finite());
        for &t in tris {
            let [a, b, c] = tri(t);
            // An edge-on (or degenerate) triangle blocks no light; its
            // volume would be flat and, with the light in its plane, its
            // sides would cover the whole plane seen from the eye.
            let [a, b, c] = match facing(a, b, c) {
                Facing::Towards => [a, b, c],
                Facing::Away => [a, c, b],
                Facing::EdgeOn => continue,
            };
            // A floor under everything: its volume holds no surface, and
            // its sides would be filled over the whole floor once per
            // triangle and light.
            let n = (b - a).cross(c - a).normalize_or_zero();
            if all_finite && corners.iter().all(|&k| n.dot(k - a) >= -eps) {
                continue;
            }
            push_cap_and_back(a, b, c, out);
            side(a, b, out);
            side(b, c, out);
            side(c, a, out);
        }
        return;
    }
    // Closed: silhouette edges between light-facing and other triangles.
    let key = |p: Vec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    // Edge-on triangles count as facing away, so that every triangle has
    // one class and the front cap, back cap and sides close up.
    let mut lit_edges: HashMap<([u32; 3], [u32; 3]), bool> = HashMap::new();
    let mut lit = Vec::new();
    for &t in tris {
        let [a, b, c] = tri(t);
        let f = facing(a, b, c) == Facing::Towards;
        for (p, q) in [(a, b), (b, c), (c, a)] {
            lit_edges.insert((key(p), key(q)), f);
        }
        if f {
            lit.push([a, b, c]);
        }
    }
    for [a, b, c] in lit {
        push_cap_and_back(a, b, c, out);
        for (p, q) in [(a, b), (b, c), (c, a)] {
            // The twin edge q -> p belongs to a triangle facing away.
            if lit_edges.get(&(key(q), key(p))) == Some(&false) {
                side(p, q, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_faces_cover_their_directions() {
        let views = cube_views(Vec3::ZERO, 16);
        for d in [
            Vec3::new(1.0, 0.3, -0.2),
            Vec3::new(-0.2, -1.0, 0.5),
            Vec3::new(0.1, 0.2, -0.9),
        ] {
            let v = &views[cube_face(d)];
            let c = v.clip_from_world * d.extend(1.0);
            assert!(c.w > 0.0);
            assert!(
                (c.x / c.w).abs() <= 1.0 && (c.y / c.w).abs() <= 1.0,
                "{d} {c}"
            );
        }
    }

    /// The shadow-ray fallback of one-sample scan-line renders classifies
    /// points exactly as the object-precision fragments it replaces: on
    /// random points of every triangle of the shadow test scene they agree
    /// except within a hair of a fragment boundary, and both lit and
    /// shadowed points occur.
    #[test]
    fn ray_fallback_classifies_points_like_the_fragments() {
        use chiaro_core::prepared::PrepareOptions;
        use chiaro_core::sampling::{pixel_rng, uniform2};
        let scene = chiaro_testkit::scenes::shadow_test(64);
        let ps = PreparedScene::new(&scene, PrepareOptions::default());
        let one = RenderSettings {
            technique: chiaro_core::scene::Technique::Phong,
            samples: 1,
            ..RenderSettings::default()
        };
        let four = RenderSettings {
            samples: 4,
            ..one.clone()
        };
        let rays = scanline_fallbacks(&ps, &one).expect("ray fallback");
        let frags = scanline_fallbacks(&ps, &four).expect("fragments");
        let (mut agree, mut total, mut lit, mut dark) = (0u32, 0u32, 0u32, 0u32);
        for (r, f) in rays.iter().zip(&frags) {
            let (Some(r), Some(f)) = (r, f) else { continue };
            assert!(matches!(r, ExactFallback::Ray { .. }));
            assert!(matches!(f, ExactFallback::Fragments(_)));
            for t in 0..ps.triangles.len() as u32 {
                let [a, b, c] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
                for k in 0..32 {
                    let mut rng = pixel_rng(7, t, k, 0);
                    let u = uniform2(&mut rng);
                    let (u, v) = if u.x + u.y > 1.0 {
                        (1.0 - u.x, 1.0 - u.y)
                    } else {
                        (u.x, u.y)
                    };
                    let p = a + (b - a) * u + (c - a) * v;
                    let (x, y) = (r.lit_fraction(t, p), f.lit_fraction(t, p));
                    total += 1;
                    agree += (x == y) as u32;
                    lit += (y == 1.0) as u32;
                    dark += (y == 0.0) as u32;
                }
            }
        }
        assert!(
            lit > total / 10 && dark > total / 20,
            "lit {lit} dark {dark} of {total}"
        );
        assert!(
            total - agree <= total / 500,
            "{} of {total} points classified differently",
            total - agree
        );
    }
}
