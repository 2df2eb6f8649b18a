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
            chiaro_ray::path::render_with_kernel(
                scene,
                s,
                &NoProgress,
                &chiaro_core::accel::instanced::build_accelerator,
                k,
            )
            .expect("renders")
            .0
        }
    }
}
