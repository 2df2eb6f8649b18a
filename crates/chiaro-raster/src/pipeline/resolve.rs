//! Step 5: resolving the samples of the crop window into the film with the
//! tent filter of [`crate::filter`] (the box filter is applied while shading).

use crate::raster::Rect;
use chiaro_core::film::{Film, TilePixels, TileRect};
use glam::Vec3;

/// Replaces the box-filtered colours of the pixels of `out` (the crop
/// window) by the tent filter of the samples of `region` (the crop window
/// and a one-pixel border, see [`crate::filter::tent_resolve`]); the pixels
/// of the border outside `out` are reset to black with infinite depth.
/// `tiles` are the shaded tiles with their sample colours (indexed like
/// [`TileVis::ids`]).
///
/// [`TileVis::ids`]: crate::pipeline::visibility::TileVis::ids
pub(crate) fn tent_filter(
    film: &mut Film,
    tiles: &[(TileRect, Vec<Vec3>)],
    region: Rect,
    out: Rect,
    offsets: &[[i32; 2]],
) {
    let spp = offsets.len();
    let rw = (region.x1 - region.x0) as usize;
    let rh = (region.y1 - region.y0) as usize;
    let mut samples = vec![Vec3::ZERO; rw * rh * spp];
    for (rect, colors) in tiles {
        let x0 = rect.x.max(region.x0);
        let x1 = (rect.x + rect.width).min(region.x1);
        let y0 = rect.y.max(region.y0);
        let y1 = (rect.y + rect.height).min(region.y1);
        if x0 >= x1 {
            continue;
        }
        let n = (x1 - x0) as usize * spp;
        for y in y0..y1 {
            let src = (((y - rect.y) * rect.width + (x0 - rect.x)) as usize) * spp;
            let dst = (((y - region.y0) as usize) * rw + (x0 - region.x0) as usize) * spp;
            if let (Some(d), Some(s)) = (samples.get_mut(dst..dst + n), colors.get(src..src + n)) {
                d.copy_from_slice(s);
            }
        }
    }
    let sub = crate::raster::SUBPIXEL as f32;
    let pos: Vec<[f32; 2]> = offsets
        .iter()
        .map(|o| [o[0] as f32 / sub, o[1] as f32 / sub])
        .collect();
    let colors = crate::filter::tent_resolve(&samples, region, &pos, out);
    let ow = (out.x1 - out.x0) as usize;
    for y in region.y0..region.y1 {
        for x in region.x0..region.x1 {
            let k = film.index(x, y);
            if (out.x0..out.x1).contains(&x) && (out.y0..out.y1).contains(&y) {
                film.color[k] = colors[((y - out.y0) as usize) * ow + (x - out.x0) as usize];
            } else {
                film.color[k] = Vec3::ZERO;
                film.depth[k] = f32::INFINITY;
                film.normal[k] = Vec3::ZERO;
            }
        }
    }
}

/// Tiles outside the crop window stay black with infinite depth (the
/// shaded tiles overwrite every pixel of theirs): writes them.
pub(crate) fn clear_undrawn(
    film: &mut Film,
    rects: &[TileRect],
    active: &[(usize, TileRect, Rect)],
) {
    let mut drawn = vec![false; rects.len()];
    for &(ti, ..) in active {
        drawn[ti] = true;
    }
    for (&rect, _) in rects.iter().zip(&drawn).filter(|(_, d)| !**d) {
        film.write_tile(&TilePixels::new(rect));
    }
}
