//! Image metrics for comparing techniques, the one set that `compare`, the
//! web viewer's split view and Python's `chiaro.metrics` report
//! ([`Metrics`], [`measure`]): relative MSE and ꟻLIP (the measures to rank
//! by), the PSNR of the displayed images, and RMSE, PSNR and mean relative
//! error of linear radiance; besides them, a false-colour difference image
//! and the ꟻLIP map.
//!
//! The metrics work over every channel of every pixel; `a` is the image
//! under test and `b` the reference, of the same size. RMSE, PSNR, the mean
//! relative error and relative MSE read the films' **linear** colours
//! (before exposure and tone mapping); `display_mse`, `display_psnr` and
//! ꟻLIP read them as an 8-bit PNG shows them (clamped, sRGB-encoded), where
//! an emitter far brighter than white cannot dominate. Linear RMSE and PSNR
//! are dominated by the few brightest pixels (an emitter's edge: phong
//! against path on a scene with visible lights can read PSNR -9 dB for two
//! pictures that look alike), hence ranking by relMSE and ꟻLIP.

use chiaro_core::Vec3;
use chiaro_core::error::{CoreError, Result};
use chiaro_core::film::Film;
use chiaro_core::film::tonemap::{self, srgb_eotf, srgb_oetf};
use chiaro_core::scene::ToneMap;
use chiaro_core::shading::sanitize;
use serde::Serialize;

/// The `epsilon` in the mean relative error `|a - b| / (b + epsilon)`: keeps
/// black reference pixels from dominating (the convention of e.g. the
/// "relMSE" of Rousselle et al. 2011 uses 0.01 as well).
pub const RELATIVE_EPSILON: f32 = 0.01;

fn check_sizes(a: &Film, b: &Film) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(CoreError::Unsupported(format!(
            "cannot compare images of different sizes: {}x{} and {}x{}",
            a.width, a.height, b.width, b.height
        )));
    }
    Ok(())
}

/// Iterates over the channel pairs `(a, b)` of two equally sized films, NaN
/// and negative values read as 0.
fn channels<'f>(a: &'f Film, b: &'f Film) -> impl Iterator<Item = (f64, f64)> + 'f {
    a.color.iter().zip(&b.color).flat_map(|(&x, &y)| {
        let (x, y) = (sanitize(x), sanitize(y));
        [(x.x, y.x), (x.y, y.y), (x.z, y.z)].map(|(p, q)| (f64::from(p), f64::from(q)))
    })
}

/// The mean over all channel pairs of `err(a, b)` (0 for empty films).
fn mean_channel_error(a: &Film, b: &Film, err: impl Fn(f64, f64) -> f64) -> Result<f64> {
    check_sizes(a, b)?;
    let n = a.color.len() * 3;
    if n == 0 {
        return Ok(0.0);
    }
    Ok(channels(a, b).map(|(p, q)| err(p, q)).sum::<f64>() / n as f64)
}

/// Mean squared error over all channels (linear units squared).
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn mse(a: &Film, b: &Film) -> Result<f64> {
    mean_channel_error(a, b, |p, q| (p - q) * (p - q))
}

/// Root mean squared error over all channels, in linear radiance units:
/// `sqrt(mean((a - b)^2))`.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn rmse(a: &Film, b: &Film) -> Result<f64> {
    mse(a, b).map(f64::sqrt)
}

/// Peak signal-to-noise ratio in decibels, `10 log10(peak^2 / MSE)`, with
/// the MSE on linear values and the stated `peak` (1.0 for a film whose
/// white is 1). Identical films give `f64::INFINITY`.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size or `peak` is not
/// positive and finite.
pub fn psnr(a: &Film, b: &Film, peak: f32) -> Result<f64> {
    if !(peak.is_finite() && peak > 0.0) {
        return Err(CoreError::Unsupported(format!(
            "PSNR peak must be positive, got {peak}"
        )));
    }
    let m = mse(a, b)?;
    if m == 0.0 {
        return Ok(f64::INFINITY);
    }
    let p = f64::from(peak);
    Ok(10.0 * (p * p / m).log10())
}

/// Mean relative error over all channels,
/// `mean(|a - b| / (b + RELATIVE_EPSILON))`, dimensionless (0.05 = 5 %),
/// with `b` the reference.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn mean_relative_error(a: &Film, b: &Film) -> Result<f64> {
    let eps = f64::from(RELATIVE_EPSILON);
    mean_channel_error(a, b, |p, q| (p - q).abs() / (q + eps))
}

