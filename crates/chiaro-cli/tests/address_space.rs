//! The hostile cases under a real limit: `prlimit --as=4000000000` (4 GB
//! of address space, as a small container or a shared machine gives), the
//! default memory budget read from it (`chiaro info --system`), and every
//! case ends with a clear refusal (exit 1, one `error:` line) or a render
//! (exit 0), never an abort (SIGABRT, exit 134) on a failed allocation.
//! Skipped with a message where util-linux's `prlimit` is not installed.

use chiaro_testkit::{SPARSE_GLTF_24_GIB, put};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The address-space limit of these tests, bytes.
const LIMIT: &str = "--as=4000000000";

/// Whether `prlimit` is missing here (it prints its usage with
/// `--version`); says the test is skipped when it is.
fn prlimit_missing() -> bool {
    let have = Command::new("prlimit")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        eprintln!("skipped: prlimit (util-linux) is not installed");
    }
    !have
}

/// `chiaro ARGS` under the address-space limit.
fn chiaro_limited(args: &[&str]) -> Output {
    Command::new("prlimit")
        .arg(LIMIT)
        .arg(env!("CARGO_BIN_EXE_chiaro"))
        .args(args)
        .output()
        .expect("prlimit runs")
}

/// A fresh, empty directory for one test.
fn fresh_dir(name: &str) -> PathBuf {
    chiaro_testkit::fresh_dir(env!("CARGO_TARGET_TMPDIR"), &format!("as-limit-{name}"))
}

/// How a run ended.
#[derive(Debug, PartialEq)]
enum Ending {
    Rendered,
    Refused(String),
}

/// The run's ending, failing the test on anything but exit 0, or exit 1
/// with one `error:` line after any warnings (a signal, 134, a panic, an allocator
/// message).
fn ending(what: &str, o: &Output) -> Ending {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        !err.contains("memory allocation of") && !err.contains("panicked"),
        "{what}: {err}"
    );
    match o.status.code() {
        Some(0) => Ending::Rendered,
        Some(1) => {
            // Warnings about the settings may come first.
            let lines: Vec<&str> = err
                .lines()
                .filter(|l| !l.trim().is_empty() && !l.starts_with("warning: "))
                .collect();
            assert!(
                lines.len() == 1 && lines[0].starts_with("error: "),
                "{what}: not one error line: {err}"
            );
            Ending::Refused(lines[0].to_string())
        }
        other => panic!("{what}: ended with {other:?} (a signal when None): {err}"),
    }
}

/// A TOML scene of `n` spheres of radius 0.4 on a 100-wide grid with unit
/// spacing, seen whole by a camera 60 units away, lit by one point light:
/// at 32x24 each sphere is under a pixel wide.
fn spheres_toml(n: usize) -> String {
    let mut s = String::from(
        "[render]\ntechnique = \"gouraud\"\nwidth = 32\nheight = 24\n\n\
         [camera]\neye = [0, 0, 60]\nlook_at = [0, 0, 0]\nup = [0, 1, 0]\nfov = 60\n\n\
         [[light]]\ntype = \"point\"\nposition = [0, 20, 60]\ncolor = [1, 1, 1]\nintensity = 1\n\n\
         [material.white]\ndiffuse = [0.8, 0.8, 0.8]\n",
    );
    for i in 0..n {
        let (x, y) = ((i % 100) as f32 - 49.5, (i / 100) as f32 - 24.5);
        s.push_str(&format!(
            "\n[[object]]\nprimitive = \"sphere\"\nradius = 0.4\nmaterial = \"white\"\n\
             transform = {{ translate = [{x}, {y}, 0] }}\n"
        ));
    }
    s
}

/// `render SCENE` at 32x24 with `extra` arguments, into `dir`.
fn render(dir: &Path, scene: &Path, extra: &[&str]) -> Output {
    let out = dir.join("out.png").display().to_string();
    let scene = scene.display().to_string();
    let mut args = vec![
        "render", &scene, "-o", &out, "--width", "32", "--height", "24",
    ];
    args.extend_from_slice(extra);
    chiaro_limited(&args)
}

