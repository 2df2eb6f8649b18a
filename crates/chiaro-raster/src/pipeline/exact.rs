//! `Vec3A` (SSE) versions of the `Vec3` operations the shading pass uses,
//! giving bit-for-bit the results of glam's `Vec3` ones: the same IEEE
//! operations lane by lane. Add, subtract, multiply, divide and `dot`
//! (which sums `(x + y) + z` for both types) are glam's own; glam's
//! `Vec3A::cross` fuses a multiply-subtract on FMA targets and its
//! `normalize` divides by the length where `Vec3`'s multiplies by its
//! reciprocal, so those are written here.

use glam::{BVec3A, Vec3A, Vec3Swizzles};

/// `Vec3::cross`: `(a.y b.z - b.y a.z, a.z b.x - b.z a.x, a.x b.y - b.x a.y)`.
#[inline]
pub(crate) fn cross(a: Vec3A, b: Vec3A) -> Vec3A {
    (a.zxy() * b - a * b.zxy()).zxy()
}

/// `Vec3::length_recip`: `1 / sqrt(v . v)`.
#[inline]
fn length_recip(v: Vec3A) -> f32 {
    1.0 / v.length()
}

/// `Vec3::normalize`: `v * (1 / |v|)` (not finite for a zero vector).
#[inline]
pub(crate) fn normalize(v: Vec3A) -> Vec3A {
    v * length_recip(v)
}

/// `Vec3::try_normalize`: `None` when `1 / |v|` is not finite and positive.
#[inline]
pub(crate) fn try_normalize(v: Vec3A) -> Option<Vec3A> {
    let rcp = length_recip(v);
    (rcp.is_finite() && rcp > 0.0).then(|| v * rcp)
}

/// `Vec3::normalize_or_zero`.
#[inline]
pub(crate) fn normalize_or_zero(v: Vec3A) -> Vec3A {
    try_normalize(v).unwrap_or(Vec3A::ZERO)
}

/// `chiaro_core::geometry::normals::face_normal`: the cross product of the
/// two edges at the vertex opposite the longest edge, normalised; `None`
/// for a degenerate triangle. The three candidate products are all computed
/// and one is selected, without a branch: which edge of a mesh triangle is
/// the longest is unpredictable, and the shading pass takes the normal of
/// every triangle it fetches.
#[inline]
pub(crate) fn face_normal(a: Vec3A, b: Vec3A, c: Vec3A) -> Option<Vec3A> {
    let (e0, e1, e2) = (b - a, c - b, a - c);
    let (l0, l1, l2) = (e0.dot(e0), e1.dot(e1), e2.dot(e2));
    let first = BVec3A::splat(l0 >= l1 && l0 >= l2);
    let second = BVec3A::splat(l1 >= l2);
    let n = Vec3A::select(
        first,
        cross(e1, e2),
        Vec3A::select(second, cross(e2, e0), cross(e0, e1)),
    );
    let len = n.length();
    (len > 0.0 && len.is_finite() && len > 1e-12 * (l0 + l1 + l2)).then(|| n / len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    #[test]
    fn vec3a_helpers_match_vec3_bit_for_bit() {
        let mut rng = chiaro_testkit::XorShift64(0x2545_f491_4f6c_dd1d);
        let mut next = || {
            let state = rng.next_u64();
            // Spread over many magnitudes, both signs, with exact zeros.
            let m = (state >> 41) as f32 / (1u64 << 23) as f32 - 0.5;
            let e = ((state >> 8) % 40) as i32 - 20;
            if state.is_multiple_of(17) {
                0.0
            } else {
                m * 2f32.powi(e)
            }
        };
        for _ in 0..20_000 {
            let a = Vec3::new(next(), next(), next());
            let b = Vec3::new(next(), next(), next());
            let (aa, ba) = (Vec3A::from(a), Vec3A::from(b));
            assert_eq!(bits(cross(aa, ba).into()), bits(a.cross(b)));
            assert_eq!(bits((aa - ba).into()), bits(a - b));
            assert_eq!(aa.dot(ba).to_bits(), a.dot(b).to_bits());
            assert_eq!(aa.length().to_bits(), a.length().to_bits());
            if a != Vec3::ZERO {
                assert_eq!(bits(normalize(aa).into()), bits(a.normalize()));
            }
            assert_eq!(
                try_normalize(aa).map(|v| bits(v.into())),
                a.try_normalize().map(bits)
            );
            assert_eq!(
                bits(normalize_or_zero(aa).into()),
                bits(a.normalize_or_zero())
            );
            let c = Vec3::new(next(), next(), next());
            assert_eq!(
                face_normal(aa, ba, c.into()).map(|n| bits(n.into())),
                chiaro_core::geometry::normals::face_normal(a, b, c).map(bits)
            );
        }
    }
}
