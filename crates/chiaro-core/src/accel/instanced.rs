//! Instancing: a two-level BVH ([`InstancedBvh`]) that stores each mesh
//! shared by several objects once, in object space, and places it with a
//! transform, instead of the flattened world-space copies of
//! [`PreparedScene`].
//!
//! Structure (after pbrt-v4's `TransformedPrimitive` inside a
//! `BVHAggregate`, and Embree's instanced scenes):
//!
//! - **Bottom level.** One [`SceneBvh`] per *shared* mesh (referenced by at
//!   least two objects), built once over the mesh's object-space triangles,
//!   plus one flat [`SceneBvh`] in world space over everything else: meshes
//!   used by a single object (a world-space copy costs nothing extra and
//!   needs no ray transform), tessellated spheres, analytic spheres, and any
//!   object whose flattened triangles could not be matched to its mesh.
//! - **Top level.** A [`Bvh`] over the instances' world boxes (the eight
//!   transformed corners of the bottom level's object-space box, padded by
//!   a few ulps for the rounding of the transform).
//! - **Queries.** A ray reaching an instance is carried to object space with
//!   the inverse affine transform, direction *not* renormalised, so a point
//!   at parameter `t` in object space is the point at `t` in world space
//!   (affine maps preserve ratios along a line) and `t_min`, `t_max` and the
//!   hit distance need no conversion (pbrt-v4, section 6.1.4 and
//!   `Transform::ApplyInverse(Ray)`).
//!
//! Answers are those of [`SceneBvh`] over the flattened scene up to
//! rounding: [`Hit::prim`] is the triangle's index in the flattened
//! [`PreparedScene`] (the object's first triangle plus the mesh-local
//! index), and `u`, `v` are the barycentrics of that flattened triangle. A
//! mirroring transform (negative determinant) makes [`PreparedScene`] swap
//! vertices 1 and 2 to keep the winding, so `u` and `v` are swapped back
//! for such instances. Intersecting in object space rounds differently from
//! intersecting the transformed triangles, so `t`, `u`, `v` agree to a few
//! ulps of the object's extent and a ray exactly on a shared edge may pick
//! the other neighbour.
//!
//! **When to use it** ([`build_accelerator`]): the two-level BVH saves
//! memory and build time in proportion to the triangles it does not
//! duplicate, and costs a transform and a second traversal start per
//! instance a ray meets. It is chosen when the shared meshes would add at
//! least [`MIN_DUPLICATED_TRIANGLES`] duplicated triangles to a flat BVH;
//! otherwise the flat [`SceneBvh`] is used (same answers, and for small or
//! uninstanced scenes the faster of the two).

use super::bvh::{Bvh, BvhNode, BvhOptions, PAD_SLOT, SceneBvh};
use super::{Accelerator, Hit};
use crate::geometry::{Aabb, Ray};
use crate::prepared::{PrepareOptions, PreparedScene};
use crate::scene::{Geometry, Mesh, MeshId, Object, Scene, Transform};
use glam::{Affine3A, Mat4, Vec3, Vec4};

/// [`build_accelerator`] picks the two-level BVH when instancing saves at
/// least this many triangles (the triangles a flat BVH would hold beyond
/// one copy of each shared mesh, about 60 bytes each in a [`SceneBvh`], so
/// about 2 MiB: a core's share of L2 on the 2-core test box). Below it the
/// flat BVH is as fast or faster and small anyway; above it incoherent rays
/// (the path tracer's), build time and memory favour the two-level BVH,
/// while coherent camera rays lose a little until the flat BVH outgrows
/// the caches (`instanced_bench`; BENCHMARKS.md, "Ray tracing").
pub const MIN_DUPLICATED_TRIANGLES: usize = 32_768;

/// Slots per SoA leaf block of a [`SceneBvh`].
const SCENE_BVH_BLOCK: usize = 4;
/// Bytes of one leaf block of a [`SceneBvh`] (nine rows of
/// [`SCENE_BVH_BLOCK`] `f32` coordinates and as many `u32` prim ids), plus
/// its one-byte sphere-lane mask.
const SCENE_BVH_BLOCK_BYTES: usize = (9 * 4 + 4) * SCENE_BVH_BLOCK + 1;

/// One placed bottom level.
#[derive(Debug, Clone, Copy)]
struct Instance {
    /// `object_from_world`, or `None` for the flat level (identity).
    object_from_world: Option<Affine3A>,
    /// Index into [`InstancedBvh::levels`].
    level: u32,
    /// Flattened prim of the level's local triangle 0 (shared meshes only).
    prim_offset: u32,
    /// The transform mirrors (negative determinant): swap `u` and `v`.
    mirrored: bool,
}

