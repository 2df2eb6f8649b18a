//! 8-bit indexed (palette) images: the magazine series' VGA colour bands and a
//! median-cut quantizer.
//!
//! **VGA bands** (seed 002, "Palette Definition" and "Colours"): the 256
//! palette entries are split into [`MAX_BANDS`] bands of [`BAND_LEVELS`]
//! levels; `make_range` fills a band with a ramp from black through a colour
//! to white, the knee (where black-to-colour turns into colour-to-white) at a
//! chosen fraction. The seed picks the band from the object number; a film
//! carries no object ids, so here a pixel's band is the one whose colour has
//! the nearest *chromaticity* (`rgb / (r + g + b)`, linear) to the pixel's,
//! and its level within the band is the one whose luminance is nearest the
//! pixel's (Rec. 709 luminance of linear values). With more than four band
//! colours, the four that most pixels choose are kept and every pixel picks
//! among those. Bands left unused (fewer than four colours) hold a grey ramp
//! and take part like the others.
//!
//! **Median cut** (Heckbert 1982, "Color image quantization for frame buffer
//! display", SIGGRAPH): the box of all colours is split at the median
//! (by pixel count) along its longest side, always splitting the box with the
//! largest `pixel count * longest side`, until there are `N` boxes or every
//! box holds a single colour; each box's representative is its
//! count-weighted mean. Pixels map to the nearest representative (squared
//! distance in sRGB code values), optionally with Floyd-Steinberg error
//! diffusion (Floyd and Steinberg 1976, weights 7/16, 3/16, 5/16, 1/16,
//! serpentine scan) in sRGB code space.
//!
//! All inputs and outputs here are 8-bit sRGB codes, row-major from the
//! top-left (the output of [`super::tonemap::to_srgb8`]).

use super::tonemap::{linear_to_srgb8, srgb_oetf, srgb8_to_linear_table};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Levels per VGA colour band (the magazine series' "about 64 grey levels").
pub const BAND_LEVELS: usize = 64;
/// Number of VGA colour bands: 256 / 64.
pub const MAX_BANDS: usize = 4;
/// Where each VGA band turns from black-to-colour into colour-to-white, as a
/// fraction of the band (the magazine series' `make_range(..., 0.5)`).
pub const BAND_KNEE: f32 = 0.5;

/// An image of palette indices.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IndexedImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// 8-bit sRGB colours; at most 256.
    pub palette: Vec<[u8; 3]>,
    /// `width * height` indices into `palette`, row-major from the top-left.
    pub indices: Vec<u8>,
}

impl IndexedImage {
    /// The image expanded to 8-bit sRGB colours.
    pub fn to_rgb8(&self) -> Vec<[u8; 3]> {
        self.indices
            .iter()
            .map(|&i| self.palette.get(usize::from(i)).copied().unwrap_or([0; 3]))
            .collect()
    }
}

/// How to turn a true-colour image into an indexed one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "mode", deny_unknown_fields)]
pub enum PaletteMode {
    /// The magazine series' 256-entry palette of up to four black-colour-white bands,
    /// one per colour (linear RGB, e.g. the materials' diffuse colours).
    Vga {
        /// Band colours (linear RGB); up to four are used.
        band_colors: Vec<Vec3>,
    },
    /// Median-cut quantization to at most `colors` (1..=256) colours.
    MedianCut {
        /// Palette size, clamped to `1..=256`.
        colors: usize,
        /// Floyd-Steinberg error diffusion.
        dither: bool,
    },
}

/// Converts an 8-bit sRGB image to an indexed one by `mode`.
///
/// # Panics
/// If `rgb8.len() != width * height`.
pub fn quantize(rgb8: &[[u8; 3]], width: u32, height: u32, mode: &PaletteMode) -> IndexedImage {
    match mode {
        PaletteMode::Vga { band_colors } => vga_palette_image(rgb8, width, height, band_colors),
        PaletteMode::MedianCut { colors, dither } => {
            median_cut(rgb8, width, height, *colors, *dither)
        }
    }
}

