//! chiaro: one scene, every classic illumination and shading technique.
//!
//! This crate is the facade the CLI, the Python module and the web viewer
//! use. It re-exports the scene model and offers one entry point,
//! [`render`], which dispatches a scene to the technique its settings name,
//! plus [`settings::apply_override`] for `--set key=value`.
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
pub mod compare;
pub mod gallery;
pub mod hybrid;
pub mod limitations;
pub mod settings;
pub mod sheet;

pub use chiaro_core::budget;
pub use chiaro_core::film::{self, Film};
pub use chiaro_core::progress::{self, NoProgress, Progress};
pub use chiaro_core::scene::{self, RenderSettings, Scene, Technique};
pub use chiaro_core::{Vec2, Vec3};
pub use chiaro_io as io;
pub use limitations::{Limitation, limitations};

use chiaro_core::accel::Accelerator;
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::Severity;
use std::time::{Duration, Instant};
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

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The techniques this build can render, in the order they are listed:
/// every one of [`Technique::ALL`] (the one list; no technique is optional).
pub fn available_techniques() -> &'static [Technique] {
    &Technique::ALL
}

/// Statistics of one render.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RenderStats {
    /// Wall-clock time of the render (excluding file I/O).
    pub elapsed: Duration,
    /// Triangles in the prepared scene.
    pub triangles: u64,
    /// Rays traced, where the technique counts them (0 otherwise).
    pub rays: u64,
}

/// Checks that `settings` can be rendered by this build: the technique
/// exists, and the image size and sample count are within limits.
pub fn check_settings(settings: &RenderSettings) -> Result<(), CoreError> {
    if !available_techniques().contains(&settings.technique) {
        return Err(CoreError::UnknownTechnique {
            name: settings.technique.name().into(),
            available: technique_list(),
        });
    }
    let probe = Scene {
        render: settings.clone(),
        ..Scene::default()
    };
    let issues: Vec<String> = probe
        .validate()
        .into_iter()
        .filter(|i| i.severity == Severity::Error && i.path.starts_with("render"))
        .map(|i| i.to_string())
        .collect();
    if issues.is_empty() {
        Ok(())
    } else {
        Err(CoreError::InvalidScene { issues })
    }
}

