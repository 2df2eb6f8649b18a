//! Face and vertex normals and tangents.
//!
//! Vertex normals are the angle-weighted average of the normals of the faces
//! around a vertex (Thürmer and Wüthrich 1998), skipping faces whose normal
//! differs by more than a crease angle from the face being drawn, so a cube
//! stays faceted and a sphere is smooth (the seeds' "keep real edges sharp").
//! Zero-area faces contribute nothing: coincident points never produce a
//! zero normal and a dark corner (the seed's warning).

use glam::{Vec2, Vec3, Vec4};
use std::collections::HashMap;

/// The unit normal of triangle `(a, b, c)` (counter-clockwise front), or
/// `None` when the triangle has zero area (coincident or collinear points).
#[inline]
pub fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Option<Vec3> {
    // Cross the two edges at the vertex opposite the longest edge: the most
    // accurate pair in floating point.
    let (e0, e1, e2) = (b - a, c - b, a - c);
    let (l0, l1, l2) = (
        e0.length_squared(),
        e1.length_squared(),
        e2.length_squared(),
    );
    let n = if l0 >= l1 && l0 >= l2 {
        e1.cross(e2)
    } else if l1 >= l2 {
        e2.cross(e0)
    } else {
        e0.cross(e1)
    };
    let len = n.length();
    if len > 0.0 && len.is_finite() && len > 1e-12 * (l0 + l1 + l2) {
        Some(n / len)
    } else {
        None
    }
}

/// Newell's method: the unit normal of a planar or nearly planar polygon,
/// robust to repeated points; `None` for a degenerate polygon.
pub fn polygon_normal(points: &[Vec3]) -> Option<Vec3> {
    let mut n = Vec3::ZERO;
    for (i, p) in points.iter().enumerate() {
        let q = points[(i + 1) % points.len()];
        n += Vec3::new(
            (p.y - q.y) * (p.z + q.z),
            (p.z - q.z) * (p.x + q.x),
            (p.x - q.x) * (p.y + q.y),
        );
    }
    n.try_normalize()
}

/// A mesh re-indexed so that every vertex carries one normal.
#[derive(Debug, Clone, PartialEq)]
pub struct SmoothedMesh {
    /// For each new vertex, the index of the original vertex it copies.
    pub source_vertex: Vec<u32>,
    /// Unit normal of each new vertex.
    pub normals: Vec<Vec3>,
    /// Triangles over the new vertices (same order as the input).
    pub indices: Vec<[u32; 3]>,
}

/// Vertex normals with a crease angle. Vertices at the same position are
/// treated as one for averaging (so uv seams stay smooth), and a vertex is
/// split wherever faces around it meet at more than `crease_degrees`.
/// Degenerate triangles keep their indices and receive the normal of a
/// neighbour (or +z when alone).
pub fn vertex_normals(
    positions: &[Vec3],
    indices: &[[u32; 3]],
    crease_degrees: f32,
) -> SmoothedMesh {
    let cos_crease = crease_degrees.clamp(0.0, 180.0).to_radians().cos();
    // Weld by position (quantised to a millionth of the mesh size) for adjacency.
    let extent = super::Aabb::from_points(positions.iter().copied())
        .extent()
        .max_element()
        .max(1e-30);
    let quantum = extent * 1e-6;
    let mut canon: HashMap<[i64; 3], u32> = HashMap::with_capacity(positions.len());
    let weld: Vec<u32> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let q = (*p / quantum).round();
            *canon
                .entry([q.x as i64, q.y as i64, q.z as i64])
                .or_insert(i as u32)
        })
        .collect();
    let face_n: Vec<Option<Vec3>> = indices
        .iter()
        .map(|t| {
            face_normal(
                positions[t[0] as usize],
                positions[t[1] as usize],
                positions[t[2] as usize],
            )
        })
        .collect();
    // Corner angle weights.
    let corner_angle = |t: &[u32; 3], k: usize| -> f32 {
        let p = positions[t[k] as usize];
        let a = (positions[t[(k + 1) % 3] as usize] - p).normalize_or_zero();
        let b = (positions[t[(k + 2) % 3] as usize] - p).normalize_or_zero();
        a.dot(b).clamp(-1.0, 1.0).acos()
    };
    // Faces around each welded vertex.
    let mut around: HashMap<u32, Vec<(u32, f32)>> = HashMap::new();
    for (f, t) in indices.iter().enumerate() {
        if face_n[f].is_none() {
            continue;
        }
        for k in 0..3 {
            around
                .entry(weld[t[k] as usize])
                .or_default()
                .push((f as u32, corner_angle(t, k)));
        }
    }
    let mut out = SmoothedMesh {
        source_vertex: Vec::new(),
        normals: Vec::new(),
        indices: Vec::with_capacity(indices.len()),
    };
    // (original vertex, quantised normal) -> new vertex
    let mut made: HashMap<(u32, [i32; 3]), u32> = HashMap::new();
    for (f, t) in indices.iter().enumerate() {
        let fallback = face_n[f];
        let mut tri = [0u32; 3];
        for k in 0..3 {
            let v = t[k];
            let n = match fallback {
                Some(nf) => {
                    let mut sum = Vec3::ZERO;
                    if let Some(list) = around.get(&weld[v as usize]) {
                        for &(g, w) in list {
                            if let Some(ng) = face_n[g as usize]
                                && ng.dot(nf) >= cos_crease - 1e-6
                            {
                                sum += ng * w;
                            }
                        }
                    }
                    sum.try_normalize().unwrap_or(nf)
                }
                None => around
                    .get(&weld[v as usize])
                    .and_then(|l| l.first())
                    .and_then(|&(g, _)| face_n[g as usize])
                    .unwrap_or(Vec3::Z),
            };
            let key = (
                v,
                [(n.x * 1e5) as i32, (n.y * 1e5) as i32, (n.z * 1e5) as i32],
            );
            tri[k] = *made.entry(key).or_insert_with(|| {
                out.source_vertex.push(v);
                out.normals.push(n);
                out.source_vertex.len() as u32 - 1
            });
        }
        out.indices.push(tri);
    }
    out
}