/// A bottom-level BVH and how its local prims map to flattened ones.
#[derive(Debug, Clone)]
struct Level {
    bvh: SceneBvh,
    /// Flat level: the flattened prim of every local prim (triangles, then
    /// spheres). Empty for a shared mesh (flattened = offset + local).
    prims: Vec<u32>,
}

/// The two-level BVH over a [`PreparedScene`]: shared meshes stored once
/// in object space and placed by transforms, everything else in one flat
/// world-space level. An [`Accelerator`] with the same answers as
/// [`SceneBvh`] over the same scene, up to rounding (see the module docs).
#[derive(Debug, Clone)]
pub struct InstancedBvh {
    top: Bvh,
    instances: Vec<Instance>,
    levels: Vec<Level>,
}

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
fn valid_triangles(mesh: &Mesh) -> Vec<[u32; 3]> {
    let nv = mesh.positions.len();
    mesh.indices
        .iter()
        .filter(|t| t.iter().all(|&i| (i as usize) < nv))
        .copied()
        .collect()
}

/// An object that can be an instance of a shared mesh.
struct Candidate {
    object: usize,
    first: u32,
    object_from_world: Affine3A,
    mirrored: bool,
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
fn shared_instances(ps: &PreparedScene<'_>) -> Vec<(MeshId, Vec<Candidate>)> {
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
/// [`InstancedBvh`] would share: `sum over shared meshes of (instances - 1)
/// * triangles`. Zero when no mesh is instanced.
pub fn duplicated_triangles(ps: &PreparedScene<'_>) -> usize {
    duplicated(ps, &shared_instances(ps))
}

fn duplicated(ps: &PreparedScene<'_>, shared: &[(MeshId, Vec<Candidate>)]) -> usize {
    shared
        .iter()
        .map(|(m, c)| (c.len() - 1) * valid_triangles(&ps.scene.meshes[m.index()]).len())
        .sum()
}

/// The accelerator for `ps`: an [`InstancedBvh`] when instancing saves at
/// least [`MIN_DUPLICATED_TRIANGLES`] triangles ([`duplicated_triangles`]),
/// the flat [`SceneBvh`] otherwise. Both give the same answers up to
/// rounding; the choice only trades memory and build time against the
/// per-instance cost of a ray transform. Wrapped in
/// [`super::alpha::AlphaTested`] when the scene has masked materials, and in
/// [`super::cull::Culled`] when it has single-sided (`cull_backface`) ones.
pub fn build_accelerator(ps: &PreparedScene<'_>) -> Box<dyn Accelerator> {
    let shared = shared_instances(ps);
    let inner: Box<dyn Accelerator> = if duplicated(ps, &shared) >= MIN_DUPLICATED_TRIANGLES {
        Box::new(InstancedBvh::with_shared(ps, &shared))
    } else {
        Box::new(SceneBvh::new(ps))
    };
    // Masked (alpha-tested) materials: every ray skips cut-out texels.
    let alpha = super::alpha::AlphaTested::wrap(ps, inner);
    // Single-sided materials: camera rays skip their backs.
    super::cull::Culled::wrap(ps, alpha)
}

/// A [`SceneBvh`] over triangles `tris` of `positions` (indices in range)
/// and analytic spheres `(center, radius)`, with local prims numbered as
/// [`SceneBvh`] numbers them (triangles in order, then spheres). Built
/// through a one-object scene with an identity transform, so the positions
/// are used exactly as given.
fn level_bvh(positions: Vec<Vec3>, tris: Vec<[u32; 3]>, spheres: &[(Vec3, f32)]) -> SceneBvh {
    let nv = positions.len();
    let mut scene = Scene::default();
    if !tris.is_empty() {
        // Given normals and tangents keep PreparedScene from deriving them
        // (the BVH reads only positions and triangles).
        let mesh = scene.add_mesh(Mesh {
            positions,
            normals: vec![Vec3::Z; nv],
            tangents: vec![Vec4::new(1.0, 0.0, 0.0, 1.0); nv],
            indices: tris,
            ..Mesh::default()
        });
        scene.objects.push(Object {
            geometry: Geometry::Mesh(mesh),
            smooth: true,
            ..Object::default()
        });
    }
    for &(center, radius) in spheres {
        scene.objects.push(Object {
            geometry: Geometry::Sphere { radius },
            transform: Transform {
                translate: center,
                ..Transform::default()
            },
            ..Object::default()
        });
    }
    let ps = PreparedScene::new(
        &scene,
        PrepareOptions {
            analytic_spheres: true,
            ..PrepareOptions::default()
        },
    );
    SceneBvh::new(&ps)
}

/// The world box of an object-space box under `world_from_object`: its
/// eight transformed corners, padded by 4 ulps of the largest coordinate
/// so the rounding of the transform never cuts a triangle off.
fn world_box(b: Aabb, world_from_object: Mat4) -> Aabb {
    if b.is_empty() {
        return b;
    }
    let mut w = Aabb::EMPTY;
    for k in 0..8 {
        let c = Vec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        );
        w = w.grow(world_from_object.transform_point3(c));
    }
    let pad = Vec3::splat(4.0 * f32::EPSILON * w.min.abs().max(w.max.abs()).max_element());
    Aabb {
        min: w.min - pad,
        max: w.max + pad,
    }
}

impl InstancedBvh {
    /// Builds the two-level BVH over `ps`: one object-space bottom level per
    /// mesh that at least two objects instance, one world-space level for
    /// the rest, and the top level over their world boxes. A scene without
    /// instancing gets just the flat level (one instance, no transform).
    pub fn new(ps: &PreparedScene<'_>) -> Self {
        Self::with_shared(ps, &shared_instances(ps))
    }

