//! Mitsuba 3 XML scenes: `chiaro_io::mitsuba::load_str`, then preparation.
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
    let options = chiaro_io::LoadOptions {
        defines: vec![("spp".into(), "2".into())],
    };
    if let Ok(loaded) = chiaro_io::mitsuba::load_str(text, base, "fuzz.xml", &options) {
        chiaro_fuzz::prepare(&loaded);
    }
});
