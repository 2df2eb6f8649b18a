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

mod sharing;
#[cfg(test)]
mod tests;

pub use sharing::duplicated_triangles;

use super::bvh::{Bvh, BvhNode, BvhOptions, PAD_SLOT, SceneBvh};
use super::{Accelerator, Hit};
use crate::geometry::{Aabb, Ray};
use crate::prepared::{PrepareOptions, PreparedScene};
use crate::scene::{Geometry, Mesh, MeshId, Object, Scene, Transform};
use glam::{Affine3A, Mat4, Vec3, Vec4};
use sharing::{Candidate, duplicated, shared_instances, valid_triangles};

/// [`build_accelerator`] picks the two-level BVH when instancing saves at
/// least this many triangles (the triangles a flat BVH would hold beyond
/// one copy of each shared mesh). Below it the flat BVH's extra copies
/// still fit a core's cache: it is as fast or faster and small anyway;
/// above it incoherent rays (the path tracer's), build time and memory
/// favour the two-level BVH,
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

/// The accelerator for `ps`: an [`InstancedBvh`] when instancing saves at
/// least [`MIN_DUPLICATED_TRIANGLES`] triangles ([`duplicated_triangles`]),
/// the flat [`SceneBvh`] otherwise. Both give the same answers up to
/// rounding; the choice only trades memory and build time against the
/// per-instance cost of a ray transform. Wrapped in
/// [`super::alpha::AlphaTested`] when the scene has masked materials, and in
/// [`super::cull::Culled`] when it has single-sided (`Sidedness::Culled`) ones.
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
