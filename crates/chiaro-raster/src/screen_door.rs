//! Screen-door transparency for the scan converter (Foley et al. 16.5.1):
//! a transparent surface is drawn into the ordinary z-buffer in a fraction
//! `1 - kt` of the samples, chosen by an 8x8 ordered-dither mask (Bayer
//! 1973), so what lies behind shows through the others.

use crate::raster::{RasterTri, Rect, rasterize_window};
use glam::Vec3;

/// The 8x8 ordered-dither (Bayer) threshold in `(0, 1)` of sample `s` of
/// pixel `(x, y)`: over any 8x8 block each of the 64 values occurs once, so
/// a surface drawn where `threshold >= kt` covers a fraction `1 - kt`.
#[inline]
pub fn dither_threshold(x: u32, y: u32, s: u32) -> f32 {
    const BAYER: [u8; 64] = [
        0, 32, 8, 40, 2, 34, 10, 42, 48, 16, 56, 24, 50, 18, 58, 26, 12, 44, 4, 36, 14, 46, 6, 38,
        60, 28, 52, 20, 62, 30, 54, 22, 3, 35, 11, 43, 1, 33, 9, 41, 51, 19, 59, 27, 49, 17, 57,
        25, 15, 47, 7, 39, 13, 45, 5, 37, 63, 31, 55, 23, 61, 29, 53, 21,
    ];
    // Samples of one pixel use shifted masks so they cover different levels.
    let (xs, ys) = (
        x.wrapping_add(s.wrapping_mul(5)),
        y.wrapping_add(s.wrapping_mul(3)),
    );
    (f32::from(BAYER[((ys % 8) * 8 + xs % 8) as usize]) + 0.5) / 64.0
}

/// The transparency `kt` a screen-door material's mask reproduces: the mean
/// of its transmit colour, clamped to `[0, 1]` (the mask has one level).
pub(crate) fn mask_level(transmit: Vec3) -> f32 {
    let kt = transmit.clamp(Vec3::ZERO, Vec3::ONE);
    (kt.x + kt.y + kt.z) / 3.0
}

/// Draws the screen-door triangle `rt` (mask level `kt`) into a tile's
/// z-buffer `key` and item buffer `ids` (sample `s` of pixel `(x, y)` at
/// `index(x, y, s)`): a sample takes the triangle where it is nearer and
/// its dither threshold is at least `kt`.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn draw(
    rt: &RasterTri,
    rect: Rect,
    window: Rect,
    offsets: &[[i32; 2]],
    kt: f32,
    key: &mut [f32],
    ids: &mut [u32],
    index: impl Fn(u32, u32, usize) -> usize,
) {
    rasterize_window(rt, rect, window, offsets, |x, y, s, k| {
        let i = index(x, y, s);
        if k > key[i] && dither_threshold(x, y, s as u32) >= kt {
            key[i] = k;
            ids[i] = rt.id;
        }
    })
}
