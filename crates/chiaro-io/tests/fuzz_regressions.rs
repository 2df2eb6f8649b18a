//! Inputs the fuzz targets (`fuzz/`) once crashed on, each loaded through
//! the public loaders and expected to end cleanly (`tests/data/fuzz/README.md`).

use chiaro_testkit::assert_contains_all;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

/// Why loading the crash input `name` is refused (`refused`: what the test
/// expects to be refused).
fn refusal(name: &str, refused: &str) -> String {
    chiaro_io::load_scene(&data(name))
        .expect_err(refused)
        .to_string()
}

#[test]
fn a_colour_with_one_number_in_an_mtl_is_a_grey() {
    // The crash input as it was: its mangled `v` line is a clean parse error
    // naming file, line and column.
    let msg = refusal("short-kd.obj", "a bad vertex");
    assert_contains_all(&msg, &["short-kd.obj:6:21", "expected a finite number"]);
    // Its library under a valid OBJ: `Kd 000000` is the MTL format's grey
    // (one number for all three), `Ks 0 al` is dropped; the materials load.
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-short-kd");
    std::fs::create_dir_all(&d).expect("dir");
    let obj = "mtllib short-kd.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl white\nf 1 2 3\n";
    std::fs::write(d.join("tri.obj"), obj).expect("obj");
    std::fs::copy(data("short-kd.mtl"), d.join("short-kd.mtl")).expect("mtl");
    let loaded = chiaro_io::load_scene(&d.join("tri.obj")).expect("the triangle loads");
    assert_eq!(loaded.scene.triangle_count(), 1);
    assert!(
        loaded.scene.materials.iter().any(|m| m.name == "white"),
        "{:?}",
        loaded.warnings
    );
    let mtl = std::fs::read_to_string(data("short-kd.mtl")).expect("mtl");
    let imported = chiaro_io::obj::load_obj_str(obj, Some(&mtl), "tri.obj").expect("loads");
    assert!(imported.materials.iter().any(|m| m.name == "white"));
    // One number is a grey: the same material as three equal numbers.
    let tri = "mtllib g.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl g\nf 1 2 3\n";
    let one = chiaro_io::obj::load_obj_str(tri, Some("newmtl g\nKd 0.25\n"), "g.obj").expect("one");
    let three = chiaro_io::obj::load_obj_str(tri, Some("newmtl g\nKd 0.25 0.25 0.25\n"), "g.obj")
        .expect("three");
    assert_eq!(one.materials, three.materials);
    assert!(one.warnings.is_empty(), "{:?}", one.warnings);
}

#[test]
fn a_buffer_view_image_without_a_mime_type_is_ignored_with_a_warning() {
    let path = data("image-without-mime-type.glb");
    let loaded = chiaro_io::load_scene(&path).expect("the meshes load");
    assert!(loaded.scene.triangle_count() > 0);
    let w = loaded.warnings.join("\n");
    assert_contains_all(&w, &["needs a mimeType", "texture ignored"]);
}

#[test]
fn a_ply_element_count_larger_than_the_file_is_refused() {
    let msg = refusal("huge-element-count.ply", "a count no file can back");
    assert_contains_all(&msg, &["huge-element-count.ply", "element `vertex` claims"]);
    // A real file is not touched by the check.
    let ok = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
               end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let imported =
        chiaro_io::ply::load_ply_slice(ok, std::path::Path::new("tri.ply")).expect("loads");
    assert_eq!(imported.objects.len(), 1);
}

/// The `ply` target ran out of memory on a binary file whose format line
/// says version 0.0: the element-count check skipped files without a
/// `1.0` format line, and the parser allocated for 5e15 vertices.
#[test]
fn a_huge_element_count_is_refused_whatever_the_format_version() {
    let msg = refusal("odd-version-huge-count.ply", "a count no file can back");
    assert!(msg.contains("claims"), "{msg}");
}
