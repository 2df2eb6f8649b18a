//! The contact sheet of a comparison: one row per image (the reference
//! first), each with the tone-mapped image, its false-colour error against
//! the reference, and a label strip (technique, samples, seconds, RMSE,
//! PSNR, mean relative error).
//!
//! All error images share one scale, so rows can be compared: the largest of
//! the per-technique 99th percentiles of the per-pixel absolute error
//! (mean over channels of `|a - ref|`, linear radiance), printed in the
//! header next to a viridis colour bar. Text is drawn with a 5x7 bitmap
//! font (plus a descender row) defined below as data (one `u8` per glyph row, bit 4 the leftmost
//! pixel), drawn for this project.

use crate::compare::{CacheStatus, Comparison, Entry, format_psnr};
use crate::metrics::{ErrorKind, difference_image, viridis};
use chiaro::Result;
use chiaro_core::Vec3;
use chiaro_core::film::Film;
use chiaro_core::film::tonemap::{self, tonemap_color};
use chiaro_core::scene::ToneMap;
use chiaro_io::output::{OutputOptions, write_film};
use std::path::Path;

/// Glyph width in pixels (at text scale 1).
pub const GLYPH_WIDTH: u32 = 5;
/// Glyph height in pixels (at text scale 1): 7 rows above the baseline
/// and one for descenders.
pub const GLYPH_HEIGHT: u32 = 8;
/// Horizontal advance per character (glyph plus one pixel of spacing).
pub const ADVANCE_X: u32 = GLYPH_WIDTH + 1;
/// Line height (glyph plus one pixel of spacing).
pub const LINE_HEIGHT: u32 = GLYPH_HEIGHT + 1;
/// Padding between cells and around the sheet, in pixels.
pub const PAD: u32 = 4;
/// Characters per label line (labels are cut to this width).
pub const LABEL_CHARS: u32 = 18;
/// Lines in a row's label strip.
pub const LABEL_LINES: u32 = 9;
/// Lines of header text.
pub const HEADER_LINES: u32 = 2;

const BACKGROUND: Vec3 = Vec3::splat(0.015);
const TEXT: Vec3 = Vec3::splat(0.9);
const DIM_TEXT: Vec3 = Vec3::splat(0.35);

