//! Form factors: closed forms for tests, the exact point-to-polygon form
//! factor, and the [`FormFactor`] methods (ray-cast, analytic, and the
//! hemicube in [`crate::hemicube`]).
//!
//! Notation: `F_ij` is the fraction of the energy leaving element `i` that
//! arrives at element `j`; reciprocity is `A_i F_ij = A_j F_ji`. Every method
//! computes a *column*: `F_ji` for all receivers `j` and one source `i`,
//! which is what a gathering solver needs for a row of its matrix and what a
//! shooting solver needs to distribute the unshot radiosity of `i`.

use crate::mesh::Element;
use chiaro_core::accel::Accelerator;
use chiaro_core::geometry::Ray;
use chiaro_core::scene::Light;
use chiaro_core::shading::sample_light;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::TAU;

/// Form factor between two parallel coaxial discs of radii `r1` (emitter)
/// and `r2` at distance `h`: `F_12 = (X - sqrt(X^2 - 4 (R2/R1)^2)) / 2` with
/// `Ri = ri / h`, `X = 1 + (1 + R2^2) / R1^2` (Howell, *A Catalog of
/// Radiation Heat Transfer Configuration Factors*, C-41).
pub fn disc_to_disc(r1: f32, r2: f32, h: f32) -> f32 {
    let (r1, r2, h) = (r1 as f64, r2 as f64, h as f64);
    let (a, b) = (r1 / h, r2 / h);
    let x = 1.0 + (1.0 + b * b) / (a * a);
    (0.5 * (x - (x * x - 4.0 * (b / a) * (b / a)).sqrt())) as f32
}

/// Form factor from a rectangle of width `w` to a perpendicular rectangle of
/// height `h` sharing an edge of length `l` (Howell's catalog, C-14;
/// Siegel and Howell, *Thermal Radiation Heat Transfer*, appendix C).
pub fn perpendicular_rectangles(w: f32, h: f32, l: f32) -> f32 {
    let (w, h) = ((w / l) as f64, (h / l) as f64);
    let (w2, h2) = (w * w, h * h);
    let s = (w2 + h2).sqrt();
    let a = (1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2);
    let b = (w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2))).powf(w2);
    let c = (h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2))).powf(h2);
    let f = (w * (1.0 / w).atan() + h * (1.0 / h).atan() - s * (1.0 / s).atan()
        + 0.25 * (a * b * c).ln())
        / (std::f64::consts::PI * w);
    f as f32
}

/// The exact unoccluded form factor from a differential area at `x` with
/// unit normal `n` to the polygon `poly` (Lambert's contour integral,
/// Baum, Rushmeier and Winget 1989, eq. 4):
/// `F = 1/(2 pi) sum_k gamma_k n . (R_k x R_k+1) / |R_k x R_k+1|`.
/// The polygon is first clipped to the half-space in front of `x`, so a
/// polygon straddling the tangent plane is handled. The caller decides
/// whether the polygon faces `x` (one-sided emitters).
///
/// Returns a value in `[0, 1]`.
pub fn point_to_polygon(x: Vec3, n: Vec3, poly: &[Vec3]) -> f32 {
    let mut clipped = [Vec3::ZERO; 8];
    let mut c = 0usize;
    let len = poly.len().min(6);
    for k in 0..len {
        let (a, b) = (poly[k], poly[(k + 1) % len]);
        let (da, db) = (n.dot(a - x), n.dot(b - x));
        if da > 0.0 && c < 8 {
            clipped[c] = a;
            c += 1;
        }
        if (da > 0.0) != (db > 0.0) && c < 8 {
            clipped[c] = a + (b - a) * (da / (da - db));
            c += 1;
        }
    }
    if c < 3 {
        return 0.0;
    }
    let mut sum = 0.0f32;
    for k in 0..c {
        let r0 = clipped[k] - x;
        let r1 = clipped[(k + 1) % c] - x;
        let cr = r0.cross(r1);
        let l = cr.length();
        if l <= 0.0 || !l.is_finite() {
            continue;
        }
        let gamma = l.atan2(r0.dot(r1));
        sum += gamma * n.dot(cr) / l;
    }
    (sum.abs() / TAU).min(1.0)
}

