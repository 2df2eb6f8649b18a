//! Meshing: every surface of the scene (and every area light) cut into
//! triangular *elements* by uniform subdivision, with shared display
//! vertices and no T-vertices.
//!
//! Each source triangle (a triangle of the [`PreparedScene`], or a triangle
//! of a meshed area light) is split into `k x k` congruent triangles
//! (`k` per edge). Two triangles that share an edge get the same `k` (it is
//! propagated as the maximum over each edge-connected component), so the
//! vertices along a shared edge coincide and the display mesh has no
//! T-vertices. Vertices are keyed by the prepared-scene vertex indices
//! (corners), by the edge and step along it (edge vertices) or are fresh
//! (interior), so surfaces are welded exactly where the prepared scene
//! welds them, and split at creases where it splits them.

use chiaro_core::error::CoreError;
use chiaro_core::geometry::face_normal;
use chiaro_core::geometry::primitives;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{AreaShape, Light};
use glam::Vec3;
use std::collections::HashMap;

/// Largest number of elements a solution may have.
pub const MAX_ELEMENTS: usize = 4_000_000;

/// Where a source triangle comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum SourceKind {
    /// Triangle `t` of the prepared scene.
    Prepared(u32),
    /// A triangle of area light `light`, emitting `le` (radiance).
    AreaLight { light: u32, le: Vec3 },
}

/// A triangle that is subdivided into elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SourceTri {
    /// Global vertex ids (prepared-scene vertex indices, or fresh ids above
    /// them for area lights) used to weld subdivision vertices.
    pub v: [u32; 3],
    /// Corner positions, world space.
    pub p: [Vec3; 3],
    /// Unit face normal.
    pub n: Vec3,
    /// Object index (`u32::MAX` for area lights).
    pub object: u32,
    /// Origin.
    pub kind: SourceKind,
}

/// One element (patch): a triangle with constant albedo and emission.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Element {
    /// Corners, counter-clockwise seen from the front.
    pub p: [Vec3; 3],
    /// Centroid.
    pub c: Vec3,
    /// Unit front normal.
    pub n: Vec3,
    /// Area, square scene units.
    pub area: f32,
    /// Lambertian albedo rho (RGB, clamped to `[0, 1]`).
    pub rho: Vec3,
    /// Emitted radiance Le (front side).
    pub le: Vec3,
    /// Display vertex indices.
    pub verts: [u32; 3],
    /// Source triangle index.
    pub source: u32,
}

impl Element {
    /// Builds an element from its corners (normal from the source triangle).
    pub fn new(p: [Vec3; 3], n: Vec3, rho: Vec3, le: Vec3, verts: [u32; 3], source: u32) -> Self {
        Self {
            p,
            c: (p[0] + p[1] + p[2]) / 3.0,
            n,
            area: 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length(),
            rho,
            le,
            verts,
            source,
        }
    }
}

/// The elements of a scene and the display mesh over them.
#[derive(Debug, Clone)]
pub(crate) struct ElementMesh {
    /// Source triangles (prepared-scene triangles first, in order).
    pub sources: Vec<SourceTri>,
    /// Subdivision per source triangle.
    pub k: Vec<u32>,
    /// First element of each source triangle (elements of a source are contiguous).
    pub first: Vec<u32>,
    /// All elements.
    pub elements: Vec<Element>,
    /// Display vertex positions.
    pub vertices: Vec<Vec3>,
}

/// The point of barycentric grid `(i, j)` (weights `i/k` on `p1`, `j/k` on `p2`).
#[inline]
pub(crate) fn grid_point(p: &[Vec3; 3], k: u32, i: u32, j: u32) -> Vec3 {
    let (u, v) = (i as f32 / k as f32, j as f32 / k as f32);
    p[0] + u * (p[1] - p[0]) + v * (p[2] - p[0])
}

/// Index, within its source triangle, of the element containing barycentric
/// `(u, v)` (weights of `p1`, `p2`) for subdivision `k`. Elements are ordered
/// row by row (`j`), each row alternating "up" and "down" triangles; row `j`
/// starts at `j (2k - j)`.
pub(crate) fn element_at(k: u32, u: f32, v: f32) -> u32 {
    let kf = k as f32;
    let x = (u.clamp(0.0, 1.0) * kf).min(kf - 1e-4);
    let y = (v.clamp(0.0, 1.0) * kf).min(kf - 1e-4);
    let j = (y.floor() as u32).min(k - 1);
    let i = (x.floor() as u32).min(k - 1 - j);
    let (fx, fy) = (x - i as f32, y - j as f32);
    let down = fx + fy > 1.0 && i + j + 1 < k;
    j * (2 * k - j) + 2 * i + down as u32
}

