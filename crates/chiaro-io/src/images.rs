//! Decoding image files into linear texels: PNG (8/16-bit), JPEG and
//! Radiance HDR through the `image` crate, OpenEXR through the `exr` crate.
//!
//! - 8- and 16-bit **colour** textures are sRGB-encoded: with `srgb = true`
//!   the sRGB EOTF (IEC 61966-2-1) turns them linear. Data textures (normal
//!   and bump maps, roughness) pass `srgb = false` and get `code / max`.
//! - 8-bit textures keep their codes (four bytes a texel) and are decoded at
//!   each lookup to the same `f32` values (`ImageTexture::texels8`); 16-bit
//!   and float images are held as linear `f32`.
//! - HDR and EXR files hold linear floats already and are read as they are.
//! - Alpha is always linear, 1 where the file has none.
//! - NaN, infinite and negative colour values (possible in HDR/EXR files) are
//!   read as 0; alpha is clamped to `[0, 1]`.
//! - Images wider or taller than [`MAX_IMAGE_SIDE`], or whose decoding would
//!   not fit the memory budget ([`decode_bytes`]), are refused from their
//!   header before they are decoded; undecodable files give an error naming
//!   the file.
//!
//! The format is found from the file's first bytes, not its extension.

use crate::error::{IoError, Result};
use chiaro_core::budget::MemoryBudget;
use chiaro_core::film::tonemap::srgb_eotf;
use chiaro_core::glam::Vec3;
use chiaro_core::scene::{ImageTexture, WrapMode};
use std::io::Cursor;
use std::path::Path;

/// The largest width or height (texels) of an image chiaro decodes.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// The four magic bytes that open every OpenEXR file.
const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// Reads and decodes an image texture into linear RGBA texels (see the
/// module docs for what `srgb` does).
///
/// # Errors
/// [`IoError::Io`] if the file cannot be read; [`IoError::Format`] naming
/// the file if it is not a PNG, JPEG, Radiance HDR or OpenEXR image, is
/// corrupt, has no RGB or luminance channels (EXR), or is larger than
/// [`MAX_IMAGE_SIDE`] on a side or needs more memory than the process
/// budget ([`MemoryBudget::process`]).
pub fn load_texture(path: &Path, srgb: bool) -> Result<ImageTexture> {
    load_texture_within(path, srgb, MemoryBudget::process())
}

/// [`load_texture`] within `budget`.
///
/// # Errors
/// As [`load_texture`].
pub fn load_texture_within(path: &Path, srgb: bool, budget: MemoryBudget) -> Result<ImageTexture> {
    let bytes = crate::files::read_file_within(path, budget, u64::MAX)?;
    decode_texture_within(&bytes, path, srgb, budget, path.display().to_string())
}

/// Decodes an image held in memory (a glTF embedded or buffer-view image);
/// `name` stands for the file in messages and becomes the texture's
/// `source`. Otherwise as [`load_texture`].
///
/// # Errors
/// As [`load_texture`], with `name` in place of the path.
pub fn load_texture_bytes(bytes: &[u8], name: &str, srgb: bool) -> Result<ImageTexture> {
    load_texture_bytes_within(bytes, name, srgb, MemoryBudget::process())
}

/// [`load_texture_bytes`] within `budget`.
///
/// # Errors
/// As [`load_texture`].
pub fn load_texture_bytes_within(
    bytes: &[u8],
    name: &str,
    srgb: bool,
    budget: MemoryBudget,
) -> Result<ImageTexture> {
    decode_texture_within(bytes, Path::new(name), srgb, budget, name.to_string())
}

/// The most memory decoding a `width x height` image takes, in bytes: its
/// RGBA `f32` texels (16 a pixel; an 8-bit file's codes take 4), their `f32`
/// mip levels (a third more), and the decoder's own buffers (at most 16 a
/// pixel, for a 32-bit float file).
pub fn decode_bytes(width: u32, height: u32) -> u64 {
    (u64::from(width) * u64::from(height)).saturating_mul(16 * 7) / 3
}

/// A decoded image with whatever extra buffers its file had.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DecodedImage {
    pub width: u32,
    pub height: u32,
    /// Linear RGBA, row-major from the top-left.
    pub texels: Vec<[f32; 4]>,
    /// The `Z` channel of an EXR file.
    pub depth: Option<Vec<f32>>,
    /// The `N.X`, `N.Y`, `N.Z` channels of an EXR file.
    pub normal: Option<Vec<Vec3>>,
}

