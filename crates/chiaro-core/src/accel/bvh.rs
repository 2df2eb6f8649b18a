//! The bounding volume hierarchy: an 8-wide BVH (BVH8) built top-down with
//! the binned surface-area heuristic, and [`SceneBvh`], the scene-level
//! [`Accelerator`] over a [`PreparedScene`]'s triangles and analytic
//! spheres.
//!
//! Splits (after Wald 2007, "On fast Construction of SAH-based Bounding
//! Volume Hierarchies", and pbrt-v4 `BVHAggregate::buildRecursive`):
//! primitive references are binned by centroid into `bins` buckets on each
//! axis, the split with the least SAH cost `C_trav + (A_l N_l + A_r N_r) / A`
//! is taken (or a leaf when that is cheaper and the node holds at most
//! `max_leaf` primitives), and the references are partitioned in place by a
//! branch-free block partition (Edelkamp and Weiss 2016) that also gathers
//! each side's centroid bounds, so
//! the final reference order is the leaf order and primitives can be stored
//! in it for locality. Each level costs O(n), the tree has O(log n) levels:
//! O(n log n).
//!
//! Wide nodes (Wald, Benthin and Boulos 2008, "Getting Rid of Packets",
//! section 3; Embree's BVH8 builder): each [`WIDTH`]-wide node starts from
//! its two halves and keeps splitting the child with the largest surface
//! area that the SAH would split, until it has `WIDTH` children or only
//! leaves. This is the tree that collapsing the binary tree would give,
//! built without it. Eight children cut the depth to about a third of the
//! binary tree's, so a ray waits on fewer dependent node loads (eight
//! against four: BENCHMARKS.md, "Ray tracing"). Large nodes bin and
//! partition in parallel and build their children with rayon; the result
//! does not depend on the number of threads.
//!
//! Layout: 256-byte [`BvhNode`]s (four cache lines, loaded independently)
//! holding the child boxes in structure-of-arrays form,
//! `bounds[row][lane]`, so one node test is one round of 8-lane AVX
//! operations on x86-64 with AVX (through `safe_arch`'s safe wrappers; the
//! workspace forbids `unsafe`) and two rounds of 4-lane `glam::Vec4`
//! elsewhere, the two bit-identical. The SAH prices a leaf in blocks of [`BLOCK`] = 4 primitives
//! (as Embree's builder does) and every leaf starts at a slot that is a
//! multiple of four, so in a [`SceneBvh`] a leaf of up to four triangles is
//! one 160-byte SoA block, tested four at a time with the same arithmetic
//! as the scalar watertight test.
//!
//! Traversal keeps an explicit stack, tests boxes with the slab method
//! (Kay and Kajiya 1986) using the precomputed inverse direction and the
//! per-ray choice of near and far planes by direction sign (Williams et al.
//! 2005), visits hit children nearest first for closest hits and skips
//! popped ones that lie beyond the current hit, and stops at the first hit
//! for occlusion queries; the nodes and triangle blocks of children pushed
//! on the stack are prefetched, so that a ray's cache misses overlap. Box
//! exits are widened by `1 + 2 gamma(3)`
//! (pbrt-v4 section 6.8.2) so that rounding never culls a primitive the
//! exact test would hit.

use super::pages::HugeArray;
use super::{Accelerator, Hit, WatertightRay, intersect_sphere, sphere_roots};
use crate::geometry::{Aabb, Ray};
use crate::prepared::PreparedScene;
use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Most bins a build may use.
pub const MAX_BINS: usize = 64;
/// Children per node.
pub const WIDTH: usize = 8;
const _: () = assert!(
    WIDTH.is_multiple_of(4),
    "node tests run four lanes at a time"
);
/// Primitives per leaf block: leaves start at multiples of `BLOCK` slots
/// and a [`SceneBvh`] tests a block's triangles together.
pub const BLOCK: usize = 4;
/// Depth from which the build splits at the object median (bounding the
/// depth however the primitives are distributed).
const MEDIAN_DEPTH: u32 = 64;
/// `1 + 2 gamma(3)`, gamma(n) = n eps / (1 - n eps) with eps = 2^-24
/// (pbrt-v4 eq. 6.24 and section 6.8.2).
const EXIT_SLACK: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);
/// [`Bvh::prim_order`] entry of a padding slot (no leaf refers to it).
pub const PAD_SLOT: u32 = u32::MAX;
/// [`BvhNode::count`] of an unused lane.
pub const EMPTY_LANE: u32 = u32::MAX;

/// One [`WIDTH`]-wide node: up to `WIDTH` children, each an inner node or
/// a leaf (a run of primitive slots). `32 * WIDTH` bytes, 64-byte aligned.
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
pub struct BvhNode {
    /// Child boxes, structure of arrays: rows 0-2 hold the lower corners'
    /// x, y, z, rows 3-5 the upper corners', one lane per child. Unused
    /// lanes hold an inverted (empty) box.
    pub bounds: [[f32; WIDTH]; 6],
    /// Per lane: the child node's index for an inner child, the first slot
    /// in [`Bvh::prim_order`] for a leaf.
    pub child: [u32; WIDTH],
    /// Per lane: 0 for an inner child, the primitive count (>= 1) for a
    /// leaf, [`EMPTY_LANE`] for an unused lane.
    pub count: [u32; WIDTH],
}

/// One child of a [`BvhNode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Child {
    /// An inner node, by index.
    Node(u32),
    /// A leaf: `count` primitives from slot `first` on.
    Leaf {
        /// First slot.
        first: u32,
        /// Number of slots (>= 1).
        count: u32,
    },
}

impl BvhNode {
    const EMPTY: BvhNode = BvhNode {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [0; WIDTH],
        count: [EMPTY_LANE; WIDTH],
    };

    fn set_lane(&mut self, lane: usize, b: &Aabb, child: u32, count: u32) {
        for a in 0..3 {
            self.bounds[a][lane] = b.min[a];
            self.bounds[a + 3][lane] = b.max[a];
        }
        self.child[lane] = child;
        self.count[lane] = count;
    }

    /// The used lanes: each child's box and what it is.
    pub fn children(&self) -> impl Iterator<Item = (Aabb, Child)> + '_ {
        (0..WIDTH)
            .filter(|&i| self.count[i] != EMPTY_LANE)
            .map(|i| {
                let b = Aabb {
                    min: Vec3::new(self.bounds[0][i], self.bounds[1][i], self.bounds[2][i]),
                    max: Vec3::new(self.bounds[3][i], self.bounds[4][i], self.bounds[5][i]),
                };
                let c = if self.count[i] == 0 {
                    Child::Node(self.child[i])
                } else {
                    Child::Leaf {
                        first: self.child[i],
                        count: self.count[i],
                    }
                };
                (b, c)
            })
    }

    /// Slab test of all lanes: per lane the entry distance, and the bit
    /// mask of the lanes whose box the ray meets inside `(t_min, t_max)`.
    /// `max`/`min` take their second operand when either is NaN (the SSE
    /// and AVX `max`/`min` instructions), so a NaN product (a zero
    /// direction component with the origin on a slab plane) never narrows
    /// the interval. Unused lanes hold inverted boxes, whose entry always
    /// lies beyond their exit, so they never hit.
    ///
    /// With AVX (the default x86-64-v3 build) all eight lanes are one
    /// round of 256-bit operations; elsewhere two rounds of 4-lane
    /// `glam::Vec4` ([`BvhNode::intersect4`]). Both do the same IEEE
    /// operations per lane, so they agree bit for bit.
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    #[inline(always)]
    fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        use safe_arch::*;
        const _: () = assert!(WIDTH == 8, "the AVX node test is eight lanes wide");
        let b = &self.bounds;
        let slab =
            |row: usize, a: usize| mul_m256(sub_m256(m256::from_array(b[row]), r.org[a]), r.inv[a]);
        let near = max_m256(
            slab(r.near_row[2], 2),
            max_m256(
                slab(r.near_row[1], 1),
                max_m256(slab(r.near_row[0], 0), set_splat_m256(t_min)),
            ),
        );
        let far = min_m256(
            slab(r.far_row[2], 2),
            min_m256(
                slab(r.far_row[1], 1),
                min_m256(slab(r.far_row[0], 0), set_splat_m256(f32::INFINITY)),
            ),
        );
        let far = min_m256(
            mul_m256(far, set_splat_m256(EXIT_SLACK)),
            set_splat_m256(t_max),
        );
        let hit = cmp_op_mask_m256::<{ cmp_op!(LessEqualOrdered) }>(near, far);
        (near.to_array(), move_mask_m256(hit) as u32)
    }

    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    #[inline(always)]
    fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        self.intersect4(&r.org, &r.inv, r, t_min, t_max)
    }

    /// [`BvhNode::intersect`] four lanes at a time with `glam::Vec4` (SSE
    /// on x86), from the ray's origin and inverse direction splat over four
    /// lanes: the portable node test, and the AVX one's test oracle.
    #[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "avx"))))]
    #[inline(always)]
    fn intersect4(
        &self,
        org: &[Vec4; 3],
        inv: &[Vec4; 3],
        r: &RayPre,
        t_min: f32,
        t_max: f32,
    ) -> ([f32; WIDTH], u32) {
        let b = &self.bounds;
        let mut near_all = [0.0f32; WIDTH];
        let mut mask = 0u32;
        for h in 0..WIDTH / 4 {
            let lanes = 4 * h..4 * h + 4;
            let slab =
                |row: usize, a: usize| (Vec4::from_slice(&b[row][lanes.clone()]) - org[a]) * inv[a];
            let near = slab(r.near_row[2], 2)
                .max(slab(r.near_row[1], 1).max(slab(r.near_row[0], 0).max(Vec4::splat(t_min))));
            let far = slab(r.far_row[2], 2)
                .min(slab(r.far_row[1], 1).min(slab(r.far_row[0], 0).min(Vec4::INFINITY)));
            let far = (far * EXIT_SLACK).min(Vec4::splat(t_max));
            mask |= near.cmple(far).bitmask() << (4 * h);
            near.write_to_slice(&mut near_all[lanes]);
        }
        (near_all, mask)
    }
}

