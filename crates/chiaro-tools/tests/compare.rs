//! `chiaro_tools::compare` and the contact sheet on a tiny scene: every technique
//! is measured with finite numbers, the path tracer against itself differs
//! only by noise, the sheet has the documented size, and the reference
//! cache is hit on the second run.

use chiaro::scene::Technique;
use chiaro::{NoProgress, RenderSettings, Scene};
use chiaro_testkit::scenes;
use chiaro_tools::compare::{
    CacheStatus, Comparison, ReferenceSamples, ReferenceSpec, compare, reference_seed,
};
use chiaro_tools::sheet::{contact_sheet, sheet_size, write_sheet};
use std::path::{Path, PathBuf};

const SIZE: u32 = 24;

fn setup() -> (Scene, RenderSettings) {
    let scene = scenes::shadow_test(SIZE);
    let mut s = scene.render.clone();
    s.width = SIZE;
    s.height = SIZE;
    s.samples = 4;
    s.seed = 11;
    (scene, s)
}

fn path16() -> ReferenceSpec {
    ReferenceSpec::fixed(Technique::Path, 16)
}

/// `techniques` on `scene` with `base`, against the path tracer at 16 spp,
/// the reference cached in `cache` when given.
fn against_path16(
    scene: &Scene,
    base: &RenderSettings,
    techniques: &[Technique],
    cache: Option<&Path>,
) -> Comparison {
    compare(scene, base, techniques, &path16(), cache, &NoProgress).expect("compares")
}

/// The shipped Cornell box at `size` x `size` pixels, 4 samples a pixel.
fn cornell_box(size: u32) -> (Scene, RenderSettings) {
    let scene = scenes::cornell_box(size);
    let mut base = scene.render.clone();
    base.samples = 4;
    (scene, base)
}

/// A fresh, empty directory under the test output directory.
fn fresh_dir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("test output directory");
    dir
}

#[test]
fn phong_and_whitted_against_path_report_finite_metrics() {
    let (scene, base) = setup();
    let c = against_path16(&scene, &base, &[Technique::Phong, Technique::Whitted], None);
    assert_eq!(c.cache, CacheStatus::Disabled);
    assert_eq!(c.reference.technique, Technique::Path);
    assert_eq!(c.reference.settings.samples, 16);
    assert_eq!(c.reference.settings.seed, reference_seed(base.seed));
    assert_eq!(c.reference.metrics.rmse, 0.0);
    assert!(c.reference.metrics.psnr.is_infinite());
    let names: Vec<_> = c.entries.iter().map(|e| e.technique).collect();
    assert_eq!(names, [Technique::Phong, Technique::Whitted]);
    for e in &c.entries {
        assert_eq!(e.settings.samples, base.samples);
        assert_eq!((e.film.width, e.film.height), (SIZE, SIZE));
        for v in [
            e.metrics.rmse,
            e.metrics.psnr,
            e.metrics.mean_relative_error,
            e.seconds,
        ] {
            assert!(v.is_finite() && v >= 0.0, "{:?}: {v}", e.technique);
        }
        assert!(
            e.metrics.rmse > 0.0,
            "{:?} cannot equal the path tracer",
            e.technique
        );
    }

    // The JSON report has every field the issue names, for every technique.
    let json: serde_json::Value =
        serde_json::from_str(&c.to_json("shadow_test")).expect("valid JSON");
    assert_eq!(json["scene"], "shadow_test");
    assert_eq!(json["width"], SIZE);
    assert_eq!(json["reference"]["technique"], "path");
    assert_eq!(json["reference"]["spp"], 16);
    let rows = json["techniques"].as_array().expect("techniques array");
    assert_eq!(rows.len(), 2);
    for (row, name) in rows.iter().zip(["phong", "whitted"]) {
        assert_eq!(row["technique"], name);
        for key in ["rmse", "psnr", "mean_relative_error", "seconds"] {
            let v = row[key].as_f64().unwrap_or(f64::NAN);
            assert!(v.is_finite(), "{name}.{key} = {}", row[key]);
        }
    }

    // The Markdown table has a header, a rule, and one line per image.
    let md = c.to_markdown();
    assert_eq!(md.lines().take_while(|l| l.starts_with('|')).count(), 2 + 3);
    assert!(md.contains("Reference: path at 16 spp (fixed)"), "{md}");
    assert!(
        md.lines()
            .nth(2)
            .is_some_and(|l| l.starts_with("| phong |"))
    );
    assert!(md.contains("| path (reference) | 16 |"));
}

