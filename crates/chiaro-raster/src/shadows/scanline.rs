//! Scan-line shadows (Bouknight and Kelley 1970, "An algorithm for producing
//! half-tone computer graphics presentations with shadows and movable light
//! sources", SJCC): shadows found by a scan-line pass over the camera image.
//!
//! 1. **Pre-pass from the light.** Bouknight and Kelley project every
//!    polygon onto a cube around the light and pair only polygons whose
//!    projections overlap. Here the same criterion (overlap as seen from the
//!    light) is applied per receiver with a bounding volume hierarchy: the
//!    receiver's shadow frustum (the pyramid from the light through it, cut
//!    by its plane; a prism for a directional light) is tested against a
//!    BVH of the casters' boxes, so a receiver only meets the occluders
//!    inside its frustum instead of every triangle in the same cube cell.
//! 2. **Shadow projections.** For each remaining pair (occluder, receiver)
//!    the occluder's part between the light and the receiver's plane is
//!    projected from the light onto that plane and clipped to the receiver:
//!    a convex *shadow polygon* (see [`crate::shadows::object_precision`] for the
//!    geometry, which is shared).
//! 3. **Scan-line pass.** Shadow polygons are projected to the screen. On
//!    each scan line (through pixel centres) every shadow polygon crossing it
//!    gives an entry and an exit abscissa; sweeping the line left to right,
//!    a per-receiver counter goes up at entries and down at exits, and a
//!    pixel centre is in shadow when the counter of the polygon visible
//!    there is positive.
//!
//! The visible polygon of each pixel comes from the z-buffer's item buffer
//! ([`crate::zbuffer::item_buffer`]), i.e. the same sampling as the
//! renderer. Lights, occluders and tolerances are as in
//! [`crate::shadows::object_precision`]: shadows are hard, and an area light casts the
//! shadow of a point light at its centre (no penumbra; use shadow rays or
//! shadow maps for soft shadows).
//!
//! # Cost
//! The pairs found by the frustum test dominate: on a 104k-triangle scene
//! of spheres over a plane, about 9 million candidate pairs give 414,000
//! shadow polygons; the sweep itself is `O(rows * active polygons)`.

use crate::raster::DepthKey;
use crate::shadows::object_precision::{
    Casters, DVec2, DVec3, LightGeom, ReceiverFrame, intersect2, scene_scale, tri_points,
};
use crate::zbuffer::{ItemBufferOptions, NO_ITEM, item_buffer_with};
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::Camera;
use glam::Mat4;
use rayon::prelude::*;

/// Result of [`scanline_visibility`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScanlineShadows {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Visible triangle at each pixel centre (row-major from the top-left),
    /// [`NO_ITEM`] where none.
    pub visible: Vec<u32>,
    /// Per pixel centre: 1 when the light reaches the visible point, 0 when
    /// it is in shadow; 1 where no triangle is visible.
    pub lit: Vec<f32>,
    /// Candidate (occluder, receiver) pairs left by the light pre-pass.
    pub candidate_pairs: usize,
    /// Shadow polygons actually cast (non-empty on their receiver).
    pub shadow_polygons: usize,
}

/// `[x, y, z, w]` clip coordinates of `p` in `f64`.
fn to_clip(m: &Mat4, p: DVec3) -> [f64; 4] {
    let c = m.to_cols_array_2d();
    let mut out = [0.0; 4];
    for (r, o) in out.iter_mut().enumerate() {
        *o = f64::from(c[0][r]) * p.x
            + f64::from(c[1][r]) * p.y
            + f64::from(c[2][r]) * p.z
            + f64::from(c[3][r]);
    }
    out
}

/// Computes, with the Bouknight-Kelley scan-line method, whether light
/// `light_index` of `ps.lights` reaches the visible point at each pixel
/// centre of a `width x height` image seen through `camera` (aspect
/// `width / height`, as the renderer uses it).
///
/// # Errors
/// [`CoreError::Unsupported`] for an ambient light, an out-of-range index
/// or a scene with analytic spheres.
pub fn scanline_visibility(
    ps: &PreparedScene<'_>,
    camera: &Camera,
    width: u32,
    height: u32,
    light_index: usize,
) -> Result<ScanlineShadows, CoreError> {
    scanline_visibility_with(ps, camera, width, height, light_index, &Casters::new(ps))
}

/// [`scanline_visibility`] of every light with `lights[li]` true (`None`
/// for the others), the casters' BVH built once.
///
/// # Errors
/// As [`scanline_visibility`].
pub(crate) fn scanline_visibility_per_light(
    ps: &PreparedScene<'_>,
    camera: &Camera,
    width: u32,
    height: u32,
    lights: &[bool],
) -> Result<Vec<Option<ScanlineShadows>>, CoreError> {
    let casters = Casters::new(ps);
    (0..ps.lights.len())
        .map(|li| match lights.get(li) {
            Some(true) => {
                scanline_visibility_with(ps, camera, width, height, li, &casters).map(Some)
            }
            _ => Ok(None),
        })
        .collect()
}

