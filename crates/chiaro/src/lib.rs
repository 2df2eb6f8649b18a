//! chiaro: one scene, every classic illumination and shading technique.
//!
//! This crate is the facade the CLI, the Python module and the web viewer
//! use. It re-exports the scene model and renders through one path: the
//! settings are validated once into a [`RenderContext`] and the technique
//! they name renders it through the [`Renderer`] interface ([`renderer`]).
//! [`render`] and [`render_with_stats`] do both; [`render_with`] renders a
//! context a front built itself (one given a saved radiosity solution with
//! [`RenderContext::with_solution`], or whose solution it then saves with
//! [`radiosity_solution`] and [`save_solution`]); [`render_frame`] renders
//! one frame of an interactive session through the same path, keeping what
//! does not depend on the camera in a [`FrameCache`] for the next frame;
//! [`settings::apply_override`] is `--set key=value`.
//!
//! ```
//! use chiaro::scene::{Scene, Material, Object, Geometry, Technique};
//! use chiaro::progress::NoProgress;
//!
//! let mut scene = Scene::default();
//! scene.add_material(Material::diffuse("white", chiaro::Vec3::splat(0.8)));
//! scene.objects.push(Object { geometry: Geometry::Sphere { radius: 1.0 }, ..Default::default() });
//! let mut settings = scene.render.clone();
//! settings.technique = Technique::Preview;
//! settings.width = 16;
//! settings.height = 16;
//! let film = chiaro::render(&scene, &settings, &NoProgress).unwrap();
//! assert!(film.get(8, 8).x > 0.5);
//! ```

pub mod camera;
pub mod hybrid;
pub mod limitations;
pub mod settings;

pub use chiaro_core::accel::bvh::{KERNEL_ENV, Kernel, kernel};
pub use chiaro_core::budget;
pub use chiaro_core::film::{self, Film};
pub use chiaro_core::progress::{self, NoProgress, Progress};
pub use chiaro_core::scene::{self, RenderSettings, Scene, Technique};
pub use chiaro_core::{Vec2, Vec3};
pub use chiaro_io as io;
pub use limitations::{Limitation, limitations};

pub use chiaro_core::budget::Estimate;
pub use chiaro_core::context::{CachedPiece, FrameCache, RenderContext, RenderStats, Renderer};
pub use chiaro_core::scene::Issue;
pub use chiaro_core::technique::Description;
pub use chiaro_radiosity::{RadiositySolution, SolveStats, fingerprint as radiosity_fingerprint};

use chiaro_core::budget::ByteSize;
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{AaMode, Severity};
use std::path::Path;
use std::sync::Arc;
use thiserror::Error;

