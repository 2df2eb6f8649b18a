//! pbrt-v4 / pbrt-v3 scenes: `chiaro_io::pbrt::load_str`, then preparation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Relative file names resolve against the shipped scenes (their meshes).
    let base = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes"));
    if let Ok(loaded) = chiaro_io::pbrt::load_str(text, base, "fuzz.pbrt") {
        chiaro_fuzz::prepare(&loaded);
    }
});
