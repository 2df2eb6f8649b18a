//! Writing films to PNG / EXR / HDR / PPM / indexed PNG and reading them back.

use chiaro_core::film::Film;
use chiaro_core::film::palette::{BAND_LEVELS, vga_palette};
use chiaro_core::film::tonemap::{srgb_oetf, to_srgb8};
use chiaro_core::glam::Vec3;
use chiaro_core::scene::ToneMap;
use chiaro_io::output::{
    OutputOptions, PaletteMode, SUPPORTED_EXTENSIONS, read_image_as_film, write_film,
};
use chiaro_io::{IoError, images};
use std::path::{Path, PathBuf};

/// A fresh, empty directory for one test (removed by the test at the end).
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("chiaro-output-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create scratch dir");
    d
}

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A 16x8 film: a colour gradient in [0, 1], some depth and normals.
fn gradient_film() -> Film {
    let (w, h) = (16, 8);
    let mut f = Film::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let i = f.index(x, y);
            f.color[i] = Vec3::new(x as f32 / 15.0, y as f32 / 7.0, ((x * y) % 7) as f32 / 6.0);
            f.depth[i] = if x == 0 {
                f32::INFINITY
            } else {
                0.5 + x as f32 + y as f32 * 0.25
            };
            f.normal[i] = Vec3::new(x as f32 - 7.5, 1.0, y as f32 - 3.5).normalize();
        }
    }
    f
}

/// Asserts that `dir` holds exactly the entries `names` (no temporary
/// file left behind), then removes it.
fn assert_holds_only(dir: &Path, names: &[&str]) {
    assert_eq!(entries(dir), names);
    let _ = std::fs::remove_dir_all(dir);
}

/// Writes `film` to `path` (its extension picks the format) with 16 bits
/// a channel or 8, and returns the path.
fn write_at_depth(film: &Film, path: &Path, sixteen: bool) -> PathBuf {
    let opts = OutputOptions {
        bit_depth16: sixteen,
        ..OutputOptions::default()
    };
    write_film(film, path, &opts).expect("writes");
    path.to_path_buf()
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = scratch("exr");
    let mut film = gradient_film();
    film.color[5] = Vec3::new(1234.5, 1e-7, 3.0); // HDR values survive
    let path = dir.join("out.exr");
    write_film(&film, &path, &OutputOptions::default()).expect("write exr");
    let back = read_image_as_film(&path).expect("read exr");
    assert_eq!(back, film);
    assert_holds_only(&dir, &["out.exr"]);
}

