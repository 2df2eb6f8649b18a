//! Test support for chiaro: an approximate-equality macro, film comparison
//! with a report of where two films differ, the pixels two films agree are
//! the same surface, sample statistics, and small scenes (built in code, or
//! with the `io` feature loaded from the shipped files) that several
//! crates' tests share.

pub mod bench;
pub mod scenes;
pub mod stats;

use chiaro_core::film::Film;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{RenderSettings, ShadowMethod, Technique};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

/// Asserts `|a - b| <= eps` for floats, with both values in the message.
#[macro_export]
macro_rules! assert_approx_eq {
    ($a:expr, $b:expr, $eps:expr) => {{
        let (a, b, eps) = ($a as f64, $b as f64, $eps as f64);
        assert!(
            (a - b).abs() <= eps,
            "assert_approx_eq failed: {} vs {} (eps {})",
            a,
            b,
            eps
        );
    }};
}

/// How two films differ over a set of pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FilmDiff {
    /// Pixels compared.
    pub compared: usize,
    /// Pixels whose largest channel difference exceeds the tolerance.
    pub over: usize,
    /// Largest channel difference seen.
    pub max_abs: f32,
    /// Mean absolute channel difference.
    pub mean_abs: f32,
}

/// Compares `a` and `b` on the pixels where `mask(index)` is true, counting
/// pixels whose largest absolute channel difference exceeds `tol`.
///
/// # Panics
/// If the films differ in size (a test bug, not user input).
pub fn diff_films(a: &Film, b: &Film, tol: f32, mask: impl Fn(usize) -> bool) -> FilmDiff {
    diff_films_scaled(a, b, tol, mask, |_, _| 1.0)
}

/// [`diff_films`] with `tol` relative to the brighter of the two pixels'
/// largest channel where that exceeds 1: for high-dynamic-range films
/// (reflected lamps), where two renders agree in their leading digits.
pub fn diff_films_relative(a: &Film, b: &Film, tol: f32, mask: impl Fn(usize) -> bool) -> FilmDiff {
    diff_films_scaled(a, b, tol, mask, |x, y| {
        x.max_element().max(y.max_element()).max(1.0)
    })
}

/// [`diff_films`] with `tol` relative to `a`'s brightest channel, or to
/// `floor` where that is darker: for two estimates of the same picture
/// (a reference `a` and a Monte Carlo `b`) compared in relative terms.
pub fn diff_films_relative_to_first(
    a: &Film,
    b: &Film,
    tol: f32,
    floor: f32,
    mask: impl Fn(usize) -> bool,
) -> FilmDiff {
    diff_films_scaled(a, b, tol, mask, |x, _| x.max_element().max(floor))
}

fn diff_films_scaled(
    a: &Film,
    b: &Film,
    tol: f32,
    mask: impl Fn(usize) -> bool,
    scale: impl Fn(glam::Vec3, glam::Vec3) -> f32,
) -> FilmDiff {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "films differ in size"
    );
    let mut d = FilmDiff::default();
    let mut sum = 0.0f64;
    for i in 0..a.color.len() {
        if !mask(i) {
            continue;
        }
        let e = (a.color[i] - b.color[i]).abs().max_element();
        d.compared += 1;
        d.max_abs = d.max_abs.max(e);
        sum += f64::from(e);
        if e > tol * scale(a.color[i], b.color[i]) {
            d.over += 1;
        }
    }
    d.mean_abs = if d.compared > 0 {
        (sum / d.compared as f64) as f32
    } else {
        0.0
    };
    d
}

/// Pixels where films `a` and `b` see a surface at the same depth (within
/// 1e-3 relative, absolute below depth 1) with the same normal (cosine
/// above 0.999), and so do the four neighbours: no silhouettes, so a
/// pixel-by-pixel comparison of two techniques compares shading alone.
pub fn same_surface(a: &Film, b: &Film) -> impl Fn(usize) -> bool + use<> {
    let w = a.width as usize;
    let h = a.height as usize;
    let ok: Vec<bool> = (0..a.color.len())
        .map(|i| {
            let (da, db) = (a.depth[i], b.depth[i]);
            da.is_finite()
                && db.is_finite()
                && (da - db).abs() <= 1e-3 * da.max(1.0)
                && a.normal[i].dot(b.normal[i]) > 0.999
        })
        .collect();
    move |i| {
        let (x, y) = (i % w, i / w);
        ok[i]
            && x > 0
            && y > 0
            && x + 1 < w
            && y + 1 < h
            && ok[i - 1]
            && ok[i + 1]
            && ok[i - w]
            && ok[i + w]
    }
}