/// The names of [`available_techniques`], comma separated.
pub fn technique_list() -> String {
    available_techniques()
        .iter()
        .map(|t| t.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The accelerator used by the ray-based techniques (preview, path): the
/// two-level `InstancedBvh` when meshes shared by several objects would
/// otherwise be duplicated by at least
/// `chiaro_core::accel::instanced::MIN_DUPLICATED_TRIANGLES` triangles, the
/// flat `SceneBvh` otherwise (same hits up to rounding).
fn accelerator(p: &PreparedScene<'_>) -> Box<dyn Accelerator> {
    chiaro_core::accel::instanced::build_accelerator(p)
}

/// What rendering `scene` with `settings` will allocate, by consumer, in
/// bytes: the prepared triangles and vertices (with the spheres the scan
/// converter and radiosity tessellate), texture mip levels, the film and
/// the scan converter's supersamples, shadow maps (up to their share of the
/// budget, [`chiaro_core::budget::MemoryBudget::shadow_map_bytes`]), and a dense radiosity
/// matrix. The per-item sizes are the constants of
/// [`chiaro_core::budget`]; the sum is an estimate of the peak, made
/// without allocating anything.
pub fn memory_estimate(scene: &Scene, settings: &RenderSettings) -> chiaro_core::budget::Estimate {
    use chiaro_core::budget::bytes_of;
    use chiaro_core::geometry::primitives::MeshSize;
    use chiaro_core::scene::{Geometry, RadiositySettings, ShadowMethod, Texture};
    let analytic = matches!(
        settings.technique,
        Technique::Preview | Technique::Whitted | Technique::Path
    );
    let (mut meshes, mut spheres) = (
        MeshSize {
            vertices: 0,
            triangles: 0,
        },
        0u64,
    );
    for obj in &scene.objects {
        match obj.geometry {
            Geometry::Mesh(id) => {
                if let Some(m) = scene.meshes.get(id.index()) {
                    let s = MeshSize::of(m);
                    meshes.vertices = meshes.vertices.saturating_add(s.vertices);
                    meshes.triangles = meshes.triangles.saturating_add(s.triangles);
                }
            }
            Geometry::Sphere { .. } => spheres += 1,
        }
    }
    let slices = chiaro_core::prepared::PrepareOptions::default().sphere_slices;
    let sphere = MeshSize::uv_sphere(slices, slices / 2).times(spheres);
    let mut e = chiaro_core::budget::Estimate::default();
    e.add(
        format!("{} mesh triangles", meshes.triangles),
        meshes.prepared_bytes(),
    );
    if !analytic {
        e.add(
            format!(
                "{spheres} tessellated spheres ({} triangles)",
                sphere.triangles
            ),
            sphere.prepared_bytes(),
        );
    }
    let texels: u64 = scene
        .textures
        .iter()
        .map(|t| match t {
            Texture::Image(i) => u64::from(i.width) * u64::from(i.height),
            Texture::Procedural(_) => 0,
        })
        .sum();
    // Mip levels: a third of the texels again, RGBA f32.
    e.add("texture mip levels", bytes_of(texels, 16) / 3);
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    // Colour, depth and normal a pixel.
    e.add("film", bytes_of(pixels, 28));
    if matches!(
        settings.technique,
        Technique::Flat | Technique::Gouraud | Technique::Phong
    ) {
        // Colour, depth and item a supersample.
        e.add(
            "supersamples",
            bytes_of(
                pixels.saturating_mul(u64::from(settings.samples.max(1))),
                20,
            ),
        );
    }
    if settings.shadows == ShadowMethod::Map {
        // Up to six depth faces of f32 per light; lights past the shadow-map
        // share of the budget use shadow rays instead, so no more than it.
        let r = u64::from(settings.shadow_map.resolution);
        let lights = scene.lights.len() as u64;
        e.add(
            "shadow maps",
            bytes_of(r * r * 6, 4)
                .saturating_mul(lights)
                .min(settings.memory_budget().shadow_map_bytes()),
        );
    }
    if matches!(settings.technique, Technique::Radiosity | Technique::Hybrid) {
        let RadiositySettings { solver, .. } = &settings.radiosity;
        if solver == "jacobi" || solver == "gauss-seidel" {
            // Two f32 matrices over at least one element a triangle.
            let n = meshes.triangles.saturating_add(sphere.triangles);
            e.add("radiosity matrix", bytes_of(n.saturating_mul(n), 8));
        }
    }
    e
}

/// Refuses a render whose [`memory_estimate`] exceeds the settings' budget.
fn check_memory(scene: &Scene, settings: &RenderSettings) -> Result<(), CoreError> {
    memory_estimate(scene, settings)
        .check(settings.memory_budget())
        .map_err(CoreError::Unsupported)
}

/// Renders `scene` with `settings` (which override `scene.render`), reporting
/// to `progress`. The scene is validated first: every error found is
/// reported at once.
pub fn render(scene: &Scene, settings: &RenderSettings, progress: &dyn Progress) -> Result<Film> {
    render_with_stats(scene, settings, progress).map(|(f, _)| f)
}

/// [`render`], also returning [`RenderStats`].
pub fn render_with_stats(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats)> {
    check_settings(settings)?;
    let mut scene_checked = scene.clone();
    scene_checked.render = settings.clone();
    let errors: Vec<String> = scene_checked
        .validate()
        .into_iter()
        .filter(|i| i.severity == Severity::Error)
        .map(|i| i.to_string())
        .collect();
    if !errors.is_empty() {
        return Err(CoreError::InvalidScene { issues: errors }.into());
    }
    check_memory(scene, settings)?;
    if settings.aa == chiaro_core::scene::AaMode::Post {
        // The seeds' "render, then remove the aliasing": one sample per
        // pixel, then an edge-aware post filter (FXAA).
        let one = RenderSettings {
            aa: chiaro_core::scene::AaMode::Supersample,
            samples: 1,
            ..settings.clone()
        };
        let (film, stats) = render_with_stats(scene, &one, progress)?;
        return Ok((chiaro_core::film::postfilter::fxaa(&film), stats));
    }
    warn_limitations(scene, settings, progress);
    let start = Instant::now();
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    let (film, rays) = match settings.technique {
        Technique::Preview => (
            chiaro_ray::preview::render_with(scene, settings, progress, &accelerator)?,
            pixels * u64::from(settings.samples.max(1)),
        ),
        Technique::Flat | Technique::Gouraud | Technique::Phong => {
            (chiaro_raster::render(scene, settings, progress)?, 0)
        }
        Technique::Whitted => {
            let (film, stats) = chiaro_ray::whitted::render_with_stats(scene, settings, progress)?;
            (film, stats.rays)
        }
        Technique::Radiosity => (chiaro_radiosity::render(scene, settings, progress)?, 0),
        Technique::Hybrid => {
            let (film, stats) = hybrid::render(scene, settings, progress)?;
            (film, stats.rays)
        }
        Technique::Path => {
            let (film, stats) =
                chiaro_ray::path::render_with(scene, settings, progress, &accelerator)?;
            (film, stats.rays)
        }
    };
    let stats = RenderStats {
        elapsed: start.elapsed(),
        triangles: scene.triangle_count() as u64,
        rays,
    };
    debug_assert!(film.is_clean());
    Ok((film, stats))
}

/// Says, once each, what `scene` has that `settings.technique` cannot
/// show, naming the objects ([`limitations`]).
fn warn_limitations(scene: &Scene, settings: &RenderSettings, progress: &dyn Progress) {
    for l in limitations::limitations_of_render(scene, settings) {
        progress.warning(&l.to_string());
    }
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
    if !matches!(settings.technique, Technique::Radiosity | Technique::Hybrid) {
        return Err(CoreError::BadSetting {
            key: "solution".into(),
            message: format!(
                "a radiosity solution file needs --technique radiosity or hybrid, not {}",
                settings.technique.name()
            ),
        }
        .into());
    }
    check_settings(settings)?;
    check_memory(scene, settings)?;
    warn_limitations(scene, settings, progress);
    let start = Instant::now();
    let solution = match files.load {
        Some(path) => {
            let file = std::fs::File::open(path).map_err(|e| chiaro_io::IoError::io(path, e))?;
            chiaro_radiosity::RadiositySolution::load(std::io::BufReader::new(file), scene)
                .map_err(|e| Error::Io(chiaro_io::IoError::format(path, e.to_string())))?
        }
        None => chiaro_radiosity::solve(scene, settings, progress)?,
    };
    if let Some(path) = files.save {
        let mut bytes = Vec::new();
        solution.save(&mut bytes)?;
        chiaro_io::output::write_atomically(path, &bytes)?;
    }
    let (film, rays) = match settings.technique {
        Technique::Hybrid => {
            let (film, stats) = hybrid::render_with_solution(scene, solution, settings, progress)?;
            (film, stats.rays)
        }
        _ => (
            chiaro_radiosity::render_solution(scene, &solution, settings, progress)?,
            0,
        ),
    };
    let stats = RenderStats {
        elapsed: start.elapsed(),
        triangles: scene.triangle_count() as u64,
        rays,
    };
    Ok((film, stats))
}