#[test]
fn path_against_itself_at_another_seed_differs_only_by_noise() {
    let (scene, mut base) = setup();
    base.samples = 16;
    let c = against_path16(&scene, &base, &[Technique::Path, Technique::Phong], None);
    let (path, phong) = (&c.entries[0], &c.entries[1]);
    // A different seed: not the same image ...
    assert_ne!(path.settings.seed, c.reference.settings.seed);
    assert!(path.metrics.rmse > 0.0);
    // ... but the same estimate: a small error, and smaller than that of a
    // different technique (Phong's ambient term instead of indirect light).
    assert!(
        path.metrics.rmse < phong.metrics.rmse,
        "path {} phong {}",
        path.metrics.rmse,
        phong.metrics.rmse
    );
    let mean = f64::from(c.reference.film.mean().element_sum() / 3.0);
    assert!(
        path.metrics.rmse < 0.5 * mean.max(1e-3),
        "path rmse {} vs mean {mean}",
        path.metrics.rmse
    );
    assert!(path.metrics.psnr > 20.0, "path psnr {}", path.metrics.psnr);
}

#[test]
fn reference_is_cached_and_reused() {
    let (scene, base) = setup();
    let dir = fresh_dir("compare-cache");
    let run = || against_path16(&scene, &base, &[Technique::Phong], Some(&dir));
    let first = run();
    let CacheStatus::Stored(file) = &first.cache else {
        panic!("first run should store the reference: {:?}", first.cache);
    };
    assert!(file.is_file());
    assert_eq!(file.extension().and_then(|e| e.to_str()), Some("exr"));
    let second = run();
    assert_eq!(second.cache, CacheStatus::Hit(file.clone()));
    // The cached reference is bit-identical (EXR f32), so are the metrics,
    // and the report keeps the original render time.
    assert_eq!(second.reference.film.color, first.reference.film.color);
    assert_eq!(
        second.entries[0].metrics.rmse,
        first.entries[0].metrics.rmse
    );
    assert_eq!(second.reference.seconds, first.reference.seconds);
    assert!(second.report("s").reference.cached);

    // A damaged cache file is rendered again and replaced.
    std::fs::write(file, b"not an EXR").expect("damages the cache");
    let repaired = run();
    assert_eq!(repaired.cache, CacheStatus::Stored(file.clone()));
    assert_eq!(run().cache, CacheStatus::Hit(file.clone()));

    // Other reference settings miss the cache.
    let mut other = base.clone();
    other.seed += 1;
    let third = against_path16(&scene, &other, &[Technique::Phong], Some(&dir));
    assert!(matches!(third.cache, CacheStatus::Stored(ref f) if f != file));
}

#[test]
fn sheet_has_the_documented_size_and_is_written() {
    let (scene, base) = setup();
    let c = against_path16(&scene, &base, &[Technique::Phong, Technique::Whitted], None);
    let sheet = contact_sheet(&c, "shadow_test").expect("sheet");
    let (w, h) = sheet_size(SIZE, SIZE, 3);
    assert_eq!((sheet.film.width, sheet.film.height), (w, h));
    assert!(w > 2 * SIZE && h > 3 * SIZE);
    assert!(sheet.film.is_clean());
    assert!(sheet.error_scale.is_finite() && sheet.error_scale > 0.0);

    let dir = fresh_dir("compare-sheet");
    let path = dir.join("sheet.png");
    write_sheet(&c, "shadow_test", &path).expect("writes");
    let back = chiaro::io::output::read_image_as_film(&path).expect("reads back");
    assert_eq!((back.width, back.height), (w, h));
}

#[test]
fn bad_settings_fail() {
    let (scene, base) = setup();
    let run = |base: &RenderSettings, techniques: &[Technique]| {
        compare(&scene, base, techniques, &path16(), None, &NoProgress)
    };
    let zero = RenderSettings {
        width: 0,
        ..base.clone()
    };
    let msg = run(&zero, &[Technique::Phong])
        .expect_err("zero width")
        .to_string();
    assert!(msg.contains("render.width"), "{msg}");
}

/// The share of a per-pixel error sum that falls on `mask`ed pixels.
fn share(errors: &[f64], mask: &[bool]) -> f64 {
    let total: f64 = errors.iter().sum();
    let masked: f64 = errors
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|(e, _)| e)
        .sum();
    if total > 0.0 { masked / total } else { 0.0 }
}