/// Barycentrics `(u, v)` of `p` in triangle `t` (least squares in its plane).
pub(crate) fn barycentric(t: &[Vec3; 3], p: Vec3) -> (f32, f32) {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.abs() <= f32::MIN_POSITIVE {
        return (1.0 / 3.0, 1.0 / 3.0);
    }
    ((d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum VKey {
    Corner(u32),
    Edge(u32, u32, u32),
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[parent[x as usize] as usize];
        parent[x as usize] = p;
        x = p;
    }
    x
}

/// Triangles of area light `li` (quads and disks one-sided or two-sided,
/// spheres tessellated), as corner lists.
fn area_light_triangles(light: &Light) -> Vec<[Vec3; 3]> {
    let Light::Area {
        shape, two_sided, ..
    } = light
    else {
        return Vec::new();
    };
    let mut tris: Vec<[Vec3; 3]> = match *shape {
        AreaShape::Quad {
            corner,
            edge_u,
            edge_v,
        } => {
            let (a, b, c, d) = (
                corner,
                corner + edge_u,
                corner + edge_u + edge_v,
                corner + edge_v,
            );
            vec![[a, b, c], [a, c, d]]
        }
        AreaShape::Disk {
            center,
            normal,
            radius,
        } => {
            let f = chiaro_core::geometry::Frame::from_normal(normal.normalize_or_zero());
            let seg = 32;
            (0..seg)
                .map(|i| {
                    let a0 = i as f32 / seg as f32 * std::f32::consts::TAU;
                    let a1 = (i + 1) as f32 / seg as f32 * std::f32::consts::TAU;
                    let q = |a: f32| center + radius * (a.cos() * f.s + a.sin() * f.t);
                    [center, q(a0), q(a1)]
                })
                .collect()
        }
        AreaShape::Triangle { a, b, c } => vec![[a, b, c]],
        AreaShape::Sphere { center, radius } => {
            let m = primitives::uv_sphere(radius, 24, 12);
            m.indices
                .iter()
                .map(|t| t.map(|i| center + m.positions[i as usize]))
                .collect()
        }
    };
    if *two_sided && !matches!(shape, AreaShape::Sphere { .. }) {
        let back: Vec<[Vec3; 3]> = tris.iter().map(|t| [t[0], t[2], t[1]]).collect();
        tris.extend(back);
    }
    tris.retain(|t| face_normal(t[0], t[1], t[2]).is_some());
    tris
}

/// The source triangles of a prepared scene plus its area lights.
pub(crate) fn source_triangles(ps: &PreparedScene<'_>) -> Vec<SourceTri> {
    let mut out = Vec::with_capacity(ps.triangles.len());
    for (t, tri) in ps.triangles.iter().enumerate() {
        let p = tri.map(|i| ps.positions[i as usize]);
        out.push(SourceTri {
            v: *tri,
            p,
            n: face_normal(p[0], p[1], p[2]).unwrap_or(Vec3::Z),
            object: ps.tri_object[t],
            kind: SourceKind::Prepared(t as u32),
        });
    }
    let mut next_id = ps.positions.len() as u32;
    for (li, light) in ps.scene.lights.iter().enumerate() {
        let le = light.power_rgb();
        for p in area_light_triangles(light) {
            out.push(SourceTri {
                v: [next_id, next_id + 1, next_id + 2],
                p,
                n: face_normal(p[0], p[1], p[2]).unwrap_or(Vec3::Z),
                object: u32::MAX,
                kind: SourceKind::AreaLight {
                    light: li as u32,
                    le,
                },
            });
            next_id += 3;
        }
    }
    out
}

/// Albedo and emitted radiance of a source triangle at barycentrics `(u, v)`.
pub(crate) fn material_at(ps: &PreparedScene<'_>, s: &SourceTri, u: f32, v: f32) -> (Vec3, Vec3) {
    match s.kind {
        SourceKind::Prepared(t) => crate::surface(ps, t, u, v),
        SourceKind::AreaLight { le, .. } => (Vec3::ZERO, le.max(Vec3::ZERO)),
    }
}

/// Chooses the subdivision of every source triangle: `ceil(longest edge /
/// patch_size)` (rounded up to a power of two when `power_of_two`), then the
/// maximum over each group of triangles connected by shared edges.
pub(crate) fn subdivision(sources: &[SourceTri], patch_size: f32, power_of_two: bool) -> Vec<u32> {
    let mut k: Vec<u32> = sources
        .iter()
        .map(|s| {
            let longest = (0..3)
                .map(|e| (s.p[(e + 1) % 3] - s.p[e]).length())
                .fold(0.0f32, f32::max);
            let k = (longest / patch_size).ceil().clamp(1.0, 4096.0) as u32;
            if power_of_two {
                k.next_power_of_two()
            } else {
                k
            }
        })
        .collect();
    // Union the triangles that share an edge.
    let mut parent: Vec<u32> = (0..sources.len() as u32).collect();
    let mut edge_owner: HashMap<(u32, u32), u32> = HashMap::new();
    for (t, s) in sources.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (s.v[e], s.v[(e + 1) % 3]);
            let key = (a.min(b), a.max(b));
            if let Some(&o) = edge_owner.get(&key) {
                let (ra, rb) = (find(&mut parent, o), find(&mut parent, t as u32));
                if ra != rb {
                    parent[ra as usize] = rb;
                }
            } else {
                edge_owner.insert(key, t as u32);
            }
        }
    }
    let mut group_k: HashMap<u32, u32> = HashMap::new();
    for (t, &kt) in k.iter().enumerate() {
        let r = find(&mut parent, t as u32);
        let g = group_k.entry(r).or_insert(1);
        *g = (*g).max(kt);
    }
    for (t, kt) in k.iter_mut().enumerate() {
        let r = find(&mut parent, t as u32);
        *kt = group_k[&r];
    }
    k
}