    /// [`InstancedBvh::new`] with the shared meshes and their instances
    /// already found.
    fn with_shared(ps: &PreparedScene<'_>, shared: &[(MeshId, Vec<Candidate>)]) -> Self {
        let nt = ps.triangles.len();
        let mut instanced = vec![false; nt];
        let mut levels = Vec::new();
        let mut instances = Vec::new();
        let mut boxes = Vec::new();
        // Shared meshes, object space.
        for (mesh_id, cands) in shared {
            let mesh = &ps.scene.meshes[mesh_id.index()];
            let valid = valid_triangles(mesh);
            let count = valid.len();
            let bvh = level_bvh(mesh.positions.clone(), valid, &[]);
            let object_box = bvh.bvh().bounds();
            let level = levels.len() as u32;
            levels.push(Level {
                bvh,
                prims: Vec::new(),
            });
            for c in cands {
                instanced[c.first as usize..c.first as usize + count].fill(true);
                let world_from_object = ps.scene.objects[c.object].transform.world_from_object();
                boxes.push(world_box(object_box, world_from_object));
                instances.push(Instance {
                    object_from_world: Some(c.object_from_world),
                    level,
                    prim_offset: c.first,
                    mirrored: c.mirrored,
                });
            }
        }
        // Everything else, world space, with its vertices compacted.
        let mut remap = vec![u32::MAX; ps.positions.len()];
        let mut positions = Vec::new();
        let mut tris = Vec::new();
        let mut prims = Vec::new();
        for (t, tri) in ps.triangles.iter().enumerate() {
            if instanced[t] {
                continue;
            }
            let local = tri.map(|v| {
                let r = &mut remap[v as usize];
                if *r == u32::MAX {
                    *r = positions.len() as u32;
                    positions.push(ps.positions[v as usize]);
                }
                *r
            });
            tris.push(local);
            prims.push(t as u32);
        }
        prims.extend((0..ps.spheres.len()).map(|s| (nt + s) as u32));
        if !prims.is_empty() {
            let spheres: Vec<(Vec3, f32)> =
                ps.spheres.iter().map(|s| (s.center, s.radius)).collect();
            let bvh = level_bvh(positions, tris, &spheres);
            boxes.push(bvh.bvh().bounds());
            instances.push(Instance {
                object_from_world: None,
                level: levels.len() as u32,
                prim_offset: 0,
                mirrored: false,
            });
            levels.push(Level { bvh, prims });
        }
        // One instance per leaf: the top level's 4-wide box test then culls
        // every instance the ray misses before its transform and its
        // bottom level's setup are paid for.
        let top_opts = BvhOptions {
            max_leaf: 1,
            ..BvhOptions::default()
        };
        Self {
            top: Bvh::build_with(&boxes, &top_opts),
            instances,
            levels,
        }
    }

    /// Number of placed bottom levels (each shared mesh's objects, plus one
    /// for the flat level when it is not empty).
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// Number of distinct bottom-level BVHs (shared meshes, plus the flat
    /// level when it is not empty).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Bytes held by the structure: top-level nodes, slot order and
    /// instances, and for each bottom level what [`scene_bvh_memory_bytes`]
    /// counts plus its prim map. Excludes the `Vec` headers.
    pub fn memory_bytes(&self) -> usize {
        bvh_bytes(&self.top)
            + self.instances.len() * size_of::<Instance>()
            + self
                .levels
                .iter()
                .map(|l| scene_bvh_memory_bytes(&l.bvh) + l.prims.len() * size_of::<u32>())
                .sum::<usize>()
    }

    /// The ray in the instance's space, with `t_max` shrunk to `t_max`.
    #[inline(always)]
    fn local_ray(inst: &Instance, ray: &Ray, t_max: f32) -> Ray {
        match &inst.object_from_world {
            None => Ray { t_max, ..*ray },
            Some(m) => Ray {
                origin: m.transform_point3(ray.origin),
                dir: m.transform_vector3(ray.dir),
                t_min: ray.t_min,
                t_max,
            },
        }
    }

