//! The Utah teapot: Martin Newell's 32 bicubic Bézier patches (1975),
//! tessellated into a triangle mesh with analytic normals.
//!
//! Data: the 306 control points and 32 patch index lists of the classic
//! "teaset" (as in markkilgard/opengl4_examples `tessellation/teapot.cpp`,
//! "adapted from <http://www.sjbaker.org/teapot/teaset.tgz>"). Licence: the teapot data
//! (Martin Newell, 1975) is conventionally treated as public domain. Patch
//! groups (0-based): 0-3 rim, 4-11 body, 12-15 handle, 16-19 spout, 20-27
//! lid, 28-31 bottom (the bottom was not part of Newell's original 28).
//!
//! Frame and scale: the data is z-up with the bottom at z = 0 and the lid
//! knob top at z = 3.15. [`teapot`] turns it y-up (`(x, y, z) -> (x, z, -y)`,
//! a rotation, so handedness and winding are kept) and scales it by
//! `1 / 3.15`, so the teapot sits on `y = 0`, its knob top is at `y = 1`,
//! its body axis is the y axis, the spout points to +x and the whole pot is
//! about 2 units long (spout tip to handle).
//!
//! Normals come from the patch partial derivatives,
//! `N = dP/dv x dP/du` (the data's patches are oriented inward; Farin, *Curves and Surfaces for CAGD*, ch. 6). Lid
//! and bottom patches have a collapsed row of control points (a pole) where
//! one derivative vanishes; there the normal is taken from the nearest
//! parameter point inside the patch where the cross product is not
//! degenerate, so no vertex ever gets a zero or NaN normal (the magazine
//! series' "dark corner" from coincident points). The surface is not watertight:
//! the original data has small gaps and T-junctions between patches.

use crate::scene::Mesh;
use glam::{Vec2, Vec3};

/// Height of the original data (lid knob top), which [`teapot`] maps to 1.
pub const TEAPOT_DATA_HEIGHT: f32 = 3.15;

/// The Utah teapot as a triangle mesh, y up, resting on `y = 0`, knob top at
/// `y = 1` (see the module docs for the frame).
///
/// Each of the 32 patches is evaluated on an `(n + 1) x (n + 1)` grid of
/// `(u, v)` parameters, `n = subdivisions.max(1)`, giving
/// `32 * (n + 1)^2` vertices (patches do not share vertices) and up to
/// `32 * 2 * n * n` triangles, counter-clockwise seen from outside: at the
/// lid and bottom poles, where two corners of a grid triangle coincide, the
/// zero-area triangle is left out (`8 n` of them for `n >= 2`: one per
/// pole quad, fewer where rounding leaves a sliver). Normals are unit and analytic; uvs are the patch parameters
/// `(u, v)` in `[0, 1]^2`.
pub fn teapot(subdivisions: u32) -> Mesh {
    let n = subdivisions.max(1);
    let scale = 1.0 / TEAPOT_DATA_HEIGHT;
    let mut mesh = Mesh {
        name: "teapot".into(),
        ..Mesh::default()
    };
    let verts_per_patch = ((n + 1) * (n + 1)) as usize;
    mesh.positions.reserve(32 * verts_per_patch);
    mesh.normals.reserve(32 * verts_per_patch);
    mesh.uvs.reserve(32 * verts_per_patch);
    mesh.indices.reserve(32 * 2 * (n * n) as usize);

    for patch in &PATCHES {
        // Control points in the y-up frame, scaled.
        let cp: [Vec3; 16] = std::array::from_fn(|k| {
            let [x, y, z] = CONTROL_POINTS[patch[k] as usize];
            Vec3::new(x, z, -y) * scale
        });
        let base = mesh.positions.len() as u32;
        for i in 0..=n {
            let u = i as f32 / n as f32;
            for j in 0..=n {
                let v = j as f32 / n as f32;
                let (p, _, _) = eval_patch(&cp, u, v);
                mesh.positions.push(p);
                mesh.normals.push(patch_normal(&cp, u, v));
                mesh.uvs.push(Vec2::new(u, v));
            }
        }
        // Grid (i, j) -> base + i * (n + 1) + j. Newell's patches are
        // oriented so that Pu x Pv points *into* the pot; the outward normal
        // is Pv x Pu and the corners (i, j) -> (i, j + 1) -> (i + 1, j + 1)
        // run counter-clockwise seen from outside.
        let row = n + 1;
        for i in 0..n {
            for j in 0..n {
                let a = base + i * row + j;
                let (b, c, d) = (a + row, a + row + 1, a + 1);
                for t in [[a, d, c], [a, c, b]] {
                    // At a pole two corners coincide: skip the triangle
                    // (the test `Scene::validate` warns about).
                    let [p0, p1, p2] = t.map(|k| mesh.positions[k as usize]);
                    if (p1 - p0).cross(p2 - p0).length_squared() > 0.0 {
                        mesh.indices.push(t);
                    }
                }
            }
        }
    }
    mesh
}

