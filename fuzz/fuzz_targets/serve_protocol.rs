//! The web viewer's text messages: `Request::parse`, and for a render
//! request the job it becomes for a small scene under the default limits.
#![no_main]
use chiaro_serve::protocol::{Limits, Request, make_job};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

/// The shipped Whitted scene (self-contained: spheres, planes, lights).
fn scene() -> &'static chiaro_core::scene::Scene {
    static SCENE: OnceLock<chiaro_core::scene::Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let text = include_str!("../../scenes/whitted.toml");
        chiaro_io::load_scene_str(text, std::path::Path::new("."), "whitted.toml")
            .expect("the shipped Whitted scene loads")
            .scene
    })
}

fuzz_target!(|data: &[u8]| {
    chiaro_fuzz::init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(Request::Render {
        id,
        width,
        height,
        orbit,
        progressive,
        refine,
        views,
    }) = Request::parse(text)
    {
        let _ = make_job(
            scene(),
            &Limits::default(),
            id,
            width,
            height,
            orbit,
            progressive,
            refine,
            &views,
        );
    }
});
