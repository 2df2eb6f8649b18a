//! OBJ + MTL import: the tinyobjloader edge cases load or fail cleanly
//! (never panic), the McGuire Cornell boxes (negative indices) load as whole
//! scenes with their emissive light, and the MTL mapping holds.

use chiaro_core::scene::Geometry;
use chiaro_io::load_scene;
use std::path::{Path, PathBuf};

fn assets() -> Option<PathBuf> {
    chiaro_testkit::shared_assets()
}

fn objs_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    v.retain(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")));
    v.sort();
    v
}

fn triangles(l: &chiaro_io::Loaded) -> usize {
    l.scene
        .objects
        .iter()
        .map(|o| match o.geometry {
            Geometry::Mesh(m) => l.scene.meshes[m.index()].indices.len(),
            Geometry::Sphere { .. } => 0,
        })
        .sum()
}

#[test]
fn obj_edge_cases_load_or_fail_without_panicking() {
    let Some(root) = assets() else { return };
    let files = objs_in(&root.join("obj-edge-cases/tinyobjloader-models"));
    assert!(files.len() >= 30, "found {}", files.len());
    let (report, panics) = chiaro_testkit::count_panics(|| {
        let mut report = Vec::new();
        for f in &files {
            let name = f
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            match std::panic::catch_unwind(|| load_scene(f)) {
                Ok(Ok(l)) => report.push(format!("{name}: ok, {} triangles", triangles(&l))),
                Ok(Err(e)) => report.push(format!("{name}: error: {e}")),
                Err(_) => report.push(format!("{name}: PANIC")),
            }
        }
        report
    });
    println!("{}", report.join("\n"));
    assert_eq!(panics, 0, "{}", report.join("\n"));
    // Specific expectations.
    let find = |n: &str| {
        report
            .iter()
            .find(|r| r.starts_with(n))
            .cloned()
            .unwrap_or_default()
    };
    assert!(
        find("cube.obj:").contains("ok, 12 triangles"),
        "{}",
        find("cube.obj:")
    );
    assert!(find("missing_material_file.obj:").contains("ok"));
    assert!(
        find("test-nan.obj:").contains("error"),
        "{}",
        find("test-nan.obj:")
    );
    assert!(
        find("line-prim.obj:").contains("nothing to render")
            && find("line-prim.obj:").contains("skipped"),
        "{}",
        find("line-prim.obj:")
    );
    assert!(find("issue-140-zero-face-idx.obj:").contains("error"));
}

#[test]
fn missing_mtl_gives_a_warning_and_default_material() {
    let dir = std::env::temp_dir().join(format!("chiaro-io-obj-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let f = dir.join("tri.obj");
    std::fs::write(
        &f,
        "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\nl 1 2 3\n",
    )
    .expect("write");
    let l = load_scene(&f).expect("loads");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        l.warnings.iter().any(|w| w.contains("material library")),
        "{:?}",
        l.warnings
    );
    assert!(
        l.warnings.iter().any(|w| w.contains("point/line")),
        "{:?}",
        l.warnings
    );
    assert_eq!(triangles(&l), 1, "the polyline adds no face");
    assert_eq!(
        l.scene.materials[l.scene.objects[0].material.index()].name,
        "default"
    );
}

#[test]
fn mcguire_cornell_boxes_load_with_negative_indices() {
    let Some(root) = assets() else { return };
    let files = objs_in(&root.join("mcguire-archive/CornellBox"));
    assert!(files.len() >= 8);
    for f in &files {
        let l = load_scene(f).unwrap_or_else(|e| panic!("{e}"));
        assert!(triangles(&l) >= 10, "{}", f.display());
        // The camera frames the box: its centre is well inside the view.
        let b = chiaro_io::world_bounds(&l.scene);
        let c = l.scene.camera;
        let off = (b.center() - c.eye)
            .angle_between(c.look_at - c.eye)
            .to_degrees();
        assert!(off < 0.25 * c.fov_y_degrees, "{off} degrees off the axis");
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        // The ceiling light is emissive (Ke), except in the variants whose
        // .mtl lacks the "light" material (Glossy, Glossy-Floor): there the
        // loader must say so.
        if name.starts_with("CornellBox-") {
            let emissive = l.scene.materials.iter().any(|m| m.is_emissive());
            let warned = l
                .warnings
                .iter()
                .any(|w| w.contains("light") && w.contains("not defined"));
            assert!(emissive || warned, "{name}: {:?}", l.warnings);
        }
    }
    let original = load_scene(&root.join("mcguire-archive/CornellBox/CornellBox-Original.obj"))
        .expect("loads");
    assert!(
        original
            .scene
            .materials
            .iter()
            .any(|m| m.name == "light" && m.is_emissive())
    );
    // The original box: Kd of the red wall and its ambient relative to it.
    let l = load_scene(&root.join("mcguire-archive/CornellBox/CornellBox-Original.obj"))
        .expect("loads");
    let red = l
        .scene
        .materials
        .iter()
        .find(|m| m.name == "leftWall")
        .expect("leftWall");
    assert!(
        red.diffuse.x > 0.5 && red.diffuse.y < 0.2,
        "{:?}",
        red.diffuse
    );
    // Ka = Kd in this file, so ka (relative to kd) is 1.
    assert!(
        (red.ambient - chiaro_core::Vec3::ONE).length() < 1e-5,
        "{:?}",
        red.ambient
    );
}

#[test]
fn a_file_with_nothing_to_render_is_an_error_naming_what_was_skipped() {
    let dir = std::env::temp_dir().join(format!("chiaro-io-empty-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let f = dir.join("points.obj");
    std::fs::write(&f, "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1 2\nl 1 2 3\n").expect("write");
    let e = load_scene(&f).expect_err("no faces");
    let g = dir.join("verts.obj");
    std::fs::write(&g, "v 0 0 0\nv 1 0 0\n").expect("write");
    let e2 = load_scene(&g).expect_err("no faces");
    let _ = std::fs::remove_dir_all(&dir);
    let msg = e.to_string();
    assert!(
        msg.contains("points.obj") && msg.contains("nothing to render") && msg.contains("skipped"),
        "{msg}"
    );
    assert!(e2.to_string().contains("nothing to render"), "{e2}");
}
