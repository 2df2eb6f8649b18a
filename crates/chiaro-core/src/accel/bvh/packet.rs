//! Packet traversal of a [`Bvh`]: up to [`PACKET`] coherent rays (a tile of
//! camera rays, shadow rays towards one light) walk the tree together. A
//! node is loaded once for the packet and each child box is tested against
//! every active ray: with AVX against all eight at once, one ray per lane
//! ([`node_packet`]), elsewhere with [`BvhNode::intersect`] per ray; either
//! way the single-ray test's operations per ray, so the same entry
//! distances and masks. A child is visited when any active ray meets it,
//! with the rays that do.
//!
//! Closest hit: children are visited nearest first by the entry of the
//! first ray that meets them, and a popped child keeps only the rays whose
//! entry lies before their current hit. A packet visits leaves in another
//! order than each ray alone would, so a ray's answer may differ from its
//! single traversal only where that order decides it: two primitives at
//! exactly the same distance (the first visited wins), or a hit that lies
//! before the computed entry of one of its ancestors' boxes (rounding;
//! single traversal may cull such a box). The leaf callback sees both
//! (rays cull with their hit widened by [`CULL_MARGIN`], so a box entered
//! just beyond the hit is still visited) and flags the ray; flagged rays
//! are traced again alone, so the answers are the single traversal's bit
//! for bit. (Only a hit computed more than `CULL_MARGIN` before such an
//! entry, a rounding error far beyond the triangle test's, could escape.)
//!
//! Any hit: each ray visits exactly the leaves its single traversal would
//! (the same node tests with its fixed `t_max`), in another order, and
//! leaves the packet at its first hit.

use super::node::RayPre;
use super::scene::{TriBlock, block_lanes, prefetch_block, read_ray};
use super::traverse::{FixedStack, prefetch};
use super::{BLOCK, Bvh, BvhNode, SceneBvh, WIDTH};
use crate::accel::{Hit, WatertightRay};
use crate::geometry::Ray;

/// Rays per packet (a 4 x 2 tile of camera rays).
pub const PACKET: usize = 8;
const _: () = assert!(PACKET <= 32, "ray masks are u32");

/// Relative widening of a ray's current hit distance for culling (see the
/// module documentation): boxes entered up to this far beyond the hit are
/// still visited, so that hits the single traversal may have ordered
/// differently are seen and the ray is flagged.
pub(super) const CULL_MARGIN: f32 = 1.0 / 1024.0;

/// A ray's culling distance for a current hit (or `t_max`) of `t`.
#[inline(always)]
pub(super) fn widen(t: f32) -> f32 {
    t + t.abs() * CULL_MARGIN
}

/// A deferred child of a packet traversal: the rays that meet it and, per
/// ray, the largest entry distance on the path to it (its own box's and
/// its ancestors').
#[derive(Debug, Clone, Copy)]
pub(super) struct PacketEntry {
    pub(super) child: u32,
    pub(super) count: u32,
    pub(super) rays: u32,
    pub(super) near: [f32; PACKET],
}

impl Default for PacketEntry {
    fn default() -> Self {
        Self {
            child: 0,
            count: 0,
            rays: 0,
            near: [0.0; PACKET],
        }
    }
}

/// Entries in a packet stack's first fixed part, cleared for every packet
/// (a packet through a small scene seldom holds more, and clearing a larger
/// array would cost more than its traversal).
const PACKET_STACK_FIRST: usize = 12;
/// Entries in the second fixed part, set up only when a packet first needs
/// it; deeper trees spill into a `Vec`.
const PACKET_STACK_MORE: usize = 36;

/// The packet traversal stack.
pub(super) type PacketStack = FixedStack<PacketEntry, PACKET_STACK_FIRST, PACKET_STACK_MORE>;

/// Iterates over the set bits of a mask, lowest first.
#[inline(always)]
fn bits(mut m: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            i
        })
    })
}

/// A packet's origins, inverse directions and `t_min`s in
/// structure-of-arrays form, one ray per lane, for [`node_packet`]'s test of
/// a child box against all rays at once.
#[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
pub(super) struct PacketPre {
    org: [safe_arch::m256; 3],
    /// `1 / dir` per axis; its sign bit picks the entry plane, as
    /// [`RayPre`]'s rows do.
    inv: [safe_arch::m256; 3],
    t_min: safe_arch::m256,
}

