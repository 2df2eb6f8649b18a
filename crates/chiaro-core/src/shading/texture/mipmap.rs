//! Mip-mapping (Williams 1983, "Pyramidal parametrics"): the box-filtered
//! pyramid and trilinear lookups by screen-space footprint.

use super::image::filtered;
use crate::scene::{Filter, ImageTexture};
use glam::{Vec2, Vec4};

/// A mip-map pyramid of an image texture: level 0 is the image, each next
/// level halves both sides (rounding up) by a 2x2 box filter, down to 1x1.
/// Level 0 of an 8-bit image shares the image's codes; the smaller levels
/// are `f32` (their box-filtered values are not 8-bit codes).
#[derive(Debug, Clone, PartialEq)]
pub struct MipMap {
    /// The levels, finest first.
    pub levels: Vec<ImageTexture>,
}

impl MipMap {
    /// Builds the pyramid of `img`. An empty image gives a single empty level
    /// (which samples as white, like [`bilinear`](super::bilinear)).
    pub fn new(img: &ImageTexture) -> Self {
        let mut levels = vec![img.clone()];
        while let Some(prev) = levels.last() {
            if prev.texel_count() == 0 || (prev.width <= 1 && prev.height <= 1) {
                break;
            }
            let (w, h) = (
                prev.width.div_ceil(2).max(1),
                prev.height.div_ceil(2).max(1),
            );
            let mut texels = Vec::with_capacity((w * h) as usize);
            for y in 0..h {
                for x in 0..w {
                    // Average the (up to) 2x2 parent texels; odd edges repeat the last one.
                    let x0 = (2 * x).min(prev.width - 1);
                    let x1 = (2 * x + 1).min(prev.width - 1);
                    let y0 = (2 * y).min(prev.height - 1);
                    let y1 = (2 * y + 1).min(prev.height - 1);
                    let s = Vec4::from(prev.texel(x0, y0))
                        + Vec4::from(prev.texel(x1, y0))
                        + Vec4::from(prev.texel(x0, y1))
                        + Vec4::from(prev.texel(x1, y1));
                    texels.push((s * 0.25).to_array());
                }
            }
            let next = ImageTexture {
                source: prev.source.clone(),
                width: w,
                height: h,
                texels,
                texels8: None,
                ..*prev
            };
            levels.push(next);
        }
        Self { levels }
    }

    /// The bytes the levels hold beyond the image's own texels (level 0 of
    /// an 8-bit image is shared, of an `f32` image a copy).
    pub fn extra_bytes(&self) -> usize {
        let shared = self.levels[0].texels8.is_some();
        self.levels
            .iter()
            .skip(usize::from(shared))
            .map(ImageTexture::texel_bytes)
            .sum()
    }

    /// The level of detail for the screen-space derivatives of the texture
    /// coordinates, `duv_dx` and `duv_dy` (uv units per pixel): `log2` of the
    /// longer footprint side in level-0 texels (OpenGL 4.6 section 8.14.1,
    /// equation 8.7), clamped to `[0, levels - 1]`. Non-finite input gives 0.
    pub fn lod(&self, duv_dx: Vec2, duv_dy: Vec2) -> f32 {
        let base = &self.levels[0];
        let size = Vec2::new(base.width as f32, base.height as f32);
        let rho = (duv_dx * size).length().max((duv_dy * size).length());
        let lod = if rho > 0.0 { rho.log2() } else { 0.0 };
        if !lod.is_finite() {
            return 0.0;
        }
        lod.clamp(0.0, (self.levels.len() - 1) as f32)
    }

    /// Lookup at level of detail `lod` with the image's filters (OpenGL 4.6
    /// section 8.14): `lod <= 0` is magnification (`mag_filter` on level 0);
    /// otherwise `min_filter` within a level, on the nearest level
    /// (`mip_filter` nearest), blended between the two levels around `lod`
    /// (linear: trilinear with linear filters), or on level 0 (no mip-map).
    /// Linear RGBA.
    pub fn sample(&self, uv: Vec2, lod: f32) -> Vec4 {
        let base = &self.levels[0];
        let max = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() {
            lod.clamp(0.0, max)
        } else {
            0.0
        };
        if lod <= 0.0 {
            return filtered(base, uv, base.mag_filter);
        }
        let min = base.min_filter;
        match base.mip_filter {
            None => filtered(base, uv, min),
            Some(Filter::Nearest) => {
                let l = (lod.round() as usize).min(self.levels.len() - 1);
                filtered(&self.levels[l], uv, min)
            }
            Some(Filter::Linear) => {
                let l0 = lod.floor() as usize;
                let f = lod - l0 as f32;
                let a = filtered(&self.levels[l0], uv, min);
                if f <= 0.0 || l0 + 1 >= self.levels.len() {
                    return a;
                }
                a.lerp(filtered(&self.levels[l0 + 1], uv, min), f)
            }
        }
    }

    /// Trilinear lookup with the level chosen from the uv derivatives.
    pub fn sample_footprint(&self, uv: Vec2, duv_dx: Vec2, duv_dy: Vec2) -> Vec4 {
        self.sample(uv, self.lod(duv_dx, duv_dy))
    }
}
