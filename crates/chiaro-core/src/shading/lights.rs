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
    /// `Le * solid_angle / pi` for spheres and for rectangles sampled in
    /// solid angle), so averaging samples integrates the light.
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
            if let Some(rect) = SphericalRectangle::new(corner, edge_u, edge_v, p) {
                return rect.sample(u, p, c / area, two_sided, le);
            }
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

/// Rectangles seen under less solid angle than this (far away) are
/// sampled uniformly in area: there the two samplings differ little, and
/// the spherical one loses its precision in `f32`.
const MIN_RECT_SOLID_ANGLE: f32 = 1e-3;

/// A rectangular area light as seen from a point: the spherical rectangle
/// it subtends, sampled uniformly in solid angle (Urena, Fajardo and King
/// 2013, "An area-preserving parametrization for spherical rectangles").
/// A sample's estimate is then `Le * solid_angle / pi` at most, however
/// close the point: uniform area sampling's `Le cos A / (pi d^2)` grows
/// without bound for points near the light (speckles on what a ceiling
/// panel almost touches, and on what those points light).
#[derive(Debug, Clone, Copy)]
struct SphericalRectangle {
    /// The local frame: `x`, `y` along the edges, `z` away from the point.
    x: Vec3,
    y: Vec3,
    z: Vec3,
    /// The rectangle's extent in that frame, seen from the point.
    x0: f32,
    x1: f32,
    y0: f32,
    y1: f32,
    /// Its (negative) distance along `z`.
    z0: f32,
    b0: f32,
    b1: f32,
    k: f32,
    /// The solid angle.
    solid_angle: f32,
}

