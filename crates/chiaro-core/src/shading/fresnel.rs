//! Reflection, refraction and Fresnel: small pure functions.

use glam::Vec3;

/// Mirror direction of `wo` about the unit normal `n`: `2 (n . wo) n - wo`.
/// Both point away from the surface.
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * n.dot(wo) * n - wo
}

/// Refracted direction of `wo` (pointing away from the surface, on the side
/// `n` points to) into the other medium, by Snell's law with
/// `eta = eta_outside / eta_inside` (n1 / n2). `None` under total internal
/// reflection. `n` must be unit and on the side of `wo`.
///
/// Source: pbrt-v4, section 9.3 "Specular Reflection and Transmission".
#[inline]
pub fn refract(wo: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = n.dot(wo);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = eta * eta * sin2_i;
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wo * eta + n * (eta * cos_i - cos_t)).normalize())
}

/// Schlick's approximation `F0 + (1 - F0)(1 - cos)^5` (Schlick 1994).
#[inline]
pub fn fresnel_schlick(f0: Vec3, cos_theta: f32) -> Vec3 {
    f0 + (Vec3::ONE - f0) * schlick_weight(cos_theta)
}

/// The weight `w = (1 - cos)^5` of Schlick's approximation, which is
/// `F0 (1 - w) + w`: linear in `F0`, so a lobe's colourless parts can be
/// found where `F0` is not yet known (flat and Gouraud shading).
#[inline]
pub fn schlick_weight(cos_theta: f32) -> f32 {
    let m = (1.0 - cos_theta).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Unpolarised Fresnel reflectance of a dielectric interface for light
/// arriving at `cos_theta_i` (> 0 on the side of medium `n1`) going into
/// medium `n2`. Returns 1 under total internal reflection.
///
/// Source: the Fresnel equations, e.g. pbrt-v4 eq. 9.4-9.5.
pub fn fresnel_dielectric(cos_theta_i: f32, n1: f32, n2: f32) -> f32 {
    let cos_i = cos_theta_i.clamp(0.0, 1.0);
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_par = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t);
    let r_perp = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    0.5 * (r_par * r_par + r_perp * r_perp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_at_known_angle() {
        let n = Vec3::Y;
        let t = 30f32.to_radians();
        let wo = Vec3::new(-t.sin(), t.cos(), 0.0);
        let wt = refract(wo, n, 1.0 / 1.5).expect("no TIR entering glass");
        let sin_t = wt.x.abs();
        assert!((sin_t - t.sin() / 1.5).abs() < 1e-6);
        assert!(wt.y < 0.0 && wt.x > 0.0);
    }

    #[test]
    fn total_internal_reflection_past_critical_angle() {
        let crit = (1.0f32 / 1.5).asin();
        let n = Vec3::Y;
        let just_below = crit - 1e-3;
        let just_above = crit + 1e-3;
        let dir = |a: f32| Vec3::new(-a.sin(), a.cos(), 0.0);
        assert!(refract(dir(just_below), n, 1.5).is_some());
        assert!(refract(dir(just_above), n, 1.5).is_none());
        assert_eq!(fresnel_dielectric(just_above.cos(), 1.5, 1.0), 1.0);
    }

    #[test]
    fn fresnel_normal_incidence_and_limits() {
        let r0 = fresnel_dielectric(1.0, 1.0, 1.5);
        assert!((r0 - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(1e-6, 1.0, 1.5) - 1.0).abs() < 1e-3);
        let s = fresnel_schlick(Vec3::splat(0.04), 1.0);
        assert!((s.x - 0.04).abs() < 1e-7);
        assert!((fresnel_schlick(Vec3::splat(0.04), 0.0).x - 1.0).abs() < 1e-6);
    }

    #[test]
    fn reflect_is_mirror() {
        let wo = Vec3::new(1.0, 1.0, 0.0).normalize();
        let r = reflect(wo, Vec3::Y);
        assert!((r - Vec3::new(-1.0, 1.0, 0.0).normalize()).length() < 1e-6);
    }
}