/// Cubic Bernstein basis `B_k(t)` and its derivative `B_k'(t)`.
fn bernstein(t: f32) -> ([f32; 4], [f32; 4]) {
    let s = 1.0 - t;
    (
        [s * s * s, 3.0 * t * s * s, 3.0 * t * t * s, t * t * t],
        [
            -3.0 * s * s,
            3.0 * s * s - 6.0 * t * s,
            6.0 * t * s - 3.0 * t * t,
            3.0 * t * t,
        ],
    )
}

/// Position and the partial derivatives `(P, dP/du, dP/dv)` of a bicubic
/// Bézier patch; `u` runs over control-point rows, `v` over columns.
fn eval_patch(cp: &[Vec3; 16], u: f32, v: f32) -> (Vec3, Vec3, Vec3) {
    let (bu, du) = bernstein(u);
    let (bv, dv) = bernstein(v);
    let (mut p, mut pu, mut pv) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    for r in 0..4 {
        for c in 0..4 {
            let q = cp[r * 4 + c];
            p += q * (bu[r] * bv[c]);
            pu += q * (du[r] * bv[c]);
            pv += q * (bu[r] * dv[c]);
        }
    }
    (p, pu, pv)
}

/// The outward `dP/dv x dP/du` normalised, or `None` where a tangent
/// vanishes (shorter than `tol`, a length relative to the patch size: at a
/// pole rounding leaves a tiny tangent of arbitrary direction) or the two
/// are (nearly) parallel.
fn cross_normal(cp: &[Vec3; 16], u: f32, v: f32, tol: f32) -> Option<Vec3> {
    let (_, pu, pv) = eval_patch(cp, u, v);
    let c = pv.cross(pu);
    let (lu, lv) = (pu.length(), pv.length());
    (lu > tol && lv > tol && c.length() > 1e-4 * lu * lv).then(|| c.normalize())
}

/// The unit outward normal of the patch at `(u, v)`. At a pole (a collapsed
/// row, where one partial derivative is zero) it steps a little into the
/// patch, along u, along v, then both, and uses the first non-degenerate
/// normal: the limit of the normal at the pole, to `O(step)`.
fn patch_normal(cp: &[Vec3; 16], u: f32, v: f32) -> Vec3 {
    let inward = |t: f32, h: f32| if t < 0.5 { t + h } else { t - h };
    // Tangent lengths below 1e-4 of the control net's size count as zero.
    let (lo, hi) = cp.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| {
        (lo.min(p), hi.max(p))
    });
    let tol = 1e-4 * (hi - lo).length();
    let mut found = cross_normal(cp, u, v, tol);
    for h in [1e-3, 1e-2, 1e-1] {
        if found.is_some() {
            break;
        }
        found = cross_normal(cp, inward(u, h), v, tol * h)
            .or_else(|| cross_normal(cp, u, inward(v, h), tol * h))
            .or_else(|| cross_normal(cp, inward(u, h), inward(v, h), tol * h));
    }
    // A patch degenerate everywhere near (u, v) does not occur in the data;
    // fall back to "up" rather than ever returning zero.
    found.map_or(Vec3::Y, |n| n.normalize_or(Vec3::Y))
}