/// Fills `palette[start..start + len]` with a ramp from black through
/// `color` (8-bit sRGB codes, as the magazine series' DAC values) to white, linearly
/// interpolated in code values, turning at `knee` (fraction of the range,
/// clamped to `[0, 1]`): entry `start` is black and entry `start + len - 1`
/// is white (for `len >= 2`). Entries past the end of `palette` are skipped.
pub fn make_range(palette: &mut [[u8; 3]], start: usize, len: usize, color: [u8; 3], knee: f32) {
    let knee = if knee.is_finite() {
        knee.clamp(0.0, 1.0)
    } else {
        0.5
    };
    let col = Vec3::new(color[0].into(), color[1].into(), color[2].into());
    for k in 0..len {
        let t = if len > 1 {
            k as f32 / (len - 1) as f32
        } else {
            1.0
        };
        let c = if t <= knee && knee > 0.0 {
            col * (t / knee)
        } else if knee < 1.0 {
            col + (Vec3::splat(255.0) - col) * ((t - knee) / (1.0 - knee)).max(0.0)
        } else {
            col
        };
        if let Some(slot) = palette.get_mut(start + k) {
            let q = c.round().clamp(Vec3::ZERO, Vec3::splat(255.0));
            *slot = [q.x as u8, q.y as u8, q.z as u8];
        }
    }
}

/// A band colour as 8-bit sRGB, scaled so its largest channel is 1 (the band
/// carries hue; brightness comes from the level). Black or invalid colours
/// become white, i.e. a grey band.
fn band_code(color: Vec3) -> [u8; 3] {
    let c = crate::shading::sanitize(color);
    let m = c.max_element();
    let c = if m > 1e-6 { c / m } else { Vec3::ONE };
    [
        linear_to_srgb8(c.x),
        linear_to_srgb8(c.y),
        linear_to_srgb8(c.z),
    ]
}

/// The 256-entry VGA palette for up to [`MAX_BANDS`] band colours (linear
/// RGB; extra colours are ignored, missing bands are grey ramps). Band `b`
/// occupies entries `64 b .. 64 b + 63`, black to white.
pub fn vga_palette(band_colors: &[Vec3]) -> Vec<[u8; 3]> {
    let mut palette = vec![[0u8; 3]; MAX_BANDS * BAND_LEVELS];
    for b in 0..MAX_BANDS {
        let code = band_colors.get(b).map_or([255; 3], |&c| band_code(c));
        make_range(&mut palette, b * BAND_LEVELS, BAND_LEVELS, code, BAND_KNEE);
    }
    palette
}

/// Chromaticity `(r, g) / (r + g + b)` of a linear colour, or `None` for black.
fn chromaticity(c: Vec3) -> Option<(f32, f32)> {
    let s = c.x + c.y + c.z;
    (s > 1e-6).then(|| (c.x / s, c.y / s))
}

/// Rec. 709 / sRGB luminance of a linear colour (ITU-R BT.709).
fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Index of the colour in `bands` whose chromaticity is nearest `c`'s
/// (band 0 for black).
fn nearest_band(c: Vec3, bands: &[(f32, f32)]) -> usize {
    let Some((r, g)) = chromaticity(c) else {
        return 0;
    };
    index_of_least(
        bands
            .iter()
            .map(|&(br, bg)| (r - br).powi(2) + (g - bg).powi(2)),
    )
}

/// The index of the least of `distances` (the first of equals; 0 when
/// there is none below `f32::MAX`).
fn index_of_least(distances: impl Iterator<Item = f32>) -> usize {
    let mut best = (f32::MAX, 0);
    for (i, d) in distances.enumerate() {
        if d < best.0 {
            best = (d, i);
        }
    }
    best.1
}

