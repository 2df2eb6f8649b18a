//! The subcommands: load, render, write, describe.

use crate::cli::{CompareArgs, PaletteArg, RenderArgs, RenderOptions, ToneMapArg};
use anyhow::{Context, Result, anyhow};
use chiaro::io::output::{OutputOptions, PaletteMode};
use chiaro::scene::{Geometry, Light, Scene, Texture, ToneMap};
use chiaro::{RenderSettings, Technique};
use std::path::Path;

/// Loads a scene, printing its warnings to stderr.
fn load(path: &Path) -> Result<Scene> {
    let loaded = chiaro::io::load_scene(path)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded.scene)
}

/// The scene's settings with the command-line options applied.
pub fn settings_from(scene: &Scene, opts: &RenderOptions) -> Result<RenderSettings> {
    let mut s = scene.render.clone();
    if let Some(t) = &opts.technique {
        s.technique = Technique::from_name(t).ok_or_else(|| {
            anyhow!(
                "unknown technique `{t}` (available: {})",
                chiaro::technique_list()
            )
        })?;
    }
    if let Some(w) = opts.width {
        s.width = w;
    }
    if let Some(h) = opts.height {
        s.height = h;
    }
    if let Some(n) = opts.samples {
        s.samples = n;
    }
    if let Some(seed) = opts.seed {
        s.seed = seed;
    }
    for kv in &opts.set {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| anyhow!("--set expects KEY=VALUE, got `{kv}`"))?;
        chiaro::settings::apply_override(&mut s, k.trim(), v.trim())?;
    }
    chiaro::check_settings(&s)?;
    Ok(s)
}

/// `chiaro render`.
pub fn render(args: RenderArgs) -> Result<()> {
    if args.display_server.is_none() {
        chiaro::io::output::check_output_path(&args.output)?;
    }
    let scene = load(&args.scene)?;
    let mut settings = settings_from(&scene, &args.opts)?;
    if let Some(t) = args.tonemap {
        settings.tonemap = match t {
            ToneMapArg::Clamp => ToneMap::Clamp,
            ToneMapArg::Reinhard => ToneMap::Reinhard,
            ToneMapArg::Filmic => ToneMap::Filmic,
        };
    }
    if let Some(e) = args.exposure {
        settings.exposure = e;
    }
    if let Some(n) = args.opts.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("setting the thread count")?;
    }
    let bar = crate::progress::Bar::new();
    let files = chiaro::SolutionFiles {
        load: args.solution.as_deref(),
        save: args.save_solution.as_deref(),
    };
    let result = match &args.display_server {
        Some(addr) => {
            if files.load.is_some() || files.save.is_some() {
                bar.finish();
                anyhow::bail!(
                    "--display-server cannot be combined with --solution or --save-solution"
                );
            }
            let name = args.output.file_name().map_or_else(
                || "chiaro".to_string(),
                |n| n.to_string_lossy().into_owned(),
            );
            chiaro_serve::tev::render_to_tev(&scene, &settings, &bar, addr, &name)
                .map_err(anyhow::Error::from)
        }
        None => chiaro::render_with_solution_files(&scene, &settings, &bar, files)
            .map_err(anyhow::Error::from),
    };
    bar.finish();
    let (film, stats) = result?;
    let palette = args.palette.map(|p| match p {
        PaletteArg::Vga => PaletteMode::Vga {
            band_colors: band_colors(&scene),
        },
        PaletteArg::MedianCut => PaletteMode::MedianCut {
            colors: 256,
            dither: true,
        },
    });
    let out = OutputOptions {
        tonemap: settings.tonemap,
        exposure: settings.exposure,
        bit_depth16: args.png16,
        palette,
    };
    chiaro::io::output::write_film(&film, &args.output, &out)?;
    let secs = stats.elapsed.as_secs_f64().max(1e-9);
    let mut line = format!(
        "{}: {} {}x{} {} spp in {:.3} s",
        args.output.display(),
        settings.technique.name(),
        settings.width,
        settings.height,
        settings.samples,
        secs
    );
    if stats.rays > 0 {
        line += &format!(", {:.2} Mrays/s", stats.rays as f64 / secs / 1e6);
    } else {
        line += &format!(", {} triangles", stats.triangles);
    }
    eprintln!("{line}");
    Ok(())
}