/// Without AVX the packet's node test runs per ray ([`node_per_ray`]).
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
pub(super) struct PacketPre;

impl PacketPre {
    #[inline(always)]
    pub(super) fn new(rays: &[Ray; PACKET], pre: &[RayPre; PACKET], t_min: &[f32; PACKET]) -> Self {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
        {
            const _: () = assert!(PACKET == 8, "one ray per AVX lane");
            let row =
                |f: &dyn Fn(usize) -> f32| safe_arch::m256::from_array(std::array::from_fn(f));
            Self {
                org: std::array::from_fn(|a| row(&|r| rays[r].origin[a])),
                inv: std::array::from_fn(|a| row(&|r| pre[r].recip[a])),
                t_min: safe_arch::m256::from_array(*t_min),
            }
        }
        #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
        {
            let _ = (rays, pre, t_min);
            Self
        }
    }
}

/// Mask of the rays whose `near` is at most their `cull` (NaN: not).
#[inline(always)]
fn before(near: &[f32; PACKET], cull: &[f32; PACKET]) -> u32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    {
        use safe_arch::*;
        let le = cmp_op_mask_m256::<{ cmp_op!(LessEqualOrdered) }>(
            m256::from_array(*near),
            m256::from_array(*cull),
        );
        move_mask_m256(le) as u32
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    {
        (0..PACKET).fold(0, |m, r| m | (u32::from(near[r] <= cull[r]) << r))
    }
}

/// Per child of `n`: the mask of the rays in `rays` that meet its box
/// within `(t_min, cull)` (the single-ray node test's answer for each
/// ray), their entry distances raised to their `path` entries, and the
/// entry of the first such ray (the packet's order key).
pub(super) type NodeRays = ([u32; WIDTH], [[f32; PACKET]; WIDTH], [f32; WIDTH]);