/// Maps an 8-bit sRGB image to the magazine series' VGA palette ([`vga_palette`]):
/// each pixel picks the band of nearest chromaticity and the level of
/// nearest luminance (see the module docs). With more than four
/// `band_colors` (linear RGB), the four chosen by the most pixels are kept,
/// in order of first appearance in `band_colors`.
///
/// # Panics
/// If `rgb8.len() != width * height`.
pub fn vga_palette_image(
    rgb8: &[[u8; 3]],
    width: u32,
    height: u32,
    band_colors: &[Vec3],
) -> IndexedImage {
    assert_eq!(rgb8.len(), width as usize * height as usize, "image size");
    let table = srgb8_to_linear_table();
    let linear = |p: [u8; 3]| {
        Vec3::new(
            table[usize::from(p[0])],
            table[usize::from(p[1])],
            table[usize::from(p[2])],
        )
    };
    let chroma_of =
        |c: Vec3| chromaticity(crate::shading::sanitize(c)).unwrap_or((1.0 / 3.0, 1.0 / 3.0));

    // Keep the four band colours most pixels would choose.
    let mut colors: Vec<Vec3> = band_colors.to_vec();
    if colors.len() > MAX_BANDS {
        let all: Vec<(f32, f32)> = colors.iter().map(|&c| chroma_of(c)).collect();
        let mut counts = vec![0usize; colors.len()];
        for &p in rgb8 {
            counts[nearest_band(linear(p), &all)] += 1;
        }
        let mut order: Vec<usize> = (0..colors.len()).collect();
        order.sort_by(|&a, &b| counts[b].cmp(&counts[a]).then(a.cmp(&b)));
        order.truncate(MAX_BANDS);
        order.sort_unstable();
        colors = order.iter().map(|&i| colors[i]).collect();
    }
    let palette = vga_palette(&colors);
    // Bands actually in the palette (grey for the padding ones).
    let bands: Vec<(f32, f32)> = (0..MAX_BANDS)
        .map(|b| {
            colors
                .get(b)
                .map_or((1.0 / 3.0, 1.0 / 3.0), |&c| chroma_of(c))
        })
        .collect();
    let level_luma: Vec<f32> = palette.iter().map(|&p| luminance(linear(p))).collect();

    let mut cache: HashMap<[u8; 3], u8> = HashMap::new();
    let indices = rgb8
        .iter()
        .map(|&p| {
            *cache.entry(p).or_insert_with(|| {
                let c = linear(p);
                let band = nearest_band(c, &bands);
                let y = luminance(c);
                let base = band * BAND_LEVELS;
                let level = (0..BAND_LEVELS)
                    .min_by(|&a, &b| {
                        let da = (level_luma[base + a] - y).abs();
                        let db = (level_luma[base + b] - y).abs();
                        da.total_cmp(&db)
                    })
                    .unwrap_or(0);
                (base + level) as u8
            })
        })
        .collect();
    IndexedImage {
        width,
        height,
        palette,
        indices,
    }
}

/// A box of the median-cut: a range of the colour list.
#[derive(Clone, Copy)]
struct CutBox {
    start: usize,
    end: usize,
    pixels: u64,
    /// Longest side (code values) and its channel.
    extent: u8,
    axis: usize,
}

fn make_box(entries: &[([u8; 3], u32)], start: usize, end: usize) -> CutBox {
    let mut lo = [255u8; 3];
    let mut hi = [0u8; 3];
    let mut pixels = 0u64;
    for (c, n) in &entries[start..end] {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
        pixels += u64::from(*n);
    }
    let sides = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let axis = (0..3).max_by_key(|&k| (sides[k], 3 - k)).unwrap_or(0);
    CutBox {
        start,
        end,
        pixels,
        extent: sides[axis],
        axis,
    }
}

