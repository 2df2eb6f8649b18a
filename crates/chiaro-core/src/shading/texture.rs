//! Texture evaluation: image textures (bilinear, mip-mapped) and procedural
//! solid textures. Owned by the scan-conversion work (issue 3); the ray
//! tracers call the same functions.

use crate::scene::{ImageTexture, WrapMode};
use glam::{Vec2, Vec4};

/// Wraps a texel coordinate into `0..size`.
#[inline]
pub fn wrap_index(i: i64, size: u32, mode: WrapMode) -> u32 {
    let n = i64::from(size.max(1));
    match mode {
        WrapMode::Repeat => i.rem_euclid(n) as u32,
        WrapMode::Clamp => i.clamp(0, n - 1) as u32,
        WrapMode::Mirror => {
            let m = i.rem_euclid(2 * n);
            (if m < n { m } else { 2 * n - 1 - m }) as u32
        }
    }
}

/// Bilinear lookup of `img` at `uv` (`v = 0` at the top row, as glTF and
/// OBJ-with-flip use), returning linear RGBA.
pub fn bilinear(img: &ImageTexture, uv: Vec2) -> Vec4 {
    if img.texels.is_empty() {
        return Vec4::ONE;
    }
    let x = uv.x * img.width as f32 - 0.5;
    let y = uv.y * img.height as f32 - 0.5;
    if !(x.is_finite() && y.is_finite()) {
        return Vec4::from(img.texels[0]);
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let t = |dx: i64, dy: i64| {
        Vec4::from(img.texel(
            wrap_index(x0 + dx, img.width, img.wrap),
            wrap_index(y0 + dy, img.height, img.wrap),
        ))
    };
    let top = t(0, 0).lerp(t(1, 0), fx);
    let bottom = t(0, 1).lerp(t(1, 1), fx);
    top.lerp(bottom, fy)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap_index(-1, 4, WrapMode::Repeat), 3);
        assert_eq!(wrap_index(5, 4, WrapMode::Clamp), 3);
        assert_eq!(wrap_index(4, 4, WrapMode::Mirror), 3);
        assert_eq!(wrap_index(-1, 4, WrapMode::Mirror), 0);
    }
}
