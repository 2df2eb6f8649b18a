//! glTF JSON or GLB bytes (embedded data only), then preparation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let name = Path::new("fuzz.glb");
    if let Ok(imported) = chiaro_io::gltf_import::load_gltf_slice(data, None, name) {
        if let Ok(loaded) = chiaro_io::whole_scene(imported, name) {
            chiaro_fuzz::prepare(&loaded);
        }
    }
});
