//! The triangle rasterizer at the heart of every scan-conversion pass:
//! viewport mapping, fixed-point snapping, integer edge functions with the
//! top-left fill rule, and an incremental traversal of a screen rectangle.
//!
//! Edge functions (Pineda 1988, "A parallel algorithm for polygon
//! rasterization") are evaluated in exact 64-bit integer arithmetic on
//! vertices snapped to 1/256 pixel, so two triangles sharing an edge compute
//! the same edge value with opposite signs at every sample. The top-left rule
//! (Direct3D's rasterization rules; Fabian Giesen, "The barycentric
//! conspiracy", 2013) then gives a sample on a shared edge to exactly one of
//! them: a mesh has no cracks and no sample is drawn twice.
//!
//! Screen space: `x` to the right, `y` down, pixel `(i, j)` covers
//! `[i, i+1) x [j, j+1)`; its centre is `(i + 0.5, j + 0.5)`, the point
//! [`chiaro_core::scene::Camera::ray_direction`] shoots through.

use crate::clip::{ClipVertex, clip_triangle};
use glam::Vec4;

/// Sub-pixel precision of snapped vertices, in bits.
pub const SUBPIXEL_BITS: u32 = 8;
/// Sub-pixel units per pixel.
pub const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;

/// What the depth buffer stores. Both are affine in screen space, so they
/// interpolate exactly from the vertices; the stored *closeness* key is
/// larger for nearer surfaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthKey {
    /// `1 / w`: the reciprocal view depth of a perspective projection (a
    /// "reversed" depth buffer with the far plane at infinity; its precision
    /// is relative, so it does not collapse far from a small near plane).
    /// Requires a perspective projection (`w` = view depth).
    #[default]
    InvW,
    /// `-z / w`: the NDC depth (smaller `z/w` = nearer), for orthographic
    /// projections where `w` is constant.
    ZOverW,
}

impl DepthKey {
    /// The key for `camera`'s projection: [`DepthKey::InvW`] for a
    /// perspective camera, [`DepthKey::ZOverW`] for an orthographic one.
    pub fn of_camera(camera: &chiaro_core::scene::Camera) -> Self {
        if camera.orthographic_half_height().is_some() {
            DepthKey::ZOverW
        } else {
            DepthKey::InvW
        }
    }
}

/// A triangle ready for rasterization: snapped screen vertices in
/// counter-clockwise order *on screen with y down* (positive doubled area),
/// per-vertex depth keys, and the id written to the item buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterTri {
    /// Vertices in 1/[`SUBPIXEL`] pixel units.
    pub v: [[i32; 2]; 3],
    /// Closeness key at each vertex (see [`DepthKey`]).
    pub key: [f32; 3],
    /// Item id (the source triangle index in the renderer).
    pub id: u32,
    /// True if the source triangle faces away from the viewer.
    pub back: bool,
}

impl RasterTri {
    /// Inclusive pixel bounds `[x0, y0, x1, y1]` of every sample the triangle
    /// can cover (not clamped to the viewport).
    #[inline]
    pub fn pixel_bounds(&self) -> [i32; 4] {
        let [a, b, c] = self.v;
        let s = SUBPIXEL_BITS;
        [
            a[0].min(b[0]).min(c[0]) >> s,
            a[1].min(b[1]).min(c[1]) >> s,
            a[0].max(b[0]).max(c[0]) >> s,
            a[1].max(b[1]).max(c[1]) >> s,
        ]
    }
}

/// Maps clip-space vertices to a viewport, snaps them, and culls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Viewport {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Drop triangles that face away from the viewer.
    pub cull_back: bool,
    /// What the depth buffer stores.
    pub depth_key: DepthKey,
}