/// The median-cut palette of an 8-bit sRGB image: at most `colors`
/// (clamped to `1..=256`) count-weighted box means. An image with at most
/// `colors` distinct colours gets exactly those colours.
pub fn median_cut_palette(rgb8: &[[u8; 3]], colors: usize) -> Vec<[u8; 3]> {
    let colors = colors.clamp(1, 256);
    let mut hist: HashMap<[u8; 3], u32> = HashMap::new();
    for &p in rgb8 {
        *hist.entry(p).or_insert(0) += 1;
    }
    let mut entries: Vec<([u8; 3], u32)> = hist.into_iter().collect();
    // Deterministic order regardless of the hash seed.
    entries.sort_unstable();
    if entries.is_empty() {
        return vec![[0; 3]];
    }
    let mut boxes = vec![make_box(&entries, 0, entries.len())];
    while boxes.len() < colors {
        // Split the box with the largest pixels * longest side.
        let Some((bi, _)) = boxes
            .iter()
            .enumerate()
            .filter(|(_, b)| b.extent > 0)
            .max_by_key(|(i, b)| (b.pixels * u64::from(b.extent), usize::MAX - i))
        else {
            break;
        };
        let b = boxes[bi];
        let slice = &mut entries[b.start..b.end];
        slice.sort_unstable_by_key(|(c, _)| (c[b.axis], *c));
        // Median by pixel count; both halves keep at least one colour.
        let half = b.pixels.div_ceil(2);
        let mut cum = 0u64;
        let mut split = b.end - 1;
        for (i, (_, n)) in slice.iter().enumerate() {
            cum += u64::from(*n);
            if cum >= half {
                split = b.start + i + 1;
                break;
            }
        }
        let split = split.clamp(b.start + 1, b.end - 1);
        boxes[bi] = make_box(&entries, b.start, split);
        boxes.push(make_box(&entries, split, b.end));
    }
    boxes
        .iter()
        .map(|b| {
            let mut sum = [0u64; 3];
            for (c, n) in &entries[b.start..b.end] {
                for k in 0..3 {
                    sum[k] += u64::from(c[k]) * u64::from(*n);
                }
            }
            let p = b.pixels.max(1);
            sum.map(|s| ((s + p / 2) / p) as u8)
        })
        .collect()
}

/// Index of the palette entry nearest `c` (squared distance in code values).
fn nearest_entry(palette: &[[u8; 3]], c: Vec3) -> usize {
    index_of_least(
        palette
            .iter()
            .map(|p| (Vec3::new(p[0].into(), p[1].into(), p[2].into()) - c).length_squared()),
    )
}

/// Maps an 8-bit sRGB image onto a given palette (at most 256 entries, at
/// least one): each pixel takes the nearest entry, or, with `dither`,
/// Floyd-Steinberg error diffusion in code space (serpentine scan), which
/// keeps the mean colour of flat areas.
///
/// # Panics
/// If `rgb8.len() != width * height`, or `palette` is empty or longer than 256.
pub fn map_to_palette(
    rgb8: &[[u8; 3]],
    width: u32,
    height: u32,
    palette: &[[u8; 3]],
    dither: bool,
) -> IndexedImage {
    assert_eq!(rgb8.len(), width as usize * height as usize, "image size");
    assert!(!palette.is_empty() && palette.len() <= 256, "palette size");
    let to_vec = |p: [u8; 3]| Vec3::new(p[0].into(), p[1].into(), p[2].into());
    let indices = if !dither {
        let mut cache: HashMap<[u8; 3], u8> = HashMap::new();
        rgb8.iter()
            .map(|&p| {
                *cache
                    .entry(p)
                    .or_insert_with(|| nearest_entry(palette, to_vec(p)) as u8)
            })
            .collect()
    } else {
        let (w, h) = (width as usize, height as usize);
        let mut out = vec![0u8; w * h];
        // Error carried into the current and the next row.
        let mut cur = vec![Vec3::ZERO; w + 2];
        let mut next = vec![Vec3::ZERO; w + 2];
        for y in 0..h {
            let forward = y % 2 == 0;
            for step in 0..w {
                let x = if forward { step } else { w - 1 - step };
                // Error buffers are offset by one so x - 1 and x + 1 exist.
                let xi = x + 1;
                let want =
                    (to_vec(rgb8[y * w + x]) + cur[xi]).clamp(Vec3::ZERO, Vec3::splat(255.0));
                let i = nearest_entry(palette, want);
                out[y * w + x] = i as u8;
                let err = want - to_vec(palette[i]);
                let (ahead, behind) = if forward {
                    (xi + 1, xi - 1)
                } else {
                    (xi - 1, xi + 1)
                };
                cur[ahead] += err * (7.0 / 16.0);
                next[behind] += err * (3.0 / 16.0);
                next[xi] += err * (5.0 / 16.0);
                next[ahead] += err * (1.0 / 16.0);
            }
            std::mem::swap(&mut cur, &mut next);
            next.fill(Vec3::ZERO);
        }
        out
    };
    IndexedImage {
        width,
        height,
        palette: palette.to_vec(),
        indices,
    }
}

