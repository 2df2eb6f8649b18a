//! Closest-hit and any-hit traversal of a [`Bvh`]: an explicit stack, hit
//! children nearest first with popped ones beyond the hit skipped, prefetching.

use super::node::RayPre;
use super::{Bvh, BvhNode, WIDTH};
use crate::geometry::Ray;

/// Starts loading a child pushed on the traversal stack into the cache:
/// the four cache lines of an inner child's node (`count` 0), or, through
/// `leaf`, a leaf's primitives (`leaf(first)`). A pushed child is popped
/// after its nearer sibling's subtree, by when its data has arrived, so an
/// incoherent ray waits on several misses at once rather than one after
/// another. A hint only; nothing else changes.
#[inline(always)]
pub(super) fn prefetch(nodes: &[BvhNode], child: u32, count: u32, leaf: &impl Fn(u32)) {
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
pub(super) struct Entry {
    pub(super) child: u32,
    pub(super) count: u32,
    pub(super) near: f32,
}

/// Entries kept in the first fixed part of the stack, cleared for every
/// ray: a ray through a small scene seldom holds more, and clearing a
/// larger array would cost more than such a ray's traversal.
const STACK_FIRST: usize = 8;
/// Entries in the second fixed part, set up only when a ray first needs
/// it. Ordered traversal with pop-culling rarely holds more than a dozen
/// or two; deeper trees spill into a `Vec`.
const STACK_MORE: usize = 24;

/// A traversal stack: two fixed arrays, the second made only when the
/// first is full (an `Option`, whose `None` is one tag store), then a
/// `Vec` (never allocated for ordinary trees), so that no tree is too deep.
/// Single rays use [`Stack`], packets `packet::PacketStack`.
pub(super) struct FixedStack<E: Copy + Default, const FIRST: usize, const MORE: usize> {
    first: [E; FIRST],
    more: Option<[E; MORE]>,
    len: usize,
    spill: Vec<E>,
}

/// The single-ray traversal stack.
pub(super) type Stack = FixedStack<Entry, STACK_FIRST, STACK_MORE>;

impl<E: Copy + Default, const FIRST: usize, const MORE: usize> FixedStack<E, FIRST, MORE> {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            first: [E::default(); FIRST],
            more: None,
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    pub(super) fn push(&mut self, e: E) {
        if self.len < FIRST {
            self.first[self.len] = e;
            self.len += 1;
        } else {
            self.push_more(e);
        }
    }

    /// [`FixedStack::push`] past the first part (out of line: the traversal
    /// loop keeps only the common case).
    #[inline(never)]
    fn push_more(&mut self, e: E) {
        if self.len < FIRST + MORE {
            let more = self.more.get_or_insert([E::default(); MORE]);
            more[self.len - FIRST] = e;
            self.len += 1;
        } else {
            self.spill.push(e);
        }
    }

    #[inline(always)]
    pub(super) fn pop(&mut self) -> Option<E> {
        // (The spill holds entries only when both fixed parts are full.)
        if self.len > FIRST {
            self.pop_more()
        } else if self.len > 0 {
            self.len -= 1;
            Some(self.first[self.len])
        } else {
            None
        }
    }

    /// [`FixedStack::pop`] past the first part.
    #[inline(never)]
    fn pop_more(&mut self) -> Option<E> {
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len -= 1;
        self.more.as_ref().map(|m| m[self.len - FIRST])
    }
}

impl Bvh {
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
    pub(super) fn traverse_closest_pre(
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
    pub(super) fn traverse_any_pre(
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
