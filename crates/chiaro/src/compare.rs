//! `compare`: render one scene with several techniques, measure each against
//! a reference, and report the errors and times.
//!
//! The reference is, by default, the path tracer at [`DEFAULT_REFERENCE_SPP`]
//! samples per pixel with the same image size and `--set` options as the
//! techniques under test, and a seed derived from theirs
//! ([`reference_seed`]) so that a path-traced entry is not correlated with
//! the reference. It can be cached as OpenEXR (lossless `f32`) in a cache
//! directory, keyed by a hash of the scene and the reference settings
//! ([`cache_key`]), and reused.
//!
//! Metrics (see `chiaro_core::film::metrics`) are computed on **linear**
//! radiance, before exposure and tone mapping, over all channels:
//! - `rmse`: `sqrt(mean((a - r)^2))`, radiance units;
//! - `psnr`: `10 log10(1 / MSE)` dB, i.e. linear values with a peak of 1.0
//!   (white of an unexposed, clamped image); infinite (JSON `null`) for an
//!   image identical to the reference;
//! - `mean_relative_error`: `mean(|a - r| / (r + 0.01))`, dimensionless;
//! - `relative_mse`: `mean((a - r)^2 / (r^2 + 0.01))`, the relMSE of
//!   rendering papers: every pixel's error relative to its brightness.
//!
//! and on the **displayed** images (clamped to `[0, 1]`, sRGB-encoded, as
//! an 8-bit PNG shows them), where emitters brighter than white cannot
//! dominate:
//! - `display_psnr`: PSNR of the displayed values, peak 1 (dB);
//! - `flip`: the mean of ꟻLIP (Andersson et al. 2020, NVIDIA's perceptual
//!   difference, LDR version, 67 pixels per degree), 0 = identical, 1 =
//!   maximal; its per-pixel map is drawn on the contact sheet.
//!
//! Rank techniques by `relative_mse` or `flip`: linear RMSE and PSNR are
//! dominated by the few pixels where the reference is brightest (the
//! emitter's edge in a Cornell box).
//!
//! ```no_run
//! use chiaro::compare::{compare, ReferenceSpec};
//! use chiaro::{NoProgress, Technique};
//! let scene = chiaro::io::load_scene("scenes/cornell-box.toml".as_ref()).unwrap().scene;
//! let mut base = scene.render.clone();
//! base.width = 64;
//! base.height = 64;
//! let reference = ReferenceSpec::parse("path:64").unwrap();
//! let c = compare(&scene, &base, &[Technique::Phong, Technique::Whitted], &reference, None, &NoProgress).unwrap();
//! println!("{}", c.to_markdown());
//! ```

use crate::{Error, Result, available_techniques, render_with_stats};
use chiaro_core::Vec3;
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, metrics, tonemap};
use chiaro_core::progress::Progress;
use chiaro_core::scene::{RenderSettings, Scene, Technique, ToneMap};
use chiaro_io::output::{OutputOptions, read_image_as_film, write_atomically, write_film};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Samples per pixel of the default reference (`path:256`).
pub const DEFAULT_REFERENCE_SPP: u32 = 256;

/// The PSNR convention, as written into the report.
pub const PSNR_CONVENTION: &str = "linear radiance before tone mapping, peak 1.0";

/// Which technique renders the reference, and with how many samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReferenceSpec {
    /// The reference technique (normally [`Technique::Path`]).
    pub technique: Technique,
    /// Samples per pixel of the reference.
    pub samples: u32,
}

impl Default for ReferenceSpec {
    fn default() -> Self {
        Self {
            technique: Technique::Path,
            samples: DEFAULT_REFERENCE_SPP,
        }
    }
}

impl ReferenceSpec {
    /// Parses `TECHNIQUE:SPP`, `TECHNIQUE` (default SPP) or `SPP` (path
    /// tracer), e.g. `path:64`.
    ///
    /// # Errors
    /// [`CoreError::BadSetting`] (key `reference`) for an unknown or
    /// unavailable technique, or an SPP that is not a positive integer.
    pub fn parse(text: &str) -> Result<Self, CoreError> {
        let bad = |message: String| CoreError::BadSetting {
            key: "reference".into(),
            message,
        };
        let text = text.trim();
        let (name, spp) = match text.split_once(':') {
            Some((n, s)) => (n.trim(), Some(s.trim())),
            None if text.chars().all(|c| c.is_ascii_digit()) && !text.is_empty() => {
                ("path", Some(text))
            }
            None => (text, None),
        };
        let technique = Technique::from_name(name)
            .filter(|t| available_techniques().contains(t))
            .ok_or_else(|| {
                bad(format!(
                    "unknown technique `{name}` in `{text}` (expected TECHNIQUE:SPP, e.g. path:256; available: {})",
                    crate::technique_list()
                ))
            })?;
        let samples = match spp {
            None => DEFAULT_REFERENCE_SPP,
            Some(s) => match s.parse::<u32>() {
                Ok(n) if n > 0 => n,
                _ => {
                    return Err(bad(format!(
                        "samples per pixel `{s}` in `{text}` is not a positive integer"
                    )));
                }
            },
        };
        Ok(Self { technique, samples })
    }

