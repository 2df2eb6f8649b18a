//! `compare`: render one scene with several techniques, measure each against
//! a reference, and report the errors and times.
//!
//! The reference is, by default, the path tracer with the same image size
//! and `--set` options as the techniques under test, and seeds derived from
//! theirs ([`reference_seed`]) so that a path-traced entry is not
//! correlated with the reference. It is rendered as [`BATCHES`] independent
//! images (different seeds) whose per-pixel spread estimates the variance
//! of their mean, the reference ([`ReferenceNoise`]). By default
//! (`path:auto`) its sample count is chosen from that estimate: the batches
//! are refined, doubling the samples, until the reference's own estimated
//! relMSE is at most [`DEFAULT_NOISE_FRACTION`] of the smallest relMSE it
//! judges, or [`DEFAULT_REFERENCE_CAP`] samples are reached; `path:256`
//! renders a fixed count (and still estimates its noise). It can be cached
//! as OpenEXR (lossless `f32`) in a cache directory, keyed by a hash of the
//! scene and the reference settings ([`cache_key`]), and reused when its
//! recorded noise meets the target.
//!
//! Metrics ([`crate::metrics`], the same for the web viewer and Python)
//! are computed on **linear**
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
//! use chiaro_tools::compare::{compare, ReferenceSpec};
//! use chiaro::{NoProgress, Technique};
//! let scene = chiaro::io::load_scene("scenes/cornell-box.toml".as_ref()).unwrap().scene;
//! let mut base = scene.render.clone();
//! base.width = 64;
//! base.height = 64;
//! let reference = ReferenceSpec::parse("path:64").unwrap();
//! let c = compare(&scene, &base, &[Technique::Phong, Technique::Whitted], &reference, None, &NoProgress).unwrap();
//! println!("{}", c.to_markdown());
//! ```

use crate::metrics::{self, Metrics};
use chiaro::{Error, Result, render_with_stats};
use chiaro_core::Vec3;
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{RenderSettings, Scene, Technique};
use chiaro_io::output::{OutputOptions, read_image_as_film, write_atomically, write_film};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Samples per pixel of a reference named without a count (`whitted`).
pub const DEFAULT_REFERENCE_SPP: u32 = 256;

/// The most samples per pixel an adaptive reference (`path:auto`) takes.
pub const DEFAULT_REFERENCE_CAP: u32 = 4096;

/// An adaptive reference stops when its estimated relMSE is at most this
/// fraction of the smallest relMSE of the techniques it judges.
pub const DEFAULT_NOISE_FRACTION: f64 = 0.1;

/// Independent images the reference is rendered as; their spread estimates
/// the variance of their mean.
pub const BATCHES: u32 = 8;

/// Samples per pixel of each batch in an adaptive reference's first round.
const FIRST_BATCH_SPP: u32 = 4;

/// The PSNR convention, as written into the report.
pub const PSNR_CONVENTION: &str = "linear radiance before tone mapping, peak 1.0";

/// How many samples the reference takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReferenceSamples {
    /// Exactly this many per pixel.
    Fixed(u32),
    /// Doubling from [`BATCHES`] x 4 until the estimated relMSE is at most
    /// `fraction` of the smallest relMSE judged, or `cap` is reached.
    Auto {
        /// The fraction of the smallest judged relMSE to reach.
        fraction: f64,
        /// The most samples per pixel.
        cap: u32,
    },
}

impl ReferenceSamples {
    /// The largest sample count this can take.
    pub fn max_spp(self) -> u32 {
        match self {
            Self::Fixed(n) => n,
            Self::Auto { cap, .. } => cap,
        }
    }
}

/// Which technique renders the reference, and with how many samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSpec {
    /// The reference technique (normally [`Technique::Path`]).
    pub technique: Technique,
    /// Samples per pixel, fixed or chosen from the reference's variance.
    pub samples: ReferenceSamples,
}

