//! Which meshes the two-level BVH shares: objects whose flattened triangles are
//! their mesh's, transformed in mesh order, grouped by mesh.

use crate::prepared::PreparedScene;
use crate::scene::{Geometry, Mesh, MeshId};
use glam::{Affine3A, Mat4};

/// Where an object's triangles lie in the flattened scene, if they form one
/// contiguous run: `(first, count)`.
fn object_ranges(ps: &PreparedScene<'_>) -> Vec<Option<(u32, u32)>> {
    let n = ps.scene.objects.len();
    let mut ranges: Vec<Option<(u32, u32)>> = vec![None; n];
    let mut broken = vec![false; n];
    for (t, &o) in ps.tri_object.iter().enumerate() {
        let Some(r) = ranges.get_mut(o as usize) else {
            continue;
        };
        match r {
            None => *r = Some((t as u32, 1)),
            Some((first, count)) if *first + *count == t as u32 => *count += 1,
            Some(_) => broken[o as usize] = true,
        }
    }
    for (r, b) in ranges.iter_mut().zip(broken) {
        if b {
            *r = None;
        }
    }
    ranges
}

/// The triangles [`PreparedScene`] keeps of `mesh`: those whose three
/// indices are in range, in mesh order.
pub(super) fn valid_triangles(mesh: &Mesh) -> Vec<[u32; 3]> {
    let nv = mesh.positions.len();
    mesh.indices
        .iter()
        .filter(|t| t.iter().all(|&i| (i as usize) < nv))
        .copied()
        .collect()
}

/// An object that can be an instance of a shared mesh.
pub(super) struct Candidate {
    pub(super) object: usize,
    pub(super) first: u32,
    pub(super) object_from_world: Affine3A,
    pub(super) mirrored: bool,
}

/// Checks that object `oi` (mesh `mesh` under `world_from_object`) was
/// flattened as `count` triangles from `first` in mesh order, each the
/// transformed mesh triangle with vertices 1 and 2 swapped when mirrored:
/// exactly, on the first, last and a spread of triangles in between.
fn flattened_as_mesh_order(
    ps: &PreparedScene<'_>,
    valid: &[[u32; 3]],
    mesh: &Mesh,
    world_from_object: Mat4,
    first: u32,
    mirrored: bool,
) -> bool {
    let n = valid.len();
    let step = (n / 61).max(1);
    (0..n).step_by(step).chain([n - 1]).all(|k| {
        let t = valid[k];
        let t = if mirrored { [t[0], t[2], t[1]] } else { t };
        let Some(flat) = ps.triangles.get(first as usize + k) else {
            return false;
        };
        t.iter().zip(flat).all(|(&m, &f)| {
            ps.positions.get(f as usize).copied()
                == Some(world_from_object.transform_point3(mesh.positions[m as usize]))
        })
    })
}

/// The objects that instance a mesh shared by at least two of them, grouped
/// by mesh (in mesh id order).
pub(super) fn shared_instances(ps: &PreparedScene<'_>) -> Vec<(MeshId, Vec<Candidate>)> {
    let scene = ps.scene;
    let ranges = object_ranges(ps);
    // Objects per mesh first, so that meshes used once cost no checks.
    let mut users: Vec<Vec<usize>> = vec![Vec::new(); scene.meshes.len()];
    for (oi, obj) in scene.objects.iter().enumerate() {
        if let Geometry::Mesh(id) = obj.geometry
            && let Some(u) = users.get_mut(id.index())
        {
            u.push(oi);
        }
    }
    let mut out = Vec::new();
    for (mi, objs) in users.iter().enumerate() {
        if objs.len() < 2 {
            continue;
        }
        let mesh = &scene.meshes[mi];
        let valid = valid_triangles(mesh);
        if valid.is_empty() {
            continue;
        }
        let cands: Vec<Candidate> =
            objs.iter()
                .filter_map(|&oi| {
                    let (first, count) = ranges.get(oi).copied().flatten()?;
                    if count as usize != valid.len() {
                        return None;
                    }
                    let world_from_object = scene.objects[oi].transform.world_from_object();
                    let det = world_from_object.determinant();
                    let object_from_world = world_from_object.inverse();
                    if det == 0.0 || !det.is_finite() || !object_from_world.is_finite() {
                        return None;
                    }
                    // The same test PreparedScene uses to flip the winding.
                    let mirrored = det < 0.0;
                    flattened_as_mesh_order(ps, &valid, mesh, world_from_object, first, mirrored)
                        .then(|| Candidate {
                            object: oi,
                            first,
                            object_from_world: Affine3A::from_mat4(object_from_world),
                            mirrored,
                        })
                })
                .collect();
        if cands.len() >= 2 {
            out.push((MeshId(mi as u32), cands));
        }
    }
    out
}

/// Triangles a flat BVH holds beyond one copy of each mesh that
/// [`InstancedBvh`](super::InstancedBvh) would share: `sum over shared meshes of (instances - 1)
/// * triangles`. Zero when no mesh is instanced.
pub fn duplicated_triangles(ps: &PreparedScene<'_>) -> usize {
    duplicated(ps, &shared_instances(ps))
}

pub(super) fn duplicated(ps: &PreparedScene<'_>, shared: &[(MeshId, Vec<Candidate>)]) -> usize {
    shared
        .iter()
        .map(|(m, c)| (c.len() - 1) * valid_triangles(&ps.scene.meshes[m.index()]).len())
        .sum()
}
