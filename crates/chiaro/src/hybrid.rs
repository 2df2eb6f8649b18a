//! The hybrid technique (the lecture notes' "radiosity for diffuse, ray
//! tracing for specular", as Wallace, Cohen and Greenberg's two-pass method,
//! 1987): a radiosity solution supplies the diffuse
//! interreflection, Whitted ray tracing supplies direct light with shadow
//! rays, specular reflection and refraction. Where the ray tracer would add
//! the ambient term `Ia ka kd`, it adds `kd / pi * E_indirect` instead, with
//! `E_indirect` the radiosity solution's incident *indirect* irradiance at
//! the hit point (light reflected at least once), so direct light is not
//! counted twice.

use chiaro_core::Vec3;
use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_radiosity::RadiositySolution;
use chiaro_ray::whitted::Tracer;
use std::f32::consts::PI;

/// The hybrid technique, as the technique interface's [`Renderer`]:
/// radiosity solved first (`settings.radiosity`), then ray traced.
#[derive(Debug, Clone, Copy, Default)]
pub struct Hybrid;

impl Renderer for Hybrid {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats), CoreError> {
        let solution = chiaro_radiosity::solve(ctx)?;
        render_with_solution(ctx, &solution)
    }
}

/// Renders the context's scene with the hybrid technique from an existing
/// radiosity solution (which must belong to the scene).
pub fn render_with_solution(
    ctx: &RenderContext<'_>,
    solution: &RadiositySolution,
) -> Result<(Film, RenderStats), CoreError> {
    solution.check_scene(ctx.scene())?;
    let progress = ctx.progress();
    progress.begin("prepare", 1);
    let tracer = Tracer::new(ctx).with_indirect(move |hit| {
        solution
            .indirect_irradiance_at(hit.object, hit.p, hit.ng)
            .unwrap_or(Vec3::ZERO)
            / PI
    });
    progress.advance(1);
    let (film, stats) = tracer.render(progress)?;
    Ok((film, ctx.stats(stats.rays)))
}
