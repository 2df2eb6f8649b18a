//! [`SceneBvh`]: the BVH over a prepared scene's triangles and spheres, leaf
//! triangles in four-wide blocks for the watertight test (Woop, Benthin and Wald 2013).

use super::dispatch::{self, Kernel, kernel};
use super::node::RayPre;
use super::{BLOCK, Bvh, BvhOptions, PAD_SLOT};
use crate::accel::pages::HugeArray;
use crate::accel::{Accelerator, Hit, WatertightRay, intersect_sphere, sphere_roots};
use crate::geometry::{Aabb, Ray};
use crate::prepared::PreparedScene;
use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// Four primitives in consecutive BVH slots (`4 k .. 4 k + 4`), triangles
/// in structure-of-arrays form so that [`TriBlock::intersect`] tests all
/// four at once. 160 bytes.
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(32))]
pub(super) struct TriBlock {
    /// `v[3 * vertex + axis][lane]`; NaN for a sphere or unused lane.
    pub(super) v: [[f32; BLOCK]; 9],
    /// Per lane the [`Hit::prim`] (a sphere when `>= triangle_count`).
    pub(super) prim: [u32; BLOCK],
}

/// Per-lane results of [`TriBlock::intersect`].
pub(super) struct Lanes {
    pub(super) t: [f32; BLOCK],
    pub(super) u: [f32; BLOCK],
    pub(super) v: [f32; BLOCK],
    /// Lanes hit.
    pub(super) mask: u32,
}

impl TriBlock {
    pub(super) const EMPTY: TriBlock = TriBlock {
        v: [[f32::NAN; BLOCK]; 9],
        prim: [u32::MAX; BLOCK],
    };

    /// The watertight test of [`WatertightRay::intersect`] on the lanes in
    /// `lanes`, four at a time (`glam::Vec4`, SSE on x86): the same
    /// operations in the same order per lane and no fused multiply-adds, so
    /// `t`, `u`, `v` are bit-identical to the scalar test (the
    /// double-precision edge fallback runs per lane, scalar).
    #[inline(always)]
    pub(super) fn intersect(&self, wr: &WatertightRay, lanes: u32) -> Lanes {
        let (kx, ky, kz) = (wr.kx, wr.ky, wr.kz);
        let o = wr.origin.to_array();
        let (ox, oy, oz) = (Vec4::splat(o[kx]), Vec4::splat(o[ky]), Vec4::splat(o[kz]));
        let (sx, sy, sz) = (Vec4::splat(wr.sx), Vec4::splat(wr.sy), Vec4::splat(wr.sz));
        let v = &self.v;
        // Translate vertex k to the ray origin and shear: (x, y, z - oz).
        let shear = |k: usize| {
            let dz = Vec4::from_array(v[3 * k + kz]) - oz;
            let x = (Vec4::from_array(v[3 * k + kx]) - ox) - sx * dz;
            let y = (Vec4::from_array(v[3 * k + ky]) - oy) - sy * dz;
            (x, y, dz)
        };
        let (ax, ay, az) = shear(0);
        let (bx, by, bz) = shear(1);
        let (cx, cy, cz) = shear(2);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let zero = Vec4::ZERO;
        let mut fix = (u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero)).bitmask() & lanes;
        if fix != 0 {
            // Recompute in double precision on edges (the paper's fallback).
            let (mut ua, mut va, mut wa) = (u.to_array(), v.to_array(), w.to_array());
            let [axa, aya, bxa, bya, cxa, cya] = [ax, ay, bx, by, cx, cy].map(|x| x.to_array());
            while fix != 0 {
                let i = fix.trailing_zeros() as usize;
                fix &= fix - 1;
                let (cxd, cyd, bxd, byd, axd, ayd) = (
                    cxa[i] as f64,
                    cya[i] as f64,
                    bxa[i] as f64,
                    bya[i] as f64,
                    axa[i] as f64,
                    aya[i] as f64,
                );
                ua[i] = (cxd * byd - cyd * bxd) as f32;
                va[i] = (axd * cyd - ayd * cxd) as f32;
                wa[i] = (bxd * ayd - byd * axd) as f32;
            }
            (u, v, w) = (
                Vec4::from_array(ua),
                Vec4::from_array(va),
                Vec4::from_array(wa),
            );
        }
        let neg = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
        let pos = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
        let det = u + v + w;
        let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
        let inv = Vec4::ONE / det;
        let t = t_scaled * inv;
        let ok = det.cmpne(zero) & t.cmpgt(Vec4::splat(wr.t_min)) & t.cmplt(Vec4::splat(wr.t_max));
        Lanes {
            t: t.to_array(),
            u: (v * inv).to_array(),
            v: (w * inv).to_array(),
            mask: ok.bitmask() & !(neg & pos).bitmask() & lanes,
        }
    }
}

