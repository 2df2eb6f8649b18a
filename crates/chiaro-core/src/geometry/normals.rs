//! Face and vertex normals and tangents.
//!
//! Vertex normals are the angle-weighted average of the normals of the faces
//! around a vertex (Thürmer and Wüthrich 1998), skipping faces whose normal
//! differs by more than a crease angle from the face being drawn, so a cube
//! stays faceted and a sphere is smooth (the textbook chapter's "keep real
//! edges sharp"). Zero-area faces contribute nothing: coincident points never
//! produce a zero normal and a dark corner (the magazine series' warning).

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

/// Vertex normals with a crease angle. Vertices within the weld tolerance of
/// each other ([`weld_tolerance`]) are treated as one for averaging (so uv
/// seams stay smooth), and a vertex is split wherever faces around it meet at
/// more than `crease_degrees`. Degenerate triangles keep their indices and
/// receive the normal of a neighbour (or +z when alone). Runs in O(n) expected
/// time (a hash of tolerance-sized cells and a bounded crease pass).
pub fn vertex_normals(
    positions: &[Vec3],
    indices: &[[u32; 3]],
    crease_degrees: f32,
) -> SmoothedMesh {
    vertex_normals_counted(positions, indices, crease_degrees, &mut Work::default())
}

/// Comparisons made by [`vertex_normals`], for tests that bound its work.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Work {
    /// Point-to-representative distance tests in the weld.
    pub(crate) weld_tests: usize,
    /// Normal-to-normal dot products in the crease pass.
    pub(crate) crease_tests: usize,
}

/// Welded vertices with at most this many corners average exactly the faces
/// within the crease angle of each corner's face (all pairs); more crowded
/// ones cluster their corners around at most this many seed normals.
const CREASE_PAIRS_MAX: usize = 32;

