//! Step 3: per-tile z-buffer visibility (Catmull 1974) into an item buffer,
//! with screen-door transparency ([`crate::screen_door`]) and the A-buffer's
//! fragment lists ([`crate::abuffer`]).

use crate::abuffer::fragment_lists;
use crate::pipeline::binning::Bins;
use crate::pipeline::vertex::Rays;
use crate::pipeline::{NONE, RasterWork};
use crate::raster::RasterTri;
use crate::raster::{rasterize_window, rasterize_window_masked};
use crate::screen_door;
use crate::shadows::volumes::{VolumeCounting, count_volumes};
use chiaro_core::accel::alpha::Coverage;
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::Progress;
use rayon::prelude::*;
use std::sync::atomic::Ordering;

use crate::raster::Rect;
use chiaro_core::film::TileRect;
use chiaro_core::scene::{Material, RenderSettings, TransparencyMode};

/// How the visibility pass treats a material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Class {
    /// Opaque (or `transmit = 0`).
    Opaque,
    /// Screen-door: covers the samples whose dither threshold is at least `kt`.
    ScreenDoor(f32),
    /// A fragment composited over what is behind it.
    Blend(TransparencyMode),
}

impl Class {
    pub(crate) fn of(m: &Material, settings: &RenderSettings) -> Class {
        if !m.is_transparent() {
            return Class::Opaque;
        }
        match settings.transparency.unwrap_or(m.transparency) {
            TransparencyMode::ScreenDoor => Class::ScreenDoor(screen_door::mask_level(m.transmit)),
            mode => Class::Blend(mode),
        }
    }
}

/// One tile's visibility: the nearest opaque triangle of each sample, the
/// transparent fragments in front of it, and the shadow-volume counts.
pub(crate) struct TileVis {
    pub(crate) rect: TileRect,
    /// The part of the tile inside the crop window: the only pixels drawn.
    pub(crate) window: Rect,
    /// Nearest opaque (or screen-door) triangle per sample.
    pub(crate) ids: Vec<u32>,
    /// Transparent fragments of sample `i`: `frags[start[i]..start[i + 1]]`,
    /// nearest first (empty `start` when there are none).
    pub(crate) start: Vec<u32>,
    /// `(triangle, key)` of each transparent fragment.
    pub(crate) frags: Vec<(u32, f32)>,
    /// Shadow-volume counts, `lights` per point: points are the samples,
    /// then the fragments (empty without shadow volumes).
    pub(crate) counts: Vec<i32>,
}

/// The tiles of `rects` that meet the crop window `crop`, with their part
/// of it.
pub(crate) fn active_tiles(rects: &[TileRect], crop: Rect) -> Vec<(usize, TileRect, Rect)> {
    // Only the tiles that meet the crop window, and only their part of it.
    rects
        .iter()
        .enumerate()
        .filter_map(|(ti, &rect)| {
            let win = Rect {
                x0: rect.x.max(crop.x0),
                y0: rect.y.max(crop.y0),
                x1: (rect.x + rect.width).min(crop.x1),
                y1: (rect.y + rect.height).min(crop.y1),
            };
            (win.x0 < win.x1 && win.y0 < win.y1).then_some((ti, rect, win))
        })
        .collect()
}

/// What step 3 reads: the binned triangles, how each material is drawn, the
/// alpha masks, and the binned shadow-volume polygons to count.
pub(crate) struct Visibility<'a, 's> {
    pub(crate) ps: &'a PreparedScene<'s>,
    /// The triangles binned by step 2, per chunk.
    pub(crate) chunks: &'a [Bins],
    /// Per material: how it is drawn.
    pub(crate) class: &'a [Class],
    /// True when every material is [`Class::Opaque`].
    pub(crate) all_opaque: bool,
    /// MASK: a fragment of a masked triangle whose alpha (at the sample's
    /// point of the triangle) is below the cutoff is discarded.
    pub(crate) coverage: Option<Coverage>,
    /// The eye rays of the samples, for the alpha masks.
    pub(crate) sample_rays: Rays,
    /// The sample positions in a pixel (see [`crate::raster::sample_offsets`]).
    pub(crate) offsets: &'a [[i32; 2]],
    /// Samples per pixel.
    pub(crate) spp: usize,
    /// The binned shadow-volume polygons (shadow volumes only) and the
    /// number of count slots per point.
    pub(crate) vol_bins: Option<Bins>,
    pub(crate) nl: usize,
    pub(crate) counting: VolumeCounting,
    /// Where the work done is counted.
    pub(crate) work: &'a RasterWork,
}

impl Visibility<'_, '_> {
    /// True when the masked triangle `t` is cut out at sample `o` of pixel
    /// `(x, y)`.
    fn cut_out(&self, t: u32, x: u32, y: u32, o: &[i32; 2]) -> bool {
        let (ps, coverage, sample_rays) = (self.ps, &self.coverage, &self.sample_rays);
        let sub = crate::raster::SUBPIXEL as f32;
        let Some(c) = coverage else { return false };
        let (sx, sy) = (x as f32 + o[0] as f32 / sub, y as f32 + o[1] as f32 / sub);
        let dir = sample_rays.dir(sx, sy);
        let [a, b, d] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
        let ray = chiaro_core::geometry::Ray::new(sample_rays.origin(sx, sy).into(), dir);
        match chiaro_core::accel::intersect_triangle(&ray, a, b, d) {
            Some((t_hit, u, v)) => !c.covers(&chiaro_core::accel::Hit {
                t: t_hit,
                prim: t,
                u,
                v,
            }),
            None => false,
        }
    }