fn scanline_visibility_with(
    ps: &PreparedScene<'_>,
    camera: &Camera,
    width: u32,
    height: u32,
    light_index: usize,
    casters: &Casters,
) -> Result<ScanlineShadows, CoreError> {
    let light = LightGeom::of(ps, light_index)?;
    let eps = 1e-5 * scene_scale(ps);
    let nt = ps.triangles.len();
    // 1-2. Candidate occluders of each receiver from its shadow frustum,
    // and their shadow polygons clipped to it, in world space.
    let per_receiver: Vec<(usize, Vec<Vec<DVec3>>)> = (0..nt)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(stack, shadows), r| {
                let Some(p) = tri_points(ps, r) else {
                    return (0, Vec::new());
                };
                let Some(frame) = ReceiverFrame::new(p, light, eps) else {
                    return (0, Vec::new());
                };
                shadows.clear();
                let n = casters.shadows_on(r, p, &frame, light, stack, shadows);
                let polys = shadows
                    .iter()
                    .filter_map(|s| {
                        let s = intersect2(s, &frame.tri);
                        (s.len() >= 3).then(|| s.iter().map(|&q| frame.world_of(q)).collect())
                    })
                    .collect();
                (n, polys)
            },
        )
        .collect();
    let candidate_pairs = per_receiver.iter().map(|(n, _)| n).sum();
    // 3. The camera: visible triangles and screen-space shadow polygons.
    let m = camera.projection_matrix(width as f32 / height.max(1) as f32) * camera.view_matrix();
    let options = ItemBufferOptions {
        cull_back_faces: false,
        depth_key: DepthKey::of_camera(camera),
    };
    let items = item_buffer_with(
        m,
        width,
        height,
        &ps.positions,
        &ps.triangles,
        &[],
        &options,
    );
    let (wf, hf) = (f64::from(width), f64::from(height));
    // Screen polygons bucketed by the first scan line they cross.
    let mut rows: Vec<Vec<(u32, Vec<DVec2>)>> = vec![Vec::new(); height as usize];
    let mut shadow_polygons = 0;
    for (r, (_, polys)) in per_receiver.iter().enumerate() {
        for poly in polys {
            shadow_polygons += 1;
            // Homogeneous near-plane clip (z >= 0, Direct3D convention).
            let clip: Vec<[f64; 4]> = poly.iter().map(|&p| to_clip(&m, p)).collect();
            let mut kept: Vec<[f64; 4]> = Vec::new();
            for i in 0..clip.len() {
                let (a, b) = (clip[i], clip[(i + 1) % clip.len()]);
                if a[2] >= 0.0 {
                    kept.push(a);
                }
                if (a[2] >= 0.0) != (b[2] >= 0.0) {
                    let t = a[2] / (a[2] - b[2]);
                    kept.push(std::array::from_fn(|k| a[k] + (b[k] - a[k]) * t));
                }
            }
            if kept.len() < 3 || kept.iter().any(|c| c[3] <= 0.0) {
                continue;
            }
            let screen: Vec<DVec2> = kept
                .iter()
                .map(|c| {
                    DVec2::new(
                        (c[0] / c[3] * 0.5 + 0.5) * wf,
                        (0.5 - c[1] / c[3] * 0.5) * hf,
                    )
                })
                .collect();
            let ymin = screen.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
            let first = (ymin - 0.5).ceil().max(0.0);
            if first < hf {
                rows[first as usize].push((r as u32, screen));
            }
        }
    }
    // The scan-line sweep: an active list of shadow polygons, entry and exit
    // events along each line, a shadow counter per receiver.
    let mut lit = vec![1.0f32; items.id.len()];
    let mut active: Vec<(u32, Vec<DVec2>)> = Vec::new();
    let mut events: Vec<(f64, u32, i32)> = Vec::new();
    // Shadow counter per receiver; only the receivers met on a line are
    // touched, and reset after it.
    let mut count = vec![0i32; nt];
    for (j, row) in rows.iter_mut().enumerate() {
        let yc = j as f64 + 0.5;
        active.append(row);
        active.retain(|(_, s)| s.iter().any(|p| p.y >= yc));
        events.clear();
        for (r, s) in &active {
            let (mut xl, mut xr) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..s.len() {
                let (a, b) = (s[i], s[(i + 1) % s.len()]);
                if (a.y <= yc && b.y >= yc) || (b.y <= yc && a.y >= yc) {
                    let x = if (b.y - a.y).abs() > 0.0 {
                        a.x + (b.x - a.x) * ((yc - a.y) / (b.y - a.y))
                    } else {
                        a.x.min(b.x)
                    };
                    let x2 = if (b.y - a.y).abs() > 0.0 {
                        x
                    } else {
                        a.x.max(b.x)
                    };
                    xl = xl.min(x);
                    xr = xr.max(x2);
                }
            }
            if xl < xr {
                events.push((xl, *r, 1));
                events.push((xr, *r, -1));
            }
        }
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut e = 0;
        for i in 0..width as usize {
            let xc = i as f64 + 0.5;
            // Entries strictly left of the centre open a shadow, exits
            // strictly left close it: shadowed iff xl < xc <= xr.
            while e < events.len() && events[e].0 < xc {
                if let Some(c) = count.get_mut(events[e].1 as usize) {
                    *c += events[e].2;
                }
                e += 1;
            }
            let k = j * width as usize + i;
            let t = items.id[k];
            if t != NO_ITEM && count.get(t as usize).is_some_and(|&c| c > 0) {
                lit[k] = 0.0;
            }
        }
        for &(_, r, _) in &events[..e] {
            if let Some(c) = count.get_mut(r as usize) {
                *c = 0;
            }
        }
    }
    Ok(ScanlineShadows {
        width,
        height,
        visible: items.id,
        lit,
        candidate_pairs,
        shadow_polygons,
    })
}
