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
#[inline]
pub fn bilinear(img: &ImageTexture, uv: Vec2) -> Vec4 {
    match bilinear_taps(img, uv) {
        Some(taps) => taps.blend(taps.read(img)),
        None => bilinear_off_grid(img),
    }
}

/// The four texels [`bilinear`] reads and its weights between them.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BilinearTaps {
    /// Row-major texel indices: top left, top right, bottom left, bottom
    /// right.
    pub(crate) idx: [usize; 4],
    /// The weight of the right column.
    pub(crate) fx: f32,
    /// The weight of the bottom row.
    pub(crate) fy: f32,
}

impl BilinearTaps {
    /// The four texels, read from `img`. (Spelled out: a `map` closure
    /// was left as a call per lane in the lane loop.)
    #[inline(always)]
    pub(crate) fn read(&self, img: &ImageTexture) -> [[f32; 4]; 4] {
        let i = self.idx;
        [
            img.texel_at(i[0]),
            img.texel_at(i[1]),
            img.texel_at(i[2]),
            img.texel_at(i[3]),
        ]
    }

    /// The lookup's value from the four texels read at `idx`.
    #[inline(always)]
    pub(crate) fn blend(&self, t: [[f32; 4]; 4]) -> Vec4 {
        let t = t.map(Vec4::from);
        let top = t[0].lerp(t[1], self.fx);
        let bottom = t[2].lerp(t[3], self.fx);
        top.lerp(bottom, self.fy)
    }
}

/// Where [`bilinear`] reads `img` at `uv`; `None` where it reads no pair of
/// rows and columns (an image without texels, a coordinate not finite:
/// see [`bilinear_off_grid`]).
#[inline(always)]
pub(crate) fn bilinear_taps(img: &ImageTexture, uv: Vec2) -> Option<BilinearTaps> {
    let x = uv.x * img.width as f32 - 0.5;
    let y = uv.y * img.height as f32 - 0.5;
    if img.texel_count() == 0 || !(x.is_finite() && y.is_finite()) {
        return None;
    }
    let (wrap_u, wrap_v) = img.wrap_uv();
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    // Each axis's two texel indices, wrapped once.
    let xs = [x0, x0 + 1].map(|x| wrap_index(x, img.width, wrap_u));
    let ys = [y0, y0 + 1].map(|y| wrap_index(y, img.height, wrap_v));
    let at = |dx: usize, dy: usize| (ys[dy] * img.width + xs[dx]) as usize;
    Some(BilinearTaps {
        idx: [at(0, 0), at(1, 0), at(0, 1), at(1, 1)],
        fx,
        fy,
    })
}

/// [`bilinear`] where [`bilinear_taps`] finds no texels: white for an
/// image without texels, else the first texel (a coordinate not finite).
#[cold]
pub(crate) fn bilinear_off_grid(img: &ImageTexture) -> Vec4 {
    if img.texel_count() == 0 {
        Vec4::ONE
    } else {
        Vec4::from(img.texel_at(0))
    }
}

/// [`bilinear`] at the coordinates `(u[i], v[i])` of the lanes set in
/// `m` (the others are zero), bit for bit, in three passes over the lanes:
/// the texel indices and weights, the sixteen-or-so independent texel
/// reads (whose cache misses overlap instead of following one another),
/// and the blends.
#[inline(always)]
pub(crate) fn bilinear_lanes<const N: usize>(
    img: &ImageTexture,
    u: &[f32; N],
    v: &[f32; N],
    m: &[bool; N],
) -> [Vec4; N] {
    let mut taps = [BilinearTaps::default(); N];
    let mut on_grid = [false; N];
    for i in 0..N {
        if m[i]
            && let Some(t) = bilinear_taps(img, Vec2::new(u[i], v[i]))
        {
            (taps[i], on_grid[i]) = (t, true);
        }
    }
    let mut texels = [[[0.0f32; 4]; 4]; N];
    for i in 0..N {
        if on_grid[i] {
            texels[i] = taps[i].read(img);
        }
    }
    std::array::from_fn(|i| {
        if on_grid[i] {
            taps[i].blend(texels[i])
        } else if m[i] {
            bilinear_off_grid(img)
        } else {
            Vec4::ZERO
        }
    })
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
