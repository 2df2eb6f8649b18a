//! Built-in primitives as triangle meshes, in object space with uvs:
//! sphere, plane/quad, disk, box (cube), cylinder. The Utah teapot lives in
//! [`super::teapot`].

use crate::scene::Mesh;
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// The vertex and triangle counts of a primitive before it is tessellated,
/// so that its memory can be checked first (upper bounds where a primitive
/// drops degenerate triangles).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshSize {
    /// Vertices.
    pub vertices: u64,
    /// Triangles.
    pub triangles: u64,
}

impl MeshSize {
    /// [`uv_sphere`]'s counts.
    pub fn uv_sphere(slices: u32, stacks: u32) -> Self {
        let (sl, st) = (u64::from(slices.max(3)), u64::from(stacks.max(2)));
        Self {
            vertices: (sl + 1) * (st + 1),
            triangles: sl * (2 * st - 2),
        }
    }

    /// [`plane`]'s counts.
    pub fn plane(n: u32) -> Self {
        let n = u64::from(n.max(1));
        Self {
            vertices: (n + 1) * (n + 1),
            triangles: 2 * n * n,
        }
    }

    /// [`disk`]'s counts.
    pub fn disk(segments: u32) -> Self {
        let s = u64::from(segments.max(3));
        Self {
            vertices: s + 1,
            triangles: s,
        }
    }

    /// [`cylinder`]'s counts.
    pub fn cylinder(segments: u32) -> Self {
        let s = u64::from(segments.max(3));
        Self {
            vertices: 4 * s + 4,
            triangles: 4 * s,
        }
    }

    /// [`super::teapot::teapot`]'s counts (at most).
    pub fn teapot(subdivisions: u32) -> Self {
        let n = u64::from(subdivisions.max(1));
        Self {
            vertices: 32 * (n + 1) * (n + 1),
            triangles: 64 * n * n,
        }
    }

    /// Bytes of the authoring [`Mesh`]: positions, normals, uvs, tangents
    /// and colours a vertex, indices and a face material a triangle.
    pub fn mesh_bytes(&self) -> u64 {
        use crate::budget::{MESH_TRIANGLE_BYTES, MESH_VERTEX_BYTES};
        self.vertices
            .saturating_mul(MESH_VERTEX_BYTES)
            .saturating_add(self.triangles.saturating_mul(MESH_TRIANGLE_BYTES))
    }

    /// Bytes of a technique's prepared copy (see
    /// [`crate::budget::PREPARED_TRIANGLE_BYTES`]).
    pub fn prepared_bytes(&self) -> u64 {
        use crate::budget::{PREPARED_TRIANGLE_BYTES, PREPARED_VERTEX_BYTES};
        self.vertices
            .saturating_mul(PREPARED_VERTEX_BYTES)
            .saturating_add(self.triangles.saturating_mul(PREPARED_TRIANGLE_BYTES))
    }

    /// The counts of an existing mesh.
    pub fn of(mesh: &Mesh) -> Self {
        Self {
            vertices: mesh.positions.len() as u64,
            triangles: mesh.indices.len() as u64,
        }
    }

    /// `self` `times` over.
    pub fn times(&self, times: u64) -> Self {
        Self {
            vertices: self.vertices.saturating_mul(times),
            triangles: self.triangles.saturating_mul(times),
        }
    }
}

