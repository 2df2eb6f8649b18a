//! Partitioning the references at a split: the branch-free block partition of
//! Edelkamp and Weiss (2016, BlockQuicksort) with a Lomuto tail.

use super::build::{PrimRef, Split};
use crate::geometry::Aabb;
use glam::Vec3A;

/// What [`partition`] made: the size of the left part (always in `1..n`)
/// and, for a binned split, the centroid bounds of both parts.
pub(super) struct Parted {
    pub(super) mid: usize,
    pub(super) centroids: Option<[Aabb; 2]>,
}

/// Applies a split.
pub(super) fn partition(refs: &mut [PrimRef], split: &Split, cb: &Aabb, parallel: bool) -> Parted {
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
pub(super) struct Plane {
    pub(super) lo: Vec3A,
    pub(super) scale: Vec3A,
    pub(super) limit: Vec3A,
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
pub(super) fn partition_by<const AXIS: usize>(
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
pub(super) fn grow_sides(
    m: glam::BVec3A,
    c: Vec3A,
    l: [Vec3A; 2],
    r: [Vec3A; 2],
) -> ([Vec3A; 2], [Vec3A; 2]) {
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
