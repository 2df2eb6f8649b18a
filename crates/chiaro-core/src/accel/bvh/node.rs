//! The [`WIDTH`]-wide node ([`BvhNode`]) and its slab test (Kay and Kajiya 1986;
//! near and far planes by direction sign after Williams et al. 2005).

use super::{EMPTY_LANE, EXIT_SLACK, WIDTH};
use crate::geometry::{Aabb, Ray};
#[cfg(any(
    test,
    not(all(
        target_arch = "x86_64",
        target_feature = "avx2",
        target_feature = "fma"
    ))
))]
use glam::Vec4;
use glam::{Vec3, Vec3A};

/// One [`WIDTH`]-wide node: up to `WIDTH` children, each an inner node or
/// a leaf (a run of primitive slots). 128 bytes (two cache lines), 64-byte
/// aligned.
///
/// Child boxes are quantised (Ylitie, Karras and Laine 2017; Embree's
/// QBVH8): per axis a grid from `origin` (the lower corner of all the
/// children) in steps of `scale`, a power of two, and per child and plane
/// an 8-bit grid index, rounded outward so that the decoded box holds the
/// child's box. A plane decodes as `fma(q, scale, origin)` (see
/// [`BvhNode::decode`]): `q * scale` is exact, so the scalar build and every
/// vector kernel get the same bits, and the node test is the slab test of
/// the decoded boxes.
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
pub struct BvhNode {
    /// Per axis: the grid's origin.
    pub origin: [f32; 3],
    /// Per axis: the grid's step, a power of two.
    pub scale: [f32; 3],
    /// Child boxes' grid indices, structure of arrays: rows 0-2 hold the
    /// lower corners' x, y, z, rows 3-5 the upper corners', one lane per
    /// child.
    pub q: [[u8; WIDTH]; 6],
    /// Per lane: the child node's index for an inner child, the first slot
    /// in [`Bvh::prim_order`](super::Bvh::prim_order) for a leaf.
    pub child: [u32; WIDTH],
    /// Per lane: 0 for an inner child, the primitive count (>= 1) for a
    /// leaf, [`EMPTY_LANE`] for an unused lane.
    pub count: [u16; WIDTH],
    /// Bit mask of the used lanes (the node test's answer is masked by it).
    pub used: u8,
    _pad: [u8; 7],
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

/// `2^e` for `e` in `-126..=127`.
fn pow2(e: i32) -> f32 {
    f32::from_bits(((e + 127) as u32) << 23)
}

/// The smallest power of two `s` (from `2^-126`, so that `q * s` stays
/// exact) with `fma(255, s, lo) >= hi`, or `2^127`.
fn grid_step(lo: f32, hi: f32) -> f32 {
    let (mut a, mut b) = (-126i32, 127i32);
    while a < b {
        let m = (a + b).div_euclid(2);
        if BvhNode::decode(255, pow2(m), lo) >= hi {
            b = m;
        } else {
            a = m + 1;
        }
    }
    pow2(a)
}

/// The first grid index `q` in `0..=255` for which the monotone `pred(q)`
/// holds, or 256 (binary search).
fn search(pred: impl Fn(u8) -> bool) -> u16 {
    let (mut a, mut b) = (0u16, 256u16);
    while a < b {
        let m = (a + b) / 2;
        if pred(m as u8) {
            b = m;
        } else {
            a = m + 1;
        }
    }
    a
}

impl BvhNode {
    pub(super) const EMPTY: BvhNode = BvhNode {
        origin: [0.0; 3],
        scale: [1.0; 3],
        q: [[0; WIDTH]; 6],
        child: [0; WIDTH],
        count: [EMPTY_LANE; WIDTH],
        used: 0,
        _pad: [0; 7],
    };

    /// A plane's coordinate from its grid index: one fused multiply-add,
    /// whose product is exact (a power of two times an integer below 256),
    /// so it is also `origin + q * scale` rounded once, whatever unit
    /// computes it.
    #[inline(always)]
    pub(super) fn decode(q: u8, scale: f32, origin: f32) -> f32 {
        f32::from(q).mul_add(scale, origin)
    }

    /// The node whose lanes `0..lanes.len()` hold the given children
    /// (`(box, child, count)`, as [`BvhNode::child`] and [`BvhNode::count`]
    /// say), their boxes quantised outward; the other lanes unused.
    pub(super) fn new(lanes: &[(Aabb, u32, u32)]) -> Self {
        debug_assert!(lanes.len() <= WIDTH);
        let mut n = Self::EMPTY;
        let all = lanes.iter().fold(Aabb::EMPTY, |u, l| u.union(l.0));
        for a in 0..3 {
            let (lo, hi) = (all.min[a], all.max[a]);
            n.origin[a] = lo;
            n.scale[a] = grid_step(lo, hi);
        }
        for (lane, (b, child, count)) in lanes.iter().enumerate() {
            for a in 0..3 {
                let dec = |q: u8| Self::decode(q, n.scale[a], n.origin[a]);
                // The last index at or below the box (0 decodes to the
                // origin, at or below every box), the first at or above it
                // (255 decodes at or above every box).
                n.q[a][lane] = search(|q| dec(q) > b.min[a]).saturating_sub(1) as u8;
                n.q[a + 3][lane] = search(|q| dec(q) >= b.max[a]).min(255) as u8;
            }
            n.child[lane] = *child;
            // (Leaves hold at most 255 primitives: `BvhOptions::max_leaf`.)
            debug_assert!(*count < u32::from(EMPTY_LANE));
            n.count[lane] = *count as u16;
            n.used |= 1 << lane;
        }
        n
    }

