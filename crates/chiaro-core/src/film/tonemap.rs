//! From linear radiance to display values: exposure, tone mapping and the
//! sRGB transfer functions.
//!
//! The pipeline for one pixel is `sanitize -> * 2^exposure -> tone map ->
//! clamp [0, 1] -> sRGB OETF -> quantise`. Tone maps act per channel on
//! linear values and return linear display values in `[0, 1]`; only the last
//! step encodes them. Decoding textures uses the inverse, [`srgb_eotf`].

use super::Film;
use crate::scene::ToneMap;
use crate::shading::sanitize;
use glam::Vec3;

/// The factor `2^stops` that an exposure of `stops` multiplies radiance by.
#[inline]
pub fn exposure_scale(stops: f32) -> f32 {
    if stops.is_finite() { stops.exp2() } else { 1.0 }
}

/// The ACES filmic curve fitted by Krzysztof Narkowicz (2015, "ACES Filmic
/// Tone Mapping Curve"): `x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`,
/// clamped to `[0, 1]`. Input is linear, non-negative.
#[inline]
pub fn aces_narkowicz(x: f32) -> f32 {
    let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
    ((x * (a * x + b)) / (x * (c * x + d) + e)).clamp(0.0, 1.0)
}

/// Applies a tone map to one linear channel value `x >= 0`, returning a
/// linear display value in `[0, 1]`. Negative, NaN and infinite inputs are
/// treated as 0 (infinity would be 1 for Reinhard and filmic, but a film never
/// holds one).
#[inline]
pub fn tonemap_channel(x: f32, tonemap: ToneMap) -> f32 {
    let x = if x.is_finite() && x > 0.0 { x } else { 0.0 };
    match tonemap {
        ToneMap::Clamp => x.min(1.0),
        // Reinhard et al. 2002, "Photographic Tone Reproduction", eq. 3.
        ToneMap::Reinhard => x / (1.0 + x),
        ToneMap::Filmic => aces_narkowicz(x),
    }
}