/// `build_checked` with nothing to check (the tests' meshes).
#[cfg(test)]
pub(crate) fn build(
    ps: &PreparedScene<'_>,
    patch_size: f32,
    power_of_two: bool,
    progress: &dyn Progress,
) -> Result<ElementMesh, CoreError> {
    build_checked(ps, patch_size, power_of_two, progress, &|_, _| Ok(()))
}

/// Meshes the prepared scene and its area lights into elements of edge at
/// most `patch_size` (see the module docs), calling `check` with the number
/// of source triangles and of elements once they are known and before the
/// elements are made (the solver's memory check).
///
/// # Errors
/// [`CoreError::Unsupported`] when the mesh would exceed [`MAX_ELEMENTS`];
/// `check`'s error; [`CoreError::Cancelled`] when `progress` asks.
pub(crate) fn build_checked(
    ps: &PreparedScene<'_>,
    patch_size: f32,
    power_of_two: bool,
    progress: &dyn Progress,
    check: &dyn Fn(usize, u64) -> Result<(), CoreError>,
) -> Result<ElementMesh, CoreError> {
    let sources = source_triangles(ps);
    let k = subdivision(&sources, patch_size, power_of_two);
    let total: u64 = k.iter().map(|&k| k as u64 * k as u64).sum();
    if total > MAX_ELEMENTS as u64 {
        return Err(CoreError::Unsupported(format!(
            "radiosity: patch size {patch_size} gives {total} elements (at most {MAX_ELEMENTS}); \
             raise radiosity.patch_size"
        )));
    }
    check(sources.len(), total)?;
    let mut mesh = ElementMesh {
        sources,
        k,
        first: Vec::new(),
        elements: Vec::with_capacity(total as usize),
        vertices: Vec::new(),
    };
    let mut keyed: HashMap<VKey, u32> = HashMap::new();
    let mut grid: Vec<u32> = Vec::new();
    for si in 0..mesh.sources.len() {
        if si % 4096 == 0 && progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        let s = mesh.sources[si];
        let k = mesh.k[si];
        mesh.first.push(mesh.elements.len() as u32);
        // Display vertices of the (k+1)(k+2)/2 grid points.
        grid.clear();
        let mut row_start = Vec::with_capacity(k as usize + 1);
        for j in 0..=k {
            row_start.push(grid.len());
            for i in 0..=(k - j) {
                let key = if (i, j) == (0, 0) {
                    Some(VKey::Corner(s.v[0]))
                } else if (i, j) == (k, 0) {
                    Some(VKey::Corner(s.v[1]))
                } else if (i, j) == (0, k) {
                    Some(VKey::Corner(s.v[2]))
                } else if j == 0 {
                    Some(edge_key(s.v[0], s.v[1], i, k))
                } else if i == 0 {
                    Some(edge_key(s.v[0], s.v[2], j, k))
                } else if i + j == k {
                    Some(edge_key(s.v[1], s.v[2], j, k))
                } else {
                    None
                };
                let pos = grid_point(&s.p, k, i, j);
                let id = match key {
                    Some(key) => *keyed.entry(key).or_insert_with(|| {
                        mesh.vertices.push(pos);
                        mesh.vertices.len() as u32 - 1
                    }),
                    None => {
                        mesh.vertices.push(pos);
                        mesh.vertices.len() as u32 - 1
                    }
                };
                grid.push(id);
            }
        }
        let g = |i: u32, j: u32| grid[row_start[j as usize] + i as usize];
        let pt = |i: u32, j: u32| grid_point(&s.p, k, i, j);
        for j in 0..k {
            for i in 0..(k - j) {
                let mut push = |tri: [(u32, u32); 3]| {
                    let p = tri.map(|(a, b)| pt(a, b));
                    let c = (p[0] + p[1] + p[2]) / 3.0;
                    let (u, v) = barycentric(&s.p, c);
                    let (rho, le) = material_at(ps, &s, u, v);
                    mesh.elements.push(Element::new(
                        p,
                        s.n,
                        rho,
                        le,
                        tri.map(|(a, b)| g(a, b)),
                        si as u32,
                    ));
                };
                push([(i, j), (i + 1, j), (i, j + 1)]);
                if i + j + 1 < k {
                    push([(i + 1, j), (i + 1, j + 1), (i, j + 1)]);
                }
            }
        }
    }
    Ok(mesh)
}