/// The `m * m` centroids of the uniform subdivision of triangle `p`
/// (equal-area quadrature points), written to `out`; returns how many.
///
/// # Panics
/// If `m > 8`.
pub(crate) fn sub_centroids(p: &[Vec3; 3], m: u32, out: &mut [Vec3; 64]) -> usize {
    let mut n = 0;
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let mf = m as f32;
    for j in 0..m {
        for i in 0..(m - j) {
            let (u, v) = ((i as f32 + 1.0 / 3.0) / mf, (j as f32 + 1.0 / 3.0) / mf);
            out[n] = p[0] + u * e1 + v * e2;
            n += 1;
            if i + j + 1 < m {
                let (u, v) = ((i as f32 + 2.0 / 3.0) / mf, (j as f32 + 2.0 / 3.0) / mf);
                out[n] = p[0] + u * e1 + v * e2;
                n += 1;
            }
        }
    }
    n
}

/// Point-to-point visibility against the scene's geometry.
pub struct Visibility<'a> {
    /// The accelerator over the prepared scene's triangles.
    pub accel: &'a dyn Accelerator,
    /// Offset of ray end points along their normals, scene units.
    pub eps: f32,
}

impl std::fmt::Debug for Visibility<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Visibility")
            .field("eps", &self.eps)
            .finish()
    }
}

impl Visibility<'_> {
    /// True if the segment from `a` (normal `na`) to `b` (normal `nb`) is
    /// free; both ends are lifted off their surfaces by `eps`.
    #[inline]
    pub fn visible(&self, a: Vec3, na: Vec3, b: Vec3, nb: Vec3) -> bool {
        let o = a + na * self.eps;
        let t = b + nb * self.eps;
        !self.accel.occluded(&Ray::segment(o, t))
    }
}

/// True if some of `r` lies in front of `s` and some of `s` in front of `r`
/// (a necessary condition for a nonzero form factor between one-sided
/// elements).
#[inline]
pub(crate) fn facing(r: &Element, s: &Element, tol: f32) -> bool {
    s.p.iter().any(|&v| r.n.dot(v - r.c) > tol) && r.p.iter().any(|&v| s.n.dot(v - s.c) > tol)
}

/// How a form factor is estimated between two elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PairRule {
    /// Receiver quadrature `m` (m*m points) for distant pairs (centroid
    /// distance above ten times the square root of the larger area).
    pub far_m: u32,
    /// Receiver quadrature for pairs in between.
    pub mid_m: u32,
    /// Receiver quadrature for near pairs (centroid distance below four times
    /// the square root of the larger element's area).
    pub near_m: u32,
    /// Visibility samples on the source (`m*m` rays), 0 for none.
    pub vis_m: u32,
}