/// The node test of a packet, one child at a time across the rays (one ray
/// per AVX lane): per ray the same operations in the same order as
/// [`BvhNode::intersect`] (the entry plane chosen by the sign of `1 /
/// dir`, `max`/`min` with the same operand order), so the same bits.
/// Without AVX, [`node_per_ray`].
#[inline(always)]
pub(super) fn node_packet(
    n: &BvhNode,
    pre: &[RayPre; PACKET],
    soa: &PacketPre,
    t_min: &[f32; PACKET],
    cull: &[f32; PACKET],
    rays: u32,
    path: &[f32; PACKET],
) -> NodeRays {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    {
        use super::{EMPTY_LANE, EXIT_SLACK};
        use safe_arch::*;
        // (The per-ray forms are for the portable test.)
        let _ = (pre, t_min);
        let mut lane_rays = [0u32; WIDTH];
        let mut lane_near = [[f32::INFINITY; PACKET]; WIDTH];
        let mut lane_key = [f32::INFINITY; WIDTH];
        let cull = m256::from_array(*cull);
        let path = m256::from_array(*path);
        let b = &n.bounds;
        for i in 0..WIDTH {
            if n.count[i] == EMPTY_LANE {
                continue;
            }
            let slab = |a: usize, near: bool| {
                let (lo, hi) = (set_splat_m256(b[a][i]), set_splat_m256(b[a + 3][i]));
                let plane = if near {
                    blend_varying_m256(lo, hi, soa.inv[a])
                } else {
                    blend_varying_m256(hi, lo, soa.inv[a])
                };
                mul_m256(sub_m256(plane, soa.org[a]), soa.inv[a])
            };
            let near = max_m256(
                slab(2, true),
                max_m256(slab(1, true), max_m256(slab(0, true), soa.t_min)),
            );
            let far = min_m256(
                slab(2, false),
                min_m256(
                    slab(1, false),
                    min_m256(slab(0, false), set_splat_m256(f32::INFINITY)),
                ),
            );
            let far = min_m256(mul_m256(far, set_splat_m256(EXIT_SLACK)), cull);
            let hit = cmp_op_mask_m256::<{ cmp_op!(LessEqualOrdered) }>(near, far);
            let mask = move_mask_m256(hit) as u32 & rays;
            if mask != 0 {
                lane_rays[i] = mask;
                let near = near.to_array();
                lane_key[i] = near[mask.trailing_zeros() as usize];
                lane_near[i] = max_m256(m256::from_array(near), path).to_array();
            }
        }
        (lane_rays, lane_near, lane_key)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    {
        let _ = soa; // (The AVX test's form of the rays.)
        node_per_ray(n, pre, t_min, cull, rays, path)
    }
}

/// [`node_packet`] a ray at a time with [`BvhNode::intersect`]: the
/// portable packet node test, and the AVX one's test oracle.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "avx"))))]
#[inline(always)]
pub(super) fn node_per_ray(
    n: &BvhNode,
    pre: &[RayPre; PACKET],
    t_min: &[f32; PACKET],
    cull: &[f32; PACKET],
    rays: u32,
    path: &[f32; PACKET],
) -> NodeRays {
    let mut lane_rays = [0u32; WIDTH];
    let mut lane_near = [[f32::INFINITY; PACKET]; WIDTH];
    let mut lane_key = [f32::INFINITY; WIDTH];
    for r in bits(rays) {
        let (near, mask) = n.intersect(&pre[r], t_min[r], cull[r]);
        for i in bits(mask) {
            if lane_rays[i] == 0 {
                lane_key[i] = near[i];
            }
            lane_rays[i] |= 1 << r;
            lane_near[i][r] = near[i].max(path[r]);
        }
    }
    (lane_rays, lane_near, lane_key)
}

impl Bvh {
    /// Closest-hit traversal of the rays in `rays` (a mask over `pre`):
    /// `pre[r]` is ray `r`'s `RayPre`, `t_min[r]` its `t_min` and `cull[r]`
    /// its culling distance (`widen(t_max)`). `test(first, count, rays,
    /// near, cull)` intersects the leaf's slots `first..first + count` for
    /// the rays in mask `rays`, whose path entry distances are `near`, and
    /// lowers `cull` for the rays it finds hits for; `leaf(first)` is called
    /// for each leaf pushed on the stack, to prefetch its data.
    #[inline(always)]
    pub(super) fn traverse_closest_packet(
        &self,
        pre: &[RayPre; PACKET],
        soa: &PacketPre,
        t_min: &[f32; PACKET],
        cull: &mut [f32; PACKET],
        rays: u32,
        leaf: impl Fn(u32),
        mut test: impl FnMut(usize, usize, u32, &[f32; PACKET], &mut [f32; PACKET]),
    ) {
        if self.nodes.is_empty() || rays == 0 {
            return;
        }
        let nodes: &[BvhNode] = &self.nodes;
        let mut stack = PacketStack::new();
        let mut cur = PacketEntry {
            rays,
            near: [f32::NEG_INFINITY; PACKET],
            ..PacketEntry::default()
        };
        loop {
            if cur.count == 0 {
                let n = &nodes[cur.child as usize];
                let (lane_rays, lane_near, lane_min) =
                    node_packet(n, pre, soa, t_min, cull, cur.rays, &cur.near);
                // Hit children, farthest (by the packet's entry) first.
                let mut order = [0usize; WIDTH];
                let mut k = 0usize;
                for i in 0..WIDTH {
                    if lane_rays[i] == 0 {
                        continue;
                    }
                    let mut j = k;
                    while j > 0 && lane_min[order[j - 1]] < lane_min[i] {
                        order[j] = order[j - 1];
                        j -= 1;
                    }
                    order[j] = i;
                    k += 1;
                }
                if k > 0 {
                    let entry = |i: usize| PacketEntry {
                        child: n.child[i],
                        count: n.count[i],
                        rays: lane_rays[i],
                        near: lane_near[i],
                    };
                    for &i in &order[..k - 1] {
                        prefetch(nodes, n.child[i], n.count[i], &leaf);
                        stack.push(entry(i));
                    }
                    cur = entry(order[k - 1]);
                    continue;
                }
            } else {
                test(
                    cur.child as usize,
                    cur.count as usize,
                    cur.rays,
                    &cur.near,
                    cull,
                );
            }
            // Pop the next child, keeping the rays whose entry lies before
            // their culling distance.
            loop {
                let Some(mut e) = stack.pop() else {
                    return;
                };
                e.rays &= before(&e.near, cull);
                if e.rays != 0 {
                    cur = e;
                    break;
                }
            }
        }
    }

    /// Any-hit traversal of the rays in `rays` (a mask over `pre`), each
    /// with its `t_min[r]` and `t_max[r]`: `test(first, count, rays)`
    /// intersects the leaf's slots `first..first + count` for the rays in
    /// mask `rays` and returns the mask of those that hit something, which
    /// then leave the packet. Returns the mask of rays that hit; `leaf` as
    /// in [`Bvh::traverse_closest_packet`]. Each ray meets exactly the
    /// leaves its single any-hit traversal would.
    #[inline(always)]
    pub(super) fn traverse_any_packet(
        &self,
        pre: &[RayPre; PACKET],
        soa: &PacketPre,
        t_min: &[f32; PACKET],
        t_max: &[f32; PACKET],
        rays: u32,
        leaf: impl Fn(u32),
        mut test: impl FnMut(usize, usize, u32) -> u32,
    ) -> u32 {
        if self.nodes.is_empty() || rays == 0 {
            return 0;
        }
        let nodes: &[BvhNode] = &self.nodes;
        let mut stack = PacketStack::new();
        let mut done = 0u32;
        let mut cur = PacketEntry {
            rays,
            ..PacketEntry::default()
        };
        loop {
            if cur.count == 0 {
                let n = &nodes[cur.child as usize];
                let far = [f32::NEG_INFINITY; PACKET];
                let (lane_rays, _, _) = node_packet(n, pre, soa, t_min, t_max, cur.rays, &far);
                let mut first = None;
                for (i, &rays) in lane_rays.iter().enumerate() {
                    if rays == 0 {
                        continue;
                    }
                    let e = PacketEntry {
                        child: n.child[i],
                        count: n.count[i],
                        rays,
                        near: [0.0; PACKET],
                    };
                    if first.is_none() {
                        first = Some(e);
                    } else {
                        prefetch(nodes, e.child, e.count, &leaf);
                        stack.push(e);
                    }
                }
                if let Some(e) = first {
                    cur = e;
                    continue;
                }
            } else {
                done |= test(cur.child as usize, cur.count as usize, cur.rays);
                if done == rays {
                    return done;
                }
            }
            loop {
                let Some(mut e) = stack.pop() else {
                    return done;
                };
                e.rays &= !done;
                if e.rays != 0 {
                    cur = e;
                    break;
                }
            }
        }
    }
}

/// One packet's rays (the last padded with copies of the first) and their
/// per-ray constants.
struct Packet {
    rays: [Ray; PACKET],
    pre: [RayPre; PACKET],
    soa: PacketPre,
    wr: [WatertightRay; PACKET],
    t_min: [f32; PACKET],
    /// Mask of the real rays.
    live: u32,
}

impl Packet {
    #[inline(always)]
    fn new(rays: &[Ray]) -> Self {
        debug_assert!(!rays.is_empty() && rays.len() <= PACKET);
        let rays: [Ray; PACKET] = std::array::from_fn(|i| read_ray(&rays[i.min(rays.len() - 1)]));
        let pre: [RayPre; PACKET] = std::array::from_fn(|i| RayPre::new(&rays[i]));
        let t_min = rays.map(|r| r.t_min);
        Self {
            wr: std::array::from_fn(|i| WatertightRay::with_inverse(&rays[i], pre[i].recip)),
            soa: PacketPre::new(&rays, &pre, &t_min),
            t_min,
            live: (1u32 << rays.len().min(PACKET)) - 1,
            rays,
            pre,
        }
    }
}

/// Nodes from which [`SceneBvh`]'s `Accelerator` packet queries trace
/// packets; smaller trees loop over single rays. A packet saves node loads
/// that miss the cache and costs set-up and per-node work for eight rays, so
/// it pays only on a tree far larger than the cache (BENCHMARKS.md, "BVH ray
/// packets").
pub const PACKET_MIN_NODES: usize = 1 << 15;

impl SceneBvh {
    /// Whether packets pay on this tree ([`PACKET_MIN_NODES`]): the
    /// `Accelerator` packet queries use them when true and loop over single
    /// rays otherwise. [`SceneBvh::intersect_packet`] and
    /// [`SceneBvh::occluded_packet`] always trace packets.
    pub fn packets_pay(&self) -> bool {
        self.bvh.node_count() >= PACKET_MIN_NODES
    }

    /// [`Accelerator::intersect`](crate::accel::Accelerator::intersect) of
    /// each ray into `hits` (`hits.len() == rays.len()`), [`PACKET`] rays
    /// at a time through the packet traversal: bit-identical answers, faster
    /// when neighbouring rays are coherent (a tile of camera rays).
    pub fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        debug_assert_eq!(rays.len(), hits.len());
        for (rs, hs) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            if rs.len() == 1 {
                hs[0] = crate::accel::Accelerator::intersect(self, &rs[0]);
            } else {
                self.closest_packet(rs, hs);
            }
        }
    }

    /// [`Accelerator::occluded`](crate::accel::Accelerator::occluded) of
    /// each ray into `occluded` (`occluded.len() == rays.len()`), [`PACKET`]
    /// rays at a time (shadow rays towards one light).
    pub fn occluded_packet(&self, rays: &[Ray], occluded: &mut [bool]) {
        debug_assert_eq!(rays.len(), occluded.len());
        for (rs, os) in rays.chunks(PACKET).zip(occluded.chunks_mut(PACKET)) {
            let p = Packet::new(rs);
            let hit = self.any_packet(&p);
            for (i, o) in os.iter_mut().enumerate() {
                *o = hit >> i & 1 == 1;
            }
        }
    }

    /// Closest hits of up to [`PACKET`] rays (see the module documentation
    /// for the rays traced again alone).
    fn closest_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        let p = Packet::new(rays);
        let mut best_t = p.rays.map(|r| r.t_max);
        let mut cull = best_t.map(widen);
        let mut best: [Option<Hit>; PACKET] = [None; PACKET];
        let mut again = 0u32;
        let blocks: &[TriBlock] = &self.blocks;
        self.bvh.traverse_closest_packet(
            &p.pre,
            &p.soa,
            &p.t_min,
            &mut cull,
            p.live,
            |first| prefetch_block(blocks, first),
            |first, count, rays, near, cull| {
                let end = first + count;
                for r in bits(rays) {
                    let mut wr = p.wr[r];
                    wr.t_max = cull[r];
                    for (b, blk) in
                        (first / BLOCK..).zip(&blocks[first / BLOCK..=(end - 1) / BLOCK])
                    {
                        let lanes = block_lanes(b, first, end);
                        let spheres = self.sphere_lanes[b] as u32 & lanes;
                        let res = blk.intersect(&wr, lanes & !spheres);
                        for i in bits(res.mask | spheres) {
                            let hit = if res.mask >> i & 1 == 1 {
                                Some((res.t[i], res.u[i], res.v[i]))
                            } else {
                                self.sphere_hit(&p.rays[r], blk.prim[i], wr.t_max)
                                    .map(|t| (t, 0.0, 0.0))
                            };
                            let Some((t, u, v)) = hit else {
                                continue;
                            };
                            if t < best_t[r] {
                                // Before an entry on its path: the single
                                // traversal may have culled this leaf.
                                if t < near[r] {
                                    again |= 1 << r;
                                }
                                best_t[r] = t;
                                cull[r] = widen(t);
                                wr.t_max = cull[r];
                                best[r] = Some(Hit {
                                    t,
                                    prim: blk.prim[i],
                                    u,
                                    v,
                                });
                            } else if t == best_t[r] && best[r].is_some() {
                                // A tie: the visiting order decides it.
                                again |= 1 << r;
                            }
                        }
                    }
                }
            },
        );
        for (i, h) in hits.iter_mut().enumerate() {
            *h = if again >> i & 1 == 1 {
                crate::accel::Accelerator::intersect(self, &rays[i])
            } else {
                best[i]
            };
        }
    }

    /// The mask of the rays of `p` that hit anything.
    fn any_packet(&self, p: &Packet) -> u32 {
        let blocks: &[TriBlock] = &self.blocks;
        let t_max = p.rays.map(|r| r.t_max);
        self.bvh.traverse_any_packet(
            &p.pre,
            &p.soa,
            &p.t_min,
            &t_max,
            p.live,
            |first| prefetch_block(blocks, first),
            |first, count, rays| {
                let end = first + count;
                let mut hit = 0u32;
                for r in bits(rays) {
                    let blks = &blocks[first / BLOCK..=(end - 1) / BLOCK];
                    let found = (first / BLOCK..).zip(blks).any(|(b, blk)| {
                        let lanes = block_lanes(b, first, end);
                        let spheres = self.sphere_lanes[b] as u32 & lanes;
                        blk.intersect(&p.wr[r], lanes & !spheres).mask != 0
                            || bits(spheres).any(|i| {
                                self.sphere_hit(&p.rays[r], blk.prim[i], t_max[r]).is_some()
                            })
                    });
                    if found {
                        hit |= 1 << r;
                    }
                }
                hit
            },
        )
    }
}
