//! The bounding volume hierarchy: a binary BVH built with the binned
//! surface-area heuristic, and [`SceneBvh`], the scene-level
//! [`Accelerator`] over a [`PreparedScene`]'s triangles and analytic spheres.
//!
//! Build (after Wald 2007, "On fast Construction of SAH-based Bounding Volume
//! Hierarchies", and pbrt-v4 `BVHAggregate::buildRecursive`): primitive
//! references are binned by centroid into `bins` buckets on each axis, the
//! split with the least SAH cost `C_trav + (A_l N_l + A_r N_r) / A` is taken
//! (or a leaf when that is cheaper and the node holds at most `max_leaf`
//! primitives), and the references are partitioned in place, so the final
//! reference order is the leaf order and primitives can be stored in it for
//! locality. Each level costs O(n), the tree has O(log n) levels: O(n log n).
//! Large nodes bin in parallel and build their two halves with
//! `rayon::join`; the result does not depend on the number of threads.
//!
//! Layout: 32-byte [`BvhNode`]s in depth-first order; the two children of
//! an interior node are adjacent (`offset`, `offset + 1`), so one cache line
//! holds both boxes that traversal tests together.
//!
//! Traversal keeps an explicit stack, tests boxes with the slab method and
//! the precomputed inverse direction (Kay and Kajiya 1986; Williams et al.
//! 2005), visits the nearer child first for closest hits (pbrt-v4 section
//! 7.3.5), and stops at the first hit for occlusion queries. Box exits are
//! widened by `1 + 2 gamma(3)` (pbrt-v4 section 6.8.2) so that rounding
//! never culls a primitive the exact test would hit.

use super::{Accelerator, Hit, WatertightRay, intersect_sphere};
use crate::geometry::{Aabb, Ray};
use crate::prepared::PreparedScene;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;

/// Most bins a build may use.
pub const MAX_BINS: usize = 64;
/// Traversal stack size; the build keeps the tree shallower than this.
const STACK: usize = 128;
/// Depth from which the build splits at the object median (bounding the
/// depth however the primitives are distributed).
const MEDIAN_DEPTH: u32 = 64;
/// `1 + 2 gamma(3)`, gamma(n) = n eps / (1 - n eps) with eps = 2^-24
/// (pbrt-v4 eq. 6.24 and section 6.8.2).
const EXIT_SLACK: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// One node: its box, and either two children or a run of primitives.
/// 32 bytes, 32-byte aligned.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
pub struct BvhNode {
    /// Lower corner of the box.
    pub min: [f32; 3],
    /// Interior node: index of the left child (the right one follows it).
    /// Leaf: first slot of its primitives in [`Bvh::prim_order`].
    pub offset: u32,
    /// Upper corner of the box.
    pub max: [f32; 3],
    /// Number of primitives of a leaf; 0 for an interior node.
    pub count: u32,
}

impl BvhNode {
    const EMPTY: BvhNode = BvhNode {
        min: [0.0; 3],
        offset: 0,
        max: [0.0; 3],
        count: 0,
    };

    fn new(b: &Aabb, offset: u32, count: u32) -> Self {
        Self {
            min: b.min.to_array(),
            offset,
            max: b.max.to_array(),
            count,
        }
    }

    /// True for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// The node's box.
    pub fn bounds(&self) -> Aabb {
        Aabb {
            min: Vec3::from(self.min),
            max: Vec3::from(self.max),
        }
    }
}

/// Build parameters. The defaults suit ray tracing triangle meshes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BvhOptions {
    /// SAH bins per axis (clamped to `2..=MAX_BINS`).
    pub bins: usize,
    /// Largest leaf (clamped to `1..=255`); leaves are made smaller when
    /// the SAH says splitting pays.
    pub max_leaf: u32,
    /// Cost of a traversal step relative to one primitive test.
    pub traversal_cost: f32,
    /// Nodes with at least this many primitives bin in parallel and build
    /// their children with `rayon::join`.
    pub parallel_threshold: usize,
}

impl Default for BvhOptions {
    fn default() -> Self {
        Self {
            bins: 16,
            max_leaf: 4,
            traversal_cost: 1.0,
            parallel_threshold: 8192,
        }
    }
}

/// A primitive reference during the build.
#[derive(Debug, Clone, Copy)]
struct PrimRef {
    min: Vec3,
    max: Vec3,
    index: u32,
}

impl PrimRef {
    #[inline]
    fn centroid(&self) -> Vec3A {
        (Vec3A::from(self.min) + Vec3A::from(self.max)) * 0.5
    }
}

/// Two sibling nodes in one 64-byte cache line.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(64))]
struct NodePair([BvhNode; 2]);