/// Relative mean squared error over all channels,
/// `mean((a - b)^2 / (b^2 + RELATIVE_EPSILON))` (Rousselle et al. 2011, the
/// measure rendering papers report): each pixel's error relative to its own
/// brightness, so a bright emitter's edge weighs as much as a dim wall.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn relative_mse(a: &Film, b: &Film) -> Result<f64> {
    let eps = f64::from(RELATIVE_EPSILON);
    mean_channel_error(a, b, |p, q| (p - q) * (p - q) / (q * q + eps))
}

/// The displayed value of a linear channel: clamped to `[0, 1]` and
/// sRGB-encoded, what an 8-bit PNG of the film shows (before quantising).
#[inline]
pub fn display_channel(x: f32) -> f32 {
    srgb_oetf(sanitize(Vec3::splat(x)).x.min(1.0))
}

/// Mean squared error of the **displayed** images ([`display_channel`]):
/// what the eye compares on screen, where an emitter brighter than white is
/// white in both images whatever its radiance.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn display_mse(a: &Film, b: &Film) -> Result<f64> {
    mean_channel_error(a, b, |p, q| {
        let d = f64::from(display_channel(p as f32)) - f64::from(display_channel(q as f32));
        d * d
    })
}

/// PSNR of the displayed images ([`display_mse`]) in dB, peak 1 (white):
/// the usual 8-bit PSNR up to quantisation. Identical displays give
/// `f64::INFINITY`.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn display_psnr(a: &Film, b: &Film) -> Result<f64> {
    let m = display_mse(a, b)?;
    Ok(if m == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * m.log10()
    })
}

/// ꟻLIP between the displayed images of `test` and `reference` (clamped,
/// sRGB 8-bit, as [`display_channel`] shows them; Andersson et al. 2020,
/// NVIDIA's perceptual difference, LDR version, 67 pixels per degree): the
/// mean error in `[0, 1]` and the per-pixel error in the magma colour map,
/// as linear RGB.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn flip(test: &Film, reference: &Film) -> Result<(f64, Film)> {
    let map = flip_image(test, reference)?;
    let (w, h) = (reference.width, reference.height);
    let mean = f64::from(nv_flip::FlipPool::from_image(&map).mean());
    let colours = map.apply_color_lut(&nv_flip::magma_lut()).to_vec();
    let to_linear = tonemap::srgb8_to_linear_table();
    let mut film = Film::new(w, h);
    for (px, c) in film.color.iter_mut().zip(colours.chunks_exact(3)) {
        *px = Vec3::new(
            to_linear[c[0] as usize],
            to_linear[c[1] as usize],
            to_linear[c[2] as usize],
        );
    }
    Ok((if mean.is_finite() { mean } else { 1.0 }, film))
}

/// The ꟻLIP error of every pixel (row by row, in `[0, 1]`) between the
/// displayed images of `test` and `reference`, as [`flip`] computes it.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn flip_errors(test: &Film, reference: &Film) -> Result<Vec<f32>> {
    Ok(flip_image(test, reference)?.to_vec())
}

fn flip_image(test: &Film, reference: &Film) -> Result<nv_flip::FlipImageFloat> {
    check_sizes(test, reference)?;
    let (w, h) = (reference.width, reference.height);
    let rgb8 = |f: &Film| -> Vec<u8> {
        tonemap::to_srgb8(f, ToneMap::Clamp, 0.0)
            .into_iter()
            .flatten()
            .collect()
    };
    Ok(nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(reference)),
        nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(test)),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    ))
}

/// The numbers reported for an image against a reference, wherever one is
/// compared (`compare`'s report and contact sheet, the web viewer, Python).
/// Serialised with these names; an infinite PSNR (identical images) becomes
/// JSON `null`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Metrics {
    /// [`relative_mse`] (dimensionless): rank by this or [`Self::flip`].
    pub relative_mse: f64,
    /// The mean of [`flip`]'s per-pixel error, 0 (identical) to 1.
    pub flip: f64,
    /// [`display_psnr`] in dB; infinite when the displays are identical.
    pub display_psnr: f64,
    /// [`rmse`], linear radiance units.
    pub rmse: f64,
    /// [`psnr`] in dB with peak 1.0 (linear radiance); infinite when the
    /// images are identical.
    pub psnr: f64,
    /// [`mean_relative_error`] (dimensionless).
    pub mean_relative_error: f64,
}

