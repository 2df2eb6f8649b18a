//! A mutated scene through every technique: the input is a TOML scene
//! (meshes resolve against `scenes/`) or, when it is not one, OBJ text
//! optionally followed by a NUL byte and its MTL text. Each loaded scene
//! is rendered at 8x6 with every technique under a work budget
//! (`chiaro_fuzz::render_every_technique`), so a render that does not end
//! is a libFuzzer timeout, not only a crash.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    if let Ok(text) = std::str::from_utf8(data) {
        let base = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes"));
        if let Ok(loaded) = chiaro_io::load_scene_str(text, base, "fuzz.toml") {
            chiaro_fuzz::render_every_technique(&loaded);
            return;
        }
    }
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], Some(&data[i + 1..])),
        None => (data, None),
    };
    let obj = String::from_utf8_lossy(obj);
    let mtl = mtl.map(String::from_utf8_lossy);
    if let Ok(mut imported) = chiaro_io::obj::load_obj_str(&obj, mtl.as_deref(), "fuzz.obj") {
        chiaro_io::dedupe_faces(&mut imported, Path::new("fuzz.obj"));
        if let Ok(loaded) = chiaro_io::whole_scene(imported, Path::new("fuzz.obj")) {
            chiaro_fuzz::render_every_technique(&loaded);
        }
    }
});
