//! Light samples: direction, distance and the classic intensity factor
//! `f_att * Ip * spot` of each light as seen from a point.

use crate::geometry::Frame;
use crate::scene::{AreaShape, Light, SpotLight};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// One sample of a light as seen from a point `p`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    /// Unit direction from `p` towards the sample.
    pub wi: Vec3,
    /// Distance from `p` to the sample (`f32::INFINITY` for directional lights).
    pub distance: f32,
    /// The sample position (for shadow tests); for directional lights a point
    /// far away along `wi`.
    pub point: Vec3,
    /// The intensity factor: the reflected radiance is
    /// `pi * f(wo, wi) * cos_theta_i * intensity` (see [`super`]).
    /// For point-like lights `f_att * Ip * spot`; for an area-light sample the
    /// one-sample estimate `Le * cos_theta_l * A / (pi d^2)` (or
    /// `Le * solid_angle / pi` for spheres), so averaging samples integrates
    /// the light.
    pub intensity: Vec3,
    /// True for a point, spot or directional light (a delta distribution).
    pub is_delta: bool,
}

/// The Warn spotlight factor at point `p`: `cos^n` of the angle to the axis,
/// zero outside the cone or outside any flap, with an optional smooth edge.
pub fn spot_factor(s: &SpotLight, p: Vec3) -> f32 {
    let to_p = p - s.position;
    for flap in &s.flaps {
        let x = to_p.dot(flap.axis);
        if x < flap.min || x > flap.max {
            return 0.0;
        }
    }
    let Some(dir) = to_p.try_normalize() else {
        return 0.0;
    };
    let axis = s.direction.normalize_or_zero();
    let cos_a = dir.dot(axis);
    let cos_cone = s.cone_degrees.to_radians().cos();
    if cos_a < cos_cone {
        return 0.0;
    }
    let mut f = cos_a.max(0.0).powf(s.exponent);
    if s.cone_softness_degrees > 0.0 {
        let inner = (s.cone_degrees - s.cone_softness_degrees)
            .max(0.0)
            .to_radians()
            .cos();
        if cos_a < inner {
            let t = ((cos_a - cos_cone) / (inner - cos_cone)).clamp(0.0, 1.0);
            f *= t * t * (3.0 - 2.0 * t);
        }
    }
    f
}

/// Samples `light` as seen from `p` with the 2D sample `u` in `[0,1)^2`
/// (ignored by delta lights). `None` for ambient lights, for points where the
/// light contributes nothing (outside a spot cone, behind a one-sided area
/// light), and at the light's own position.
#[inline]
pub fn sample_light(light: &Light, p: Vec3, u: Vec2) -> Option<LightSample> {
    match light {
        Light::Ambient { .. } => None,
        Light::Point {
            position,
            attenuation,
            ..
        } => {
            let d = *position - p;
            let dist = d.length();
            if dist <= 0.0 {
                return None;
            }
            Some(LightSample {
                wi: d / dist,
                distance: dist,
                point: *position,
                intensity: light.power_rgb() * attenuation.factor(dist),
                is_delta: true,
            })
        }
        Light::Directional { direction, .. } => {
            let wi = (-*direction).try_normalize()?;
            Some(LightSample {
                wi,
                distance: f32::INFINITY,
                point: p + wi * 1.0e7,
                intensity: light.power_rgb(),
                is_delta: true,
            })
        }
        Light::Spot(s) => {
            let d = s.position - p;
            let dist = d.length();
            if dist <= 0.0 {
                return None;
            }
            let k = spot_factor(s, p);
            if k <= 0.0 {
                return None;
            }
            Some(LightSample {
                wi: d / dist,
                distance: dist,
                point: s.position,
                intensity: light.power_rgb() * (s.attenuation.factor(dist) * k),
                is_delta: true,
            })
        }
        Light::Area {
            shape, two_sided, ..
        } => sample_area(shape, *two_sided, light.power_rgb(), p, u),
    }
}

