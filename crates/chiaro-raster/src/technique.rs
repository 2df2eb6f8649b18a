//! Scan conversion as the technique interface's [`Renderer`]: flat,
//! Gouraud or Phong shading (by `settings.technique`) of the context's
//! tessellated scene.

use crate::pipeline::Frame;
use crate::{RasterOptions, RasterWork, render_work};
use chiaro_core::budget::{Estimate, bytes_of};
use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::{CoreError, Result};
use chiaro_core::film::Film;
use chiaro_core::scene::{
    Issue, MAX_RASTER_SAMPLES, RenderSettings, Scene, Severity, ShadeMode, Technique,
};
use chiaro_core::technique::{
    COAT_REFLECTS_ENVIRONMENT, Description, ENVIRONMENT_UNOCCLUDED, Feature,
};

/// The scan-conversion techniques (flat, Gouraud, Phong).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ScanConversion {
    /// Options that are not render settings (the shadow-volume counting).
    pub options: RasterOptions,
}

impl ScanConversion {
    /// The default options (z-fail shadow volumes): what every front renders with.
    pub const DEFAULT: Self = Self {
        options: RasterOptions {
            volume_counting: crate::VolumeCounting::ZFail,
        },
    };

    /// The shading mode of the context's technique.
    fn mode(ctx: &RenderContext<'_>) -> Result<ShadeMode> {
        let technique = ctx.settings().technique;
        technique.shade_mode().ok_or_else(|| {
            CoreError::Unsupported(format!(
                "the scan converter renders flat, gouraud and phong, not `{}`",
                technique.name()
            ))
        })
    }

    /// Renders `ctx` into `film`, whose buffers are reused when it already
    /// has the image's size (so frames rendered one after another neither
    /// allocate nor fault in a new film, as a GPU reuses its framebuffer);
    /// it is resized otherwise. The work done is counted into `work`. On
    /// success `film` holds exactly the picture [`Renderer::render`]
    /// returns, whatever it held before; on an error its pixels are
    /// unspecified.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    pub fn render_into(
        &self,
        ctx: &RenderContext<'_>,
        film: &mut Film,
        work: &RasterWork,
    ) -> Result<()> {
        let mode = Self::mode(ctx)?;
        render_work(
            ctx.tessellated(),
            Frame {
                settings: ctx.settings(),
                camera: ctx.camera(),
                derived: ctx.tessellated_derived(),
            },
            mode,
            &self.options,
            ctx.progress(),
            film,
            work,
        )
    }
}

impl Renderer for ScanConversion {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)> {
        let settings = ctx.settings();
        let mut film = Film::new(settings.width, settings.height);
        self.render_into(ctx, &mut film, &RasterWork::default())?;
        Ok((film, ctx.stats(0)))
    }

    fn descriptions(&self) -> &'static [Description] {
        &[FLAT, GOURAUD, PHONG]
    }

    fn check_settings(&self, settings: &RenderSettings) -> Vec<Issue> {
        let mut issues = Vec::new();
        if settings.samples > MAX_RASTER_SAMPLES {
            issues.push(Issue {
                severity: Severity::Warning,
                path: "render.samples".into(),
                message: format!(
                    "scan conversion takes at most {MAX_RASTER_SAMPLES} samples per pixel; {} are rendered as {MAX_RASTER_SAMPLES}",
                    settings.samples
                ),
            });
        }
        issues
    }

    fn memory(&self, _scene: &Scene, settings: &RenderSettings, estimate: &mut Estimate) {
        // Colour, depth and item a supersample.
        let pixels = u64::from(settings.width) * u64::from(settings.height);
        let samples = pixels.saturating_mul(u64::from(settings.samples.max(1)));
        estimate.add("supersamples", bytes_of(samples, 20));
    }
}

/// What the scan converter shows of other objects in a mirror.
const NO_MIRRORS: &str =
    "mirror reflections of other objects: only the environment map is reflected";
/// What it shows of refraction.
const NO_REFRACTION: &str = "refraction: transparent surfaces do not bend light";
/// Polygon shadows (volume, object, scan-line) do not cut alpha-masked texels.
const WHOLE_MASK_SHADOWS: &str = "shadows of alpha-masked cut-outs with `shadows` = volume, object or scanline: masked surfaces cast whole shadows (`shadows` = ray or map cut them)";