/// A UV sphere of `radius` centred at the origin, poles on +-y, with
/// `slices` segments around and `stacks` from pole to pole.
pub fn uv_sphere(radius: f32, slices: u32, stacks: u32) -> Mesh {
    let (slices, stacks) = (slices.max(3), stacks.max(2));
    let mut m = Mesh {
        name: "sphere".into(),
        ..Mesh::default()
    };
    for j in 0..=stacks {
        let v = j as f32 / stacks as f32;
        let theta = v * PI;
        for i in 0..=slices {
            let u = i as f32 / slices as f32;
            // The seam column repeats column 0 exactly.
            let phi = (i % slices) as f32 / slices as f32 * TAU;
            let n = Vec3::new(
                theta.sin() * phi.sin(),
                theta.cos(),
                theta.sin() * phi.cos(),
            );
            m.positions.push(n * radius);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    let row = slices + 1;
    for j in 0..stacks {
        for i in 0..slices {
            let a = j * row + i;
            let (b, c, d) = (a + 1, a + row, a + row + 1);
            if j != 0 {
                m.indices.push([a, c, b]);
            }
            if j != stacks - 1 {
                m.indices.push([b, c, d]);
            }
        }
    }
    m
}

/// A square in the xz plane from `-half` to `+half`, normal +y, subdivided
/// `n x n` times (so scan conversion and radiosity get vertices inside).
pub fn plane(half: f32, n: u32) -> Mesh {
    let n = n.max(1);
    let mut m = Mesh {
        name: "plane".into(),
        ..Mesh::default()
    };
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
            m.positions.push(Vec3::new(
                (2.0 * u - 1.0) * half,
                0.0,
                (2.0 * v - 1.0) * half,
            ));
            m.normals.push(Vec3::Y);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
            m.indices.push([a, c, b]);
            m.indices.push([b, c, d]);
        }
    }
    m
}

/// A parallelogram `corner + s * edge_u + t * edge_v`, two triangles, front
/// face along `edge_u x edge_v`.
pub fn quad(corner: Vec3, edge_u: Vec3, edge_v: Vec3) -> Mesh {
    let n = edge_u.cross(edge_v).normalize_or_zero();
    Mesh {
        name: "quad".into(),
        positions: vec![
            corner,
            corner + edge_u,
            corner + edge_u + edge_v,
            corner + edge_v,
        ],
        normals: vec![n; 4],
        uvs: vec![
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::ZERO,
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Mesh::default()
    }
}

/// A disk of `radius` in the xz plane, normal +y, with `segments` around.
pub fn disk(radius: f32, segments: u32) -> Mesh {
    let segments = segments.max(3);
    let mut m = Mesh {
        name: "disk".into(),
        ..Mesh::default()
    };
    m.positions.push(Vec3::ZERO);
    m.normals.push(Vec3::Y);
    m.uvs.push(Vec2::splat(0.5));
    for i in 0..segments {
        let phi = i as f32 / segments as f32 * TAU;
        let (s, c) = phi.sin_cos();
        m.positions.push(Vec3::new(s * radius, 0.0, c * radius));
        m.normals.push(Vec3::Y);
        m.uvs.push(Vec2::new(0.5 + 0.5 * s, 0.5 + 0.5 * c));
    }
    for i in 0..segments {
        m.indices.push([0, 1 + i, 1 + (i + 1) % segments]);
    }
    m
}

/// The unit cube `[-1, 1]^3`, 24 vertices so every face has its own normals and uvs.
pub fn cube() -> Mesh {
    let mut m = Mesh {
        name: "box".into(),
        ..Mesh::default()
    };
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (n, u, v) in faces {
        let base = m.positions.len() as u32;
        for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            m.positions.push(n + u * su + v * sv);
            m.normals.push(n);
            m.uvs.push(Vec2::new(0.5 + 0.5 * su, 0.5 - 0.5 * sv));
        }
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base, base + 2, base + 3]);
    }
    m
}

/// A box with the given half extents centred at the origin.
pub fn box_mesh(half: Vec3) -> Mesh {
    let mut m = cube();
    for p in &mut m.positions {
        *p *= half;
    }
    m
}