fn sample_area(
    shape: &AreaShape,
    two_sided: bool,
    le: Vec3,
    p: Vec3,
    u: Vec2,
) -> Option<LightSample> {
    let (q, nl, area) = match *shape {
        AreaShape::Quad {
            corner,
            edge_u,
            edge_v,
        } => {
            let c = edge_u.cross(edge_v);
            let area = c.length();
            (corner + u.x * edge_u + u.y * edge_v, c / area, area)
        }
        AreaShape::Disk {
            center,
            normal,
            radius,
        } => {
            let n = normal.normalize();
            let d = crate::sampling::sample_concentric_disk(u) * radius;
            let f = Frame::from_normal(n);
            (
                center + f.to_world(Vec3::new(d.x, d.y, 0.0)),
                n,
                PI * radius * radius,
            )
        }
        AreaShape::Sphere { center, radius } => {
            return sample_sphere_cone(center, radius, le, p, u);
        }
        AreaShape::Triangle { a, b, c } => {
            let e = TriangleEmitter::new(a, b, c, le, two_sided)?;
            let s = e.sample(p, u)?;
            return Some(LightSample {
                wi: s.wi,
                distance: s.dist2.sqrt(),
                point: s.point,
                intensity: le * (s.cos_l * e.area / (PI * s.dist2)),
                is_delta: false,
            });
        }
    };
    let d = q - p;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return None;
    }
    let dist = dist2.sqrt();
    let wi = d / dist;
    let cos_l = facing_cosine(nl, wi, two_sided)?;
    Some(LightSample {
        wi,
        distance: dist,
        point: q,
        intensity: le * (cos_l * area / (PI * dist2)),
        is_delta: false,
    })
}

/// The cosine between an emitter's normal `n` and `-wi` (its magnitude when
/// `two_sided`): `None` when the emitter faces away from the point.
#[inline]
fn facing_cosine(n: Vec3, wi: Vec3, two_sided: bool) -> Option<f32> {
    let cos_l = -n.dot(wi);
    let cos_l = if two_sided { cos_l.abs() } else { cos_l };
    if cos_l <= 0.0 { None } else { Some(cos_l) }
}

/// An emissive triangle as a light: sampled uniformly in area, its samples
/// converted to solid angle by `d^2 / cos_l`. [`sample_light`]'s triangle
/// case and the path tracer's emissive-triangle lights both sample it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriangleEmitter {
    pub a: Vec3,
    pub b: Vec3,
    pub c: Vec3,
    /// Unit normal (counter-clockwise front).
    pub n: Vec3,
    pub area: f32,
    /// Emitted radiance.
    pub le: Vec3,
    /// Emits from both faces (otherwise from the front only).
    pub two_sided: bool,
}

/// One sample of a [`TriangleEmitter`] as seen from a point `p`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriangleSample {
    /// Unit direction from `p` towards the sample.
    pub wi: Vec3,
    /// The sample point.
    pub point: Vec3,
    /// Squared distance from `p` to the sample.
    pub dist2: f32,
    /// Cosine at the light between its emitting normal and `-wi` (positive).
    pub cos_l: f32,
}

impl TriangleEmitter {
    /// The triangle `a b c` emitting `le`; `None` when it is degenerate.
    pub fn new(a: Vec3, b: Vec3, c: Vec3, le: Vec3, two_sided: bool) -> Option<Self> {
        let cr = (b - a).cross(c - a);
        let len = cr.length();
        (len > 0.0).then(|| Self {
            a,
            b,
            c,
            n: cr / len,
            area: 0.5 * len,
            le,
            two_sided,
        })
    }

    /// A point uniform in area for `u` in `[0,1)^2`, seen from `p`; `None`
    /// at `p` itself and behind a one-sided emitter.
    #[inline]
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<TriangleSample> {
        let bary = crate::sampling::sample_uniform_triangle(u);
        let q = self.a * bary.x + self.b * bary.y + self.c * (1.0 - bary.x - bary.y);
        let d = q - p;
        let dist2 = d.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let wi = d * (1.0 / dist2.sqrt());
        let cos_l = facing_cosine(self.n, wi, self.two_sided)?;
        Some(TriangleSample {
            wi,
            point: q,
            dist2,
            cos_l,
        })
    }

    /// The solid-angle pdf of sample `s`: `d^2 / (cos_l A)`.
    #[inline]
    pub fn pdf(&self, s: &TriangleSample) -> f32 {
        s.dist2 / (s.cos_l * self.area)
    }
}

/// The solid-angle pdf with which [`sample_light`] samples the direction
/// from `p` towards the point `q` on area light `light` (pbrt-v4's
/// `Light::PDF_Li`); `None` for delta lights and where the light is seen
/// edge-on. For a sphere the pdf of its uniformly sampled cone.
pub fn sample_light_pdf(light: &Light, p: Vec3, q: Vec3) -> Option<f32> {
    let Light::Area { shape, .. } = light else {
        return None;
    };
    match *shape {
        AreaShape::Sphere { center, radius } => {
            let dc2 = (center - p).length_squared();
            let cos_max = (1.0 - radius * radius / dc2).max(0.0).sqrt();
            Some(1.0 / (2.0 * PI * (1.0 - cos_max)).max(1e-12))
        }
        _ => {
            let nl = match *shape {
                AreaShape::Quad { edge_u, edge_v, .. } => edge_u.cross(edge_v).normalize_or_zero(),
                AreaShape::Disk { normal, .. } => normal.normalize_or_zero(),
                AreaShape::Triangle { a, b, c } => (b - a).cross(c - a).normalize_or_zero(),
                AreaShape::Sphere { .. } => Vec3::ZERO,
            };
            let d = q - p;
            let d2 = d.length_squared();
            let cos_l = nl.dot(d / d2.sqrt()).abs();
            (cos_l > 0.0).then(|| d2 / (cos_l * shape.area()))
        }
    }
}