/// A ray constant splat over the node test's lanes.
#[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
type Splat = safe_arch::m256;
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
type Splat = Vec4;

#[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
#[inline(always)]
fn splat(v: f32) -> Splat {
    safe_arch::set_splat_m256(v)
}
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
#[inline(always)]
fn splat(v: f32) -> Splat {
    Vec4::splat(v)
}

/// Per-ray constants of the slab test. [`SceneBvh`] builds it once per
/// ray and derives the triangle test's [`WatertightRay`] from the same
/// reciprocal direction ([`WatertightRay::with_inverse`]).
struct RayPre {
    /// Origin and inverse direction, each component splat over the node
    /// test's lanes.
    org: [Splat; 3],
    inv: [Splat; 3],
    /// Row of [`BvhNode::bounds`] holding the entry plane on each axis (the
    /// lower corner for a positive direction component).
    near_row: [usize; 3],
    far_row: [usize; 3],
    /// `1 / ray.dir`, per component (one vector division).
    recip: Vec3,
}

impl RayPre {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        // `Vec3A` divides all three components in one instruction; each
        // lane is the same IEEE division as `1.0 / ray.dir.x` etc.
        let recip = Vec3::from(Vec3A::from(ray.dir).recip());
        let inv = recip.to_array();
        let neg = inv.map(|v| v.is_sign_negative() as usize);
        let o = ray.origin.to_array();
        Self {
            org: o.map(splat),
            inv: inv.map(splat),
            near_row: [3 * neg[0], 1 + 3 * neg[1], 2 + 3 * neg[2]],
            far_row: [3 - 3 * neg[0], 4 - 3 * neg[1], 5 - 3 * neg[2]],
            recip,
        }
    }
}

