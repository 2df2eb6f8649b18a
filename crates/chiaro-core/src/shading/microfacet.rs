//! Microfacet distributions and Smith masking for Torrance-Sparrow.
//!
//! Sources: Walter et al. 2007, "Microfacet Models for Refraction through
//! Rough Surfaces" (GGX, Beckmann, and their Smith G1), and Heitz 2014,
//! "Understanding the Masking-Shadowing Function".
//!
//! Every microfacet lobe (Torrance-Sparrow reflection, the clear coat, the
//! rough dielectric) draws its microfacet normal with the one pair
//! [`sample_microfacet_normal`] / [`microfacet_normal_pdf`]: the normals
//! visible from `wo` for GGX (Heitz 2018, "Sampling the GGX Distribution of
//! Visible Normals"; the spherical-cap form of Dupuy and Benyoub 2023), so
//! that a sample's weight is bounded by Smith's `G1(wi)`; `D(h) cos_theta_h`
//! for Beckmann, whose `G1` here is Walter's rational approximation, which
//! the visible-normal density would have to match exactly.

use crate::scene::Distribution;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Normal distribution `D(h)` (1/sr, normalised so that
/// `integral D(h) cos_theta_h dh = 1`) for `cos_h = n . h` and roughness `alpha`.
#[inline]
pub fn d(dist: Distribution, cos_h: f32, alpha: f32) -> f32 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let c2 = cos_h * cos_h;
    match dist {
        Distribution::Ggx => {
            let t = c2 * (a2 - 1.0) + 1.0;
            a2 / (PI * t * t)
        }
        Distribution::Beckmann => {
            let tan2 = (1.0 - c2) / c2;
            (-tan2 / a2).exp() / (PI * a2 * c2 * c2)
        }
    }
}

/// Smith's one-direction masking `G1` for a direction at `cos_theta` from the normal.
#[inline]
pub fn g1(dist: Distribution, cos_theta: f32, alpha: f32) -> f32 {
    if cos_theta <= 0.0 {
        return 0.0;
    }
    let c2 = cos_theta * cos_theta;
    let tan2 = ((1.0 - c2) / c2).max(0.0);
    match dist {
        Distribution::Ggx => 2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt()),
        Distribution::Beckmann => {
            // Walter et al. 2007, eq. 27 (rational approximation).
            let a = 1.0 / (alpha * tan2.sqrt()).max(1e-7);
            if a >= 1.6 {
                1.0
            } else {
                (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
            }
        }
    }
}

/// Separable Smith shadowing-masking `G1(o) G1(i)`.
#[inline]
pub fn g_smith(dist: Distribution, cos_o: f32, cos_i: f32, alpha: f32) -> f32 {
    g1(dist, cos_o, alpha) * g1(dist, cos_i, alpha)
}

/// Samples a microfacet normal about +z for the local outgoing direction
/// `wo` (unit, `wo.z > 0`) from `u` in `[0, 1)^2`, with the density
/// [`microfacet_normal_pdf`]: GGX's visible normals, `G1(wo) max(0, wo.h)
/// D(h) / cos_theta_o` (Heitz 2018, eq. 1), drawn as the uniform direction
/// on a spherical cap about the stretched `wo`, added to it and unstretched
/// (Dupuy and Benyoub 2023, listing 3); Beckmann's `D(h) cos_theta_h`
/// (Walter et al. 2007, eqs. 28, 35). The normal is unit, with `h.z >= 0`.
#[inline]
pub fn sample_microfacet_normal(dist: Distribution, alpha: f32, wo: Vec3, u: Vec2) -> Vec3 {
    match dist {
        Distribution::Ggx => {
            // Stretch to the hemisphere configuration (roughness 1).
            let ws = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize_or(Vec3::Z);
            // A uniform direction on the cap `z > -ws.z` of the unit sphere.
            let phi = 2.0 * PI * u.x;
            let z = (1.0 - u.y) * (1.0 + ws.z) - ws.z;
            let sin_t = (1.0 - z * z).clamp(0.0, 1.0).sqrt();
            let (s, c) = phi.sin_cos();
            let hs = Vec3::new(sin_t * c, sin_t * s, z) + ws;
            // Unstretch the hemisphere's normal back to roughness `alpha`.
            Vec3::new(alpha * hs.x, alpha * hs.y, hs.z.max(0.0)).normalize_or(Vec3::Z)
        }
        Distribution::Beckmann => {
            let tan2 = -alpha * alpha * (1.0 - u.x).max(1e-7).ln();
            let cos_t = 1.0 / (1.0 + tan2).sqrt();
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let (s, c) = (2.0 * PI * u.y).sin_cos();
            Vec3::new(sin_t * c, sin_t * s, cos_t)
        }
    }
}

/// Density (1/sr, over microfacet normals) with which
/// [`sample_microfacet_normal`] draws `h`, given `cos_o = n.wo`,
/// `cos_h = n.h` and `o_h = wo.h`: `G1(wo) max(0, o_h) D(h) / cos_o` for
/// GGX (0 when `wo` is below the surface), `D(h) cos_h` for Beckmann.
#[inline]
pub fn microfacet_normal_pdf(
    dist: Distribution,
    alpha: f32,
    cos_o: f32,
    cos_h: f32,
    o_h: f32,
) -> f32 {
    match dist {
        Distribution::Ggx => {
            if cos_o <= 0.0 || o_h <= 0.0 {
                return 0.0;
            }
            g1(dist, cos_o, alpha) * o_h * d(dist, cos_h, alpha) / cos_o
        }
        Distribution::Beckmann => d(dist, cos_h, alpha) * cos_h.max(0.0),
    }
}

