//! Carpenter's (1984) A-buffer for the scan converter: per sample, a list of
//! the transparent fragments in front of the nearest opaque surface, sorted
//! by depth and composited back to front (Foley et al. 16.5.1).

use crate::gouraud::PolyShading;
use crate::pipeline::shading::{Ctx, SampleResult, shade_sample};
use crate::pipeline::triangles::TriCache;
use crate::pipeline::visibility::{Class, TileVis};
use crate::raster::{RasterTri, Rect, rasterize_window};
use chiaro_core::scene::TransparencyMode;
use chiaro_core::shading::{SampleShare, sanitize};
use glam::{Vec3, Vec3A};

impl TileVis {
    /// The range of `frags` that holds the transparent fragments of sample `i`.
    pub(crate) fn frag_range(&self, i: usize) -> std::ops::Range<usize> {
        if self.start.is_empty() {
            0..0
        } else {
            self.start[i] as usize..self.start[i + 1] as usize
        }
    }
}

/// The fragment lists of one tile: every fragment of the `blend` triangles
/// nearer than the sample's opaque surface (`key`, indexed by `index`), as
/// `(start, frags)` of [`TileVis`] for `n` samples, nearest first per sample.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fragment_lists(
    blend: Vec<&RasterTri>,
    r: Rect,
    win: Rect,
    offsets: &[[i32; 2]],
    n: usize,
    key: &[f32],
    index: impl Fn(u32, u32, usize) -> usize,
) -> (Vec<u32>, Vec<(u32, f32)>) {
    if blend.is_empty() {
        (Vec::new(), Vec::new())
    } else {
        let mut list: Vec<(u32, f32, u32)> = Vec::new();
        for rt in blend {
            rasterize_window(rt, r, win, offsets, |x, y, s, k| {
                let i = index(x, y, s);
                if k > key[i] {
                    list.push((i as u32, k, rt.id));
                }
            });
        }
        list.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
        let mut start = vec![0u32; n + 1];
        for e in &list {
            start[e.0 as usize + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        (start, list.into_iter().map(|e| (e.2, e.1)).collect())
    }
}

/// Composites the transparent fragments of sample `i` (at film position
/// `(sx, sy)`, its pixel's sub-sample `share`) over `r` (what the sample
/// shows behind them), back to front: BLEND coverage, interpolated (the
/// front specular kept whole) or filtered transparency.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn composite<'a, 'b>(
    ctx: &Ctx<'a, '_>,
    poly: &PolyShading,
    tv: &'b TileVis,
    i: usize,
    (sx, sy, share): (f32, f32, SampleShare),
    dir: Vec3A,
    r: &mut SampleResult,
    cache: &mut TriCache<'a>,
    counts_of: impl Fn(usize) -> Option<&'b [i32]>,
) {
    let n = tv.ids.len();
    for f in tv.frag_range(i).rev() {
        let t = tv.frags[f].0;
        let m = ctx.material_of(t);
        let kt = m.transmit.clamp(Vec3::ZERO, Vec3::ONE);
        let interpolated = ctx.class.get(ctx.ps.tri_material[t as usize].index())
            == Some(&Class::Blend(TransparencyMode::Interpolated));
        let td = ctx.tri_data(t, cache, poly);
        let front = shade_sample(
            ctx,
            poly,
            td,
            sx,
            sy,
            dir,
            counts_of(n + f),
            interpolated,
            share,
        );
        let behind = sanitize(r.color);
        r.color = if let Some(kt) = front.coverage_kt {
            // BLEND: I = alpha I_surface + (1 - alpha) I_behind, the
            // first term already premultiplied.
            front.color + kt * behind
        } else if interpolated {
            // Foley et al. 16.5.1: I = (1 - kt) I_front + kt I_behind,
            // with the front surface's specular highlight kept whole.
            (Vec3::ONE - kt) * (front.color - front.specular) + front.specular + kt * behind
        } else {
            // Filtered: I = I_front + kt Ot I_behind.
            front.color + kt * behind
        };
        r.depth = front.depth;
        r.normal = front.normal;
    }
}