/// A binary BVH over primitive boxes. It knows nothing about the
/// primitives themselves: queries call back with *slots*, positions in
/// [`Bvh::prim_order`], which maps each slot to the index of the box given
/// to [`Bvh::build`].
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    /// Node `i` is `pairs[i / 2].0[i % 2]`; the root is node 0 (node 1 is
    /// unused padding), so every pair of siblings shares a cache line.
    pairs: Vec<NodePair>,
    prim_order: Vec<u32>,
}

#[derive(Debug, Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Aabb::EMPTY,
    count: 0,
};

/// How to cut a node's references.
enum Split {
    Leaf,
    /// Partition along `axis` into `bins` bins: bins `0..=bin` go left.
    Binned {
        axis: usize,
        bin: usize,
        bins: usize,
    },
    /// Split at the object median along `axis` (degenerate centroids or a
    /// deep node).
    Median {
        axis: usize,
    },
}

impl Bvh {
    /// Builds a BVH over `bounds` with [`BvhOptions::default`].
    pub fn build(bounds: &[Aabb]) -> Self {
        Self::build_with(bounds, &BvhOptions::default())
    }

    /// Builds a BVH over `bounds` (one box per primitive). Empty or
    /// non-finite boxes are left out: nothing can hit them.
    pub fn build_with(bounds: &[Aabb], opts: &BvhOptions) -> Self {
        let opts = BvhOptions {
            bins: opts.bins.clamp(2, MAX_BINS),
            max_leaf: opts.max_leaf.clamp(1, 255),
            traversal_cost: if opts.traversal_cost.is_finite() {
                opts.traversal_cost.max(0.0)
            } else {
                1.0
            },
            parallel_threshold: opts.parallel_threshold.max(2),
        };
        let make = |(i, b): (usize, &Aabb)| {
            (!b.is_empty() && b.min.is_finite() && b.max.is_finite()).then_some(PrimRef {
                min: b.min,
                max: b.max,
                index: i as u32,
            })
        };
        let mut refs: Vec<PrimRef> = if bounds.len() >= opts.parallel_threshold {
            bounds.par_iter().enumerate().filter_map(make).collect()
        } else {
            bounds.iter().enumerate().filter_map(make).collect()
        };
        if refs.is_empty() {
            return Self::default();
        }
        let nodes = build_subtree(&mut refs, 0, 0, &opts);
        let pairs = nodes
            .chunks(2)
            .map(|c| NodePair([c[0], c.get(1).copied().unwrap_or(BvhNode::EMPTY)]))
            .collect();
        let prim_order = refs.iter().map(|r| r.index).collect();
        Self { pairs, prim_order }
    }

    /// Number of node slots (node 1 is padding; 0 for an empty BVH).
    pub fn node_count(&self) -> usize {
        self.pairs.len() * 2
    }

    /// Node `i` (the root is node 0; the children of an interior node `n`
    /// are `n.offset` and `n.offset + 1`).
    ///
    /// # Panics
    /// If `i >= self.node_count()`.
    #[inline(always)]
    pub fn node(&self, i: usize) -> &BvhNode {
        &self.pairs[i >> 1].0[i & 1]
    }