/// Uniform sampling of the cone of directions subtended by a sphere
/// (pbrt-v4 section 6.2.3); the estimate is `Le * solid_angle / pi`.
fn sample_sphere_cone(
    center: Vec3,
    radius: f32,
    le: Vec3,
    p: Vec3,
    u: Vec2,
) -> Option<LightSample> {
    let to_c = center - p;
    let dc2 = to_c.length_squared();
    if dc2 <= radius * radius {
        return None; // inside the light
    }
    let dc = dc2.sqrt();
    let axis = to_c / dc;
    let sin_max2 = radius * radius / dc2;
    let cos_max = (1.0 - sin_max2).max(0.0).sqrt();
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let wi =
        Frame::from_normal(axis).to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t));
    // Distance to the near intersection with the sphere.
    let b = wi.dot(to_c);
    let disc = (b * b - (dc2 - radius * radius)).max(0.0);
    let dist = b - disc.sqrt();
    let solid_angle = 2.0 * PI * (1.0 - cos_max);
    Some(LightSample {
        wi,
        distance: dist,
        point: p + wi * dist,
        intensity: le * (solid_angle / PI),
        is_delta: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Attenuation, Flap};

    fn spot() -> SpotLight {
        SpotLight {
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: Vec3::NEG_Y,
            color: Vec3::ONE,
            intensity: 1.0,
            attenuation: Attenuation::None,
            exponent: 4.0,
            cone_degrees: 30.0,
            cone_softness_degrees: 0.0,
            flaps: vec![],
        }
    }

    #[test]
    fn warn_spot_is_cos_n_inside_cone_and_zero_outside() {
        let s = spot();
        assert!((spot_factor(&s, Vec3::ZERO) - 1.0).abs() < 1e-6);
        let a = 20f32.to_radians();
        let p = Vec3::new(2.0 * a.tan(), 0.0, 0.0);
        assert!((spot_factor(&s, p) - a.cos().powf(4.0)).abs() < 1e-5);
        let b = 31f32.to_radians();
        assert_eq!(spot_factor(&s, Vec3::new(2.0 * b.tan(), 0.0, 0.0)), 0.0);
    }

    #[test]
    fn flaps_clip_the_light() {
        let mut s = spot();
        s.flaps.push(Flap {
            axis: Vec3::X,
            min: -0.1,
            max: 0.5,
        });
        assert!(spot_factor(&s, Vec3::new(0.4, 0.0, 0.0)) > 0.0);
        assert_eq!(spot_factor(&s, Vec3::new(0.6, 0.0, 0.0)), 0.0);
        assert_eq!(spot_factor(&s, Vec3::new(-0.2, 0.0, 0.0)), 0.0);
    }

    #[test]
    fn small_quad_light_matches_point_light() {
        // A tiny quad of radiance Le and area A, facing down, 2 units above:
        // intensity -> Le A / (pi d^2) at normal incidence.
        let e = 1e-3;
        let light = Light::Area {
            shape: AreaShape::Quad {
                corner: Vec3::new(-e, 2.0, -e),
                edge_u: Vec3::new(2.0 * e, 0.0, 0.0),
                edge_v: Vec3::new(0.0, 0.0, 2.0 * e),
            },
            color: Vec3::ONE,
            intensity: 100.0,
            two_sided: false,
        };
        let s = sample_light(&light, Vec3::ZERO, Vec2::splat(0.5)).expect("facing down");
        let expect = 100.0 * 4.0 * e * e / (PI * 4.0);
        assert!(
            (s.intensity.x - expect).abs() < 1e-4 * expect,
            "{} vs {expect}",
            s.intensity.x
        );
        assert!(
            sample_light(&light, Vec3::new(0.0, 4.0, 0.0), Vec2::splat(0.5)).is_none(),
            "one-sided"
        );
    }

    #[test]
    fn sphere_light_integrates_to_closed_form() {
        // Irradiance at a point under a sphere light of radiance Le, straight
        // overhead: E = pi Le sin^2(theta_max); our estimate: mean of
        // pi * intensity * cos over samples.
        let light = Light::Area {
            shape: AreaShape::Sphere {
                center: Vec3::new(0.0, 3.0, 0.0),
                radius: 1.0,
            },
            color: Vec3::ONE,
            intensity: 2.0,
            two_sided: false,
        };
        let k = 64;
        let mut e = 0.0;
        for i in 0..k {
            for j in 0..k {
                let u = Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                let s = sample_light(&light, Vec3::ZERO, u).expect("outside");
                e += PI * s.intensity.x * s.wi.y.max(0.0);
            }
        }
        e /= (k * k) as f32;
        let expect = PI * 2.0 * (1.0f32 / 9.0);
        assert!((e - expect).abs() < 1e-3 * expect * 10.0, "{e} vs {expect}");
    }

    /// For each area shape, [`sample_light_pdf`] at a sample's point is the
    /// pdf implied by the sample's intensity (`Le / (pi * intensity)`, see
    /// [`LightSample::intensity`]).
    #[test]
    fn sample_light_pdf_is_the_pdf_sample_light_draws_with() {
        let shapes = [
            AreaShape::Quad {
                corner: Vec3::new(-0.5, 2.0, -0.3),
                edge_u: Vec3::new(1.0, 0.1, 0.0),
                edge_v: Vec3::new(0.0, 0.0, 0.7),
            },
            AreaShape::Disk {
                center: Vec3::new(0.3, 2.5, 0.1),
                normal: Vec3::new(0.1, -1.0, 0.2),
                radius: 0.4,
            },
            AreaShape::Triangle {
                a: Vec3::new(-0.4, 1.5, -0.2),
                b: Vec3::new(0.2, 1.7, 0.6),
                c: Vec3::new(0.5, 1.6, -0.3),
            },
            AreaShape::Sphere {
                center: Vec3::new(0.2, 3.0, -0.4),
                radius: 0.6,
            },
        ];
        let p = Vec3::new(0.1, 0.0, 0.2);
        for shape in shapes {
            let light = Light::Area {
                shape,
                color: Vec3::ONE,
                intensity: 3.0,
                two_sided: true,
            };
            let le = light.power_rgb().x;
            let mut checked = 0;
            for &u in &[[0.1, 0.2], [0.5, 0.5], [0.9, 0.3], [0.25, 0.8]] {
                let s = sample_light(&light, p, Vec2::from_array(u)).expect("visible");
                let implied = le / (PI * s.intensity.x);
                let pdf = sample_light_pdf(&light, p, s.point).expect("area light");
                assert!(
                    (pdf - implied).abs() <= 1e-4 * implied,
                    "{shape:?} at {u:?}: {pdf} vs {implied}"
                );
                checked += 1;
            }
            assert_eq!(checked, 4);
        }
        let point = Light::Point {
            position: Vec3::Y,
            color: Vec3::ONE,
            intensity: 1.0,
            attenuation: crate::scene::Attenuation::None,
        };
        assert_eq!(sample_light_pdf(&point, Vec3::ZERO, Vec3::Y), None);
    }

    /// `sample_light`'s triangle case is the emitter's sample: the same
    /// direction and point, and intensity `Le / (pi * pdf)`.
    #[test]
    fn triangle_light_samples_through_the_emitter() {
        let (a, b, c) = (
            Vec3::new(-0.4, 1.5, -0.2),
            Vec3::new(0.5, 1.6, -0.3),
            Vec3::new(0.2, 1.7, 0.6),
        );
        let light = Light::Area {
            shape: AreaShape::Triangle { a, b, c },
            color: Vec3::ONE,
            intensity: 2.0,
            two_sided: false,
        };
        let e = TriangleEmitter::new(a, b, c, light.power_rgb(), false).expect("not degenerate");
        let p = Vec3::new(0.1, 0.0, 0.2);
        let u = Vec2::new(0.3, 0.6);
        let s = sample_light(&light, p, u).expect("front");
        let t = e.sample(p, u).expect("front");
        assert_eq!((s.wi, s.point), (t.wi, t.point));
        let expect = e.le.x / (PI * e.pdf(&t));
        assert!((s.intensity.x - expect).abs() <= 1e-5 * expect);
        // One-sided: nothing from above.
        assert!(e.sample(Vec3::new(0.1, 3.0, 0.2), u).is_none());
        assert!(TriangleEmitter::new(a, a, c, Vec3::ONE, false).is_none());
    }
}
