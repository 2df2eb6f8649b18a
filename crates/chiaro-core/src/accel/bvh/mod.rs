//! The bounding volume hierarchy: an 8-wide BVH (BVH8) built top-down with
//! the binned surface-area heuristic, and [`SceneBvh`], the scene-level
//! [`Accelerator`](super::Accelerator) over a
//! [`PreparedScene`](crate::prepared::PreparedScene)'s triangles and analytic
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
//!
//! Coherent rays can also walk the tree as packets of [`PACKET`]
//! ([`SceneBvh::intersect_packet`], [`SceneBvh::occluded_packet`]): one node
//! load per packet, the single-ray node and leaf tests per ray, and answers
//! bit-identical to single rays (`packet.rs` says how ties are kept). The
//! `Accelerator` packet queries use them only on trees of at least
//! [`PACKET_MIN_NODES`] nodes, where they pay.

mod build;
mod dispatch;
mod node;
mod packet;
mod partition;
mod scene;
#[cfg(test)]
mod tests;
mod traverse;
mod wide;

pub use dispatch::{KERNEL_ENV, Kernel, kernel};
pub use node::{BvhNode, Child};
pub use packet::{PACKET, PACKET_MIN_NODES};
pub use scene::SceneBvh;

use super::pages::HugeArray;
use crate::geometry::Aabb;

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

impl Bvh {
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
}