/// A closed cylinder of `radius` from `y = 0` to `y = height`, with caps.
pub fn cylinder(radius: f32, height: f32, segments: u32) -> Mesh {
    let segments = segments.max(3);
    let mut m = Mesh {
        name: "cylinder".into(),
        ..Mesh::default()
    };
    for i in 0..=segments {
        let u = i as f32 / segments as f32;
        let (s, c) = (u * TAU).sin_cos();
        let n = Vec3::new(s, 0.0, c);
        for (y, v) in [(0.0, 1.0), (height, 0.0)] {
            m.positions.push(Vec3::new(s * radius, y, c * radius));
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    for i in 0..segments {
        let a = 2 * i;
        m.indices.push([a, a + 2, a + 1]);
        m.indices.push([a + 1, a + 2, a + 3]);
    }
    for (y, n) in [(0.0, Vec3::NEG_Y), (height, Vec3::Y)] {
        let centre = m.positions.len() as u32;
        m.positions.push(Vec3::new(0.0, y, 0.0));
        m.normals.push(n);
        m.uvs.push(Vec2::splat(0.5));
        for i in 0..segments {
            let (s, c) = (i as f32 / segments as f32 * TAU).sin_cos();
            m.positions.push(Vec3::new(s * radius, y, c * radius));
            m.normals.push(n);
            m.uvs.push(Vec2::new(0.5 + 0.5 * s, 0.5 + 0.5 * c));
        }
        for i in 0..segments {
            let (a, b) = (centre + 1 + i, centre + 1 + (i + 1) % segments);
            if n.y > 0.0 {
                m.indices.push([centre, a, b])
            } else {
                m.indices.push([centre, b, a])
            }
        }
    }
    m
}

/// An icosphere: the icosahedron subdivided `levels` times, projected to the
/// sphere (20 * 4^levels triangles), with exact sphere normals and zero
/// uvs. The mesh of the benchmark scenes (a 14x14 grid of level-4
/// icospheres, 5120 triangles each, as the peers build it).
pub fn icosphere(radius: f32, levels: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut p: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
        let mut m = |a: u32, b: u32, p: &mut Vec<Vec3>| {
            let k = (a.min(b), a.max(b));
            *mid.entry(k).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                p.len() as u32 - 1
            })
        };
        let mut nf = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut p), m(b, c, &mut p), m(c, a, &mut p));
            nf.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    Mesh {
        name: "icosphere".into(),
        normals: p.clone(),
        uvs: vec![Vec2::ZERO; p.len()],
        positions: p.iter().map(|&v| v * radius).collect(),
        indices: f,
        ..Mesh::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::face_normal;

    fn outward(m: &Mesh) {
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let centroid = (a + b + c) / 3.0;
            let n = face_normal(a, b, c).expect("non-degenerate");
            let avg_n =
                (m.normals[t[0] as usize] + m.normals[t[1] as usize] + m.normals[t[2] as usize])
                    .normalize();
            assert!(
                n.dot(avg_n) > 0.5,
                "{} winding disagrees with normals at {centroid}",
                m.name
            );
        }
    }

    #[test]
    fn primitives_are_wound_outwards() {
        outward(&uv_sphere(1.0, 12, 6));
        outward(&plane(1.0, 3));
        outward(&disk(1.0, 8));
        outward(&cube());
        outward(&cylinder(1.0, 2.0, 10));
        outward(&quad(Vec3::ZERO, Vec3::X, Vec3::Y));
        outward(&icosphere(1.0, 2));
        assert_eq!(icosphere(1.0, 4).indices.len(), 5120);
    }

    #[test]
    fn sizes_match_the_tessellations() {
        let size = |m: &Mesh| (m.positions.len() as u64, m.indices.len() as u64);
        let exact = |s: MeshSize| (s.vertices, s.triangles);
        for (slices, stacks) in [(3, 2), (16, 8), (64, 32)] {
            assert_eq!(
                size(&uv_sphere(1.0, slices, stacks)),
                exact(MeshSize::uv_sphere(slices, stacks))
            );
        }
        for n in [1, 7] {
            assert_eq!(size(&plane(1.0, n)), exact(MeshSize::plane(n)));
        }
        assert_eq!(size(&disk(1.0, 12)), exact(MeshSize::disk(12)));
        assert_eq!(size(&cylinder(1.0, 1.0, 12)), exact(MeshSize::cylinder(12)));
        for n in [1, 8] {
            let (v, t) = size(&crate::geometry::teapot::teapot(n));
            let bound = MeshSize::teapot(n);
            assert!(v <= bound.vertices && t <= bound.triangles && 2 * t > bound.triangles);
        }
    }
}