/// Flat shading, described.
pub const FLAT: Description = Description {
    technique: Technique::Flat,
    title: "flat",
    method: "z-buffer scan conversion, one illumination per polygon",
    shows: "direct light and shadows per polygon, textures per pixel, non-refractive transparency, environment reflection maps and the environment's light",
    cannot_show: &[
        (Feature::Mirrors, NO_MIRRORS),
        (Feature::ClearCoat, COAT_REFLECTS_ENVIRONMENT),
        (Feature::Refraction, NO_REFRACTION),
        (
            Feature::NormalMaps,
            "normal and bump maps: polygons are lit with the face normal",
        ),
        (
            Feature::InsideLargePolygons,
            "highlights and shadows inside a polygon: each polygon is lit once, at its centre",
        ),
        (Feature::EnvironmentLight, ENVIRONMENT_UNOCCLUDED),
        (
            Feature::VolumeShadows,
            "shadows with `shadows = \"volume\"`: the volumes exist per sample, not at polygon centres",
        ),
        (Feature::AlphaMaskShadows, WHOLE_MASK_SHADOWS),
    ],
};

/// Gouraud shading, described.
pub const GOURAUD: Description = Description {
    technique: Technique::Gouraud,
    title: "Gouraud",
    method: "illumination at the vertices, colours interpolated",
    shows: "direct light and shadows per vertex, interpolated; textures per pixel, non-refractive transparency, environment reflection maps and the environment's light",
    cannot_show: &[
        (Feature::Mirrors, NO_MIRRORS),
        (Feature::ClearCoat, COAT_REFLECTS_ENVIRONMENT),
        (Feature::Refraction, NO_REFRACTION),
        (
            Feature::NormalMaps,
            "normal and bump maps: vertices are lit with the interpolated normal",
        ),
        (
            Feature::InsideLargePolygons,
            "highlights and shadows inside a polygon: light is computed at the vertices only",
        ),
        (Feature::EnvironmentLight, ENVIRONMENT_UNOCCLUDED),
        (
            Feature::VolumeShadows,
            "shadows with `shadows = \"volume\"`: the volumes exist per sample, not at vertices",
        ),
        (Feature::AlphaMaskShadows, WHOLE_MASK_SHADOWS),
    ],
};

/// Phong shading, described.
pub const PHONG: Description = Description {
    technique: Technique::Phong,
    title: "Phong",
    method: "normals interpolated, illumination per pixel",
    shows: "direct light, highlights and shadows per pixel, textures, normal and bump maps, non-refractive transparency, environment reflection maps and the environment's light",
    cannot_show: &[
        (Feature::Mirrors, NO_MIRRORS),
        (Feature::ClearCoat, COAT_REFLECTS_ENVIRONMENT),
        (Feature::Refraction, NO_REFRACTION),
        (Feature::EnvironmentLight, ENVIRONMENT_UNOCCLUDED),
        (Feature::AlphaMaskShadows, WHOLE_MASK_SHADOWS),
    ],
};

/// The scan converter driven the ways the crate's tests drive it: from a
/// scene through a render context, or over a prepared scene they built.
#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use crate::RasterOptions;
    use chiaro_core::prepared::PreparedScene;
    use chiaro_core::progress::Progress;
    use chiaro_core::scene::{RenderSettings, Scene};

    /// [`ScanConversion`] of `scene` with `settings`.
    pub(crate) fn render(
        scene: &Scene,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<Film> {
        let ctx = RenderContext::new(scene, settings, progress)?;
        ScanConversion::default().render(&ctx).map(|(film, _)| film)
    }

    /// The pipeline over `ps` (spheres tessellated) with `mode` and `options`.
    pub(crate) fn render_prepared_with(
        ps: &PreparedScene<'_>,
        settings: &RenderSettings,
        mode: ShadeMode,
        options: &RasterOptions,
        progress: &dyn Progress,
    ) -> Result<Film> {
        let mut film = Film::new(settings.width, settings.height);
        let work = RasterWork::default();
        let derived = chiaro_core::context::Derived::default();
        let frame = Frame {
            settings,
            camera: &ps.scene.camera,
            derived: &derived,
        };
        render_work(ps, frame, mode, options, progress, &mut film, &work)?;
        Ok(film)
    }

    /// [`render_prepared_with`] with the default options.
    pub(crate) fn render_prepared(
        ps: &PreparedScene<'_>,
        settings: &RenderSettings,
        mode: ShadeMode,
        progress: &dyn Progress,
    ) -> Result<Film> {
        render_prepared_with(ps, settings, mode, &RasterOptions::default(), progress)
    }
}
