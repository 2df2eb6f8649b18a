//! The subcommands: load, render, write, describe.

use crate::cli::{CompareArgs, PaletteArg, RenderArgs, RenderOptions, ToneMapArg};
use anyhow::{Context, Result, anyhow};
use chiaro::io::output::{ImageFormat, OutputOptions, PaletteMode};
use chiaro::scene::{Geometry, Scene, Texture, ToneMap};
use chiaro::{RenderSettings, Technique};
use std::path::Path;

/// Loads a scene with the `-D name=value` parameters, printing its
/// warnings to stderr.
fn load(path: &Path, defines: &[String]) -> Result<Scene> {
    let options = chiaro::io::LoadOptions::from_defines(defines).map_err(|e| anyhow!(e))?;
    let loaded = chiaro::io::load_scene_with(path, &options)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded.scene)
}

/// Applies the camera flags of `opts` for images of the size in `settings`.
fn place_camera(scene: &mut Scene, opts: &RenderOptions, settings: &RenderSettings) -> Result<()> {
    let choice = opts.camera.choice()?;
    chiaro::camera::apply_camera(scene, &choice, settings.aspect())?;
    Ok(())
}

/// A technique named on the command line (any case), or an error with a
/// "did you mean" and the list.
fn parse_technique(flag: &str, name: &str) -> Result<Technique> {
    Technique::from_name(name).ok_or_else(|| {
        let names = Technique::ALL.map(Technique::name);
        anyhow!(
            "{flag}: unknown technique `{name}`{} (available: {})",
            chiaro::io::plain::suggestion(name, names),
            chiaro::technique_list()
        )
    })
}

/// `value` when it is at least 1, else an error naming the flag.
fn positive(flag: &str, value: Option<u32>) -> Result<Option<u32>> {
    match value {
        Some(0) => Err(anyhow!("{flag} must be at least 1, got 0")),
        v => Ok(v),
    }
}

