//! The encoders behind [`super::write_film`], each producing the file's
//! bytes in memory, and the PPM decoder behind
//! [`super::read_image_as_film`].

use super::OutputOptions;
use crate::images::DecodedImage;
use chiaro_core::film::Film;
use chiaro_core::film::palette::{PaletteMode, quantize};
use chiaro_core::film::tonemap::{srgb_eotf, to_srgb8, to_srgb16};
use chiaro_core::glam::Vec3;
use chiaro_core::shading::sanitize;
use std::io::Cursor;

type Encoded = Result<Vec<u8>, String>;

fn png_encoder<'o>(out: &'o mut Vec<u8>, film: &Film) -> png::Encoder<'static, &'o mut Vec<u8>> {
    let mut enc = png::Encoder::new(out, film.width, film.height);
    // Tag the file as sRGB so viewers do not re-interpret it.
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    enc
}

fn png_error(e: png::EncodingError) -> String {
    format!("cannot encode the PNG: {e}")
}

/// 8- or 16-bit RGB PNG of the tone-mapped film.
pub(super) fn png(film: &Film, opts: &OutputOptions) -> Encoded {
    let mut out = Vec::new();
    let mut enc = png_encoder(&mut out, film);
    enc.set_color(png::ColorType::Rgb);
    let data: Vec<u8> = if opts.bit_depth16 {
        enc.set_depth(png::BitDepth::Sixteen);
        // PNG stores 16-bit samples big-endian (PNG spec, section 7.1).
        to_srgb16(film, opts.tonemap, opts.exposure)
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_be_bytes()))
            .collect()
    } else {
        enc.set_depth(png::BitDepth::Eight);
        to_srgb8(film, opts.tonemap, opts.exposure)
            .into_iter()
            .flatten()
            .collect()
    };
    let mut w = enc.write_header().map_err(png_error)?;
    w.write_image_data(&data).map_err(png_error)?;
    w.finish().map_err(png_error)?;
    Ok(out)
}

/// Indexed PNG (colour type 3, PLTE) of the tone-mapped film, quantised by
/// `mode`.
pub(super) fn indexed_png(film: &Film, mode: &PaletteMode, opts: &OutputOptions) -> Encoded {
    let rgb8 = to_srgb8(film, opts.tonemap, opts.exposure);
    let img = quantize(&rgb8, film.width, film.height, mode);
    if img.palette.is_empty() || img.palette.len() > 256 {
        return Err(format!("a palette of {} colours", img.palette.len()));
    }
    let mut out = Vec::new();
    let mut enc = png_encoder(&mut out, film);
    enc.set_color(png::ColorType::Indexed);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_palette(img.palette.iter().flatten().copied().collect::<Vec<u8>>());
    let mut w = enc.write_header().map_err(png_error)?;
    w.write_image_data(&img.indices).map_err(png_error)?;
    w.finish().map_err(png_error)?;
    Ok(out)
}

/// OpenEXR with float `R G B Z N.X N.Y N.Z` channels (lossless ZIP).
pub(super) fn exr(film: &Film) -> Encoded {
    use exr::prelude::*;
    let size = (film.width as usize, film.height as usize);
    let colors: Vec<Vec3> = film.color.iter().map(|&c| sanitize(c)).collect();
    let normals: Vec<Vec3> = film
        .normal
        .iter()
        .map(|&n| if n.is_finite() { n } else { Vec3::ZERO })
        .collect();
    let depth: Vec<f32> = film
        .depth
        .iter()
        .map(|&d| if d.is_nan() { f32::INFINITY } else { d })
        .collect();
    let ch = |name: &str, v: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(v));
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = vec![
        ch("R", colors.iter().map(|c| c.x).collect()),
        ch("G", colors.iter().map(|c| c.y).collect()),
        ch("B", colors.iter().map(|c| c.z).collect()),
        ch("Z", depth),
        ch("N.X", normals.iter().map(|n| n.x).collect()),
        ch("N.Y", normals.iter().map(|n| n.y).collect()),
        ch("N.Z", normals.iter().map(|n| n.z).collect()),
    ]
    .into();
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let mut out = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| format!("cannot encode the OpenEXR image: {e}"))?;
    Ok(out.into_inner())
}