/// Every [`Metrics`] number of `test` against `reference`.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn measure(test: &Film, reference: &Film) -> Result<Metrics> {
    measure_with_flip_map(test, reference).map(|(m, _)| m)
}

/// [`measure`], and the ꟻLIP map that comes with it ([`flip`]).
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn measure_with_flip_map(test: &Film, reference: &Film) -> Result<(Metrics, Film)> {
    let (flip, flip_map) = flip(test, reference)?;
    let metrics = Metrics {
        relative_mse: relative_mse(test, reference)?,
        flip,
        display_psnr: display_psnr(test, reference)?,
        rmse: rmse(test, reference)?,
        psnr: psnr(test, reference, 1.0)?,
        mean_relative_error: mean_relative_error(test, reference)?,
    };
    Ok((metrics, flip_map))
}

/// Which per-pixel error the difference image shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ErrorKind {
    /// Mean over channels of `|a - b|` (linear radiance units).
    #[default]
    Absolute,
    /// Mean over channels of `|a - b| / (b + RELATIVE_EPSILON)`.
    Relative,
}

/// The viridis colour map (van der Walt and Smith, matplotlib 2015), sampled
/// at 9 evenly spaced points as 8-bit sRGB (`viridis(9)` in R):
/// #440154 #472D7B #3B528B #2C728E #21908C #27AD81 #5DC863 #AADC32 #FDE725.
const VIRIDIS: [[u8; 3]; 9] = [
    [0x44, 0x01, 0x54],
    [0x47, 0x2d, 0x7b],
    [0x3b, 0x52, 0x8b],
    [0x2c, 0x72, 0x8e],
    [0x21, 0x90, 0x8c],
    [0x27, 0xad, 0x81],
    [0x5d, 0xc8, 0x63],
    [0xaa, 0xdc, 0x32],
    [0xfd, 0xe7, 0x25],
];

/// The viridis colour at `t` in `[0, 1]` (clamped; NaN gives 0), as
/// **linear** RGB, so that writing it through the sRGB encoder shows the
/// published colours. Interpolated linearly between the 9 samples in sRGB
/// code space.
pub fn viridis(t: f32) -> Vec3 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (VIRIDIS.len() - 1) as f32;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f32;
    let c = |k: usize| {
        Vec3::new(
            VIRIDIS[k][0].into(),
            VIRIDIS[k][1].into(),
            VIRIDIS[k][2].into(),
        )
    };
    let s = (c(i) * (1.0 - f) + c(i + 1) * f) / 255.0;
    Vec3::new(srgb_eotf(s.x), srgb_eotf(s.y), srgb_eotf(s.z))
}

/// A false-colour difference image.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorImage {
    /// The per-pixel error mapped through [`viridis`]: dark purple is no
    /// error, yellow is `scale` or more. Depth and normal are those of `a`.
    pub film: Film,
    /// The error that maps to the top of the colour map.
    pub scale: f32,
    /// The largest per-pixel error.
    pub max_error: f32,
}