impl Default for ReferenceSpec {
    fn default() -> Self {
        Self {
            technique: Technique::Path,
            samples: ReferenceSamples::Auto {
                fraction: DEFAULT_NOISE_FRACTION,
                cap: DEFAULT_REFERENCE_CAP,
            },
        }
    }
}

impl ReferenceSpec {
    /// A reference of `technique` at exactly `spp` samples per pixel.
    pub fn fixed(technique: Technique, spp: u32) -> Self {
        Self {
            technique,
            samples: ReferenceSamples::Fixed(spp),
        }
    }

    /// Parses `TECHNIQUE:SPP` (`path:256`), `TECHNIQUE:auto` or
    /// `TECHNIQUE:auto:CAP` (samples chosen from the reference's variance,
    /// at most CAP, default [`DEFAULT_REFERENCE_CAP`]), `SPP` (path
    /// tracer) or `TECHNIQUE` (the path tracer: auto; others:
    /// [`DEFAULT_REFERENCE_SPP`]).
    ///
    /// # Errors
    /// [`CoreError::BadSetting`] (key `reference`) for an unknown or
    /// unavailable technique, or a count that is not a positive integer.
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
        let technique = Technique::from_name(name).ok_or_else(|| {
                bad(format!(
                    "unknown technique `{name}` in `{text}` (expected TECHNIQUE:SPP or TECHNIQUE:auto, e.g. path:256; available: {})",
                    chiaro::technique_list()
                ))
            })?;
        let count = |s: &str| match s.trim().parse::<u32>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(bad(format!(
                "samples per pixel `{s}` in `{text}` is not a positive integer"
            ))),
        };
        let auto = |cap| ReferenceSamples::Auto {
            fraction: DEFAULT_NOISE_FRACTION,
            cap,
        };
        let samples = match spp {
            None if technique == Technique::Path => auto(DEFAULT_REFERENCE_CAP),
            None => ReferenceSamples::Fixed(DEFAULT_REFERENCE_SPP),
            Some(s) if s.eq_ignore_ascii_case("auto") => auto(DEFAULT_REFERENCE_CAP),
            Some(s) => match s.split_once(':') {
                Some((a, cap)) if a.trim().eq_ignore_ascii_case("auto") => auto(count(cap)?),
                _ => ReferenceSamples::Fixed(count(s)?),
            },
        };
        Ok(Self { technique, samples })
    }

    /// The settings of the reference's first batch: `base` with this
    /// technique, the largest sample count it may take, and the seed
    /// [`reference_seed`]`(base.seed)`.
    pub fn settings(&self, base: &RenderSettings) -> RenderSettings {
        RenderSettings {
            technique: self.technique,
            samples: self.samples.max_spp(),
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
    /// Its errors against the reference (PSNR: [`PSNR_CONVENTION`]).
    pub metrics: Metrics,
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
    /// The reference's own estimated error and how its sample count was
    /// chosen.
    pub reference_noise: ReferenceNoise,
}

/// The reference's own estimated error: the metrics of the reference
/// against the (unknown) converged image, from the variance of its mean
/// estimated over [`BATCHES`] independent batches, and how its sample
/// count was chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceNoise {
    /// Independent batches the reference was averaged from (1: no
    /// estimate, the fields below are `None`).
    pub batches: u32,
    /// Estimated relMSE of the reference: `mean(var / (r^2 + eps))`.
    pub relative_mse: Option<f64>,
    /// Estimated RMSE of the reference, `sqrt(mean(var))`.
    pub rmse: Option<f64>,
    /// The PSNR of that RMSE (dB, [`PSNR_CONVENTION`]).
    pub psnr: Option<f64>,
    /// Estimated mean relative error, `mean(sigma sqrt(2/pi) / (r + eps))`
    /// (the mean absolute value of a normal error of deviation sigma).
    pub mean_relative_error: Option<f64>,
    /// An adaptive reference's stopping target: [`Self::fraction`] times
    /// the smallest relMSE judged (`None` for a fixed count).
    pub target_relative_mse: Option<f64>,
    /// An adaptive reference's fraction (`None` for a fixed count).
    pub fraction: Option<f64>,
    /// The most samples an adaptive reference could take.
    pub cap: Option<u32>,
}