/// Exposes (by `2^exposure`, stops) and tone maps a linear colour, returning
/// linear display values in `[0, 1]` per channel. Never NaN.
#[inline]
pub fn tonemap_color(c: Vec3, tonemap: ToneMap, exposure: f32) -> Vec3 {
    let c = sanitize(c) * exposure_scale(exposure);
    Vec3::new(
        tonemap_channel(c.x, tonemap),
        tonemap_channel(c.y, tonemap),
        tonemap_channel(c.z, tonemap),
    )
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear
/// `[0, 1]` to encoded `[0, 1]`, exactly piecewise: `12.92 x` up to
/// `0.0031308`, then `1.055 x^(1/2.4) - 0.055`. Input is clamped to `[0, 1]`
/// (NaN gives 0).
#[inline]
pub fn srgb_oetf(x: f32) -> f32 {
    let x = if x > 0.0 { x.min(1.0) } else { 0.0 };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The sRGB electro-optical transfer function (IEC 61966-2-1), the inverse
/// of [`srgb_oetf`]: encoded `[0, 1]` to linear `[0, 1]`: `x / 12.92` up to
/// `0.04045`, then `((x + 0.055) / 1.055)^2.4`. Input is clamped to `[0, 1]`.
#[inline]
pub fn srgb_eotf(x: f32) -> f32 {
    let x = if x > 0.0 { x.min(1.0) } else { 0.0 };
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// The 256 linear values of the 8-bit sRGB codes: `table[v] = srgb_eotf(v / 255)`.
pub fn srgb8_to_linear_table() -> [f32; 256] {
    std::array::from_fn(|v| srgb_eotf(v as f32 / 255.0))
}

/// Encodes a linear display value in `[0, 1]` to an 8-bit sRGB code,
/// rounding to nearest.
#[inline]
pub fn linear_to_srgb8(x: f32) -> u8 {
    (srgb_oetf(x) * 255.0 + 0.5) as u8
}

/// Encodes a linear display value in `[0, 1]` to a 16-bit sRGB code,
/// rounding to nearest.
#[inline]
pub fn linear_to_srgb16(x: f32) -> u16 {
    (srgb_oetf(x) * 65535.0 + 0.5) as u16
}

/// The film as 8-bit sRGB, row-major from the top-left: each pixel exposed
/// by `2^exposure` (stops), tone mapped, and sRGB encoded.
pub fn to_srgb8(film: &Film, tonemap: ToneMap, exposure: f32) -> Vec<[u8; 3]> {
    encode_film(film, tonemap, exposure, linear_to_srgb8)
}

/// The film as 16-bit sRGB, like [`to_srgb8`] with codes in `0..=65535`.
pub fn to_srgb16(film: &Film, tonemap: ToneMap, exposure: f32) -> Vec<[u16; 3]> {
    encode_film(film, tonemap, exposure, linear_to_srgb16)
}

/// Each pixel of `film` exposed, tone mapped, and its channels encoded by
/// `encode` (red, green, blue in turn).
fn encode_film<T>(
    film: &Film,
    tonemap: ToneMap,
    exposure: f32,
    encode: impl Fn(f32) -> T,
) -> Vec<[T; 3]> {
    film.color
        .iter()
        .map(|&c| {
            let d = tonemap_color(c, tonemap, exposure);
            [encode(d.x), encode(d.y), encode(d.z)]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_known_values() {
        assert_eq!(srgb_oetf(0.0), 0.0);
        assert!((srgb_oetf(1.0) - 1.0).abs() < 1e-6);
        // Mid grey: linear 0.18 encodes to 0.4613561 (IEC 61966-2-1 formula).
        assert!((srgb_oetf(0.18) - 0.461_356_1).abs() < 1e-5);
        // Code 128 decodes to 0.2158605.
        assert!((srgb_eotf(128.0 / 255.0) - 0.215_860_5).abs() < 1e-6);
        // The linear segment and the continuity at the knee.
        assert!((srgb_oetf(0.002) - 0.02584).abs() < 1e-6);
        let below = srgb_oetf(0.003_130_8);
        let above = 1.055 * 0.003_130_8f32.powf(1.0 / 2.4) - 0.055;
        assert!((below - above).abs() < 1e-5);
        assert_eq!(linear_to_srgb8(0.18), 118);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb16(1.0), 65535);
    }

    #[test]
    fn srgb_round_trip() {
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            assert!((srgb_eotf(srgb_oetf(x)) - x).abs() < 2e-6, "{x}");
            assert!((srgb_oetf(srgb_eotf(x)) - x).abs() < 2e-6, "{x}");
        }
        // Every 8-bit code survives decode + encode.
        let table = srgb8_to_linear_table();
        for (v, &lin) in table.iter().enumerate() {
            assert_eq!(linear_to_srgb8(lin) as usize, v);
        }
    }

    #[test]
    fn tone_maps() {
        assert_eq!(tonemap_channel(2.0, ToneMap::Clamp), 1.0);
        assert_eq!(tonemap_channel(0.25, ToneMap::Clamp), 0.25);
        assert!((tonemap_channel(1.0, ToneMap::Reinhard) - 0.5).abs() < 1e-7);
        assert!((tonemap_channel(3.0, ToneMap::Reinhard) - 0.75).abs() < 1e-7);
        // Narkowicz at 1: 2.54 / 3.16.
        assert!((tonemap_channel(1.0, ToneMap::Filmic) - 2.54 / 3.16).abs() < 1e-6);
        assert_eq!(tonemap_channel(0.0, ToneMap::Filmic), 0.0);
        assert_eq!(tonemap_channel(1e6, ToneMap::Filmic), 1.0);
        // Monotone.
        for tm in [ToneMap::Clamp, ToneMap::Reinhard, ToneMap::Filmic] {
            let mut last = 0.0;
            for i in 0..200 {
                let y = tonemap_channel(i as f32 * 0.05, tm);
                assert!(y >= last && y <= 1.0);
                last = y;
            }
            assert_eq!(tonemap_channel(f32::NAN, tm), 0.0);
            assert_eq!(tonemap_channel(-1.0, tm), 0.0);
        }
    }

    #[test]
    fn exposure_in_stops() {
        assert_eq!(exposure_scale(0.0), 1.0);
        assert_eq!(exposure_scale(1.0), 2.0);
        assert_eq!(exposure_scale(-2.0), 0.25);
        let c = tonemap_color(Vec3::splat(0.25), ToneMap::Clamp, 1.0);
        assert_eq!(c, Vec3::splat(0.5));
    }

    #[test]
    fn film_to_8_and_16_bit() {
        let mut film = Film::new(2, 1);
        film.set(0, 0, Vec3::new(0.18, 1.0, 4.0));
        film.color[1] = Vec3::new(f32::NAN, f32::INFINITY, -1.0);
        let p8 = to_srgb8(&film, ToneMap::Clamp, 0.0);
        assert_eq!(p8, vec![[118, 255, 255], [0, 0, 0]]);
        let p16 = to_srgb16(&film, ToneMap::Clamp, 0.0);
        assert_eq!(p16[0][1], 65535);
        assert_eq!(p16[1], [0, 0, 0]);
        assert!((f32::from(p16[0][0]) / 65535.0 - 0.461_356).abs() < 2e-5);
    }
}
