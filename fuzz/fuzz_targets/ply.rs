//! Stanford PLY (ASCII and binary), then preparation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let name = Path::new("fuzz.ply");
    if let Ok(imported) = chiaro_io::ply::load_ply_slice(data, name) {
        if let Ok(loaded) = chiaro_io::whole_scene(imported, name) {
            chiaro_fuzz::prepare(&loaded);
        }
    }
});