/// `F_{recv -> src}`: the mean over quadrature points `x` of the receiver of
/// the exact point-to-polygon form factor to `src`, times the fraction of
/// visibility rays from `x` to points of `src` that are unoccluded
/// (area-to-point form factors with ray-cast visibility, after Wallace,
/// Elmquist and Haines 1989, with the exact polygon term in place of the
/// disc approximation).
pub(crate) fn pair(
    recv: &Element,
    src: &Element,
    rule: PairRule,
    vis: Option<&Visibility<'_>>,
    tol: f32,
) -> f32 {
    if !facing(recv, src, tol) {
        return 0.0;
    }
    let size2 = recv.area.max(src.area);
    let d2 = recv.c.distance_squared(src.c);
    let m = if d2 < 16.0 * size2 {
        rule.near_m
    } else if d2 < 100.0 * size2 {
        rule.mid_m
    } else {
        rule.far_m
    };
    let mut xs = [Vec3::ZERO; 64];
    let nx = sub_centroids(&recv.p, m, &mut xs);
    // Visibility: (2 vis_m)^2 points on the source, of which each receiver
    // point tests every fourth (offset by its index), so a large source is
    // probed at many places while each point casts vis_m^2 rays.
    let mut ys = [Vec3::ZERO; 64];
    let ny = match vis {
        Some(_) if rule.vis_m > 0 => sub_centroids(&src.p, (2 * rule.vis_m).min(8), &mut ys),
        _ => 0,
    };
    let mut sum = 0.0;
    for (a, &x) in xs[..nx].iter().enumerate() {
        if src.n.dot(x - src.c) <= 0.0 {
            continue;
        }
        let f = point_to_polygon(x, recv.n, &src.p);
        if f <= 0.0 {
            continue;
        }
        let frac = match vis {
            Some(v) if ny > 0 => {
                let (mut seen, mut tried) = (0u32, 0u32);
                for y in ys[..ny].iter().skip(a % 4).step_by(4) {
                    tried += 1;
                    if recv.n.dot(*y - x) > 0.0 && v.visible(x, recv.n, *y, src.n) {
                        seen += 1;
                    }
                }
                seen as f32 / tried.max(1) as f32
            }
            _ => 1.0,
        };
        sum += f * frac;
    }
    sum / nx as f32
}

/// One way of computing form factors.
pub trait FormFactor: Sync {
    /// Writes `F_ji` (from receiver `j` to source `i`) for every element `j`
    /// into `out` (`out[i] = 0`). Dimensionless, in `[0, 1]`.
    ///
    /// # Panics
    /// If `out.len()` differs from the number of elements.
    fn column(&self, i: usize, out: &mut [f32]);
    /// Writes `F_ji` for every `i` (the row of receiver `j`) into `out` and
    /// returns true, for methods whose natural output is a row (the
    /// hemicube: its rows sum to one); the default returns false and the
    /// matrix is assembled from columns.
    fn row(&self, _j: usize, _out: &mut [f32]) -> bool {
        false
    }
    /// A short name (`"raycast"`, ...).
    fn name(&self) -> &'static str;
}

/// Ray-cast (or, without visibility, analytic) form factors over a list of
/// elements.
pub(crate) struct PairFormFactor<'a> {
    pub elements: &'a [Element],
    pub rule: PairRule,
    pub vis: Option<Visibility<'a>>,
    pub tol: f32,
    pub name: &'static str,
}

impl std::fmt::Debug for PairFormFactor<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PairFormFactor")
            .field("rule", &self.rule)
            .field("name", &self.name)
            .finish()
    }
}

impl<'a> PairFormFactor<'a> {
    /// Ray-cast form factors: 1 receiver point for distant pairs, 4 for
    /// middle ones, 36 for near ones; 4
    /// visibility rays.
    pub fn raycast(elements: &'a [Element], vis: Visibility<'a>, tol: f32) -> Self {
        Self {
            elements,
            rule: PairRule {
                far_m: 1,
                mid_m: 2,
                near_m: 6,
                vis_m: 2,
            },
            vis: Some(vis),
            tol,
            name: "raycast",
        }
    }

    /// Analytic form factors for unoccluded pairs: the exact point-to-polygon
    /// factor integrated over the receiver with 4, 9 or 64 points; no
    /// visibility.
    pub fn analytic(elements: &'a [Element], tol: f32) -> Self {
        Self {
            elements,
            rule: PairRule {
                far_m: 2,
                mid_m: 3,
                near_m: 8,
                vis_m: 0,
            },
            vis: None,
            tol,
            name: "analytic",
        }
    }
}

impl FormFactor for PairFormFactor<'_> {
    fn column(&self, i: usize, out: &mut [f32]) {
        let src = &self.elements[i];
        out.par_iter_mut().enumerate().for_each(|(j, o)| {
            *o = if j == i {
                0.0
            } else {
                pair(
                    &self.elements[j],
                    src,
                    self.rule,
                    self.vis.as_ref(),
                    self.tol,
                )
            };
        });
    }

    fn name(&self) -> &'static str {
        self.name
    }
}

