//! Scan-line shadows (Bouknight and Kelley 1970, "An algorithm for producing
//! half-tone computer graphics presentations with shadows and movable light
//! sources", SJCC): shadows found by a scan-line pass over the camera image.
//!
//! 1. **Pre-pass from the light.** Every triangle is projected onto a cube
//!    around a point light (each face a 90-degree central projection, the
//!    triangle clipped to the face's pyramid first) or, for a directional
//!    light, onto a plane perpendicular to the light. Each face is a
//!    `32 x 32` grid; two triangles can only shadow each other when their
//!    projections share a cell, which discards most pairs.
//! 2. **Shadow projections.** For each remaining pair (occluder, receiver)
//!    the occluder's part between the light and the receiver's plane is
//!    projected from the light onto that plane and clipped to the receiver:
//!    a convex *shadow polygon* (see [`crate::object_shadows`] for the
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
//! [`crate::object_shadows`].

use crate::object_shadows::{
    DVec2, DVec3, LightGeom, ReceiverFrame, casts, intersect2, scene_scale, tri_points,
};
use crate::zbuffer::{NO_ITEM, item_buffer};
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::Camera;
use glam::Mat4;
use rayon::prelude::*;
use std::collections::HashMap;

/// Cells per side of each light-projection face.
const GRID: usize = 32;

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

/// Grid cells of the light's projection that triangle `p` covers, as
/// `face * GRID * GRID + row * GRID + col`. For a directional light
/// `frame = (e1, e2, lo, size)` describes the one projection plane.
fn light_cells(p: [DVec3; 3], light: LightGeom, ortho: &(DVec3, DVec3, DVec2, f64)) -> Vec<usize> {
    let mut out = Vec::new();
    let mut push_box = |face: usize, lo: DVec2, hi: DVec2, origin: DVec2, size: f64| {
        let cell = |v: f64| (((v) / size * GRID as f64).floor().max(0.0) as usize).min(GRID - 1);
        let (c0, c1) = (cell(lo.x - origin.x), cell(hi.x - origin.x));
        let (r0, r1) = (cell(lo.y - origin.y), cell(hi.y - origin.y));
        for r in r0..=r1 {
            for c in c0..=c1 {
                out.push(face * GRID * GRID + r * GRID + c);
            }
        }
    };
    match light {
        LightGeom::Point(l) => {
            let q = p.map(|x| x - l);
            let comp = |v: DVec3, k: usize| match k {
                0 => v.x,
                1 => v.y,
                _ => v.z,
            };
            for face in 0..6 {
                let (k, s) = (face / 2, if face % 2 == 0 { 1.0 } else { -1.0 });
                let (j1, j2) = ((k + 1) % 3, (k + 2) % 3);
                // The face's pyramid: s*q_k >= |q_j| for both other axes.
                let mut poly = q.to_vec();
                for (j, sj) in [(j1, 1.0), (j1, -1.0), (j2, 1.0), (j2, -1.0)] {
                    poly = clip_affine(&poly, |v| s * comp(v, k) - sj * comp(v, j));
                    if poly.len() < 3 {
                        break;
                    }
                }
                if poly.len() < 3 {
                    continue;
                }
                let mut lo = DVec2::splat(1.0);
                let mut hi = DVec2::splat(-1.0);
                for v in &poly {
                    let m = s * comp(*v, k);
                    let uv = if m > 0.0 {
                        DVec2::new(comp(*v, j1) / m, comp(*v, j2) / m)
                    } else {
                        // The light's own position: the whole face.
                        lo = DVec2::splat(-1.0);
                        hi = DVec2::splat(1.0);
                        continue;
                    };
                    lo = lo.min(uv);
                    hi = hi.max(uv);
                }
                push_box(face, lo, hi, DVec2::splat(-1.0), 2.0);
            }
        }
        LightGeom::Directional(_) => {
            let (e1, e2, origin, size) = *ortho;
            let uv = p.map(|x| DVec2::new(x.dot(e1), x.dot(e2)));
            let lo = uv[0].min(uv[1]).min(uv[2]);
            let hi = uv[0].max(uv[1]).max(uv[2]);
            push_box(0, lo, hi, origin, size);
        }
    }
    out
}

