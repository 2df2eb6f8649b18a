//! Image texture lookups in one level: texel wrapping, nearest and bilinear
//! filtering.

use crate::scene::{Filter, ImageTexture, WrapMode};
use glam::{Vec2, Vec4};

/// Wraps a texel coordinate into `0..size`.
#[inline]
pub fn wrap_index(i: i64, size: u32, mode: WrapMode) -> u32 {
    let n = i64::from(size.max(1));
    // (Inside the image every mode is the identity: no division.)
    if (0..n).contains(&i) {
        return i as u32;
    }
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
/// OBJ-with-flip use), returning linear RGBA. The image's uv transform is
/// not applied here (see [`eval_texture`](super::eval_texture)).
pub fn bilinear(img: &ImageTexture, uv: Vec2) -> Vec4 {
    if img.texel_count() == 0 {
        return Vec4::ONE;
    }
    let x = uv.x * img.width as f32 - 0.5;
    let y = uv.y * img.height as f32 - 0.5;
    if !(x.is_finite() && y.is_finite()) {
        return Vec4::from(img.texel_at(0));
    }
    let (wrap_u, wrap_v) = img.wrap_uv();
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    // Each axis's two texel indices, wrapped once.
    let xs = [x0, x0 + 1].map(|x| wrap_index(x, img.width, wrap_u));
    let ys = [y0, y0 + 1].map(|y| wrap_index(y, img.height, wrap_v));
    let t = |dx: usize, dy: usize| Vec4::from(img.texel(xs[dx], ys[dy]));
    let top = t(0, 0).lerp(t(1, 0), fx);
    let bottom = t(0, 1).lerp(t(1, 1), fx);
    top.lerp(bottom, fy)
}

/// Nearest-texel lookup of `img` at `uv` (the texel containing it), linear RGBA.
pub fn nearest(img: &ImageTexture, uv: Vec2) -> Vec4 {
    if img.texel_count() == 0 {
        return Vec4::ONE;
    }
    let x = (uv.x * img.width as f32).floor();
    let y = (uv.y * img.height as f32).floor();
    if !(x.is_finite() && y.is_finite()) {
        return Vec4::from(img.texel_at(0));
    }
    let (wrap_u, wrap_v) = img.wrap_uv();
    Vec4::from(img.texel(
        wrap_index(x as i64, img.width, wrap_u),
        wrap_index(y as i64, img.height, wrap_v),
    ))
}

/// A lookup in one level with `filter`.
#[inline]
pub(super) fn filtered(img: &ImageTexture, uv: Vec2, filter: Filter) -> Vec4 {
    match filter {
        Filter::Linear => bilinear(img, uv),
        Filter::Nearest => nearest(img, uv),
    }
}
