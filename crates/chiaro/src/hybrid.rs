//! The hybrid technique (the seeds' two-pass method, Wallace, Cohen and
//! Greenberg 1987): a radiosity solution supplies the diffuse
//! interreflection, Whitted ray tracing supplies direct light with shadow
//! rays, specular reflection and refraction. Where the ray tracer would add
//! the ambient term `Ia ka kd`, it adds `kd / pi * E_indirect` instead, with
//! `E_indirect` the radiosity solution's incident *indirect* irradiance at
//! the hit point (light reflected at least once), so direct light is not
//! counted twice.

use chiaro_core::Vec3;
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{RenderSettings, Scene};
use chiaro_radiosity::RadiositySolution;
use chiaro_ray::whitted::{RenderStats, Tracer};
use std::f32::consts::PI;

/// Renders `scene` with the hybrid technique, solving radiosity first
/// (`settings.radiosity`). Returns the film and the ray tracer's counts.
pub fn render(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats), CoreError> {
    let solution = chiaro_radiosity::solve(scene, settings, progress)?;
    render_with_solution(scene, solution, settings, progress)
}

/// Renders `scene` with the hybrid technique from an existing radiosity
/// solution (which must belong to `scene`).
pub fn render_with_solution(
    scene: &Scene,
    solution: RadiositySolution,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats), CoreError> {
    solution.check_scene(scene)?;
    progress.begin("prepare", 1);
    let tracer = Tracer::new(scene, settings).with_indirect(move |hit| {
        solution
            .indirect_irradiance_at(hit.object, hit.p, hit.ng)
            .unwrap_or(Vec3::ZERO)
            / PI
    });
    progress.advance(1);
    tracer.render(progress)
}
