//! The [`WIDTH`]-wide tree built directly from the binned splits (Wald, Benthin
//! and Boulos 2008, section 3; Embree's BVH8 builder), and its flattening.

use super::build::{Bins, Build, PrimRef, Split, choose_split, new_bins, ref_bounds, split_bounds};
use super::partition::partition;
use super::{BLOCK, BvhNode, EMPTY_LANE, PAD_SLOT, WIDTH};
use crate::accel::pages::HugeArray;
use crate::geometry::Aabb;
use rayon::prelude::*;

/// A child-to-be of a node under construction: a run of references (from
/// `start` in the slice being built), their bounds and centroid bounds, its
/// depth in the binary tree that the binned splits make, and how it will be
/// cut. The boxes of its two parts are read from the bins when the split is
/// chosen, since the bins are reused by the next choice.
#[derive(Debug, Clone, Copy)]
pub(super) struct Item {
    pub(super) start: usize,
    pub(super) len: usize,
    pub(super) bounds: Aabb,
    pub(super) cb: Aabb,
    pub(super) depth: u32,
    pub(super) split: Split,
    /// For a binned split: the parts' boxes and the left part's size, as
    /// the bins counted them.
    pub(super) parts: Option<([Aabb; 2], usize)>,
}

impl Item {
    /// Bounds (unless `known`) and the split of `refs`.
    pub(super) fn plan(
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
pub(super) fn build_tree(refs: &mut [PrimRef], root: Item, opts: &Build) -> Tree {
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
/// leaf of up to four primitives is one block of a [`SceneBvh`](super::SceneBvh) (the gaps
/// hold [`PAD_SLOT`]), and the subtrees built in parallel below it. Leaves
/// are placed as they are made, so the order follows the build's
/// depth-first walk.
pub(super) struct Tree {
    pub(super) nodes: Vec<BvhNode>,
    pub(super) order: Vec<u32>,
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
    pub(super) tree: &'t Tree,
    root_at: usize,
    node_at: usize,
    slot_at: usize,
}

impl Placed<'_> {
    /// The final index of this tree's node `j`.
    pub(super) fn node(&self, j: usize) -> usize {
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
    pub(super) fn new(refs: usize) -> Self {
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
    pub(super) fn leaf(&mut self, refs: &[PrimRef]) -> u32 {
        let first = self.order.len().next_multiple_of(BLOCK);
        self.order.resize(first, PAD_SLOT);
        self.order.extend(refs.iter().map(|r| r.index()));
        first as u32
    }

    /// The whole nest as one node array (in huge-page-advised memory when
    /// large) and one slot order: each tree's nodes and slots written once,
    /// the trees in parallel, every index moved to its final place.
    pub(super) fn flatten(&self) -> (HugeArray<BvhNode>, Vec<u32>) {
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