impl DecodedImage {
    fn into_texture(self, source: String) -> ImageTexture {
        ImageTexture {
            source,
            width: self.width,
            height: self.height,
            texels: self.texels,
            wrap: WrapMode::default(),
            ..Default::default()
        }
    }
}

/// A colour channel read from a file: finite and non-negative.
#[inline]
fn clean(x: f32) -> f32 {
    if x.is_finite() && x > 0.0 { x } else { 0.0 }
}

/// Alpha read from a file: in `[0, 1]`, NaN as 1.
#[inline]
fn clean_alpha(a: f32) -> f32 {
    if a.is_nan() { 1.0 } else { a.clamp(0.0, 1.0) }
}

fn check_size(width: u32, height: u32, name: &Path, budget: MemoryBudget) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(IoError::format(name, "the image is empty (0 pixels)"));
    }
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(IoError::format(
            name,
            format!(
                "the image is {width}x{height}, larger than the {MAX_IMAGE_SIDE} pixels per side chiaro accepts"
            ),
        ));
    }
    budget
        .check(
            &format!("decoding the {width}x{height} image"),
            decode_bytes(width, height),
        )
        .map_err(|m| IoError::format(name, m))
}

/// Decodes any supported image from its bytes; `name` is for messages.
pub(crate) fn decode_image(bytes: &[u8], name: &Path, srgb: bool) -> Result<DecodedImage> {
    decode_image_within(bytes, name, srgb, MemoryBudget::process())
}

/// [`decode_image`] within `budget`.
pub(crate) fn decode_image_within(
    bytes: &[u8],
    name: &Path,
    srgb: bool,
    budget: MemoryBudget,
) -> Result<DecodedImage> {
    if bytes.starts_with(&EXR_MAGIC) {
        decode_exr(bytes, name, budget)
    } else {
        let img = decode_with_image_crate(bytes, name, budget)?;
        Ok(DecodedImage {
            width: img.width(),
            height: img.height(),
            texels: linear_texels(&img, srgb),
            depth: None,
            normal: None,
        })
    }
}

/// Decodes an image texture: 8-bit files keep their codes
/// ([`ImageTexture::new_8bit`]), others become linear `f32` texels.
fn decode_texture_within(
    bytes: &[u8],
    name: &Path,
    srgb: bool,
    budget: MemoryBudget,
    source: String,
) -> Result<ImageTexture> {
    if bytes.starts_with(&EXR_MAGIC) {
        return Ok(decode_exr(bytes, name, budget)?.into_texture(source));
    }
    let img = decode_with_image_crate(bytes, name, budget)?;
    let (width, height) = (img.width(), img.height());
    Ok(match codes8(img) {
        Ok(codes) => ImageTexture::new_8bit(source, width, height, codes, srgb),
        Err(img) => DecodedImage {
            width,
            height,
            texels: linear_texels(&img, srgb),
            depth: None,
            normal: None,
        }
        .into_texture(source),
    })
}

/// The RGBA codes of an 8-bit image (luminance as grey, alpha 255 where the
/// file has none); other images back as they are.
fn codes8(img: image::DynamicImage) -> std::result::Result<Vec<[u8; 4]>, image::DynamicImage> {
    use image::DynamicImage;
    match img {
        DynamicImage::ImageRgb32F(_)
        | DynamicImage::ImageRgba32F(_)
        | DynamicImage::ImageLuma16(_)
        | DynamicImage::ImageLumaA16(_)
        | DynamicImage::ImageRgb16(_)
        | DynamicImage::ImageRgba16(_) => Err(img),
        _ => Ok(img
            .into_rgba8()
            .pixels()
            .map(|p| p.0)
            .collect::<Vec<[u8; 4]>>()),
    }
}

/// The decoded image as linear RGBA `f32` (8-bit codes through the same
/// decode as [`ImageTexture::texel`]'s).
fn linear_texels(img: &image::DynamicImage, srgb: bool) -> Vec<[f32; 4]> {
    use image::DynamicImage;
    match img {
        DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_) => img
            .to_rgba32f()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                [clean(r), clean(g), clean(b), clean_alpha(a)]
            })
            .collect(),
        DynamicImage::ImageLuma16(_)
        | DynamicImage::ImageLumaA16(_)
        | DynamicImage::ImageRgb16(_)
        | DynamicImage::ImageRgba16(_) => {
            let decode = |v: u16| {
                let x = f32::from(v) / 65535.0;
                if srgb { srgb_eotf(x) } else { x }
            };
            img.to_rgba16()
                .pixels()
                .map(|p| {
                    let [r, g, b, a] = p.0;
                    [decode(r), decode(g), decode(b), f32::from(a) / 65535.0]
                })
                .collect()
        }
        _ => {
            let codes = img.to_rgba8().pixels().map(|p| p.0).collect();
            let t = ImageTexture::new_8bit(String::new(), img.width(), img.height(), codes, srgb);
            (0..t.texel_count()).map(|i| t.texel_at(i)).collect()
        }
    }
}