#[test]
fn metrics_rank_radiosity_first_on_the_cornell_box_without_the_emitter_dominating() {
    let (scene, base) = cornell_box(48);
    let reference = ReferenceSpec::fixed(Technique::Path, 256);
    let c = compare(
        &scene,
        &base,
        &[Technique::Phong, Technique::Radiosity],
        &reference,
        None,
        &NoProgress,
    )
    .expect("compares");
    let (phong, radiosity) = (&c.entries[0], &c.entries[1]);
    // Radiosity is visibly the closest; the measures meant for ranking say so.
    assert!(
        radiosity.metrics.relative_mse < 0.5 * phong.metrics.relative_mse,
        "{} {}",
        radiosity.metrics.relative_mse,
        phong.metrics.relative_mse
    );
    assert!(
        radiosity.metrics.flip < 0.5 * phong.metrics.flip,
        "{} {}",
        radiosity.metrics.flip,
        phong.metrics.flip
    );
    assert!(radiosity.metrics.display_psnr > phong.metrics.display_psnr + 3.0);
    // The emitter: pixels where the reference is brighter than white.
    let r = &c.reference.film;
    let mask: Vec<bool> = r.color.iter().map(|c| c.max_element() > 1.0).collect();
    let emitter = mask.iter().filter(|&&m| m).count();
    assert!(emitter > 0 && emitter < mask.len() / 10, "{emitter}");
    let per_pixel = |f: &dyn Fn(f32, f32) -> f64, film: &chiaro::Film| -> Vec<f64> {
        film.color
            .iter()
            .zip(&r.color)
            .map(|(a, b)| (0..3).map(|k| f(a[k], b[k])).sum())
            .collect()
    };
    let sq = |a: f32, b: f32| f64::from(a - b).powi(2);
    let rel = |a: f32, b: f32| f64::from(a - b).powi(2) / (f64::from(b).powi(2) + 0.01);
    let disp = |a: f32, b: f32| {
        use chiaro_tools::metrics::display_channel;
        f64::from(display_channel(a) - display_channel(b)).powi(2)
    };
    for e in [phong, radiosity] {
        let flip: Vec<f64> = chiaro_tools::metrics::flip_errors(&e.film, r)
            .expect("flip")
            .into_iter()
            .map(f64::from)
            .collect();
        let shares = [
            share(&per_pixel(&sq, &e.film), &mask),
            share(&per_pixel(&rel, &e.film), &mask),
            share(&per_pixel(&disp, &e.film), &mask),
            share(&flip, &mask),
        ];
        println!(
            "{}: emitter pixels {emitter}/{}; share of MSE {:.3}, relMSE {:.3}, display MSE {:.3}, FLIP {:.3}",
            e.technique.name(),
            mask.len(),
            shares[0],
            shares[1],
            shares[2],
            shares[3]
        );
        // Linear MSE is the emitter's (under 1 % of the pixels); relative
        // MSE and FLIP are not.
        assert!(shares[0] > 0.5, "{shares:?}");
        assert!(shares[1] < 0.3 && shares[3] < 0.1, "{shares:?}");
    }
}

#[test]
fn the_reference_takes_samples_until_its_own_noise_is_below_the_target() {
    let (scene, base) = cornell_box(24);
    let cap = 1 << 14;
    let run = |samples| {
        let spec = ReferenceSpec {
            technique: Technique::Path,
            samples,
        };
        compare(&scene, &base, &[Technique::Phong], &spec, None, &NoProgress).expect("compares")
    };
    let mut chosen = Vec::new();
    let mut finest = None;
    for fraction in [0.1, 0.02] {
        let c = run(ReferenceSamples::Auto { fraction, cap });
        let n = &c.reference_noise;
        let estimate = n.relative_mse.expect("estimated");
        let judged = c.entries[0].metrics.relative_mse;
        assert!(
            estimate <= fraction * judged,
            "reference relMSE {estimate} above {fraction} x {judged}"
        );
        assert_eq!(n.target_relative_mse, Some(fraction * judged));
        let spp = c.reference.settings.samples;
        assert!(spp < cap, "stopped by the cap, not the target");
        assert!(
            c.reference_sentence()
                .contains("chosen from its own variance"),
            "{}",
            c.reference_sentence()
        );
        chosen.push(spp);
        finest = Some((c.reference, estimate));
    }
    assert!(chosen[1] > chosen[0], "spp {chosen:?} for a falling target");

    // The estimate is honest: a fixed 64-spp reference's measured relMSE
    // against the finest one is the sum of their estimated noises (both
    // unbiased, independent), within the spread of an 8-batch estimate.
    let (finest, finest_estimate) = finest.expect("rendered");
    let coarse = run(ReferenceSamples::Fixed(64));
    let measured =
        chiaro_tools::metrics::relative_mse(&coarse.reference.film, &finest.film).expect("sizes");
    let predicted = coarse.reference_noise.relative_mse.expect("estimated") + finest_estimate;
    assert!(
        measured > 0.5 * predicted && measured < 2.0 * predicted,
        "measured relMSE {measured}, estimated {predicted}"
    );
}