    /// A bottom-level hit as a hit on the flattened scene.
    #[inline(always)]
    fn flattened(&self, inst: &Instance, h: Hit) -> Hit {
        let level = &self.levels[inst.level as usize];
        let prim = if level.prims.is_empty() {
            inst.prim_offset + h.prim
        } else {
            level.prims.get(h.prim as usize).copied().unwrap_or(h.prim)
        };
        let (u, v) = if inst.mirrored {
            (h.v, h.u)
        } else {
            (h.u, h.v)
        };
        Hit { prim, u, v, ..h }
    }
}

/// Bytes of a bare [`Bvh`]: its nodes and slot order.
fn bvh_bytes(b: &Bvh) -> usize {
    b.node_count() * size_of::<BvhNode>() + size_of_val(b.prim_order())
}

/// An estimate of the bytes a [`SceneBvh`] holds: its nodes, slot order
/// (4 bytes a slot), one 161-byte SoA triangle block per four slots, and 16 bytes per analytic sphere. Excludes the `Vec`
/// headers.
pub fn scene_bvh_memory_bytes(b: &SceneBvh) -> usize {
    let order = b.bvh().prim_order();
    let spheres = order
        .iter()
        .filter(|&&p| p != PAD_SLOT && p >= b.triangle_count())
        .count();
    bvh_bytes(b.bvh())
        + order.len().div_ceil(SCENE_BVH_BLOCK) * SCENE_BVH_BLOCK_BYTES
        + spheres * 16
}

impl Accelerator for InstancedBvh {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let order = self.top.prim_order();
        let mut best = None;
        self.top
            .traverse_closest_leaves(ray, |first, count, mut t_max| {
                let mut found = None;
                for &i in &order[first..first + count] {
                    let Some(inst) = self.instances.get(i as usize) else {
                        continue;
                    };
                    let local = Self::local_ray(inst, ray, t_max);
                    if let Some(h) = self.levels[inst.level as usize].bvh.intersect(&local) {
                        t_max = h.t;
                        found = Some(h.t);
                        best = Some(self.flattened(inst, h));
                    }
                }
                found
            });
        best
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        let order = self.top.prim_order();
        self.top.traverse_any_leaves(ray, |first, count| {
            order[first..first + count].iter().any(|&i| {
                self.instances.get(i as usize).is_some_and(|inst| {
                    let local = Self::local_ray(inst, ray, ray.t_max);
                    self.levels[inst.level as usize]
                        .bvh
                        .visit_hits(&local, |h| visit(&self.flattened(inst, *h)))
                })
            })
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let order = self.top.prim_order();
        self.top.traverse_any_leaves(ray, |first, count| {
            order[first..first + count].iter().any(|&i| {
                self.instances.get(i as usize).is_some_and(|inst| {
                    let local = Self::local_ray(inst, ray, ray.t_max);
                    self.levels[inst.level as usize].bvh.occluded(&local)
                })
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::list::ListAccel;
    use crate::geometry::primitives::{cube, cylinder, icosphere};
    use crate::geometry::{Frame, offset_ray_origin};
    use crate::sampling::{
        pixel_rng, sample_uniform_sphere, sample_uniform_triangle, uniform, uniform2,
    };
    use crate::scene::{Camera, Material};
    use rayon::prelude::*;

    /// Objects of [`instanced_scene`] that instance the icosphere.
    const ICOSPHERES: usize = 24;

    /// One icosphere instanced [`ICOSPHERES`] times under random rotations,
    /// non-uniform scales and translations (one instance mirrored, one
    /// sheared by a full matrix), a cube with one out-of-range triangle
    /// (dropped by `PreparedScene`) instanced twice, a cylinder used once,
    /// an analytic sphere and a floor.
    fn instanced_scene() -> Scene {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let ico = s.add_mesh(icosphere(1.0, 2));
        let mut broken_cube = cube();
        broken_cube.indices.insert(3, [0, 1, 999]);
        let cube_id = s.add_mesh(broken_cube);
        let cyl = s.add_mesh(cylinder(0.5, 2.0, 24));
        let floor = s.add_mesh(crate::geometry::primitives::plane(12.0, 4));
        let mut rng = pixel_rng(11, 0, 0, 0);
        for k in 0..ICOSPHERES {
            let mut scale = Vec3::new(
                0.3 + 1.2 * uniform(&mut rng),
                0.3 + 1.2 * uniform(&mut rng),
                0.3 + 1.2 * uniform(&mut rng),
            );
            let mut matrix = Mat4::IDENTITY;
            if k == 3 {
                scale.y = -scale.y;
            }
            if k == 5 {
                matrix = Mat4::from_cols(
                    Vec4::new(1.0, 0.0, 0.0, 0.0),
                    Vec4::new(0.4, 1.0, 0.0, 0.0),
                    Vec4::new(0.0, -0.3, 1.0, 0.0),
                    Vec4::new(0.0, 0.0, 0.0, 1.0),
                );
            }
            s.objects.push(Object {
                geometry: Geometry::Mesh(ico),
                transform: Transform {
                    translate: Vec3::new(
                        (k % 6) as f32 * 3.0 - 7.5,
                        (k / 6) as f32 * 2.5 - 2.0 + uniform(&mut rng),
                        4.0 * uniform(&mut rng) - 2.0,
                    ),
                    rotate_degrees: Vec3::new(
                        360.0 * uniform(&mut rng),
                        360.0 * uniform(&mut rng),
                        360.0 * uniform(&mut rng),
                    ),
                    scale,
                    matrix,
                },
                ..Object::default()
            });
        }
        for (t, r) in [
            (Vec3::new(-3.0, -3.0, 3.0), 20.0),
            (Vec3::new(3.0, -3.0, 3.0), -35.0),
        ] {
            s.objects.push(Object {
                geometry: Geometry::Mesh(cube_id),
                transform: Transform {
                    translate: t,
                    rotate_degrees: Vec3::new(0.0, r, 0.0),
                    scale: Vec3::new(1.0, 0.5, 0.8),
                    ..Transform::default()
                },
                smooth: false,
                ..Object::default()
            });
        }
        s.objects.push(Object {
            geometry: Geometry::Mesh(cyl),
            transform: Transform {
                translate: Vec3::new(0.0, -2.0, 3.5),
                rotate_degrees: Vec3::new(10.0, 0.0, 30.0),
                ..Transform::default()
            },
            ..Object::default()
        });
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 1.2 },
            transform: Transform {
                translate: Vec3::new(0.5, 0.0, 4.0),
                ..Transform::default()
            },
            ..Object::default()
        });
        s.objects.push(Object {
            geometry: Geometry::Mesh(floor),
            transform: Transform {
                translate: Vec3::new(0.0, -4.0, 0.0),
                ..Transform::default()
            },
            ..Object::default()
        });
        s.camera = Camera {
            eye: Vec3::new(0.0, 3.0, 18.0),
            look_at: Vec3::new(0.0, 0.0, 0.0),
            fov_y_degrees: 50.0,
            ..Camera::default()
        };
        s
    }

    fn prepare(s: &Scene, analytic_spheres: bool) -> PreparedScene<'_> {
        PreparedScene::new(
            s,
            PrepareOptions {
                analytic_spheres,
                sphere_slices: 16,
            },
        )
    }

    /// Random rays: half from anywhere around the scene in uniform
    /// directions, half aimed at random triangles with unnormalised
    /// directions.
    fn random_rays(ps: &PreparedScene<'_>, count: u32, seed: u64) -> Vec<Ray> {
        let b = ps.bounds;
        let grow = b.extent() * 0.2;
        (0..count)
            .map(|i| {
                let mut rng = pixel_rng(seed, i, 0, 0);
                let o = b.min - grow
                    + (b.extent() + 2.0 * grow)
                        * Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
                if i % 2 == 0 {
                    Ray::new(o, sample_uniform_sphere(uniform2(&mut rng)))
                } else {
                    let t = (uniform(&mut rng) * ps.triangles.len() as f32) as u32
                        % ps.triangles.len() as u32;
                    let uv = sample_uniform_triangle(uniform2(&mut rng));
                    let target = ps.triangle_surface(t, uv.x, uv.y).p;
                    Ray::new(o, (target - o) * 0.7)
                }
            })
            .collect()
    }

    /// The smallest barycentric of a triangle hit (distance to an edge in
    /// barycentric units).
    fn edge_distance(h: &Hit) -> f32 {
        h.u.min(h.v).min(1.0 - h.u - h.v)
    }

    /// True when `a` (ours) and `b` (the oracle) are the same hit on prim
    /// `prim` of `ray` up to rounding. Away from grazing angles (|cos| of
    /// the ray and face normal >= 0.05) `t` must agree within 1e-5
    /// relative and the points named by the two `(u, v)` within 1e-5 of
    /// the scene's scale (the watertight test's edge functions lose
    /// precision with the distance to the ray origin, so barycentrics of a
    /// small far triangle carry absolute, not relative, rounding). At
    /// grazing angles rounding of
    /// the plane moves the hit along the ray by about (error / cos), so
    /// the hits must agree across the plane (|dt| |d| |cos| <= 1e-5 of
    /// the scene's scale) and our `(u, v)` must name the point at our `t`.
    fn same_hit(ps: &PreparedScene<'_>, ray: &Ray, a: &Hit, b: &Hit) -> bool {
        let scale = ray
            .at(b.t)
            .abs()
            .max_element()
            .max(ray.origin.abs().max_element())
            .max(1.0);
        if a.prim >= ps.triangles.len() as u32 {
            return (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0);
        }
        let cos = ps.face_normal(a.prim).dot(ray.dir.normalize()).abs();
        let p = ps.triangle_surface(a.prim, a.u, a.v).p;
        if cos >= 0.05 {
            let q = ps.triangle_surface(b.prim, b.u, b.v).p;
            (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0) && (p - q).length() <= 1e-5 * scale
        } else {
            (a.t - b.t).abs() * ray.dir.length() * cos <= 1e-5 * scale
                && (p - ray.at(a.t)).length() <= 1e-4 * scale
        }
    }

    /// Compares closest and any hits with the brute-force oracle: the same
    /// hit ([`same_hit`]), or a tie on a shared edge (a different prim at
    /// the same `t`, both hits within 1e-4 of an edge), at most 1 in 2000
    /// rays. Returns the number of such ties.
    fn check_against_oracle(ps: &PreparedScene<'_>, accel: &InstancedBvh, rays: &[Ray]) -> usize {
        let list = ListAccel::new(ps);
        let nt = ps.triangles.len() as u32;
        let results: Vec<Result<bool, String>> = rays
            .par_iter()
            .map(|r| {
                let a = accel.intersect(r);
                let b = list.intersect(r);
                let mut tie = false;
                let same = match (a, b) {
                    (None, None) => true,
                    (Some(a), Some(b)) if a.prim == b.prim => same_hit(ps, r, &a, &b),
                    (Some(a), Some(b)) => {
                        tie = true;
                        (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0)
                            && a.prim < nt
                            && b.prim < nt
                            && edge_distance(&a) < 1e-4
                            && edge_distance(&b) < 1e-4
                    }
                    _ => false,
                };
                let occ_same = accel.occluded(r) == b.is_some();
                if same && occ_same {
                    Ok(tie)
                } else {
                    Err(format!("{r:?}: instanced {a:?} list {b:?}"))
                }
            })
            .collect();
        let errors: Vec<&String> = results.iter().filter_map(|r| r.as_ref().err()).collect();
        assert!(
            errors.is_empty(),
            "{} mismatches of {}, first: {}",
            errors.len(),
            rays.len(),
            errors[0]
        );
        let ties = results.iter().filter(|r| matches!(r, Ok(true))).count();
        assert!(ties * 2000 <= rays.len(), "{ties} edge ties");
        ties
    }

    #[test]
    fn instances_share_one_bottom_level_per_mesh() {
        let s = instanced_scene();
        let ps = prepare(&s, true);
        let bvh = InstancedBvh::new(&ps);
        // Icosphere and cube shared; cylinder, floor and sphere flat.
        assert_eq!(bvh.level_count(), 3);
        assert_eq!(bvh.instance_count(), ICOSPHERES + 2 + 1);
        // The cube keeps 12 of its 13 triangles.
        assert_eq!(duplicated_triangles(&ps), (ICOSPHERES - 1) * 320 + 12);
        // The shared meshes are stored once: less memory than the flat BVH.
        let flat = scene_bvh_memory_bytes(&SceneBvh::new(&ps));
        assert!(
            bvh.memory_bytes() * 5 < flat,
            "{} vs {flat}",
            bvh.memory_bytes()
        );
    }

    /// Every hit along `ray`, sorted by prim and `t`.
    fn all_hits(accel: &dyn Accelerator, ray: &Ray) -> Vec<Hit> {
        let mut hits = Vec::new();
        let stopped = accel.for_each_hit(ray, &mut |h| {
            hits.push(*h);
            false
        });
        assert!(!stopped, "no visit asked to stop");
        hits.sort_by(|a, b| a.prim.cmp(&b.prim).then(a.t.total_cmp(&b.t)));
        hits
    }

    #[test]
    fn every_hit_matches_brute_force() {
        let s = instanced_scene();
        for analytic in [true, false] {
            let ps = prepare(&s, analytic);
            let nt = ps.triangles.len() as u32;
            let list = ListAccel::new(&ps);
            let accels: [Box<dyn Accelerator>; 2] = [
                Box::new(InstancedBvh::new(&ps)),
                Box::new(SceneBvh::new(&ps)),
            ];
            let rays = random_rays(&ps, 4000, 11 + analytic as u64);
            let mut total = 0;
            for accel in &accels {
                for r in &rays {
                    let want = all_hits(&list, r);
                    let got = all_hits(accel.as_ref(), r);
                    // Hits near an edge may be reported by either neighbour
                    // (watertightness promises at least one); the rest must
                    // be the same hits on the same prims.
                    let firm = |v: &[Hit]| -> Vec<Hit> {
                        v.iter()
                            .filter(|h| h.prim >= nt || edge_distance(h) >= 1e-4)
                            .copied()
                            .collect()
                    };
                    let (w, g) = (firm(&want), firm(&got));
                    assert_eq!(w.len(), g.len(), "{r:?}: {want:?} vs {got:?}");
                    for (b, a) in w.iter().zip(&g) {
                        assert!(
                            a.prim == b.prim && same_hit(&ps, r, a, b),
                            "{r:?}: {a:?} vs {b:?}"
                        );
                    }
                    total += w.len();
                    // Stopping at the first hit reports it.
                    let mut seen = 0;
                    let stopped = accel.for_each_hit(r, &mut |_| {
                        seen += 1;
                        true
                    });
                    assert_eq!(stopped, !got.is_empty());
                    assert_eq!(seen, usize::from(stopped));
                }
            }
            // Rays cross several surfaces: the comparison is not vacuous.
            assert!(total > rays.len() * 2, "{total} hits");
        }
    }

    #[test]
    fn closest_and_any_hit_match_brute_force() {
        let s = instanced_scene();
        for analytic in [true, false] {
            let ps = prepare(&s, analytic);
            let bvh = InstancedBvh::new(&ps);
            let count = if analytic { 20_000 } else { 8000 };
            let rays = random_rays(&ps, count, 3 + analytic as u64);
            let ties = check_against_oracle(&ps, &bvh, &rays);
            println!(
                "analytic spheres {analytic}: {ties} edge ties in {}",
                rays.len()
            );
        }
    }

    #[test]
    fn rays_with_finite_extent_match_brute_force() {
        // Segments between random surface points (shadow-ray shaped):
        // t_max limits both the top and the bottom level.
        let s = instanced_scene();
        let ps = prepare(&s, true);
        let bvh = InstancedBvh::new(&ps);
        let nt = ps.triangles.len() as u32;
        let rays: Vec<Ray> = (0..4000u32)
            .map(|i| {
                let mut rng = pixel_rng(21, i, 0, 0);
                let mut point = || {
                    let t = (uniform(&mut rng) * nt as f32) as u32 % nt;
                    let uv = sample_uniform_triangle(uniform2(&mut rng));
                    let sh = ps.triangle_surface(t, uv.x, uv.y);
                    sh.p + sh.ng * 0.05
                };
                let (a, b) = (point(), point());
                Ray::segment(a, b)
            })
            .collect();
        check_against_oracle(&ps, &bvh, &rays);
    }

    #[test]
    fn scenes_without_sharing_or_geometry() {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let ps = prepare(&s, true);
        let bvh = InstancedBvh::new(&ps);
        assert_eq!(bvh.instance_count(), 0);
        assert!(bvh.intersect(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::X)));
        // A mesh used once and a sphere: one flat level, same hits.
        let m = s.add_mesh(icosphere(1.0, 1));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            ..Object::default()
        });
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 0.5 },
            transform: Transform {
                translate: Vec3::new(3.0, 0.0, 0.0),
                ..Transform::default()
            },
            ..Object::default()
        });
        let ps = prepare(&s, true);
        let bvh = InstancedBvh::new(&ps);
        assert_eq!((bvh.level_count(), bvh.instance_count()), (1, 1));
        assert_eq!(duplicated_triangles(&ps), 0);
        check_against_oracle(&ps, &bvh, &random_rays(&ps, 4000, 9));
    }

    #[test]
    fn build_accelerator_matches_brute_force_on_both_sides_of_the_threshold() {
        // 3 and 8 instances of a 5120-triangle mesh: 10240 and 35840
        // duplicated triangles, below and above the threshold.
        for (count, two_level) in [(3, false), (8, true)] {
            let mut s = Scene::default();
            s.add_material(Material::default());
            let m = s.add_mesh(icosphere(1.0, 4));
            for k in 0..count {
                s.objects.push(Object {
                    geometry: Geometry::Mesh(m),
                    transform: Transform {
                        translate: Vec3::new(2.5 * k as f32, 0.0, 0.0),
                        scale: Vec3::new(1.0, 0.5 + 0.1 * k as f32, 1.0),
                        ..Transform::default()
                    },
                    ..Object::default()
                });
            }
            let ps = prepare(&s, true);
            assert_eq!(
                duplicated_triangles(&ps) >= MIN_DUPLICATED_TRIANGLES,
                two_level
            );
            let accel = build_accelerator(&ps);
            let list = ListAccel::new(&ps);
            for r in random_rays(&ps, 600, 17) {
                let (a, b) = (accel.intersect(&r), list.intersect(&r));
                match (a, b) {
                    (None, None) => {}
                    (Some(a), Some(b)) if a.prim == b.prim => {
                        assert!(same_hit(&ps, &r, &a, &b), "{r:?}: {a:?} vs {b:?}")
                    }
                    (Some(a), Some(b)) => assert!(
                        (a.t - b.t).abs() <= 1e-5 * b.t && edge_distance(&a) < 1e-4,
                        "{r:?}: {a:?} vs {b:?}"
                    ),
                    _ => panic!("{r:?}: {a:?} vs {b:?}"),
                }
                assert_eq!(accel.occluded(&r), b.is_some(), "{r:?}");
            }
        }
    }

    #[test]
    fn rays_leaving_a_surface_do_not_hit_it_again() {
        let s = instanced_scene();
        let ps = prepare(&s, true);
        let bvh = InstancedBvh::new(&ps);
        let nt = ps.triangles.len() as u32;
        let sphere = ps.spheres[0];
        let mut rng = pixel_rng(5, 0, 0, 0);
        for i in 0..20_000u32 {
            let (prim, p, ng) = if i % 8 == 0 {
                let d = sample_uniform_sphere(uniform2(&mut rng));
                (nt, sphere.center + sphere.radius * d, d)
            } else {
                let t = (uniform(&mut rng) * nt as f32) as u32 % nt;
                let uv = sample_uniform_triangle(uniform2(&mut rng));
                let sh = ps.triangle_surface(t, uv.x, uv.y);
                (t, sh.p, sh.ng)
            };
            // Directions on both sides, down to grazing angles (1e-3 rad).
            let f = Frame::from_normal(ng);
            let side = if i % 2 == 0 { 1.0 } else { -1.0 };
            let graze = if i % 3 == 0 { 1e-3 } else { uniform(&mut rng) };
            let phi = std::f32::consts::TAU * uniform(&mut rng);
            let cos_t = graze.max(1e-3);
            let sin_t = (1.0 - cos_t * cos_t).sqrt();
            let dir = f.to_world(Vec3::new(
                sin_t * phi.cos(),
                sin_t * phi.sin(),
                side * cos_t,
            ));
            let ray = Ray::new(offset_ray_origin(p, ng, dir), dir);
            if let Some(h) = bvh.intersect(&ray).filter(|h| h.prim == prim) {
                // Only a sphere can be re-entered, and then far away.
                assert!(
                    prim >= nt && side < 0.0 && h.t > 1e-2,
                    "self-hit {h:?} at {i}"
                );
            }
        }
    }

    /// A small shaded image: Lambert under a point light with shadow rays,
    /// one ray per pixel centre, as linear grey values (0 for background).
    fn render(ps: &PreparedScene<'_>, accel: &dyn Accelerator, w: u32, h: u32) -> Vec<f32> {
        let cam = &ps.scene.camera;
        let light = Vec3::new(6.0, 12.0, 10.0);
        (0..w * h)
            .into_par_iter()
            .map(|k| {
                let (x, y) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
                let ray = Ray::new(cam.eye, cam.ray_direction(x, y, w, h));
                let Some(hit) = accel.intersect(&ray) else {
                    return 0.0;
                };
                let sh = ps.surface(&ray, &hit);
                let ng = if sh.ng.dot(ray.dir) > 0.0 {
                    -sh.ng
                } else {
                    sh.ng
                };
                let ns = if sh.ns.dot(ng) < 0.0 { -sh.ns } else { sh.ns };
                let to_light = light - sh.p;
                let cos = ns.dot(to_light.normalize()).max(0.0);
                let origin = offset_ray_origin(sh.p, ng, to_light);
                let lit = cos > 0.0 && !accel.occluded(&Ray::segment(origin, light));
                0.1 + if lit { 0.8 * cos } else { 0.0 }
            })
            .collect()
    }

    #[test]
    fn render_matches_the_flat_bvh() {
        let s = instanced_scene();
        let ps = prepare(&s, true);
        let (w, h) = (64, 64);
        let flat = render(&ps, &SceneBvh::new(&ps), w, h);
        let inst = render(&ps, &InstancedBvh::new(&ps), w, h);
        // The image is not trivial: most pixels see geometry, some of it
        // in shadow.
        let covered = flat.iter().filter(|&&v| v > 0.0).count();
        let shadowed = flat.iter().filter(|&&v| v == 0.1).count();
        assert!(covered > 2000 && shadowed > 50, "{covered} {shadowed}");
        // Object-space intersection rounds differently, so a pixel may
        // differ only at float noise or where a ray grazes a silhouette
        // or a shadow ray passes exactly along an edge.
        let differing: Vec<(usize, f32, f32)> = flat
            .iter()
            .zip(&inst)
            .enumerate()
            .filter(|(_, (a, b))| (*a - *b).abs() > 1.0 / 255.0)
            .map(|(i, (a, b))| (i, *a, *b))
            .collect();
        assert!(differing.len() <= 3, "{differing:?}");
    }
}
