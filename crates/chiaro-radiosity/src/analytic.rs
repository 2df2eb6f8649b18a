//! The analytic form factor: the exact unoccluded point-to-polygon factor
//! (Lambert's contour integral; Baum, Rushmeier and Winget, "Improving
//! Radiosity Solutions Through the Use of Analytically Determined
//! Form-Factors", SIGGRAPH 1989), integrated over the receiver without
//! visibility. The ray-cast method ([`crate::ray_cast`]) uses the same
//! point-to-polygon term and adds visibility rays.

use crate::mesh::Element;
use crate::ray_cast::{PairFormFactor, PairRule};
use glam::Vec3;
use std::f32::consts::TAU;

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

impl<'a> PairFormFactor<'a> {
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

#[cfg(test)]
mod tests {
    use super::*;

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
