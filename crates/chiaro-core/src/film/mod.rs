//! The film every technique writes: linear RGB `f32` radiance plus depth and
//! normal buffers, and the tiling used to render it in parallel.
//!
//! Tone mapping, palettes and the post filter live in the submodules; file
//! encoding lives in chiaro-io, image metrics in chiaro-tools.

pub mod palette;
pub mod postfilter;
pub mod reconstruction;
pub mod tonemap;

use crate::progress::Progress;
use crate::shading::sanitize;
use glam::Vec3;
use rayon::prelude::*;

/// A rendered image. Pixels are row-major from the top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB radiance; never NaN or infinite (writers sanitise).
    pub color: Vec<Vec3>,
    /// Distance from the eye along the primary ray to the first surface
    /// (scene units), `f32::INFINITY` where nothing was hit.
    pub depth: Vec<f32>,
    /// World-space unit shading normal of the first surface, zero where none.
    pub normal: Vec<Vec3>,
}

impl Film {
    /// A black film with infinite depth.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            color: vec![Vec3::ZERO; n],
            depth: vec![f32::INFINITY; n],
            normal: vec![Vec3::ZERO; n],
        }
    }

    /// Index of pixel `(x, y)`.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// The colour at `(x, y)`.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.color[self.index(x, y)]
    }

    /// Sets pixel `(x, y)`, replacing NaN, infinite or negative channels by 0.
    #[inline]
    pub fn set(&mut self, x: u32, y: u32, c: Vec3) {
        let i = self.index(x, y);
        self.color[i] = sanitize(c);
    }

    /// Copies a rendered tile into the film.
    pub fn write_tile(&mut self, tile: &TilePixels) {
        let r = tile.rect;
        let w = r.width as usize;
        // Row by row, as slices (no per-pixel index arithmetic or bounds checks).
        for y in 0..r.height {
            let src = y as usize * w..(y as usize + 1) * w;
            let d0 = self.index(r.x, r.y + y);
            let dst = d0..d0 + w;
            for (d, &c) in self.color[dst.clone()]
                .iter_mut()
                .zip(&tile.color[src.clone()])
            {
                *d = sanitize(c);
            }
            self.depth[dst.clone()].copy_from_slice(&tile.depth[src.clone()]);
            self.normal[dst].copy_from_slice(&tile.normal[src]);
        }
    }

    /// Mean colour over all pixels.
    pub fn mean(&self) -> Vec3 {
        self.color.iter().copied().sum::<Vec3>() / self.color.len().max(1) as f32
    }

    /// True if every channel of every pixel is finite and non-negative.
    pub fn is_clean(&self) -> bool {
        self.color
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0)
    }
}

/// A rectangle of the film.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// The pixels of one rendered tile.
#[derive(Debug, Clone, PartialEq)]
pub struct TilePixels {
    /// Where it goes.
    pub rect: TileRect,
    /// Row-major colours.
    pub color: Vec<Vec3>,
    /// Row-major depths.
    pub depth: Vec<f32>,
    /// Row-major normals.
    pub normal: Vec<Vec3>,
}

impl TilePixels {
    /// A tile of black pixels with infinite depth.
    pub fn new(rect: TileRect) -> Self {
        let n = rect.width as usize * rect.height as usize;
        Self {
            rect,
            color: vec![Vec3::ZERO; n],
            depth: vec![f32::INFINITY; n],
            normal: vec![Vec3::ZERO; n],
        }
    }
}

/// Splits a `width x height` image into tiles of at most `size x size`,
/// row by row.
pub fn tiles(width: u32, height: u32, size: u32) -> Vec<TileRect> {
    let size = size.max(1);
    let mut out = Vec::new();
    let mut y = 0;
    while y < height {
        let mut x = 0;
        let h = size.min(height - y);
        while x < width {
            let w = size.min(width - x);
            out.push(TileRect {
                x,
                y,
                width: w,
                height: h,
            });
            x += w;
        }
        y += h;
    }
    out
}

/// Renders every tile of the `crop` window (`[x0, y0, x1, y1]`, see
/// `RenderSettings::crop_rect`; the whole image is `[0, 0, width, height]`)
/// in parallel with `render_tile` and assembles the film. Tiles are cut to
/// the window; pixels outside it stay black with infinite depth. Reports
/// one unit of progress per tile under the stage `stage`, and stops with
/// [`crate::error::CoreError::Cancelled`] when the progress asks to. The
/// result does not depend on the number of threads, and every pixel inside
/// a window has its full-render value, as long as `render_tile` depends
/// only on the tile.
pub fn render_tiles<F>(
    width: u32,
    height: u32,
    crop: [u32; 4],
    tile_size: u32,
    stage: &str,
    progress: &dyn Progress,
    render_tile: F,
) -> crate::error::Result<Film>
where
    F: Fn(TileRect) -> TilePixels + Sync,
{
    let [x0, y0, x1, y1] = crop;
    let rects: Vec<TileRect> = tiles(width, height, tile_size)
        .into_iter()
        .filter_map(|t| {
            let (ax, ay) = (t.x.max(x0), t.y.max(y0));
            let (bx, by) = ((t.x + t.width).min(x1), (t.y + t.height).min(y1));
            (ax < bx && ay < by).then(|| TileRect {
                x: ax,
                y: ay,
                width: bx - ax,
                height: by - ay,
            })
        })
        .collect();
    progress.begin(stage, rects.len() as u64);
    // One task per tile: rayon's default splitting leaves a thread running a
    // long unsplit run of tiles alone while the other idles when costs are
    // uneven (a quarter of Whitted's adaptive render; BENCHMARKS.md).
    let done: Vec<Option<TilePixels>> = rects
        .par_iter()
        .with_max_len(1)
        .map(|&r| {
            if progress.cancelled() {
                return None;
            }
            let t = render_tile(r);
            progress.advance(1);
            Some(t)
        })
        .collect();
    let mut film = Film::new(width, height);
    for t in done {
        film.write_tile(&t.ok_or(crate::error::CoreError::Cancelled)?);
    }
    Ok(film)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_image_once() {
        let (w, h) = (37, 23);
        let mut count = vec![0u8; (w * h) as usize];
        for t in tiles(w, h, 8) {
            for y in t.y..t.y + t.height {
                for x in t.x..t.x + t.width {
                    count[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1));
    }

    #[test]
    fn cropped_tiles_match_the_full_render() {
        let shade = |r: TileRect| {
            let mut t = TilePixels::new(r);
            for y in 0..r.height {
                for x in 0..r.width {
                    let (px, py) = (r.x + x, r.y + y);
                    t.color[(y * r.width + x) as usize] = Vec3::new(px as f32, py as f32, 1.0);
                }
            }
            t
        };
        let np = crate::progress::NoProgress;
        let full = render_tiles(30, 20, [0, 0, 30, 20], 8, "t", &np, shade).expect("renders");
        let crop = render_tiles(30, 20, [5, 3, 17, 19], 8, "t", &np, shade).expect("renders");
        for y in 0..20 {
            for x in 0..30 {
                let inside = (5..17).contains(&x) && (3..19).contains(&y);
                let want = if inside { full.get(x, y) } else { Vec3::ZERO };
                assert_eq!(crop.get(x, y), want, "{x},{y}");
            }
        }
    }

    #[test]
    fn set_guards_nan() {
        let mut f = Film::new(2, 2);
        f.set(1, 1, Vec3::new(f32::NAN, 1.0, -2.0));
        assert_eq!(f.get(1, 1), Vec3::new(0.0, 1.0, 0.0));
        assert!(f.is_clean());
    }
}
