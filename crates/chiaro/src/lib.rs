//! chiaro: one scene, every classic illumination and shading technique.
//!
//! This crate is the facade the CLI, the Python module and the web viewer
//! use. It re-exports the scene model and renders through one path: the
//! settings are validated once into a [`RenderContext`] and the technique
//! they name renders it through the [`Renderer`] interface ([`renderer`]).
//! [`render`] and [`render_with_stats`] do both; [`solve_radiosity`] and
//! [`render_from_solution`] split the radiosity techniques at their
//! view-independent solution; [`settings::apply_override`] is `--set
//! key=value`.
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

pub use chiaro_core::budget;
pub use chiaro_core::film::{self, Film};
pub use chiaro_core::progress::{self, NoProgress, Progress};
pub use chiaro_core::scene::{self, RenderSettings, Scene, Technique};
pub use chiaro_core::{Vec2, Vec3};
pub use chiaro_io as io;
pub use limitations::{Limitation, limitations};

pub use chiaro_core::context::{RenderContext, RenderStats, Renderer, memory_estimate};
pub use chiaro_radiosity::{RadiositySolution, SolveStats, fingerprint as radiosity_fingerprint};

use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{AaMode, Severity};
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

/// Checks `settings` alone ([`RenderSettings::validate`]), before a scene
/// is loaded: every error at once, each naming its setting.
pub fn check_settings(settings: &RenderSettings) -> Result<(), CoreError> {
    let issues: Vec<String> = settings
        .validate()
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

/// The renderer of `technique`.
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
    render_with(scene, settings, progress, renderer(settings.technique))
}

/// [`render_with_stats`] with a given renderer in place of the one the
/// settings' technique names (a path tracer's other kernels, for tests and
/// benchmarks that compare them).
pub fn render_with(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    renderer: &dyn Renderer,
) -> Result<(Film, RenderStats)> {
    let ctx = RenderContext::new(scene, settings, progress)?;
    render_context(&ctx, |ctx| renderer.render(ctx))
}

/// Runs `render` on `ctx` as every front does: the limitations of the
/// technique said once, and `aa = post` (the seeds' "render, then remove
/// the aliasing") as one sample per pixel followed by an edge-aware post
/// filter (FXAA).
fn render_context(
    ctx: &RenderContext<'_>,
    render: impl Fn(&RenderContext<'_>) -> Result<(Film, RenderStats), CoreError>,
) -> Result<(Film, RenderStats)> {
    if ctx.settings().aa == AaMode::Post {
        let one = ctx.with_settings(|s| {
            s.aa = AaMode::Supersample;
            s.samples = 1;
        })?;
        let (film, stats) = render_context(&one, render)?;
        return Ok((chiaro_core::film::postfilter::fxaa(&film), stats));
    }
    for l in limitations::limitations_of_render(ctx.scene(), ctx.settings()) {
        ctx.progress().warning(&l.to_string());
    }
    let (film, stats) = render(ctx)?;
    debug_assert!(film.is_clean());
    Ok((film, stats))
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

/// Solves the radiosity of `scene` with `settings.radiosity` (validated as
/// for a render): the view-independent solution that `radiosity` and
/// `hybrid` render from ([`render_from_solution`]).
pub fn solve_radiosity(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<RadiositySolution> {
    let ctx = RenderContext::new(scene, settings, progress)?;
    Ok(chiaro_radiosity::solve(&ctx)?)
}

/// Renders `scene` from an existing radiosity `solution` with
/// `settings.technique` (`radiosity`: the solution displayed; `hybrid`:
/// Whitted ray tracing with the solution's indirect light). Nothing is
/// solved.
///
/// # Errors
/// [`CoreError::BadSetting`] for another technique; a solution of another
/// scene is [`CoreError::Unsupported`].
pub fn render_from_solution(
    scene: &Scene,
    settings: &RenderSettings,
    solution: &RadiositySolution,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats)> {
    check_solution_technique(settings.technique)?;
    let ctx = RenderContext::new(scene, settings, progress)?;
    render_context(&ctx, |ctx| match ctx.settings().technique {
        Technique::Hybrid => hybrid::render_with_solution(ctx, solution),
        _ => {
            let film = chiaro_radiosity::render_solution(ctx, solution)?;
            Ok((film, ctx.stats(0)))
        }
    })
}

/// Where a radiosity solution comes from and goes to, for the techniques
/// that solve radiosity (`radiosity`, `hybrid`): a solution is view
/// independent, so it can be solved once, saved, and rendered from other
/// cameras without solving again.
#[derive(Debug, Clone, Copy, Default)]
pub struct SolutionFiles<'a> {
    /// Read the solution from this file instead of solving (refused with a
    /// clear error when it belongs to another scene).
    pub load: Option<&'a std::path::Path>,
    /// Write the solution to this file (atomically) after solving.
    pub save: Option<&'a std::path::Path>,
}

/// [`render_with_stats`] for `radiosity` and `hybrid` with a saved or
/// to-be-saved solution. Other techniques with a file given are an error.
pub fn render_with_solution_files(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    files: SolutionFiles<'_>,
) -> Result<(Film, RenderStats)> {
    if files.load.is_none() && files.save.is_none() {
        return render_with_stats(scene, settings, progress);
    }
    check_solution_technique(settings.technique)?;
    let solution = match files.load {
        Some(path) => {
            let file = std::fs::File::open(path).map_err(|e| chiaro_io::IoError::io(path, e))?;
            RadiositySolution::load(std::io::BufReader::new(file), scene)
                .map_err(|e| Error::Io(chiaro_io::IoError::format(path, e.to_string())))?
        }
        None => solve_radiosity(scene, settings, progress)?,
    };
    if let Some(path) = files.save {
        let mut bytes = Vec::new();
        solution.save(&mut bytes)?;
        chiaro_io::output::write_atomically(path, &bytes)?;
    }
    render_from_solution(scene, settings, &solution, progress)
}