impl Viewport {
    /// Snapped screen position of a clip-space point (which must have `w > 0`).
    #[inline]
    pub(crate) fn snap(&self, c: Vec4) -> [i32; 2] {
        let inv_w = 1.0 / c.w;
        let sx = (c.x * inv_w * 0.5 + 0.5) * self.width as f32;
        let sy = (0.5 - c.y * inv_w * 0.5) * self.height as f32;
        let k = SUBPIXEL as f32;
        [round_to_i32(sx * k), round_to_i32(sy * k)]
    }

    /// Appends the screen triangle with snapped vertices `s` (in the
    /// source triangle's winding) and closeness keys `key`, unless it is
    /// degenerate or (with `cull_back`) back-facing. Every setup path ends
    /// here, so a triangle set up from precomputed vertices is bit for bit
    /// the one [`Viewport::setup`] makes.
    #[inline]
    pub fn emit(&self, s: [[i32; 2]; 3], key: [f32; 3], id: u32, out: &mut Vec<RasterTri>) {
        let [first, sb, sc] = s;
        let area = edge_area(first, sb, sc);
        if area == 0 {
            return;
        }
        // Counter-clockwise in the world (front) is clockwise on a y-down
        // screen, i.e. negative doubled area.
        let back = area > 0;
        if back && self.cull_back {
            return;
        }
        let [k0, kb, kc] = key;
        out.push(if back {
            RasterTri {
                v: [first, sb, sc],
                key: [k0, kb, kc],
                id,
                back,
            }
        } else {
            RasterTri {
                v: [first, sc, sb],
                key: [k0, kc, kb],
                id,
                back,
            }
        });
    }

    /// Clips the clip-space triangle `clip` (counter-clockwise seen from its
    /// front) and appends the resulting screen triangles to `out`.
    /// `scratch` is reused between calls. Degenerate (zero-area) pieces and,
    /// with `cull_back`, back-facing triangles produce nothing.
    pub fn setup(
        &self,
        clip: [Vec4; 3],
        id: u32,
        scratch: &mut Vec<ClipVertex>,
        out: &mut Vec<RasterTri>,
    ) {
        self.setup_homogeneous(clip, [1.0; 3], id, scratch, out);
    }

    /// [`Viewport::setup`] for vertices given in homogeneous world
    /// coordinates `(x, y, z, w_h)`: `clip` is `clip_from_world * (x, y, z,
    /// w_h)` and `w_h` the vertices' homogeneous weights, 0 for points at
    /// infinity (the far ends of shadow volumes, Crow 1977; Everitt and
    /// Kilgard 2002). With [`DepthKey::InvW`] the key of a vertex is
    /// `w_h / w_clip`, the reciprocal view depth of the point it stands for
    /// (0 at infinity); [`DepthKey::ZOverW`] ignores `w_h`.
    pub fn setup_homogeneous(
        &self,
        clip: [Vec4; 3],
        w_h: [f32; 3],
        id: u32,
        scratch: &mut Vec<ClipVertex>,
        out: &mut Vec<RasterTri>,
    ) {
        clip_triangle(clip, scratch);
        if scratch.len() < 3 {
            return;
        }
        let wh = glam::Vec3::from_array(w_h);
        let key = |v: &ClipVertex| match self.depth_key {
            DepthKey::InvW => v.bary.dot(wh) / v.clip.w,
            DepthKey::ZOverW => -v.clip.z / v.clip.w,
        };
        let first = self.snap(scratch[0].clip);
        let k0 = key(&scratch[0]);
        for i in 1..scratch.len() - 1 {
            let (b, c) = (scratch[i].clip, scratch[i + 1].clip);
            let s = [first, self.snap(b), self.snap(c)];
            self.emit(s, [k0, key(&scratch[i]), key(&scratch[i + 1])], id, out);
        }
    }
}

/// `x.round() as i32` (ties away from zero, saturating, NaN to 0), without
/// the libm call `f32::round` becomes on baseline x86-64: below 2^22 the
/// truncation and the fraction `x - trunc(x)` are exact, so the result is
/// the same integer. The fraction's two tests are added as integers rather
/// than branched on: which way a snapped coordinate rounds is a coin toss,
/// and the vertex pass rounds two per vertex.
#[inline]
pub(crate) fn round_to_i32(x: f32) -> i32 {
    if x.abs() < 4_194_304.0 {
        let t = x as i32;
        let f = x - t as f32;
        t + i32::from(f >= 0.5) - i32::from(f <= -0.5)
    } else {
        x.round() as i32
    }
}