/// Starts loading the triangle block holding slot `first` (a leaf's first
/// block; see [`prefetch`](super::traverse::prefetch)).
#[inline(always)]
pub(super) fn prefetch_block(blocks: &[TriBlock], first: u32) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
    if let Some(b) = blocks.get(first as usize / BLOCK) {
        // 160 bytes: at most four cache lines, starting at v[0], v[4],
        // v[8] and the lane ids.
        safe_arch::prefetch_t0(&b.v[0]);
        safe_arch::prefetch_t0(&b.v[4]);
        safe_arch::prefetch_t0(&b.v[8]);
        safe_arch::prefetch_t0(&b.prim);
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
    let _ = (blocks, first);
}

/// The lane mask of slots `first..end` inside block `b`.
#[inline(always)]
pub(super) fn block_lanes(b: usize, first: usize, end: usize) -> u32 {
    let lo = first.saturating_sub(BLOCK * b).min(BLOCK);
    let hi = (end - BLOCK * b).min(BLOCK);
    ((1u32 << hi) - 1) & !((1u32 << lo) - 1)
}

/// The BVH over a [`PreparedScene`]'s triangles and analytic spheres, with
/// the triangles copied into leaf order in [`BLOCK`]-wide blocks. [`Hit::prim`]
/// numbers triangles first, then spheres, as [`PreparedScene::surface`]
/// expects.
#[derive(Debug, Clone)]
pub struct SceneBvh {
    pub(super) bvh: Bvh,
    /// Slot `s` is lane `s % 4` of block `s / 4`.
    pub(super) blocks: HugeArray<TriBlock>,
    /// Mask per block of the lanes holding spheres.
    pub(super) sphere_lanes: Vec<u8>,
    pub(super) spheres: Vec<(Vec3, f32)>,
    triangle_count: u32,
}

impl SceneBvh {
    /// Builds the BVH over `scene` with [`BvhOptions::default`].
    pub fn new(scene: &PreparedScene<'_>) -> Self {
        Self::with_options(scene, &BvhOptions::default())
    }

    /// Builds the BVH over `scene` with `opts`.
    pub fn with_options(scene: &PreparedScene<'_>, opts: &BvhOptions) -> Self {
        let tri = |t: &[u32; 3]| {
            t.map(|i| {
                scene
                    .positions
                    .get(i as usize)
                    .copied()
                    .unwrap_or(Vec3::NAN)
            })
        };
        let n = scene.triangles.len();
        let box_of = |i: usize| match scene.triangles.get(i) {
            Some(t) => Aabb::from_points(tri(t)),
            None => {
                let s = &scene.spheres[i - n];
                Aabb {
                    min: s.center - Vec3::splat(s.radius.abs()),
                    max: s.center + Vec3::splat(s.radius.abs()),
                }
            }
        };
        let bvh = Bvh::build_boxes(n + scene.spheres.len(), box_of, opts);
        let block = |slots: &[u32]| {
            let mut b = TriBlock::EMPTY;
            let mut spheres = 0u8;
            for (lane, &p) in slots.iter().enumerate() {
                b.prim[lane] = p;
                if p == PAD_SLOT {
                    continue;
                } else if (p as usize) < n {
                    for (k, v) in tri(&scene.triangles[p as usize]).iter().enumerate() {
                        for a in 0..3 {
                            b.v[3 * k + a][lane] = v[a];
                        }
                    }
                } else {
                    spheres |= 1 << lane;
                }
            }
            (b, spheres)
        };
        // Written in place: the mapping's pages are touched (and zeroed by
        // the kernel) by the thread that fills them.
        let count = bvh.prim_order.len().div_ceil(BLOCK);
        let mut blocks = HugeArray::<TriBlock>::zeroed(count);
        let mut sphere_lanes = vec![0u8; count];
        let fill = |((blk, lanes), slots): ((&mut TriBlock, &mut u8), &[u32])| {
            (*blk, *lanes) = block(slots);
        };
        if bvh.prim_order.len() >= opts.parallel_threshold {
            blocks
                .par_iter_mut()
                .zip(sphere_lanes.par_iter_mut())
                .zip(bvh.prim_order.par_chunks(BLOCK))
                .for_each(fill);
        } else {
            blocks
                .iter_mut()
                .zip(sphere_lanes.iter_mut())
                .zip(bvh.prim_order.chunks(BLOCK))
                .for_each(fill);
        }
        Self {
            bvh,
            blocks,
            sphere_lanes,
            spheres: scene.spheres.iter().map(|s| (s.center, s.radius)).collect(),
            triangle_count: n as u32,
        }
    }