/// Median-cut quantization ([`median_cut_palette`]) of an 8-bit sRGB image
/// to at most `colors` (clamped to `1..=256`) colours, then
/// [`map_to_palette`] with or without dithering. Lossless when the image has
/// at most `colors` distinct colours and `dither` is off (and with it on, as
/// every error is then zero).
///
/// # Panics
/// If `rgb8.len() != width * height`.
pub fn median_cut(
    rgb8: &[[u8; 3]],
    width: u32,
    height: u32,
    colors: usize,
    dither: bool,
) -> IndexedImage {
    let palette = median_cut_palette(rgb8, colors);
    map_to_palette(rgb8, width, height, &palette, dither)
}

/// The 8-bit sRGB code of a linear value (a convenience for band colours).
#[inline]
pub fn srgb8(c: Vec3) -> [u8; 3] {
    let f = |x: f32| (srgb_oetf(x) * 255.0 + 0.5) as u8;
    [f(c.x), f(c.y), f(c.z)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn vga_palette_has_256_entries_black_to_white_bands() {
        let colors = [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.2, 0.6, 0.1)];
        let p = vga_palette(&colors);
        assert_eq!(p.len(), 256);
        for b in 0..MAX_BANDS {
            assert_eq!(p[b * BAND_LEVELS], [0, 0, 0]);
            assert_eq!(p[b * BAND_LEVELS + BAND_LEVELS - 1], [255, 255, 255]);
        }
        // Band 0 passes through pure red at the knee; band 2 is a grey ramp.
        let knee = (BAND_KNEE * (BAND_LEVELS - 1) as f32).round() as usize;
        assert!(
            p[knee][0] > 240 && p[knee][1] < 12 && p[knee][2] < 12,
            "{:?}",
            p[knee]
        );
        let g = p[2 * BAND_LEVELS + 20];
        assert!(g[0] == g[1] && g[1] == g[2]);
    }

    #[test]
    fn make_range_is_the_seeds_ramp() {
        // make_range(256, 0, 0, 64, 64, 0.5) in the seed: a red band at 64..127.
        let mut p = vec![[7u8; 3]; 256];
        make_range(&mut p, 64, 64, [255, 0, 0], 0.5);
        assert_eq!(p[63], [7, 7, 7]);
        assert_eq!(p[128], [7, 7, 7]);
        assert_eq!(p[64], [0, 0, 0]);
        assert_eq!(p[127], [255, 255, 255]);
        // Monotone in every channel.
        for pair in p[64..128].windows(2) {
            assert!((0..3).all(|c| pair[1][c] >= pair[0][c]));
        }
    }

    #[test]
    fn vga_image_picks_band_by_hue_and_level_by_brightness() {
        let red = Vec3::new(0.63, 0.065, 0.05);
        let green = Vec3::new(0.14, 0.45, 0.091);
        let pixels = [
            srgb8(red * 0.2),
            srgb8(red * 0.9),
            srgb8(green * 0.5),
            [0, 0, 0],
        ];
        let img = vga_palette_image(&pixels, 2, 2, &[red, green]);
        let band = |i: usize| usize::from(img.indices[i]) / BAND_LEVELS;
        let level = |i: usize| usize::from(img.indices[i]) % BAND_LEVELS;
        assert_eq!((band(0), band(1), band(2)), (0, 0, 1));
        assert!(level(0) < level(1));
        assert_eq!(level(3), 0);
    }

    #[test]
    fn vga_keeps_the_four_most_used_bands() {
        let hues = [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        // Green is never used: it must be dropped.
        let mut pixels = Vec::new();
        for (i, &h) in hues.iter().enumerate() {
            if i != 1 {
                pixels.extend(std::iter::repeat_n(srgb8(h * 0.5), 4));
            }
        }
        let img = vga_palette_image(&pixels, 4, 4, &hues);
        let knee = (BAND_KNEE * (BAND_LEVELS - 1) as f32).round() as usize;
        let mids: Vec<[u8; 3]> = (0..4)
            .map(|b| img.palette[b * BAND_LEVELS + knee])
            .collect();
        assert!(
            mids.iter().all(|m| !(m[1] > 200 && m[0] < 50 && m[2] < 50)),
            "{mids:?}"
        );
        // Every pixel lands in the band of its own hue.
        let out = img.to_rgb8();
        for (o, i) in out.iter().zip(&pixels) {
            let dom_o = (0..3).max_by_key(|&k| o[k]);
            let dom_i = (0..3).max_by_key(|&k| i[k]);
            assert_eq!(dom_o, dom_i, "{o:?} vs {i:?}");
        }
    }

    #[test]
    fn median_cut_is_lossless_with_few_colours() {
        let mut rng = rand_pcg::Pcg32::seed_from_u64(7);
        let colors: Vec<[u8; 3]> = (0..37)
            .map(|_| [rng.random(), rng.random(), rng.random()])
            .collect();
        let pixels: Vec<[u8; 3]> = (0..32 * 32).map(|i| colors[(i * 7 + i / 5) % 37]).collect();
        for n in [37, 64, 256] {
            for dither in [false, true] {
                let img = median_cut(&pixels, 32, 32, n, dither);
                assert!(img.palette.len() <= n);
                assert_eq!(img.to_rgb8(), pixels, "n {n} dither {dither}");
            }
        }
    }

    #[test]
    fn median_cut_respects_palette_size_and_stays_close() {
        let mut rng = rand_pcg::Pcg32::seed_from_u64(3);
        let pixels: Vec<[u8; 3]> = (0..48 * 48)
            .map(|_| [rng.random(), rng.random::<u8>() / 2, 100])
            .collect();
        let img = median_cut(&pixels, 48, 48, 16, false);
        assert_eq!(img.palette.len(), 16);
        // Mean error well below the spread of random colours (~100 codes).
        let out = img.to_rgb8();
        let err: f32 = out
            .iter()
            .zip(&pixels)
            .map(|(a, b)| {
                (0..3)
                    .map(|k| (f32::from(a[k]) - f32::from(b[k])).abs())
                    .sum::<f32>()
            })
            .sum::<f32>()
            / (3 * pixels.len()) as f32;
        assert!(err < 20.0, "mean abs error {err}");
    }

    #[test]
    fn dithering_preserves_the_mean_of_a_flat_area() {
        let (w, h) = (64u32, 64u32);
        let flat = [100u8, 40, 150]; // inside the palette's convex hull
        let pixels = vec![flat; (w * h) as usize];
        let palette = [[0, 0, 0], [255, 255, 255], [255, 0, 0], [0, 0, 255]];
        let img = map_to_palette(&pixels, w, h, &palette, true);
        let out = img.to_rgb8();
        let mean: [f32; 3] = std::array::from_fn(|k| {
            out.iter().map(|p| f32::from(p[k])).sum::<f32>() / out.len() as f32
        });
        for k in 0..3 {
            assert!(
                (mean[k] - f32::from(flat[k])).abs() < 2.0,
                "channel {k}: {mean:?}"
            );
        }
        // Without dithering every pixel is the same entry: the mean is off.
        let plain = map_to_palette(&pixels, w, h, &palette, false).to_rgb8();
        assert!(plain.iter().all(|p| *p == plain[0]));
    }

    #[test]
    fn quantize_dispatches_by_mode() {
        let m = PaletteMode::MedianCut {
            colors: 16,
            dither: true,
        };
        let img = quantize(&[[1, 2, 3]], 1, 1, &m);
        assert_eq!(img.to_rgb8(), vec![[1, 2, 3]]);
        let v = PaletteMode::Vga {
            band_colors: vec![Vec3::X],
        };
        assert_eq!(quantize(&[[0, 0, 0]], 1, 1, &v).indices, vec![0]);
    }
}