/// Pixels of `film` inside its border whose four neighbours' colours
/// differ from theirs by at most `rel` of its brightest channel (at least
/// `floor`) in every channel: away from edges in the picture, where two
/// techniques that place their samples in a pixel differently see
/// different coverage.
pub fn smooth_colour(film: &Film, rel: f32, floor: f32) -> impl Fn(usize) -> bool + '_ {
    let w = film.width as usize;
    let h = film.height as usize;
    move |i| {
        let (x, y) = (i % w, i / w);
        if x == 0 || y == 0 || x + 1 >= w || y + 1 >= h {
            return false;
        }
        let c = film.color[i].max_element().max(floor);
        [i - 1, i + 1, i - w, i + w]
            .iter()
            .all(|&j| (film.color[j] - film.color[i]).abs().max_element() <= rel * c)
    }
}

/// The mean colour of the `2 half` x `2 half` pixels at the centre of
/// `film`.
///
/// # Panics
/// If the film is smaller than that square.
pub fn central_mean(film: &Film, half: usize) -> Vec3 {
    let (w, h) = (film.width as usize, film.height as usize);
    let mut sum = Vec3::ZERO;
    for y in h / 2 - half..h / 2 + half {
        for x in w / 2 - half..w / 2 + half {
            sum += film.color[y * w + x];
        }
    }
    sum / (4 * half * half) as f32
}

/// The pair that must agree on surfaces seen directly: the scan converter
/// (Phong) and Whitted at depth 0, each rendered by `render` from `s`,
/// which is left set for the second.
pub fn phong_and_whitted_at_depth_0(
    s: &mut RenderSettings,
    render: impl Fn(&RenderSettings) -> Film,
) -> (Film, Film) {
    s.technique = Technique::Phong;
    let raster = render(s);
    s.technique = Technique::Whitted;
    s.whitted.max_depth = 0;
    (raster, render(s))
}

/// The pair that must agree on direct light: Whitted at depth 0 and the
/// path tracer at depth 1, both with shadow rays, each rendered by
/// `render` from `s`, which is left set for the second.
pub fn whitted_and_path_direct(
    s: &mut RenderSettings,
    render: impl Fn(&RenderSettings) -> Film,
) -> (Film, Film) {
    s.shadows = ShadowMethod::Ray;
    s.technique = Technique::Whitted;
    s.whitted.max_depth = 0;
    let whitted = render(s);
    s.technique = Technique::Path;
    s.path.max_depth = 1;
    (whitted, render(s))
}

/// A [`Progress`] that keeps the warnings a render or a solve gives, in
/// order, for the tests that check them (stages and counts are ignored).
#[derive(Debug, Default)]
pub struct Warnings(Mutex<Vec<String>>);

impl Warnings {
    /// The warnings given so far.
    pub fn into_vec(self) -> Vec<String> {
        self.0.into_inner().unwrap_or_else(PoisonError::into_inner)
    }

    /// The warnings given so far, one a line.
    pub fn joined(&self) -> String {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .join("\n")
    }
}

impl Progress for Warnings {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn warning(&self, text: &str) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(text.to_string());
    }
}

/// Runs `f` and returns its result with the number of panics raised
/// meanwhile, counted by a panic hook, so that a panic the code under test
/// catches itself (a loader's last-resort guard) still counts. The hook
/// prints each panic as the default one does, and the default hook is
/// back afterwards.
pub fn count_panics<T>(f: impl FnOnce() -> T) -> (T, usize) {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let panics = Arc::new(AtomicUsize::new(0));
    let counter = Arc::clone(&panics);
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        counter.fetch_add(1, Ordering::SeqCst);
        previous(info);
    }));
    let result = f();
    let _ = std::panic::take_hook();
    (result, panics.load(Ordering::SeqCst))
}

/// A fresh, empty directory `root/name` for one test's files (what a
/// previous run left there is removed).
pub fn fresh_dir(root: &str, name: &str) -> PathBuf {
    let dir = Path::new(root).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("test directory");
    dir
}

/// Writes `contents` to `dir/name` and returns the path.
pub fn put(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, contents).expect("write");
    path
}

/// Standard base64 (RFC 4648, with padding) of `bytes`, for data URIs.
pub fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A glTF whose one sparse accessor has 2^31 VEC3 elements (24 GiB of
/// zeros) in a 16-byte buffer: a memory limit must refuse it.
pub const SPARSE_GLTF_24_GIB: &str = r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"componentType": 5126, "count": 2147483648, "type": "VEC3",
          "min": [0, 0, 0], "max": [1, 2, 3],
          "sparse": {"count": 1, "indices": {"bufferView": 0, "componentType": 5125},
            "values": {"bufferView": 1}}}],
        "bufferViews": [{"buffer": 0, "byteLength": 4}, {"buffer": 0, "byteOffset": 4, "byteLength": 12}],
        "buffers": [{"byteLength": 16, "uri": "data:application/octet-stream;base64,AQAAAAAAgD8AAABAAABAQA=="}]}"#;