    /// The underlying BVH (slots map to prims through [`Bvh::prim_order`]).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Number of triangles (sphere prims are numbered from here).
    pub fn triangle_count(&self) -> u32 {
        self.triangle_count
    }

    #[inline(always)]
    pub(super) fn sphere(&self, prim: u32) -> (Vec3, f32) {
        self.spheres[(prim - self.triangle_count) as usize]
    }

    /// `intersect_sphere` of `ray` (with `t_max`) and sphere `prim`, out of
    /// line: the traversal loops stay free of the sphere test's per-ray
    /// constants, which triangle scenes never use.
    #[cold]
    #[inline(never)]
    pub(super) fn sphere_hit(&self, ray: &Ray, prim: u32, t_max: f32) -> Option<f32> {
        let (c, rad) = self.sphere(prim);
        intersect_sphere(&Ray { t_max, ..*ray }, c, rad)
    }

    /// Calls `visit(hit)` for every intersection with `t` in
    /// `(ray.t_min, ray.t_max)`, in no particular order (a sphere crossed
    /// twice reports both roots), until `visit` returns true. Returns true
    /// if it did. Shadow rays use it to filter non-casting objects and to
    /// attenuate light through transparent surfaces.
    pub fn visit_hits(&self, ray: &Ray, mut visit: impl FnMut(&Hit) -> bool) -> bool {
        let ray = &read_ray(ray);
        self.any_block(ray, |blk, r, spheres| {
            for i in 0..BLOCK {
                let prim = blk.prim[i];
                if r.mask >> i & 1 == 1 {
                    let h = Hit {
                        t: r.t[i],
                        prim,
                        u: r.u[i],
                        v: r.v[i],
                    };
                    if visit(&h) {
                        return true;
                    }
                } else if spheres >> i & 1 == 1 {
                    let (c, rad) = self.sphere(prim);
                    let hit = sphere_roots(ray, c, rad).into_iter().flatten().any(|t| {
                        visit(&Hit {
                            t,
                            prim,
                            u: 0.0,
                            v: 0.0,
                        })
                    });
                    if hit {
                        return true;
                    }
                }
            }
            false
        })
    }

    /// Any-hit traversal a triangle block at a time: for each block of each
    /// leaf the ray crosses, `f(block, triangle hits, sphere lanes)` gets the
    /// block, its triangle lanes' watertight test and the mask of its lanes
    /// that are spheres (untested), until `f` returns true. Returns true if
    /// it did. [`SceneBvh::visit_hits`] and shadow rays share it.
    #[inline(always)]
    fn any_block(&self, ray: &Ray, mut f: impl FnMut(&TriBlock, Lanes, u32) -> bool) -> bool {
        let pre = RayPre::new(ray);
        let wr = WatertightRay::with_inverse(ray, pre.recip);
        let blocks: &[TriBlock] = &self.blocks;
        self.bvh.traverse_any_pre(
            ray,
            &pre,
            |first| prefetch_block(blocks, first),
            |first, count| {
                let end = first + count;
                for (b, blk) in (first / BLOCK..).zip(&blocks[first / BLOCK..=(end - 1) / BLOCK]) {
                    let lanes = block_lanes(b, first, end);
                    let spheres = self.sphere_lanes[b] as u32 & lanes;
                    if f(blk, blk.intersect(&wr, lanes & !spheres), spheres) {
                        return true;
                    }
                }
                false
            },
        )
    }
}