/// Doubled signed area of the snapped triangle (positive = counter-clockwise
/// on a y-down screen).
#[inline]
fn edge_area(a: [i32; 2], b: [i32; 2], c: [i32; 2]) -> i64 {
    let (ax, ay) = (i64::from(a[0]), i64::from(a[1]));
    let (bx, by) = (i64::from(b[0]), i64::from(b[1]));
    let (cx, cy) = (i64::from(c[0]), i64::from(c[1]));
    (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
}

/// A screen rectangle, pixels `x0..x1` by `y0..y1` (exclusive ends).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Left column.
    pub x0: u32,
    /// Top row.
    pub y0: u32,
    /// One past the right column.
    pub x1: u32,
    /// One past the bottom row.
    pub y1: u32,
}

/// Sample positions within a pixel, in 1/[`SUBPIXEL`] units from its
/// top-left corner. One sample sits at the centre; `n` samples form a
/// stratified "n-rooks" pattern (one sample per column and per row of an
/// `n x n` grid, rows ordered by the radical inverse in base 2), so
/// that any `n` gives well-spread positions.
pub fn sample_offsets(n: u32) -> Vec<[i32; 2]> {
    let n = n.max(1);
    (0..n)
        .map(|i| {
            let x = (i as f32 + 0.5) / n as f32;
            let y = if n == 1 {
                0.5
            } else {
                // Rows of an n x n grid visited in radical-inverse order.
                let r = (i.reverse_bits() as f64 / 4_294_967_296.0) as f32;
                ((r * n as f32).floor() + 0.5) / n as f32
            };
            let k = SUBPIXEL as f32;
            [
                (x * k).round().clamp(0.0, (SUBPIXEL - 1) as f32) as i32,
                (y * k).round().clamp(0.0, (SUBPIXEL - 1) as f32) as i32,
            ]
        })
        .collect()
}

/// Calls `frag(x, y, sample, key)` for every sample of every pixel in `rect`
/// that the triangle covers, by the top-left rule; `key` is the triangle's
/// closeness key interpolated at the sample (see [`DepthKey`]).
///
/// The traversal steps the three edge functions incrementally across the
/// triangle's bounding box clipped to `rect`.
#[inline]
pub fn rasterize<F: FnMut(u32, u32, usize, f32)>(
    t: &RasterTri,
    rect: Rect,
    samples: &[[i32; 2]],
    frag: F,
) {
    rasterize_window(t, rect, rect, samples, frag);
}

/// [`rasterize`] in `rect`, calling `frag` only for the pixels inside
/// `window` as well. The keys (rounded from an origin in `rect`) are bit
/// for bit those [`rasterize`] gives in `rect`: a crop window draws exactly
/// the samples of the full render.
#[inline]
pub fn rasterize_window<F: FnMut(u32, u32, usize, f32)>(
    t: &RasterTri,
    rect: Rect,
    window: Rect,
    samples: &[[i32; 2]],
    mut frag: F,
) {
    rasterize_window_masked(t, rect, window, samples, |x, y, s, key, covered| {
        if covered {
            frag(x, y, s, key);
        }
    });
}