/// The 5x7 glyphs of printable ASCII (32 `' '` to 126 `'~'`), top row first,
/// with an eighth row for the descenders of `g j p q y ,`; in each row, bit 4 is the leftmost pixel and bit 0 the rightmost.
const FONT: [[u8; 8]; 95] = [
    [
        0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // ' '
    [
        0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000, 0b00100, 0b00000,
    ], // '!'
    [
        0b01010, 0b01010, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // '"'
    [
        0b01010, 0b01010, 0b11111, 0b01010, 0b11111, 0b01010, 0b01010, 0b00000,
    ], // '#'
    [
        0b00100, 0b01111, 0b10100, 0b01110, 0b00101, 0b11110, 0b00100, 0b00000,
    ], // '$'
    [
        0b11000, 0b11001, 0b00010, 0b00100, 0b01000, 0b10011, 0b00011, 0b00000,
    ], // '%'
    [
        0b01100, 0b10010, 0b10100, 0b01000, 0b10101, 0b10010, 0b01101, 0b00000,
    ], // '&'
    [
        0b00100, 0b00100, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // '\''
    [
        0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00100, 0b00010, 0b00000,
    ], // '('
    [
        0b01000, 0b00100, 0b00010, 0b00010, 0b00010, 0b00100, 0b01000, 0b00000,
    ], // ')'
    [
        0b00000, 0b00100, 0b10101, 0b01110, 0b10101, 0b00100, 0b00000, 0b00000,
    ], // '*'
    [
        0b00000, 0b00100, 0b00100, 0b11111, 0b00100, 0b00100, 0b00000, 0b00000,
    ], // '+'
    [
        0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b00100, 0b01000,
    ], // ','
    [
        0b00000, 0b00000, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // '-'
    [
        0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b01100, 0b00000,
    ], // '.'
    [
        0b00000, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b00000, 0b00000,
    ], // '/'
    [
        0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110, 0b00000,
    ], // '0'
    [
        0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110, 0b00000,
    ], // '1'
    [
        0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111, 0b00000,
    ], // '2'
    [
        0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110, 0b00000,
    ], // '3'
    [
        0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010, 0b00000,
    ], // '4'
    [
        0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110, 0b00000,
    ], // '5'
    [
        0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110, 0b00000,
    ], // '6'
    [
        0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00000,
    ], // '7'
    [
        0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110, 0b00000,
    ], // '8'
    [
        0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100, 0b00000,
    ], // '9'
    [
        0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b01100, 0b00000, 0b00000,
    ], // ':'
    [
        0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b00100, 0b01000, 0b00000,
    ], // ';'
    [
        0b00010, 0b00100, 0b01000, 0b10000, 0b01000, 0b00100, 0b00010, 0b00000,
    ], // '<'
    [
        0b00000, 0b00000, 0b11111, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000,
    ], // '='
    [
        0b01000, 0b00100, 0b00010, 0b00001, 0b00010, 0b00100, 0b01000, 0b00000,
    ], // '>'
    [
        0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b00000, 0b00100, 0b00000,
    ], // '?'
    [
        0b01110, 0b10001, 0b00001, 0b01101, 0b10101, 0b10101, 0b01110, 0b00000,
    ], // '@'
    [
        0b01110, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001, 0b00000,
    ], // 'A'
    [
        0b11110, 0b10001, 0b10001, 0b11110, 0b10001, 0b10001, 0b11110, 0b00000,
    ], // 'B'
    [
        0b01110, 0b10001, 0b10000, 0b10000, 0b10000, 0b10001, 0b01110, 0b00000,
    ], // 'C'
    [
        0b11100, 0b10010, 0b10001, 0b10001, 0b10001, 0b10010, 0b11100, 0b00000,
    ], // 'D'
    [
        0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b11111, 0b00000,
    ], // 'E'
    [
        0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b10000, 0b00000,
    ], // 'F'
    [
        0b01110, 0b10001, 0b10000, 0b10111, 0b10001, 0b10001, 0b01111, 0b00000,
    ], // 'G'
    [
        0b10001, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001, 0b00000,
    ], // 'H'
    [
        0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110, 0b00000,
    ], // 'I'
    [
        0b00111, 0b00010, 0b00010, 0b00010, 0b00010, 0b10010, 0b01100, 0b00000,
    ], // 'J'
    [
        0b10001, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b10001, 0b00000,
    ], // 'K'
    [
        0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111, 0b00000,
    ], // 'L'
    [
        0b10001, 0b11011, 0b10101, 0b10101, 0b10001, 0b10001, 0b10001, 0b00000,
    ], // 'M'
    [
        0b10001, 0b10001, 0b11001, 0b10101, 0b10011, 0b10001, 0b10001, 0b00000,
    ], // 'N'
    [
        0b01110, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110, 0b00000,
    ], // 'O'
    [
        0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000, 0b00000,
    ], // 'P'
    [
        0b01110, 0b10001, 0b10001, 0b10001, 0b10101, 0b10010, 0b01101, 0b00000,
    ], // 'Q'
    [
        0b11110, 0b10001, 0b10001, 0b11110, 0b10100, 0b10010, 0b10001, 0b00000,
    ], // 'R'
    [
        0b01111, 0b10000, 0b10000, 0b01110, 0b00001, 0b00001, 0b11110, 0b00000,
    ], // 'S'
    [
        0b11111, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000,
    ], // 'T'
    [
        0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110, 0b00000,
    ], // 'U'
    [
        0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100, 0b00000,
    ], // 'V'
    [
        0b10001, 0b10001, 0b10001, 0b10101, 0b10101, 0b10101, 0b01010, 0b00000,
    ], // 'W'
    [
        0b10001, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b10001, 0b00000,
    ], // 'X'
    [
        0b10001, 0b10001, 0b01010, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000,
    ], // 'Y'
    [
        0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b11111, 0b00000,
    ], // 'Z'
    [
        0b01110, 0b01000, 0b01000, 0b01000, 0b01000, 0b01000, 0b01110, 0b00000,
    ], // '['
    [
        0b00000, 0b10000, 0b01000, 0b00100, 0b00010, 0b00001, 0b00000, 0b00000,
    ], // '\\'
    [
        0b01110, 0b00010, 0b00010, 0b00010, 0b00010, 0b00010, 0b01110, 0b00000,
    ], // ']'
    [
        0b00100, 0b01010, 0b10001, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // '^'
    [
        0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b11111, 0b00000,
    ], // '_'
    [
        0b01000, 0b00100, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000,
    ], // '`'
    [
        0b00000, 0b00000, 0b01110, 0b00001, 0b01111, 0b10001, 0b01111, 0b00000,
    ], // 'a'
    [
        0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b11110, 0b00000,
    ], // 'b'
    [
        0b00000, 0b00000, 0b01110, 0b10000, 0b10000, 0b10001, 0b01110, 0b00000,
    ], // 'c'
    [
        0b00001, 0b00001, 0b01101, 0b10011, 0b10001, 0b10001, 0b01111, 0b00000,
    ], // 'd'
    [
        0b00000, 0b00000, 0b01110, 0b10001, 0b11111, 0b10000, 0b01110, 0b00000,
    ], // 'e'
    [
        0b00110, 0b01001, 0b01000, 0b11100, 0b01000, 0b01000, 0b01000, 0b00000,
    ], // 'f'
    [
        0b00000, 0b00000, 0b01111, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110,
    ], // 'g'
    [
        0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001, 0b00000,
    ], // 'h'
    [
        0b00100, 0b00000, 0b01100, 0b00100, 0b00100, 0b00100, 0b01110, 0b00000,
    ], // 'i'
    [
        0b00010, 0b00000, 0b00110, 0b00010, 0b00010, 0b00010, 0b10010, 0b01100,
    ], // 'j'
    [
        0b10000, 0b10000, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b00000,
    ], // 'k'
    [
        0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110, 0b00000,
    ], // 'l'
    [
        0b00000, 0b00000, 0b11010, 0b10101, 0b10101, 0b10001, 0b10001, 0b00000,
    ], // 'm'
    [
        0b00000, 0b00000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001, 0b00000,
    ], // 'n'
    [
        0b00000, 0b00000, 0b01110, 0b10001, 0b10001, 0b10001, 0b01110, 0b00000,
    ], // 'o'
    [
        0b00000, 0b00000, 0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000,
    ], // 'p'
    [
        0b00000, 0b00000, 0b01111, 0b10001, 0b10001, 0b01111, 0b00001, 0b00001,
    ], // 'q'
    [
        0b00000, 0b00000, 0b10110, 0b11001, 0b10000, 0b10000, 0b10000, 0b00000,
    ], // 'r'
    [
        0b00000, 0b00000, 0b01110, 0b10000, 0b01110, 0b00001, 0b11110, 0b00000,
    ], // 's'
    [
        0b01000, 0b01000, 0b11100, 0b01000, 0b01000, 0b01001, 0b00110, 0b00000,
    ], // 't'
    [
        0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b10011, 0b01101, 0b00000,
    ], // 'u'
    [
        0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100, 0b00000,
    ], // 'v'
    [
        0b00000, 0b00000, 0b10001, 0b10001, 0b10101, 0b10101, 0b01010, 0b00000,
    ], // 'w'
    [
        0b00000, 0b00000, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b00000,
    ], // 'x'
    [
        0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110,
    ], // 'y'
    [
        0b00000, 0b00000, 0b11111, 0b00010, 0b00100, 0b01000, 0b11111, 0b00000,
    ], // 'z'
    [
        0b00010, 0b00100, 0b00100, 0b01000, 0b00100, 0b00100, 0b00010, 0b00000,
    ], // '{'
    [
        0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000,
    ], // '|'
    [
        0b01000, 0b00100, 0b00100, 0b00010, 0b00100, 0b00100, 0b01000, 0b00000,
    ], // '}'
    [
        0b00000, 0b00000, 0b01000, 0b10101, 0b00010, 0b00000, 0b00000, 0b00000,
    ], // '~'
];

/// The rows of the glyph for `c` (bit 4 leftmost); characters outside
/// printable ASCII are drawn as `?`.
pub fn glyph(c: char) -> [u8; 8] {
    let code = c as u32;
    if (32..=126).contains(&code) {
        FONT[(code - 32) as usize]
    } else {
        FONT[('?' as u32 - 32) as usize]
    }
}

/// Draws `text` into `film` with its top-left corner at `(x, y)`, each
/// font pixel a `scale` x `scale` block of `color` (linear RGB). Pixels
/// outside the film are skipped. Returns the width drawn, in pixels.
pub fn draw_text(film: &mut Film, x: u32, y: u32, text: &str, color: Vec3, scale: u32) -> u32 {
    let scale = scale.max(1);
    let mut cx = x;
    for c in text.chars() {
        let rows = glyph(c);
        for (gy, bits) in rows.iter().enumerate() {
            for gx in 0..GLYPH_WIDTH {
                if bits & (1 << (GLYPH_WIDTH - 1 - gx)) == 0 {
                    continue;
                }
                fill(
                    film,
                    cx + gx * scale,
                    y + gy as u32 * scale,
                    scale,
                    scale,
                    color,
                );
            }
        }
        cx += ADVANCE_X * scale;
    }
    cx - x
}

/// Fills a rectangle, clipped to the film.
fn fill(film: &mut Film, x: u32, y: u32, w: u32, h: u32, color: Vec3) {
    for py in y..(y + h).min(film.height) {
        for px in x..(x + w).min(film.width) {
            film.set(px, py, color);
        }
    }
}

/// Copies `src` into `dst` at `(x, y)` through `map` (clipped).
fn blit(dst: &mut Film, src: &Film, x: u32, y: u32, map: impl Fn(Vec3) -> Vec3) {
    for sy in 0..src.height {
        for sx in 0..src.width {
            if x + sx < dst.width && y + sy < dst.height {
                dst.set(x + sx, y + sy, map(src.get(sx, sy)));
            }
        }
    }
}

/// The text scale for images `height` pixels tall: 2 from 160 pixels up
/// (so labels stay readable next to large images), else 1.
pub fn text_scale(height: u32) -> u32 {
    if height >= 160 { 2 } else { 1 }
}

/// The size in pixels `(width, height)` of the sheet for `rows` images of
/// `width` x `height`: a header, then per row the image, the absolute error
/// image, the ꟻLIP error image and the label strip, separated and
/// surrounded by [`PAD`].
pub fn sheet_size(width: u32, height: u32, rows: u32) -> (u32, u32) {
    let s = text_scale(height);
    let label_w = LABEL_CHARS * ADVANCE_X * s;
    let row_h = height.max(LABEL_LINES * LINE_HEIGHT * s);
    let content_w = 3 * width + label_w + 3 * PAD;
    let header_w = header_chars() * ADVANCE_X * s;
    let w = content_w.max(header_w) + 2 * PAD;
    let h = PAD + header_height(s) + rows * (row_h + PAD);
    (w, h)
}

/// Width of the header text, in characters (the longer line is cut).
fn header_chars() -> u32 {
    2 * LABEL_CHARS
}

/// Height of the header (text lines and colour bar, plus padding).
fn header_height(s: u32) -> u32 {
    HEADER_LINES * LINE_HEIGHT * s + colour_bar_height(s) + PAD
}

fn colour_bar_height(s: u32) -> u32 {
    4 * s
}

/// A rendered contact sheet.
#[derive(Debug, Clone)]
pub struct Sheet {
    /// The sheet, as display-referred linear values in `[0, 1]` (already
    /// tone mapped): write it with [`OutputOptions::default`] (clamp, no
    /// exposure).
    pub film: Film,
    /// The absolute error (linear radiance, mean over channels) that maps to
    /// the top (yellow) of the colour map in every row.
    pub error_scale: f32,
}

/// Cuts `text` to `n` characters.
fn cut(text: &str, n: u32) -> String {
    text.chars().take(n as usize).collect()
}

/// Builds the contact sheet of `comparison`, headed by `title` (e.g. the
/// scene path). The images are tone mapped with each entry's own tone map
/// and exposure.
///
/// # Errors
/// Only if the comparison's images differ in size from the reference.
pub fn contact_sheet(comparison: &Comparison, title: &str) -> Result<Sheet> {
    let reference = &comparison.reference;
    let (w, h) = (reference.film.width, reference.film.height);
    let rows: Vec<&Entry> = std::iter::once(reference)
        .chain(&comparison.entries)
        .collect();

    // One error scale for every row: the largest per-technique 99th
    // percentile (difference_image's automatic scale).
    let mut error_scale = 0.0f32;
    for e in &comparison.entries {
        let auto = difference_image(&e.film, &reference.film, ErrorKind::Absolute, None)?;
        if auto.max_error > 0.0 {
            error_scale = error_scale.max(auto.scale);
        }
    }
    if !(error_scale.is_finite() && error_scale > 0.0) {
        error_scale = 1.0;
    }

    let s = text_scale(h);
    let (sw, sh) = sheet_size(w, h, rows.len() as u32);
    let mut film = Film::new(sw, sh);
    fill(&mut film, 0, 0, sw, sh, BACKGROUND);

    // Header: title, error convention and colour bar.
    let line = LINE_HEIGHT * s;
    let chars = (sw - 2 * PAD) / (ADVANCE_X * s);
    draw_text(&mut film, PAD, PAD, &cut(title, chars), TEXT, s);
    let caption = format!("|a-ref| 0 .. {error_scale:.3}; FLIP 0 .. 1");
    draw_text(
        &mut film,
        PAD,
        PAD + line,
        &cut(&caption, chars),
        DIM_TEXT,
        s,
    );
    // Colour bars over the error columns: viridis for |a - ref|, magma for FLIP.
    let bar_y = PAD + HEADER_LINES * line;
    for x in 0..w {
        let c = viridis(x as f32 / (w - 1).max(1) as f32);
        fill(
            &mut film,
            2 * PAD + w + x,
            bar_y,
            1,
            colour_bar_height(s),
            c,
        );
    }
    let magma = nv_flip::magma_lut().to_vec();
    let to_linear = tonemap::srgb8_to_linear_table();
    let entries = (magma.len() / 3).max(1);
    for x in 0..w {
        let k = (x as usize * (entries - 1) / (w - 1).max(1) as usize).min(entries - 1);
        let c = magma.get(3 * k..3 * k + 3).map_or(Vec3::ZERO, |c| {
            Vec3::new(
                to_linear[c[0] as usize],
                to_linear[c[1] as usize],
                to_linear[c[2] as usize],
            )
        });
        fill(
            &mut film,
            3 * PAD + 2 * w + x,
            bar_y,
            1,
            colour_bar_height(s),
            c,
        );
    }

    // One row per image.
    let row_h = h.max(LABEL_LINES * line);
    let mut y = PAD + header_height(s);
    for (i, e) in rows.iter().enumerate() {
        let tm = e.settings.tonemap;
        let ex = e.settings.exposure;
        blit(&mut film, &e.film, PAD, y, |c| tonemap_color(c, tm, ex));
        let err = difference_image(
            &e.film,
            &reference.film,
            ErrorKind::Absolute,
            Some(error_scale),
        )?;
        blit(&mut film, &err.film, 2 * PAD + w, y, |c| c);
        blit(&mut film, &e.flip_map, 3 * PAD + 2 * w, y, |c| c);
        let lx = 4 * PAD + 3 * w;
        let name = if i == 0 {
            let cached = if matches!(comparison.cache, CacheStatus::Hit(_)) {
                " cached"
            } else {
                ""
            };
            format!("{} ref{cached}", e.technique.name())
        } else {
            e.technique.name().to_string()
        };
        let lines = if i == 0 {
            // The reference against itself is 0 everywhere: show its own
            // estimated error instead (`~`), where it can be estimated.
            let n = &comparison.reference_noise;
            let est =
                |v: Option<f64>, d: usize| v.map_or_else(|| "-".into(), |v| format!("~{v:.d$}"));
            [
                (name, TEXT),
                (format!("{} spp", e.settings.samples), DIM_TEXT),
                (format!("{:.3} s", e.seconds), TEXT),
                (format!("relMSE {}", est(n.relative_mse, 5)), TEXT),
                ("FLIP -".into(), TEXT),
                ("PSNRd -".into(), TEXT),
                (format!("RMSE {}", est(n.rmse, 5)), DIM_TEXT),
                (
                    format!(
                        "PSNR {}",
                        n.psnr
                            .map_or_else(|| "-".into(), |p| format!("~{} dB", format_psnr(p)))
                    ),
                    DIM_TEXT,
                ),
                (format!("MRE  {}", est(n.mean_relative_error, 4)), DIM_TEXT),
            ]
        } else {
            [
                (name, TEXT),
                (format!("{} spp", e.settings.samples), DIM_TEXT),
                (format!("{:.3} s", e.seconds), TEXT),
                (format!("relMSE {:.5}", e.metrics.relative_mse), TEXT),
                (format!("FLIP {:.4}", e.metrics.flip), TEXT),
                (
                    format!("PSNRd {} dB", format_psnr(e.metrics.display_psnr)),
                    TEXT,
                ),
                (format!("RMSE {:.5}", e.metrics.rmse), DIM_TEXT),
                (format!("PSNR {} dB", format_psnr(e.metrics.psnr)), DIM_TEXT),
                (
                    format!("MRE  {:.4}", e.metrics.mean_relative_error),
                    DIM_TEXT,
                ),
            ]
        };
        for (k, (text, color)) in lines.iter().enumerate() {
            draw_text(
                &mut film,
                lx,
                y + k as u32 * line,
                &cut(text, LABEL_CHARS),
                *color,
                s,
            );
        }
        y += row_h + PAD;
    }
    Ok(Sheet { film, error_scale })
}

/// Builds the contact sheet (see [`contact_sheet`]) and writes it to
/// `path` (format from the extension, normally `.png`) atomically.
///
/// # Errors
/// Those of [`contact_sheet`], and [`chiaro_io::IoError`] if the file
/// cannot be written.
pub fn write_sheet(comparison: &Comparison, title: &str, path: &Path) -> Result<Sheet> {
    let sheet = contact_sheet(comparison, title)?;
    let opts = OutputOptions {
        tonemap: ToneMap::Clamp,
        ..OutputOptions::default()
    };
    write_film(&sheet.film, path, &opts)?;
    Ok(sheet)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_printable_glyph_but_space_has_ink_and_fits() {
        for code in 33u8..=126 {
            let g = glyph(code as char);
            assert!(g.iter().any(|&r| r != 0), "{}", code as char);
            assert!(g.iter().all(|&r| r < 32), "{}", code as char);
        }
        assert_eq!(glyph(' '), [0; 8]);
        assert_eq!(glyph('\u{e9}'), glyph('?'));
    }

    #[test]
    fn glyphs_are_distinct() {
        for a in 33u8..=126 {
            for b in (a + 1)..=126 {
                assert_ne!(
                    glyph(a as char),
                    glyph(b as char),
                    "{} {}",
                    a as char,
                    b as char
                );
            }
        }
    }

    #[test]
    fn draw_text_inks_the_right_pixels() {
        let mut f = Film::new(20, 10);
        let w = draw_text(&mut f, 1, 1, "L|", Vec3::ONE, 1);
        assert_eq!(w, 2 * ADVANCE_X);
        // 'L': left column and bottom row lit, top right not.
        assert_eq!(f.get(1, 1), Vec3::ONE);
        assert_eq!(f.get(1, 7), Vec3::ONE);
        assert_eq!(f.get(5, 7), Vec3::ONE);
        assert_eq!(f.get(5, 1), Vec3::ZERO);
        // '|': the middle column of the second cell.
        assert_eq!(f.get(1 + ADVANCE_X + 2, 4), Vec3::ONE);
        // Clipped at the edge without panicking.
        draw_text(&mut f, 18, 8, "WW", Vec3::ONE, 3);
    }

    #[test]
    fn draw_text_scales() {
        let mut f = Film::new(20, 20);
        draw_text(&mut f, 0, 0, "I", Vec3::ONE, 2);
        let lit = f.color.iter().filter(|c| c.x > 0.0).count();
        let bits: u32 = glyph('I').iter().map(|r| r.count_ones()).sum();
        assert_eq!(lit as u32, bits * 4);
    }

    #[test]
    fn sheet_size_grows_with_rows_and_images() {
        let (w1, h1) = sheet_size(24, 24, 3);
        let (w2, h2) = sheet_size(24, 24, 4);
        assert_eq!(w1, w2);
        assert_eq!(h2 - h1, 24u32.max(LABEL_LINES * LINE_HEIGHT) + PAD);
        let (w3, _) = sheet_size(300, 300, 3);
        assert!(w3 >= 2 * 300 + LABEL_CHARS * ADVANCE_X * 2);
    }
}