/// Solid-angle pdf (1/sr) of `wi = reflect(wo, h)` for `h` drawn by
/// [`sample_microfacet_normal`] about the unit normal `n`: the normal's
/// density times the Jacobian `1 / (4 wo.h)` (Walter et al. 2007, eq. 14);
/// for GGX `G1(wo) D(h) / (4 cos_o)`. 0 when `wo` or `wi` is below `n`.
#[inline]
pub fn reflection_pdf(dist: Distribution, alpha: f32, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
    let (cos_o, cos_i) = (n.dot(wo), n.dot(wi));
    if cos_o <= 0.0 || cos_i <= 0.0 {
        return 0.0;
    }
    let Some(h) = (wo + wi).try_normalize() else {
        return 0.0;
    };
    let (cos_h, o_h) = (n.dot(h), wo.dot(h));
    if cos_h <= 0.0 || o_h <= 0.0 {
        return 0.0;
    }
    microfacet_normal_pdf(dist, alpha, cos_o, cos_h, o_h) / (4.0 * o_h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distributions_are_normalised() {
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.1f32, 0.4, 0.8] {
                // integral over the hemisphere of D cos dω = 1, midpoint rule in cos.
                let k = 20000;
                let mut s = 0.0f64;
                for i in 0..k {
                    let c = (i as f32 + 0.5) / k as f32;
                    s += (d(dist, c, alpha) * c) as f64 * (2.0 * std::f64::consts::PI / k as f64);
                }
                assert!((s - 1.0).abs() < 0.01, "{dist:?} {alpha}: {s}");
            }
        }
    }

    /// A unit direction at polar angle `theta` (radians) and azimuth `phi`.
    fn polar(theta: f64, phi: f64) -> Vec3 {
        let (s, c) = theta.sin_cos();
        Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32)
    }

    /// `integral f(h) dh` over the upper hemisphere by the midpoint rule in
    /// `(theta, phi)` with `theta = (pi/2) x^2`, so that cells shrink near
    /// the pole, where narrow lobes live; summed in `f64`.
    fn hemisphere_integral(f: impl Fn(Vec3) -> f64) -> f64 {
        let (kt, kp) = (4000, 256);
        let mut s = 0.0f64;
        for i in 0..kt {
            let x = (i as f64 + 0.5) / kt as f64;
            let theta = std::f64::consts::FRAC_PI_2 * x * x;
            let dtheta = std::f64::consts::PI * x / kt as f64;
            for j in 0..kp {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / kp as f64;
                s += f(polar(theta, phi)) * theta.sin() * dtheta;
            }
        }
        s * (2.0 * std::f64::consts::PI / kp as f64)
    }

    #[test]
    fn visible_normal_density_integrates_to_one() {
        // integral over the hemisphere of h of the normal's density = 1 (the
        // visible projected area of the microsurface is cos_theta_o), by the
        // midpoint rule in (theta, phi); dense near the pole for narrow lobes.
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.3, 0.8] {
                for theta_o in [0.0f64, 40.0, 75.0, 88.0] {
                    let wo = polar(theta_o.to_radians(), 0.7);
                    let s = hemisphere_integral(|h| {
                        f64::from(microfacet_normal_pdf(dist, alpha, wo.z, h.z, wo.dot(h)))
                    });
                    // (Beckmann's D cos is exact; GGX's uses the exact G1.)
                    assert!(
                        (s - 1.0).abs() < 5e-3,
                        "{dist:?} alpha {alpha} theta_o {theta_o}: {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn sampled_normals_face_wo_and_follow_their_density() {
        // Every GGX normal is visible (wo.h >= 0, h.z >= 0), and the mean of
        // cos_theta_h over samples equals its integral against the density.
        let mut rng = crate::sampling::pixel_rng(41, 0, 0, 0);
        for alpha in [0.05f32, 0.4, 1.0] {
            for theta_o in [10.0f64, 60.0, 85.0] {
                let wo = polar(theta_o.to_radians(), 1.3);
                let n = 200_000;
                let mut mean = 0.0f64;
                for _ in 0..n {
                    let u = crate::sampling::uniform2(&mut rng);
                    let h = sample_microfacet_normal(Distribution::Ggx, alpha, wo, u);
                    assert!((h.length() - 1.0).abs() < 1e-5 && h.z >= 0.0, "{h}");
                    assert!(wo.dot(h) >= -1e-6, "alpha {alpha} wo {wo}: h {h}");
                    mean += f64::from(h.z);
                }
                mean /= f64::from(n);
                let want = hemisphere_integral(|h| {
                    let p = microfacet_normal_pdf(Distribution::Ggx, alpha, wo.z, h.z, wo.dot(h));
                    f64::from(p * h.z)
                });
                // The standard error of a mean of values in [0, 1] is below
                // 0.5 / sqrt(n) ~ 1.1e-3.
                assert!(
                    (mean - want).abs() < 5e-3,
                    "alpha {alpha} theta_o {theta_o}: E[cos h] {mean} vs {want}"
                );
            }
        }
    }
}
