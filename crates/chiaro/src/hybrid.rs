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
use chiaro_core::budget::Estimate;
use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_core::scene::{RenderSettings, Scene, Technique};
use chiaro_core::technique::{
    COAT_REFLECTS_ENVIRONMENT, Description, ENVIRONMENT_UNOCCLUDED, Feature, ROUGH_AS_SMOOTH,
};
use chiaro_ray::whitted::Tracer;
use std::f32::consts::PI;

/// The hybrid technique, as the technique interface's [`Renderer`]: the
/// context's radiosity solution (solved first with `settings.radiosity`,
/// or the one it was given), then ray traced.
#[derive(Debug, Clone, Copy, Default)]
pub struct Hybrid;

impl Renderer for Hybrid {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats), CoreError> {
        let solution = chiaro_radiosity::solution(ctx)?;
        let progress = ctx.progress();
        progress.begin("prepare", 1);
        let tracer = Tracer::new(ctx).with_indirect(move |hit| {
            solution
                .indirect_irradiance_at(hit.object, hit.p, hit.ng)
                .unwrap_or(Vec3::ZERO)
                / PI
        });
        progress.advance(1);
        tracer.render(ctx)
    }

    fn descriptions(&self) -> &'static [Description] {
        std::slice::from_ref(&DESCRIPTION)
    }

    fn memory(&self, scene: &Scene, settings: &RenderSettings, estimate: &mut Estimate) {
        chiaro_radiosity::solver_memory(scene, settings, estimate);
    }
}

/// The hybrid technique, described.
pub const DESCRIPTION: Description = Description {
    technique: Technique::Hybrid,
    title: "hybrid",
    method: "radiosity for diffuse interreflection + Whitted ray tracing for direct light, reflection and refraction",
    shows: "Whitted's direct light, highlights, mirrors and glass, with radiosity's diffuse interreflection in place of ambient light",
    cannot_show: &[
        (
            Feature::SpecularIndirect,
            "light that mirrors and glass send onto other surfaces (caustics): the radiosity pass sees them as matte and opaque",
        ),
        (
            Feature::AlphaMask,
            "cut-outs of alpha-masked (glTF MASK) surfaces in the indirect light: the radiosity pass sees them whole",
        ),
        (
            Feature::AmbientLight,
            "ambient lights: interreflection is computed instead",
        ),
        (Feature::EnvironmentLight, ENVIRONMENT_UNOCCLUDED),
        (Feature::RoughTransmission, ROUGH_AS_SMOOTH),
        (Feature::ClearCoat, COAT_REFLECTS_ENVIRONMENT),
    ],
};