/// A false-colour image of the per-pixel error between `a` and the
/// reference `b` (see [`ErrorKind`]), each pixel's error divided by `scale`
/// and mapped through [`viridis`]. Without a `scale` (or with a non-positive
/// one) the 99th percentile of the per-pixel errors is used (the largest
/// error if that is 0; 1 if all are 0), so a few fireflies do not wash out
/// the image.
///
/// # Errors
/// [`CoreError::Unsupported`] if the films differ in size.
pub fn difference_image(
    a: &Film,
    b: &Film,
    kind: ErrorKind,
    scale: Option<f32>,
) -> Result<ErrorImage> {
    check_sizes(a, b)?;
    let errors: Vec<f32> = a
        .color
        .iter()
        .zip(&b.color)
        .map(|(&x, &y)| {
            let (x, y) = (sanitize(x), sanitize(y));
            let d = (x - y).abs();
            let e = match kind {
                ErrorKind::Absolute => d,
                ErrorKind::Relative => d / (y + Vec3::splat(RELATIVE_EPSILON)),
            };
            let m = (e.x + e.y + e.z) / 3.0;
            if m.is_finite() { m } else { 0.0 }
        })
        .collect();
    let max_error = errors.iter().copied().fold(0.0, f32::max);
    let scale = match scale {
        Some(s) if s.is_finite() && s > 0.0 => s,
        _ => {
            let mut sorted = errors.clone();
            sorted.sort_by(f32::total_cmp);
            let p99 = sorted
                .get((sorted.len() as f32 * 0.99) as usize)
                .or(sorted.last())
                .copied()
                .unwrap_or(0.0);
            if p99 > 0.0 {
                p99
            } else if max_error > 0.0 {
                max_error
            } else {
                1.0
            }
        }
    };
    let mut film = a.clone();
    for (c, &e) in film.color.iter_mut().zip(&errors) {
        *c = viridis(e / scale);
    }
    Ok(ErrorImage {
        film,
        scale,
        max_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(w: u32, h: u32, c: Vec3) -> Film {
        let mut f = Film::new(w, h);
        f.color.fill(c);
        f
    }

    #[test]
    fn rmse_and_psnr_closed_forms() {
        let a = flat(4, 4, Vec3::splat(0.5));
        let b = flat(4, 4, Vec3::splat(0.4));
        // Every channel differs by 0.1: RMSE 0.1, PSNR 20 dB at peak 1.
        assert!((rmse(&a, &b).unwrap_or(0.0) - 0.1).abs() < 1e-6);
        assert!((psnr(&a, &b, 1.0).unwrap_or(0.0) - 20.0).abs() < 1e-4);
        // Peak 10 adds 20 dB.
        assert!((psnr(&a, &b, 10.0).unwrap_or(0.0) - 40.0).abs() < 1e-4);
        assert_eq!(psnr(&a, &a, 1.0).ok(), Some(f64::INFINITY));
        assert!(psnr(&a, &b, 0.0).is_err());
        // One channel of one pixel off by 1 out of 16 * 3 channels.
        let mut c = a.clone();
        c.color[5].y += 1.0;
        assert!((mse(&c, &a).unwrap_or(0.0) - 1.0 / 48.0).abs() < 1e-9);
    }

    #[test]
    fn relative_error_closed_form() {
        let a = flat(2, 2, Vec3::splat(1.1));
        let b = flat(2, 2, Vec3::splat(0.99));
        let e = mean_relative_error(&a, &b).unwrap_or(0.0);
        assert!((e - 0.11).abs() < 1e-6, "{e}");
        // Black reference: |a| / 0.01.
        let z = flat(2, 2, Vec3::ZERO);
        let e = mean_relative_error(&flat(2, 2, Vec3::splat(0.001)), &z).unwrap_or(0.0);
        assert!((e - 0.1).abs() < 1e-6);
    }

    #[test]
    fn relative_mse_closed_form() {
        let a = flat(2, 2, Vec3::splat(1.1));
        let b = flat(2, 2, Vec3::splat(1.0));
        let e = relative_mse(&a, &b).unwrap_or(0.0);
        assert!((e - 0.01 / 1.01).abs() < 1e-6, "{e}");
        // 10 % off counts about the same on a dim and on a bright pixel
        // (0.02^2 / (0.04 + 0.01) and 2^2 / (400 + 0.01)).
        let dim = relative_mse(
            &flat(1, 1, Vec3::splat(0.22)),
            &flat(1, 1, Vec3::splat(0.2)),
        );
        let bright = relative_mse(
            &flat(1, 1, Vec3::splat(22.0)),
            &flat(1, 1, Vec3::splat(20.0)),
        );
        let (dim, bright) = (dim.unwrap_or(0.0), bright.unwrap_or(0.0));
        assert!((dim - 0.008).abs() < 1e-6, "{dim}");
        assert!((bright - 4.0 / 400.01).abs() < 1e-7, "{bright}");
    }

    #[test]
    fn display_metrics_see_what_the_screen_shows() {
        // An emitter at 17 rendered at 15: both display as white.
        let a = flat(2, 2, Vec3::splat(17.0));
        let b = flat(2, 2, Vec3::splat(15.0));
        assert!((rmse(&a, &b).unwrap_or(0.0) - 2.0).abs() < 1e-6);
        assert_eq!(display_mse(&a, &b).ok(), Some(0.0));
        assert_eq!(display_psnr(&a, &b).ok(), Some(f64::INFINITY));
        // 0.5 against 0.4 linear: sRGB 0.7354 against 0.6653.
        let d = display_mse(&flat(1, 1, Vec3::splat(0.5)), &flat(1, 1, Vec3::splat(0.4)))
            .unwrap_or(0.0);
        let expect = (0.735_357_f64 - 0.665_185).powi(2);
        assert!((d - expect).abs() < 1e-5, "{d}");
        let p = display_psnr(&flat(1, 1, Vec3::splat(0.5)), &flat(1, 1, Vec3::splat(0.4)));
        assert!((p.unwrap_or(0.0) + 10.0 * expect.log10()).abs() < 1e-3);
    }

    #[test]
    fn sizes_must_match() {
        let a = Film::new(2, 2);
        let b = Film::new(3, 2);
        assert!(rmse(&a, &b).is_err());
        assert!(mean_relative_error(&a, &b).is_err());
        assert!(measure(&a, &b).is_err());
        assert!(difference_image(&a, &b, ErrorKind::Absolute, None).is_err());
    }

    #[test]
    fn measure_gathers_the_single_metrics() {
        let b = flat(8, 8, Vec3::splat(0.4));
        let mut a = b.clone();
        a.color[9] = Vec3::new(0.9, 0.1, 0.4);
        let (m, map) = measure_with_flip_map(&a, &b).expect("same size");
        assert_eq!(m.relative_mse, relative_mse(&a, &b).expect("same size"));
        assert_eq!(m.display_psnr, display_psnr(&a, &b).expect("same size"));
        assert_eq!(m.rmse, rmse(&a, &b).expect("same size"));
        assert_eq!(m.psnr, psnr(&a, &b, 1.0).expect("same size"));
        assert_eq!(m.flip, flip(&a, &b).expect("same size").0);
        assert!(m.flip > 0.0 && m.flip < 1.0, "{}", m.flip);
        assert_eq!((map.width, map.height), (8, 8));
        // Identical images: no error, infinite PSNRs written as null.
        let same = measure(&b, &b).expect("same size");
        assert_eq!((same.relative_mse, same.rmse, same.flip), (0.0, 0.0, 0.0));
        let json = serde_json::to_value(same).expect("serialises");
        assert!(
            json["psnr"].is_null() && json["display_psnr"].is_null(),
            "{json}"
        );
    }

    #[test]
    fn nan_is_read_as_zero() {
        let mut a = flat(2, 1, Vec3::ZERO);
        a.color[0] = Vec3::splat(f32::NAN);
        let b = flat(2, 1, Vec3::ZERO);
        assert_eq!(rmse(&a, &b).ok(), Some(0.0));
    }

    #[test]
    fn viridis_endpoints() {
        let lo = viridis(0.0);
        let hi = viridis(1.0);
        assert!((lo.x - srgb_eotf(68.0 / 255.0)).abs() < 1e-6);
        assert!((hi.y - srgb_eotf(231.0 / 255.0)).abs() < 1e-6);
        assert_eq!(viridis(-3.0), lo);
        assert_eq!(viridis(f32::NAN), lo);
        assert_eq!(viridis(7.0), hi);
        // Luminance increases along the map.
        let luma = |c: Vec3| 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
        for i in 1..=20 {
            assert!(luma(viridis(i as f32 / 20.0)) > luma(viridis((i - 1) as f32 / 20.0)));
        }
    }

    #[test]
    fn difference_image_maps_error_to_colour() {
        let b = flat(4, 1, Vec3::splat(0.5));
        let mut a = b.clone();
        a.color[1] = Vec3::splat(0.75); // error 0.25
        a.color[2] = Vec3::splat(1.0); // error 0.5
        let img = difference_image(&a, &b, ErrorKind::Absolute, Some(0.5)).expect("same size");
        assert_eq!(img.scale, 0.5);
        assert!((img.max_error - 0.5).abs() < 1e-6);
        assert_eq!(img.film.color[0], viridis(0.0));
        assert!((img.film.color[1] - viridis(0.5)).abs().max_element() < 1e-6);
        assert_eq!(img.film.color[2], viridis(1.0));
        assert!(img.film.is_clean());
        // Automatic scale: the 99th percentile, here the largest error.
        let auto = difference_image(&a, &b, ErrorKind::Absolute, None).expect("same size");
        assert!((auto.scale - 0.5).abs() < 1e-6);
        // Relative: 0.25 / 0.51.
        let rel = difference_image(&a, &b, ErrorKind::Relative, Some(1.0)).expect("same size");
        assert!(
            (rel.film.color[1] - viridis(0.25 / 0.51))
                .abs()
                .max_element()
                < 1e-5
        );
    }
}
