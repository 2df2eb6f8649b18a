//! The [`WIDTH`]-wide node ([`BvhNode`]) and its slab test (Kay and Kajiya 1986;
//! near and far planes by direction sign after Williams et al. 2005).

use super::{EMPTY_LANE, EXIT_SLACK, WIDTH};
use crate::geometry::{Aabb, Ray};
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "avx"))))]
use glam::Vec4;
use glam::{Vec3, Vec3A};

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
    /// in [`Bvh::prim_order`](super::Bvh::prim_order) for a leaf.
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
    pub(super) const EMPTY: BvhNode = BvhNode {
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

    pub(super) fn set_lane(&mut self, lane: usize, b: &Aabb, child: u32, count: u32) {
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
    pub(super) fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
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
    pub(super) fn intersect(&self, r: &RayPre, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        self.intersect4(&r.org, &r.inv, r, t_min, t_max)
    }

    /// [`BvhNode::intersect`] four lanes at a time with `glam::Vec4` (SSE
    /// on x86), from the ray's origin and inverse direction splat over four
    /// lanes: the portable node test, and the AVX one's test oracle.
    #[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "avx"))))]
    #[inline(always)]
    pub(super) fn intersect4(
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
pub(super) fn splat(v: f32) -> Splat {
    safe_arch::set_splat_m256(v)
}
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
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
    /// Row of [`BvhNode::bounds`] holding the entry plane on each axis (the
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
