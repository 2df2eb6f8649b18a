//! Microfacet distributions and Smith masking for Torrance-Sparrow.
//!
//! Sources: Walter et al. 2007, "Microfacet Models for Refraction through
//! Rough Surfaces" (GGX, Beckmann, and their Smith G1), and Heitz 2014,
//! "Understanding the Masking-Shadowing Function".

use crate::scene::Distribution;
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
}