impl ReferenceNoise {
    /// Whether this noise meets `target` (a fixed reference always does).
    fn meets(&self, target: Option<f64>) -> bool {
        match (target, self.relative_mse) {
            (None, _) => true,
            (Some(t), Some(e)) => e <= t,
            (Some(_), None) => false,
        }
    }
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
    /// Its own estimated error and how its sample count was chosen.
    pub noise: ReferenceNoise,
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
                noise: self.reference_noise.clone(),
            },
            techniques: self
                .entries
                .iter()
                .map(|e| {
                    let m = &e.metrics;
                    TechniqueReport {
                        technique: e.technique.name().into(),
                        rmse: m.rmse,
                        psnr: m.psnr.is_finite().then_some(m.psnr),
                        mean_relative_error: m.mean_relative_error,
                        relative_mse: m.relative_mse,
                        display_psnr: m.display_psnr.is_finite().then_some(m.display_psnr),
                        flip: m.flip,
                        seconds: e.seconds,
                        samples: e.settings.samples,
                    }
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
            let m = &e.metrics;
            s += &format!(
                "| {} | {} | {:.3} | {:.5} | {:.4} | {} | {:.5} | {} | {:.4} |\n",
                e.technique.name(),
                e.settings.samples,
                e.seconds,
                m.relative_mse,
                m.flip,
                format_psnr(m.display_psnr),
                m.rmse,
                format_psnr(m.psnr),
                m.mean_relative_error
            );
        }
        let r = &self.reference;
        let n = &self.reference_noise;
        let est = |v: Option<f64>, digits: usize| {
            v.map_or_else(|| "-".into(), |v| format!("~{v:.digits$}"))
        };
        s += &format!(
            "| {} (reference{}) | {} | {:.3} | {} | - | - | {} | {} | {} |\n",
            r.technique.name(),
            if matches!(self.cache, CacheStatus::Hit(_)) {
                ", cached"
            } else {
                ""
            },
            r.settings.samples,
            r.seconds,
            est(n.relative_mse, 5),
            est(n.rmse, 5),
            n.psnr
                .map_or_else(|| "-".into(), |p| format!("~{}", format_psnr(p))),
            est(n.mean_relative_error, 4),
        );
        s += &format!("\n{}\n", self.reference_sentence());
        s
    }

    /// One sentence on the reference: its samples, how they were chosen,
    /// and its own estimated error.
    pub fn reference_sentence(&self) -> String {
        let r = &self.reference;
        let n = &self.reference_noise;
        let spp = r.settings.samples;
        let chosen = match (n.fraction, n.target_relative_mse, n.cap) {
            (Some(f), Some(t), Some(cap)) => {
                let met = if n.meets(Some(t)) {
                    "met"
                } else {
                    "not met: cap reached"
                };
                format!(
                    "{spp} spp chosen from its own variance (target: estimated relMSE <= {f} x the smallest judged = {t:.3e}, {met}; cap {cap})"
                )
            }
            _ => format!("{spp} spp (fixed)"),
        };
        match n.relative_mse {
            Some(e) => format!(
                "Reference: {} at {chosen}; its own estimated relMSE {e:.3e} from {} independent batches (the `~` row).",
                r.technique.name(),
                n.batches
            ),
            None => format!(
                "Reference: {} at {chosen}; its noise is not estimated (one batch).",
                r.technique.name()
            ),
        }
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
        h.write_all(concat!("chiaro-reference-v2 ", env!("CARGO_PKG_VERSION"), "\n").as_bytes());
    let _ = serde_json::to_writer(&mut h, &keyed);
    format!("{:016x}", h.0)
}

