//! OBJ with its MTL: the input is the OBJ text, optionally followed by a NUL
//! byte and the text of the material library every `mtllib` reads.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], Some(&data[i + 1..])),
        None => (data, None),
    };
    let obj = String::from_utf8_lossy(obj);
    let mtl = mtl.map(String::from_utf8_lossy);
    if let Ok(imported) = chiaro_io::obj::load_obj_str(&obj, mtl.as_deref(), "fuzz.obj") {
        if let Ok(loaded) = chiaro_io::whole_scene(imported, Path::new("fuzz.obj")) {
            chiaro_fuzz::prepare(&loaded);
        }
    }
});