/// Reflected radiance at an element from the point, spot and directional
/// lights (the "first unshot gather"): `rho * sum_l mean_x f_att Ip spot
/// cos_theta V`, over 4 points of the element, with shadow rays. This is
/// `rho / pi` times the irradiance `pi Ip f_att cos / d^2` of the
/// radiometric convention, so it equals what the local techniques and the path tracer
/// give for a Lambertian surface. Area and ambient lights give nothing here.
pub(crate) fn point_light_direct(e: &Element, lights: &[Light], vis: &Visibility<'_>) -> Vec3 {
    if e.rho == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let mut xs = [Vec3::ZERO; 64];
    let nx = sub_centroids(&e.p, 2, &mut xs);
    let mut sum = Vec3::ZERO;
    for light in lights {
        if matches!(light, Light::Ambient { .. } | Light::Area { .. }) {
            continue;
        }
        for &x in &xs[..nx] {
            let Some(s) = sample_light(light, x, Vec2::splat(0.5)) else {
                continue;
            };
            let cos = s.wi.dot(e.n);
            if cos <= 0.0 {
                continue;
            }
            let o = x + e.n * vis.eps;
            let target = if s.distance.is_finite() {
                s.point
            } else {
                x + s.wi * 1.0e6
            };
            if vis.accel.occluded(&Ray::segment(o, target)) {
                continue;
            }
            sum += s.intensity * cos;
        }
    }
    e.rho * sum / nx as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_forms_known_values() {
        // Unit squares at right angles sharing an edge: 0.2000 (Howell C-14).
        assert!((perpendicular_rectangles(1.0, 1.0, 1.0) - 0.20004).abs() < 1e-4);
        // Equal discs, radius = distance: (3 - sqrt 5) / 2 = 0.38197.
        assert!((disc_to_disc(1.0, 1.0, 1.0) - 0.381966).abs() < 1e-5);
    }

    #[test]
    fn point_to_polygon_matches_disc_formula_and_clips() {
        // A point under the centre of a coaxial disc of radius r at height h
        // sees F = r^2 / (h^2 + r^2); use a fine polygon.
        let (r, h) = (1.0f32, 2.0f32);
        let poly: Vec<Vec3> = (0..6)
            .map(|i| {
                let a = i as f32 / 6.0 * TAU;
                Vec3::new(a.cos(), a.sin(), h) * Vec3::new(r, r, 1.0)
            })
            .collect();
        // Hexagon area / disc area ratio: compare to a disc of equal area.
        let hex_area = 1.5 * 3f32.sqrt() * r * r;
        let r_eq = (hex_area / std::f32::consts::PI).sqrt();
        let f = point_to_polygon(Vec3::ZERO, Vec3::Z, &poly);
        let expect = r_eq * r_eq / (h * h + r_eq * r_eq);
        assert!((f - expect).abs() < 0.01, "{f} vs {expect}");
        // A polygon entirely behind the point's plane contributes nothing.
        let below: Vec<Vec3> = poly.iter().map(|p| Vec3::new(p.x, p.y, -h)).collect();
        assert_eq!(point_to_polygon(Vec3::ZERO, Vec3::Z, &below), 0.0);
        // An infinite-ish plane straddling the tangent plane: half of it is seen.
        let big = [
            Vec3::new(-1e3, 1.0, -1e3),
            Vec3::new(1e3, 1.0, -1e3),
            Vec3::new(1e3, 1.0, 1e3),
            Vec3::new(-1e3, 1.0, 1e3),
        ];
        let f = point_to_polygon(Vec3::ZERO, Vec3::Z, &big);
        assert!((f - 0.5).abs() < 0.01, "{f}");
    }
}