    /// How triangle `t`'s material is drawn.
    fn class_of(&self, t: u32) -> Class {
        let (ps, class) = (self.ps, self.class);
        class
            .get(ps.tri_material[t as usize].index())
            .copied()
            .unwrap_or(Class::Opaque)
    }

    /// Step 3 for one tile: the z-buffer (`key`, reused from tile to tile)
    /// and item buffer of its window, its transparent fragments and its
    /// shadow-volume counts.
    fn tile(&self, key: &mut Vec<f32>, ti: usize, rect: TileRect, win: Rect) -> TileVis {
        // Keys are interpolated from the tile's origin whatever the window.
        let r = Rect {
            x0: rect.x,
            y0: rect.y,
            x1: rect.x + rect.width,
            y1: rect.y + rect.height,
        };
        let n = (rect.width * rect.height) as usize * self.spp;
        key.clear();
        key.resize(n, f32::NEG_INFINITY);
        let mut ids = vec![NONE; n];
        let tw = rect.width as usize;
        let index = |x: u32, y: u32, s: usize| {
            (((y - rect.y) as usize) * tw + (x - rect.x) as usize) * self.spp + s
        };
        // Opaque and screen-door surfaces: the z-buffer.
        let mut blend: Vec<&RasterTri> = Vec::new();
        for c in self.chunks {
            for rt in &c.bins[ti] {
                // (No per-triangle material lookup when all are opaque.)
                let class = if self.all_opaque {
                    Class::Opaque
                } else {
                    self.class_of(rt.id)
                };
                let masked = self.coverage.as_ref().is_some_and(|c| c.is_masked(rt.id));
                match class {
                    Class::Opaque if masked => {
                        rasterize_window(rt, r, win, self.offsets, |x, y, s, k| {
                            let i = index(x, y, s);
                            if k > key[i] && !self.cut_out(rt.id, x, y, &self.offsets[s]) {
                                key[i] = k;
                                ids[i] = rt.id;
                            }
                        })
                    }
                    // The depth test as selects, not a branch (see
                    // rasterize_window_masked).
                    Class::Opaque => {
                        rasterize_window_masked(rt, r, win, self.offsets, |x, y, s, k, covered| {
                            let i = index(x, y, s);
                            let nearer = covered & (k > key[i]);
                            key[i] = if nearer { k } else { key[i] };
                            ids[i] = if nearer { rt.id } else { ids[i] };
                        })
                    }
                    Class::ScreenDoor(kt) => {
                        screen_door::draw(rt, r, win, self.offsets, kt, key, &mut ids, index)
                    }
                    Class::Blend(_) => blend.push(rt),
                }
            }
        }
        // Transparent fragments in front of the opaque surface, sorted
        // per sample nearest first.
        let (start, frags) = fragment_lists(blend, r, win, self.offsets, n, key, index);
        let binned: usize = self.chunks.iter().map(|c| c.bins[ti].len()).sum();
        self.work
            .tile_triangles
            .fetch_add(binned as u64, Ordering::Relaxed);
        self.work.samples.fetch_add(n as u64, Ordering::Relaxed);
        self.work
            .fragments
            .fetch_add(frags.len() as u64, Ordering::Relaxed);
        let mut tv = TileVis {
            rect,
            window: win,
            ids,
            start,
            frags,
            counts: Vec::new(),
        };
        if let Some(vb) = &self.vol_bins {
            self.work
                .volume_tile_polygons
                .fetch_add(vb.bins[ti].len() as u64, Ordering::Relaxed);
            count_volumes(
                &mut tv,
                key,
                vb,
                ti,
                r,
                self.offsets,
                self.nl,
                self.counting,
            );
        }
        tv
    }

    /// Step 3: the visibility of every tile of `active`.
    pub(crate) fn run(
        &self,
        active: &[(usize, TileRect, Rect)],
        progress: &dyn Progress,
    ) -> Result<Vec<TileVis>, CoreError> {
        // The depth buffer is only read while its tile is rasterized (and its
        // shadow volumes counted): one per job, reused from tile to tile, stays
        // in cache instead of a fresh one per tile being written out to memory.
        let vis: Vec<Option<TileVis>> = active
            .par_iter()
            .map_init(Vec::new, |key: &mut Vec<f32>, &(ti, rect, win)| {
                if progress.cancelled() {
                    return None;
                }
                let tv = self.tile(key, ti, rect, win);
                progress.advance(1);
                Some(tv)
            })
            .collect();
        vis.into_iter()
            .collect::<Option<Vec<_>>>()
            .ok_or(CoreError::Cancelled)
    }
}