    /// The decoded child boxes, rows as in [`BvhNode::q`] (unused lanes
    /// decode to the origin).
    pub fn planes(&self) -> [[f32; WIDTH]; 6] {
        std::array::from_fn(|row| {
            let a = row % 3;
            self.q[row].map(|q| Self::decode(q, self.scale[a], self.origin[a]))
        })
    }

    /// The used lanes: each child's (decoded) box and what it is.
    pub fn children(&self) -> impl Iterator<Item = (Aabb, Child)> + '_ {
        let p = self.planes();
        (0..WIDTH)
            .filter(|&i| self.used >> i & 1 == 1)
            .map(move |i| {
                let b = Aabb {
                    min: Vec3::new(p[0][i], p[1][i], p[2][i]),
                    max: Vec3::new(p[3][i], p[4][i], p[5][i]),
                };
                let c = if self.count[i] == 0 {
                    Child::Node(self.child[i])
                } else {
                    Child::Leaf {
                        first: self.child[i],
                        count: u32::from(self.count[i]),
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
    /// the interval. Unused lanes are masked out by [`BvhNode::used`].
    /// The boxes are the decoded ones, which hold the children's, so the
    /// exit widening's argument is unchanged.
    ///
    /// With AVX2 and FMA (the default x86-64-v3 build) all eight lanes are
    /// one round of 256-bit operations; elsewhere two rounds of 4-lane
    /// `glam::Vec4` ([`BvhNode::intersect4`]) on [`BvhNode::planes`]. Both
    /// do the same IEEE operations per lane, so they agree bit for bit.
    #[cfg(all(
        target_arch = "x86_64",
        target_feature = "avx2",
        target_feature = "fma"
    ))]
    #[inline(always)]
    pub(super) fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        use safe_arch::*;
        const _: () = assert!(WIDTH == 8, "the AVX node test is eight lanes wide");
        // A row's eight grid indices widened to f32, then decoded.
        let plane = |row: usize, a: usize| {
            let q = set_i64_m128i_s(i64::from_le_bytes(self.q[row]));
            let q = convert_to_m256_from_i32_m256i(convert_to_i16_m256i_from_lower8_u8_m128i(q));
            fused_mul_add_m256(
                q,
                set_splat_m256(self.scale[a]),
                set_splat_m256(self.origin[a]),
            )
        };
        let slab = |row: usize, a: usize| mul_m256(sub_m256(plane(row, a), r.org[a]), r.inv[a]);
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
        (
            near.to_array(),
            move_mask_m256(hit) as u32 & u32::from(self.used),
        )
    }

    #[cfg(not(all(
        target_arch = "x86_64",
        target_feature = "avx2",
        target_feature = "fma"
    )))]
    #[inline(always)]
    pub(super) fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        self.intersect4(&r.org, &r.inv, r, t_min, t_max)
    }

    /// [`BvhNode::intersect`] four lanes at a time with `glam::Vec4` (SSE
    /// on x86), from the ray's origin and inverse direction splat over four
    /// lanes: the portable node test, and the AVX one's test oracle.
    #[cfg(any(
        test,
        not(all(
            target_arch = "x86_64",
            target_feature = "avx2",
            target_feature = "fma"
        ))
    ))]
    #[inline(always)]
    pub(super) fn intersect4(
        &self,
        org: &[Vec4; 3],
        inv: &[Vec4; 3],
        r: &RayPre,
        t_min: f32,
        t_max: f32,
    ) -> ([f32; WIDTH], u32) {
        let b = self.planes();
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
        (near_all, mask & u32::from(self.used))
    }
}

/// A ray constant splat over the node test's lanes.
#[cfg(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
))]
type Splat = safe_arch::m256;
#[cfg(not(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
)))]
type Splat = Vec4;

#[cfg(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
))]
#[inline(always)]
pub(super) fn splat(v: f32) -> Splat {
    safe_arch::set_splat_m256(v)
}
#[cfg(not(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma"
)))]
#[inline(always)]
pub(super) fn splat(v: f32) -> Splat {
    Vec4::splat(v)
}

/// Per-ray constants of the slab test. [`SceneBvh`](super::SceneBvh) builds
/// it once per ray and derives the triangle test's
/// [`WatertightRay`](crate::accel::WatertightRay) from the same reciprocal
/// direction ([`WatertightRay::with_inverse`](crate::accel::WatertightRay::with_inverse)).
pub(super) struct RayPre {
    /// Origin and inverse direction, each component splat over the node
    /// test's lanes.
    pub(super) org: [Splat; 3],
    pub(super) inv: [Splat; 3],
    /// Row of [`BvhNode::q`] holding the entry plane on each axis (the
    /// lower corner for a positive direction component).
    near_row: [usize; 3],
    far_row: [usize; 3],
    /// `1 / ray.dir`, per component (one vector division).
    pub(super) recip: Vec3,
}

impl RayPre {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
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
