//! The TOML scene format: `chiaro_io::load_scene_str`, then preparation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Relative paths resolve against the shipped scenes (their meshes).
    let base = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes"));
    if let Ok(loaded) = chiaro_io::load_scene_str(text, base, "fuzz.toml") {
        chiaro_fuzz::prepare(&loaded);
    }
});
