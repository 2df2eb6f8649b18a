//! Reconstruction of pixel colours from supersamples: the tent filter.
//!
//! The box filter (the default) is the mean of a pixel's own samples and is
//! computed while shading. The tent (triangle, "Bartlett") filter of radius
//! one pixel weights every sample within one pixel of the pixel centre, in
//! the pixel itself or in one of its eight neighbours, by
//! `max(0, 1 - |dx|) * max(0, 1 - |dy|)` and divides by the sum of the
//! weights (pbrt-v4 section 8.8.1, `TriangleFilter`, with the weighted mean
//! of its equation 5.13). The weights of a pixel therefore sum to one: a
//! constant image stays constant, and an edge is spread over two pixels
//! instead of one.

use crate::raster::Rect;
use glam::Vec3;
use rayon::prelude::*;

/// The tent weight of a sample `(dx, dy)` pixels from a pixel centre:
/// `max(0, 1 - |dx|) * max(0, 1 - |dy|)`, in `[0, 1]`.
#[inline]
pub fn tent_weight(dx: f32, dy: f32) -> f32 {
    (1.0 - dx.abs()).max(0.0) * (1.0 - dy.abs()).max(0.0)
}

/// Resolves supersamples with the tent filter.
///
/// `samples` holds `pos.len()` colours per pixel of `region`, pixel-major in
/// row-major pixel order (`samples[((y - y0) * width + (x - x0)) * spp + s]`);
/// `pos[s]` is the position of sample `s` inside its pixel, in pixels from
/// the pixel's top-left corner (in `[0, 1)^2`). Only samples inside `region`
/// contribute, so pixels on its border use the weights of the samples they
/// have, normalised.
///
/// Returns the colours of the pixels of `out` (row-major, `out` must lie
/// inside `region`); a pixel whose samples all have zero weight (possible
/// only for samples exactly one pixel away) gets the mean of its own samples.
pub fn tent_resolve(samples: &[Vec3], region: Rect, pos: &[[f32; 2]], out: Rect) -> Vec<Vec3> {
    let spp = pos.len().max(1);
    let rw = (region.x1 - region.x0) as usize;
    // weights[(ddy + 1) * 3 + (ddx + 1)][s]: sample s of the neighbour at
    // (ddx, ddy) as seen from the centre (0.5, 0.5) of this pixel.
    let weights: Vec<[f32; 9]> = pos
        .iter()
        .map(|p| {
            let mut w = [0.0; 9];
            for ddy in -1i32..=1 {
                for ddx in -1i32..=1 {
                    w[((ddy + 1) * 3 + ddx + 1) as usize] =
                        tent_weight(ddx as f32 + p[0] - 0.5, ddy as f32 + p[1] - 0.5);
                }
            }
            w
        })
        .collect();
    let ow = (out.x1 - out.x0) as usize;
    let oh = (out.y1 - out.y0) as usize;
    let mut result = vec![Vec3::ZERO; ow * oh];
    if ow == 0 {
        return result;
    }
    let sample = |x: u32, y: u32, s: usize| {
        samples
            .get(((y - region.y0) as usize * rw + (x - region.x0) as usize) * spp + s)
            .copied()
            .unwrap_or(Vec3::ZERO)
    };
    result
        .par_chunks_mut(ow)
        .enumerate()
        .for_each(|(row, line)| {
            let y = out.y0 + row as u32;
            for (col, c) in line.iter_mut().enumerate() {
                let x = out.x0 + col as u32;
                let mut sum = Vec3::ZERO;
                let mut wsum = 0.0f32;
                for ddy in -1i32..=1 {
                    let ny = y as i64 + i64::from(ddy);
                    if ny < i64::from(region.y0) || ny >= i64::from(region.y1) {
                        continue;
                    }
                    for ddx in -1i32..=1 {
                        let nx = x as i64 + i64::from(ddx);
                        if nx < i64::from(region.x0) || nx >= i64::from(region.x1) {
                            continue;
                        }
                        let k = ((ddy + 1) * 3 + ddx + 1) as usize;
                        for (s, w) in weights.iter().enumerate() {
                            if w[k] > 0.0 {
                                sum += w[k] * sample(nx as u32, ny as u32, s);
                                wsum += w[k];
                            }
                        }
                    }
                }
                *c = if wsum > 0.0 {
                    sum / wsum
                } else {
                    (0..spp).map(|s| sample(x, y, s)).sum::<Vec3>() / spp as f32
                };
            }
        });
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{SUBPIXEL, sample_offsets};

    fn positions(spp: u32) -> Vec<[f32; 2]> {
        sample_offsets(spp)
            .iter()
            .map(|o| [o[0] as f32 / SUBPIXEL as f32, o[1] as f32 / SUBPIXEL as f32])
            .collect()
    }

    fn rect(w: u32, h: u32) -> Rect {
        Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        }
    }

    /// Samples of a `w x h` image, coloured by `f(x + px, y + py)` at each
    /// sample position.
    fn image(w: u32, h: u32, pos: &[[f32; 2]], f: impl Fn(f32, f32) -> Vec3) -> Vec<Vec3> {
        let mut v = Vec::new();
        for y in 0..h {
            for x in 0..w {
                for p in pos {
                    v.push(f(x as f32 + p[0], y as f32 + p[1]));
                }
            }
        }
        v
    }

    /// The box filter: the mean of each pixel's own samples.
    fn box_resolve(samples: &[Vec3], spp: usize) -> Vec<Vec3> {
        samples
            .chunks(spp)
            .map(|c| c.iter().sum::<Vec3>() / spp as f32)
            .collect()
    }

    #[test]
    fn tent_weight_is_a_unit_triangle() {
        assert_eq!(tent_weight(0.0, 0.0), 1.0);
        assert_eq!(tent_weight(1.0, 0.0), 0.0);
        assert_eq!(tent_weight(0.0, -1.5), 0.0);
        assert!((tent_weight(0.5, 0.5) - 0.25).abs() < 1e-7);
        assert!((tent_weight(-0.25, 0.0) - 0.75).abs() < 1e-7);
    }

    #[test]
    fn constant_image_resolves_to_the_box_value() {
        for spp in [1, 4, 9, 16] {
            let pos = positions(spp);
            let c = Vec3::new(0.3, 1.7, 0.05);
            let s = image(7, 5, &pos, |_, _| c);
            let tent = tent_resolve(&s, rect(7, 5), &pos, rect(7, 5));
            let bx = box_resolve(&s, pos.len());
            for (t, b) in tent.iter().zip(&bx) {
                assert!((*t - *b).abs().max_element() < 1e-6, "{spp}: {t} vs {b}");
            }
        }
    }

    #[test]
    fn one_sample_per_pixel_is_the_box() {
        // The centre samples of the neighbours are one pixel away: weight 0.
        let pos = positions(1);
        let s = image(6, 4, &pos, |x, y| Vec3::new(x, y, x * y));
        assert_eq!(
            tent_resolve(&s, rect(6, 4), &pos, rect(6, 4)),
            box_resolve(&s, 1)
        );
    }

    #[test]
    fn weights_of_a_pixel_sum_to_one() {
        // The result is linear in the samples: the response of pixel (2, 2)
        // to a unit impulse at each sample is that sample's normalised
        // weight. They sum to one, inside and on the border of the region.
        let pos = positions(4);
        let spp = pos.len();
        let (w, h) = (5u32, 5u32);
        let n = (w * h) as usize * spp;
        for (px, py) in [(2u32, 2u32), (0, 0), (4, 2)] {
            let mut total = 0.0f32;
            let mut nonzero = 0;
            for k in 0..n {
                let mut s = vec![Vec3::ZERO; n];
                s[k] = Vec3::ONE;
                let r = tent_resolve(&s, rect(w, h), &pos, rect(w, h));
                let v = r[(py * w + px) as usize].x;
                assert!(v >= 0.0);
                total += v;
                nonzero += usize::from(v > 0.0);
            }
            assert!((total - 1.0).abs() < 1e-5, "({px}, {py}): {total}");
            // Samples of the neighbours contribute, not only the pixel's own.
            assert!(nonzero > spp, "({px}, {py}): {nonzero}");
        }
    }

    #[test]
    fn hard_edge_spreads_over_more_than_one_pixel_monotonically() {
        // Black left of x = 4, white right of it (a pixel boundary).
        let pos = positions(16);
        let (w, h) = (8u32, 3u32);
        let s = image(w, h, &pos, |x, _| {
            Vec3::splat(if x < 4.0 { 0.0 } else { 1.0 })
        });
        let tent = tent_resolve(&s, rect(w, h), &pos, rect(w, h));
        let bx = box_resolve(&s, pos.len());
        let row = |v: &[Vec3]| -> Vec<f32> { (0..w).map(|x| v[(w + x) as usize].x).collect() };
        let (t, b) = (row(&tent), row(&bx));
        // The box switches between two adjacent pixels; no pixel in between.
        assert_eq!(b.iter().filter(|&&v| v > 0.0 && v < 1.0).count(), 0);
        // The tent has intermediate pixels on both sides of the edge...
        let mid = t.iter().filter(|&&v| v > 1e-4 && v < 1.0 - 1e-4).count();
        assert!(mid >= 2, "{t:?}");
        // ...on both sides of it, and rises monotonically from 0 to 1.
        assert!(t[3] > 0.0 && t[4] < 1.0, "{t:?}");
        for x in 1..w as usize {
            assert!(t[x] >= t[x - 1], "{t:?}");
        }
        assert!(t[0] == 0.0 && (t[7] - 1.0).abs() < 1e-6, "{t:?}");
    }

    #[test]
    fn sub_rectangle_equals_the_same_pixels_of_the_whole() {
        let pos = positions(4);
        let s = image(6, 6, &pos, |x, y| Vec3::new(x.sin(), y.cos(), x * 0.1));
        let whole = tent_resolve(&s, rect(6, 6), &pos, rect(6, 6));
        let out = Rect {
            x0: 1,
            y0: 2,
            x1: 4,
            y1: 5,
        };
        let part = tent_resolve(&s, rect(6, 6), &pos, out);
        for y in out.y0..out.y1 {
            for x in out.x0..out.x1 {
                let a = part[((y - out.y0) * 3 + (x - out.x0)) as usize];
                assert_eq!(a, whole[(y * 6 + x) as usize]);
            }
        }
    }
}
