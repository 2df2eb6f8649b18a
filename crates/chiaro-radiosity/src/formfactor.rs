//! Form factors: the [`FormFactor`] interface every method implements,
//! closed forms for tests, and the quadrature and facing test the
//! methods share. The methods have files of their own: ray casting
//! ([`crate::ray_cast`]), the analytic point-to-polygon factor
//! ([`crate::analytic`]) and the hemicube ([`crate::hemicube`]).
//!
//! Notation: `F_ij` is the fraction of the energy leaving element `i` that
//! arrives at element `j`; reciprocity is `A_i F_ij = A_j F_ji`. Every method
//! computes a *column*: `F_ji` for all receivers `j` and one source `i`,
//! which is what a gathering solver needs for a row of its matrix and what a
//! shooting solver needs to distribute the unshot radiosity of `i`.

use crate::mesh::Element;
use glam::Vec3;

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

/// True if some of `r` lies in front of `s` and some of `s` in front of `r`
/// (a necessary condition for a nonzero form factor between one-sided
/// elements). "In front" means by more than `tol`, or than the rounding
/// error of the plane distance at the elements' coordinates, whichever is
/// larger: two coplanar elements (coincident duplicates, overlapping faces)
/// exchange no light, and far from the origin rounding alone could put a
/// coplanar vertex "in front" by more than a tolerance scaled to the
/// scene's size (issue 47: such pairs kept light bouncing between copies).
#[inline]
pub(crate) fn facing(r: &Element, s: &Element, tol: f32) -> bool {
    let magnitude = r.c.abs().max_element().max(s.c.abs().max_element());
    let tol = tol.max(8.0 * f32::EPSILON * magnitude);
    s.p.iter().any(|&v| r.n.dot(v - r.c) > tol) && r.p.iter().any(|&v| s.n.dot(v - s.c) > tol)
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
}
