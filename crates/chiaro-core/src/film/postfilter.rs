//! Post-filter anti-aliasing: render once, then remove the aliasing from the
//! image ("render, then remove the aliasing"), an alternative to
//! supersampling selected with `aa = post`.
//!
//! [`fxaa`] follows the structure of Lottes' FXAA 3.11 "quality" filter
//! (NVIDIA white paper, 2009/2011), written from its description:
//! 1. per pixel, the luma contrast of the four neighbours; pixels below
//!    `max(EDGE_MIN, EDGE_THRESHOLD * max luma)` are left untouched;
//! 2. the edge orientation from the 3x3 luma second differences, and the
//!    side (the neighbour with the steepest luma gradient);
//! 3. a search along the edge, both ways, for the ends where the average
//!    luma across the edge changes by a quarter of the gradient;
//! 4. the blend offset: `0.5 - (distance to the nearer end) / edge length`
//!    when the centre's luma varies the right way towards that end, at least
//!    the sub-pixel term `0.75 * smoothstep(|avg3x3 - luma| / range)^2`;
//! 5. a bilinear sample of the colour moved by that offset across the edge.
//!
//! Luma is computed from the colour clamped to `[0, 1]` with the Rec. 601
//! weights and a square root (an approximation of a display gamma), so the
//! edge detection works on perceptual rather than linear differences; the
//! blend itself is in linear radiance.

use super::Film;
use crate::shading::sanitize;
use glam::Vec3;

/// Minimum luma range to process (FXAA's `edgeThresholdMin`, 1/32).
const EDGE_MIN: f32 = 0.0312;
/// Range relative to the local maximum to process (FXAA's `edgeThreshold`).
const EDGE_THRESHOLD: f32 = 0.125;
/// Steps of the edge-end search in each direction.
const SEARCH_STEPS: usize = 12;
/// Sub-pixel aliasing removal strength (FXAA's `subpix`, 0.75).
const SUBPIX: f32 = 0.75;

/// Perceptual luma of a linear colour, in `[0, 1]`.
fn luma(c: Vec3) -> f32 {
    let c = sanitize(c).min(Vec3::ONE);
    c.dot(Vec3::new(0.299, 0.587, 0.114)).max(0.0).sqrt()
}