    /// The settings the reference is rendered with: `base` with this
    /// technique and sample count and the seed [`reference_seed`]`(base.seed)`.
    pub fn settings(&self, base: &RenderSettings) -> RenderSettings {
        RenderSettings {
            technique: self.technique,
            samples: self.samples,
            seed: reference_seed(base.seed),
            ..base.clone()
        }
    }
}

/// The seed of the reference render for techniques rendered with `seed`:
/// a different stream, so that a Monte Carlo entry's noise is measured
/// rather than shared with the reference. The result fits in 53 bits, so
/// it survives a round trip through JSON numbers (IEEE doubles).
pub fn reference_seed(seed: u64) -> u64 {
    // splitmix64 finaliser (Steele, Lea and Flood 2014) of seed + a constant.
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)) >> 11
}

/// One rendered image and its errors against the reference.
#[derive(Debug, Clone)]
pub struct Entry {
    /// The technique.
    pub technique: Technique,
    /// The exact settings it was rendered with.
    pub settings: RenderSettings,
    /// The image (linear radiance).
    pub film: Film,
    /// Render wall-clock time in seconds (for a cached reference: the time
    /// of the render that filled the cache, 0 if unknown).
    pub seconds: f64,
    /// RMSE against the reference, linear radiance units.
    pub rmse: f64,
    /// PSNR against the reference in dB ([`PSNR_CONVENTION`]); infinite for
    /// an identical image.
    pub psnr: f64,
    /// Mean relative error against the reference (dimensionless).
    pub mean_relative_error: f64,
    /// Relative MSE against the reference (dimensionless).
    pub relative_mse: f64,
    /// PSNR of the displayed images in dB; infinite when they are identical.
    pub display_psnr: f64,
    /// Mean ꟻLIP error of the displayed images, in `[0, 1]`.
    pub flip: f64,
    /// The ꟻLIP error per pixel in the magma colour map (linear RGB).
    pub flip_map: Film,
}

/// What happened with the reference cache.
#[derive(Debug, Clone, PartialEq)]
pub enum CacheStatus {
    /// No cache directory was given.
    Disabled,
    /// The reference was read from this file.
    Hit(PathBuf),
    /// The reference was rendered and stored in this file.
    Stored(PathBuf),
    /// The reference was rendered but could not be stored (the message says why).
    StoreFailed(String),
}

/// The result of [`compare`].
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The reference (its metrics are against itself: 0, 0, infinite PSNR).
    pub reference: Entry,
    /// The techniques under test, in the order asked for.
    pub entries: Vec<Entry>,
    /// Whether the reference came from, or went to, the cache.
    pub cache: CacheStatus,
}

/// One row of the report: the fields named in the issue.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TechniqueReport {
    /// Technique name (`phong`).
    pub technique: String,
    /// RMSE, linear radiance units.
    pub rmse: f64,
    /// PSNR in dB, `null` when infinite (identical to the reference).
    pub psnr: Option<f64>,
    /// Mean relative error (dimensionless).
    pub mean_relative_error: f64,
    /// Relative MSE (dimensionless).
    pub relative_mse: f64,
    /// PSNR of the displayed (clamped, sRGB) images in dB, `null` when identical.
    pub display_psnr: Option<f64>,
    /// Mean ꟻLIP error of the displayed images, 0 (identical) to 1.
    pub flip: f64,
    /// Render time in seconds.
    pub seconds: f64,
    /// Samples per pixel it was rendered with.
    pub samples: u32,
}

/// The reference's part of the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceReport {
    /// Technique name (`path`).
    pub technique: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Seed it was rendered with.
    pub seed: u64,
    /// Render time in seconds (of the original render if cached; 0 if unknown).
    pub seconds: f64,
    /// Whether it was read from the cache.
    pub cached: bool,
}

