//! Bump mapping by the height gradient (Blinn 1978, surface-gradient form of
//! Mikkelsen 2010) and tangent-space normal maps.

use glam::{Vec3, Vec4};

/// Bump mapping with a height-field gradient (Blinn 1978, in the "surface
/// gradient" form of Mikkelsen 2010, "Bump mapping unparametrized
/// surfaces"): the surface displaced by `h` along `n` has the normal
/// `normalize(n - grad_s h)`, where `grad_s h` is the gradient of `h` (scene
/// units per scene unit) projected into the tangent plane.
///
/// `grad_h` is the world-space gradient of the displacement; `n` must be unit.
#[inline]
pub fn bump_normal(n: Vec3, grad_h: Vec3) -> Vec3 {
    let gs = grad_h - grad_h.dot(n) * n;
    (n - gs).try_normalize().unwrap_or(n)
}

/// The world-space surface gradient of a function of uv with partial
/// derivatives `dh_du`, `dh_dv`, on a surface with position derivatives
/// `dpdu`, `dpdv` and unit normal `n`: `dh_du grad u + dh_dv grad v`, where
/// `grad u = (dpdv x n) / (dpdu . (dpdv x n))` and
/// `grad v = (n x dpdu) / (dpdv . (n x dpdu))`. Zero for a degenerate
/// parametrisation.
pub fn uv_surface_gradient(n: Vec3, dpdu: Vec3, dpdv: Vec3, dh_du: f32, dh_dv: f32) -> Vec3 {
    let a = dpdv.cross(n);
    let b = n.cross(dpdu);
    let da = dpdu.dot(a);
    let db = dpdv.dot(b);
    if da.abs() < 1e-20 || db.abs() < 1e-20 {
        return Vec3::ZERO;
    }
    let g = a * (dh_du / da) + b * (dh_dv / db);
    if g.is_finite() { g } else { Vec3::ZERO }
}

/// Tangent-space normal mapping (glTF 2.0 `normalTexture`): the texel `rgb`
/// in `[0, 1]` encodes `t = 2 rgb - 1`, and the perturbed normal is
/// `normalize(t.x T + t.y B + t.z N)` with `B = sign (N x T)`.
/// `tangent` is the tangent with the bitangent sign in `w`; `n` must be unit.
/// Falls back to `n` when the tangent is degenerate.
pub fn normal_map_normal(n: Vec3, tangent: Vec4, rgb: Vec3) -> Vec3 {
    let t = tangent.truncate();
    // Gram-Schmidt: the interpolated tangent need not be orthogonal to n.
    let Some(t) = (t - n * n.dot(t)).try_normalize() else {
        return n;
    };
    let sign = if tangent.w < 0.0 { -1.0 } else { 1.0 };
    let b = n.cross(t) * sign;
    let m = rgb * 2.0 - Vec3::ONE;
    (t * m.x + b * m.y + n * m.z).try_normalize().unwrap_or(n)
}
