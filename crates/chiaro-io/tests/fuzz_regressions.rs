//! Inputs the fuzz targets (`fuzz/`) once crashed on, each loaded through
//! the public loaders and expected to end cleanly (`tests/data/fuzz/README.md`).

use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

#[test]
fn a_colour_with_one_number_in_an_mtl_is_a_warning() {
    // The crash input as it was: its mangled `v` line is a clean parse error
    // after the library (read first) no longer panics.
    let path = data("short-kd.obj");
    let msg = chiaro_io::load_scene(&path)
        .expect_err("a bad vertex")
        .to_string();
    assert!(
        msg.contains("short-kd.obj") && msg.contains("position parse error"),
        "{msg}"
    );
    // Its library under a valid OBJ: the geometry loads with the default
    // material and a warning, from a file and from memory.
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-short-kd");
    std::fs::create_dir_all(&d).expect("dir");
    let obj = "mtllib short-kd.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl white\nf 1 2 3\n";
    std::fs::write(d.join("tri.obj"), obj).expect("obj");
    std::fs::copy(data("short-kd.mtl"), d.join("short-kd.mtl")).expect("mtl");
    let loaded = chiaro_io::load_scene(&d.join("tri.obj")).expect("the triangle loads");
    assert_eq!(loaded.scene.triangle_count(), 1);
    let w = loaded.warnings.join("\n");
    assert!(w.contains("material library could not be read"), "{w}");
    let mtl = std::fs::read_to_string(data("short-kd.mtl")).expect("mtl");
    let imported = chiaro_io::obj::load_obj_str(obj, Some(&mtl), "tri.obj").expect("loads");
    assert!(
        imported
            .warnings
            .join("\n")
            .contains("material library could not be read"),
        "{:?}",
        imported.warnings
    );
}

#[test]
fn a_buffer_view_image_without_a_mime_type_is_ignored_with_a_warning() {
    let path = data("image-without-mime-type.glb");
    let loaded = chiaro_io::load_scene(&path).expect("the meshes load");
    assert!(loaded.scene.triangle_count() > 0);
    let w = loaded.warnings.join("\n");
    assert!(
        w.contains("needs a mimeType") && w.contains("texture ignored"),
        "{w}"
    );
}
