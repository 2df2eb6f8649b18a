//! Light samples: direction, distance and the classic intensity factor
//! `f_att * Ip * spot` of each light as seen from a point.

use crate::geometry::Frame;
use crate::scene::{AreaShape, Light, SpotLight};
use crate::shading::texture::{atan2, sin_cos};
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
            // A one-sided quad whose plane faces away lights nothing here
            // (found before the rectangle's set-up, by its sign alone).
            let c = edge_u.cross(edge_v);
            if !two_sided && (p - corner).dot(c) <= 0.0 {
                return None;
            }
            if let Some(rect) = SphericalRectangle::new(corner, edge_u, edge_v, p) {
                return rect.sample(u, p, two_sided, le);
            }
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

/// Rectangles seen under less solid angle than this are sampled uniformly
/// in area: the solid angle is a difference of four corner terms, whose
/// rounding (a few 1e-6 sr at worst) would be 0.1 % of it or more.
const MIN_RECT_SOLID_ANGLE: f32 = 1e-3;

/// Points at least this many half-diagonals from a rectangle's centre
/// sample it uniformly in area, which is then almost as good and cheaper.
/// The single sample stays bounded there: for a planar emitter
/// `cos_l / d^2 = h / d^3` (`h`: the point's distance from the plane), so
/// the area sample's estimate `Le A h / (pi d^3)` over solid-angle
/// sampling's `Le Omega / pi`, where `Omega = int h / d^3 dA >= A h /
/// d_max^3`, is at most `(d_max / d_min)^3`; every point of the rectangle
/// lies within a half-diagonal `R` of its centre, so at `|p - c| >= k R`
/// that is at most `((k + 1) / (k - 1))^3` (`FAR_RECT_ESTIMATE_BOUND`),
/// whatever the orientation.
const FAR_RECT_HALF_DIAGONALS: f32 = 8.0;

/// `((k + 1) / (k - 1))^3` for `k` = [`FAR_RECT_HALF_DIAGONALS`]: how far an
/// area-sampled far rectangle's estimate can exceed `Le Omega / pi`.
#[cfg(test)]
const FAR_RECT_ESTIMATE_BOUND: f32 = {
    let r = (FAR_RECT_HALF_DIAGONALS + 1.0) / (FAR_RECT_HALF_DIAGONALS - 1.0);
    r * r * r
};

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
    /// The `z` components of the normals of the planes through the point
    /// and the edges `y = y0` and `y = y1`.
    b0: f32,
    b1: f32,
    /// `1 - b0^2`, without its cancellation.
    one_minus_b0_sq: f32,
    /// The sampled angle at `u.x = 0`, less `pi` (the paper's `k - pi`).
    phi0: f32,
    /// The solid angle.
    solid_angle: f32,
    /// The point is on the emitting side (`edge_u x edge_v`'s).
    front: bool,
}