/// What the cache stores beside the image.
#[derive(Debug, Serialize, Deserialize)]
struct CacheMeta {
    technique: String,
    spp: u32,
    seconds: f64,
    noise: ReferenceNoise,
}

/// Reads a cached reference and what was recorded with it, if both are
/// there and the image has the right size.
fn read_cache(exr: &Path, meta: &Path, settings: &RenderSettings) -> Option<(Film, CacheMeta)> {
    if !exr.is_file() {
        return None;
    }
    let film = read_image_as_film(exr).ok()?;
    if film.width != settings.width || film.height != settings.height {
        return None;
    }
    let meta = std::fs::read(meta)
        .ok()
        .and_then(|b| serde_json::from_slice::<CacheMeta>(&b).ok())?;
    Some((film, meta))
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

/// The reference as [`BATCHES`] independent images of equal sample
/// counts (distinct seeds), refined by doubling.
struct Batches {
    films: Vec<Film>,
    /// Samples per pixel of each film.
    spp_each: u32,
    /// Renders done so far (each gets its own seed).
    renders: u64,
    seconds: f64,
}

impl Batches {
    fn new() -> Self {
        Self {
            films: Vec::new(),
            spp_each: 0,
            renders: 0,
            seconds: 0.0,
        }
    }

    /// Samples per pixel of the mean.
    fn spp(&self) -> u32 {
        self.spp_each * self.films.len() as u32
    }

    /// Adds `spp` samples per pixel to each of `count` batches (the first
    /// call makes them), each rendered with a seed of its own derived from
    /// `first.seed`.
    fn refine(
        &mut self,
        scene: &Scene,
        first: &RenderSettings,
        count: u32,
        spp: u32,
        progress: &dyn Progress,
    ) -> Result<()> {
        let label = format!(
            "reference {} ({} spp)",
            first.technique.name(),
            self.spp_each.saturating_add(spp).saturating_mul(count)
        );
        let labelled = Labelled {
            inner: progress,
            label: &label,
        };
        for k in 0..count as usize {
            let settings = RenderSettings {
                samples: spp,
                // Stays below 2^53 (JSON numbers) for any reference seed.
                seed: (first.seed + self.renders) & ((1 << 53) - 1),
                ..first.clone()
            };
            self.renders += 1;
            let (film, stats) = render_with_stats(scene, &settings, &labelled)?;
            self.seconds += stats.elapsed.as_secs_f64();
            match self.films.get_mut(k) {
                None => self.films.push(film),
                Some(old) => {
                    let (a, b) = (self.spp_each as f32, spp as f32);
                    for (o, n) in old.color.iter_mut().zip(&film.color) {
                        *o = (*o * a + *n * b) / (a + b);
                    }
                }
            }
        }
        self.spp_each += spp;
        Ok(())
    }

    /// The mean of the batches (depth and normals of the first).
    fn mean(&self) -> Film {
        let mut mean = self.films[0].clone();
        let k = self.films.len() as f32;
        for (i, m) in mean.color.iter_mut().enumerate() {
            *m = self.films.iter().map(|f| f.color[i]).sum::<Vec3>() / k;
        }
        mean
    }

    /// The estimated error of `mean` from the spread of the batches, with
    /// the metrics' own formulas applied to `mean + sigma` (relMSE, RMSE,
    /// PSNR: the expected values of the squared error) and to
    /// `mean + sigma sqrt(2/pi)` (the mean absolute error of a normal
    /// error).
    fn noise(&self, mean: &Film) -> Result<ReferenceNoise> {
        let k = self.films.len();
        let mut noise = ReferenceNoise {
            batches: k as u32,
            relative_mse: None,
            rmse: None,
            psnr: None,
            mean_relative_error: None,
            target_relative_mse: None,
            fraction: None,
            cap: None,
        };
        if k < 2 {
            return Ok(noise);
        }
        let mut shifted = mean.clone();
        for (i, out) in shifted.color.iter_mut().enumerate() {
            let m = mean.color[i];
            let var = self
                .films
                .iter()
                .map(|f| (f.color[i] - m) * (f.color[i] - m))
                .sum::<Vec3>()
                / (k * (k - 1)) as f32;
            *out = m + Vec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt());
        }
        let mut half_normal = mean.clone();
        let scale = (2.0 / std::f32::consts::PI).sqrt();
        for ((h, s), m) in half_normal
            .color
            .iter_mut()
            .zip(&shifted.color)
            .zip(&mean.color)
        {
            *h = *m + (*s - *m) * scale;
        }
        noise.relative_mse = Some(metrics::relative_mse(&shifted, mean)?);
        noise.rmse = Some(metrics::rmse(&shifted, mean)?);
        noise.psnr = Some(metrics::psnr(&shifted, mean, 1.0)?);
        noise.mean_relative_error = Some(metrics::mean_relative_error(&half_normal, mean)?);
        Ok(noise)
    }
}