/// Radiance RGBE (`.hdr`) of the linear film.
pub(super) fn hdr(film: &Film) -> Encoded {
    let pixels: Vec<image::Rgb<f32>> = film
        .color
        .iter()
        .map(|&c| image::Rgb(sanitize(c).to_array()))
        .collect();
    let mut out = Vec::new();
    image::codecs::hdr::HdrEncoder::new(&mut out)
        .encode(&pixels, film.width as usize, film.height as usize)
        .map_err(|e| format!("cannot encode the Radiance HDR image: {e}"))?;
    Ok(out)
}

/// Binary PPM (`P6`, Netpbm): 8-bit, or 16-bit big-endian samples with
/// `bit_depth16` (maxval 65535).
pub(super) fn ppm(film: &Film, opts: &OutputOptions) -> Vec<u8> {
    let maxval = if opts.bit_depth16 { 65535 } else { 255 };
    let mut out = format!("P6\n{} {}\n{maxval}\n", film.width, film.height).into_bytes();
    if opts.bit_depth16 {
        for p in to_srgb16(film, opts.tonemap, opts.exposure) {
            for v in p {
                out.extend_from_slice(&v.to_be_bytes());
            }
        }
    } else {
        out.extend(
            to_srgb8(film, opts.tonemap, opts.exposure)
                .into_iter()
                .flatten(),
        );
    }
    out
}

/// Decodes a binary PPM (`P6`, maxval 1..=65535, `#` comments in the
/// header) as sRGB-encoded into linear texels.
pub(crate) fn decode_ppm(bytes: &[u8]) -> Result<DecodedImage, String> {
    // Header: magic, width, height, maxval, separated by whitespace and
    // comments, then exactly one whitespace byte (Netpbm ppm(5)).
    let mut pos = 2;
    let mut fields = [0u32; 3];
    for field in &mut fields {
        loop {
            match bytes.get(pos) {
                Some(b) if b.is_ascii_whitespace() => pos += 1,
                Some(b'#') => {
                    while bytes.get(pos).is_some_and(|&b| b != b'\n') {
                        pos += 1;
                    }
                }
                _ => break,
            }
        }
        let start = pos;
        while bytes.get(pos).is_some_and(u8::is_ascii_digit) {
            pos += 1;
        }
        *field = std::str::from_utf8(&bytes[start..pos])
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| format!("bad PPM header at byte {start}"))?;
    }
    pos += 1;
    let [width, height, maxval] = fields;
    if width == 0 || height == 0 || width > super::MAX_IMAGE_SIDE || height > super::MAX_IMAGE_SIDE
    {
        return Err(format!("unsupported PPM size {width}x{height}"));
    }
    if maxval == 0 || maxval > 65535 {
        return Err(format!("bad PPM maxval {maxval}"));
    }
    let wide = maxval > 255;
    let n = width as usize * height as usize;
    let need = n * 3 * if wide { 2 } else { 1 };
    let data = bytes
        .get(pos..pos + need)
        .ok_or_else(|| format!("the PPM is truncated: {need} bytes of pixels expected"))?;
    let sample = |i: usize| {
        let v = if wide {
            u16::from_be_bytes([data[2 * i], data[2 * i + 1]])
        } else {
            u16::from(data[i])
        };
        srgb_eotf(f32::from(v) / maxval as f32)
    };
    let texels = (0..n)
        .map(|p| [sample(3 * p), sample(3 * p + 1), sample(3 * p + 2), 1.0])
        .collect();
    Ok(DecodedImage {
        width,
        height,
        texels,
        depth: None,
        normal: None,
    })
}
