//! Light visibility for the scan converter: the one thing a technique
//! supplies to [`chiaro_core::shading::shade_local`].
//!
//! This module dispatches over the methods, chosen by [`ShadowMethod`]; each
//! lives in its file:
//! - **Shadow rays** ([`ShadowMethod::Ray`], [`rays`]): a segment from the
//!   point to the light sample against the scene BVH; transparent surfaces
//!   multiply the light by their transmit colour, by the one query the
//!   Whitted tracer also calls ([`chiaro_core::shadow`]).
//! - **Shadow z-buffers** ([`ShadowMethod::Map`], Williams 1978, the lecture notes'
//!   "two-pass z-buffer", [`maps`]): a depth image of the scene from each
//!   light (orthographic for directional lights, perspective for narrow
//!   spots, a cube of six 90-degree views for point lights and wide spots),
//!   and for area lights one cube map per light sample so that the penumbra
//!   is the average of several hard shadows (the "several shadow maps over
//!   the light's area" of Heckbert and Herf 1997).
//! - **Shadow volumes** ([`ShadowMethod::Volume`], Crow 1977, [`volumes`]):
//!   built, binned and counted per visible sample (z-pass or z-fail);
//!   transparent casters tint by shadow rays that see only them.
//! - **Object-precision shadows** ([`ShadowMethod::Object`], Atherton,
//!   Weiler and Greenberg 1978, [`object_precision`]): lit fragments of each
//!   receiver, found from the light.
//! - **Scan-line shadows** ([`ShadowMethod::Scanline`], Bouknight and Kelley
//!   1970, [`scanline`]): a scan-line pass over the camera image.
//! - No shadows ([`ShadowMethod::None`]).
//!
//! Shadow maps are sized against the job's shadow-map share
//! ([`chiaro_core::budget::MemoryBudget::shadow_map_bytes`] of
//! [`RenderSettings::memory_budget`]) before anything is allocated; lights
//! past it use shadow rays, and a warning says which.
//!
//! Objects with `casts_shadows = false` cast no shadow in any method.

pub mod maps;
pub mod object_precision;
pub mod rays;
pub mod scanline;
pub mod volumes;

#[cfg(test)]
mod tests;

use crate::pipeline::Frame;
use crate::shadows::maps::ShadowMaps;
use crate::shadows::rays::RayShadows;
use crate::shadows::volumes::VolumeShadows;
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{Light, RenderSettings, ShadeMode, ShadowMethod};
use chiaro_core::shading::ShadingPoint;
use chiaro_core::shading::{EmitterGroup, LightSample, samples_for_light};
pub(crate) use chiaro_core::shadow::Blocker;
use chiaro_core::shadow::ShadowCasters;
use glam::Vec3;

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
        lights: Vec<Option<crate::shadows::object_precision::ObjectShadows>>,
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
        lines: Vec<Option<crate::shadows::scanline::ScanlineShadows>>,
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
    Fragments(crate::shadows::object_precision::ObjectShadows),
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
        light: crate::shadows::object_precision::LightGeom,
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
                    crate::shadows::object_precision::LightGeom::Point(q) => {
                        let q = Vec3::from(q);
                        Ray::segment(offset_ray_origin(p, ng, q - p), q)
                    }
                    crate::shadows::object_precision::LightGeom::Directional(d) => {
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
pub(crate) fn shades_off_centre(ps: &PreparedScene<'_>, settings: &RenderSettings) -> bool {
    let mode = settings.technique.shade_mode().unwrap_or(ShadeMode::Flat);
    settings.samples > 1
        || mode != ShadeMode::Phong
        || ps
            .scene
            .objects
            .iter()
            .any(|o| o.shade_mode.is_some_and(|m| m != ShadeMode::Phong))
}

/// The [`ExactFallback`] of every light of a scan-line render.
pub(crate) fn scanline_fallbacks(
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
    let opaque = crate::shadows::object_precision::opaque_casters(ps);
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
                light: crate::shadows::object_precision::LightGeom::of(ps, li)?,
            })),
            _ => Ok(None),
        })
        .collect()
}

/// The object-precision fragments of every light an exact method handles
/// itself ([`exact_lights`]); `None` for the others. The casters' BVH is
/// built once and shared by the lights.
pub(crate) fn object_shadows_per_light(
    ps: &PreparedScene<'_>,
    exact: &[bool],
) -> Result<
    Vec<Option<crate::shadows::object_precision::ObjectShadows>>,
    chiaro_core::error::CoreError,
> {
    let casters = crate::shadows::object_precision::Casters::new(ps);
    (0..ps.lights.len())
        .map(|li| match exact.get(li) {
            Some(true) => {
                crate::shadows::object_precision::ObjectShadows::build_with(ps, li, &casters)
                    .map(Some)
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
    /// [`crate::shadows::object_precision`]).
    /// Fallbacks (lights past the shadow-map budget) are reported through
    /// `progress.warning`.
    pub(crate) fn new(
        ps: &PreparedScene<'_>,
        frame: Frame<'_>,
        progress: &dyn chiaro_core::progress::Progress,
    ) -> Result<Self, chiaro_core::error::CoreError> {
        let Frame {
            settings,
            camera,
            derived,
        } = frame;
        let group = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
        if let Some(w) = group_warning(settings.shadows, group.as_ref()) {
            progress.warning(&w);
        }
        let exact = exact_lights(ps, group.as_ref());
        Ok(match settings.shadows {
            ShadowMethod::None => Shadows::None,
            ShadowMethod::Ray => Shadows::Ray(RayShadows::kept(ps, derived)),
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
                transparent: RayShadows::transparent_only(ps, derived),
            }),
            ShadowMethod::Object => Shadows::Object {
                lights: object_shadows_per_light(ps, &exact)?,
                transparent: RayShadows::transparent_only(ps, derived),
            },
            ShadowMethod::Scanline => Shadows::Scanline {
                lines: crate::shadows::scanline::scanline_visibility_per_light(
                    ps,
                    camera,
                    settings.width,
                    settings.height,
                    &exact,
                )?,
                fallback: scanline_fallbacks(ps, settings)?,
                transparent: RayShadows::transparent_only(ps, derived),
            },
        })
    }
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

impl crate::pipeline::shading::Ctx<'_, '_> {
    /// Visibility of sample `i` of light `li` from the shading point.
    pub(crate) fn visibility(
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
            // not fit: shadow rays (see `exact_lights`).
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
}
