//! Crow (1977) shadow volumes: their polygons (from the silhouette edges of
//! closed casters), binned like the scene and counted per sample.

use crate::pipeline::binning::Binner;
use crate::pipeline::binning::Bins;
use crate::pipeline::visibility::TileVis;
use crate::shadows::Blocker;
use crate::shadows::Shadows;
use crate::shadows::blockers;
use crate::shadows::rays::RayShadows;
use chiaro_core::progress::Progress;

use crate::raster::rasterize_window;
use crate::raster::{DepthKey, RasterTri, Rect, Viewport};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{Light, RenderSettings};
use chiaro_core::shading::EmitterGroup;
use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use std::collections::HashMap;

/// How shadow-volume faces are counted per sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VolumeCounting {
    /// Crow's count from the eye to the sample: +1 for each front face of a
    /// volume in front of the sample, -1 for each back face (the textbook
    /// chapter's parity count). Wrong when the eye is itself inside a shadow volume.
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
    /// `Some(l)`: extrude to finite points `l` beyond each vertex instead
    /// of to infinity (an orthographic camera, under which points at
    /// infinity have no place on the screen and the back caps would be
    /// lost); `l` exceeds the scene's extent, so the volumes still hold
    /// every receiver they shadow.
    pub(crate) finite_reach: Option<f32>,
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
            finite_reach: None,
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
            extrude(ps, tris, self.closed[o], *from, self.finite_reach, sink);
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
pub(crate) fn is_closed(ps: &PreparedScene<'_>, tris: &[u32]) -> bool {
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
pub(crate) enum Facing {
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
pub(crate) const EDGE_ON_EPS: f32 = 1e-5;

/// Which side of triangle `(a, b, c)` the light at homogeneous position
/// `from` is on (`w = 0`: a direction towards the light).
pub(crate) fn facing_light(a: Vec3, b: Vec3, c: Vec3, from: Vec4) -> Facing {
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
/// at homogeneous position `from` (`w = 0`: a direction towards the light),
/// extruded to infinity, or `reach` beyond each vertex when given (see
/// [`ShadowVolumes::finite_reach`]).
pub(crate) fn extrude(
    ps: &PreparedScene<'_>,
    tris: &[u32],
    closed: bool,
    from: Vec4,
    reach: Option<f32>,
    out: &mut impl FnMut([Vec4; 3]),
) {
    let l3 = from.truncate();
    // Direction of extrusion of a point away from the light, as a point at
    // infinity (or `reach` along it).
    let inf = |p: Vec3| -> Vec4 {
        let d = if from.w == 0.0 { -l3 } else { p - l3 };
        match reach {
            None => d.extend(0.0),
            Some(l) => (p + d.normalize_or_zero() * l).extend(1.0),
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

/// Relative tolerance of the shadow-volume depth comparison: a volume face
/// within it of a sample's depth counts as behind the sample, so the front
/// cap lying on a lit surface does not shadow it.
pub(crate) const VOLUME_EPS: f32 = 2e-5;

/// The bins of the shadow-volume triangles of the lights of `v` that fit
/// in the shadow share of the memory budget
/// ([`chiaro_core::budget::MemoryBudget::shadow_map_bytes`], the share the
/// shadow maps use), with the warnings to give, and the number of count
/// slots. Each light's volumes are counted before any is stored: its
/// binned copies plus one `i32` count per sample of the image; lights in
/// light order take what is left, and a light that does not fit uses
/// shadow rays (`v.by_ray`), named in a warning.
#[allow(clippy::too_many_arguments)]
pub(crate) fn volume_bins(
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    v: &mut crate::shadows::volumes::VolumeShadows,
    binner: &Binner,
    vp: &Viewport,
    clip_from_world: Mat4,
    spp: u32,
) -> ((Bins, [Option<String>; 2]), usize) {
    let group = EmitterGroup::of_scene(ps, settings.light_samples.max(1));
    let exact = crate::shadows::exact_lights(ps, group.as_ref());
    let mut vols = ShadowVolumes::new(ps, &exact);
    if vp.depth_key == DepthKey::ZOverW {
        // The viewport keys depth by NDC z only under an orthographic camera.
        let extent = (ps.bounds.max - ps.bounds.min).length();
        vols.finite_reach = Some(if extent.is_finite() {
            2.0 * extent + 1.0
        } else {
            f32::MAX.sqrt()
        });
    }
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
    let (by_ray, bytes) = crate::shadows::plan_budget(&needs, budget);
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
pub(crate) fn count_volumes(
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
                // Within VOLUME_EPS of the key, relative to its size: a
                // `1/w` key is positive, an orthographic `-z/w` one negative.
                let behind = if key >= 0.0 {
                    k <= key * (1.0 + VOLUME_EPS)
                } else {
                    k <= key * (1.0 - VOLUME_EPS)
                };
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

/// The shadow-volume polygons of `shadows`, clipped and binned like the
/// scene's triangles (their id is the light's slot among the per-sample
/// counts), and the number of slots; none for the other shadow methods.
#[allow(clippy::too_many_arguments)]
pub(crate) fn bin_volumes(
    shadows: &mut Shadows,
    ps: &PreparedScene<'_>,
    settings: &RenderSettings,
    binner: &Binner,
    vp_all: &Viewport,
    clip_from_world: Mat4,
    spp: u32,
    progress: &dyn Progress,
) -> (Option<Bins>, usize) {
    match shadows {
        Shadows::Volume(v) => {
            let (bins, slots) = volume_bins(ps, settings, v, binner, vp_all, clip_from_world, spp);
            for w in bins.1.iter().flatten() {
                progress.warning(w);
            }
            (Some(bins.0), slots)
        }
        _ => (None, 0),
    }
}