#[test]
fn png_round_trips_within_one_code() {
    let dir = scratch("png");
    let film = gradient_film();
    for (name, sixteen, tol) in [
        ("8.png", false, 0.5 / 255.0),
        ("16.png", true, 0.5 / 65535.0),
    ] {
        let path = write_at_depth(&film, &dir.join(name), sixteen);
        let back = read_image_as_film(&path).expect("read png");
        assert_eq!((back.width, back.height), (film.width, film.height));
        for (a, b) in film.color.iter().zip(&back.color) {
            for k in 0..3 {
                let d = (srgb_oetf(a[k]) - srgb_oetf(b[k])).abs();
                assert!(d <= tol + 1e-6, "{name}: {a} vs {b}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn png_applies_exposure_and_tone_map() {
    let dir = scratch("tonemap");
    let mut film = Film::new(1, 1);
    film.color[0] = Vec3::splat(0.5);
    let path = dir.join("t.png");
    let opts = OutputOptions {
        tonemap: ToneMap::Reinhard,
        exposure: 1.0,
        ..OutputOptions::default()
    };
    write_film(&film, &path, &opts).expect("write");
    // 0.5 * 2 = 1 -> Reinhard 0.5 -> sRGB code 188.
    let img = image::open(&path).expect("decode").to_rgb8();
    assert_eq!(img.get_pixel(0, 0).0, [188, 188, 188]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn hdr_and_ppm_round_trip() {
    let dir = scratch("hdr-ppm");
    let mut film = gradient_film();
    film.color[3] = Vec3::new(40.0, 0.25, 7.0);
    let hdr = dir.join("out.hdr");
    write_film(&film, &hdr, &OutputOptions::default()).expect("write hdr");
    let back = read_image_as_film(&hdr).expect("read hdr");
    for (a, b) in film.color.iter().zip(&back.color) {
        // RGBE keeps 8 mantissa bits relative to the largest channel.
        assert!(
            (*a - *b).abs().max_element() <= a.max_element() / 128.0 + 1e-6,
            "{a} vs {b}"
        );
    }
    let clamp = |c: Vec3| c.min(Vec3::ONE);
    for (name, sixteen, tol) in [
        ("8.ppm", false, 0.5 / 255.0),
        ("16.ppm", true, 0.5 / 65535.0),
    ] {
        let path = write_at_depth(&film, &dir.join(name), sixteen);
        let bytes = std::fs::read(&path).expect("read bytes");
        assert!(bytes.starts_with(b"P6\n16 8\n"));
        let back = read_image_as_film(&path).expect("read ppm");
        for (a, b) in film.color.iter().zip(&back.color) {
            let a = clamp(*a);
            for k in 0..3 {
                assert!(
                    (srgb_oetf(a[k]) - srgb_oetf(b[k])).abs() <= tol + 1e-6,
                    "{name}"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn indexed_png_decodes_to_the_palette() {
    let dir = scratch("indexed");
    // Five distinct colours: median cut to 8 is lossless.
    let mut film = Film::new(20, 10);
    let colours = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.5, 0.0),
        Vec3::new(0.2, 0.2, 0.9),
        Vec3::ZERO,
        Vec3::ONE,
    ];
    for (i, c) in film.color.iter_mut().enumerate() {
        *c = colours[(i / 7) % 5];
    }
    let path = dir.join("mc.png");
    let opts = OutputOptions {
        palette: Some(PaletteMode::MedianCut {
            colors: 8,
            dither: false,
        }),
        ..OutputOptions::default()
    };
    write_film(&film, &path, &opts).expect("write indexed");
    // The file really is indexed, with a PLTE of the five colours.
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&path).expect("open"),
    ));
    let reader = decoder.read_info().expect("png header");
    assert_eq!(reader.info().color_type, png::ColorType::Indexed);
    let plte = reader.info().palette.as_ref().expect("PLTE").to_vec();
    assert_eq!(plte.len(), 5 * 3);
    // The image crate expands it to exactly the film's 8-bit colours.
    let img = image::open(&path).expect("decode").to_rgb8();
    let want = to_srgb8(&film, ToneMap::Clamp, 0.0);
    for (p, w) in img.pixels().zip(&want) {
        assert_eq!(&p.0, w);
    }

    // VGA bands: every pixel is one of the 256 band colours.
    let bands = vec![Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.5, 0.0)];
    let path = dir.join("vga.png");
    let opts = OutputOptions {
        palette: Some(PaletteMode::Vga {
            band_colors: bands.clone(),
        }),
        ..OutputOptions::default()
    };
    write_film(&gradient_film(), &path, &opts).expect("write vga");
    let palette = vga_palette(&bands);
    assert_eq!(palette.len(), 4 * BAND_LEVELS);
    let img = image::open(&path).expect("decode").to_rgb8();
    assert!(img.pixels().all(|p| palette.contains(&p.0)));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unknown_extension_is_refused_with_the_list() {
    let dir = scratch("ext");
    for name in ["out.jpg", "out"] {
        let path = dir.join(name);
        let e =
            write_film(&gradient_film(), &path, &OutputOptions::default()).expect_err("refused");
        assert!(matches!(e, IoError::Format { .. }));
        let msg = e.to_string();
        assert!(msg.contains(name), "{msg}");
        for ext in SUPPORTED_EXTENSIONS {
            assert!(msg.contains(&format!(".{ext}")), "{msg}");
        }
    }
    // A palette with a non-PNG file.
    let opts = OutputOptions {
        palette: Some(PaletteMode::MedianCut {
            colors: 4,
            dither: true,
        }),
        ..OutputOptions::default()
    };
    assert!(write_film(&gradient_film(), &dir.join("x.exr"), &opts).is_err());
    assert_holds_only(&dir, &[]);
}

#[test]
fn missing_directory_errors_and_leaves_nothing() {
    let dir = scratch("missing");
    let path = dir.join("no/such/dir/out.png");
    let e = write_film(&gradient_film(), &path, &OutputOptions::default()).expect_err("no dir");
    assert!(matches!(e, IoError::Io { .. }));
    assert!(e.to_string().contains("no/such/dir/out.png"), "{e}");
    assert_holds_only(&dir, &[]);
}

#[test]
fn overwriting_replaces_the_file_and_leaves_no_temporary() {
    let dir = scratch("overwrite");
    let path = dir.join("o.png");
    std::fs::write(&path, b"old").expect("seed");
    write_film(&gradient_film(), &path, &OutputOptions::default()).expect("write");
    assert!(std::fs::read(&path).expect("read").starts_with(b"\x89PNG"));
    assert_holds_only(&dir, &["o.png"]);
}

#[test]
fn nan_never_reaches_a_file() {
    let dir = scratch("nan");
    let mut film = Film::new(4, 1);
    film.color = vec![
        Vec3::new(f32::NAN, 0.5, 0.5),
        Vec3::new(f32::INFINITY, f32::NEG_INFINITY, -3.0),
        Vec3::splat(0.25),
        Vec3::new(0.1, f32::NAN, 2.0),
    ];
    film.depth[1] = f32::NAN;
    film.normal[2] = Vec3::splat(f32::NAN);
    for ext in SUPPORTED_EXTENSIONS {
        let path = dir.join(format!("n.{ext}"));
        write_film(&film, &path, &OutputOptions::default()).expect("write");
        let back = read_image_as_film(&path).expect("read");
        assert!(back.is_clean(), "{ext}");
        assert!(back.normal.iter().all(|n| n.is_finite()), "{ext}");
        assert!(back.depth.iter().all(|d| !d.is_nan()), "{ext}");
        assert_eq!(back.color[0].x, 0.0, "{ext}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reading_garbage_names_the_file() {
    let dir = scratch("garbage");
    let path = dir.join("junk.png");
    std::fs::write(&path, b"not a png at all").expect("write");
    let e = read_image_as_film(&path).expect_err("garbage");
    assert!(e.to_string().contains("junk.png"));
    let e = images::load_texture(&path, true).expect_err("garbage");
    assert!(e.to_string().contains("junk.png"));
    let ppm = dir.join("short.ppm");
    std::fs::write(&ppm, b"P6\n4 4\n255\nabc").expect("write");
    let e = read_image_as_film(&ppm).expect_err("truncated");
    assert!(e.to_string().contains("short.ppm") && e.to_string().contains("truncated"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_paths_are_checked_before_rendering() {
    use chiaro_io::output::check_output_path;
    let dir = scratch("check");
    assert!(check_output_path(&dir.join("ok.png")).is_ok());
    assert!(check_output_path(&dir.join("ok.EXR")).is_ok());
    let e = check_output_path(&dir.join("missing/out.png")).expect_err("no directory");
    assert!(e.to_string().contains("does not exist"), "{e}");
    let e = check_output_path(&dir.join("out.jpg")).expect_err("format");
    assert!(e.to_string().contains(".png"), "{e}");
    let sub = dir.join("sub.png");
    std::fs::create_dir_all(&sub).expect("dir");
    let e = check_output_path(&sub).expect_err("a directory");
    assert!(e.to_string().contains("directory"), "{e}");
    // A read-only directory (root may still write there: then it passes).
    let ro = dir.join("ro");
    std::fs::create_dir_all(&ro).expect("dir");
    let mut perms = std::fs::metadata(&ro).expect("meta").permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(&ro, perms).expect("chmod");
    let writable = std::fs::File::create(ro.join("x")).is_ok();
    let r = check_output_path(&ro.join("out.png"));
    assert_eq!(r.is_ok(), writable, "{r:?}");
    let mut perms = std::fs::metadata(&ro).expect("meta").permissions();
    #[allow(clippy::permissions_set_readonly_false)]
    perms.set_readonly(false);
    std::fs::set_permissions(&ro, perms).expect("chmod");
    // The probe leaves nothing behind.
    assert_holds_only(&dir, &["ro", "sub.png"]);
}