/// `ray`, read one component at a time. Callers build a ray field by field
/// just before the call (4-byte stores), and LLVM would read its origin and
/// direction back in 8-byte pieces, loads that span two of those stores:
/// a processor cannot forward such a load from the stores still in flight,
/// so it waits for them to reach the cache, at the head of the traversal's
/// chain of dependent steps. `black_box` keeps each component a load of its
/// own, which the store-to-load forwarding can serve (BENCHMARKS.md, "Path
/// tracing vs Mitsuba 3").
#[inline(always)]
pub(super) fn read_ray(ray: &Ray) -> Ray {
    let bb = std::hint::black_box::<f32>;
    Ray {
        origin: Vec3::new(bb(ray.origin.x), bb(ray.origin.y), bb(ray.origin.z)),
        dir: Vec3::new(bb(ray.dir.x), bb(ray.dir.y), bb(ray.dir.z)),
        t_min: ray.t_min,
        t_max: ray.t_max,
    }
}

impl SceneBvh {
    /// The closest-hit query's body, inlined into each kernel
    /// ([`super::dispatch`]) that [`Accelerator::intersect`] picks from.
    #[inline(always)]
    pub(super) fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let ray = &read_ray(ray);
        let pre = RayPre::new(ray);
        let mut wr = WatertightRay::with_inverse(ray, pre.recip);
        let mut best = None;
        let blocks: &[TriBlock] = &self.blocks;
        self.bvh.traverse_closest_pre(
            ray,
            &pre,
            |first| prefetch_block(blocks, first),
            |first, count, t_max| {
                let end = first + count;
                wr.t_max = t_max;
                let mut found = None;
                for (b, blk) in (first / BLOCK..).zip(&blocks[first / BLOCK..=(end - 1) / BLOCK]) {
                    let lanes = block_lanes(b, first, end);
                    let spheres = self.sphere_lanes[b] as u32 & lanes;
                    let r = blk.intersect(&wr, lanes & !spheres);
                    // In slot order, keep a hit only if strictly nearer (as a
                    // one-at-a-time scan shrinking t_max would).
                    let mut todo = r.mask | spheres;
                    while todo != 0 {
                        let i = todo.trailing_zeros() as usize;
                        todo &= todo - 1;
                        let hit = if r.mask >> i & 1 == 1 {
                            (r.t[i] < wr.t_max).then_some((r.t[i], r.u[i], r.v[i]))
                        } else if spheres >> i & 1 == 1 {
                            self.sphere_hit(ray, blk.prim[i], wr.t_max)
                                .map(|t| (t, 0.0, 0.0))
                        } else {
                            None
                        };
                        if let Some((t, u, v)) = hit {
                            wr.t_max = t;
                            found = Some(t);
                            best = Some(Hit {
                                t,
                                prim: blk.prim[i],
                                u,
                                v,
                            });
                        }
                    }
                }
                found
            },
        );
        best
    }

    /// The occlusion query's body, inlined into each kernel as
    /// [`SceneBvh::closest_hit`] is.
    #[inline(always)]
    pub(super) fn any_hit(&self, ray: &Ray) -> bool {
        let ray = &read_ray(ray);
        self.any_block(ray, |blk, r, mut spheres| {
            if r.mask != 0 {
                return true;
            }
            while spheres != 0 {
                let i = spheres.trailing_zeros() as usize;
                spheres &= spheres - 1;
                if self.sphere_hit(ray, blk.prim[i], ray.t_max).is_some() {
                    return true;
                }
            }
            false
        })
    }
}

impl Accelerator for SceneBvh {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        match kernel() {
            #[cfg(target_arch = "x86_64")]
            Kernel::X86_64V4 => dispatch::closest_hit_v4(self, ray),
            _ => self.closest_hit(ray),
        }
    }

    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        if self.packets_pay() {
            SceneBvh::intersect_packet(self, rays, hits);
        } else {
            for (r, h) in rays.iter().zip(hits) {
                *h = self.intersect(r);
            }
        }
    }

    fn intersect_camera_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        Accelerator::intersect_packet(self, rays, hits);
    }

    fn occluded_packet(&self, rays: &[Ray], occluded: &mut [bool]) {
        if self.packets_pay() {
            SceneBvh::occluded_packet(self, rays, occluded);
        } else {
            for (r, o) in rays.iter().zip(occluded) {
                *o = self.occluded(r);
            }
        }
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        self.visit_hits(ray, visit)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        match kernel() {
            #[cfg(target_arch = "x86_64")]
            Kernel::X86_64V4 => dispatch::any_hit_v4(self, ray),
            _ => self.any_hit(ray),
        }
    }
}
