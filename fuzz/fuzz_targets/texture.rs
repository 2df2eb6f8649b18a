//! Image textures (PNG, JPEG, Radiance HDR, OpenEXR: the format is found
//! from the first bytes) through chiaro's texture path and its limits, as
//! a colour texture and as a data texture.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    for srgb in [true, false] {
        if let Ok(t) = chiaro_io::images::load_texture_bytes(data, "fuzz", srgb) {
            assert_eq!(
                t.texel_count() as u64,
                u64::from(t.width) * u64::from(t.height)
            );
        }
    }
});