/// The scene's settings with the command-line options applied.
pub fn settings_from(scene: &Scene, opts: &RenderOptions) -> Result<RenderSettings> {
    let mut s = scene.render.clone();
    if let Some(t) = &opts.technique {
        s.technique = parse_technique("--technique", t)?;
    }
    if let Some(w) = positive("--width", opts.width)? {
        s.width = w;
    }
    if let Some(h) = positive("--height", opts.height)? {
        s.height = h;
    }
    if let Some(n) = positive("--samples", opts.samples)? {
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
    Ok(s)
}

/// Checks an output image before anything is rendered: its extension names
/// a format chiaro writes, and its directory exists and is writable.
fn check_output(path: &Path) -> Result<ImageFormat> {
    chiaro::io::output::check_output_path(path)?;
    Ok(ImageFormat::from_path(path)?)
}

/// An error unless `path`'s directory exists.
fn check_output_dir(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        anyhow::bail!(
            "{}: cannot write here: the directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// The render options that only apply to some output formats: an error for
/// the ones that cannot be honoured, a warning for the ones that are ignored.
fn check_output_options(args: &RenderArgs, format: ImageFormat) -> Result<()> {
    let name = args.output.display();
    if format != ImageFormat::Png {
        if args.palette.is_some() {
            anyhow::bail!("{name}: --palette writes an indexed PNG; use a .png file");
        }
        if args.png16 {
            anyhow::bail!("{name}: --png16 needs a .png file");
        }
    }
    if matches!(format, ImageFormat::Exr | ImageFormat::Hdr) {
        for (given, flag) in [
            (args.tonemap.is_some(), "--tonemap"),
            (args.exposure.is_some(), "--exposure"),
        ] {
            if given {
                eprintln!(
                    "warning: {flag} does not apply to {name}: EXR and HDR files keep the linear radiance"
                );
            }
        }
    }
    Ok(())
}

/// Renders through the one render path; for `radiosity` and `hybrid` the
/// context is given the solution read from `load`, and the solution (read
/// or solved) is written to `save` before it is displayed.
fn render_solution_files(
    scene: &chiaro::Scene,
    settings: &chiaro::RenderSettings,
    progress: &dyn chiaro::Progress,
    load: Option<&Path>,
    save: Option<&Path>,
) -> Result<(chiaro::Film, chiaro::RenderStats)> {
    if load.is_some() || save.is_some() {
        chiaro::check_solution_technique(settings.technique)?;
    }
    let mut ctx = chiaro::RenderContext::new(scene, settings, progress)?;
    if let Some(path) = load {
        ctx = ctx.with_solution(chiaro::load_solution(path, scene)?);
    }
    if let Some(path) = save {
        let solution = chiaro::radiosity_solution(&ctx)?;
        chiaro::save_solution(&solution, path)?;
    }
    Ok(chiaro::render_with(
        &ctx,
        chiaro::renderer(settings.technique),
    )?)
}

/// `chiaro render`.
pub fn render(args: RenderArgs) -> Result<()> {
    let format = check_output(&args.output)?;
    check_output_options(&args, format)?;
    let mut scene = load(&args.scene, &args.opts.define)?;
    let mut settings = settings_from(&scene, &args.opts)?;
    place_camera(&mut scene, &args.opts, &settings)?;
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
    let (load, save) = (args.solution.as_deref(), args.save_solution.as_deref());
    let result = match &args.display_server {
        Some(addr) => {
            if load.is_some() || save.is_some() {
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
        None => render_solution_files(&scene, &settings, &bar, load, save),
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

/// A number as a person writes it: at most four decimals, no trailing zeros
/// (`1.9000001` is `1.9`).
fn num(x: f32) -> String {
    let t = format!("{x:.4}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" { "0".into() } else { t.into() }
}

/// A point as `[x, y, z]` with [`num`]'s numbers.
fn point(p: chiaro::Vec3) -> String {
    format!("[{}, {}, {}]", num(p.x), num(p.y), num(p.z))
}

/// The word the scene file uses for a setting's value (`ray` for
/// `ShadowMode::Ray`).
fn word<T: serde::Serialize + std::fmt::Debug>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        _ => format!("{v:?}").to_lowercase(),
    }
}

/// The scene's lights in the scene file's words, emissive meshes included
/// (they light every technique, as area lights).
fn light_list(s: &Scene) -> Vec<String> {
    let mut lights: Vec<String> = s.lights.iter().map(|l| l.kind().to_string()).collect();
    for o in &s.objects {
        let Geometry::Mesh(id) = o.geometry else {
            if s.materials
                .get(o.material.index())
                .is_some_and(|m| m.is_emissive())
            {
                lights.push(format!("emissive sphere `{}`", o.name));
            }
            continue;
        };
        let Some(mesh) = s.meshes.get(id.index()) else {
            continue;
        };
        let emits = |m: chiaro::scene::MaterialId| {
            s.materials.get(m.index()).is_some_and(|m| m.is_emissive())
        };
        let count = if mesh.face_materials.is_empty() {
            if emits(o.material) {
                mesh.indices.len()
            } else {
                0
            }
        } else {
            mesh.face_materials.iter().filter(|&&m| emits(m)).count()
        };
        if count > 0 {
            let plural = if count == 1 { "" } else { "s" };
            lights.push(format!(
                "emissive mesh `{}` ({count} triangle{plural})",
                o.name
            ));
        }
    }
    lights
}

/// `chiaro info --system`: the memory limits read, the one that binds, and
/// the budget a job gets.
pub fn info_system() {
    use chiaro::budget::{ByteSize, DEFAULT_SHARE, MemoryBudget, SystemMemory};
    let m = SystemMemory::read();
    let show = |v: Option<u64>, none: &str| v.map_or(none.to_string(), |b| ByteSize(b).to_string());
    println!("memory     {}", show(m.mem_total, "unreadable"));
    println!(
        "cgroup     {}",
        m.cgroup
            .map_or("no limit".to_string(), |(b, source)| format!(
                "{} ({source})",
                ByteSize(b)
            ))
    );
    println!("RLIMIT_AS  {}", show(m.address_space, "unlimited"));
    match m.limit() {
        Some((b, source)) => println!("limit      {} from {source}", ByteSize(b)),
        None => println!("limit      unknown"),
    }
    let budget = MemoryBudget::process();
    let default = m.default_budget();
    if budget.limit.0 == default {
        println!(
            "budget     {} ({DEFAULT_SHARE} of the limit; --memory-limit or render.memory_limit set it)",
            budget.limit
        );
    } else {
        println!("budget     {} (set with --memory-limit)", budget.limit);
    }
    // The BVH queries' kernel, chosen once from the CPU (and CHIARO_KERNEL).
    use chiaro::{KERNEL_ENV, Kernel, kernel};
    let names: Vec<&str> = Kernel::available().iter().map(|k| k.name()).collect();
    println!(
        "kernels    BVH traversal: {} (this CPU runs: {}; {KERNEL_ENV}=baseline caps it)",
        kernel().name(),
        names.join(", ")
    );
}

/// `chiaro info`.
/// `chiaro export`: writes `path`'s scene as `to` (or the format
/// `output`'s extension names), prints the files written and every
/// approximation; a refusal names the object and feature, writing nothing.
pub fn export(path: &Path, to: Option<&str>, output: &Path, defines: &[String]) -> Result<()> {
    use chiaro::io::export::Format;
    let format: Format = match to {
        Some(t) => t.parse().map_err(|e: String| anyhow!(e))?,
        None => match output.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("xml") => Format::Mitsuba,
            Some(e) if e.eq_ignore_ascii_case("pbrt") => Format::Pbrt,
            _ => {
                return Err(anyhow!(
                    "{}: give --to mitsuba or --to pbrt (the extension is neither .xml nor .pbrt)",
                    output.display()
                ));
            }
        },
    };
    let scene = load(path, defines)?;
    let done = chiaro::io::export::export(&scene, format, output)?;
    for w in &done.warnings {
        eprintln!("warning: {w}");
    }
    for f in &done.files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

pub fn info(path: &Path, defines: &[String]) -> Result<()> {
    let options = chiaro::io::LoadOptions::from_defines(defines).map_err(|e| anyhow!(e))?;
    let loaded = chiaro::io::load_scene_with(path, &options)?;
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
    let lights = light_list(s);
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
    println!(
        "bounds     {} .. {}",
        point(prepared.min),
        point(prepared.max)
    );
    let r = &s.render;
    println!(
        "render     technique = {}, {}x{}, samples = {}, shadows = {}",
        r.technique.name(),
        r.width,
        r.height,
        r.samples,
        word(&r.shadows)
    );
    let lens = match s.camera.orthographic_half_height() {
        None => format!("fov = {}", num(s.camera.fov_y_degrees)),
        Some(h) => format!("orthographic, half_height = {}", num(h)),
    };
    println!(
        "camera     eye = {}, look_at = {}, {lens}",
        point(s.camera.eye),
        point(s.camera.look_at),
    );
    println!("cannot show (per technique, see the README's table):");
    for t in chiaro::Technique::ALL {
        let limits = chiaro::limitations(s, t);
        if limits.is_empty() {
            println!("  {}: none of the table's limitations apply", t.name());
        }
        for l in limits {
            println!("  {l}");
        }
    }
    for w in &loaded.warnings {
        println!("warning    {w}");
    }
    for i in s.validate() {
        println!("{i}");
    }
    for i in chiaro::renderer(r.technique).check_settings(r) {
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
        .map(|t| parse_technique("--techniques", t))
        .collect::<Result<Vec<_>>>()?;
    let reference = chiaro_tools::compare::ReferenceSpec::parse(&args.reference)?;
    check_output(&args.output)?;
    if let Some(report) = &args.report {
        check_output_dir(report)?;
    }
    let mut scene = load(&args.scene, &args.opts.define)?;
    let settings = settings_from(&scene, &args.opts)?;
    place_camera(&mut scene, &args.opts, &settings)?;
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
    let result = chiaro_tools::compare::compare(
        &scene,
        &settings,
        &techniques,
        &reference,
        cache_dir.as_deref(),
        &bar,
    );
    bar.finish();
    let comparison = result?;
    use chiaro_tools::compare::CacheStatus;
    match &comparison.cache {
        CacheStatus::Hit(p) => eprintln!("reference: reusing cached {}", p.display()),
        CacheStatus::Stored(p) => eprintln!("reference: cached as {}", p.display()),
        CacheStatus::StoreFailed(m) => eprintln!("warning: reference not cached: {m}"),
        CacheStatus::Disabled => {}
    }
    let title = args.scene.display().to_string();
    let sheet = chiaro_tools::sheet::write_sheet(&comparison, &title, &args.output)?;
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