/// Starts loading a child pushed on the traversal stack into the cache:
/// the four cache lines of an inner child's node (`count` 0), or, through
/// `leaf`, a leaf's primitives (`leaf(first)`). A pushed child is popped
/// after its nearer sibling's subtree, by when its data has arrived, so an
/// incoherent ray waits on several misses at once rather than one after
/// another. A hint only; nothing else changes.
#[inline(always)]
fn prefetch(nodes: &[BvhNode], child: u32, count: u32, leaf: &impl Fn(u32)) {
    if count != 0 {
        leaf(child);
        return;
    }
    #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
    if let Some(n) = nodes.get(child as usize) {
        safe_arch::prefetch_t0(&n.bounds[0]);
        safe_arch::prefetch_t0(&n.bounds[2]);
        safe_arch::prefetch_t0(&n.bounds[4]);
        safe_arch::prefetch_t0(&n.child);
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
    let _ = nodes;
}

/// A deferred child on the traversal stack.
#[derive(Debug, Clone, Copy, Default)]
struct Entry {
    child: u32,
    count: u32,
    near: f32,
}

/// Entries kept in the first fixed part of the stack, cleared for every
/// ray: a ray through a small scene seldom holds more, and clearing a
/// larger array would cost more than such a ray's traversal.
const STACK_FIRST: usize = 8;
/// Entries in the second fixed part, set up only when a ray first needs
/// it. Ordered traversal with pop-culling rarely holds more than a dozen
/// or two; deeper trees spill into a `Vec`.
const STACK_MORE: usize = 24;

/// The traversal stack: two fixed arrays, the second made only when the
/// first is full (an `Option`, whose `None` is one tag store), then a
/// `Vec` (never allocated for ordinary trees), so that no tree is too deep.
struct Stack {
    first: [Entry; STACK_FIRST],
    more: Option<[Entry; STACK_MORE]>,
    len: usize,
    spill: Vec<Entry>,
}

impl Stack {
    #[inline(always)]
    fn new() -> Self {
        Self {
            first: [Entry::default(); STACK_FIRST],
            more: None,
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    fn push(&mut self, e: Entry) {
        if self.len < STACK_FIRST {
            self.first[self.len] = e;
            self.len += 1;
        } else {
            self.push_more(e);
        }
    }

    /// [`Stack::push`] past the first part (out of line: the traversal
    /// loop keeps only the common case).
    #[inline(never)]
    fn push_more(&mut self, e: Entry) {
        if self.len < STACK_FIRST + STACK_MORE {
            let more = self.more.get_or_insert([Entry::default(); STACK_MORE]);
            more[self.len - STACK_FIRST] = e;
            self.len += 1;
        } else {
            self.spill.push(e);
        }
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<Entry> {
        // (The spill holds entries only when both fixed parts are full.)
        if self.len > STACK_FIRST {
            self.pop_more()
        } else if self.len > 0 {
            self.len -= 1;
            Some(self.first[self.len])
        } else {
            None
        }
    }

    /// [`Stack::pop`] past the first part.
    #[inline(never)]
    fn pop_more(&mut self) -> Option<Entry> {
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len -= 1;
        self.more.as_ref().map(|m| m[self.len - STACK_FIRST])
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
    /// BVHs over fewer primitives than this also consider splitting nodes
    /// of at most one block, pricing that split's traversal at one lane of
    /// a wide node (`traversal_cost / WIDTH`) since it seldom adds a node:
    /// a block of large overlapping primitives (the walls of a room, whose
    /// box is the whole room, met by every ray inside it) is then cut into
    /// tighter leaves. Larger BVHs skip it: it lengthens their build and
    /// does not speed up their rays, while a small scene's build is cheap
    /// and its rays many (BENCHMARKS.md, "Ray tracing").
    pub fine_leaves_below: usize,
}

/// The clamped options of one build, and what follows from its size.
#[derive(Debug, Clone, Copy)]
struct Build {
    opts: BvhOptions,
    /// Split one-block nodes where it pays ([`BvhOptions::fine_leaves_below`]).
    fine: bool,
}

impl std::ops::Deref for Build {
    type Target = BvhOptions;

    fn deref(&self) -> &BvhOptions {
        &self.opts
    }
}

impl Default for BvhOptions {
    fn default() -> Self {
        Self {
            bins: 16,
            max_leaf: 4,
            traversal_cost: 1.0,
            parallel_threshold: 8192,
            fine_leaves_below: 1 << 16,
        }
    }
}

/// A primitive reference during the build: 32 bytes, two aligned SIMD
/// vectors (the primitive's index rides in the lower corner's fourth lane,
/// as in Embree's `PrimRef`), so binning and partitioning load each
/// reference with two aligned loads.
#[derive(Debug, Clone, Copy)]
struct PrimRef {
    /// Lower corner in x, y, z; the index's bits in w.
    lo: Vec4,
    /// Upper corner.
    hi: Vec3A,
}

impl PrimRef {
    #[inline(always)]
    fn new(b: &Aabb, index: u32) -> Self {
        Self {
            lo: b.min.extend(f32::from_bits(index)),
            hi: b.max.into(),
        }
    }

    #[inline(always)]
    fn min(&self) -> Vec3A {
        Vec3A::from_vec4(self.lo)
    }

    #[inline(always)]
    fn max(&self) -> Vec3A {
        self.hi
    }

    #[inline(always)]
    fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }

    fn aabb(&self) -> Aabb {
        Aabb {
            min: self.min().into(),
            max: self.max().into(),
        }
    }

    #[inline(always)]
    fn centroid(&self) -> Vec3A {
        (self.min() + self.max()) * 0.5
    }
}

/// A [`WIDTH`]-wide BVH over primitive boxes. It knows nothing about the
/// primitives themselves: queries call back with *slots*, positions in
/// [`Bvh::prim_order`], which maps each slot to the index of the box given
/// to [`Bvh::build`].
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    /// The root is node 0.
    nodes: HugeArray<BvhNode>,
    prim_order: Vec<u32>,
    bounds: Aabb,
}

/// One SAH bin: the box of its references (SIMD corners) and their count.
/// The children's centroid bounds are gathered by [`partition`], which
/// computes every centroid anyway, rather than per bin on every axis.
#[derive(Debug, Clone, Copy)]
struct Bin {
    min: Vec3A,
    max: Vec3A,
    count: u32,
}

impl Bin {
    #[inline(always)]
    fn bounds(&self) -> Aabb {
        Aabb {
            min: self.min.into(),
            max: self.max.into(),
        }
    }
}

const EMPTY_BIN: Bin = Bin {
    min: Vec3A::INFINITY,
    max: Vec3A::NEG_INFINITY,
    count: 0,
};

/// The bins of one node, axis-major; a node with `bins` bins uses the first
/// `bins` of each row. Fixed rows of [`MAX_BINS`] let the binning loop
/// index by a masked bin number with no bounds check. Rows 0-2 hold the
/// result; rows 3-5 are a second set that [`bin_refs`] fills with every
/// other reference of a large node and then adds into the first.
type Bins = [[Bin; MAX_BINS]; 6];

/// A fresh set of bins, on the heap (18 KiB).
fn new_bins() -> Box<Bins> {
    Box::new([[EMPTY_BIN; MAX_BINS]; 6])
}

/// Nodes from this many references bin into two sets ([`Bins`]).
const TWO_SETS: usize = 512;

/// Bounds of the two sides of a binned split: bins `0..=bin` of `axis`
/// and the rest. Exact unions, so they equal what [`ref_bounds`] would
/// compute over each side's references.
fn split_bounds(binned: &Bins, axis: usize, bin: usize, bins: usize) -> [Aabb; 2] {
    let row = &binned[axis][..bins];
    let side = |r: &[Bin]| {
        r.iter()
            .fold(EMPTY_BIN, |a, b| Bin {
                min: a.min.min(b.min),
                max: a.max.max(b.max),
                count: 0,
            })
            .bounds()
    };
    [side(&row[..=bin]), side(&row[bin + 1..])]
}

/// How to cut a node's references.
#[derive(Debug, Clone, Copy)]
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
        Self::build_boxes(bounds.len(), |i| bounds[i], opts)
    }

    /// [`Bvh::build_with`] over `count` boxes given by `box_of(index)`, so
    /// that a caller computing them need not store them first.
    pub fn build_boxes(
        count: usize,
        box_of: impl Fn(usize) -> Aabb + Sync,
        opts: &BvhOptions,
    ) -> Self {
        let opts = BvhOptions {
            bins: opts.bins.clamp(2, MAX_BINS),
            max_leaf: opts.max_leaf.clamp(1, 255),
            traversal_cost: if opts.traversal_cost.is_finite() {
                opts.traversal_cost.max(0.0)
            } else {
                1.0
            },
            parallel_threshold: opts.parallel_threshold.max(2),
            fine_leaves_below: opts.fine_leaves_below,
        };
        let opts = Build {
            opts,
            fine: count < opts.fine_leaves_below,
        };
        let usable = |b: &Aabb| !b.is_empty() && b.min.is_finite() && b.max.is_finite();
        let mut refs: Vec<PrimRef> = if count >= opts.parallel_threshold {
            // An indexed `map` collects straight into place (`filter_map`
            // would gather pieces and copy them); the rare unusable box is
            // flagged and dropped afterwards, keeping the order.
            let unusable = AtomicBool::new(false);
            let mut refs: Vec<PrimRef> = (0..count)
                .into_par_iter()
                .map(|i| {
                    let b = box_of(i);
                    if !usable(&b) {
                        unusable.store(true, Ordering::Relaxed);
                    }
                    PrimRef::new(&b, i as u32)
                })
                .collect();
            if unusable.into_inner() {
                refs.retain(|r| usable(&r.aabb()));
            }
            refs
        } else {
            (0..count)
                .filter_map(|i| {
                    let b = box_of(i);
                    usable(&b).then_some(PrimRef::new(&b, i as u32))
                })
                .collect()
        };
        if refs.is_empty() {
            return Self::default();
        }
        let mut scratch = new_bins();
        let root = Item::plan(&refs, None, 0, &opts, &mut scratch);
        let bounds = root.bounds;
        let (nodes, prim_order) = build_tree(&mut refs, root, &opts).flatten();
        Self {
            nodes,
            prim_order,
            bounds,
        }
    }

    /// Number of nodes (0 for an empty BVH).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Node `i` (the root is node 0).
    ///
    /// # Panics
    /// If `i >= self.node_count()`.
    #[inline(always)]
    pub fn node(&self, i: usize) -> &BvhNode {
        &self.nodes[i]
    }

    /// Every node, in storage order (the root first).
    pub fn nodes(&self) -> impl Iterator<Item = &BvhNode> + '_ {
        self.nodes.iter()
    }

    /// For each slot, the index of its primitive in the `bounds` given to
    /// the build, or [`PAD_SLOT`] for the padding that starts every leaf at
    /// a multiple of [`BLOCK`]. Leaves refer to contiguous runs of slots.
    pub fn prim_order(&self) -> &[u32] {
        &self.prim_order
    }

    /// Bounds of everything (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        if self.nodes.is_empty() {
            Aabb::EMPTY
        } else {
            self.bounds
        }
    }

    /// Depth of the tree in [`WIDTH`]-wide nodes, leaves counted as a level (a
    /// single leaf under the root has depth 2; 0 when empty).
    pub fn depth(&self) -> usize {
        fn rec(b: &Bvh, i: usize) -> usize {
            1 + b.nodes[i]
                .children()
                .map(|(_, c)| match c {
                    Child::Node(k) => rec(b, k as usize),
                    Child::Leaf { .. } => 1,
                })
                .max()
                .unwrap_or(0)
        }
        if self.nodes.is_empty() {
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
        self.traverse_closest_leaves(ray, |first, count, mut t_max| {
            let mut hit = None;
            for slot in first..first + count {
                if let Some(t) = test(slot, t_max) {
                    t_max = t;
                    hit = Some(t);
                }
            }
            hit
        })
    }

    /// [`Bvh::traverse_closest`] a leaf at a time: `test(first, count,
    /// t_max)` intersects the primitives in slots `first..first + count`
    /// and returns the nearest hit distance inside `(ray.t_min, t_max)`.
    #[inline]
    pub fn traverse_closest_leaves(
        &self,
        ray: &Ray,
        test: impl FnMut(usize, usize, f32) -> Option<f32>,
    ) -> f32 {
        self.traverse_closest_pre(ray, &RayPre::new(ray), |_| {}, test)
    }

    /// [`Bvh::traverse_closest_leaves`] with the ray's slab constants
    /// already computed (`pre` is `RayPre::new(ray)`); `leaf(first)` is
    /// called for each leaf pushed on the stack, to prefetch its data.
    #[inline(always)]
    fn traverse_closest_pre(
        &self,
        ray: &Ray,
        pre: &RayPre,
        leaf: impl Fn(u32),
        mut test: impl FnMut(usize, usize, f32) -> Option<f32>,
    ) -> f32 {
        let mut t_max = ray.t_max;
        if self.nodes.is_empty() {
            return t_max;
        }
        // One look-up of the (possibly mapped) node array per ray.
        let nodes: &[BvhNode] = &self.nodes;
        let t_min = ray.t_min;
        let mut stack = Stack::new();
        let (mut child, mut count) = (0u32, 0u32);
        loop {
            if count == 0 {
                let n = &nodes[child as usize];
                let (near, mask) = n.intersect(pre, t_min, t_max);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        // One child: descend.
                        (child, count) = (n.child[first], n.count[first]);
                        continue;
                    }
                    let second = rest.trailing_zeros() as usize;
                    if rest & (rest - 1) == 0 {
                        // Two (the common case): push the farther, descend
                        // into the nearer (the later lane on a tie, as the
                        // sort below orders them).
                        let (far, near_lane) = if near[first] < near[second] {
                            (second, first)
                        } else {
                            (first, second)
                        };
                        prefetch(nodes, n.child[far], n.count[far], &leaf);
                        stack.push(Entry {
                            child: n.child[far],
                            count: n.count[far],
                            near: near[far],
                        });
                        (child, count) = (n.child[near_lane], n.count[near_lane]);
                        continue;
                    }
                    // Several: push all but the nearest, farthest deepest
                    // (insertion sort of at most `WIDTH`).
                    let mut hits = [Entry::default(); WIDTH];
                    let mut k = 0usize;
                    let mut m = mask;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let e = Entry {
                            child: n.child[i],
                            count: n.count[i],
                            near: near[i],
                        };
                        let mut j = k;
                        while j > 0 && hits[j - 1].near < e.near {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = e;
                        k += 1;
                    }
                    for e in &hits[..k - 1] {
                        prefetch(nodes, e.child, e.count, &leaf);
                        stack.push(*e);
                    }
                    (child, count) = (hits[k - 1].child, hits[k - 1].count);
                    continue;
                }
            } else if let Some(t) = test(child as usize, count as usize, t_max) {
                t_max = t;
            }
            // Pop the next child whose box still starts before the hit.
            loop {
                let Some(e) = stack.pop() else {
                    return t_max;
                };
                if e.near <= t_max {
                    (child, count) = (e.child, e.count);
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
        self.traverse_any_leaves(ray, |first, count| (first..first + count).any(&mut test))
    }

    /// [`Bvh::traverse_any`] a leaf at a time: `test(first, count)` gets
    /// the slots `first..first + count` of a leaf the ray crosses.
    #[inline]
    pub fn traverse_any_leaves(&self, ray: &Ray, test: impl FnMut(usize, usize) -> bool) -> bool {
        self.traverse_any_pre(ray, &RayPre::new(ray), |_| {}, test)
    }

    /// [`Bvh::traverse_any_leaves`] with the ray's slab constants already
    /// computed (`pre` is `RayPre::new(ray)`); `leaf` as in
    /// [`Bvh::traverse_closest_pre`].
    #[inline(always)]
    fn traverse_any_pre(
        &self,
        ray: &Ray,
        pre: &RayPre,
        leaf: impl Fn(u32),
        mut test: impl FnMut(usize, usize) -> bool,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        // One look-up of the (possibly mapped) node array per ray.
        let nodes: &[BvhNode] = &self.nodes;
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        let mut stack = Stack::new();
        let (mut child, mut count) = (0u32, 0u32);
        loop {
            if count == 0 {
                let n = &nodes[child as usize];
                let (_, mut mask) = n.intersect(pre, t_min, t_max);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        prefetch(nodes, n.child[i], n.count[i], &leaf);
                        stack.push(Entry {
                            child: n.child[i],
                            count: n.count[i],
                            near: 0.0,
                        });
                    }
                    (child, count) = (n.child[first], n.count[first]);
                    continue;
                }
            } else if test(child as usize, count as usize) {
                return true;
            }
            let Some(e) = stack.pop() else {
                return false;
            };
            (child, count) = (e.child, e.count);
        }
    }
}

