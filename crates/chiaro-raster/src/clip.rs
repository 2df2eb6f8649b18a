//! Homogeneous clipping of triangles in clip space (Sutherland and Hodgman
//! 1974; Blinn and Newell 1978, "Clipping using homogeneous coordinates").
//!
//! Triangles are clipped against the near plane `z >= 0` (the Direct3D/Vulkan
//! clip-space convention of [`chiaro_core::scene::Camera::projection_matrix`],
//! where `z_clip >= 0` is exactly `view depth >= near`) and against a guard
//! band `|x| <= G w`, `|y| <= G w` with `G = GUARD_BAND`. The guard band lies
//! outside the viewport, so the new edges it makes are never visible: it only
//! keeps snapped screen coordinates inside the fixed-point range of the
//! rasterizer. There is no far plane: the depth buffer stores `1/w`, which
//! needs none (an infinite far plane, as with reversed-Z).
//!
//! Every clipped vertex carries its barycentric weights with respect to the
//! original triangle, so attributes of the original vertices can still be
//! interpolated after clipping.

use glam::{Vec3, Vec4};

/// Half-width of the guard band in NDC units (the viewport is `[-1, 1]`).
pub const GUARD_BAND: f32 = 2.0;

/// A clip-space vertex with its barycentric weights on the source triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipVertex {
    /// Homogeneous clip-space position.
    pub clip: Vec4,
    /// Weights of the source triangle's three vertices (sum to one).
    pub bary: Vec3,
}

/// Signed distances of `c` to the five clip planes; inside where all are >= 0.
#[inline]
fn plane_distances(c: Vec4) -> [f32; 5] {
    let g = GUARD_BAND * c.w;
    [c.z, g - c.x, g + c.x, g - c.y, g + c.y]
}

/// Outcode: bit `i` set when the point is outside plane `i`.
#[inline]
pub fn outcode(c: Vec4) -> u8 {
    let d = plane_distances(c);
    let mut code = 0u8;
    for (i, di) in d.iter().enumerate() {
        // NaN distances count as outside.
        if di.is_nan() || *di < 0.0 {
            code |= 1 << i;
        }
    }
    code
}

/// Clips the triangle `v` against the near plane and the guard band.
///
/// Returns the clipped convex polygon (0 or 3..=8 vertices) in `out`,
/// keeping the winding of the input. `out` is cleared first.
pub fn clip_triangle(v: [Vec4; 3], out: &mut Vec<ClipVertex>) {
    out.clear();
    let codes = [outcode(v[0]), outcode(v[1]), outcode(v[2])];
    let bary = [Vec3::X, Vec3::Y, Vec3::Z];
    if codes[0] | codes[1] | codes[2] == 0 {
        out.extend((0..3).map(|i| ClipVertex {
            clip: v[i],
            bary: bary[i],
        }));
        return;
    }
    if codes[0] & codes[1] & codes[2] != 0 {
        return;
    }
    let mut poly: Vec<ClipVertex> = (0..3)
        .map(|i| ClipVertex {
            clip: v[i],
            bary: bary[i],
        })
        .collect();
    let mut next = Vec::with_capacity(9);
    for plane in 0..5 {
        next.clear();
        let n = poly.len();
        for i in 0..n {
            let a = poly[i];
            let b = poly[(i + 1) % n];
            let da = plane_distances(a.clip)[plane];
            let db = plane_distances(b.clip)[plane];
            let a_in = da >= 0.0;
            let b_in = db >= 0.0;
            if a_in {
                next.push(a);
            }
            if a_in != b_in {
                // Intersection at t where the distance interpolates to zero.
                let t = da / (da - db);
                if t.is_finite() {
                    next.push(ClipVertex {
                        clip: a.clip.lerp(b.clip, t),
                        bary: a.bary.lerp(b.bary, t),
                    });
                }
            }
        }
        std::mem::swap(&mut poly, &mut next);
        if poly.len() < 3 {
            return;
        }
    }
    out.extend_from_slice(&poly);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_triangle_is_unchanged() {
        let v = [
            Vec4::new(0.0, 0.0, 0.5, 1.0),
            Vec4::new(0.5, 0.0, 0.5, 1.0),
            Vec4::new(0.0, 0.5, 0.5, 1.0),
        ];
        let mut out = Vec::new();
        clip_triangle(v, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(out[1].clip, v[1]);
    }

    #[test]
    fn near_plane_cuts_a_vertex_off() {
        // One vertex behind the near plane (z < 0): a quad remains, every
        // vertex has z >= 0 and barycentrics that reproduce its position.
        let v = [
            Vec4::new(0.0, 0.0, -1.0, 0.5),
            Vec4::new(0.5, 0.0, 0.5, 1.0),
            Vec4::new(0.0, 0.5, 0.5, 1.0),
        ];
        let mut out = Vec::new();
        clip_triangle(v, &mut out);
        assert_eq!(out.len(), 4);
        for cv in &out {
            assert!(cv.clip.z >= -1e-6);
            let p = v[0] * cv.bary.x + v[1] * cv.bary.y + v[2] * cv.bary.z;
            assert!((p - cv.clip).length() < 1e-5);
        }
    }

    #[test]
    fn fully_behind_is_rejected() {
        let v = [
            Vec4::new(0.0, 0.0, -1.0, -0.5),
            Vec4::new(0.5, 0.0, -1.0, -1.0),
            Vec4::new(0.0, 0.5, -1.0, -1.0),
        ];
        let mut out = Vec::new();
        clip_triangle(v, &mut out);
        assert!(out.is_empty());
    }
}