#[test]
fn the_budget_reads_the_address_space_limit() {
    if prlimit_missing() {
        return;
    }
    let o = chiaro_limited(&["info", "--system"]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{o:?}");
    // 4e9 bytes are 3.7 GiB; the budget is half of it.
    for line in [
        "RLIMIT_AS  3.7 GiB",
        "limit      3.7 GiB from RLIMIT_AS",
        "budget     1.9 GiB",
    ] {
        assert!(text.contains(line), "{line:?} not in {text}");
    }
}

#[test]
fn big_scenes_are_refused_or_rendered_within_the_address_space() {
    if prlimit_missing() {
        return;
    }
    let dir = fresh_dir("scenes");
    let plane = put(
        &dir,
        "plane.toml",
        "[[object]]\nprimitive = \"plane\"\nsubdivisions = 4096\n",
    );
    let spheres = put(&dir, "spheres.toml", spheres_toml(5000));
    let cornell = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.toml");
    let refused = |what: &str, o: &Output, expect: &str| match ending(what, o) {
        Ending::Refused(msg) => assert!(msg.contains(expect), "{what}: {msg}"),
        Ending::Rendered => panic!("{what}: rendered, a refusal expected"),
    };
    // 33.5M triangles: refused at load.
    refused(
        "plane",
        &render(&dir, &plane, &["--technique", "gouraud"]),
        "memory limit is 1.9 GiB",
    );
    // Tessellated by size, 5,000 sub-pixel spheres fit the scan converter
    // and stay analytic in the ray tracers; radiosity's 19.8M-triangle
    // tessellation does not fit.
    for t in ["gouraud", "phong", "path"] {
        let o = render(&dir, &spheres, &["--technique", t]);
        assert_eq!(ending(&format!("spheres {t}"), &o), Ending::Rendered);
    }
    refused(
        "spheres radiosity",
        &render(&dir, &spheres, &["--technique", "radiosity"]),
        "19840000 triangles",
    );
    // 64 Mpixel at 64 supersamples, and a dense radiosity matrix.
    refused(
        "supersamples",
        &chiaro_limited(&[
            "render",
            &cornell.display().to_string(),
            "-o",
            &dir.join("big.png").display().to_string(),
            "--width",
            "8192",
            "--height",
            "8192",
            "--samples",
            "64",
        ]),
        "supersamples",
    );
    refused(
        "tiny patches",
        &render(
            &dir,
            &cornell,
            &[
                "--technique",
                "radiosity",
                "--set",
                "radiosity.patch_size=0.002",
            ],
        ),
        "elements",
    );
    let grid = put(
        &dir,
        "grid.toml",
        "[[object]]\nprimitive = \"plane\"\nsubdivisions = 256\n",
    );
    refused(
        "jacobi",
        &render(
            &dir,
            &grid,
            &[
                "--technique",
                "radiosity",
                "--set",
                "radiosity.solver=jacobi",
            ],
        ),
        "radiosity matrix",
    );
    // Shadow maps larger than their share of the budget give way to
    // shadow rays.
    let o = render(
        &dir,
        &cornell,
        &[
            "--technique",
            "phong",
            "--set",
            "shadows=map",
            "--set",
            "shadow_map.resolution=8192",
        ],
    );
    assert_eq!(ending("shadow maps", &o), Ending::Rendered);
}

#[test]
fn hostile_files_are_refused_or_rendered_within_the_address_space() {
    if prlimit_missing() {
        return;
    }
    let dir = fresh_dir("files");
    // A sparse glTF accessor of 2^31 VEC3 elements (24 GiB of zeros).
    let sparse = put(&dir, "sparse.gltf", SPARSE_GLTF_24_GIB);
    match ending("sparse accessor", &render(&dir, &sparse, &[])) {
        Ending::Refused(msg) => assert!(msg.contains("2147483648 elements"), "{msg}"),
        Ending::Rendered => panic!("sparse accessor rendered"),
    }
    // Three primitives of 100M zeros each, and one of 120M: each accessor
    // alone is within the 1.9 GiB budget as bytes, not as a mesh, nor
    // together (both aborted in the loader, copying or deduplicating).
    let text = std::fs::read_to_string(&sparse).expect("read");
    let accessor = text
        .split(r#""accessors": ["#)
        .nth(1)
        .and_then(|rest| rest.split(r#"}}],"#).next())
        .expect("the accessor")
        .to_string()
        + "}}";
    for (name, count, primitives) in [("three", 100_000_000u64, 3), ("one", 120_000_000, 1)] {
        let accessor = accessor.replace("2147483648", &count.to_string());
        let prims: Vec<String> = (0..primitives)
            .map(|i| format!(r#"{{"attributes": {{"POSITION": {i}}}}}"#))
            .collect();
        let accessors = vec![accessor.as_str(); primitives].join(", ");
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(
            &path,
            text.replace(
                r#"[{"primitives": [{"attributes": {"POSITION": 0}}]}]"#,
                &format!(r#"[{{"primitives": [{}]}}]"#, prims.join(", ")),
            )
            .replace(
                &accessor.replace(&count.to_string(), "2147483648"),
                &accessors,
            ),
        )
        .expect("write");
        match ending(name, &render(&dir, &path, &[])) {
            Ending::Refused(msg) => assert!(msg.contains("with the accessors before it"), "{msg}"),
            Ending::Rendered => panic!("{name}: rendered"),
        }
    }
    // An environment whose Radiance header says 30000 x 60000 (7 GiB of
    // RGB f32); the header is all there is.
    std::fs::write(
        dir.join("huge.hdr"),
        "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 30000 +X 60000\n",
    )
    .expect("write");
    let env = put(
        &dir,
        "env.toml",
        "[environment]\ntexture = \"huge.hdr\"\n\n[[object]]\nprimitive = \"sphere\"\n",
    );
    match ending("huge environment", &render(&dir, &env, &[])) {
        Ending::Refused(msg) => assert!(msg.contains("huge.hdr"), "{msg}"),
        Ending::Rendered => panic!("a 30000 x 60000 environment rendered"),
    }
    // The loaders' broken files and fuzz regressions, each as the scene.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../chiaro-io/tests/data");
    let mut tried = 0;
    for sub in ["broken", "fuzz"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(data.join(sub))
            .expect("test data")
            .map(|e| e.expect("entry").path())
            .collect();
        files.sort();
        for f in files {
            let ext = f.extension().and_then(|e| e.to_str()).unwrap_or("");
            if ["toml", "obj", "ply", "gltf", "glb"].contains(&ext) {
                let _ = ending(&f.display().to_string(), &render(&dir, &f, &[]));
                tried += 1;
            }
        }
    }
    assert!(tried > 20, "{tried} files");
}
