//! The binned SAH build (Wald 2007; pbrt-v4 `BVHAggregate::buildRecursive`):
//! primitive references, centroid binning and the choice of split.

use super::wide::{Item, build_tree};
use super::{BLOCK, Bvh, BvhOptions, MAX_BINS, MEDIAN_DEPTH, WIDTH};
use crate::geometry::Aabb;
use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// The clamped options of one build, and what follows from its size.
#[derive(Debug, Clone, Copy)]
pub(super) struct Build {
    pub(super) opts: BvhOptions,
    /// Split one-block nodes where it pays ([`BvhOptions::fine_leaves_below`]).
    fine: bool,
}

impl std::ops::Deref for Build {
    type Target = BvhOptions;

    fn deref(&self) -> &BvhOptions {
        &self.opts
    }
}

/// A primitive reference during the build: 32 bytes, two aligned SIMD
/// vectors (the primitive's index rides in the lower corner's fourth lane,
/// as in Embree's `PrimRef`), so binning and partitioning load each
/// reference with two aligned loads.
#[derive(Debug, Clone, Copy)]
pub(super) struct PrimRef {
    /// Lower corner in x, y, z; the index's bits in w.
    pub(super) lo: Vec4,
    /// Upper corner.
    pub(super) hi: Vec3A,
}

impl PrimRef {
    #[inline(always)]
    pub(super) fn new(b: &Aabb, index: u32) -> Self {
        Self {
            lo: b.min.extend(f32::from_bits(index)),
            hi: b.max.into(),
        }
    }

    #[inline(always)]
    pub(super) fn min(&self) -> Vec3A {
        Vec3A::from_vec4(self.lo)
    }

    #[inline(always)]
    pub(super) fn max(&self) -> Vec3A {
        self.hi
    }

    #[inline(always)]
    pub(super) fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }

    pub(super) fn aabb(&self) -> Aabb {
        Aabb {
            min: self.min().into(),
            max: self.max().into(),
        }
    }

    #[inline(always)]
    pub(super) fn centroid(&self) -> Vec3A {
        (self.min() + self.max()) * 0.5
    }
}

/// One SAH bin: the box of its references (SIMD corners) and their count.
/// The children's centroid bounds are gathered by [`partition`](super::partition::partition), which
/// computes every centroid anyway, rather than per bin on every axis.
#[derive(Debug, Clone, Copy)]
pub(super) struct Bin {
    pub(super) min: Vec3A,
    pub(super) max: Vec3A,
    pub(super) count: u32,
}

impl Bin {
    #[inline(always)]
    pub(super) fn bounds(&self) -> Aabb {
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
pub(super) type Bins = [[Bin; MAX_BINS]; 6];

/// A fresh set of bins, on the heap (18 KiB).
pub(super) fn new_bins() -> Box<Bins> {
    Box::new([[EMPTY_BIN; MAX_BINS]; 6])
}

/// Nodes from this many references bin into two sets ([`Bins`]).
const TWO_SETS: usize = 512;

/// Bounds of the two sides of a binned split: bins `0..=bin` of `axis`
/// and the rest. Exact unions, so they equal what [`ref_bounds`] would
/// compute over each side's references.
pub(super) fn split_bounds(binned: &Bins, axis: usize, bin: usize, bins: usize) -> [Aabb; 2] {
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
pub(super) enum Split {
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
}

/// Bounds of the references and of their centroids.
pub(super) fn ref_bounds(refs: &[PrimRef], parallel: bool) -> (Aabb, Aabb) {
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
pub(super) fn bin_refs(
    refs: &[PrimRef],
    cb: &Aabb,
    scale: Vec3,
    bins: usize,
    parallel: bool,
    out: &mut Bins,
) {
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
pub(super) fn choose_split(
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
pub(super) fn blocks(n: u32) -> f32 {
    n.div_ceil(BLOCK as u32) as f32
}