/// The stopping target of an adaptive reference: `fraction` of the
/// smallest relMSE of `films` against `reference` (`None` when there is
/// nothing to judge).
fn noise_target(films: &[Film], reference: &Film, fraction: f64) -> Result<Option<f64>> {
    let mut smallest = f64::INFINITY;
    for f in films {
        smallest = smallest.min(metrics::relative_mse(f, reference)?);
    }
    Ok(smallest.is_finite().then_some(fraction * smallest))
}

/// Renders the reference described by `spec` (first batch's settings
/// `first`): a fixed count split over [`BATCHES`] (fewer when it does not
/// divide), or, for `Auto`, rounds that double the samples until the
/// estimated relMSE meets the target measured against `judged` or the cap
/// is reached. Returns the mean, its settings (the samples taken), the
/// seconds and the noise.
fn render_reference(
    scene: &Scene,
    first: &RenderSettings,
    spec: &ReferenceSpec,
    judged: &[Film],
    progress: &dyn Progress,
) -> Result<(Film, RenderSettings, f64, ReferenceNoise)> {
    let mut batches = Batches::new();
    let (film, noise) = match spec.samples {
        ReferenceSamples::Fixed(n) => {
            let count = [BATCHES, 4, 2, 1]
                .into_iter()
                .find(|&k| n % k == 0)
                .unwrap_or(1);
            batches.refine(scene, first, count, n / count, progress)?;
            let mean = batches.mean();
            let noise = batches.noise(&mean)?;
            (mean, noise)
        }
        ReferenceSamples::Auto { fraction, cap } => {
            let count = BATCHES.min(cap);
            let mut spp = FIRST_BATCH_SPP.min(cap / count);
            loop {
                batches.refine(scene, first, count, spp, progress)?;
                let mean = batches.mean();
                let target = noise_target(judged, &mean, fraction)?;
                let mut noise = batches.noise(&mean)?;
                noise.target_relative_mse = target;
                noise.fraction = Some(fraction);
                noise.cap = Some(cap);
                // The next round doubles the samples, within the cap.
                spp = batches.spp_each.min((cap - batches.spp().min(cap)) / count);
                if noise.meets(target) || spp == 0 || progress.cancelled() {
                    break (mean, noise);
                }
            }
        }
    };
    let settings = RenderSettings {
        samples: batches.spp(),
        ..first.clone()
    };
    Ok((film, settings, batches.seconds, noise))
}

/// Measures `film` against `reference`.
fn measure(
    technique: Technique,
    settings: RenderSettings,
    film: Film,
    seconds: f64,
    reference: &Film,
) -> Result<Entry> {
    let (metrics, flip_map) = metrics::measure_with_flip_map(&film, reference)?;
    Ok(Entry {
        technique,
        metrics,
        flip_map,
        settings,
        film,
        seconds,
    })
}