/// Anything that can go wrong between a file and a picture.
#[derive(Debug, Error)]
pub enum Error {
    /// A scene or settings problem, or a technique refusing the scene.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A file could not be read or written.
    #[error(transparent)]
    Io(#[from] chiaro_io::IoError),
}

/// Result with [`enum@Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Every issue with `settings` alone, before a scene is loaded: those of
/// every render ([`RenderSettings::validate`]) and the technique's own
/// ([`Renderer::check_settings`]).
pub fn settings_issues(settings: &RenderSettings) -> Vec<Issue> {
    let mut issues = settings.validate();
    issues.extend(renderer(settings.technique).check_settings(settings));
    issues
}

/// Checks `settings` alone ([`settings_issues`]), before a scene is
/// loaded: every error at once, each naming its setting.
pub fn check_settings(settings: &RenderSettings) -> Result<(), CoreError> {
    let issues: Vec<String> = settings_issues(settings)
        .into_iter()
        .filter(|i| i.severity == Severity::Error)
        .map(|i| i.to_string())
        .collect();
    if issues.is_empty() {
        Ok(())
    } else {
        Err(CoreError::InvalidScene { issues })
    }
}

/// The names of [`Technique::ALL`], comma separated.
pub fn technique_list() -> String {
    Technique::ALL
        .iter()
        .map(|t| t.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The description of `technique`, written beside its renderer: what it
/// is, shows and cannot show.
pub fn description(technique: Technique) -> Option<&'static Description> {
    renderer(technique)
        .descriptions()
        .iter()
        .find(|d| d.technique == technique)
}

/// What rendering `scene` with `settings` will allocate, by consumer:
/// what every render allocates ([`chiaro_core::context::memory_estimate`])
/// and what the technique adds ([`Renderer::memory`]).
pub fn memory_estimate(scene: &Scene, settings: &RenderSettings) -> Estimate {
    frame_estimate(scene, settings, renderer(settings.technique))
}

/// The renderer of `technique`: the one line a new technique adds here.
pub fn renderer(technique: Technique) -> &'static dyn Renderer {
    match technique {
        Technique::Preview => &chiaro_ray::preview::Preview,
        Technique::Flat | Technique::Gouraud | Technique::Phong => {
            &chiaro_raster::ScanConversion::DEFAULT
        }
        Technique::Whitted => &chiaro_ray::whitted::Whitted,
        Technique::Radiosity => &chiaro_radiosity::Radiosity,
        Technique::Hybrid => &hybrid::Hybrid,
        Technique::Path => &chiaro_ray::path::PathTracing::LANES,
    }
}

/// Renders `scene` with `settings` (which override `scene.render`), reporting
/// to `progress`. The scene and settings are validated first: every error
/// found is reported at once.
pub fn render(scene: &Scene, settings: &RenderSettings, progress: &dyn Progress) -> Result<Film> {
    render_with_stats(scene, settings, progress).map(|(f, _)| f)
}

/// [`render`], also returning [`RenderStats`].
pub fn render_with_stats(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats)> {
    let ctx = RenderContext::new(scene, settings, progress)?;
    render_with(&ctx, renderer(settings.technique))
}

/// One frame of an interactive session: `scene` seen through `camera`,
/// rendered as [`render_with_stats`] renders it, taking from `cache` what an
/// earlier frame of the same scene built that does not depend on the camera
/// (prepared scenes, accelerators, mip-maps, the prefiltered environment,
/// the radiosity solution; see [`FrameCache`]) and leaving there what this
/// one builds. The picture is that of [`render_with_stats`] of the scene
/// with its camera replaced, bit for bit.
pub fn render_frame<'a>(
    scene: &'a Scene,
    settings: &RenderSettings,
    camera: &scene::Camera,
    progress: &'a dyn Progress,
    cache: &mut FrameCache<'a>,
) -> Result<(Film, RenderStats)> {
    let ctx = RenderContext::new(scene, settings, progress)?.with_camera(*camera);
    // What the cache holds that this frame does not read counts against
    // the budget beside the frame's own estimate: dropped (and said) when
    // both do not fit, before the frame allocates.
    let technique = renderer(settings.technique);
    let frame = frame_estimate(scene, settings, technique).total();
    for (piece, bytes) in cache.evict_unused(
        settings.technique,
        frame,
        settings.memory_budget(),
        solution_bytes,
    ) {
        progress.warning(&format!(
            "the viewer's cache dropped its {} ({}) kept from an earlier frame: with this frame's {} it would pass the memory limit {}",
            piece.name(),
            ByteSize(bytes),
            ByteSize(frame),
            settings.memory_budget().limit
        ));
    }
    render_with(&ctx.with_cache(cache), technique)
}

/// The bytes a cached view-independent solution holds: a radiosity
/// solution's display mesh (per vertex its position and three colours, 48
/// B; per element its corners, radiance and emission, 36 B), at most one
/// source triangle per element (corners and ids, 48 B) and the look-up
/// tree over them (16 B); 0 for a solution of another type.
pub fn solution_bytes(solution: &(dyn std::any::Any + Send + Sync)) -> u64 {
    solution
        .downcast_ref::<chiaro_radiosity::RadiositySolution>()
        .map_or(0, |s| {
            (s.vertex_count() as u64)
                .saturating_mul(48)
                .saturating_add((s.element_count() as u64).saturating_mul(36 + 48 + 16))
        })
}