/// The JSON report of a comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// The scene, as named by the caller (normally its path).
    pub scene: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// How PSNR was computed ([`PSNR_CONVENTION`]).
    pub psnr_convention: String,
    /// The reference.
    pub reference: ReferenceReport,
    /// One row per technique, in the order asked for.
    pub techniques: Vec<TechniqueReport>,
}

impl Comparison {
    /// The report for this comparison of the scene named `scene`.
    pub fn report(&self, scene: &str) -> Report {
        let r = &self.reference;
        Report {
            scene: scene.into(),
            width: r.film.width,
            height: r.film.height,
            psnr_convention: PSNR_CONVENTION.into(),
            reference: ReferenceReport {
                technique: r.technique.name().into(),
                spp: r.settings.samples,
                seed: r.settings.seed,
                seconds: r.seconds,
                cached: matches!(self.cache, CacheStatus::Hit(_)),
            },
            techniques: self
                .entries
                .iter()
                .map(|e| TechniqueReport {
                    technique: e.technique.name().into(),
                    rmse: e.rmse,
                    psnr: e.psnr.is_finite().then_some(e.psnr),
                    mean_relative_error: e.mean_relative_error,
                    relative_mse: e.relative_mse,
                    display_psnr: e.display_psnr.is_finite().then_some(e.display_psnr),
                    flip: e.flip,
                    seconds: e.seconds,
                    samples: e.settings.samples,
                })
                .collect(),
        }
    }

    /// The report as pretty-printed JSON.
    pub fn to_json(&self, scene: &str) -> String {
        // A struct of strings and numbers (non-finite PSNR already `None`)
        // always serialises.
        serde_json::to_string_pretty(&self.report(scene)).unwrap_or_default()
    }

    /// A Markdown table: one row per technique, then the reference.
    pub fn to_markdown(&self) -> String {
        let mut s = String::from(
            "| technique | spp | seconds | relMSE | FLIP | PSNR display (dB) | RMSE | PSNR (dB) | mean rel. error |\n\
             |---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for e in &self.entries {
            s += &format!(
                "| {} | {} | {:.3} | {:.5} | {:.4} | {} | {:.5} | {} | {:.4} |\n",
                e.technique.name(),
                e.settings.samples,
                e.seconds,
                e.relative_mse,
                e.flip,
                format_psnr(e.display_psnr),
                e.rmse,
                format_psnr(e.psnr),
                e.mean_relative_error
            );
        }
        let r = &self.reference;
        s += &format!(
            "| {} (reference{}) | {} | {:.3} | - | - | - | - | - | - |\n",
            r.technique.name(),
            if matches!(self.cache, CacheStatus::Hit(_)) {
                ", cached"
            } else {
                ""
            },
            r.settings.samples,
            r.seconds
        );
        s
    }
}

/// PSNR for people: `inf` or two decimals.
pub fn format_psnr(psnr: f64) -> String {
    if psnr.is_finite() {
        format!("{psnr:.2}")
    } else {
        "inf".into()
    }
}

/// An FNV-1a 64-bit hasher usable as an `io::Write` sink (Fowler, Noll and
/// Vo; constants from the IETF draft draft-eastlake-fnv). Stable across
/// runs and Rust versions, unlike `DefaultHasher`.
struct Fnv64(u64);

impl Write for Fnv64 {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        for &b in buf {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The cache key of the reference image of `scene` rendered with
/// `reference_settings`: 16 hex digits of a hash of the scene's JSON
/// serialisation with those settings in place, and this crate's version.
pub fn cache_key(scene: &Scene, reference_settings: &RenderSettings) -> String {
    let mut h = Fnv64(0xcbf2_9ce4_8422_2325);
    let keyed = Scene {
        render: reference_settings.clone(),
        ..scene.clone()
    };
    // Writing into the hasher cannot fail; a serialisation failure would
    // only make a weaker key, and the version string still separates builds.
    let _ =
        h.write_all(concat!("chiaro-reference-v1 ", env!("CARGO_PKG_VERSION"), "\n").as_bytes());
    let _ = serde_json::to_writer(&mut h, &keyed);
    format!("{:016x}", h.0)
}

/// What the cache stores beside the image.
#[derive(Debug, Serialize, Deserialize)]
struct CacheMeta {
    technique: String,
    spp: u32,
    seconds: f64,
}

/// Reads a cached reference, if one is there and has the right size.
fn read_cache(exr: &Path, meta: &Path, settings: &RenderSettings) -> Option<(Film, f64)> {
    if !exr.is_file() {
        return None;
    }
    let film = read_image_as_film(exr).ok()?;
    if film.width != settings.width || film.height != settings.height {
        return None;
    }
    let seconds = std::fs::read(meta)
        .ok()
        .and_then(|b| serde_json::from_slice::<CacheMeta>(&b).ok())
        .map_or(0.0, |m| m.seconds);
    Some((film, seconds))
}

/// Stores a reference in the cache (creating the directory).
fn write_cache(dir: &Path, exr: &Path, meta: &Path, film: &Film, m: &CacheMeta) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| chiaro_io::IoError::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    write_film(film, exr, &OutputOptions::default())?;
    let json = serde_json::to_vec_pretty(m).unwrap_or_default();
    write_atomically(meta, &json)?;
    Ok(())
}

/// Forwards to another [`Progress`], naming the technique in each stage
/// (`"phong: tiles"`), so a front end shows which render is running.
struct Labelled<'a> {
    inner: &'a dyn Progress,
    label: &'a str,
}