/// Renders `scene` with each of `techniques` (each with `base` and that
/// technique), then the reference described by `reference` (for
/// `path:auto`, refined until its estimated noise is below the target set
/// by those renders; see the module documentation), and measures each
/// against the reference. With a `cache_dir`, the reference is read from
/// `<cache_dir>/reference-<cache_key>.exr` when present and its recorded
/// noise meets the target, and written there otherwise (a failure to write
/// is reported in [`Comparison::cache`], not an error). Renders report to
/// `progress`.
///
/// # Errors
/// [`CoreError::BadSetting`] if `techniques` is empty; any error of
/// [`chiaro::render_with_stats`] (unknown technique, invalid scene or
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
    // Check every technique before spending time on any render.
    for &t in techniques {
        chiaro::check_settings(&RenderSettings {
            technique: t,
            ..base.clone()
        })?;
    }
    let ref_settings = reference.settings(base);
    chiaro::check_settings(&ref_settings)?;

    // The techniques under test: an adaptive reference needs their errors.
    let mut rendered = Vec::with_capacity(techniques.len());
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
        rendered.push((t, settings, film, stats.elapsed.as_secs_f64()));
    }
    let judged: Vec<Film> = rendered.iter().map(|r| r.2.clone()).collect();
    let fraction = match reference.samples {
        ReferenceSamples::Auto { fraction, .. } => Some(fraction),
        ReferenceSamples::Fixed(_) => None,
    };

    // The reference: from the cache when its noise meets the target, or
    // rendered (and then cached).
    let paths = cache_dir.map(|dir| {
        // Adaptive references (samples = their cap) of different fractions
        // are different files.
        let key = match fraction {
            Some(f) => format!("{}-auto{f}", cache_key(scene, &ref_settings)),
            None => cache_key(scene, &ref_settings),
        };
        (
            dir.to_path_buf(),
            dir.join(format!("reference-{key}.exr")),
            dir.join(format!("reference-{key}.json")),
        )
    });
    let cached = paths
        .as_ref()
        .and_then(|(_, exr, meta)| read_cache(exr, meta, &ref_settings))
        .and_then(|(film, meta)| {
            let target = match fraction {
                Some(f) => noise_target(&judged, &film, f).ok()?,
                None => None,
            };
            let mut noise = meta.noise;
            let capped = meta.spp >= ref_settings.samples;
            noise.target_relative_mse = target;
            (noise.meets(target) || capped).then_some((film, meta.spp, meta.seconds, noise))
        });
    let (ref_film, ref_spp, ref_seconds, noise, cache) = match (cached, &paths) {
        (Some((film, spp, secs, noise)), Some((_, exr, _))) => {
            (film, spp, secs, noise, CacheStatus::Hit(exr.clone()))
        }
        _ => {
            let (film, settings, secs, noise) =
                render_reference(scene, &ref_settings, reference, &judged, progress)?;
            let cache = match &paths {
                None => CacheStatus::Disabled,
                Some((dir, exr, meta)) => {
                    let m = CacheMeta {
                        technique: settings.technique.name().into(),
                        spp: settings.samples,
                        seconds: secs,
                        noise: noise.clone(),
                    };
                    match write_cache(dir, exr, meta, &film, &m) {
                        Ok(()) => CacheStatus::Stored(exr.clone()),
                        Err(e) => CacheStatus::StoreFailed(e.to_string()),
                    }
                }
            };
            (film, settings.samples, secs, noise, cache)
        }
    };
    let reference_entry = measure(
        ref_settings.technique,
        RenderSettings {
            samples: ref_spp,
            ..ref_settings
        },
        ref_film.clone(),
        ref_seconds,
        &ref_film,
    )?;
    let mut entries = Vec::with_capacity(rendered.len());
    for (t, settings, film, seconds) in rendered {
        entries.push(measure(t, settings, film, seconds, &reference_entry.film)?);
    }
    Ok(Comparison {
        reference: reference_entry,
        entries,
        cache,
        reference_noise: noise,
    })
}

#[cfg(test)]
mod tests;
