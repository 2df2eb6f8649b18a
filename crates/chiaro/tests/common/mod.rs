//! Helpers shared by the facade's integration tests (`mod common;`).

use chiaro::scene::RenderSettings;
use chiaro::{Film, NoProgress, Scene};
use chiaro_ray::path::Kernel;

/// `scene` rendered with `s` through the facade, or through the path
/// tracer's `kernel` when one is given (the fast kernels and the reference).
pub fn render_cell(scene: &Scene, s: &RenderSettings, kernel: Option<Kernel>) -> Film {
    match kernel {
        None => chiaro::render(scene, s, &NoProgress).expect("renders"),
        Some(k) => {
            let ctx = chiaro::RenderContext::new(scene, s, &NoProgress).expect("valid");
            chiaro::render_with(&ctx, &chiaro_ray::path::PathTracing { kernel: k })
                .expect("renders")
                .0
        }
    }
}