/// Bounds of the references and of their centroids.
fn ref_bounds(refs: &[PrimRef], parallel: bool) -> (Aabb, Aabb) {
    let one = |refs: &[PrimRef]| {
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let (mut clo, mut chi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for r in refs {
            lo = lo.min(r.min());
            hi = hi.max(r.max());
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

/// Bins the references' centroids and boxes into the first `bins` bins of
/// each of `out`'s three axis rows.
fn bin_refs(refs: &[PrimRef], cb: &Aabb, scale: Vec3, bins: usize, parallel: bool, out: &mut Bins) {
    let (lo, scale) = (Vec3A::from(cb.min), Vec3A::from(scale));
    let last = Vec3A::splat((bins - 1) as f32);
    let add = |r: &PrimRef, rows: &mut [[Bin; MAX_BINS]]| {
        let (mn, mx) = (r.min(), r.max());
        // Three axes at once: `floor(clamp((c - lo) * scale, 0, bins -
        // 1))` (the partition's `Plane` compares the same product).
        let c = (mn + mx) * 0.5;
        let k = ((c - lo) * scale).max(Vec3A::ZERO).min(last);
        for (row, k) in rows.iter_mut().zip(bin_numbers(k)) {
            // `k < bins <= MAX_BINS`: the mask only spares the bounds check.
            let b = &mut row[k & (MAX_BINS - 1)];
            b.min = b.min.min(mn);
            b.max = b.max.max(mx);
            b.count += 1;
        }
    };
    let one = |refs: &[PrimRef], out: &mut Bins| {
        let (first, second) = out.split_at_mut(3);
        for row in first.iter_mut() {
            row[..bins].fill(EMPTY_BIN);
        }
        if refs.len() < TWO_SETS {
            for r in refs {
                add(r, first);
            }
            return;
        }
        // Neighbouring references mostly fall in the same bins, so with
        // one set each update waits for the previous one's store; two
        // sets, taking every other reference, halve that chain.
        for row in second.iter_mut() {
            row[..bins].fill(EMPTY_BIN);
        }
        let mut pairs = refs.chunks_exact(2);
        for p in &mut pairs {
            add(&p[0], first);
            add(&p[1], second);
        }
        for r in pairs.remainder() {
            add(r, first);
        }
        for (orow, prow) in first.iter_mut().zip(second.iter()) {
            merge_bins(&mut orow[..bins], &prow[..bins]);
        }
    };
    if parallel {
        for row in out[..3].iter_mut() {
            row[..bins].fill(EMPTY_BIN);
        }
        let parts: Vec<Box<Bins>> = refs
            .par_chunks(16 * 1024)
            .map(|chunk| {
                let mut v = new_bins();
                one(chunk, &mut v);
                v
            })
            .collect();
        for part in parts {
            for (orow, prow) in out.iter_mut().zip(part.iter()).take(3) {
                merge_bins(&mut orow[..bins], &prow[..bins]);
            }
        }
    } else {
        one(refs, out);
    }
}

/// `floor(k)` per axis for the small non-negative `k` of [`bin_refs`].
#[inline(always)]
fn bin_numbers(k: Vec3A) -> [usize; 3] {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    {
        // One truncating conversion of all lanes (exact floor for k >= 0).
        let i: [i32; 4] = safe_arch::truncate_m128_to_m128i(safe_arch::m128(k.into())).into();
        [i[0] as usize, i[1] as usize, i[2] as usize]
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    {
        // Small non-negative integers as floats: adding 2^23 puts the
        // integer in the low mantissa bits.
        let k = (k.floor() + Vec3A::splat(8_388_608.0)).to_array();
        k.map(|k| (k.to_bits() & 0x7f_ffff) as usize)
    }
}

/// Adds the bins `from` into `to`, bin by bin.
fn merge_bins(to: &mut [Bin], from: &[Bin]) {
    for (o, b) in to.iter_mut().zip(from) {
        o.min = o.min.min(b.min);
        o.max = o.max.max(b.max);
        o.count += b.count;
    }
}

/// Chooses how to cut a node (binned SAH).
fn choose_split(
    refs: &[PrimRef],
    bounds: &Aabb,
    cb: &Aabb,
    depth: u32,
    opts: &Build,
    parallel: bool,
    scratch: &mut Bins,
) -> Split {
    let n = refs.len();
    // Without fine leaves, at most one block of primitives passes the leaf
    // test below whenever a traversal step costs at least a block test (the
    // leaf costs `area`, any split `traversal_cost * area` plus two
    // non-negative child costs), so skip the binning.
    if n <= 1
        || (!opts.fine && n as u32 <= opts.max_leaf.min(BLOCK as u32) && opts.traversal_cost >= 1.0)
    {
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
    let scale = Vec3::select(
        ext.cmpgt(Vec3::ZERO),
        Vec3::splat(bins as f32 * (1.0 - 1e-6)) / ext,
        Vec3::ZERO,
    );
    bin_refs(refs, cb, scale, bins, parallel, scratch);
    let binned = scratch[..3].iter().map(|row| &row[..bins]);
    // Sweep each axis: SAH cost of splitting after bin i (Wald 2007, eq. 1).
    let mut best = (f32::INFINITY, 0usize, 0usize);
    let mut right_area = [0.0f32; MAX_BINS];
    let mut right_count = [0u32; MAX_BINS];
    for (axis, row) in binned.enumerate() {
        if ext[axis] <= 0.0 {
            continue;
        }
        // Boxes as SIMD corners: an empty bin's inverted box leaves min/max
        // unchanged, and a side that holds references has a box that is not
        // empty, whose area equals `Aabb::surface_area`.
        let (mut lo, mut hi, mut c) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY, 0u32);
        for i in (1..bins).rev() {
            lo = lo.min(row[i].min);
            hi = hi.max(row[i].max);
            c += row[i].count;
            right_area[i] = box_area(lo, hi);
            right_count[i] = c;
        }
        let (mut lo, mut hi, mut c) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY, 0u32);
        for i in 0..bins - 1 {
            lo = lo.min(row[i].min);
            hi = hi.max(row[i].max);
            c += row[i].count;
            // A side with no references has an inverted box of infinite
            // area and no blocks: its cost is NaN, which never compares
            // below `best`.
            let rc = right_count[i + 1];
            let cost = box_area(lo, hi) * blocks(c) + right_area[i + 1] * blocks(rc);
            if cost < best.0 {
                best = (cost, axis, i);
            }
        }
    }
    let area = bounds.surface_area();
    // With fine leaves, cutting one block in two is priced at one lane's
    // traversal share (`BvhOptions::fine_leaves_below`).
    let trav = if n <= BLOCK && opts.fine {
        opts.traversal_cost / WIDTH as f32
    } else {
        opts.traversal_cost
    };
    if n as u32 <= opts.max_leaf && blocks(n as u32) * area <= trav * area + best.0 {
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

/// Surface area of the non-empty box `[lo, hi]`, as `Aabb::surface_area`.
#[inline(always)]
fn box_area(lo: Vec3A, hi: Vec3A) -> f32 {
    let e = hi - lo;
    2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
}

/// Intersection cost of `n` primitives tested [`BLOCK`] at a time, in
/// block tests (the SAH leaf cost of Embree's `BVHBuilderBinnedSAH`, whose
/// `logBlockSize` rounds counts up to whole blocks).
#[inline(always)]
fn blocks(n: u32) -> f32 {
    n.div_ceil(BLOCK as u32) as f32
}

/// What [`partition`] made: the size of the left part (always in `1..n`)
/// and, for a binned split, the centroid bounds of both parts.
struct Parted {
    mid: usize,
    centroids: Option<[Aabb; 2]>,
}

/// Applies a split.
fn partition(refs: &mut [PrimRef], split: &Split, cb: &Aabb, parallel: bool) -> Parted {
    let n = refs.len();
    match *split {
        Split::Leaf => Parted {
            mid: n,
            centroids: None,
        },
        Split::Median { axis } => {
            let mid = n / 2;
            refs.select_nth_unstable_by(mid, |a, b| {
                a.centroid()[axis].total_cmp(&b.centroid()[axis])
            });
            Parted {
                mid,
                centroids: None,
            }
        }
        Split::Binned { axis, bin, bins } => {
            let ext = cb.extent()[axis];
            let scale = bins as f32 * (1.0 - 1e-6) / ext;
            let lo = cb.min[axis];
            // `bin_refs` puts a centroid in bin
            // `floor(clamp((c - lo) * scale, 0, bins - 1))`, which is at most
            // `bin` (< bins - 1) exactly when `(c - lo) * scale < bin + 1`:
            // the same product compared with a small integer, so binning
            // and partition always agree.
            let plane = Plane {
                lo: Vec3A::splat(lo),
                scale: Vec3A::splat(scale),
                limit: Vec3A::splat((bin + 1) as f32),
            };
            let (i, [l, r]) = match axis {
                0 => partition_by::<0>(refs, &plane, parallel),
                1 => partition_by::<1>(refs, &plane, parallel),
                _ => partition_by::<2>(refs, &plane, parallel),
            };
            if i == 0 || i == n {
                // Cannot happen (both sides of the chosen plane are
                // non-empty), but never build an infinite recursion.
                Parted {
                    mid: n / 2,
                    centroids: None,
                }
            } else {
                Parted {
                    mid: i,
                    centroids: Some([l, r]),
                }
            }
        }
    }
}

/// References below which [`partition_by`] does not split its work.
const PARTITION_GRAIN: usize = 64 * 1024;

/// A binned split plane: a centroid goes left when
/// `(c[axis] - lo) * scale < limit` (each splat over the lanes).
#[derive(Debug, Clone, Copy)]
struct Plane {
    lo: Vec3A,
    scale: Vec3A,
    limit: Vec3A,
}

/// Moves the references whose centroid lies left of `plane` on `AXIS` to
/// the front; returns how many and the centroid bounds of both sides.
///
/// [`partition_blocks`] does the bulk and [`partition_lomuto`] the last
/// hundred or so references; neither has a data-dependent branch. The
/// side test is one vector compare whose mask also selects which side's
/// bounds grow (a reference classified twice grows the same side twice,
/// which changes nothing). Large inputs (`parallel`) split in halves that
/// partition in parallel; the left half's right part and the right half's
/// left part then trade places by swapping the shorter run with the far
/// end of the longer. The halves are fixed by the length, so the result
/// does not depend on the number of threads.
fn partition_by<const AXIS: usize>(
    refs: &mut [PrimRef],
    plane: &Plane,
    parallel: bool,
) -> (usize, [Aabb; 2]) {
    let n = refs.len();
    if parallel && n >= 2 * PARTITION_GRAIN {
        let (a, b) = refs.split_at_mut(n / 2);
        let ((la, [al, ar]), (lb, [bl, br])) = rayon::join(
            || partition_by::<AXIS>(a, plane, true),
            || partition_by::<AXIS>(b, plane, true),
        );
        // [L_a | R_a | L_b | R_b] -> [L_a | L_b | R_a | R_b], up to order
        // within each side.
        let (ra, half) = (n / 2 - la, n / 2);
        let swap = ra.min(lb);
        let (x, y) = refs.split_at_mut(half);
        x[la..la + swap].swap_with_slice(&mut y[lb - swap..lb]);
        return (la + lb, [al.union(bl), ar.union(br)]);
    }
    let mut sides = [
        [Vec3A::INFINITY, Vec3A::NEG_INFINITY],
        [Vec3A::INFINITY, Vec3A::NEG_INFINITY],
    ];
    // The side of one reference (true: left), growing that side's bounds.
    let mut classify = |r: &PrimRef| {
        let c = r.centroid();
        let m = ((Vec3A::splat(c[AXIS]) - plane.lo) * plane.scale).cmplt(plane.limit);
        let [l, r] = sides;
        let (l, r) = grow_sides(m, c, l, r);
        sides = [l, r];
        m.bitmask() & 1 == 1
    };
    let (lo, hi) = partition_blocks(refs, &mut classify);
    let i = lo + partition_lomuto(&mut refs[lo..hi], &mut classify);
    let aabb = |b: [Vec3A; 2]| Aabb {
        min: b[0].into(),
        max: b[1].into(),
    };
    (i, [aabb(sides[0]), aabb(sides[1])])
}

/// Block size of [`partition_blocks`].
const PART_BLOCK: usize = 64;

/// The block partition of Edelkamp and Weiss (2016, "BlockQuicksort:
/// Avoiding Branch Mispredictions in Quicksort", section 3.1): a block of
/// [`PART_BLOCK`] references at each end of the unsorted middle is
/// classified with no data-dependent branch, noting the offsets of the
/// ones on the wrong side, and then as many of those as both blocks have
/// are swapped pairwise. No load reads a reference that a store of the
/// last few iterations wrote, so nothing waits on the store buffer (the
/// single-cursor partition in [`partition_lomuto`] reads back its own
/// stores every iteration). `left(r)` says whether `r` belongs on the left
/// and is called once for each reference outside the returned middle
/// `lo..hi`: everything before `lo` belongs left, everything from `hi` on
/// right, and the middle (fewer than `2 * PART_BLOCK` references, some of
/// them already classified) is left for the caller.
fn partition_blocks(
    refs: &mut [PrimRef],
    left: &mut impl FnMut(&PrimRef) -> bool,
) -> (usize, usize) {
    const B: usize = PART_BLOCK;
    let (mut lo, mut hi) = (0usize, refs.len());
    // Offsets of the misplaced references of the current left block (from
    // `lo`) and right block (back from `hi`), pending from `start_*`.
    let (mut off_l, mut off_r) = ([0u8; B], [0u8; B]);
    let (mut num_l, mut start_l, mut num_r, mut start_r) = (0usize, 0usize, 0usize, 0usize);
    while hi - lo >= 2 * B {
        if num_l == 0 {
            start_l = 0;
            for (j, r) in refs[lo..lo + B].iter().enumerate() {
                off_l[num_l] = j as u8;
                num_l += !left(r) as usize;
            }
        }
        if num_r == 0 {
            start_r = 0;
            for (j, r) in refs[hi - B..hi].iter().rev().enumerate() {
                off_r[num_r] = j as u8;
                num_r += left(r) as usize;
            }
        }
        let m = num_l.min(num_r);
        for (&a, &b) in off_l[start_l..start_l + m]
            .iter()
            .zip(&off_r[start_r..start_r + m])
        {
            let (a, b) = (lo + a as usize, hi - 1 - b as usize);
            let (x, y) = (refs[a], refs[b]);
            refs[a] = y;
            refs[b] = x;
        }
        (num_l, num_r) = (num_l - m, num_r - m);
        (start_l, start_r) = (start_l + m, start_r + m);
        if num_l == 0 {
            lo += B;
        }
        if num_r == 0 {
            hi -= B;
        }
    }
    (lo, hi)
}

/// Branch-free Lomuto partition of `refs` by `left`: `[0, i)` goes left,
/// `[i, k)` right. Every reference is swapped with the first right one
/// whichever side it takes (a right one swaps with a right one), so the
/// loop has no data-dependent branch to mispredict: on shuffled centroids
/// a branching partition mispredicts about half of its tests. Returns `i`.
fn partition_lomuto(refs: &mut [PrimRef], left: &mut impl FnMut(&PrimRef) -> bool) -> usize {
    let mut i = 0usize;
    for k in 0..refs.len() {
        let at_k = refs[k];
        let go_left = left(&at_k);
        // The swap with both references in registers (`slice::swap` goes
        // through a stack temporary); `i <= k`, and for `i == k` both
        // stores write the same reference.
        let at_i = refs[i];
        refs[i] = at_k;
        refs[k] = at_i;
        i += go_left as usize;
    }
    i
}

/// The centroid bounds `[min, max]` of the left and right sides after `c`
/// joins the side `m` selects (all lanes true: left).
///
/// On x86 the centroid is made NaN for the side it does not join, and the
/// bounds grow by `min`/`max` with it as the receiver: SSE's `minps` and
/// `maxps` return their second operand when either is NaN, so that side
/// keeps its bound, and each side costs one select rather than two (the
/// centroids of usable boxes are finite). `Vec3A`'s `min`/`max` on other
/// targets may propagate NaN (NEON does), so there both sides' bounds are
/// selected.
#[inline(always)]
fn grow_sides(m: glam::BVec3A, c: Vec3A, l: [Vec3A; 2], r: [Vec3A; 2]) -> ([Vec3A; 2], [Vec3A; 2]) {
    if cfg!(any(target_arch = "x86", target_arch = "x86_64")) {
        let (cl, cr) = (
            Vec3A::select(m, c, Vec3A::NAN),
            Vec3A::select(m, Vec3A::NAN, c),
        );
        ([cl.min(l[0]), cl.max(l[1])], [cr.min(r[0]), cr.max(r[1])])
    } else {
        (
            [
                Vec3A::select(m, l[0].min(c), l[0]),
                Vec3A::select(m, l[1].max(c), l[1]),
            ],
            [
                Vec3A::select(m, r[0], r[0].min(c)),
                Vec3A::select(m, r[1], r[1].max(c)),
            ],
        )
    }
}

/// A child-to-be of a node under construction: a run of references (from
/// `start` in the slice being built), their bounds and centroid bounds, its
/// depth in the binary tree that the binned splits make, and how it will be
/// cut. The boxes of its two parts are read from the bins when the split is
/// chosen, since the bins are reused by the next choice.
#[derive(Debug, Clone, Copy)]
struct Item {
    start: usize,
    len: usize,
    bounds: Aabb,
    cb: Aabb,
    depth: u32,
    split: Split,
    /// For a binned split: the parts' boxes and the left part's size, as
    /// the bins counted them.
    parts: Option<([Aabb; 2], usize)>,
}

impl Item {
    /// Bounds (unless `known`) and the split of `refs`.
    fn plan(
        refs: &[PrimRef],
        known: Option<(Aabb, Aabb)>,
        depth: u32,
        opts: &Build,
        scratch: &mut Bins,
    ) -> Self {
        let parallel = refs.len() >= opts.parallel_threshold;
        let (bounds, cb) = known.unwrap_or_else(|| ref_bounds(refs, parallel));
        let split = choose_split(refs, &bounds, &cb, depth, opts, parallel, scratch);
        let parts = match split {
            Split::Binned { axis, bin, bins } => Some((
                split_bounds(scratch, axis, bin, bins),
                scratch[axis][..=bin].iter().map(|b| b.count as usize).sum(),
            )),
            _ => None,
        };
        Self {
            start: 0,
            len: refs.len(),
            bounds,
            cb,
            depth,
            split,
            parts,
        }
    }

    fn is_leaf(&self) -> bool {
        matches!(self.split, Split::Leaf)
    }

    /// Cuts this item's references (`refs` is the slice it indexes into)
    /// and plans the two parts.
    fn open(&self, refs: &mut [PrimRef], opts: &Build, scratch: &mut Bins) -> [Item; 2] {
        let mine = &mut refs[self.start..self.start + self.len];
        let parallel = self.len >= opts.parallel_threshold;
        let parted = partition(mine, &self.split, &self.cb, parallel);
        let mid = parted.mid;
        // The bins' boxes are trusted only when their count matches the
        // partition's (they always should).
        let known = match (self.parts, parted.centroids) {
            (Some(([lb, rb], count)), Some([lc, rc])) if count == mid => {
                [Some((lb, lc)), Some((rb, rc))]
            }
            _ => [None, None],
        };
        let (l, r) = mine.split_at_mut(mid);
        let mut left = Item::plan(l, known[0], self.depth + 1, opts, scratch);
        let mut right = Item::plan(r, known[1], self.depth + 1, opts, scratch);
        left.start = self.start;
        right.start = self.start + mid;
        [left, right]
    }
}

/// Builds the [`WIDTH`]-wide tree over `refs` from its planned root
/// (Wald, Benthin and Boulos 2008, section 3; Embree's BVH8 builder): each
/// node starts from its item's two parts and keeps opening the inner part
/// with the largest surface area until it has `WIDTH` children or only
/// leaves. Nodes are laid out depth first, each node's inner children
/// directly after one another. Subtrees of at least
/// `opts.parallel_threshold` references build in parallel into trees of
/// their own, which [`Tree::flatten`] then places.
fn build_tree(refs: &mut [PrimRef], root: Item, opts: &Build) -> Tree {
    let mut out = Tree::new(refs.len());
    let mut scratch = new_bins();
    if root.is_leaf() {
        let first = out.leaf(refs);
        out.nodes[0].set_lane(0, &root.bounds, first, root.len as u32);
    } else {
        fill_node(refs, root, 0, opts, &mut scratch, &mut out);
    }
    out
}

/// A tree (or subtree) being built: its nodes (root first), its slot
/// order, in which every leaf starts at a multiple of [`BLOCK`] so that a
/// leaf of up to four primitives is one block of a [`SceneBvh`] (the gaps
/// hold [`PAD_SLOT`]), and the subtrees built in parallel below it. Leaves
/// are placed as they are made, so the order follows the build's
/// depth-first walk.
struct Tree {
    nodes: Vec<BvhNode>,
    order: Vec<u32>,
    /// Subtrees built on their own (root at 0, indices relative to it),
    /// each with the node of `nodes` reserved for its root. They are placed
    /// once, by [`Tree::flatten`], after this tree's own nodes and slots and
    /// in this order: the layout that appending each level's subtrees as it
    /// finishes would give (a parallel node appends nothing after them),
    /// without copying every node once per parallel level.
    subs: Vec<(usize, Tree)>,
}

/// Where [`Tree::flatten`] puts one tree of the nest: its root node, its
/// other nodes from `node_at` on, its slots from `slot_at` on.
struct Placed<'t> {
    tree: &'t Tree,
    root_at: usize,
    node_at: usize,
    slot_at: usize,
}

impl Placed<'_> {
    /// The final index of this tree's node `j`.
    fn node(&self, j: usize) -> usize {
        if j == 0 {
            self.root_at
        } else {
            self.node_at + j - 1
        }
    }

    /// This tree's node `j` with its children's indices made final.
    fn moved(&self, j: usize) -> BvhNode {
        let mut n = self.tree.nodes[j];
        for lane in 0..WIDTH {
            match n.count[lane] {
                EMPTY_LANE => {}
                0 => n.child[lane] = self.node(n.child[lane] as usize) as u32,
                _ => n.child[lane] += self.slot_at as u32,
            }
        }
        n
    }
}

impl Tree {
    /// A tree for `refs` references: a reserved root node, room for the
    /// usual node count and slot padding.
    fn new(refs: usize) -> Self {
        let mut nodes = Vec::with_capacity(refs / 12 + 1);
        nodes.push(BvhNode::EMPTY);
        Self {
            nodes,
            order: Vec::with_capacity(refs + refs / 2),
            subs: Vec::new(),
        }
    }

    /// Places a leaf of `refs` at the next multiple of [`BLOCK`]; returns
    /// its first slot.
    fn leaf(&mut self, refs: &[PrimRef]) -> u32 {
        let first = self.order.len().next_multiple_of(BLOCK);
        self.order.resize(first, PAD_SLOT);
        self.order.extend(refs.iter().map(|r| r.index()));
        first as u32
    }

    /// The whole nest as one node array (in huge-page-advised memory when
    /// large) and one slot order: each tree's nodes and slots written once,
    /// the trees in parallel, every index moved to its final place.
    fn flatten(&self) -> (HugeArray<BvhNode>, Vec<u32>) {
        // Depth first: a tree, then each of its subtrees followed by theirs.
        fn place<'t>(
            parent: usize,
            placed: &mut Vec<Placed<'t>>,
            nodes: &mut usize,
            slots: &mut usize,
        ) {
            let tree = placed[parent].tree;
            for (reserved, sub) in &tree.subs {
                let slot_at = slots.next_multiple_of(BLOCK);
                placed.push(Placed {
                    tree: sub,
                    root_at: placed[parent].node(*reserved),
                    node_at: *nodes,
                    slot_at,
                });
                *nodes += sub.nodes.len() - 1;
                *slots = slot_at + sub.order.len();
                place(placed.len() - 1, placed, nodes, slots);
            }
        }
        let mut placed = vec![Placed {
            tree: self,
            root_at: 0,
            node_at: 1,
            slot_at: 0,
        }];
        let (mut nodes, mut slots) = (self.nodes.len(), self.order.len());
        place(0, &mut placed, &mut nodes, &mut slots);
        let mut out = HugeArray::<BvhNode>::zeroed(nodes);
        let mut order = vec![PAD_SLOT; slots];
        // Split both outputs into each tree's run (ascending in depth-first
        // order), fill the runs in parallel, then the subtrees' roots (in
        // their parents' reserved nodes).
        let mut node_runs = Vec::with_capacity(placed.len());
        let mut slot_runs = Vec::with_capacity(placed.len());
        let (mut rest_n, mut rest_s): (&mut [BvhNode], &mut [u32]) = (&mut out, &mut order);
        let (mut at_n, mut at_s) = (0, 0);
        for (k, p) in placed.iter().enumerate() {
            let (first, len) = if k == 0 {
                (0, p.tree.nodes.len())
            } else {
                (p.node_at, p.tree.nodes.len() - 1)
            };
            let (run, tail) = std::mem::take(&mut rest_n)[first - at_n..].split_at_mut(len);
            node_runs.push(run);
            (rest_n, at_n) = (tail, first + len);
            let (run, tail) =
                std::mem::take(&mut rest_s)[p.slot_at - at_s..].split_at_mut(p.tree.order.len());
            slot_runs.push(run);
            (rest_s, at_s) = (tail, p.slot_at + p.tree.order.len());
        }
        placed
            .par_iter()
            .zip(node_runs.into_par_iter().zip(slot_runs.into_par_iter()))
            .enumerate()
            .for_each(|(k, (p, (nodes, slots)))| {
                let skip = usize::from(k != 0);
                for (j, n) in nodes.iter_mut().enumerate() {
                    *n = p.moved(j + skip);
                }
                slots.copy_from_slice(&p.tree.order);
            });
        for p in &placed[1..] {
            out[p.root_at] = p.moved(0);
        }
        (out, order)
    }
}

/// Fills the reserved node `out.nodes[slot]` for the inner `item`, whose
/// references are `refs` (item positions are relative to it), and appends
/// its subtree.
fn fill_node(
    refs: &mut [PrimRef],
    item: Item,
    slot: usize,
    opts: &Build,
    scratch: &mut Bins,
    out: &mut Tree,
) {
    // Gather up to `WIDTH` children, opening the largest inner one first;
    // the left part replaces its parent and the right one follows it, so
    // children stay in reference order.
    let [a, b] = item.open(refs, opts, scratch);
    let mut kids = [a; WIDTH];
    kids[1] = b;
    let mut k = 2;
    while k < WIDTH {
        let mut best: Option<(usize, f32)> = None;
        for (j, c) in kids[..k].iter().enumerate() {
            let area = c.bounds.surface_area();
            if !c.is_leaf() && best.is_none_or(|(_, a)| area > a) {
                best = Some((j, area));
            }
        }
        let Some((j, _)) = best else { break };
        let [l, r] = kids[j].open(refs, opts, scratch);
        kids.copy_within(j + 1..k, j + 2);
        kids[j] = l;
        kids[j + 1] = r;
        k += 1;
    }
    let kids = &kids[..k];
    let mut node = BvhNode::EMPTY;
    let mut inner = [0usize; WIDTH];
    let mut ni = 0;
    for (lane, c) in kids.iter().enumerate() {
        if c.is_leaf() {
            let first = out.leaf(&refs[c.start..c.start + c.len]);
            node.set_lane(lane, &c.bounds, first, c.len as u32);
        } else {
            inner[ni] = lane;
            ni += 1;
        }
    }
    let first = out.nodes.len();
    for (m, &lane) in inner[..ni].iter().enumerate() {
        node.set_lane(lane, &kids[lane].bounds, (first + m) as u32, 0);
    }
    out.nodes.resize(first + ni, BvhNode::EMPTY);
    out.nodes[slot] = node;
    // The inner children's disjoint runs of references, in order.
    let mut runs: Vec<(&mut [PrimRef], Item)> = Vec::with_capacity(ni);
    let (mut rest, mut at) = (refs, 0);
    for &lane in &inner[..ni] {
        let c = kids[lane];
        let (mine, tail) = rest[c.start - at..].split_at_mut(c.len);
        rest = tail;
        at = c.start + c.len;
        runs.push((mine, Item { start: 0, ..c }));
    }
    if item.len >= opts.parallel_threshold {
        // Each subtree with the reserved node for its root.
        let subs: Vec<(usize, Tree)> = runs
            .into_par_iter()
            .enumerate()
            .map(|(m, (mine, c))| {
                let mut sub = Tree::new(c.len);
                fill_node(mine, c, 0, opts, &mut new_bins(), &mut sub);
                (first + m, sub)
            })
            .collect();
        out.subs.extend(subs);
    } else {
        for (m, (mine, c)) in runs.into_iter().enumerate() {
            fill_node(mine, c, first + m, opts, scratch, out);
        }
    }
}

/// Four primitives in consecutive BVH slots (`4 k .. 4 k + 4`), triangles
/// in structure-of-arrays form so that [`TriBlock::intersect`] tests all
/// four at once. 160 bytes.
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(32))]
struct TriBlock {
    /// `v[3 * vertex + axis][lane]`; NaN for a sphere or unused lane.
    v: [[f32; BLOCK]; 9],
    /// Per lane the [`Hit::prim`] (a sphere when `>= triangle_count`).
    prim: [u32; BLOCK],
}

/// Per-lane results of [`TriBlock::intersect`].
struct Lanes {
    t: [f32; BLOCK],
    u: [f32; BLOCK],
    v: [f32; BLOCK],
    /// Lanes hit.
    mask: u32,
}

impl TriBlock {
    const EMPTY: TriBlock = TriBlock {
        v: [[f32::NAN; BLOCK]; 9],
        prim: [u32::MAX; BLOCK],
    };

    /// The watertight test of [`WatertightRay::intersect`] on the lanes in
    /// `lanes`, four at a time (`glam::Vec4`, SSE on x86): the same
    /// operations in the same order per lane and no fused multiply-adds, so
    /// `t`, `u`, `v` are bit-identical to the scalar test (the
    /// double-precision edge fallback runs per lane, scalar).
    #[inline(always)]
    fn intersect(&self, wr: &WatertightRay, lanes: u32) -> Lanes {
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
/// block; see [`prefetch`]).
#[inline(always)]
fn prefetch_block(blocks: &[TriBlock], first: u32) {
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
fn block_lanes(b: usize, first: usize, end: usize) -> u32 {
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
    bvh: Bvh,
    /// Slot `s` is lane `s % 4` of block `s / 4`.
    blocks: HugeArray<TriBlock>,
    /// Mask per block of the lanes holding spheres.
    sphere_lanes: Vec<u8>,
    spheres: Vec<(Vec3, f32)>,
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
    fn sphere(&self, prim: u32) -> (Vec3, f32) {
        self.spheres[(prim - self.triangle_count) as usize]
    }

    /// `intersect_sphere` of `ray` (with `t_max`) and sphere `prim`, out of
    /// line: the traversal loops stay free of the sphere test's per-ray
    /// constants, which triangle scenes never use.
    #[cold]
    #[inline(never)]
    fn sphere_hit(&self, ray: &Ray, prim: u32, t_max: f32) -> Option<f32> {
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
/// tracing vs Mitsuba 3", session 8).
#[inline(always)]
fn read_ray(ray: &Ray) -> Ray {
    let bb = std::hint::black_box::<f32>;
    Ray {
        origin: Vec3::new(bb(ray.origin.x), bb(ray.origin.y), bb(ray.origin.z)),
        dir: Vec3::new(bb(ray.dir.x), bb(ray.dir.y), bb(ray.dir.z)),
        t_min: ray.t_min,
        t_max: ray.t_max,
    }
}

impl Accelerator for SceneBvh {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
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

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        self.visit_hits(ray, visit)
    }

    fn occluded(&self, ray: &Ray) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::intersect_triangle;
    use crate::accel::list::ListAccel;
    use crate::prepared::PrepareOptions;
    use crate::sampling::{pixel_rng, sample_uniform_sphere, uniform, uniform2};
    use crate::scene::{Geometry, Material, Mesh, Object, Scene, Transform};

    /// The Stanford bunny from the shared test assets (read in place, not
    /// redistributed), or `None` after a skip message where they are absent.
    fn bunny() -> Option<Mesh> {
        read_obj(&chiaro_testkit::shared_asset(
            "common-3d-test-models/stanford-bunny.obj",
        )?)
    }

    /// A tiny OBJ reader: `v` and `f` lines only (polygons fanned).
    fn read_obj(path: &std::path::Path) -> Option<Mesh> {
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
                // The nearest of all the hits visit_hits reports is the
                // closest hit.
                let mut visit_t: Option<f32> = None;
                bvh.visit_hits(r, |h| {
                    visit_t = Some(visit_t.map_or(h.t, |t| t.min(h.t)));
                    false
                });
                let visit_same = visit_t == b.map(|h| h.t);
                (!same || !occ_same || !visit_same).then(|| format!("{r:?}: bvh {a:?} list {b:?}"))
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
        let Some(mesh) = bunny() else {
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
        for &p in a.prim_order().iter().filter(|&&p| p != PAD_SLOT) {
            assert!(!seen[p as usize]);
            seen[p as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        // Every node but the root is referenced once; child boxes contain
        // their children's boxes and their leaves' prims; leaves cover every
        // slot once.
        let mut referenced = vec![0u32; a.node_count()];
        let mut covered = vec![0u32; a.prim_order().len()];
        for n in a.nodes() {
            for (cb, c) in n.children() {
                match c {
                    Child::Leaf { first, count } => {
                        assert!(count <= opts.max_leaf);
                        assert_eq!(first as usize % BLOCK, 0);
                        for s in first..first + count {
                            covered[s as usize] += 1;
                            let pb = boxes[a.prim_order()[s as usize] as usize];
                            assert_eq!(cb.union(pb), cb);
                        }
                    }
                    Child::Node(k) => {
                        referenced[k as usize] += 1;
                        for (gb, _) in a.node(k as usize).children() {
                            assert_eq!(cb.union(gb), cb);
                        }
                    }
                }
            }
        }
        assert_eq!(referenced[0], 0);
        assert!(referenced[1..].iter().all(|&r| r == 1));
        for (&c, &p) in covered.iter().zip(a.prim_order()) {
            assert_eq!(c, (p != PAD_SLOT) as u32);
        }
        assert!(a.depth() < 25, "depth {}", a.depth());
        assert_eq!(std::mem::size_of::<BvhNode>(), 32 * WIDTH);
    }

    #[test]
    fn partition_side_bounds_ignore_the_other_side() {
        // `grow_sides` relies on x86's min/max keeping the receiver's
        // bound beside a NaN; check the bounds it produces on this target.
        let empty = [Vec3A::INFINITY, Vec3A::NEG_INFINITY];
        let (mut l, mut r) = (empty, empty);
        let pts = [
            (Vec3A::new(1.0, -2.0, 3.0), true),
            (Vec3A::new(-4.0, 5.0, 0.5), false),
            (Vec3A::new(2.0, 0.0, -1.0), true),
            (Vec3A::new(7.0, -3.0, 2.0), false),
        ];
        for (c, left) in pts {
            (l, r) = grow_sides(glam::BVec3A::splat(left), c, l, r);
        }
        assert_eq!(l, [Vec3A::new(1.0, -2.0, -1.0), Vec3A::new(2.0, 0.0, 3.0)]);
        assert_eq!(r, [Vec3A::new(-4.0, -3.0, 0.5), Vec3A::new(7.0, 5.0, 2.0)]);
    }

    /// `partition_by` (block partition plus Lomuto tail) puts exactly the
    /// references left of the plane first, keeps the same multiset, and
    /// returns each side's exact centroid bounds, for sizes around the
    /// block size, all-left and all-right inputs, and sorted and shuffled
    /// orders.
    #[test]
    fn partition_is_exact_at_every_size() {
        let mut rng = pixel_rng(5, 0, 0, 0);
        let sizes = [1, 2, 63, 64, 65, 127, 128, 129, 191, 256, 300, 1000, 4099];
        for (case, &n) in sizes.iter().cycle().take(3 * sizes.len()).enumerate() {
            let mut refs: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let p = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
                    let p = if case % 3 == 1 {
                        p * 0.1 + Vec3::X * (i as f32 / n as f32)
                    } else {
                        p
                    };
                    let b = Aabb {
                        min: p,
                        max: p + Vec3::splat(0.01),
                    };
                    PrimRef::new(&b, i as u32)
                })
                .collect();
            // Limits below, inside and above the centroids' range.
            let limit = [0.5, -1.0, 2.0][case / sizes.len()];
            let plane = Plane {
                lo: Vec3A::ZERO,
                scale: Vec3A::ONE,
                limit: Vec3A::splat(limit),
            };
            let goes_left = |r: &PrimRef| r.centroid().x < limit;
            let mut want: Vec<u32> = refs.iter().map(|r| r.index()).collect();
            let bounds_of = |rs: &[PrimRef]| {
                rs.iter().fold(Aabb::EMPTY, |b, r| {
                    b.union(Aabb::from_points([Vec3::from(r.centroid())]))
                })
            };
            let (want_l, want_r): (Vec<PrimRef>, Vec<PrimRef>) =
                refs.iter().partition(|r| goes_left(r));
            let (i, [l, r]) = partition_by::<0>(&mut refs, &plane, false);
            assert_eq!(i, want_l.len(), "n {n} case {case}");
            assert!(refs[..i].iter().all(goes_left), "n {n} case {case}");
            assert!(!refs[i..].iter().any(goes_left), "n {n} case {case}");
            let mut got: Vec<u32> = refs.iter().map(|r| r.index()).collect();
            got.sort_unstable();
            want.sort_unstable();
            assert_eq!(got, want, "n {n} case {case}: not a permutation");
            for (side, (got, want)) in [(l, &want_l), (r, &want_r)].into_iter().enumerate() {
                let want = bounds_of(want);
                if want.is_empty() {
                    assert!(got.is_empty(), "n {n} case {case} side {side}");
                } else {
                    assert_eq!(
                        (got.min, got.max),
                        (want.min, want.max),
                        "n {n} case {case} side {side}"
                    );
                }
            }
        }
    }

    /// The traversal stack is last in, first out across its three parts
    /// (first array, second array, `Vec`), including after popping back
    /// below a part's start and pushing again.
    #[test]
    fn stack_is_lifo_across_its_parts() {
        let e = |i: u32| Entry {
            child: i,
            count: i % 5,
            near: i as f32 * 0.5,
        };
        let mut s = Stack::new();
        let mut model = Vec::new();
        let mut next = 0u32;
        for round in [3usize, 20, 50, 7, 40] {
            for _ in 0..round {
                s.push(e(next));
                model.push(next);
                next += 1;
            }
            for _ in 0..round / 2 {
                let got = s.pop().map(|x| (x.child, x.count, x.near));
                let want = model.pop().map(|i| (e(i).child, e(i).count, e(i).near));
                assert_eq!(got, want);
            }
        }
        while let Some(i) = model.pop() {
            assert_eq!(s.pop().map(|x| x.child), Some(i));
        }
        assert!(s.pop().is_none());
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
    fn small_nodes_split_when_traversal_is_cheap() {
        // Four small boxes at the corners of a large square: one leaf costs
        // the square's area, a split into single boxes a quarter of it plus
        // four tiny areas when a traversal step costs 0.25 of a block test.
        let boxes: Vec<Aabb> = [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0), (10.0, 10.0)]
            .iter()
            .map(|&(x, y)| Aabb {
                min: Vec3::new(x, y, 0.0),
                max: Vec3::new(x + 0.1, y + 0.1, 0.1),
            })
            .collect();
        let leaves = |b: &Bvh| {
            b.nodes()
                .flat_map(|n| n.children())
                .filter(|(_, c)| matches!(c, Child::Leaf { .. }))
                .count()
        };
        let coarse = BvhOptions {
            fine_leaves_below: 0,
            ..BvhOptions::default()
        };
        assert_eq!(leaves(&Bvh::build_with(&boxes, &coarse)), 1);
        let cheap = Bvh::build_with(
            &boxes,
            &BvhOptions {
                traversal_cost: 0.25,
                ..coarse
            },
        );
        assert!(leaves(&cheap) > 1);
        // Fine leaves (the default for small BVHs) split the block too.
        assert!(leaves(&Bvh::build(&boxes)) > 1);
    }

    #[test]
    fn parallel_and_serial_builds_drop_the_same_unusable_boxes() {
        // Boxes on a line, every seventh empty or NaN; a threshold of 2
        // takes the parallel paths (reference collection, binning,
        // partition, subtrees) everywhere, the default none of them here.
        let boxes: Vec<Aabb> = (0..3000)
            .map(|i| match i % 7 {
                3 => Aabb::EMPTY,
                5 => Aabb {
                    min: Vec3::new(f32::NAN, 0.0, 0.0),
                    max: Vec3::ONE,
                },
                _ => {
                    let p = Vec3::new(
                        i as f32 * 0.37 % 11.0,
                        (i * 13 % 17) as f32,
                        i as f32 * 0.01,
                    );
                    Aabb {
                        min: p,
                        max: p + Vec3::splat(0.25),
                    }
                }
            })
            .collect();
        let serial = Bvh::build(&boxes);
        let parallel = Bvh::build_with(
            &boxes,
            &BvhOptions {
                parallel_threshold: 2,
                ..BvhOptions::default()
            },
        );
        let kept = |b: &Bvh| {
            let mut v: Vec<u32> = b
                .prim_order()
                .iter()
                .copied()
                .filter(|&p| p != PAD_SLOT)
                .collect();
            v.sort_unstable();
            v
        };
        let expected: Vec<u32> = (0..3000).filter(|i| i % 7 != 3 && i % 7 != 5).collect();
        assert_eq!(kept(&serial), expected);
        assert_eq!(kept(&parallel), expected);
        // The same tree either way: the build does not depend on how it is
        // split into tasks.
        assert_eq!(serial.node_count(), parallel.node_count());
        assert_eq!(serial.bounds(), parallel.bounds());
    }

    #[test]
    fn rays_leaving_a_surface_do_not_hit_it_again() {
        let mesh = bunny().unwrap_or_else(|| crate::geometry::primitives::uv_sphere(1.0, 64, 32));
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

    /// The node test used in traversal (eight AVX lanes on x86-64-v3)
    /// and the portable four-lane one give the same entry distances, bit
    /// for bit, and the same hit masks, including the NaN slabs of a ray
    /// parallel to a box face with its origin on the face, and unused
    /// (inverted) lanes.
    #[test]
    fn node_test_matches_the_four_lane_one() {
        let mut rng = pixel_rng(11, 0, 0, 0);
        let mut hits = 0;
        for k in 0..20_000 {
            let mut node = BvhNode::EMPTY;
            let used = k % WIDTH + 1;
            for lane in 0..used {
                let g = |x: f32| (x * 8.0).round() / 8.0;
                let a = Vec3::new(
                    g(uniform(&mut rng)),
                    g(uniform(&mut rng)),
                    g(uniform(&mut rng)),
                );
                let e = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 0.5;
                let b = Aabb { min: a, max: a + e };
                node.set_lane(lane, &b, lane as u32, 0);
            }
            let o = if k % 3 == 0 {
                // On the grid the boxes' corners lie on: slab planes.
                let g = |x: f32| (x * 8.0).round() / 8.0;
                Vec3::new(
                    g(uniform(&mut rng)),
                    g(uniform(&mut rng)),
                    g(uniform(&mut rng)),
                )
            } else {
                Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 3.0 - 1.0
            };
            // Towards a random point among the boxes.
            let aim = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)) * 1.5;
            let mut dir =
                (aim - o).normalize_or(Vec3::X) + sample_uniform_sphere(uniform2(&mut rng)) * 0.1;
            if k % 3 == 0 {
                // Zero components: infinite inverses, NaN products.
                dir[k % 3] = 0.0;
                if k % 2 == 0 {
                    dir[(k + 1) % 3] = -0.0;
                }
            }
            let ray = Ray::new(o, dir);
            let pre = RayPre::new(&ray);
            let org = ray.origin.to_array().map(Vec4::splat);
            let inv = pre.recip.to_array().map(Vec4::splat);
            let t_max = if k % 2 == 0 { f32::INFINITY } else { 1.5 };
            let (near, mask) = node.intersect(&pre, 1e-4, t_max);
            let (near4, mask4) = node.intersect4(&org, &inv, &pre, 1e-4, t_max);
            assert_eq!(mask, mask4, "case {k}");
            assert_eq!(near.map(f32::to_bits), near4.map(f32::to_bits), "case {k}");
            assert_eq!(mask >> used, 0, "case {k}: an unused lane hit");
            hits += mask.count_ones();
        }
        assert!(hits > 2_000, "only {hits} box hits");
    }

    #[test]
    fn four_wide_triangle_test_is_bit_identical_to_scalar() {
        let mut rng = pixel_rng(7, 0, 0, 0);
        let mut edge_cases = 0;
        for k in 0..4000 {
            let mut blk = TriBlock::EMPTY;
            let mut tris = [[Vec3::ZERO; 3]; BLOCK];
            for (lane, t) in tris.iter_mut().enumerate() {
                for p in t.iter_mut() {
                    *p = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
                }
                if k % 2 == 0 {
                    // Axis-aligned grid triangles: rays through vertices and
                    // edges take the double-precision fallback.
                    *t = [Vec3::ZERO, Vec3::X, Vec3::Y].map(|p| p + Vec3::Z * lane as f32 * 0.1);
                }
                for (v, p) in t.iter().enumerate() {
                    for a in 0..3 {
                        blk.v[3 * v + a][lane] = p[a];
                    }
                }
            }
            let o = if k % 2 == 0 {
                let g = |x: f32| (x * 4.0).round() / 4.0;
                Vec3::new(g(uniform(&mut rng)), g(uniform(&mut rng)), 3.0)
            } else {
                Vec3::new(0.5, 0.5, 3.0)
            };
            let dir = if k % 2 == 0 {
                -Vec3::Z
            } else {
                sample_uniform_sphere(uniform2(&mut rng)) - Vec3::Z * 2.0
            };
            let wr = WatertightRay::new(&Ray::new(o, dir));
            let lanes = (k % 15 + 1) as u32;
            let r = blk.intersect(&wr, lanes);
            for (i, t) in tris.iter().enumerate() {
                let want = if lanes >> i & 1 == 1 {
                    wr.intersect(t[0], t[1], t[2])
                } else {
                    None
                };
                let got = (r.mask >> i & 1 == 1).then_some((r.t[i], r.u[i], r.v[i]));
                assert_eq!(got, want, "case {k} lane {i}");
                edge_cases += want.is_some_and(|(_, u, v)| u == 0.0 || v == 0.0) as u32;
            }
        }
        assert!(edge_cases > 10, "only {edge_cases} edge hits");
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