/// Per-vertex tangents from uv derivatives (Lengyel's method), orthogonalised
/// against the normals, with the bitangent sign in `w` (glTF convention:
/// the bitangent `w (n x t)` is the normal map's +Y, up in the image, which
/// with `v = 0` at the top row is the direction of decreasing `v`, as the
/// glTF sample viewer and MikkTSpace on flipped `v` give).
/// Vertices without a usable uv gradient get an arbitrary tangent
/// perpendicular to the normal.
pub fn tangents(
    positions: &[Vec3],
    normals: &[Vec3],
    uvs: &[Vec2],
    indices: &[[u32; 3]],
) -> Vec<Vec4> {
    let n = positions.len();
    let mut tan = vec![Vec3::ZERO; n];
    let mut bit = vec![Vec3::ZERO; n];
    if uvs.len() == n {
        for t in indices {
            let [a, b, c] = t.map(|i| i as usize);
            let (e1, e2) = (positions[b] - positions[a], positions[c] - positions[a]);
            let (d1, d2) = (uvs[b] - uvs[a], uvs[c] - uvs[a]);
            let det = d1.x * d2.y - d2.x * d1.y;
            if det.abs() < 1e-20 || !det.is_finite() {
                continue;
            }
            let r = 1.0 / det;
            let s = (e1 * d2.y - e2 * d1.y) * r;
            let tt = (e2 * d1.x - e1 * d2.x) * r;
            for v in [a, b, c] {
                tan[v] += s;
                bit[v] += tt;
            }
        }
    }
    (0..n)
        .map(|i| {
            let nn = normals.get(i).copied().unwrap_or(Vec3::Z);
            let t = (tan[i] - nn * nn.dot(tan[i]))
                .try_normalize()
                .unwrap_or_else(|| super::Frame::from_normal(nn).s);
            // +1 when n x t points up the image (along -dp/dv), -1 for mirrored uvs.
            let w = if nn.cross(t).dot(bit[i]) > 0.0 {
                -1.0
            } else {
                1.0
            };
            t.extend(w)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitives;

    #[test]
    fn tangent_bitangent_is_up_the_image_and_flips_for_mirrored_uvs() {
        // An upright image on a quad facing +z (v = 0 at its top edge): the
        // tangent is +x and the bitangent n x t = +y, the normal map's +Y.
        let q = primitives::quad(Vec3::ZERO, Vec3::X, Vec3::Y);
        for t in tangents(&q.positions, &q.normals, &q.uvs, &q.indices) {
            assert!((t.truncate() - Vec3::X).length() < 1e-6, "{t}");
            assert_eq!(t.w, 1.0);
        }
        // The image mirrored left to right: the tangent is -x, and the
        // bitangent must stay +y, so w = -1.
        let uvs: Vec<Vec2> = q.uvs.iter().map(|uv| Vec2::new(1.0 - uv.x, uv.y)).collect();
        for t in tangents(&q.positions, &q.normals, &uvs, &q.indices) {
            assert!((t.truncate() + Vec3::X).length() < 1e-6, "{t}");
            assert_eq!(t.w, -1.0);
            assert!((Vec3::Z.cross(t.truncate()) * t.w - Vec3::Y).length() < 1e-6);
        }
    }

    #[test]
    fn coincident_points_give_no_normal() {
        let a = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(face_normal(a, a, Vec3::X), None);
        assert_eq!(face_normal(Vec3::ZERO, Vec3::X, Vec3::X * 2.0), None);
        assert_eq!(face_normal(Vec3::ZERO, Vec3::X, Vec3::Y), Some(Vec3::Z));
    }

    #[test]
    fn newell_survives_repeated_points() {
        let pts = [Vec3::ZERO, Vec3::ZERO, Vec3::X, Vec3::X + Vec3::Y, Vec3::Y];
        assert_eq!(polygon_normal(&pts), Some(Vec3::Z));
    }

    #[test]
    fn cube_stays_faceted_sphere_is_smooth() {
        let cube = primitives::cube();
        let s = vertex_normals(&cube.positions, &cube.indices, 30.0);
        assert_eq!(s.normals.len(), 24, "each cube corner splits into three");
        for n in &s.normals {
            assert!(
                (n.abs().max_element() - 1.0).abs() < 1e-6,
                "axis-aligned normal {n}"
            );
        }
        let sphere = primitives::uv_sphere(1.0, 16, 8);
        let s = vertex_normals(&sphere.positions, &sphere.indices, 30.0);
        for (v, n) in s.source_vertex.iter().zip(&s.normals) {
            let p = sphere.positions[*v as usize];
            assert!(n.dot(p.normalize()) > 0.99, "sphere normal {n} at {p}");
        }
    }

    #[test]
    fn degenerate_triangle_gets_a_neighbour_normal() {
        let pos = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Y];
        let idx = vec![[0, 1, 2], [2, 3, 1]];
        let s = vertex_normals(&pos, &idx, 30.0);
        for n in &s.normals {
            assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-5);
        }
    }
}