/// The key of the vertex `step` of `k` along the edge from `a` to `b`,
/// the same from either side.
fn edge_key(a: u32, b: u32, step: u32, k: u32) -> VKey {
    if a < b {
        VKey::Edge(a, b, step)
    } else {
        VKey::Edge(b, a, k - step)
    }
}

/// Default patch size: a sixteenth of the scene's bounding-box diagonal.
pub(crate) fn default_patch_size(ps: &PreparedScene<'_>) -> f32 {
    let d = ps.bounds.diagonal();
    if d.is_finite() && d > 0.0 {
        d / 16.0
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::prepared::PrepareOptions;
    use chiaro_core::scene::{Geometry, Material, Object, Scene};

    #[test]
    fn element_lookup_matches_construction_order() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        for k in 1..6u32 {
            let mut n = 0u32;
            for j in 0..k {
                for i in 0..(k - j) {
                    let c = (grid_point(&p, k, i, j)
                        + grid_point(&p, k, i + 1, j)
                        + grid_point(&p, k, i, j + 1))
                        / 3.0;
                    assert_eq!(element_at(k, c.x, c.y), n, "up k={k} i={i} j={j}");
                    n += 1;
                    if i + j + 1 < k {
                        let c = (grid_point(&p, k, i + 1, j)
                            + grid_point(&p, k, i + 1, j + 1)
                            + grid_point(&p, k, i, j + 1))
                            / 3.0;
                        assert_eq!(element_at(k, c.x, c.y), n, "down k={k} i={i} j={j}");
                        n += 1;
                    }
                }
            }
            assert_eq!(n, k * k);
        }
    }

    #[test]
    fn shared_edges_get_shared_vertices_and_areas_add_up() {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let m = s.add_mesh(primitives::quad(
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            ..Default::default()
        });
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let mesh = build(&ps, 0.3, false, &chiaro_core::progress::NoProgress).expect("mesh");
        // Both triangles share the diagonal, so they get the same k.
        assert_eq!(mesh.k[0], mesh.k[1]);
        let k = mesh.k[0] as usize;
        assert_eq!(mesh.elements.len(), 2 * k * k);
        // A (k+1) x (k+1) grid of vertices: no duplicates along the diagonal.
        assert_eq!(mesh.vertices.len(), (k + 1) * (k + 1));
        let area: f32 = mesh.elements.iter().map(|e| e.area).sum();
        assert!((area - 2.0).abs() < 1e-4);
        for e in &mesh.elements {
            assert!(e.p.iter().all(|q| (q.z).abs() < 1e-6));
            assert!(e.n.dot(Vec3::Z) > 0.999);
        }
    }
}
