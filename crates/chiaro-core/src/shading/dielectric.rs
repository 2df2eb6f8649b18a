//! The rough dielectric interface: microfacet reflection and refraction
//! through a rough boundary between two media (Walter et al. 2007,
//! "Microfacet Models for Refraction through Rough Surfaces", eqs. 15-21;
//! pbrt-v4 `DielectricBxDF`, section 9.7), as paired pure functions
//! [`rough_dielectric_eval`], [`rough_dielectric_pdf`] and
//! [`sample_rough_dielectric`].
//!
//! `n` is the unit shading normal on the side of `wo` and `eta` the relative
//! index of refraction of the far side over the near side (`ior` seen from
//! outside, `1 / ior` from inside). Reflection is Fresnel's `F` of the
//! microfacet, refraction `(1 - F) kt`; the refracted radiance is not scaled
//! by `1 / eta^2`, as in chiaro's smooth glass ([`super::bsdf::delta_split`]),
//! so that the rough lobe tends to the delta one as the roughness goes to 0.
//!
//! At `eta = 1` the interface is a thin wall (glTF transmission without a
//! volume): nothing is reflected, and the transmitted lobe is the
//! microfacet reflection lobe mirrored through the surface's plane (glTF
//! `KHR_materials_transmission`, "thin-walled"), so light passes unbent on
//! average and blurred by the roughness.

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet;
use crate::geometry::Frame;
use crate::scene::Distribution;
use glam::{Vec2, Vec3};

/// Microfacet alpha below which a Fresnel dielectric is drawn with the
/// delta (smooth) lobe: narrower lobes differ from it by less than a pixel
/// and are numerically delicate in `f32`.
pub const MIN_ROUGH_ALPHA: f32 = 1e-2;

/// The microfacet normal of the pair `(wo, wi)`, on the side of `n`, and
/// whether `wi` is reflected: `wo + wi` for reflection, the generalised half
/// vector `wo + eta wi` for refraction (Walter et al. 2007, eq. 16). `None`
/// when it is degenerate or a side of the microfacet faces away (pbrt-v4
/// `DielectricBxDF::f`).
#[inline]
fn half_vector(n: Vec3, wo: Vec3, wi: Vec3, eta: f32) -> Option<(Vec3, bool)> {
    let cos_o = n.dot(wo);
    let cos_i = n.dot(wi);
    if cos_o <= 0.0 || cos_i == 0.0 {
        return None;
    }
    let reflected = cos_i > 0.0;
    let h = if reflected {
        wo + wi
    } else if eta == 1.0 {
        // A thin wall: the mirror image of `wi` through the surface's plane.
        wo + wi - 2.0 * cos_i * n
    } else {
        wo + eta * wi
    };
    let h = h.try_normalize()?;
    let h = if n.dot(h) < 0.0 { -h } else { h };
    // Both directions on the sides of the microfacet their normal cosines
    // say (for a thin wall, the mirror image of `wi`).
    let i_h = if eta == 1.0 && !reflected {
        h.dot(wi - 2.0 * cos_i * n)
    } else {
        h.dot(wi) * cos_i.signum()
    };
    if h.dot(wo) <= 0.0 || i_h <= 0.0 {
        return None;
    }
    Some((h, reflected))
}