/// Renders `ctx` with `renderer` as every front does: the limitations of
/// the technique said once, and `aa = post` (the magazine series' "render,
/// then remove the aliasing") as one sample per pixel followed by an edge-aware post filter
/// (FXAA). The one render path: [`render_with_stats`] calls it with the
/// settings' technique ([`renderer`]); a front that gives the context a
/// saved radiosity solution ([`RenderContext::with_solution`]) or saves
/// the one solved ([`save_solution`]) calls it directly, as do tests and
/// benchmarks that compare a technique's kernels.
pub fn render_with(
    ctx: &RenderContext<'_>,
    renderer: &dyn Renderer,
) -> Result<(Film, RenderStats)> {
    if ctx.settings().aa == AaMode::Post {
        let one = ctx.with_settings(|s| {
            s.aa = AaMode::Supersample;
            s.samples = 1;
        })?;
        let (film, stats) = render_with(&one, renderer)?;
        return Ok((chiaro_core::film::postfilter::fxaa(&film), stats));
    }
    check_context(ctx, renderer)?;
    for l in limitations::limitations_of_render(ctx.scene(), ctx.settings()) {
        ctx.progress().warning(&l.to_string());
    }
    let (film, stats) = renderer.render(ctx)?;
    debug_assert!(film.is_clean());
    Ok((film, stats))
}

/// What the context's validation leaves to the technique: its settings
/// checks (errors refused, warnings to the progress) and its memory
/// estimate against the budget.
fn check_context(ctx: &RenderContext<'_>, renderer: &dyn Renderer) -> Result<(), CoreError> {
    let (scene, settings) = (ctx.scene(), ctx.settings());
    let mut errors = Vec::new();
    for issue in renderer.check_settings(settings) {
        match issue.severity {
            Severity::Error => errors.push(issue.to_string()),
            Severity::Warning => ctx
                .progress()
                .warning(&format!("{}: {}", issue.path, issue.message)),
        }
    }
    if !errors.is_empty() {
        return Err(CoreError::InvalidScene { issues: errors });
    }
    frame_estimate(scene, settings, renderer)
        .check(settings.memory_budget())
        .map_err(CoreError::Unsupported)
}

/// What a render of `scene` with `settings` by `renderer` allocates: the
/// shared estimate and the technique's own items.
fn frame_estimate(scene: &Scene, settings: &RenderSettings, renderer: &dyn Renderer) -> Estimate {
    let mut estimate = chiaro_core::context::memory_estimate(scene, settings);
    renderer.memory(scene, settings, &mut estimate);
    estimate
}

/// World-space bounds of everything in the scene.
pub fn scene_bounds(scene: &Scene) -> chiaro_core::geometry::Aabb {
    PreparedScene::new(
        scene,
        chiaro_core::prepared::PrepareOptions {
            analytic_spheres: true,
            ..Default::default()
        },
    )
    .bounds
}

/// Refuses a technique that does not render from a radiosity solution
/// (only `radiosity` and `hybrid` do), for every front.
///
/// # Errors
/// [`CoreError::BadSetting`] for key `solution`, naming the two techniques.
pub fn check_solution_technique(technique: Technique) -> Result<(), CoreError> {
    if technique.solves_radiosity() {
        Ok(())
    } else {
        Err(CoreError::BadSetting {
            key: "solution".into(),
            message: format!(
                "a radiosity solution renders with technique radiosity or hybrid, not {}",
                technique.name()
            ),
        })
    }
}

/// The radiosity solution of `ctx` (`settings.radiosity`; view
/// independent): the one it was given, else solved now and kept, so that a
/// render of the same context after this call does not solve again.
pub fn radiosity_solution(ctx: &RenderContext<'_>) -> Result<Arc<RadiositySolution>> {
    check_context(ctx, &chiaro_radiosity::Radiosity)?;
    Ok(chiaro_radiosity::solution(ctx)?)
}

/// Reads a radiosity solution saved by [`save_solution`], refusing one of
/// another scene than `scene`; give it to a context with
/// [`RenderContext::with_solution`].
pub fn load_solution(path: &Path, scene: &Scene) -> Result<Arc<RadiositySolution>> {
    let file = std::fs::File::open(path).map_err(|e| chiaro_io::IoError::io(path, e))?;
    let solution = RadiositySolution::load(std::io::BufReader::new(file), scene)
        .map_err(|e| Error::Io(chiaro_io::IoError::format(path, e.to_string())))?;
    Ok(Arc::new(solution))
}

/// Writes `solution` to `path` whole or not at all.
pub fn save_solution(solution: &RadiositySolution, path: &Path) -> Result<()> {
    let mut bytes = Vec::new();
    solution.save(&mut bytes)?;
    chiaro_io::output::write_atomically(path, &bytes)?;
    Ok(())
}