/// Newell's 32 patches as 0-based indices into [`CONTROL_POINTS`], each a
/// row-major 4x4 grid (`[row * 4 + column]`).
const PATCHES: [[u16; 16]; 32] = [
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15],
    [3, 16, 17, 18, 7, 19, 20, 21, 11, 22, 23, 24, 15, 25, 26, 27],
    [
        18, 28, 29, 30, 21, 31, 32, 33, 24, 34, 35, 36, 27, 37, 38, 39,
    ],
    [30, 40, 41, 0, 33, 42, 43, 4, 36, 44, 45, 8, 39, 46, 47, 12],
    [
        12, 13, 14, 15, 48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59,
    ],
    [
        15, 25, 26, 27, 51, 60, 61, 62, 55, 63, 64, 65, 59, 66, 67, 68,
    ],
    [
        27, 37, 38, 39, 62, 69, 70, 71, 65, 72, 73, 74, 68, 75, 76, 77,
    ],
    [
        39, 46, 47, 12, 71, 78, 79, 48, 74, 80, 81, 52, 77, 82, 83, 56,
    ],
    [
        56, 57, 58, 59, 84, 85, 86, 87, 88, 89, 90, 91, 92, 93, 94, 95,
    ],
    [
        59, 66, 67, 68, 87, 96, 97, 98, 91, 99, 100, 101, 95, 102, 103, 104,
    ],
    [
        68, 75, 76, 77, 98, 105, 106, 107, 101, 108, 109, 110, 104, 111, 112, 113,
    ],
    [
        77, 82, 83, 56, 107, 114, 115, 84, 110, 116, 117, 88, 113, 118, 119, 92,
    ],
    [
        120, 121, 122, 123, 124, 125, 126, 127, 128, 129, 130, 131, 132, 133, 134, 135,
    ],
    [
        123, 136, 137, 120, 127, 138, 139, 124, 131, 140, 141, 128, 135, 142, 143, 132,
    ],
    [
        132, 133, 134, 135, 144, 145, 146, 147, 148, 149, 150, 151, 68, 152, 153, 154,
    ],
    [
        135, 142, 143, 132, 147, 155, 156, 144, 151, 157, 158, 148, 154, 159, 160, 68,
    ],
    [
        161, 162, 163, 164, 165, 166, 167, 168, 169, 170, 171, 172, 173, 174, 175, 176,
    ],
    [
        164, 177, 178, 161, 168, 179, 180, 165, 172, 181, 182, 169, 176, 183, 184, 173,
    ],
    [
        173, 174, 175, 176, 185, 186, 187, 188, 189, 190, 191, 192, 193, 194, 195, 196,
    ],
    [
        176, 183, 184, 173, 188, 197, 198, 185, 192, 199, 200, 189, 196, 201, 202, 193,
    ],
    [
        203, 203, 203, 203, 206, 207, 208, 209, 210, 210, 210, 210, 211, 212, 213, 214,
    ],
    [
        203, 203, 203, 203, 209, 216, 217, 218, 210, 210, 210, 210, 214, 219, 220, 221,
    ],
    [
        203, 203, 203, 203, 218, 223, 224, 225, 210, 210, 210, 210, 221, 226, 227, 228,
    ],
    [
        203, 203, 203, 203, 225, 229, 230, 206, 210, 210, 210, 210, 228, 231, 232, 211,
    ],
    [
        211, 212, 213, 214, 233, 234, 235, 236, 237, 238, 239, 240, 241, 242, 243, 244,
    ],
    [
        214, 219, 220, 221, 236, 245, 246, 247, 240, 248, 249, 250, 244, 251, 252, 253,
    ],
    [
        221, 226, 227, 228, 247, 254, 255, 256, 250, 257, 258, 259, 253, 260, 261, 262,
    ],
    [
        228, 231, 232, 211, 256, 263, 264, 233, 259, 265, 266, 237, 262, 267, 268, 241,
    ],
    [
        269, 269, 269, 269, 278, 279, 280, 281, 274, 275, 276, 277, 270, 271, 272, 273,
    ],
    [
        269, 269, 269, 269, 281, 288, 289, 290, 277, 285, 286, 287, 273, 282, 283, 284,
    ],
    [
        269, 269, 269, 269, 290, 297, 298, 299, 287, 294, 295, 296, 284, 291, 292, 293,
    ],
    [
        269, 269, 269, 269, 299, 304, 305, 278, 296, 302, 303, 274, 293, 300, 301, 270,
    ],
];