    /// Every node reachable from the root, in storage order.
    pub fn nodes(&self) -> impl Iterator<Item = &BvhNode> + '_ {
        self.pairs
            .iter()
            .enumerate()
            .flat_map(|(k, p)| p.0.iter().take(if k == 0 { 1 } else { 2 }))
    }

    /// For each slot, the index of its primitive in the `bounds` given to
    /// the build. Leaves refer to contiguous runs of slots.
    pub fn prim_order(&self) -> &[u32] {
        &self.prim_order
    }

    /// Bounds of everything (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        self.pairs.first().map_or(Aabb::EMPTY, |p| p.0[0].bounds())
    }

    /// Depth of the tree (a single leaf has depth 1; 0 when empty).
    pub fn depth(&self) -> usize {
        fn rec(b: &Bvh, i: usize) -> usize {
            let n = b.node(i);
            if n.is_leaf() {
                1
            } else {
                1 + rec(b, n.offset as usize).max(rec(b, n.offset as usize + 1))
            }
        }
        if self.pairs.is_empty() {
            0
        } else {
            rec(self, 0)
        }
    }

    /// Closest-hit traversal. `test(slot, t_max)` intersects the primitive
    /// in `slot` and returns its hit distance when it is inside
    /// `(ray.t_min, t_max)`; traversal then shrinks `t_max` to it and visits
    /// nearer children first. Returns the final `t_max` (`ray.t_max` when
    /// nothing was hit).
    #[inline]
    pub fn traverse_closest(
        &self,
        ray: &Ray,
        mut test: impl FnMut(usize, f32) -> Option<f32>,
    ) -> f32 {
        let mut t_max = ray.t_max;
        if self.pairs.is_empty() {
            return t_max;
        }
        let org = Vec3A::from(ray.origin);
        let inv = Vec3A::ONE / Vec3A::from(ray.dir);
        let t_min = ray.t_min;
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        if slab(self.node(0), org, inv, t_min, t_max).is_none() {
            return t_max;
        }
        let mut node = 0usize;
        loop {
            let n = self.node(node);
            if n.count > 0 {
                let first = n.offset as usize;
                for slot in first..first + n.count as usize {
                    if let Some(t) = test(slot, t_max) {
                        t_max = t;
                    }
                }
            } else {
                let l = n.offset as usize;
                let hl = slab(self.node(l), org, inv, t_min, t_max);
                let hr = slab(self.node(l + 1), org, inv, t_min, t_max);
                match (hl, hr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b { (l, l + 1) } else { (l + 1, l) };
                        if sp < STACK {
                            stack[sp] = far as u32;
                            sp += 1;
                        }
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = l + 1;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next node whose box still lies in front of the hit.
            loop {
                if sp == 0 {
                    return t_max;
                }
                sp -= 1;
                let i = stack[sp] as usize;
                if slab(self.node(i), org, inv, t_min, t_max).is_some() {
                    node = i;
                    break;
                }
            }
        }
    }

    /// Any-hit traversal: calls `test(slot)` for every primitive whose
    /// leaf box the ray crosses in `(ray.t_min, ray.t_max)`, in no
    /// particular order, until it returns true. Returns true if it did.
    #[inline]
    pub fn traverse_any(&self, ray: &Ray, mut test: impl FnMut(usize) -> bool) -> bool {
        if self.pairs.is_empty() {
            return false;
        }
        let org = Vec3A::from(ray.origin);
        let inv = Vec3A::ONE / Vec3A::from(ray.dir);
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        if slab(self.node(0), org, inv, t_min, t_max).is_none() {
            return false;
        }
        let mut node = 0usize;
        loop {
            let n = self.node(node);
            if n.count > 0 {
                let first = n.offset as usize;
                for slot in first..first + n.count as usize {
                    if test(slot) {
                        return true;
                    }
                }
            } else {
                let l = n.offset as usize;
                let hl = slab(self.node(l), org, inv, t_min, t_max).is_some();
                let hr = slab(self.node(l + 1), org, inv, t_min, t_max).is_some();
                if hl && hr {
                    if sp < STACK {
                        stack[sp] = (l + 1) as u32;
                        sp += 1;
                    }
                    node = l;
                    continue;
                } else if hl {
                    node = l;
                    continue;
                } else if hr {
                    node = l + 1;
                    continue;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node = stack[sp] as usize;
        }
    }
}

/// Slab test: the entry distance when the ray meets the node's box within
/// `(t_min, t_max)`.
#[inline(always)]
fn slab(n: &BvhNode, org: Vec3A, inv: Vec3A, t_min: f32, t_max: f32) -> Option<f32> {
    let t0 = (Vec3A::from(n.min) - org) * inv;
    let t1 = (Vec3A::from(n.max) - org) * inv;
    let near = t0.min(t1).max_element().max(t_min);
    let far = (t0.max(t1).min_element() * EXIT_SLACK).min(t_max);
    (near <= far).then_some(near)
}

/// Bounds of the references and of their centroids.
fn ref_bounds(refs: &[PrimRef], parallel: bool) -> (Aabb, Aabb) {
    let one = |refs: &[PrimRef]| {
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let (mut clo, mut chi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for r in refs {
            lo = lo.min(Vec3A::from(r.min));
            hi = hi.max(Vec3A::from(r.max));
            let c = r.centroid();
            clo = clo.min(c);
            chi = chi.max(c);
        }
        (
            Aabb {
                min: lo.into(),
                max: hi.into(),
            },
            Aabb {
                min: clo.into(),
                max: chi.into(),
            },
        )
    };
    if parallel {
        refs.par_chunks(16 * 1024).map(one).reduce(
            || (Aabb::EMPTY, Aabb::EMPTY),
            |a, b| (a.0.union(b.0), a.1.union(b.1)),
        )
    } else {
        one(refs)
    }
}

/// Bin index of a centroid coordinate; the build and the partition use this
/// one function so they always agree.
#[inline(always)]
fn bin_of(c: f32, lo: f32, scale: f32, bins: usize) -> usize {
    let b = ((c - lo) * scale) as i64;
    b.clamp(0, bins as i64 - 1) as usize
}

/// Bins the references' centroids and boxes into `out` (`3 * bins`
/// entries: axis-major).
fn bin_refs(
    refs: &[PrimRef],
    cb: &Aabb,
    scale: Vec3,
    bins: usize,
    parallel: bool,
    out: &mut [Bin],
) {
    let one = |refs: &[PrimRef], out: &mut [Bin]| {
        for r in refs {
            let c = r.centroid();
            let rb = Aabb {
                min: r.min,
                max: r.max,
            };
            for axis in 0..3 {
                let b = &mut out[axis * bins + bin_of(c[axis], cb.min[axis], scale[axis], bins)];
                b.bounds = b.bounds.union(rb);
                b.count += 1;
            }
        }
    };
    out.fill(EMPTY_BIN);
    if parallel {
        let parts: Vec<Vec<Bin>> = refs
            .par_chunks(16 * 1024)
            .map(|chunk| {
                let mut v = vec![EMPTY_BIN; 3 * bins];
                one(chunk, &mut v);
                v
            })
            .collect();
        for part in parts {
            for (o, b) in out.iter_mut().zip(part) {
                o.bounds = o.bounds.union(b.bounds);
                o.count += b.count;
            }
        }
    } else {
        one(refs, out);
    }
}

/// Chooses how to cut a node (binned SAH).
fn choose_split(
    refs: &[PrimRef],
    bounds: &Aabb,
    cb: &Aabb,
    depth: u32,
    opts: &BvhOptions,
    parallel: bool,
    scratch: &mut Vec<Bin>,
) -> Split {
    let n = refs.len();
    if n <= 1 {
        return Split::Leaf;
    }
    let ext = cb.extent();
    if ext.max_element() <= 0.0 || !ext.is_finite() {
        // All centroids coincide: no plane separates them.
        return if n as u32 <= opts.max_leaf {
            Split::Leaf
        } else {
            Split::Median {
                axis: cb.longest_axis(),
            }
        };
    }
    if depth >= MEDIAN_DEPTH {
        return Split::Median {
            axis: cb.longest_axis(),
        };
    }
    // Small nodes need fewer bins.
    let bins = opts.bins.min((n / 2).max(4));
    scratch.resize(3 * bins, EMPTY_BIN);
    let scale = Vec3::select(
        ext.cmpgt(Vec3::ZERO),
        Vec3::splat(bins as f32 * (1.0 - 1e-6)) / ext,
        Vec3::ZERO,
    );
    bin_refs(refs, cb, scale, bins, parallel, &mut scratch[..3 * bins]);
    let binned = scratch[..3 * bins].chunks(bins);
    // Sweep each axis: SAH cost of splitting after bin i (Wald 2007, eq. 1).
    let mut best = (f32::INFINITY, 0usize, 0usize);
    let mut right_area = [0.0f32; MAX_BINS];
    let mut right_count = [0u32; MAX_BINS];
    for (axis, row) in binned.enumerate() {
        if ext[axis] <= 0.0 {
            continue;
        }
        let (mut b, mut c) = (Aabb::EMPTY, 0u32);
        for i in (1..bins).rev() {
            b = b.union(row[i].bounds);
            c += row[i].count;
            right_area[i] = b.surface_area();
            right_count[i] = c;
        }
        let (mut b, mut c) = (Aabb::EMPTY, 0u32);
        for i in 0..bins - 1 {
            b = b.union(row[i].bounds);
            c += row[i].count;
            let rc = right_count[i + 1];
            if c == 0 || rc == 0 {
                continue;
            }
            let cost = b.surface_area() * c as f32 + right_area[i + 1] * rc as f32;
            if cost < best.0 {
                best = (cost, axis, i);
            }
        }
    }
    let area = bounds.surface_area();
    if n as u32 <= opts.max_leaf && n as f32 * area <= opts.traversal_cost * area + best.0 {
        return Split::Leaf;
    }
    if !best.0.is_finite() {
        return Split::Median {
            axis: cb.longest_axis(),
        };
    }
    Split::Binned {
        axis: best.1,
        bin: best.2,
        bins,
    }
}

/// Applies a split; returns the size of the left part (always in `1..n`).
fn partition(refs: &mut [PrimRef], split: &Split, cb: &Aabb) -> usize {
    let n = refs.len();
    match *split {
        Split::Leaf => n,
        Split::Median { axis } => {
            let mid = n / 2;
            refs.select_nth_unstable_by(mid, |a, b| {
                a.centroid()[axis].total_cmp(&b.centroid()[axis])
            });
            mid
        }
        Split::Binned { axis, bin, bins } => {
            let ext = cb.extent()[axis];
            let scale = bins as f32 * (1.0 - 1e-6) / ext;
            let lo = cb.min[axis];
            let goes_left = |r: &PrimRef| bin_of(r.centroid()[axis], lo, scale, bins) <= bin;
            // Hoare-style in-place partition.
            let (mut i, mut j) = (0usize, n);
            loop {
                while i < j && goes_left(&refs[i]) {
                    i += 1;
                }
                while i < j && !goes_left(&refs[j - 1]) {
                    j -= 1;
                }
                if i >= j {
                    break;
                }
                refs.swap(i, j - 1);
                i += 1;
                j -= 1;
            }
            if i == 0 || i == n {
                // Cannot happen (both sides of the chosen plane are
                // non-empty), but never build an infinite recursion.
                n / 2
            } else {
                i
            }
        }
    }
}

/// Builds the subtree over `refs` (whose first slot is `base`) and returns
/// its nodes laid out as `[root, padding, sibling pairs...]` (an even
/// number of nodes, every pair at an even index), child indices relative to
/// the returned vector.
fn build_subtree(refs: &mut [PrimRef], base: u32, depth: u32, opts: &BvhOptions) -> Vec<BvhNode> {
    let n = refs.len();
    let mut scratch = Vec::new();
    if n < opts.parallel_threshold {
        let mut out = Vec::with_capacity(2 * n + 2);
        out.push(BvhNode::EMPTY);
        out.push(BvhNode::EMPTY);
        build_serial(refs, base, 0, depth, &mut out, opts, &mut scratch);
        return out;
    }
    let (bounds, cb) = ref_bounds(refs, true);
    let split = choose_split(refs, &bounds, &cb, depth, opts, true, &mut scratch);
    if let Split::Leaf = split {
        return vec![BvhNode::new(&bounds, base, n as u32), BvhNode::EMPTY];
    }
    let mid = partition(refs, &split, &cb);
    let (left, right) = refs.split_at_mut(mid);
    let (ln, rn) = rayon::join(
        || build_subtree(left, base, depth + 1, opts),
        || build_subtree(right, base + mid as u32, depth + 1, opts),
    );
    // Lay out [root, pad, L0, R0, L2.., R2..] and renumber the children:
    // left nodes move by 2, right ones by |L|, both even, so pairs stay at
    // even indices.
    let nl = ln.len();
    let mut out = Vec::with_capacity(nl + rn.len());
    out.push(BvhNode::new(&bounds, 2, 0));
    out.push(BvhNode::EMPTY);
    let remap = |mut node: BvhNode, shift: usize| {
        if !node.is_leaf() {
            node.offset += shift as u32;
        }
        node
    };
    out.push(remap(ln[0], 2));
    out.push(remap(rn[0], nl));
    out.extend(ln[2..].iter().map(|&x| remap(x, 2)));
    out.extend(rn[2..].iter().map(|&x| remap(x, nl)));
    out
}

fn build_serial(
    refs: &mut [PrimRef],
    base: u32,
    index: usize,
    depth: u32,
    out: &mut Vec<BvhNode>,
    opts: &BvhOptions,
    scratch: &mut Vec<Bin>,
) {
    let n = refs.len();
    let (bounds, cb) = ref_bounds(refs, false);
    let split = choose_split(refs, &bounds, &cb, depth, opts, false, scratch);
    if let Split::Leaf = split {
        out[index] = BvhNode::new(&bounds, base, n as u32);
        return;
    }
    let mid = partition(refs, &split, &cb);
    let left = out.len();
    out.push(BvhNode::EMPTY);
    out.push(BvhNode::EMPTY);
    out[index] = BvhNode::new(&bounds, left as u32, 0);
    let (l, r) = refs.split_at_mut(mid);
    build_serial(l, base, left, depth + 1, out, opts, scratch);
    build_serial(
        r,
        base + mid as u32,
        left + 1,
        depth + 1,
        out,
        opts,
        scratch,
    );
}

/// A primitive stored in BVH slot order.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shape {
    Triangle([Vec3; 3]),
    Sphere(Vec3, f32),
}

/// Both roots of a ray-sphere intersection inside `(t_min, t_max)`, with
/// the same arithmetic as [`intersect_sphere`].
fn sphere_roots(ray: &Ray, center: Vec3, radius: f32) -> [Option<f32>; 2] {
    let Some(t0) = intersect_sphere(ray, center, radius) else {
        return [None, None];
    };
    let rest = Ray { t_min: t0, ..*ray };
    [Some(t0), intersect_sphere(&rest, center, radius)]
}

/// The BVH over a [`PreparedScene`]'s triangles and analytic spheres, with
/// the primitives copied into leaf order. [`Hit::prim`] numbers triangles
/// first, then spheres, as [`PreparedScene::surface`] expects.
#[derive(Debug, Clone)]
pub struct SceneBvh {
    bvh: Bvh,
    shapes: Vec<Shape>,
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
        let bounds: Vec<Aabb> = if n >= opts.parallel_threshold {
            scene
                .triangles
                .par_iter()
                .map(|t| Aabb::from_points(tri(t)))
                .collect()
        } else {
            scene
                .triangles
                .iter()
                .map(|t| Aabb::from_points(tri(t)))
                .collect()
        };
        let mut bounds = bounds;
        bounds.extend(scene.spheres.iter().map(|s| Aabb {
            min: s.center - Vec3::splat(s.radius.abs()),
            max: s.center + Vec3::splat(s.radius.abs()),
        }));
        let bvh = Bvh::build_with(&bounds, opts);
        let shape = |&p: &u32| {
            let p = p as usize;
            if p < n {
                Shape::Triangle(tri(&scene.triangles[p]))
            } else {
                let s = &scene.spheres[p - n];
                Shape::Sphere(s.center, s.radius)
            }
        };
        let shapes = if bvh.prim_order.len() >= opts.parallel_threshold {
            bvh.prim_order.par_iter().map(shape).collect()
        } else {
            bvh.prim_order.iter().map(shape).collect()
        };
        Self {
            bvh,
            shapes,
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

    /// Calls `visit(hit)` for every intersection with `t` in
    /// `(ray.t_min, ray.t_max)`, in no particular order (a sphere crossed
    /// twice reports both roots), until `visit` returns true. Returns true
    /// if it did. Shadow rays use it to filter non-casting objects and to
    /// attenuate light through transparent surfaces.
    pub fn visit_hits(&self, ray: &Ray, mut visit: impl FnMut(&Hit) -> bool) -> bool {
        let wr = WatertightRay::new(ray);
        let order = &self.bvh.prim_order;
        self.bvh.traverse_any(ray, |slot| {
            let prim = order[slot];
            match self.shapes[slot] {
                Shape::Triangle([a, b, c]) => wr
                    .intersect(a, b, c)
                    .is_some_and(|(t, u, v)| visit(&Hit { t, prim, u, v })),
                Shape::Sphere(c, r) => sphere_roots(ray, c, r).into_iter().flatten().any(|t| {
                    visit(&Hit {
                        t,
                        prim,
                        u: 0.0,
                        v: 0.0,
                    })
                }),
            }
        })
    }
}

impl Accelerator for SceneBvh {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut wr = WatertightRay::new(ray);
        let mut best = None;
        let order = &self.bvh.prim_order;
        self.bvh.traverse_closest(ray, |slot, t_max| {
            wr.t_max = t_max;
            match self.shapes[slot] {
                Shape::Triangle([a, b, c]) => {
                    let (t, u, v) = wr.intersect(a, b, c)?;
                    best = Some(Hit {
                        t,
                        prim: order[slot],
                        u,
                        v,
                    });
                    Some(t)
                }
                Shape::Sphere(c, r) => {
                    let t = intersect_sphere(&Ray { t_max, ..*ray }, c, r)?;
                    best = Some(Hit {
                        t,
                        prim: order[slot],
                        u: 0.0,
                        v: 0.0,
                    });
                    Some(t)
                }
            }
        });
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let wr = WatertightRay::new(ray);
        self.bvh.traverse_any(ray, |slot| match self.shapes[slot] {
            Shape::Triangle([a, b, c]) => wr.intersect(a, b, c).is_some(),
            Shape::Sphere(c, r) => intersect_sphere(ray, c, r).is_some(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::intersect_triangle;
    use crate::accel::list::ListAccel;
    use crate::prepared::PrepareOptions;
    use crate::sampling::{pixel_rng, sample_uniform_sphere, uniform, uniform2};
    use crate::scene::{Geometry, Material, Mesh, Object, Scene, Transform};

    const BUNNY: &str = "/work/shared/assets/common-3d-test-models/stanford-bunny.obj";

    /// A tiny OBJ reader: `v` and `f` lines only (polygons fanned).
    fn read_obj(path: &str) -> Option<Mesh> {
        let text = std::fs::read_to_string(path).ok()?;
        let mut mesh = Mesh::default();
        for line in text.lines() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let c: Vec<f32> = it.take(3).filter_map(|s| s.parse().ok()).collect();
                    if c.len() == 3 {
                        mesh.positions.push(Vec3::new(c[0], c[1], c[2]));
                    }
                }
                Some("f") => {
                    let nv = mesh.positions.len() as i64;
                    let idx: Vec<u32> = it
                        .filter_map(|s| s.split('/').next()?.parse::<i64>().ok())
                        .map(|i| if i < 0 { nv + i } else { i - 1 } as u32)
                        .collect();
                    for k in 1..idx.len().saturating_sub(1) {
                        mesh.indices.push([idx[0], idx[k], idx[k + 1]]);
                    }
                }
                _ => {}
            }
        }
        Some(mesh)
    }

    fn scene_of(mesh: Mesh, spheres: &[(Vec3, f32)]) -> Scene {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let m = s.add_mesh(mesh);
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            ..Default::default()
        });
        for &(c, r) in spheres {
            s.objects.push(Object {
                geometry: Geometry::Sphere { radius: r },
                transform: Transform {
                    translate: c,
                    ..Default::default()
                },
                ..Default::default()
            });
        }
        s
    }

    /// Random rays: half from random points in the (grown) bounds in
    /// random directions, half aimed at random points of random triangles.
    fn random_rays(ps: &PreparedScene<'_>, count: u32, seed: u64) -> Vec<Ray> {
        let b = ps.bounds;
        let grow = b.extent() * 0.2;
        (0..count)
            .map(|i| {
                let mut rng = pixel_rng(seed, i, 0, 0);
                let o = b.min - grow
                    + (b.extent() + 2.0 * grow)
                        * Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
                if i % 2 == 0 || ps.triangles.is_empty() {
                    Ray::new(o, sample_uniform_sphere(uniform2(&mut rng)))
                } else {
                    let t = ps.triangles[(uniform(&mut rng) * ps.triangles.len() as f32) as usize
                        % ps.triangles.len()];
                    let uv = crate::sampling::sample_uniform_triangle(uniform2(&mut rng));
                    let [a, bb, c] = t.map(|k| ps.positions[k as usize]);
                    let target = a * uv.x + bb * uv.y + c * (1.0 - uv.x - uv.y);
                    Ray::new(o, (target - o) * 0.7)
                }
            })
            .collect()
    }

    fn check_against_oracle(ps: &PreparedScene<'_>, rays: &[Ray]) {
        let list = ListAccel::new(ps);
        let bvh = SceneBvh::new(ps);
        let mismatches: Vec<String> = rays
            .par_iter()
            .filter_map(|r| {
                let a = bvh.intersect(r);
                let b = list.intersect(r);
                let same = match (a, b) {
                    (None, None) => true,
                    // The same primitive gives the bit-identical distance; a tie
                    // on a shared edge may pick either neighbour.
                    (Some(a), Some(b)) if a.prim == b.prim => a.t == b.t,
                    (Some(a), Some(b)) => (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0),
                    _ => false,
                };
                let occ_same = bvh.occluded(r) == b.is_some();
                (!same || !occ_same).then(|| format!("{r:?}: bvh {a:?} list {b:?}"))
            })
            .collect();
        assert!(
            mismatches.is_empty(),
            "{} mismatches, first: {}",
            mismatches.len(),
            mismatches[0]
        );
    }

    #[test]
    fn bunny_closest_and_any_hit_match_brute_force() {
        let Some(mesh) = read_obj(BUNNY) else {
            println!("skipped: {BUNNY} not found");
            return;
        };
        assert!(mesh.indices.len() > 60_000);
        // A patch of the real mesh for the 100k-ray comparison (brute force
        // is O(rays x triangles)), then the whole bunny with fewer rays.
        let mut patch = mesh.clone();
        patch.indices.truncate(2500);
        let s = scene_of(patch, &[]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        check_against_oracle(&ps, &random_rays(&ps, 100_000, 1));
        let s = scene_of(mesh, &[(Vec3::new(0.0, 0.1, 0.0), 0.03)]);
        let ps = PreparedScene::new(
            &s,
            PrepareOptions {
                analytic_spheres: true,
                ..Default::default()
            },
        );
        check_against_oracle(&ps, &random_rays(&ps, 2_000, 2));
    }

    #[test]
    fn random_soup_with_spheres_matches_brute_force() {
        let mut rng = pixel_rng(9, 0, 0, 0);
        let mut mesh = Mesh::default();
        for i in 0..3000u32 {
            let c = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 10.0;
            for _ in 0..3 {
                mesh.positions.push(
                    c + (Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) - 0.5),
                );
            }
            mesh.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let spheres: Vec<(Vec3, f32)> = (0..50)
            .map(|_| {
                (
                    Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 10.0,
                    0.3,
                )
            })
            .collect();
        let s = scene_of(mesh, &spheres);
        let ps = PreparedScene::new(
            &s,
            PrepareOptions {
                analytic_spheres: true,
                ..Default::default()
            },
        );
        check_against_oracle(&ps, &random_rays(&ps, 20_000, 3));
    }

    #[test]
    fn structure_invariants_and_thread_independence() {
        let mut rng = pixel_rng(4, 0, 0, 0);
        let boxes: Vec<Aabb> = (0..20_000)
            .map(|_| {
                let c = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 100.0;
                Aabb {
                    min: c,
                    max: c + Vec3::splat(uniform(&mut rng)),
                }
            })
            .collect();
        let opts = BvhOptions {
            parallel_threshold: 1000,
            ..Default::default()
        };
        let a = Bvh::build_with(&boxes, &opts);
        let serial = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let b = serial.install(|| Bvh::build_with(&boxes, &opts));
        assert!(a.nodes().eq(b.nodes()));
        assert_eq!(a.prim_order, b.prim_order);
        // Every prim appears once; every leaf box contains its prims; every
        // parent box contains its children; leaves are small.
        let mut seen = vec![false; boxes.len()];
        for &p in a.prim_order() {
            assert!(!seen[p as usize]);
            seen[p as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        for n in a.nodes() {
            let nb = n.bounds();
            if n.is_leaf() {
                assert!(n.count <= opts.max_leaf);
                for s in n.offset..n.offset + n.count {
                    let pb = boxes[a.prim_order()[s as usize] as usize];
                    assert_eq!(nb.union(pb), nb);
                }
            } else {
                for c in [n.offset, n.offset + 1] {
                    let cb = a.node(c as usize).bounds();
                    assert_eq!(nb.union(cb), nb);
                }
            }
        }
        assert!(a.depth() < 40, "depth {}", a.depth());
        assert_eq!(std::mem::size_of::<BvhNode>(), 32);
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(Bvh::build(&[]).nodes().count(), 0);
        let r = Ray::new(Vec3::ZERO, Vec3::X);
        assert!(!Bvh::build(&[]).traverse_any(&r, |_| true));
        // Many identical boxes (coincident centroids) still build and are all found.
        let b = Aabb {
            min: Vec3::splat(1.0),
            max: Vec3::splat(2.0),
        };
        let bvh = Bvh::build(&vec![b; 100]);
        let ray = Ray::new(Vec3::new(0.0, 1.5, 1.5), Vec3::X);
        let mut found = 0;
        bvh.traverse_any(&ray, |_| {
            found += 1;
            false
        });
        assert_eq!(found, 100);
        // Empty and NaN boxes are dropped.
        let bvh = Bvh::build(&[
            Aabb::EMPTY,
            Aabb {
                min: Vec3::NAN,
                max: Vec3::ONE,
            },
            b,
        ]);
        assert_eq!(bvh.prim_order(), &[2]);
    }

    #[test]
    fn rays_leaving_a_surface_do_not_hit_it_again() {
        let mesh =
            read_obj(BUNNY).unwrap_or_else(|| crate::geometry::primitives::uv_sphere(1.0, 64, 32));
        let s = scene_of(mesh, &[(Vec3::new(5.0, 0.0, 0.0), 0.5)]);
        let ps = PreparedScene::new(
            &s,
            PrepareOptions {
                analytic_spheres: true,
                ..Default::default()
            },
        );
        let bvh = SceneBvh::new(&ps);
        let nt = ps.triangles.len() as u32;
        let mut rng = pixel_rng(5, 0, 0, 0);
        for i in 0..20_000u32 {
            let (prim, p, ng) = if i % 4 == 0 {
                let d = sample_uniform_sphere(uniform2(&mut rng));
                (nt, Vec3::new(5.0, 0.0, 0.0) + 0.5 * d, d)
            } else {
                let t = (uniform(&mut rng) * nt as f32) as u32 % nt;
                let uv = crate::sampling::sample_uniform_triangle(uniform2(&mut rng));
                let sh = ps.triangle_surface(t, uv.x, uv.y);
                (t, sh.p, sh.ng)
            };
            // Directions on both sides, down to grazing angles (1e-3 rad).
            let f = crate::geometry::Frame::from_normal(ng);
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
            let o = crate::geometry::offset_ray_origin(p, ng, dir);
            let ray = Ray::new(o, dir);
            if let Some(h) = bvh.intersect(&ray).filter(|h| h.prim == prim) {
                // Only a sphere can be re-entered, and then far away.
                assert!(
                    prim >= nt && side < 0.0 && h.t > 1e-2,
                    "self-hit {h:?} at {i}"
                );
            }
        }
    }

    #[test]
    fn watertight_ray_agrees_with_free_function() {
        let mut rng = pixel_rng(6, 0, 0, 0);
        for _ in 0..1000 {
            let p: Vec<Vec3> = (0..3)
                .map(|_| Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)))
                .collect();
            let r = Ray::new(
                Vec3::new(0.5, 0.5, 3.0),
                sample_uniform_sphere(uniform2(&mut rng)) - Vec3::Z * 2.0,
            );
            assert_eq!(
                WatertightRay::new(&r).intersect(p[0], p[1], p[2]),
                intersect_triangle(&r, p[0], p[1], p[2])
            );
        }
    }
}