/// [`rasterize_window`], calling `frag(x, y, sample, key, covered)` for
/// every sample of the triangle's bounding box in `rect` and `window`,
/// `covered` telling whether the triangle covers it (the key is only
/// meaningful where it does). For a z-buffer that folds `covered` into its
/// depth test without a branch: the triangles of a large mesh are a few
/// pixels wide, and which samples of their bounding boxes they cover is
/// too irregular for a branch predictor.
#[inline]
pub fn rasterize_window_masked<F: FnMut(u32, u32, usize, f32, bool)>(
    t: &RasterTri,
    rect: Rect,
    window: Rect,
    samples: &[[i32; 2]],
    mut frag: F,
) {
    let b = t.pixel_bounds();
    let x0 = b[0].max(rect.x0 as i32);
    let y0 = b[1].max(rect.y0 as i32);
    let x1 = (b[2] + 1).min(rect.x1 as i32);
    let y1 = (b[3] + 1).min(rect.y1 as i32);
    if x0 >= x1 || y0 >= y1 {
        return;
    }
    let v = t.v.map(|p| [i64::from(p[0]), i64::from(p[1])]);
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
    if area <= 0 {
        return;
    }
    // Edge i runs from v[i] to v[i+1]; E_i(p) = A (px - vx) + B (py - vy) is
    // positive inside. The samples with E_i = 0 belong to the triangle only on
    // a top edge (A = 0, B > 0: the interior lies below) or a left edge (A > 0:
    // the interior lies to the right), which the bias encodes.
    let mut ea = [0i64; 3];
    let mut eb = [0i64; 3];
    let mut e_origin = [0i64; 3];
    let (px0, py0) = (i64::from(x0) * SUBPIXEL, i64::from(y0) * SUBPIXEL);
    for i in 0..3 {
        let (p, q) = (v[i], v[(i + 1) % 3]);
        let a = p[1] - q[1];
        let bb = q[0] - p[0];
        let bias = if a > 0 || (a == 0 && bb > 0) { 0 } else { -1 };
        ea[i] = a;
        eb[i] = bb;
        e_origin[i] = a * (px0 - p[0]) + bb * (py0 - p[1]) + bias;
    }
    // Closeness key: barycentric weight of the vertex opposite edge i is E_i / area.
    let k = t.key.map(f64::from);
    let kw = [k[2], k[0], k[1]];
    let inv_area = 1.0 / area as f64;
    let dkdx = (ea[0] as f64 * kw[0] + ea[1] as f64 * kw[1] + ea[2] as f64 * kw[2]) * inv_area;
    let dkdy = (eb[0] as f64 * kw[0] + eb[1] as f64 * kw[1] + eb[2] as f64 * kw[2]) * inv_area;
    // Key at the bbox origin, from the unbiased edge values.
    let mut k_origin = 0.0f64;
    for i in 0..3 {
        let (p, q) = (v[i], v[(i + 1) % 3]);
        let a = p[1] - q[1];
        let bb = q[0] - p[0];
        k_origin += (a * (px0 - p[0]) + bb * (py0 - p[1])) as f64 * kw[i];
    }
    k_origin *= inv_area;
    let step = SUBPIXEL;
    for (s, o) in samples.iter().enumerate() {
        let (ox, oy) = (i64::from(o[0]), i64::from(o[1]));
        let mut row = [0i64; 3];
        for i in 0..3 {
            row[i] = e_origin[i] + ea[i] * ox + eb[i] * oy;
        }
        let key_s = k_origin + dkdx * ox as f64 + dkdy * oy as f64;
        let kx = (dkdx * step as f64) as f32;
        // The part of the box inside the window.
        let (wx0, wx1) = (x0.max(window.x0 as i32), x1.min(window.x1 as i32));
        let (wy0, wy1) = (y0.max(window.y0 as i32), y1.min(window.y1 as i32));
        if wx0 >= wx1 || wy0 >= wy1 {
            return;
        }
        for i in 0..3 {
            row[i] += eb[i] * step * i64::from(wy0 - y0) + ea[i] * step * i64::from(wx0 - x0);
        }
        for y in wy0..wy1 {
            let mut e = row;
            let ky_row = (key_s + dkdy * (i64::from(y - y0) * step) as f64) as f32;
            let mut x = wx0;
            while x < wx1 {
                let key = ky_row + kx * (x - x0) as f32;
                frag(x as u32, y as u32, s, key, (e[0] | e[1] | e[2]) >= 0);
                e[0] += ea[0] * step;
                e[1] += ea[1] * step;
                e[2] += ea[2] * step;
                x += 1;
            }
            for i in 0..3 {
                row[i] += eb[i] * step;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn vp(w: u32, h: u32, cull: bool) -> Viewport {
        Viewport {
            width: w,
            height: h,
            cull_back: cull,
            depth_key: DepthKey::InvW,
        }
    }

    /// Clip-space position of a screen point `(sx, sy)` at w = 1.
    fn at(sx: f32, sy: f32, w: u32, h: u32) -> Vec4 {
        Vec4::new(
            sx / w as f32 * 2.0 - 1.0,
            1.0 - sy / h as f32 * 2.0,
            0.5,
            1.0,
        )
    }

    fn coverage(tris: &[[Vec4; 3]], w: u32, h: u32, samples: u32) -> Vec<u32> {
        let v = vp(w, h, false);
        let mut scratch = Vec::new();
        let mut rt = Vec::new();
        for (i, t) in tris.iter().enumerate() {
            v.setup(*t, i as u32, &mut scratch, &mut rt);
        }
        let offs = sample_offsets(samples);
        let mut count = vec![0u32; (w * h * samples) as usize];
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        };
        for t in &rt {
            rasterize(t, rect, &offs, |x, y, s, _| {
                count[((y * w + x) * samples) as usize + s] += 1;
            });
        }
        count
    }

    #[test]
    fn shared_edges_cover_every_sample_exactly_once() {
        // A fan and a grid whose vertices sit exactly on pixel centres and
        // edges (the hard cases of the fill rule), covering the whole viewport
        // with a margin; every sample must be covered exactly once.
        let (w, h) = (24u32, 20u32);
        let mut tris = Vec::new();
        let n = 6;
        let xs: Vec<f32> = (0..=n)
            .map(|i| -2.0 + i as f32 * (w as f32 + 4.0) / n as f32)
            .collect();
        let ys: Vec<f32> = (0..=n)
            .map(|j| -2.5 + j as f32 * (h as f32 + 5.0) / n as f32)
            .collect();
        for j in 0..n {
            for i in 0..n {
                // Split each cell through an interior point on a pixel centre.
                let c = at(
                    ((xs[i] + xs[i + 1]) * 0.5).floor() + 0.5,
                    ((ys[j] + ys[j + 1]) * 0.5).floor() + 0.5,
                    w,
                    h,
                );
                let p00 = at(xs[i], ys[j], w, h);
                let p10 = at(xs[i + 1], ys[j], w, h);
                let p01 = at(xs[i], ys[j + 1], w, h);
                let p11 = at(xs[i + 1], ys[j + 1], w, h);
                tris.push([p00, p10, c]);
                tris.push([p10, p11, c]);
                tris.push([p11, p01, c]);
                tris.push([p01, p00, c]);
            }
        }
        for samples in [1, 4, 5] {
            let count = coverage(&tris, w, h, samples);
            assert!(
                count.iter().all(|&c| c == 1),
                "samples {samples}: {count:?}"
            );
        }
    }

    #[test]
    fn closed_mesh_front_faces_cover_interior_once() {
        // A tessellated sphere seen from outside: with back faces culled, every
        // sample inside its silhouette is covered exactly once.
        let mesh = chiaro_core::geometry::primitives::uv_sphere(1.0, 24, 12);
        let (w, h) = (48u32, 48u32);
        let cam = chiaro_core::scene::Camera {
            eye: Vec3::new(0.3, 0.4, 3.5),
            ..Default::default()
        };
        let m = cam.projection_matrix(1.0) * cam.view_matrix();
        let v = vp(w, h, true);
        let mut scratch = Vec::new();
        let mut rt = Vec::new();
        for (i, t) in mesh.indices.iter().enumerate() {
            let c = t.map(|k| m * mesh.positions[k as usize].extend(1.0));
            v.setup(c, i as u32, &mut scratch, &mut rt);
        }
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        };
        let mut count = vec![0u32; (w * h) as usize];
        for t in &rt {
            rasterize(t, rect, &[[128, 128]], |x, y, _, _| {
                count[(y * w + x) as usize] += 1
            });
        }
        assert!(count.iter().all(|&c| c <= 1), "double coverage");
        // Every pixel whose centre ray hits the tessellation is covered.
        let mut covered = 0;
        for y in 0..h {
            for x in 0..w {
                let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
                let hit = mesh.indices.iter().any(|t| {
                    let [a, b, c] = t.map(|k| mesh.positions[k as usize]);
                    ray_hits(cam.eye, d, a, b, c)
                });
                if hit {
                    covered += 1;
                    assert_eq!(count[(y * w + x) as usize], 1, "pixel {x},{y} not covered");
                }
            }
        }
        assert!(covered > 500);
    }

    fn ray_hits(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> bool {
        let e1 = b - a;
        let e2 = c - a;
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            return false;
        }
        let s = o - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        // Strictly inside (away from edges) so the test is robust.
        u > 1e-4 && v > 1e-4 && u + v < 1.0 - 1e-4 && t > 0.0
    }

    #[test]
    fn back_faces_are_culled_and_front_kept() {
        let (w, h) = (8, 8);
        // Counter-clockwise in NDC (y up) = front.
        let front = [at(1.0, 7.0, w, h), at(7.0, 7.0, w, h), at(4.0, 1.0, w, h)];
        let back = [front[0], front[2], front[1]];
        let v = vp(w, h, true);
        let mut s = Vec::new();
        let mut out = Vec::new();
        v.setup(front, 0, &mut s, &mut out);
        assert_eq!(out.len(), 1);
        assert!(!out[0].back);
        v.setup(back, 1, &mut s, &mut out);
        assert_eq!(out.len(), 1);
    }

    #[test]
    fn key_interpolates_exactly() {
        // A triangle with keys 1/w: the key at a pixel centre equals the
        // screen-space (affine) interpolation of the vertex keys.
        let (w, h) = (16, 16);
        let mut a = at(0.0, 16.0, w, h) * 1.0;
        let mut b = at(16.0, 16.0, w, h) * 2.0;
        let mut c = at(0.0, 0.0, w, h) * 4.0;
        a.w = 1.0;
        b.w = 2.0;
        c.w = 4.0;
        let v = vp(w, h, false);
        let mut s = Vec::new();
        let mut out = Vec::new();
        v.setup([a, b, c], 0, &mut s, &mut out);
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        };
        let mut n = 0;
        rasterize(&out[0], rect, &[[128, 128]], |x, y, _, key| {
            let (sx, sy) = (x as f32 + 0.5, y as f32 + 0.5);
            // Screen-space barycentrics of the right triangle (0,16),(16,16),(0,0).
            let lb = sx / 16.0;
            let lc = (16.0 - sy) / 16.0;
            let la = 1.0 - lb - lc;
            let expect = la * 1.0 + lb * 0.5 + lc * 0.25;
            assert!((key - expect).abs() < 1e-5, "{key} vs {expect}");
            n += 1;
        });
        assert!(n > 100);
    }

    #[test]
    fn fast_rounding_equals_f32_round() {
        let mut x = -5_000_000.0f32;
        let special = [
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_97,
            -0.499_999_97,
            4_194_303.5,
            -4_194_303.5,
            4_194_304.0,
            8_388_607.5,
            1e10,
            -1e10,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
        ];
        for &v in &special {
            assert_eq!(round_to_i32(v), v.round() as i32, "{v}");
        }
        while x < 5_000_000.0 {
            for d in [0.0, 0.25, 0.5, 0.75] {
                let v = x + d;
                assert_eq!(round_to_i32(v), v.round() as i32, "{v}");
            }
            x += 977.312_5;
        }
    }
}
