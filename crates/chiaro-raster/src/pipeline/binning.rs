//! Step 2: triangle setup and binning of the screen triangles into 64x64
//! tiles (sort-middle tiling, Molnar et al. 1994).

use crate::pipeline::TILE_SIZE;
use crate::pipeline::vertex::ScreenVertex;
use crate::raster::Viewport;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{PixelFilter, RenderSettings};
use glam::Mat4;
use rayon::prelude::*;

use crate::raster::{RasterTri, Rect};

/// Bins screen triangles into the tiles that meet the crop window.
#[derive(Clone, Copy)]
pub(crate) struct Binner {
    pub(crate) crop: Rect,
    pub(crate) tiles_x: u32,
    pub(crate) ntiles: usize,
}

impl Binner {
    pub(crate) fn empty(&self) -> Vec<Vec<RasterTri>> {
        vec![Vec::new(); self.ntiles]
    }

    /// The number of bins [`Self::bin`] puts `rt` in.
    pub(crate) fn copies(&self, rt: &RasterTri) -> u64 {
        match self.tile_range(rt) {
            Some([tx0, ty0, tx1, ty1]) => u64::from(tx1 - tx0 + 1) * u64::from(ty1 - ty0 + 1),
            None => 0,
        }
    }

    /// The tiles `[tx0, ty0, tx1, ty1]` (inclusive) whose part of the crop
    /// window the bounding box of `rt` meets, if any.
    #[inline]
    pub(crate) fn tile_range(&self, rt: &RasterTri) -> Option<[u32; 4]> {
        let b = rt.pixel_bounds();
        let c = self.crop;
        if b[2] < c.x0 as i32 || b[3] < c.y0 as i32 || b[0] >= c.x1 as i32 || b[1] >= c.y1 as i32 {
            return None;
        }
        Some([
            (b[0].max(c.x0 as i32) as u32) / TILE_SIZE,
            (b[1].max(c.y0 as i32) as u32) / TILE_SIZE,
            (b[2].min(c.x1 as i32 - 1) as u32) / TILE_SIZE,
            (b[3].min(c.y1 as i32 - 1) as u32) / TILE_SIZE,
        ])
    }

    /// Appends a copy of `rt` to the bin of every tile whose part of the
    /// crop window the bounding box of `rt` meets.
    #[inline]
    pub(crate) fn bin(&self, rt: &RasterTri, bins: &mut [Vec<RasterTri>]) {
        let Some([tx0, ty0, tx1, ty1]) = self.tile_range(rt) else {
            return;
        };
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                bins[(ty * self.tiles_x + tx) as usize].push(*rt);
            }
        }
    }
}

/// Triangles binned to tiles: `bins[tile]` holds, in setup order, a copy
/// of every triangle that meets the tile. Copies rather than indices into
/// one array of the chunk's triangles: the visibility pass then reads each
/// tile's triangles as one contiguous run, where through indices it
/// gathered every few triangles of an array of them all (set up long before
/// and no longer in cache), a cache miss per triangle. Most triangles of a
/// large mesh meet one tile, so the copies cost little more memory.
pub(crate) struct Bins {
    pub(crate) bins: Vec<Vec<RasterTri>>,
}

/// The crop window of the film, the window whose samples are shaded (with
/// the tent filter one pixel larger), and whether the tent filter resolves
/// the samples (`out_crop`, `crop`, `tent`).
pub(crate) fn crop_windows(settings: &RenderSettings, spp: u32) -> (Rect, Rect, bool) {
    let (w, h) = (settings.width, settings.height);
    let [cx0, cy0, cx1, cy1] = settings.crop_rect();
    let out_crop = Rect {
        x0: cx0,
        y0: cy0,
        x1: cx1,
        y1: cy1,
    };
    // The tent filter reads the samples of the pixels around each pixel:
    // shade a one-pixel border around the crop window too, so that a pixel
    // of a crop window has its value in the full image.
    let tent = matches!(settings.filter, PixelFilter::Tent | PixelFilter::Gaussian) && spp > 1;
    let crop = if tent && out_crop.x0 < out_crop.x1 && out_crop.y0 < out_crop.y1 {
        Rect {
            x0: out_crop.x0.saturating_sub(1),
            y0: out_crop.y0.saturating_sub(1),
            x1: (out_crop.x1 + 1).min(w),
            y1: (out_crop.y1 + 1).min(h),
        }
    } else {
        out_crop
    };
    (out_crop, crop, tent)
}

/// Step 2: setup and binning over fixed chunks of triangles (deterministic
/// order), into the tiles that meet the crop window: per chunk, the bins.
/// `hidden[o]`: no camera ray reaches the back faces of object `o` (empty
/// unless `cull_backfaces`).
pub(crate) fn bin_triangles(
    ps: &PreparedScene<'_>,
    hidden: &[bool],
    verts: &[ScreenVertex],
    binner: &Binner,
    vp_cull: &Viewport,
    vp_all: &Viewport,
    clip_from_world: Mat4,
) -> Vec<Bins> {
    let scene = ps.scene;
    let crop = binner.crop;
    let cull_material: Vec<bool> = scene
        .materials
        .iter()
        // The backs the ray techniques' camera rays skip too (`Sidedness::Culled`).
        .map(|m| !m.sidedness.eye_sees_back())
        .collect();
    let nt = ps.triangles.len();
    let chunk = nt.div_ceil(256).max(4096);
    if crop.x0 >= crop.x1 || crop.y0 >= crop.y1 {
        Vec::new()
    } else {
        ps.triangles
            .par_chunks(chunk)
            .enumerate()
            .map(|(ci, tris)| {
                // The screen triangles of one source triangle.
                let mut out = Vec::new();
                let mut scratch = Vec::new();
                let mut bins = binner.empty();
                for (k, tri) in tris.iter().enumerate() {
                    out.clear();
                    let t = (ci * chunk + k) as u32;
                    let cull = cull_material
                        .get(ps.tri_material[t as usize].index())
                        .copied()
                        .unwrap_or(false)
                        || hidden
                            .get(ps.tri_object[t as usize] as usize)
                            .copied()
                            .unwrap_or(false);
                    let vp = if cull { vp_cull } else { vp_all };
                    let v = tri.map(|i| &verts[i as usize]);
                    if v[0].inside && v[1].inside && v[2].inside {
                        vp.emit(
                            [v[0].xy, v[1].xy, v[2].xy],
                            [v[0].key, v[1].key, v[2].key],
                            t,
                            &mut out,
                        );
                    } else {
                        // The clip-space corners again (the vertex pass's
                        // product, bit for bit) for the clipper: few
                        // triangles get here, so the vertices do not keep them.
                        let clip =
                            tri.map(|i| clip_from_world * ps.positions[i as usize].extend(1.0));
                        vp.setup(clip, t, &mut scratch, &mut out);
                    }
                    for rt in &out {
                        binner.bin(rt, &mut bins);
                    }
                }
                Bins { bins }
            })
            .collect()
    }
}