/// Newell's 306 control points in the data's own frame (z up, bottom at
/// z = 0, lid knob top at z = 3.15), exactly as published.
const CONTROL_POINTS: [[f32; 3]; 306] = [
    [1.4, 0.0, 2.4],
    [1.4, -0.784, 2.4],
    [0.784, -1.4, 2.4],
    [0.0, -1.4, 2.4],
    [1.3375, 0.0, 2.53125],
    [1.3375, -0.749, 2.53125],
    [0.749, -1.3375, 2.53125],
    [0.0, -1.3375, 2.53125],
    [1.4375, 0.0, 2.53125],
    [1.4375, -0.805, 2.53125],
    [0.805, -1.4375, 2.53125],
    [0.0, -1.4375, 2.53125],
    [1.5, 0.0, 2.4],
    [1.5, -0.84, 2.4],
    [0.84, -1.5, 2.4],
    [0.0, -1.5, 2.4],
    [-0.784, -1.4, 2.4],
    [-1.4, -0.784, 2.4],
    [-1.4, 0.0, 2.4],
    [-0.749, -1.3375, 2.53125],
    [-1.3375, -0.749, 2.53125],
    [-1.3375, 0.0, 2.53125],
    [-0.805, -1.4375, 2.53125],
    [-1.4375, -0.805, 2.53125],
    [-1.4375, 0.0, 2.53125],
    [-0.84, -1.5, 2.4],
    [-1.5, -0.84, 2.4],
    [-1.5, 0.0, 2.4],
    [-1.4, 0.784, 2.4],
    [-0.784, 1.4, 2.4],
    [0.0, 1.4, 2.4],
    [-1.3375, 0.749, 2.53125],
    [-0.749, 1.3375, 2.53125],
    [0.0, 1.3375, 2.53125],
    [-1.4375, 0.805, 2.53125],
    [-0.805, 1.4375, 2.53125],
    [0.0, 1.4375, 2.53125],
    [-1.5, 0.84, 2.4],
    [-0.84, 1.5, 2.4],
    [0.0, 1.5, 2.4],
    [0.784, 1.4, 2.4],
    [1.4, 0.784, 2.4],
    [0.749, 1.3375, 2.53125],
    [1.3375, 0.749, 2.53125],
    [0.805, 1.4375, 2.53125],
    [1.4375, 0.805, 2.53125],
    [0.84, 1.5, 2.4],
    [1.5, 0.84, 2.4],
    [1.75, 0.0, 1.875],
    [1.75, -0.98, 1.875],
    [0.98, -1.75, 1.875],
    [0.0, -1.75, 1.875],
    [2.0, 0.0, 1.35],
    [2.0, -1.12, 1.35],
    [1.12, -2.0, 1.35],
    [0.0, -2.0, 1.35],
    [2.0, 0.0, 0.9],
    [2.0, -1.12, 0.9],
    [1.12, -2.0, 0.9],
    [0.0, -2.0, 0.9],
    [-0.98, -1.75, 1.875],
    [-1.75, -0.98, 1.875],
    [-1.75, 0.0, 1.875],
    [-1.12, -2.0, 1.35],
    [-2.0, -1.12, 1.35],
    [-2.0, 0.0, 1.35],
    [-1.12, -2.0, 0.9],
    [-2.0, -1.12, 0.9],
    [-2.0, 0.0, 0.9],
    [-1.75, 0.98, 1.875],
    [-0.98, 1.75, 1.875],
    [0.0, 1.75, 1.875],
    [-2.0, 1.12, 1.35],
    [-1.12, 2.0, 1.35],
    [0.0, 2.0, 1.35],
    [-2.0, 1.12, 0.9],
    [-1.12, 2.0, 0.9],
    [0.0, 2.0, 0.9],
    [0.98, 1.75, 1.875],
    [1.75, 0.98, 1.875],
    [1.12, 2.0, 1.35],
    [2.0, 1.12, 1.35],
    [1.12, 2.0, 0.9],
    [2.0, 1.12, 0.9],
    [2.0, 0.0, 0.45],
    [2.0, -1.12, 0.45],
    [1.12, -2.0, 0.45],
    [0.0, -2.0, 0.45],
    [1.5, 0.0, 0.225],
    [1.5, -0.84, 0.225],
    [0.84, -1.5, 0.225],
    [0.0, -1.5, 0.225],
    [1.5, 0.0, 0.15],
    [1.5, -0.84, 0.15],
    [0.84, -1.5, 0.15],
    [0.0, -1.5, 0.15],
    [-1.12, -2.0, 0.45],
    [-2.0, -1.12, 0.45],
    [-2.0, 0.0, 0.45],
    [-0.84, -1.5, 0.225],
    [-1.5, -0.84, 0.225],
    [-1.5, 0.0, 0.225],
    [-0.84, -1.5, 0.15],
    [-1.5, -0.84, 0.15],
    [-1.5, 0.0, 0.15],
    [-2.0, 1.12, 0.45],
    [-1.12, 2.0, 0.45],
    [0.0, 2.0, 0.45],
    [-1.5, 0.84, 0.225],
    [-0.84, 1.5, 0.225],
    [0.0, 1.5, 0.225],
    [-1.5, 0.84, 0.15],
    [-0.84, 1.5, 0.15],
    [0.0, 1.5, 0.15],
    [1.12, 2.0, 0.45],
    [2.0, 1.12, 0.45],
    [0.84, 1.5, 0.225],
    [1.5, 0.84, 0.225],
    [0.84, 1.5, 0.15],
    [1.5, 0.84, 0.15],
    [-1.6, 0.0, 2.025],
    [-1.6, -0.3, 2.025],
    [-1.5, -0.3, 2.25],
    [-1.5, 0.0, 2.25],
    [-2.3, 0.0, 2.025],
    [-2.3, -0.3, 2.025],
    [-2.5, -0.3, 2.25],
    [-2.5, 0.0, 2.25],
    [-2.7, 0.0, 2.025],
    [-2.7, -0.3, 2.025],
    [-3.0, -0.3, 2.25],
    [-3.0, 0.0, 2.25],
    [-2.7, 0.0, 1.8],
    [-2.7, -0.3, 1.8],
    [-3.0, -0.3, 1.8],
    [-3.0, 0.0, 1.8],
    [-1.5, 0.3, 2.25],
    [-1.6, 0.3, 2.025],
    [-2.5, 0.3, 2.25],
    [-2.3, 0.3, 2.025],
    [-3.0, 0.3, 2.25],
    [-2.7, 0.3, 2.025],
    [-3.0, 0.3, 1.8],
    [-2.7, 0.3, 1.8],
    [-2.7, 0.0, 1.575],
    [-2.7, -0.3, 1.575],
    [-3.0, -0.3, 1.35],
    [-3.0, 0.0, 1.35],
    [-2.5, 0.0, 1.125],
    [-2.5, -0.3, 1.125],
    [-2.65, -0.3, 0.9375],
    [-2.65, 0.0, 0.9375],
    [-2.0, -0.3, 0.9],
    [-1.9, -0.3, 0.6],
    [-1.9, 0.0, 0.6],
    [-3.0, 0.3, 1.35],
    [-2.7, 0.3, 1.575],
    [-2.65, 0.3, 0.9375],
    [-2.5, 0.3, 1.125],
    [-1.9, 0.3, 0.6],
    [-2.0, 0.3, 0.9],
    [1.7, 0.0, 1.425],
    [1.7, -0.66, 1.425],
    [1.7, -0.66, 0.6],
    [1.7, 0.0, 0.6],
    [2.6, 0.0, 1.425],
    [2.6, -0.66, 1.425],
    [3.1, -0.66, 0.825],
    [3.1, 0.0, 0.825],
    [2.3, 0.0, 2.1],
    [2.3, -0.25, 2.1],
    [2.4, -0.25, 2.025],
    [2.4, 0.0, 2.025],
    [2.7, 0.0, 2.4],
    [2.7, -0.25, 2.4],
    [3.3, -0.25, 2.4],
    [3.3, 0.0, 2.4],
    [1.7, 0.66, 0.6],
    [1.7, 0.66, 1.425],
    [3.1, 0.66, 0.825],
    [2.6, 0.66, 1.425],
    [2.4, 0.25, 2.025],
    [2.3, 0.25, 2.1],
    [3.3, 0.25, 2.4],
    [2.7, 0.25, 2.4],
    [2.8, 0.0, 2.475],
    [2.8, -0.25, 2.475],
    [3.525, -0.25, 2.49375],
    [3.525, 0.0, 2.49375],
    [2.9, 0.0, 2.475],
    [2.9, -0.15, 2.475],
    [3.45, -0.15, 2.5125],
    [3.45, 0.0, 2.5125],
    [2.8, 0.0, 2.4],
    [2.8, -0.15, 2.4],
    [3.2, -0.15, 2.4],
    [3.2, 0.0, 2.4],
    [3.525, 0.25, 2.49375],
    [2.8, 0.25, 2.475],
    [3.45, 0.15, 2.5125],
    [2.9, 0.15, 2.475],
    [3.2, 0.15, 2.4],
    [2.8, 0.15, 2.4],
    [0.0, 0.0, 3.15],
    [0.0, -0.002, 3.15],
    [0.002, 0.0, 3.15],
    [0.8, 0.0, 3.15],
    [0.8, -0.45, 3.15],
    [0.45, -0.8, 3.15],
    [0.0, -0.8, 3.15],
    [0.0, 0.0, 2.85],
    [0.2, 0.0, 2.7],
    [0.2, -0.112, 2.7],
    [0.112, -0.2, 2.7],
    [0.0, -0.2, 2.7],
    [-0.002, 0.0, 3.15],
    [-0.45, -0.8, 3.15],
    [-0.8, -0.45, 3.15],
    [-0.8, 0.0, 3.15],
    [-0.112, -0.2, 2.7],
    [-0.2, -0.112, 2.7],
    [-0.2, 0.0, 2.7],
    [0.0, 0.002, 3.15],
    [-0.8, 0.45, 3.15],
    [-0.45, 0.8, 3.15],
    [0.0, 0.8, 3.15],
    [-0.2, 0.112, 2.7],
    [-0.112, 0.2, 2.7],
    [0.0, 0.2, 2.7],
    [0.45, 0.8, 3.15],
    [0.8, 0.45, 3.15],
    [0.112, 0.2, 2.7],
    [0.2, 0.112, 2.7],
    [0.4, 0.0, 2.55],
    [0.4, -0.224, 2.55],
    [0.224, -0.4, 2.55],
    [0.0, -0.4, 2.55],
    [1.3, 0.0, 2.55],
    [1.3, -0.728, 2.55],
    [0.728, -1.3, 2.55],
    [0.0, -1.3, 2.55],
    [1.3, 0.0, 2.4],
    [1.3, -0.728, 2.4],
    [0.728, -1.3, 2.4],
    [0.0, -1.3, 2.4],
    [-0.224, -0.4, 2.55],
    [-0.4, -0.224, 2.55],
    [-0.4, 0.0, 2.55],
    [-0.728, -1.3, 2.55],
    [-1.3, -0.728, 2.55],
    [-1.3, 0.0, 2.55],
    [-0.728, -1.3, 2.4],
    [-1.3, -0.728, 2.4],
    [-1.3, 0.0, 2.4],
    [-0.4, 0.224, 2.55],
    [-0.224, 0.4, 2.55],
    [0.0, 0.4, 2.55],
    [-1.3, 0.728, 2.55],
    [-0.728, 1.3, 2.55],
    [0.0, 1.3, 2.55],
    [-1.3, 0.728, 2.4],
    [-0.728, 1.3, 2.4],
    [0.0, 1.3, 2.4],
    [0.224, 0.4, 2.55],
    [0.4, 0.224, 2.55],
    [0.728, 1.3, 2.55],
    [1.3, 0.728, 2.55],
    [0.728, 1.3, 2.4],
    [1.3, 0.728, 2.4],
    [0.0, 0.0, 0.0],
    [1.5, 0.0, 0.15],
    [1.5, 0.84, 0.15],
    [0.84, 1.5, 0.15],
    [0.0, 1.5, 0.15],
    [1.5, 0.0, 0.075],
    [1.5, 0.84, 0.075],
    [0.84, 1.5, 0.075],
    [0.0, 1.5, 0.075],
    [1.425, 0.0, 0.0],
    [1.425, 0.798, 0.0],
    [0.798, 1.425, 0.0],
    [0.0, 1.425, 0.0],
    [-0.84, 1.5, 0.15],
    [-1.5, 0.84, 0.15],
    [-1.5, 0.0, 0.15],
    [-0.84, 1.5, 0.075],
    [-1.5, 0.84, 0.075],
    [-1.5, 0.0, 0.075],
    [-0.798, 1.425, 0.0],
    [-1.425, 0.798, 0.0],
    [-1.425, 0.0, 0.0],
    [-1.5, -0.84, 0.15],
    [-0.84, -1.5, 0.15],
    [0.0, -1.5, 0.15],
    [-1.5, -0.84, 0.075],
    [-0.84, -1.5, 0.075],
    [0.0, -1.5, 0.075],
    [-1.425, -0.798, 0.0],
    [-0.798, -1.425, 0.0],
    [0.0, -1.425, 0.0],
    [0.84, -1.5, 0.15],
    [1.5, -0.84, 0.15],
    [0.84, -1.5, 0.075],
    [1.5, -0.84, 0.075],
    [0.798, -1.425, 0.0],
    [1.425, -0.798, 0.0],
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_and_vertex_counts() {
        for n in [1, 3, 8] {
            let m = teapot(n);
            let full = (32 * 2 * n * n) as usize;
            let dropped = full - m.indices.len();
            // Only triangles of the pole rows of the eight lid and bottom
            // patches can collapse (8 n quads of two triangles).
            assert!((1..=(16 * n) as usize).contains(&dropped), "{dropped}");
            assert!(m.indices.iter().all(|t| {
                let [a, b, c] = t.map(|k| m.positions[k as usize]);
                (b - a).cross(c - a).length_squared() > 0.0
            }));
            assert_eq!(m.positions.len(), (32 * (n + 1) * (n + 1)) as usize);
            assert_eq!(m.normals.len(), m.positions.len());
            assert_eq!(m.uvs.len(), m.positions.len());
            let max = m.positions.len() as u32;
            assert!(m.indices.iter().flatten().all(|&i| i < max));
        }
    }

    #[test]
    fn no_nan_and_unit_normals() {
        let m = teapot(10);
        assert!(m.positions.iter().all(|p| p.is_finite()));
        for n in &m.normals {
            assert!(n.is_finite());
            assert!((n.length() - 1.0).abs() < 1e-4, "normal {n}");
        }
        assert!(
            m.uvs
                .iter()
                .all(|t| (0.0..=1.0).contains(&t.x) && (0.0..=1.0).contains(&t.y))
        );
    }

    #[test]
    fn sits_on_the_ground_at_unit_height() {
        let m = teapot(8);
        let min_y = m.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
        let max_y = m.positions.iter().map(|p| p.y).fold(f32::MIN, f32::max);
        assert!(min_y.abs() < 1e-5, "min y {min_y}");
        assert!((max_y - 1.0).abs() < 1e-5, "max y {max_y}");
        // Spout at +x, handle at -x: longer on the spout side.
        let min_x = m.positions.iter().map(|p| p.x).fold(f32::MAX, f32::min);
        let max_x = m.positions.iter().map(|p| p.x).fold(f32::MIN, f32::max);
        assert!(
            max_x > -min_x && max_x > 0.9 && min_x < -0.8,
            "{min_x} {max_x}"
        );
    }

    /// Fraction of the vertices of patches `range` whose normal satisfies `ok`.
    fn fraction(
        m: &Mesh,
        n: u32,
        range: std::ops::Range<usize>,
        ok: impl Fn(Vec3, Vec3) -> bool,
    ) -> f32 {
        let per = ((n + 1) * (n + 1)) as usize;
        let vs = range.start * per..range.end * per;
        let good = vs
            .clone()
            .filter(|&i| ok(m.positions[i], m.normals[i]))
            .count();
        good as f32 / vs.len() as f32
    }

    #[test]
    fn normals_point_outward() {
        let n = 8;
        let m = teapot(n);
        // Body: away from the vertical axis.
        let radial = |p: Vec3, nn: Vec3| nn.dot(Vec3::new(p.x, 0.0, p.z)) > 0.0;
        assert!(fraction(&m, n, 4..12, radial) > 0.97);
        // The rim is a lip curling out and down: mostly up. Lid: up (the
        // knob's underside faces down); bottom: down.
        assert!(fraction(&m, n, 0..4, |_, nn| nn.y > 0.0) > 0.7);
        assert!(fraction(&m, n, 24..28, |_, nn| nn.y > 0.0) > 0.95);
        let knob = |p: Vec3, nn: Vec3| nn.dot(p - Vec3::new(0.0, 0.85, 0.0)) > 0.0;
        let f = fraction(&m, n, 20..24, knob);
        assert!(f > 0.8, "knob {f}");
        assert!(fraction(&m, n, 28..32, |_, nn| nn.y < 0.0) > 0.9);
        // Handle and spout are tubes made of pairs of patches (two halves
        // of each segment); a row of constant u in both halves is a ring
        // around the tube. Normals point away from the ring's centre. The
        // spout's last segment (18, 19) is its lip, folding over into the
        // spout like the rim: only its outer quarter is checked.
        let row = (n + 1) as usize;
        let per = row * row;
        for (pair, rows) in [
            ([12, 13], 0..=n as usize),
            ([14, 15], 0..=n as usize),
            ([16, 17], 0..=n as usize),
            ([18, 19], 0..=n as usize / 4),
        ] {
            let (mut good, mut total) = (0, 0);
            for i in rows {
                let ring: Vec<usize> = pair
                    .iter()
                    .flat_map(|&k| (0..row).map(move |j| k * per + i * row + j))
                    .collect();
                let c = ring.iter().map(|&v| m.positions[v]).sum::<Vec3>() / ring.len() as f32;
                for &v in &ring {
                    total += 1;
                    if m.normals[v].dot(m.positions[v] - c) > 0.0 {
                        good += 1;
                    }
                }
            }
            assert!(
                good as f32 / total as f32 > 0.97,
                "patches {pair:?}: {good}/{total}"
            );
        }
    }

    #[test]
    fn normals_agree_where_patches_meet() {
        // Vertices of different patches at the same place are on a smooth
        // seam (the data has no creases), so their normals must agree.
        let n = 6;
        let m = teapot(n);
        let per = ((n + 1) * (n + 1)) as usize;
        let key = |p: Vec3| (p * 1e4).round().to_array().map(|x| x as i32);
        let tube = |k: usize| (12..20).contains(&k);
        let junction = |a: usize, b: usize| tube(a) != tube(b);
        let mut first: std::collections::HashMap<[i32; 3], (usize, Vec3)> = Default::default();
        let (mut pairs, mut bad) = (0, 0);
        for (v, (&p, &nn)) in m.positions.iter().zip(&m.normals).enumerate() {
            match first.get(&key(p)) {
                // The handle and spout ends meet the body at a crease.
                Some(&(w, other)) if w / per != v / per && !junction(w / per, v / per) => {
                    pairs += 1;
                    if nn.dot(other) < 0.9 {
                        bad += 1;
                    }
                }
                None => {
                    first.insert(key(p), (v, nn));
                }
                _ => {}
            }
        }
        assert!(pairs > 32 * n as usize, "{pairs} seam vertices");
        assert!(bad * 50 < pairs, "{bad} of {pairs} seam normals disagree");
    }

    #[test]
    fn winding_agrees_with_normals() {
        let m = teapot(6);
        let (mut agree, mut total) = (0, 0);
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let Some(f) = crate::geometry::face_normal(a, b, c) else {
                continue;
            };
            let avg: Vec3 = t.iter().map(|&i| m.normals[i as usize]).sum();
            total += 1;
            if f.dot(avg) > 0.0 {
                agree += 1;
            }
        }
        assert!(agree as f32 / total as f32 > 0.99, "{agree}/{total}");
    }

    #[test]
    fn poles_get_the_axis_normal() {
        // The lid knob top and the bottom centre lie on the y axis; every
        // vertex there must get a normal along +-y, never zero.
        let m = teapot(4);
        for (p, nn) in m.positions.iter().zip(&m.normals) {
            if p.x.abs() < 1e-6 && p.z.abs() < 1e-6 {
                assert!(nn.y.abs() > 0.99, "pole {p} normal {nn}");
            }
        }
    }

    #[test]
    fn data_is_consistent() {
        assert!(
            PATCHES
                .iter()
                .flatten()
                .all(|&i| (i as usize) < CONTROL_POINTS.len())
        );
        assert_eq!(CONTROL_POINTS[0], [1.4, 0.0, 2.4]);
    }
}