/// Sutherland-Hodgman: the part of convex polygon `p` where `f >= 0`.
fn clip_affine(p: &[DVec3], f: impl Fn(DVec3) -> f64) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(p.len() + 1);
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        let (fa, fb) = (f(a), f(b));
        if fa >= 0.0 {
            out.push(a);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            out.push(a + (b - a) * (fa / (fa - fb)));
        }
    }
    out
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
    let light = LightGeom::of(ps, light_index)?;
    let eps = 1e-5 * scene_scale(ps);
    let nt = ps.triangles.len();
    // 1. Pre-pass: light-projection cells of every triangle.
    let ortho = match light {
        LightGeom::Directional(d) => {
            let helper = if d.x.abs() < 0.9 {
                DVec3::new(1.0, 0.0, 0.0)
            } else {
                DVec3::new(0.0, 1.0, 0.0)
            };
            let e1 = d.cross(helper).try_normalize().unwrap_or(helper);
            let e2 = d.cross(e1);
            let mut lo = DVec2::splat(f64::INFINITY);
            let mut hi = DVec2::splat(f64::NEG_INFINITY);
            for p in &ps.positions {
                let p = DVec3::from(p);
                let uv = DVec2::new(p.dot(e1), p.dot(e2));
                lo = lo.min(uv);
                hi = hi.max(uv);
            }
            let size = (hi.x - lo.x).max(hi.y - lo.y).max(1e-9) * (1.0 + 1e-6);
            (e1, e2, lo, size)
        }
        LightGeom::Point(_) => (DVec3::ZERO, DVec3::ZERO, DVec2::splat(0.0), 1.0),
    };
    let tri_cells: Vec<Vec<usize>> = (0..nt)
        .into_par_iter()
        .map(|t| {
            tri_points(ps, t)
                .map(|p| light_cells(p, light, &ortho))
                .unwrap_or_default()
        })
        .collect();
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); 6 * GRID * GRID];
    for (t, cs) in tri_cells.iter().enumerate() {
        if casts(ps, t) {
            for &c in cs {
                cells[c].push(t as u32);
            }
        }
    }
    // 2. Shadow polygons of the candidate pairs, in world space.
    let per_receiver: Vec<(usize, Vec<Vec<DVec3>>)> = (0..nt)
        .into_par_iter()
        .map(|r| {
            let Some(frame) = tri_points(ps, r).and_then(|p| ReceiverFrame::new(p, light, eps))
            else {
                return (0, Vec::new());
            };
            let mut seen: Vec<u32> = tri_cells[r]
                .iter()
                .flat_map(|&c| cells[c].iter().copied())
                .filter(|&o| o as usize != r)
                .collect();
            seen.sort_unstable();
            seen.dedup();
            let polys = seen
                .iter()
                .filter_map(|&o| {
                    let s = frame.shadow_of(tri_points(ps, o as usize)?, light)?;
                    let s = intersect2(&s, &frame.tri);
                    (s.len() >= 3).then(|| s.iter().map(|&q| frame.world_of(q)).collect())
                })
                .collect();
            (seen.len(), polys)
        })
        .collect();
    let candidate_pairs = per_receiver.iter().map(|(n, _)| n).sum();
    // 3. The camera: visible triangles and screen-space shadow polygons.
    let m = camera.projection_matrix(width as f32 / height.max(1) as f32) * camera.view_matrix();
    let items = item_buffer(m, width, height, &ps.positions, &ps.triangles, &[]);
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
    let mut count: HashMap<u32, i32> = HashMap::new();
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
        count.clear();
        let mut e = 0;
        for i in 0..width as usize {
            let xc = i as f64 + 0.5;
            // Entries strictly left of the centre open a shadow, exits
            // strictly left close it: shadowed iff xl < xc <= xr.
            while e < events.len() && events[e].0 < xc {
                *count.entry(events[e].1).or_insert(0) += events[e].2;
                e += 1;
            }
            let k = j * width as usize + i;
            let t = items.id[k];
            if t != NO_ITEM && count.get(&t).copied().unwrap_or(0) > 0 {
                lit[k] = 0.0;
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