impl SphericalRectangle {
    /// The spherical rectangle of the quad `corner + [0,1]^2 (edge_u,
    /// edge_v)` seen from `p`; `None` when the quad is not a rectangle,
    /// `p` lies in its plane, `p` is [`FAR_RECT_HALF_DIAGONALS`] or more
    /// from it, or it subtends less than [`MIN_RECT_SOLID_ANGLE`] (the
    /// caller then samples it by area).
    #[inline]
    fn new(corner: Vec3, edge_u: Vec3, edge_v: Vec3, p: Vec3) -> Option<Self> {
        let half = 0.5 * (edge_u + edge_v);
        let k = FAR_RECT_HALF_DIAGONALS;
        if (corner + half - p).length_squared() >= k * k * half.length_squared() {
            return None;
        }
        let (ex, ey) = (edge_u.length(), edge_v.length());
        if ex <= 0.0 || ey <= 0.0 || edge_u.dot(edge_v).abs() > 1e-4 * ex * ey {
            return None;
        }
        let (x, y) = (edge_u / ex, edge_v / ey);
        let mut z = x.cross(y);
        let d = corner - p;
        let mut z0 = d.dot(z);
        let front = z0 < 0.0;
        if z0 > 0.0 {
            z = -z;
            z0 = -z0;
        }
        if z0 >= 0.0 {
            return None;
        }
        let (x0, y0) = (d.dot(x), d.dot(y));
        let (x1, y1) = (x0 + ex, y0 + ey);
        // The solid angle by inclusion-exclusion of the four corner terms
        // `atan(x y / (h r))` (the rectangle [0, x] x [0, y] at height `h`,
        // corner distance `r`). Girard's sum of the four interior angles
        // less 2 pi is the same (angle `i` is `pi/2 -+ a_i`), but rounds each
        // angle near pi/2 where these terms are small for a rectangle seen
        // near its normal. One shared polynomial `atan2` (libm's `acosf`
        // was a third of the rectangle's cost), within `MAX_ANGLE_ERROR`.
        let (h, z2) = (-z0, z0 * z0);
        let corner_term = |cx: f32, cy: f32| atan2(cx * cy, h * (cx * cx + cy * cy + z2).sqrt());
        let (a00, a01) = (corner_term(x0, y0), corner_term(x0, y1));
        let (a10, a11) = (corner_term(x1, y0), corner_term(x1, y1));
        let solid_angle = (a11 - a10) + (a00 - a01);
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
            b0: -y0 / (z2 + y0 * y0).sqrt(),
            b1: y1 / (z2 + y1 * y1).sqrt(),
            one_minus_b0_sq: z2 / (z2 + y0 * y0),
            phi0: a01 - a00,
            solid_angle,
            front,
        })
    }

    /// The sample of `u` in `[0,1)^2`, uniform in solid angle, of the
    /// rectangle emitting `le` (from its front only unless `two_sided`)
    /// seen from `p`: `None` when its back faces `p` (the whole plane
    /// does, so before any work).
    #[inline]
    fn sample(&self, u: Vec2, p: Vec3, two_sided: bool, le: Vec3) -> Option<LightSample> {
        if !(two_sided || self.front) {
            return None;
        }
        // The x coordinate: the sub-rectangle [x0, xu] covers u.x of the
        // solid angle. The paper's angle is `au = pi + phi`, so its
        // `(cos au b0 - b1) / sin au` is `(cos phi b0 + b1) / sin phi`.
        let (sin_phi, cos_phi) = sin_cos(u.x * self.solid_angle + self.phi0);
        // The paper's `cu = sign(fu) / sqrt(fu^2 + b0^2)` and `xu = -cu z0 /
        // sqrt(1 - cu^2)` in one root: `1 - b0^2` is `z0^2 / (z0^2 + y0^2)`.
        let fu = (cos_phi * self.b0 + self.b1) / sin_phi;
        let den = fu * fu - self.one_minus_b0_sq;
        let xu = if den > 0.0 {
            (-(fu.signum() * self.z0) / den.sqrt()).clamp(self.x0, self.x1)
        } else if fu > 0.0 {
            self.x1
        } else {
            self.x0
        };
        // The y coordinate: uniform in the sine of the elevation along
        // that column.
        let dd2 = xu * xu + self.z0 * self.z0;
        let h0 = self.y0 / (dd2 + self.y0 * self.y0).sqrt();
        let h1 = self.y1 / (dd2 + self.y1 * self.y1).sqrt();
        let hv = h0 + u.y * (h1 - h0);
        let hv2 = hv * hv;
        // `sqrt(dd2 / (1 - hv^2))` is the distance to the sample: `yv` is
        // `hv` times it (unless clamped, when the distance is recomputed).
        let (yv, dist) = if hv2 < 1.0 - 1e-6 {
            let t = (dd2 / (1.0 - hv2)).sqrt();
            let yv = hv * t;
            if yv >= self.y0 && yv <= self.y1 {
                (yv, t)
            } else {
                let yv = yv.clamp(self.y0, self.y1);
                (yv, (dd2 + yv * yv).sqrt())
            }
        } else {
            (self.y1, (dd2 + self.y1 * self.y1).sqrt())
        };
        if dist.is_nan() || dist <= 0.0 {
            return None;
        }
        let local = self.x * xu + self.y * yv + self.z * self.z0;
        let wi = local / dist;
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
        // centre at heights 10 (sampled by area, far), 1, 0.1 and 0.001
        // (in solid angle): the mean of pi * intensity *
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
        for h in [10.0f32, 1.0, 0.1, 0.001] {
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

    /// The solid angle of the rectangle `corner + [0,1]^2 (edge_u, edge_v)`
    /// seen from `p`, in `f64` with libm's `atan`: the four corner terms.
    fn rect_solid_angle_f64(corner: Vec3, edge_u: Vec3, edge_v: Vec3, p: Vec3) -> f64 {
        let v = |a: Vec3| a.to_array().map(f64::from);
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (eu, ev, d) = (v(edge_u), v(edge_v), v(corner - p));
        let (lu, lv) = (dot(eu, eu).sqrt(), dot(ev, ev).sqrt());
        let z = [
            eu[1] * ev[2] - eu[2] * ev[1],
            eu[2] * ev[0] - eu[0] * ev[2],
            eu[0] * ev[1] - eu[1] * ev[0],
        ];
        let h = dot(d, z).abs() / (lu * lv);
        let (x0, y0) = (dot(d, eu) / lu, dot(d, ev) / lv);
        let (x1, y1) = (x0 + lu, y0 + lv);
        let f = |cx: f64, cy: f64| (cx * cy / (h * (cx * cx + cy * cy + h * h).sqrt())).atan();
        f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
    }

    /// A 1 x 1 panel at `y = 0` facing down, `Le = 2`.
    fn panel() -> (Light, Vec3, Vec3, Vec3) {
        let (corner, edge_u, edge_v) = (Vec3::new(-0.5, 0.0, -0.5), Vec3::X, Vec3::Z);
        let light = Light::Area {
            shape: AreaShape::Quad {
                corner,
                edge_u,
                edge_v,
            },
            color: Vec3::ONE,
            intensity: 2.0,
            two_sided: false,
        };
        (light, corner, edge_u, edge_v)
    }

    #[test]
    fn rectangle_solid_angle_is_within_its_bound_of_libm() {
        // Random rectangles and points, near and far, straight under and
        // almost edge-on: the polynomial corner terms' solid angle against
        // f64 libm, within four times the shared `atan2`'s bound plus the
        // rounding of the four terms' sum.
        let bound = 4.0 * f64::from(crate::shading::texture::MAX_ANGLE_ERROR) + 2e-6;
        let (mut worst, mut worst_rel, mut checked) = (0.0f64, 0.0f64, 0);
        for i in 0..20_000u32 {
            let mut rng = crate::sampling::pixel_rng(7, i, 0, 0);
            let mut r = || crate::sampling::uniform(&mut rng);
            let edge_u = Vec3::new(r() + 0.05, 0.3 * r() - 0.15, 0.0);
            let edge_v = edge_u.cross(Vec3::Y).normalize() * (r() + 0.05);
            let corner = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5);
            let scale = 10f32.powf(2.0 * r() - 1.5);
            let p = Vec3::new(r() - 0.5, -r() * r(), r() - 0.5) * scale * 4.0;
            let Some(rect) = SphericalRectangle::new(corner, edge_u, edge_v, p) else {
                continue;
            };
            let exact = rect_solid_angle_f64(corner, edge_u, edge_v, p);
            let err = (f64::from(rect.solid_angle) - exact).abs();
            worst = worst.max(err);
            worst_rel = worst_rel.max(err / exact);
            checked += 1;
        }
        eprintln!("{checked} rectangles: worst error {worst:e} sr, relative {worst_rel:e}");
        assert!(checked > 5_000, "{checked}");
        assert!(worst <= bound, "{worst:e} > {bound:e}");
        assert!(worst_rel <= 1e-3, "relative {worst_rel:e}");
    }

    /// The chi-square statistic of `observed` counts against `expected`.
    fn chi_square(observed: &[f64], expected: &[f64]) -> f64 {
        observed
            .iter()
            .zip(expected)
            .map(|(&o, &e)| (o - e) * (o - e) / e)
            .sum()
    }

    #[test]
    fn rectangle_samples_follow_the_pdf_near_and_far() {
        // Samples binned on the panel in an 8 x 8 grid, against the count
        // that `sample_light_pdf` predicts: `n` times the integral of the
        // pdf over the cell's solid angle (4 x 4 sub-cells, each its exact
        // solid angle times the pdf at its centre). Near points (sampled in
        // solid angle) and far ones (by area).
        let (light, corner, edge_u, edge_v) = panel();
        const CELLS: usize = 8;
        const SUB: usize = 4;
        let n = 200_000u32;
        // Chi-square with 63 degrees of freedom: mean 63, sd 11.2.
        let limit = 63.0 + 6.0 * 126f64.sqrt();
        let points = [
            (Vec3::new(0.3, -0.05, 0.2), true),
            (Vec3::new(0.9, -0.3, 0.0), true),
            (Vec3::new(-0.2, -2.0, 0.4), true),
            (Vec3::new(3.0, -8.0, 2.0), false),
        ];
        for (p, solid) in points {
            assert_eq!(
                SphericalRectangle::new(corner, edge_u, edge_v, p).is_some(),
                solid,
                "{p}"
            );
            let mut observed = vec![0f64; CELLS * CELLS];
            let mut rng = crate::sampling::pixel_rng(11, 0, 0, 0);
            for _ in 0..n {
                let u = crate::sampling::uniform2(&mut rng);
                let s = sample_light(&light, p, u).expect("faces the point");
                let q = s.point - corner;
                let cell = |t: f32| ((t * CELLS as f32) as usize).min(CELLS - 1);
                observed[cell(q.z) * CELLS + cell(q.x)] += 1.0;
            }
            let mut expected = vec![0f64; CELLS * CELLS];
            let (mut area_density, step) = (vec![0f64; CELLS * CELLS], 1.0 / (CELLS * SUB) as f32);
            for j in 0..CELLS * SUB {
                for i in 0..CELLS * SUB {
                    let c = corner + edge_u * (i as f32 * step) + edge_v * (j as f32 * step);
                    let omega = rect_solid_angle_f64(c, edge_u * step, edge_v * step, p);
                    let mid = c + 0.5 * step * (edge_u + edge_v);
                    let pdf = sample_light_pdf(&light, p, mid).expect("area light");
                    let k = (j / SUB) * CELLS + i / SUB;
                    expected[k] += f64::from(n) * omega * f64::from(pdf);
                    area_density[k] += f64::from(n) * f64::from(step * step);
                }
            }
            let total: f64 = expected.iter().sum::<f64>() / f64::from(n);
            assert!(
                (total - 1.0).abs() < 1e-3,
                "{p}: the pdf integrates to {total}"
            );
            let chi2 = chi_square(&observed, &expected);
            assert!(chi2 < limit, "{p}: chi-square {chi2} (limit {limit})");
            // The test tells the two densities apart where they differ.
            if p.y > -1.0 {
                let wrong = chi_square(&observed, &area_density);
                assert!(
                    wrong > 10.0 * limit,
                    "{p}: area density's chi-square {wrong}"
                );
            }
        }
    }

    #[test]
    fn far_rectangle_area_samples_stay_within_their_bound() {
        // From points at least FAR_RECT_HALF_DIAGONALS from the panel's
        // centre, in every direction in front of it, no area sample's
        // estimate exceeds the bound times `Le Omega / pi`; just inside that
        // distance the rectangle is sampled in solid angle.
        let (light, corner, edge_u, edge_v) = panel();
        let (le, r) = (2.0f32, 0.5f32.sqrt());
        let mut rng = crate::sampling::pixel_rng(3, 0, 0, 0);
        for _ in 0..500 {
            let dir =
                crate::sampling::sample_uniform_hemisphere(crate::sampling::uniform2(&mut rng));
            // (y down, in front of the panel; not within 1 degree of its plane.)
            let dir = Vec3::new(dir.x, -dir.z.max(0.02), dir.y).normalize();
            let inside = dir * (0.99 * FAR_RECT_HALF_DIAGONALS * r);
            // (Seen edge-on it may subtend too little: area-sampled too.)
            if rect_solid_angle_f64(corner, edge_u, edge_v, inside) > 1.1e-3 {
                assert!(SphericalRectangle::new(corner, edge_u, edge_v, inside).is_some());
            }
            let p = dir
                * (FAR_RECT_HALF_DIAGONALS * r * (1.0 + 3.0 * crate::sampling::uniform(&mut rng)));
            assert!(
                SphericalRectangle::new(corner, edge_u, edge_v, p).is_none(),
                "{p}"
            );
            let omega = rect_solid_angle_f64(corner, edge_u, edge_v, p) as f32;
            let most = FAR_RECT_ESTIMATE_BOUND * le * omega / PI;
            for _ in 0..16 {
                let u = crate::sampling::uniform2(&mut rng);
                let s = sample_light(&light, p, u).expect("in front");
                assert!(
                    s.intensity.x <= most * 1.0001,
                    "{p}: {} > {most}",
                    s.intensity.x
                );
            }
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
