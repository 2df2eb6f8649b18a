//! End-to-end tests of the `chiaro` binary: rendering, `info`, `compare`,
//! and the exit codes (0 success, 1 bad input, 2 usage) with one-line
//! error messages.

use chiaro_testkit::put;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn chiaro(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chiaro"))
        .args(args)
        .output()
        .expect("the chiaro binary runs")
}

fn cornell() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/cornell-box.toml")
        .display()
        .to_string()
}

/// A fresh, empty directory for one test.
fn fresh_dir(name: &str) -> PathBuf {
    chiaro_testkit::fresh_dir(env!("CARGO_TARGET_TMPDIR"), &format!("cli-{name}"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Exit code 1 and exactly one line on stderr, starting `error:`.
fn assert_one_line_error(o: &Output, expect: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line expected: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(lines[0].contains(expect), "`{expect}` not in: {err}");
}

#[test]
fn render_writes_a_png_of_the_requested_size() {
    let dir = fresh_dir("render");
    let out = dir.join("cornell.png");
    let o = chiaro(&[
        "render",
        &cornell(),
        "--technique",
        "phong",
        "--width",
        "20",
        "--height",
        "12",
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let film = chiaro::io::output::read_image_as_film(&out).expect("a readable PNG");
    assert_eq!((film.width, film.height), (20, 12));
    assert!(film.mean().element_sum() > 0.0, "not black");
    assert!(stderr(&o).contains("phong 20x12"), "{}", stderr(&o));
}

#[test]
fn info_describes_the_scene() {
    let o = chiaro(&["info", &cornell()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    for key in ["objects", "triangles", "lights", "materials", "camera"] {
        assert!(text.lines().any(|l| l.starts_with(key)), "{key}: {text}");
    }
}

#[test]
fn bad_scenes_exit_1_with_one_line() {
    let dir = fresh_dir("bad-scene");
    let bad = put(&dir, "bad.toml", "[camera]\neye = [0, 0\n");
    let out = dir.join("x.png");
    let out = out.to_str().expect("utf-8 path");
    let o = chiaro(&["render", bad.to_str().expect("utf-8"), "-o", out]);
    assert_one_line_error(&o, "bad.toml:");
    let missing = dir.join("missing.toml");
    let o = chiaro(&["info", missing.to_str().expect("utf-8")]);
    assert_one_line_error(&o, "missing.toml");
    assert!(!Path::new(out).exists());
}

#[test]
fn unknown_setting_and_technique_exit_1_with_one_line() {
    let dir = fresh_dir("unknown");
    let out = dir.join("x.png");
    let out = out.to_str().expect("utf-8 path");
    let scene = cornell();
    let o = chiaro(&["render", &scene, "-o", out, "--set", "whitted.max_dept=3"]);
    assert_one_line_error(&o, "whitted.max_dept");
    let o = chiaro(&["render", &scene, "-o", out, "--technique", "raytrace"]);
    assert_one_line_error(&o, "raytrace");
    let o = chiaro(&["compare", &scene, "-o", out, "--techniques", "phong,gourd"]);
    assert_one_line_error(&o, "gourd");
    let o = chiaro(&[
        "compare",
        &scene,
        "-o",
        out,
        "--techniques",
        "phong",
        "--reference",
        "path:zero",
    ]);
    assert_one_line_error(&o, "path:zero");
    assert!(!Path::new(out).exists());
}

#[test]
fn usage_errors_exit_2() {
    for args in [
        &[][..],
        &["render"][..],
        &["render", "x.toml", "--widht", "3"][..],
        &["frobnicate"][..],
        &["compare", "x.toml"][..],
        &["render", "x.toml", "--width", "wide"][..],
    ] {
        let o = chiaro(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn compare_writes_sheet_and_report_and_reuses_the_reference() {
    let dir = fresh_dir("compare");
    let sheet = dir.join("sheet.png");
    let report = dir.join("report.json");
    let scene = cornell();
    let args = [
        "compare",
        &scene,
        "--techniques",
        "phong,whitted",
        "--reference",
        "path:4",
        "--width",
        "16",
        "--height",
        "16",
        "--samples",
        "1",
        "-o",
        sheet.to_str().expect("utf-8"),
        "--report",
        report.to_str().expect("utf-8"),
    ];
    let o = chiaro(&args);
    assert!(o.status.success(), "{}", stderr(&o));

    // Markdown table on stdout: header, rule, two techniques, the reference.
    let md = stdout(&o);
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with('|')).collect();
    assert_eq!(rows.len(), 5, "{md}");
    assert!(rows[2].starts_with("| phong |") && rows[3].starts_with("| whitted |"));
    assert!(rows[4].starts_with("| path (reference) | 4 |"), "{md}");

    // The report names every technique with finite numbers.
    let text = std::fs::read_to_string(&report).expect("report written");
    let json: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(json["width"], 16);
    assert_eq!(json["reference"]["spp"], 4);
    assert_eq!(json["reference"]["cached"], false);
    let techniques = json["techniques"].as_array().expect("array");
    assert_eq!(techniques.len(), 2);
    for (t, name) in techniques.iter().zip(["phong", "whitted"]) {
        assert_eq!(t["technique"], name);
        for key in ["rmse", "psnr", "mean_relative_error", "seconds"] {
            assert!(
                t[key].as_f64().is_some_and(f64::is_finite),
                "{name}.{key}: {text}"
            );
        }
    }

    // The sheet: three rows of 16x16 images, so taller than 3 * 16.
    let film = chiaro::io::output::read_image_as_film(&sheet).expect("sheet written");
    let (w, h) = chiaro_tools::sheet::sheet_size(16, 16, 3);
    assert_eq!((film.width, film.height), (w, h));

    // The reference was cached next to the sheet, and is reused.
    assert!(dir.join(".chiaro-cache").is_dir());
    let again = chiaro(&args);
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(
        stderr(&again).contains("reusing cached"),
        "{}",
        stderr(&again)
    );
    let text = std::fs::read_to_string(&report).expect("report rewritten");
    assert!(text.contains("\"cached\": true"), "{text}");

    // --no-cache renders it again.
    let mut fresh = args.to_vec();
    fresh.push("--no-cache");
    let o = chiaro(&fresh);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("cached"), "{}", stderr(&o));
}

#[test]
fn memory_limit_and_output_path_are_checked_before_rendering() {
    let dir = fresh_dir("memory");
    let scene = put(
        &dir,
        "plane.toml",
        "[[object]]\nprimitive = \"plane\"\nsubdivisions = 4096\n",
    );
    let scene = scene.display().to_string();
    // `info` too: the plane is refused before it is tessellated.
    let o = chiaro(&["info", &scene, "--memory-limit", "1G"]);
    assert_one_line_error(&o, "memory limit is 1.0 GiB");
    let o = chiaro(&["render", &cornell(), "--memory-limit", "lots"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // An output directory that does not exist fails before the render.
    let out = dir.join("missing/out.png").display().to_string();
    let o = chiaro(&[
        "render",
        &cornell(),
        "--width",
        "16",
        "--height",
        "12",
        "-o",
        &out,
    ]);
    assert_one_line_error(&o, "does not exist");
}

#[test]
fn camera_flags_move_the_camera_and_bad_values_name_the_flag() {
    let dir = fresh_dir("camera-flags");
    let out = dir.join("moved.png");
    let out = out.to_str().expect("utf-8 path");
    let base = [
        "render",
        &cornell(),
        "--technique",
        "preview",
        "--width",
        "16",
        "--height",
        "12",
        "-o",
        out,
    ];
    let run = |extra: &[&str]| chiaro(&[&base[..], extra].concat());
    // A negative coordinate is a value, not a flag.
    let o = run(&[
        "--eye",
        "-0.5,0.5,2",
        "--look-at",
        "0,0.2,-1",
        "--fov",
        "50",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_one_line_error(
        &run(&["--eye", "1,2"]),
        "--eye needs three numbers like 1,2,3, got \"1,2\"",
    );
    assert_one_line_error(
        &run(&["--look-at", "a,b,c"]),
        "--look-at needs three numbers",
    );
    assert_one_line_error(
        &run(&["--fov", "0"]),
        "--fov needs degrees between 0 and 180",
    );
    assert_one_line_error(&run(&["--up", "x"]), "--up needs y or z, got \"x\"");
    assert_one_line_error(
        &run(&["--camera", "top"]),
        "--camera: no camera named \"top\" (the scene has no named cameras)",
    );
}

#[test]
fn numeric_flags_take_negative_numbers_as_values() {
    let dir = fresh_dir("negative");
    let out = dir.join("dark.png");
    let args = |exposure: &str| {
        vec![
            "render".to_string(),
            cornell(),
            "--technique".into(),
            "preview".into(),
            "--width".into(),
            "16".into(),
            "--height".into(),
            "12".into(),
            "--exposure".into(),
            exposure.into(),
            "-o".into(),
            out.display().to_string(),
        ]
    };
    let run = |e: &str| chiaro(&args(e).iter().map(String::as_str).collect::<Vec<_>>());
    let o = run("-1");
    assert!(o.status.success(), "--exposure -1: {}", stderr(&o));
    let dark = std::fs::read(&out).expect("written");
    let o = run("0");
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(
        dark,
        std::fs::read(&out).expect("written"),
        "-1 stop darkens"
    );
    // A negative where only a positive fits is a value error naming the flag.
    let o = chiaro(&["render", &cornell(), "--width", "-16", "-o", "x.png"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("'-16' for '--width"), "{}", stderr(&o));
}

#[test]
fn mitsuba_scenes_take_d_parameters() {
    let dir = fresh_dir("mitsuba");
    let scene = dir.join("ball.xml");
    std::fs::write(
        &scene,
        r#"<scene version="3.0.0">
  <default name="spp" value="8"/>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/><rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="0" y="2" z="3"/><rgb name="intensity" value="5"/></emitter>
  <shape type="sphere"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></shape>
</scene>"#,
    )
    .expect("scene written");
    let scene = scene.to_str().expect("utf-8 path");
    let o = chiaro(&["info", scene, "-D", "spp=3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("samples = 3"), "{}", stdout(&o));
    let out = dir.join("ball.png");
    let o = chiaro(&[
        "render",
        scene,
        "-D",
        "spp=2",
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.is_file());
    // A -D without `=` is refused in one line.
    let o = chiaro(&["info", scene, "-D", "spp"]);
    assert_one_line_error(&o, "name=value");
}