fn vertex_normals_counted(
    positions: &[Vec3],
    indices: &[[u32; 3]],
    crease_degrees: f32,
    work: &mut Work,
) -> SmoothedMesh {
    let cos_crease = crease_degrees.clamp(0.0, 180.0).to_radians().cos() - 1e-6;
    let weld = weld(positions, weld_tolerance(positions, indices), work);
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
    // Corners of non-degenerate faces grouped by welded vertex (counting sort,
    // so each group lists its corners in face order): `around[start[w]..start[w + 1]]`.
    let mut start = vec![0usize; positions.len() + 1];
    for (f, t) in indices.iter().enumerate() {
        if face_n[f].is_some() {
            for &v in t {
                start[weld[v as usize] as usize + 1] += 1;
            }
        }
    }
    for w in 0..positions.len() {
        start[w + 1] += start[w];
    }
    let mut fill = start.clone();
    // (corner = 3 * face + k, face normal, angle weight)
    let mut around: Vec<(usize, Vec3, f32)> = vec![(0, Vec3::ZERO, 0.0); start[positions.len()]];
    for (f, t) in indices.iter().enumerate() {
        if let Some(n) = face_n[f] {
            for k in 0..3 {
                let w = weld[t[k] as usize] as usize;
                around[fill[w]] = (3 * f + k, n, corner_angle(t, k));
                fill[w] += 1;
            }
        }
    }
    // Smoothed normal of every corner of a non-degenerate face.
    let mut corner_n = vec![Vec3::ZERO; 3 * indices.len()];
    let mut seeds: Vec<(Vec3, Vec3)> = Vec::with_capacity(CREASE_PAIRS_MAX);
    let mut member: Vec<usize> = Vec::new();
    for w in 0..positions.len() {
        let group = &around[start[w]..start[w + 1]];
        if group.len() <= CREASE_PAIRS_MAX {
            // Each corner averages the faces within the crease angle of its own.
            for &(c, nf, _) in group {
                let mut sum = Vec3::ZERO;
                for &(_, ng, wg) in group {
                    work.crease_tests += 1;
                    if ng.dot(nf) >= cos_crease {
                        sum += ng * wg;
                    }
                }
                corner_n[c] = sum.try_normalize().unwrap_or(nf);
            }
        } else {
            // Greedy clusters: a corner joins the first seed within the crease
            // angle (or the nearest once the seeds are all taken).
            seeds.clear();
            member.clear();
            for &(_, nf, wf) in group {
                let mut best = (f32::NEG_INFINITY, usize::MAX);
                for (s, (seed, _)) in seeds.iter().enumerate() {
                    work.crease_tests += 1;
                    let d = seed.dot(nf);
                    if d >= cos_crease {
                        best = (d, s);
                        break;
                    }
                    if d > best.0 {
                        best = (d, s);
                    }
                }
                if best.0 < cos_crease && seeds.len() < CREASE_PAIRS_MAX {
                    best.1 = seeds.len();
                    seeds.push((nf, Vec3::ZERO));
                }
                seeds[best.1].1 += nf * wf;
                member.push(best.1);
            }
            for (&(c, nf, _), &s) in group.iter().zip(&member) {
                corner_n[c] = seeds[s].1.try_normalize().unwrap_or(nf);
            }
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
        let mut tri = [0u32; 3];
        for k in 0..3 {
            let v = t[k];
            let n = match face_n[f] {
                Some(_) => corner_n[3 * f + k],
                None => {
                    let w = weld[v as usize] as usize;
                    around[start[w]..start[w + 1]]
                        .first()
                        .map_or(Vec3::Z, |&(_, ng, _)| ng)
                }
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

/// The distance below which [`vertex_normals`] treats two vertices as one:
/// 1e-5 of the median length of the mesh's non-zero edges (0 when there are
/// none: only equal points weld). A median, unlike the bounding box, is not
/// inflated by a few far-away vertices, so one stray triangle cannot weld a
/// whole mesh into a point.
pub fn weld_tolerance(positions: &[Vec3], indices: &[[u32; 3]]) -> f32 {
    let mut lengths: Vec<f32> = indices
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            [a.distance(b), b.distance(c), c.distance(a)]
        })
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if lengths.is_empty() {
        return 0.0;
    }
    let mid = lengths.len() / 2;
    *lengths.select_nth_unstable_by(mid, f32::total_cmp).1 * 1e-5
}

/// For each point, the lowest-indexed earlier representative within `tol`
/// (itself when none), found through a hash of `tol`-sized cells: a point
/// looks in its cell and the 26 around it, and a cell holds a bounded number
/// of representatives (they are more than `tol` apart), so this is O(n)
/// expected. Points too far out for a cell index, or any point when
/// `tol` is 0, weld only with equal points, which is all the tolerance would
/// allow there (their spacing in `f32` exceeds `tol`).
pub(crate) fn weld(positions: &[Vec3], tol: f32, work: &mut Work) -> Vec<u32> {
    #[derive(Hash, PartialEq, Eq, Clone, Copy)]
    enum Key {
        Cell([i64; 3]),
        Exact([u32; 3]),
    }
    let tol = f64::from(tol);
    let limit = (1u64 << 62) as f64;
    let key_of = |p: Vec3| -> Key {
        if tol > 0.0 {
            let c = p.to_array().map(|x| (f64::from(x) / tol).floor());
            if c.iter().all(|x| x.abs() < limit) {
                return Key::Cell(c.map(|x| x as i64));
            }
        }
        // `+ 0.0` makes -0 and +0 one key.
        Key::Exact((p + Vec3::ZERO).to_array().map(f32::to_bits))
    };
    let mut reps: HashMap<Key, Vec<u32>> = HashMap::with_capacity(positions.len());
    let tol2 = tol * tol;
    positions
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let key = key_of(p);
            let Key::Cell(c) = key else {
                return reps.entry(key).or_insert_with(|| vec![i as u32])[0];
            };
            let mut best = u32::MAX;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let near = Key::Cell([c[0] + dx, c[1] + dy, c[2] + dz]);
                        for &r in reps.get(&near).map_or(&[][..], Vec::as_slice) {
                            work.weld_tests += 1;
                            let q = positions[r as usize];
                            let d2: f64 = (0..3)
                                .map(|k| (f64::from(q[k]) - f64::from(p[k])).powi(2))
                                .sum();
                            if d2 <= tol2 {
                                best = best.min(r);
                            }
                        }
                    }
                }
            }
            if best == u32::MAX {
                reps.entry(key).or_default().push(i as u32);
                i as u32
            } else {
                best
            }
        })
        .collect()
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

    /// The all-pairs crease rule, the oracle for the bounded pass: each
    /// corner averages every face within the crease angle of its own face
    /// among the faces at its welded vertex.
    fn all_pairs_normals(
        positions: &[Vec3],
        indices: &[[u32; 3]],
        crease_degrees: f32,
    ) -> Vec<Vec3> {
        let cos_crease = crease_degrees.to_radians().cos() - 1e-6;
        let weld = weld(
            positions,
            weld_tolerance(positions, indices),
            &mut Work::default(),
        );
        let tri = |f: usize| indices[f].map(|i| positions[i as usize]);
        let angle = |f: usize, k: usize| {
            let p = tri(f);
            let a = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let b = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            a.dot(b).clamp(-1.0, 1.0).acos()
        };
        let mut out = Vec::new();
        for (f, t) in indices.iter().enumerate() {
            let [a, b, c] = tri(f);
            let nf = face_normal(a, b, c).expect("test mesh");
            for k in 0..3 {
                let mut sum = Vec3::ZERO;
                for (g, u) in indices.iter().enumerate() {
                    let [a, b, c] = tri(g);
                    let ng = face_normal(a, b, c).expect("test mesh");
                    for j in 0..3 {
                        if weld[u[j] as usize] == weld[t[k] as usize] && ng.dot(nf) >= cos_crease {
                            sum += ng * angle(g, j);
                        }
                    }
                }
                out.push(sum.normalize());
            }
        }
        out
    }

    fn corner_normals(s: &SmoothedMesh) -> Vec<Vec3> {
        s.indices
            .iter()
            .flat_map(|t| t.map(|v| s.normals[v as usize]))
            .collect()
    }

    #[test]
    fn bounded_pass_matches_all_pairs_bit_for_bit() {
        // 40 slices: each pole is one welded vertex with 40 corners, past
        // CREASE_PAIRS_MAX, whose faces all lie within 30 degrees of each other.
        for (mesh, crease) in [
            (primitives::uv_sphere(1.0, 40, 8), 30.0),
            (primitives::uv_sphere(1.0, 12, 6), 30.0),
            (primitives::cylinder(1.0, 2.0, 40), 30.0),
            (primitives::cube(), 30.0),
            (primitives::icosphere(1.0, 2), 0.0),
        ] {
            let s = vertex_normals(&mesh.positions, &mesh.indices, crease);
            let want = all_pairs_normals(&mesh.positions, &mesh.indices, crease);
            assert_eq!(corner_normals(&s), want);
        }
    }

    /// The work bounds: the weld tests at most 27 cells of at most 8
    /// representatives a point, the crease pass at most `CREASE_PAIRS_MAX`
    /// normals a corner. The all-pairs loop did `corners^2` at one vertex.
    fn assert_bounded(positions: &[Vec3], indices: &[[u32; 3]]) -> SmoothedMesh {
        let mut work = Work::default();
        let s = vertex_normals_counted(positions, indices, 30.0, &mut work);
        assert!(work.weld_tests <= 27 * 8 * positions.len(), "{work:?}");
        assert!(
            work.crease_tests <= CREASE_PAIRS_MAX * 3 * indices.len(),
            "{work:?}"
        );
        s
    }

    #[test]
    fn repeated_faces_take_linear_work() {
        let pos = [Vec3::ZERO, Vec3::X, Vec3::Y];
        for n in [30_000, 100_000] {
            let idx = vec![[0, 1, 2]; n];
            let s = assert_bounded(&pos, &idx);
            assert_eq!(s.normals, vec![Vec3::Z; 3]);
            assert_eq!(s.indices, vec![[0, 1, 2]; n]);
        }
    }

    #[test]
    fn one_far_triangle_does_not_weld_a_grid() {
        let mut grid = primitives::plane(1.0, 100);
        assert_eq!(grid.indices.len(), 20_000);
        let base = grid.positions.len() as u32;
        grid.positions.extend([
            Vec3::splat(1e12),
            Vec3::new(1e12 + 1e6, 1e12, 1e12),
            Vec3::new(1e12, 1e12 + 1e6, 1e12),
        ]);
        grid.indices.push([base, base + 1, base + 2]);
        let tol = weld_tolerance(&grid.positions, &grid.indices);
        assert!(tol > 0.0 && tol < 1e-6, "tolerance {tol}");
        let mut work = Work::default();
        let w = weld(&grid.positions, tol, &mut work);
        assert!(
            w.iter().enumerate().all(|(i, &r)| r as usize == i),
            "nothing welds"
        );
        assert_bounded(&grid.positions, &grid.indices);
    }

    #[test]
    fn points_across_a_cell_border_weld() {
        let tol = 0.1;
        let pos = [
            Vec3::new(0.099, 0.0, 0.0),
            Vec3::new(0.101, 0.0, 0.0),
            Vec3::new(0.3, 0.0, 0.0),
            Vec3::new(0.099, 0.0, 0.0),
        ];
        let w = weld(&pos, tol, &mut Work::default());
        assert_eq!(w, vec![0, 0, 2, 0]);
        // Zero tolerance and far-out or non-finite points weld only when equal.
        let far = [
            Vec3::splat(3e38),
            Vec3::splat(3e38),
            Vec3::splat(f32::NAN),
            Vec3::new(0.0, -0.0, 0.0),
            Vec3::ZERO,
        ];
        assert_eq!(weld(&far, tol, &mut Work::default()), vec![0, 0, 2, 3, 3]);
        assert_eq!(weld(&far, 0.0, &mut Work::default()), vec![0, 0, 2, 3, 3]);
    }

    #[test]
    fn crowded_fan_takes_bounded_work() {
        // A cone apex with 20,000 faces whose normals all differ.
        let n = 20_000u32;
        let mut pos = vec![Vec3::Z];
        pos.extend((0..n).map(|i| {
            let a = i as f32 / n as f32 * std::f32::consts::TAU;
            Vec3::new(a.cos(), a.sin(), 0.0)
        }));
        let idx: Vec<[u32; 3]> = (0..n).map(|i| [0, 1 + i, 1 + (i + 1) % n]).collect();
        let s = assert_bounded(&pos, &idx);
        for n in &s.normals {
            assert!((n.length() - 1.0).abs() < 1e-5, "normal {n}");
        }
    }

    proptest::proptest! {
        /// Jittered copies of lattice points (spacing 1, jitter within a
        /// quarter of the tolerance per axis) weld to the first copy of
        /// their lattice point, and welding is idempotent.
        #[test]
        fn weld_merges_exactly_the_copies_of_a_point(
            pts in proptest::collection::vec(
                (0u8..4, 0u8..4, 0u8..4, -0.024f32..0.024, -0.024f32..0.024, -0.024f32..0.024),
                1..80,
            )
        ) {
            let tol = 0.1;
            let pos: Vec<Vec3> = pts
                .iter()
                .map(|&(x, y, z, a, b, c)| Vec3::new(f32::from(x) + a, f32::from(y) + b, f32::from(z) + c))
                .collect();
            let w = weld(&pos, tol, &mut Work::default());
            for (i, p) in pts.iter().enumerate() {
                let first = pts.iter().position(|q| q.0 == p.0 && q.1 == p.1 && q.2 == p.2).expect("itself");
                proptest::prop_assert_eq!(w[i] as usize, first);
                proptest::prop_assert_eq!(w[w[i] as usize], w[i]);
            }
        }
    }
}