/// Marsaglia's xorshift64 (shifts 13, 7, 17): tests' fixed-seed streams.
#[derive(Debug, Clone)]
pub struct XorShift64(pub u64);

impl XorShift64 {
    /// The next state (never zero from a nonzero seed).
    pub fn next_u64(&mut self) -> u64 {
        let mut s = self.0;
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        self.0 = s;
        s
    }

    /// Uniform in [0, 1), from the top 24 bits of the next state.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Asserts that `text` (a message) contains every one of `words`.
pub fn assert_contains_all(text: &str, words: &[&str]) {
    for w in words {
        assert!(text.contains(w), "{w:?} not in {text}");
    }
}

/// Where failing tests write images: `target/test-output/<name>.ppm`.
pub fn output_path(name: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/test-output");
    let _ = std::fs::create_dir_all(&root);
    root.join(format!("{name}.ppm"))
}

/// Writes a film as a binary PPM (clamped, sRGB-encoded) for looking at
/// test failures; errors are ignored (it is a diagnostic).
pub fn dump_ppm(film: &Film, name: &str) -> PathBuf {
    let path = output_path(name);
    let mut bytes = format!("P6\n{} {}\n255\n", film.width, film.height).into_bytes();
    bytes.extend(bench::srgb8_pixels(film));
    let _ = std::fs::write(&path, bytes);
    path
}

/// Mean colour of the pixels selected by `mask`.
pub fn masked_mean(film: &Film, mask: impl Fn(usize) -> bool) -> Vec3 {
    let (mut s, mut n) = (Vec3::ZERO, 0usize);
    for (i, c) in film.color.iter().enumerate() {
        if mask(i) {
            s += *c;
            n += 1;
        }
    }
    if n == 0 { Vec3::ZERO } else { s / n as f32 }
}

/// The environment variable that names the shared test-asset folder.
pub const ASSETS_VAR: &str = "CHIARO_ASSETS";

/// The shared test-asset folder (third-party models, textures and scenes
/// read in place, never copied into the repository): `$CHIARO_ASSETS` when
/// set (a relative path is taken from the workspace root). `None`, after
/// printing a skip message that names the variable (and the folder), when
/// it is unset or the folder is absent: the tests that need it then skip.
pub fn shared_assets() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(p) = assets_folder(&root, std::env::var_os(ASSETS_VAR)) else {
        eprintln!("skipped: {ASSETS_VAR} does not name the test-asset folder");
        return None;
    };
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!(
            "skipped: the shared assets folder {} is absent (set {ASSETS_VAR} to it)",
            p.display()
        );
        None
    }
}

/// One file of the shared assets, `relative` to [`shared_assets`], or
/// `None` after a skip message when the folder or the file is absent.
pub fn shared_asset(relative: &str) -> Option<PathBuf> {
    let p = shared_assets()?.join(relative);
    if p.is_file() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent", p.display());
        None
    }
}

/// Where [`shared_assets`] looks, given the workspace root and the
/// variable's value: the value (relative to the root); `None` when unset.
fn assets_folder(root: &Path, var: Option<std::ffi::OsString>) -> Option<PathBuf> {
    var.filter(|v| !v.is_empty()).map(|v| root.join(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_caught_panic_is_counted() {
        let (caught, panics) = count_panics(|| std::panic::catch_unwind(|| panic!("counted")));
        assert!(caught.is_err());
        assert_eq!(panics, 1);
        assert_eq!(count_panics(|| 7), (7, 0));
    }

    #[test]
    fn warnings_are_kept_in_order() {
        let w = Warnings::default();
        w.warning("a");
        w.warning("b");
        assert_eq!(w.joined(), "a\nb");
        assert_eq!(w.into_vec(), ["a", "b"]);
    }

    #[test]
    fn the_assets_folder_is_the_variable_or_none() {
        let root = Path::new("/ws/chiaro");
        assert_eq!(assets_folder(root, None), None);
        assert_eq!(assets_folder(root, Some("".into())), None);
        assert_eq!(
            assets_folder(root, Some("/data/assets".into())).as_deref(),
            Some(Path::new("/data/assets"))
        );
        assert_eq!(
            assets_folder(root, Some("assets".into())).as_deref(),
            Some(Path::new("/ws/chiaro/assets"))
        );
    }
}