/// A bilinear sampler over a `width x height` grid, clamped at the borders.
/// Coordinates are continuous pixels: pixel `(x, y)` has its centre at
/// `(x + 0.5, y + 0.5)`.
fn bilinear<T>(data: &[T], w: u32, h: u32, u: f32, v: f32) -> T
where
    T: Copy + std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
{
    let fx = (u - 0.5).clamp(0.0, (w - 1) as f32);
    let fy = (v - 0.5).clamp(0.0, (h - 1) as f32);
    let (x0, y0) = (fx.floor() as u32, fy.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
    let at = |x: u32, y: u32| data[(y * w + x) as usize];
    let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
    let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
    top * (1.0 - ty) + bottom * ty
}

/// FXAA-filtered copy of `film`: colours along luma edges are blended
/// across the edge; flat regions, depth and normals are unchanged. The
/// result is clean (no NaN, no negative channel) whatever the input.
pub fn fxaa(film: &Film) -> Film {
    let (w, h) = (film.width, film.height);
    let mut out = film.clone();
    if w == 0 || h == 0 || film.color.len() != w as usize * h as usize {
        return out;
    }
    let lum: Vec<f32> = film.color.iter().map(|&c| luma(c)).collect();
    let l = |x: i64, y: i64| {
        let x = x.clamp(0, w as i64 - 1) as usize;
        let y = y.clamp(0, h as i64 - 1) as usize;
        lum[y * w as usize + x]
    };
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let m = l(x, y);
            let (n, s, wv, e) = (l(x, y - 1), l(x, y + 1), l(x - 1, y), l(x + 1, y));
            let hi = m.max(n).max(s).max(wv).max(e);
            let lo = m.min(n).min(s).min(wv).min(e);
            let range = hi - lo;
            if range < EDGE_MIN.max(hi * EDGE_THRESHOLD) {
                continue;
            }
            let (nw, ne, sw, se) = (
                l(x - 1, y - 1),
                l(x + 1, y - 1),
                l(x - 1, y + 1),
                l(x + 1, y + 1),
            );
            // Second differences across rows (a horizontal edge) and columns.
            let horz = 2.0 * (n + s - 2.0 * m).abs()
                + (nw + sw - 2.0 * wv).abs()
                + (ne + se - 2.0 * e).abs();
            let vert = 2.0 * (wv + e - 2.0 * m).abs()
                + (nw + ne - 2.0 * n).abs()
                + (sw + se - 2.0 * s).abs();
            let is_horz = horz >= vert;
            // The neighbour across the edge with the steeper gradient.
            let (l1, l2) = if is_horz { (n, s) } else { (wv, e) };
            let (g1, g2) = ((l1 - m).abs(), (l2 - m).abs());
            let (side, l_side) = if g1 >= g2 { (-1.0, l1) } else { (1.0, l2) };
            let gradient_scaled = 0.25 * g1.max(g2);
            let local_avg = 0.5 * (m + l_side);
            // Across-edge step and along-edge step, in pixels.
            let across = if is_horz { (0.0, side) } else { (side, 0.0) };
            let along = if is_horz { (1.0, 0.0) } else { (0.0, 1.0) };
            let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
            let (ex, ey) = (cx + 0.5 * across.0, cy + 0.5 * across.1);
            // Search both ways along the edge for its ends.
            let mut end = [0.0f32; 2];
            let mut dist = [SEARCH_STEPS as f32; 2];
            for (k, dir) in [-1.0f32, 1.0].into_iter().enumerate() {
                for i in 1..=SEARCH_STEPS {
                    let t = i as f32 * dir;
                    let le = bilinear(&lum, w, h, ex + along.0 * t, ey + along.1 * t) - local_avg;
                    end[k] = le;
                    if le.abs() >= gradient_scaled {
                        dist[k] = i as f32 - 0.5;
                        break;
                    }
                }
            }
            let nearer = if dist[0] < dist[1] { 0 } else { 1 };
            let edge_len = dist[0] + dist[1];
            let pixel_offset = 0.5 - dist[nearer] / edge_len.max(1e-6);
            let centre_smaller = m < local_avg;
            let good = (end[nearer] < 0.0) != centre_smaller;
            let edge_offset = if good { pixel_offset.max(0.0) } else { 0.0 };
            // Sub-pixel aliasing term from the 3x3 low-pass luma.
            let avg = (2.0 * (n + s + wv + e) + nw + ne + sw + se) / 12.0;
            let sub1 = ((avg - m).abs() / range).clamp(0.0, 1.0);
            let sub2 = (-2.0 * sub1 + 3.0) * sub1 * sub1;
            let offset = edge_offset.max(sub2 * sub2 * SUBPIX);
            let c = bilinear(
                &film.color,
                w,
                h,
                cx + across.0 * offset,
                cy + across.1 * offset,
            );
            out.set(x as u32, y as u32, c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn film_from(w: u32, h: u32, f: impl Fn(u32, u32) -> Vec3) -> Film {
        let mut film = Film::new(w, h);
        for y in 0..h {
            for x in 0..w {
                film.set(x, y, f(x, y));
            }
        }
        film
    }

    #[test]
    fn flat_regions_are_unchanged() {
        let f = film_from(16, 16, |x, _| Vec3::splat(0.2 + 0.001 * x as f32));
        let g = fxaa(&f);
        assert_eq!(f, g);
    }

    #[test]
    fn hard_diagonal_edge_gets_intermediate_values_only_along_it() {
        // A staircase: white where x > 0.5 y (a shallow slope, the case FXAA
        // is built for), black elsewhere.
        let (w, h) = (48, 24);
        let inside = |x: u32, y: u32| 2 * x > y + 8;
        let f = film_from(
            w,
            h,
            |x, y| {
                if inside(x, y) { Vec3::ONE } else { Vec3::ZERO }
            },
        );
        let g = fxaa(&f);
        assert!(g.is_clean());
        let mut blended = 0;
        for y in 0..h {
            for x in 0..w {
                let v = g.get(x, y).x;
                let near_edge = (0..=2).any(|d| {
                    let (xa, xb) = (x.saturating_sub(d), (x + d).min(w - 1));
                    let (ya, yb) = (y.saturating_sub(d), (y + d).min(h - 1));
                    inside(xa, ya) != inside(xb, yb)
                        || inside(xa, yb) != inside(xb, ya)
                        || inside(x, y) != inside(xa, y)
                        || inside(x, y) != inside(xb, y)
                });
                if near_edge {
                    blended += usize::from(v > 0.02 && v < 0.98);
                } else {
                    assert_eq!(g.get(x, y), f.get(x, y), "({x}, {y}) away from the edge");
                }
            }
        }
        // Each of the 24 rows crosses the edge; most get blended pixels.
        assert!(blended >= 24, "only {blended} blended pixels");
    }

    #[test]
    fn hdr_and_bad_input_give_a_clean_film() {
        let mut f = film_from(8, 8, |x, y| {
            if (x + y) % 2 == 0 {
                Vec3::splat(1e6)
            } else {
                Vec3::ZERO
            }
        });
        f.color[3] = Vec3::NAN; // a writer that forgot to sanitise
        let g = fxaa(&f);
        assert!(g.is_clean());
        assert_eq!(g.depth, f.depth);
    }
}