/// Band colours for the VGA palette: the diffuse colours of the materials in
/// the order they appear.
fn band_colors(scene: &Scene) -> Vec<chiaro::Vec3> {
    scene.materials.iter().map(|m| m.diffuse).collect()
}

/// `chiaro info`.
pub fn info(path: &Path) -> Result<()> {
    let loaded = chiaro::io::load_scene(path)?;
    let s = &loaded.scene;
    let prepared = chiaro::scene_bounds(s);
    println!("scene      {}", path.display());
    println!("objects    {}", s.objects.len());
    let spheres = s
        .objects
        .iter()
        .filter(|o| matches!(o.geometry, Geometry::Sphere { .. }))
        .count();
    println!(
        "triangles  {} (+{spheres} analytic spheres)",
        s.triangle_count()
    );
    println!("meshes     {}", s.meshes.len());
    println!(
        "materials  {}: {}",
        s.materials.len(),
        s.materials
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let lights: Vec<&str> = s.lights.iter().map(Light::kind).collect();
    println!("lights     {}: {}", lights.len(), lights.join(", "));
    let images = s
        .textures
        .iter()
        .filter(|t| matches!(t, Texture::Image(_)))
        .count();
    println!(
        "textures   {} ({images} images, {} procedural)",
        s.textures.len(),
        s.textures.len() - images
    );
    println!("bounds     {} .. {}", prepared.min, prepared.max);
    let r = &s.render;
    println!(
        "render     {} {}x{} {} spp, shadows {:?}",
        r.technique.name(),
        r.width,
        r.height,
        r.samples,
        r.shadows
    );
    println!(
        "camera     eye {} look_at {} fov {}",
        s.camera.eye, s.camera.look_at, s.camera.fov_y_degrees
    );
    for w in &loaded.warnings {
        println!("warning    {w}");
    }
    for i in s.validate() {
        println!("{i}");
    }
    Ok(())
}

/// `chiaro compare`: renders each technique and the reference (cached),
/// writes the contact sheet and the optional JSON report, and prints the
/// Markdown table on stdout.
pub fn compare(args: CompareArgs) -> Result<()> {
    if args.opts.technique.is_some() {
        return Err(anyhow!(
            "compare takes --techniques LIST (and --reference TECHNIQUE:SPP), not --technique"
        ));
    }
    let techniques = args
        .techniques
        .iter()
        .map(|t| t.trim())
        .filter(|t| !t.is_empty())
        .map(|t| {
            Technique::from_name(t).ok_or_else(|| {
                anyhow!(
                    "unknown technique `{t}` (available: {})",
                    chiaro::technique_list()
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let reference = chiaro::compare::ReferenceSpec::parse(&args.reference)?;
    let scene = load(&args.scene)?;
    let settings = settings_from(&scene, &args.opts)?;
    if let Some(n) = args.opts.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("setting the thread count")?;
    }
    let cache_dir = if args.no_cache {
        None
    } else {
        Some(args.cache_dir.clone().unwrap_or_else(|| {
            args.output
                .parent()
                .unwrap_or(Path::new(""))
                .join(".chiaro-cache")
        }))
    };
    let bar = crate::progress::Bar::new();
    let result = chiaro::compare::compare(
        &scene,
        &settings,
        &techniques,
        &reference,
        cache_dir.as_deref(),
        &bar,
    );
    bar.finish();
    let comparison = result?;
    use chiaro::compare::CacheStatus;
    match &comparison.cache {
        CacheStatus::Hit(p) => eprintln!("reference: reusing cached {}", p.display()),
        CacheStatus::Stored(p) => eprintln!("reference: cached as {}", p.display()),
        CacheStatus::StoreFailed(m) => eprintln!("warning: reference not cached: {m}"),
        CacheStatus::Disabled => {}
    }
    let title = args.scene.display().to_string();
    let sheet = chiaro::sheet::write_sheet(&comparison, &title, &args.output)?;
    eprintln!(
        "{}: contact sheet {}x{}, error scale {:.4}",
        args.output.display(),
        sheet.film.width,
        sheet.film.height,
        sheet.error_scale
    );
    if let Some(path) = &args.report {
        let mut json = comparison.to_json(&title);
        json.push('\n');
        chiaro::io::output::write_atomically(path, json.as_bytes())?;
        eprintln!("{}: report", path.display());
    }
    print!("{}", comparison.to_markdown());
    Ok(())
}