/// `f(wo, wi) |cos_theta_i|` (1/sr) of a rough dielectric with relative
/// index `eta`, microfacet distribution `dist` of roughness `alpha`, and
/// transmission colour `kt`: `F D G / (4 cos_o)` for `wi` on the side of
/// `wo`, `kt (1 - F) D G |wi.h| |wo.h| / (cos_o (wi.h + wo.h / eta)^2)`
/// through the surface (Walter et al. 2007, eqs. 20-21, times `|cos_i|`).
/// Zero when `wo` is below `n`.
pub fn rough_dielectric_eval(
    dist: Distribution,
    alpha: f32,
    eta: f32,
    kt: Vec3,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
) -> Vec3 {
    let Some((h, reflected)) = half_vector(n, wo, wi, eta) else {
        return Vec3::ZERO;
    };
    let (cos_o, cos_i) = (n.dot(wo), n.dot(wi));
    let (o_h, i_h) = (wo.dot(h), wi.dot(h));
    let d = microfacet::d(dist, n.dot(h), alpha);
    let g = microfacet::g_smith(dist, cos_o, cos_i.abs(), alpha);
    let f = fresnel_dielectric(o_h, 1.0, eta);
    if reflected {
        return Vec3::splat(f * d * g / (4.0 * cos_o));
    }
    if eta == 1.0 {
        // A thin wall (F = 0): the reflection lobe, mirrored.
        return kt * (d * g / (4.0 * cos_o));
    }
    let denom = i_h + o_h / eta;
    let value = (1.0 - f) * d * g * (i_h * o_h).abs() / (cos_o * denom * denom);
    if value.is_finite() {
        kt * value
    } else {
        Vec3::ZERO
    }
}

/// Solid-angle pdf (1/sr) of [`sample_rough_dielectric`] at `wi`: the
/// microfacet normal's density ([`microfacet::microfacet_normal_pdf`]: the
/// normals visible from `wo` for GGX), times the Jacobian of `h -> wi`
/// (`1 / (4 |wo.h|)` for reflection, `|wi.h| / (wi.h + wo.h / eta)^2` for
/// refraction; Walter et al. 2007, eqs. 14, 17), times the probability of
/// the branch (`F` or `1 - F`).
pub fn rough_dielectric_pdf(
    dist: Distribution,
    alpha: f32,
    eta: f32,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
) -> f32 {
    let Some((h, reflected)) = half_vector(n, wo, wi, eta) else {
        return 0.0;
    };
    let (o_h, i_h) = (wo.dot(h), wi.dot(h));
    let pdf_h = microfacet::microfacet_normal_pdf(dist, alpha, n.dot(wo), n.dot(h), o_h);
    let f = fresnel_dielectric(o_h, 1.0, eta);
    if reflected {
        return f * pdf_h / (4.0 * o_h);
    }
    if eta == 1.0 {
        return pdf_h / (4.0 * o_h);
    }
    let denom = i_h + o_h / eta;
    let pdf = (1.0 - f) * pdf_h * i_h.abs() / (denom * denom);
    if pdf.is_finite() { pdf } else { 0.0 }
}

/// Samples an incident direction of the rough dielectric for `wo`: a
/// microfacet normal by `u` in `[0, 1)^2` from
/// [`microfacet::sample_microfacet_normal`] (visible from `wo` for GGX),
/// then reflection about it with probability
/// `F` (1 under total internal reflection), else refraction. `u_fresnel()`
/// gives the number of that choice and is called only when both branches
/// are possible. `None` when the microfacet faces away from `wo` or the
/// direction ends on the wrong side of `n` (the sample is lost; the pdf
/// does not renormalise).
pub fn sample_rough_dielectric(
    dist: Distribution,
    alpha: f32,
    eta: f32,
    n: Vec3,
    wo: Vec3,
    u: Vec2,
    u_fresnel: impl FnOnce() -> f32,
) -> Option<Vec3> {
    if n.dot(wo) <= 0.0 {
        return None;
    }
    let frame = Frame::from_normal(n);
    let h = frame.to_world(microfacet::sample_microfacet_normal(
        dist,
        alpha,
        frame.to_local(wo),
        u,
    ));
    let o_h = wo.dot(h);
    if o_h <= 0.0 {
        return None;
    }
    let f = fresnel_dielectric(o_h, 1.0, eta);
    let reflects = f >= 1.0 || (f > 0.0 && u_fresnel() < f);
    let wi = if reflects {
        reflect(wo, h)
    } else if eta == 1.0 {
        // A thin wall: the reflected direction mirrored through the plane.
        let r = reflect(wo, h);
        r - 2.0 * n.dot(r) * n
    } else {
        refract(wo, h, 1.0 / eta)?
    };
    let cos_i = n.dot(wi);
    if (reflects && cos_i <= 0.0) || (!reflects && cos_i >= 0.0) {
        return None;
    }
    Some(wi)
}
