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

/// Unpolarised Fresnel reflectance of a conductor, per RGB channel, for
/// light arriving at `cos_theta_i` from a dielectric of index 1 onto a
/// metal of complex index of refraction `eta + i k` (each relative to the
/// outside medium). In `[0, 1]`: `((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)`
/// at normal incidence, 1 at grazing, and [`fresnel_dielectric`] when
/// `k = 0`. A non-finite or negative `eta` or `k` is read as 0.
///
/// Source: the exact Fresnel equations for a complex index in real
/// arithmetic (K. D. Moeller, "Optics", 1988, as Mitsuba 3's
/// `fresnel_conductor` writes them; the same function as pbrt-v4's
/// `FrComplex`, eq. 9.9 with complex `eta`).
pub fn fresnel_conductor(cos_theta_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let sane = |v: Vec3| Vec3::select(v.cmpge(Vec3::ZERO) & v.is_finite_mask(), v, Vec3::ZERO);
    let (eta, k) = (sane(eta), sane(k));
    let cos_i = if cos_theta_i.is_nan() {
        0.0
    } else {
        cos_theta_i.clamp(0.0, 1.0)
    };
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let channel = |eta: f32, k: f32| {
        // a^2 + b^2 = |eta^2 - sin^2|, with (a + i b)^2 = eta^2 - sin^2.
        let t = eta * eta - k * k - sin2;
        let a2b2 = (t * t + 4.0 * eta * eta * k * k).max(0.0).sqrt();
        let a = (0.5 * (a2b2 + t)).max(0.0).sqrt();
        let t1 = a2b2 + cos2;
        let t2 = 2.0 * cos_i * a;
        let r_s = if t1 + t2 > 0.0 {
            (t1 - t2) / (t1 + t2)
        } else {
            1.0
        };
        let t3 = a2b2 * cos2 + sin2 * sin2;
        let t4 = t2 * sin2;
        let r_p = if t3 + t4 > 0.0 {
            r_s * (t3 - t4) / (t3 + t4)
        } else {
            r_s
        };
        (0.5 * (r_s + r_p)).clamp(0.0, 1.0)
    };
    Vec3::new(
        channel(eta.x, k.x),
        channel(eta.y, k.y),
        channel(eta.z, k.z),
    )
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

    /// A conductor's reflectance at normal incidence in closed form.
    fn conductor_f0(eta: f32, k: f32) -> f32 {
        ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k)
    }

    #[test]
    fn conductor_fresnel_closed_forms_and_limits() {
        let eta = Vec3::new(0.2, 1.1, 2.5);
        let k = Vec3::new(3.9, 2.4, 0.4);
        let f = fresnel_conductor(1.0, eta, k);
        for c in 0..3 {
            assert!((f[c] - conductor_f0(eta[c], k[c])).abs() < 1e-6, "{c}: {f}");
        }
        // Grazing incidence reflects everything.
        assert!(
            (fresnel_conductor(0.0, eta, k) - Vec3::ONE)
                .abs()
                .max_element()
                < 1e-6
        );
        assert!(
            (fresnel_conductor(1e-4, eta, k) - Vec3::ONE)
                .abs()
                .max_element()
                < 2e-3
        );
        // k = 0 is a dielectric, entering (eta > 1) and leaving with total
        // internal reflection (eta < 1).
        for i in 0..=20 {
            let c = i as f32 / 20.0;
            for n in [1.5f32, 2.4, 1.0 / 1.5] {
                let want = fresnel_dielectric(c, 1.0, n);
                let got = fresnel_conductor(c, Vec3::splat(n), Vec3::ZERO);
                assert!(
                    (got.x - want).abs() < 1e-5,
                    "cos {c}, eta {n}: {got} vs {want}"
                );
            }
        }
        // Mitsuba's ideal mirror `none` (eta 0, k 1) reflects 1 at every angle.
        for c in [0.0, 0.3, 0.7, 1.0] {
            let f = fresnel_conductor(c, Vec3::ZERO, Vec3::ONE);
            assert!((f - Vec3::ONE).abs().max_element() < 1e-6, "{c}: {f}");
        }
        // Bad input stays in [0, 1].
        let f = fresnel_conductor(f32::NAN, Vec3::splat(f32::NAN), Vec3::splat(-1.0));
        assert!(f.is_finite() && f.max_element() <= 1.0 && f.min_element() >= 0.0);
    }

    #[test]
    fn conductor_fresnel_tabulated_values() {
        // Values of the complex Fresnel equations computed independently
        // in double precision with complex arithmetic (pbrt-v4's FrComplex):
        // (eta, k, theta_i degrees, R).
        let table: [(f32, f32, f32, f32); 6] = [
            (0.789, 6.15, 0.0, 0.923_068),
            (0.789, 6.15, 60.0, 0.909_645),
            (0.789, 6.15, 85.0, 0.898_815),
            (0.143_119, 3.983_16, 45.0, 0.965_277),
            (1.5, 0.0, 70.0, 0.171_043),
            (2.0, 1.0, 30.0, 0.201_901),
        ];
        for (eta, k, deg, want) in table {
            let c = deg.to_radians().cos();
            let got = fresnel_conductor(c, Vec3::splat(eta), Vec3::splat(k)).x;
            assert!(
                (got - want).abs() < 2e-5,
                "eta {eta} k {k} {deg} deg: {got} vs {want}"
            );
        }
    }
}