impl Progress for Labelled<'_> {
    fn begin(&self, stage: &str, total: u64) {
        self.inner.begin(&format!("{}: {stage}", self.label), total);
    }
    fn advance(&self, n: u64) {
        self.inner.advance(n);
    }
    fn message(&self, text: &str) {
        self.inner.message(text);
    }
    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
}

/// ꟻLIP between the displayed images of `test` and `reference` (clamped,
/// sRGB 8-bit, as [`metrics::display_channel`] shows them): the mean error
/// in `[0, 1]` and the per-pixel error in the magma colour map, as linear
/// RGB.
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
    if test.width != reference.width || test.height != reference.height {
        return Err(Error::Core(CoreError::Unsupported(format!(
            "cannot compare images of different sizes: {}x{} and {}x{}",
            test.width, test.height, reference.width, reference.height
        ))));
    }
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

/// Measures `film` against `reference`.
fn measure(
    technique: Technique,
    settings: RenderSettings,
    film: Film,
    seconds: f64,
    reference: &Film,
) -> Result<Entry> {
    let (flip_mean, flip_map) = flip(&film, reference)?;
    Ok(Entry {
        technique,
        rmse: metrics::rmse(&film, reference)?,
        psnr: metrics::psnr(&film, reference, 1.0)?,
        mean_relative_error: metrics::mean_relative_error(&film, reference)?,
        relative_mse: metrics::relative_mse(&film, reference)?,
        display_psnr: metrics::display_psnr(&film, reference)?,
        flip: flip_mean,
        flip_map,
        settings,
        film,
        seconds,
    })
}