/// The error for `name`, a `what` its decoder refused with `e` (the
/// decoder's words in plain terms).
fn undecodable(name: &Path, what: &str, e: &dyn std::fmt::Display) -> IoError {
    IoError::format(
        name,
        format!(
            "cannot decode the {what}: {}",
            crate::plain::third_party(&e.to_string())
        ),
    )
}

/// Decodes a PNG, JPEG or Radiance HDR image, its size checked from the
/// header first; `name` is for messages.
fn decode_with_image_crate(
    bytes: &[u8],
    name: &Path,
    budget: MemoryBudget,
) -> Result<image::DynamicImage> {
    let bad = |e: &dyn std::fmt::Display| undecodable(name, "image", e);
    let reader = || {
        image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| bad(&e))
    };
    if reader()?.format().is_none() {
        return Err(IoError::format(
            name,
            "not a PNG, JPEG, Radiance HDR or OpenEXR image",
        ));
    }
    // Check the header's size before allocating anything.
    let (width, height) = reader()?.into_dimensions().map_err(|e| bad(&e))?;
    check_size(width, height, name, budget)?;
    let mut r = reader()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    // The decoder's own buffers stay within the budget too.
    limits.max_alloc = Some(budget.limit.0);
    r.limits(limits);
    r.decode().map_err(|e| bad(&e))
}