impl SphericalRectangle {
    /// The spherical rectangle of the quad `corner + [0,1]^2 (edge_u,
    /// edge_v)` seen from `p`; `None` when the quad is not a rectangle,
    /// `p` lies in its plane, or it subtends less than
    /// [`MIN_RECT_SOLID_ANGLE`] (the caller then samples it by area).
    fn new(corner: Vec3, edge_u: Vec3, edge_v: Vec3, p: Vec3) -> Option<Self> {
        let (ex, ey) = (edge_u.length(), edge_v.length());
        if ex <= 0.0 || ey <= 0.0 || edge_u.dot(edge_v).abs() > 1e-4 * ex * ey {
            return None;
        }
        let (x, y) = (edge_u / ex, edge_v / ey);
        let mut z = x.cross(y);
        let d = corner - p;
        let mut z0 = d.dot(z);
        if z0 > 0.0 {
            z = -z;
            z0 = -z0;
        }
        if z0 >= 0.0 {
            return None;
        }
        let (x0, y0) = (d.dot(x), d.dot(y));
        let (x1, y1) = (x0 + ex, y0 + ey);
        let v00 = Vec3::new(x0, y0, z0);
        let v01 = Vec3::new(x0, y1, z0);
        let v10 = Vec3::new(x1, y0, z0);
        let v11 = Vec3::new(x1, y1, z0);
        // The normals of the four planes through p and an edge, and the
        // rectangle's interior angles between them (Girard: their sum
        // less 2 pi is the solid angle).
        let n0 = v00.cross(v10).try_normalize()?;
        let n1 = v10.cross(v11).try_normalize()?;
        let n2 = v11.cross(v01).try_normalize()?;
        let n3 = v01.cross(v00).try_normalize()?;
        let angle = |a: Vec3, b: Vec3| (-a.dot(b)).clamp(-1.0, 1.0).acos();
        let (g0, g1, g2, g3) = (angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0));
        let k = 2.0 * PI - g2 - g3;
        let solid_angle = g0 + g1 - k;
        if solid_angle.is_nan() || solid_angle < MIN_RECT_SOLID_ANGLE {
            return None;
        }
        Some(Self {
            x,
            y,
            z,
            x0,
            x1,
            y0,
            y1,
            z0,
            b0: n0.z,
            b1: n2.z,
            k,
            solid_angle,
        })
    }

    /// The sample of `u` in `[0,1)^2`, uniform in solid angle, of the
    /// rectangle of unit normal `nl` emitting `le` (one-sided unless
    /// `two_sided`) seen from `p`: `None` when its back faces `p`.
    fn sample(&self, u: Vec2, p: Vec3, nl: Vec3, two_sided: bool, le: Vec3) -> Option<LightSample> {
        // The x coordinate: the sub-rectangle [x0, xu] covers u.x of the
        // solid angle.
        let au = u.x * self.solid_angle + self.k;
        let (sin_au, cos_au) = au.sin_cos();
        let fu = (cos_au * self.b0 - self.b1) / sin_au;
        let cu = (fu.signum() / (fu * fu + self.b0 * self.b0).sqrt()).clamp(-1.0, 1.0);
        let xu = if cu.abs() < 1.0 {
            (-(cu * self.z0) / (1.0 - cu * cu).sqrt()).clamp(self.x0, self.x1)
        } else if cu > 0.0 {
            self.x1
        } else {
            self.x0
        };
        // The y coordinate: uniform in the sine of the elevation along
        // that column.
        let dd = (xu * xu + self.z0 * self.z0).sqrt();
        let h0 = self.y0 / (dd * dd + self.y0 * self.y0).sqrt();
        let h1 = self.y1 / (dd * dd + self.y1 * self.y1).sqrt();
        let hv = h0 + u.y * (h1 - h0);
        let hv2 = hv * hv;
        let yv = if hv2 < 1.0 - 1e-6 {
            (hv * dd / (1.0 - hv2).sqrt()).clamp(self.y0, self.y1)
        } else {
            self.y1
        };
        let local = self.x * xu + self.y * yv + self.z * self.z0;
        let dist = local.length();
        if dist.is_nan() || dist <= 0.0 {
            return None;
        }
        let wi = local / dist;
        facing_cosine(nl, wi, two_sided)?;
        Some(LightSample {
            wi,
            distance: dist,
            point: p + local,
            intensity: le * (self.solid_angle / PI),
            is_delta: false,
        })
    }
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
/// edge-on. For a sphere the pdf of its uniformly sampled cone; for a
/// rectangle seen under enough solid angle one over that solid angle.
pub fn sample_light_pdf(light: &Light, p: Vec3, q: Vec3) -> Option<f32> {
    let Light::Area { shape, .. } = light else {
        return None;
    };
    // A rectangle seen under enough solid angle is sampled in it.
    if let AreaShape::Quad {
        corner,
        edge_u,
        edge_v,
    } = *shape
        && let Some(rect) = SphericalRectangle::new(corner, edge_u, edge_v, p)
    {
        return Some(1.0 / rect.solid_angle);
    }
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

    /// The form factor from a small area facing a parallel rectangle of
    /// half-sizes `a`, `b` (in units of the distance), straight under its
    /// centre: four corner terms (Howell's catalogue, B-3).
    fn centre_form_factor(a: f64, b: f64) -> f64 {
        let corner = |x: f64, y: f64| {
            let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
            (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / std::f64::consts::TAU
        };
        4.0 * corner(a, b)
    }

    #[test]
    fn rectangle_light_samples_are_bounded_and_integrate_to_closed_form() {
        // A 1 x 1 panel facing down, Le = 2; points straight under its
        // centre at heights 1, 0.1 and 0.001: the mean of pi * intensity *
        // cos is the irradiance pi Le F, and no sample exceeds what the
        // whole hemisphere could give (Le * 2 pi / pi). Uniform area
        // sampling gives samples up to Le A / (pi h^2) = 6e5 at h = 0.001.
        let le = 2.0f32;
        let light = Light::Area {
            shape: AreaShape::Quad {
                corner: Vec3::new(-0.5, 0.0, -0.5),
                edge_u: Vec3::X,
                edge_v: Vec3::Z,
            },
            color: Vec3::ONE,
            intensity: le,
            two_sided: false,
        };
        for h in [1.0f32, 0.1, 0.001] {
            let p = Vec3::new(0.0, -h, 0.0);
            let k = 128;
            let (mut e, mut most) = (0.0f64, 0.0f32);
            for i in 0..k {
                for j in 0..k {
                    let u = Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                    let s = sample_light(&light, p, u).expect("facing the panel");
                    assert!(
                        s.point.y.abs() < 1e-4 && s.point.x.abs() <= 0.5 + 1e-4,
                        "{s:?}"
                    );
                    e += f64::from(PI * s.intensity.x * s.wi.y.max(0.0));
                    most = most.max(s.intensity.x);
                }
            }
            e /= f64::from(k * k);
            let half = 0.5 / f64::from(h);
            let expect = std::f64::consts::PI * f64::from(le) * centre_form_factor(half, half);
            assert!((e - expect).abs() < 2e-3 * expect, "h {h}: {e} vs {expect}");
            assert!(most <= 2.0 * le, "h {h}: a sample of {most}");
        }
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