/// Renders `scene` with each of `techniques` (each with `base` and that
/// technique) and the reference described by `reference`, and measures
/// each against the reference. With a `cache_dir`, the reference is read
/// from `<cache_dir>/<cache_key>.exr` when present and written there
/// otherwise (a failure to write is reported in [`Comparison::cache`], not
/// an error). Renders report to `progress`.
///
/// # Errors
/// [`CoreError::BadSetting`] if `techniques` is empty; any error of
/// [`crate::render_with_stats`] (unknown technique, invalid scene or
/// settings, cancellation).
pub fn compare(
    scene: &Scene,
    base: &RenderSettings,
    techniques: &[Technique],
    reference: &ReferenceSpec,
    cache_dir: Option<&Path>,
    progress: &dyn Progress,
) -> Result<Comparison> {
    if techniques.is_empty() {
        return Err(Error::Core(CoreError::BadSetting {
            key: "techniques".into(),
            message: "no technique to compare".into(),
        }));
    }
    // Check every technique before spending time on the reference.
    for &t in techniques {
        crate::check_settings(&RenderSettings {
            technique: t,
            ..base.clone()
        })?;
    }
    let ref_settings = reference.settings(base);
    crate::check_settings(&ref_settings)?;

    // The reference: from the cache, or rendered (and then cached).
    let paths = cache_dir.map(|dir| {
        let key = cache_key(scene, &ref_settings);
        (
            dir.to_path_buf(),
            dir.join(format!("reference-{key}.exr")),
            dir.join(format!("reference-{key}.json")),
        )
    });
    let cached = paths
        .as_ref()
        .and_then(|(_, exr, meta)| read_cache(exr, meta, &ref_settings));
    let (ref_film, ref_seconds, cache) = match (cached, &paths) {
        (Some((film, secs)), Some((_, exr, _))) => (film, secs, CacheStatus::Hit(exr.clone())),
        _ => {
            let label = format!("reference {}", ref_settings.technique.name());
            let labelled = Labelled {
                inner: progress,
                label: &label,
            };
            let (film, stats) = render_with_stats(scene, &ref_settings, &labelled)?;
            let secs = stats.elapsed.as_secs_f64();
            let cache = match &paths {
                None => CacheStatus::Disabled,
                Some((dir, exr, meta)) => {
                    let m = CacheMeta {
                        technique: ref_settings.technique.name().into(),
                        spp: ref_settings.samples,
                        seconds: secs,
                    };
                    match write_cache(dir, exr, meta, &film, &m) {
                        Ok(()) => CacheStatus::Stored(exr.clone()),
                        Err(e) => CacheStatus::StoreFailed(e.to_string()),
                    }
                }
            };
            (film, secs, cache)
        }
    };
    let reference_entry = measure(
        ref_settings.technique,
        ref_settings,
        ref_film.clone(),
        ref_seconds,
        &ref_film,
    )?;

    // The techniques under test.
    let mut entries = Vec::with_capacity(techniques.len());
    for &t in techniques {
        let settings = RenderSettings {
            technique: t,
            ..base.clone()
        };
        let labelled = Labelled {
            inner: progress,
            label: t.name(),
        };
        let (film, stats) = render_with_stats(scene, &settings, &labelled)?;
        entries.push(measure(
            t,
            settings,
            film,
            stats.elapsed.as_secs_f64(),
            &reference_entry.film,
        )?);
    }
    Ok(Comparison {
        reference: reference_entry,
        entries,
        cache,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_reference_specs() {
        assert_eq!(
            ReferenceSpec::parse("path:64").expect("valid"),
            ReferenceSpec {
                technique: Technique::Path,
                samples: 64
            }
        );
        assert_eq!(ReferenceSpec::parse("32").expect("valid").samples, 32);
        assert_eq!(
            ReferenceSpec::parse("whitted").expect("valid"),
            ReferenceSpec {
                technique: Technique::Whitted,
                samples: DEFAULT_REFERENCE_SPP
            }
        );
        for bad in ["path:0", "path:-3", "path:x", "pth:4", "", "raytrace:4"] {
            let e = ReferenceSpec::parse(bad);
            assert!(
                matches!(e, Err(CoreError::BadSetting { .. })),
                "{bad}: {e:?}"
            );
        }
    }

    #[test]
    fn reference_seed_differs_and_is_stable() {
        assert_ne!(reference_seed(0), 0);
        assert_ne!(reference_seed(1), reference_seed(2));
        assert_eq!(reference_seed(7), reference_seed(7));
        assert!(reference_seed(u64::MAX) < 1 << 53);
    }

    #[test]
    fn cache_key_tracks_scene_and_settings() {
        let scene = Scene::default();
        let s = RenderSettings::default();
        let k = cache_key(&scene, &s);
        assert_eq!(k.len(), 16);
        assert_eq!(k, cache_key(&scene, &s));
        let more = RenderSettings {
            samples: s.samples + 1,
            ..s.clone()
        };
        assert_ne!(k, cache_key(&scene, &more));
        let mut other = scene.clone();
        other.background = chiaro_core::Vec3::splat(0.5);
        assert_ne!(k, cache_key(&other, &s));
    }

    #[test]
    fn labelled_progress_names_the_technique_and_forwards_cancel() {
        use std::sync::Mutex;
        #[derive(Default)]
        struct Record(Mutex<Vec<String>>, std::sync::atomic::AtomicBool);
        impl Progress for Record {
            fn begin(&self, stage: &str, total: u64) {
                if let Ok(mut v) = self.0.lock() {
                    v.push(format!("{stage}/{total}"));
                }
            }
            fn advance(&self, _n: u64) {}
            fn cancelled(&self) -> bool {
                self.1.load(std::sync::atomic::Ordering::Relaxed)
            }
        }
        let rec = Record::default();
        let l = Labelled {
            inner: &rec,
            label: "phong",
        };
        l.begin("tiles", 9);
        assert!(!l.cancelled());
        rec.1.store(true, std::sync::atomic::Ordering::Relaxed);
        assert!(l.cancelled());
        assert_eq!(*rec.0.lock().expect("not poisoned"), ["phong: tiles/9"]);
    }

    #[test]
    fn empty_technique_list_is_an_error() {
        let r = compare(
            &Scene::default(),
            &RenderSettings::default(),
            &[],
            &ReferenceSpec::default(),
            None,
            &chiaro_core::progress::NoProgress,
        );
        assert!(matches!(r, Err(Error::Core(CoreError::BadSetting { .. }))));
    }
}