/// Reads the first valid layer of an OpenEXR file: `R`, `G`, `B` (or `Y`
/// for luminance), optional `A`, `Z`, `N.X`/`N.Y`/`N.Z`. Channels may carry
/// a layer prefix (`beauty.R`) for colour.
fn decode_exr(bytes: &[u8], name: &Path, budget: MemoryBudget) -> Result<DecodedImage> {
    use exr::prelude::*;
    let bad = |e: &dyn std::fmt::Display| undecodable(name, "OpenEXR image", e);
    // Check the header's size before reading pixels.
    let meta =
        exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| bad(&e))?;
    for h in &meta.headers {
        let s = h.layer_size;
        check_size(
            u32::try_from(s.width()).unwrap_or(u32::MAX),
            u32::try_from(s.height()).unwrap_or(u32::MAX),
            name,
            budget,
        )?;
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| bad(&e))?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let n = w * h;
    let channels = &layer.channel_data.list;
    let exact = |want: &str| {
        channels
            .iter()
            .find(|c| c.name.to_string() == want)
            .map(|c| c.sample_data.values_as_f32().collect::<Vec<f32>>())
    };
    let colour = |want: &str| {
        exact(want).or_else(|| {
            let suffix = format!(".{want}");
            channels
                .iter()
                .find(|c| {
                    c.name.to_string().ends_with(&suffix) && !c.name.to_string().starts_with("N.")
                })
                .map(|c| c.sample_data.values_as_f32().collect::<Vec<f32>>())
        })
    };
    let (r, g, b) = match (colour("R"), colour("G"), colour("B"), exact("Y")) {
        (Some(r), Some(g), Some(b), _) => (r, g, b),
        (_, _, _, Some(y)) => (y.clone(), y.clone(), y),
        _ => {
            let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
            return Err(IoError::format(
                name,
                format!(
                    "the OpenEXR image has no R, G, B or Y channels (it has: {})",
                    names.join(", ")
                ),
            ));
        }
    };
    let a = colour("A");
    if [&r, &g, &b].iter().any(|c| c.len() != n) {
        return Err(bad(&"a channel has the wrong number of samples"));
    }
    let texels = (0..n)
        .map(|i| {
            [
                clean(r[i]),
                clean(g[i]),
                clean(b[i]),
                a.as_ref()
                    .and_then(|a| a.get(i))
                    .map_or(1.0, |&v| clean_alpha(v)),
            ]
        })
        .collect();
    let depth = exact("Z").filter(|z| z.len() == n).map(|z| {
        z.into_iter()
            .map(|d| if d.is_nan() { f32::INFINITY } else { d })
            .collect()
    });
    let normal = match (exact("N.X"), exact("N.Y"), exact("N.Z")) {
        (Some(x), Some(y), Some(z)) if x.len() == n && y.len() == n && z.len() == n => Some(
            (0..n)
                .map(|i| {
                    let v = Vec3::new(x[i], y[i], z[i]);
                    if v.is_finite() { v } else { Vec3::ZERO }
                })
                .collect(),
        ),
        _ => None,
    };
    Ok(DecodedImage {
        width: w as u32,
        height: h as u32,
        texels,
        depth,
        normal,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_bytes(img: &image::DynamicImage) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png)
            .expect("encode png");
        out.into_inner()
    }

    #[test]
    fn png8_srgb_and_linear() {
        let mut buf = image::RgbImage::new(2, 1);
        buf.put_pixel(0, 0, image::Rgb([128, 0, 255]));
        buf.put_pixel(1, 0, image::Rgb([10, 20, 30]));
        let bytes = png_bytes(&image::DynamicImage::ImageRgb8(buf));
        let t = load_texture_bytes(&bytes, "mem.png", true).expect("decodes");
        assert_eq!((t.width, t.height), (2, 1));
        let t0 = t.texel_at(0);
        assert!((t0[0] - 0.215_860_5).abs() < 1e-6);
        assert_eq!(t0[1], 0.0);
        assert_eq!(t0[2], 1.0);
        assert_eq!(t0[3], 1.0);
        let lin = load_texture_bytes(&bytes, "mem.png", false).expect("decodes");
        assert!((lin.texel_at(0)[0] - 128.0 / 255.0).abs() < 1e-7);
        assert_eq!(lin.source, "mem.png");
    }

    /// 8-bit files keep their codes (4 bytes a texel) and read as the `f32`
    /// decode of the same file (the film reader's route) bit for bit; a
    /// texture survives the JSON the Python module pickles scenes with.
    #[test]
    fn png8_is_held_as_codes_and_reads_as_its_f32_decode() {
        let mut buf = image::RgbaImage::new(16, 16);
        for (i, p) in buf.pixels_mut().enumerate() {
            let c = |k: usize| ((i * k + 3) % 256) as u8;
            *p = image::Rgba([c(1), c(7), c(11), c(13)]);
        }
        let bytes = png_bytes(&image::DynamicImage::ImageRgba8(buf));
        for srgb in [true, false] {
            let t = load_texture_bytes(&bytes, "mem8.png", srgb).expect("decodes");
            assert!(t.texels.is_empty());
            assert_eq!(t.texel_bytes(), 16 * 16 * 4);
            let f = decode_image(&bytes, Path::new("mem8.png"), srgb).expect("decodes");
            assert_eq!(t.texel_count(), f.texels.len());
            for (i, want) in f.texels.iter().enumerate() {
                assert_eq!(t.texel_at(i).map(f32::to_bits), want.map(f32::to_bits));
            }
            let json = serde_json::to_string(&t).expect("serializes");
            let back: ImageTexture = serde_json::from_str(&json).expect("deserializes");
            assert_eq!(back, t);
        }
        // A grey 8-bit PNG expands to RGBA codes; a 16-bit one stays f32.
        let grey = load_texture_bytes(&grey_png(4), "g.png", false).expect("decodes");
        assert_eq!(grey.texel_bytes(), 4 * 4 * 4);
        assert_eq!(grey.texel_at(5), [0.0, 0.0, 0.0, 1.0]);
        let mut buf16: image::ImageBuffer<image::Rgba<u16>, Vec<u16>> =
            image::ImageBuffer::new(2, 2);
        buf16.put_pixel(1, 1, image::Rgba([1, 2, 3, 4]));
        let t16 = load_texture_bytes(
            &png_bytes(&image::DynamicImage::ImageRgba16(buf16)),
            "m16.png",
            false,
        )
        .expect("decodes");
        assert!(t16.texels8.is_none() && t16.texels.len() == 4);
    }

    #[test]
    fn png16_keeps_precision() {
        let mut buf: image::ImageBuffer<image::Rgba<u16>, Vec<u16>> = image::ImageBuffer::new(1, 1);
        buf.put_pixel(0, 0, image::Rgba([1000, 40000, 65535, 32768]));
        let bytes = png_bytes(&image::DynamicImage::ImageRgba16(buf));
        let t = load_texture_bytes(&bytes, "mem16.png", false).expect("decodes");
        assert!(t.texels8.is_none());
        assert!((t.texels[0][0] - 1000.0 / 65535.0).abs() < 1e-7);
        assert!((t.texels[0][3] - 32768.0 / 65535.0).abs() < 1e-7);
        let s = load_texture_bytes(&bytes, "mem16.png", true).expect("decodes");
        assert!((s.texels[0][1] - srgb_eotf(40000.0 / 65535.0)).abs() < 1e-6);
    }

    #[test]
    fn garbage_is_an_error_naming_the_file() {
        let e = load_texture_bytes(b"this is not an image", "bad.png", true).expect_err("garbage");
        let msg = e.to_string();
        assert!(msg.contains("bad.png"), "{msg}");
        // A truncated PNG: the header survives, the data does not.
        let mut buf = image::RgbImage::new(8, 8);
        buf.put_pixel(3, 3, image::Rgb([1, 2, 3]));
        let bytes = png_bytes(&image::DynamicImage::ImageRgb8(buf));
        let e =
            load_texture_bytes(&bytes[..bytes.len() / 2], "cut.png", true).expect_err("truncated");
        assert!(e.to_string().contains("cut.png"));
        // A truncated EXR.
        let e = load_texture_bytes(&[0x76, 0x2f, 0x31, 0x01, 2, 0, 0], "cut.exr", false)
            .expect_err("truncated exr");
        assert!(e.to_string().contains("cut.exr"));
        // A missing file.
        let e = load_texture(Path::new("/nonexistent/dir/tex.png"), true).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/dir/tex.png"));
    }

    #[test]
    fn absurd_sizes_are_refused_before_decoding() {
        // A PNG signature and an IHDR chunk claiming 20000 x 20000, no data.
        let mut png = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend_from_slice(&20000u32.to_be_bytes());
        ihdr.extend_from_slice(&20000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(&ihdr);
        png.extend_from_slice(&crc32(&ihdr).to_be_bytes());
        for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
            png.extend_from_slice(&0u32.to_be_bytes());
            png.extend_from_slice(chunk);
            png.extend_from_slice(&crc32(chunk).to_be_bytes());
        }
        let e = load_texture_bytes(&png, "huge.png", true).expect_err("too big");
        let msg = e.to_string();
        assert!(
            msg.contains("huge.png") && msg.contains("20000x20000"),
            "{msg}"
        );
    }

    /// A PNG of a `side x side` 8-bit grey image, all black: rows of a
    /// filter byte and zeros, deflated by the `image` crate's PNG encoder.
    fn grey_png(side: u32) -> Vec<u8> {
        use image::ImageEncoder;
        let mut out = Vec::new();
        let enc = image::codecs::png::PngEncoder::new(&mut out);
        let pixels = vec![0u8; (side * side) as usize];
        enc.write_image(&pixels, side, side, image::ExtendedColorType::L8)
            .expect("encodes");
        out
    }

    #[test]
    fn images_beyond_the_budget_are_refused_from_their_header() {
        // A valid 16384 x 16384 grey PNG's header, as a file of that size
        // opens (the refusal reads nothing past IHDR).
        let mut png = grey_png(1);
        png[16..20].copy_from_slice(&16384u32.to_be_bytes());
        png[20..24].copy_from_slice(&16384u32.to_be_bytes());
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        let budget = MemoryBudget::new(1 << 30);
        let e = load_texture_bytes_within(&png, "grey.png", false, budget).expect_err("budget");
        let msg = e.to_string();
        assert!(
            msg.contains("grey.png") && msg.contains("16384x16384") && msg.contains("1.0 GiB"),
            "{msg}"
        );
        // A small image within the same budget decodes.
        let small = grey_png(64);
        let t = load_texture_bytes_within(&small, "small.png", false, budget).expect("decodes");
        assert_eq!((t.width, t.height), (64, 64));
        assert_eq!(decode_bytes(16384, 16384), 16384 * 16384 * 112 / 3);
    }

    /// CRC-32 (ISO 3309, as PNG uses), bit by bit.
    fn crc32(data: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in data {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    #[test]
    fn shipped_assets_decode() {
        // Real files from the shared assets (a Poly Haven HDR, Mitsuba's
        // museum.exr), skipped where they are absent.
        let Some(assets) = chiaro_testkit::shared_assets() else {
            return;
        };
        for rel in [
            "envmaps/polyhaven-via-drei-assets/studio_small_03_1k.hdr",
            "mitsuba3-test-scenes/common/textures/museum.exr",
        ] {
            let t = load_texture(&assets.join(rel), false).expect("shipped image decodes");
            assert!(
                t.width > 16 && t.texels.len() == (t.width * t.height) as usize,
                "{rel}"
            );
            assert!(
                t.texels
                    .iter()
                    .all(|c| c.iter().all(|v| v.is_finite() && *v >= 0.0))
            );
            let mean: f32 =
                t.texels.iter().map(|c| c[0] + c[1] + c[2]).sum::<f32>() / t.texels.len() as f32;
            assert!(mean > 0.01, "{rel}: mean {mean}");
        }
    }
}
