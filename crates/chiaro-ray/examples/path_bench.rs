//! Times the path tracer on a scene file and writes the image as `.npy`
//! (float32, height x width x 3, linear RGB) and `.png` (clamped sRGB), for
//! the Mitsuba 3 comparison in `benches/mitsuba_cbox.sh`.
//!
//! ```text
//! cargo run --release -p chiaro-ray --example path_bench -- SCENE.toml OUT_PREFIX \
//!     [--spp N] [--max-depth D] [--repeats R] [--threads N] [--seed S]
//!     [--width W] [--height H] [--max-leaf N] [--traversal-cost C]
//!     [--scalar | --reference]
//! ```
//!
//! `--width`/`--height` replace the scene's image size (the camera's
//! vertical field of view is kept): a small image at a realistic sample
//! count is how to profile the per-sample work under callgrind, where the
//! per-pixel set-up (the sampler's key hashing) is amortised as in a real
//! render.
//!
//! The accelerator is [`SceneBvh`] with [`BvhOptions::default`], as the
//! facade builds it for a scene without shared meshes; `--max-leaf` and
//! `--traversal-cost` replace those two build options (for measuring them).
//!
//! Prints one line per repeat (`render[i]=SECONDS s  M Msamples/s`, timed
//! from the loaded scene: BVH build included, file loading and image writing
//! excluded; then the process's CPU seconds over the same interval and
//! samples per CPU second, the steadier figure on a shared machine) and the
//! median; the image written is the last repeat's.

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::bvh::{BvhOptions, SceneBvh};
use chiaro_core::context::{RenderContext, Renderer};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::Technique;
use chiaro_ray::path;
use chiaro_testkit::bench::{cpu_seconds, flag_value};
use std::io::Write;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let chiaro_testkit::scenes::SceneCommandLine {
        args,
        out: prefix,
        scene,
        mut settings,
    } = chiaro_testkit::scenes::scene_command_line(
        "usage: path_bench SCENE OUT_PREFIX [--spp N] [--max-depth D] [--repeats R] [--threads N] [--seed S]",
        Technique::Path,
    )?;
    let arg = |name: &str| flag_value(&args, name);
    if let Some(n) = arg("--spp") {
        settings.samples = n.parse()?;
    }
    if let Some(d) = arg("--max-depth") {
        settings.path.max_depth = d.parse()?;
    }
    if let Some(w) = arg("--width") {
        settings.width = w.parse()?;
    }
    if let Some(h) = arg("--height") {
        settings.height = h.parse()?;
    }
    if let Some(s) = arg("--seed") {
        settings.seed = s.parse()?;
    }
    let mut bvh_options = BvhOptions::default();
    if let Some(n) = arg("--max-leaf") {
        bvh_options.max_leaf = n.parse()?;
    }
    if let Some(c) = arg("--traversal-cost") {
        bvh_options.traversal_cost = c.parse()?;
    }
    let accel = |p: &PreparedScene<'_>| -> Box<dyn Accelerator> {
        Box::new(SceneBvh::with_options(p, &bvh_options))
    };
    // `--scalar`: one path at a time (the lock-step kernel's oracle);
    // `--reference`: the plain reference path tracer.
    let kernel = if args.iter().any(|a| a == "--scalar") {
        path::Kernel::Scalar
    } else if args.iter().any(|a| a == "--reference") {
        path::Kernel::Reference
    } else {
        path::Kernel::Lanes
    };
    let repeats: usize = arg("--repeats").map_or(Ok(1), |s| s.parse())?;
    let threads: usize = arg("--threads").map_or(Ok(0), |s| s.parse())?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let samples =
        u64::from(settings.width) * u64::from(settings.height) * u64::from(settings.samples);
    println!(
        "chiaro path {}x{} spp={} max_depth={} rr_depth={} threads={} bvh max_leaf={} traversal_cost={}",
        settings.width,
        settings.height,
        settings.samples,
        settings.path.max_depth,
        settings.path.rr_depth,
        pool.current_num_threads(),
        bvh_options.max_leaf,
        bvh_options.traversal_cost
    );
    let mut times = Vec::new();
    let mut last = None;
    for i in 0..repeats.max(1) {
        let (t0, cpu0) = (Instant::now(), cpu_seconds());
        // A fresh context each time: the preparation and the BVH build are timed.
        let (film, stats) = pool.install(|| {
            let ctx = RenderContext::new(&scene, &settings, &NoProgress)?.with_accelerator(&accel);
            path::PathTracing { kernel }.render(&ctx)
        })?;
        let secs = t0.elapsed().as_secs_f64();
        let cpu = cpu_seconds().zip(cpu0).map_or(f64::NAN, |(b, a)| b - a);
        println!(
            "render[{i}]={secs:.3}s  {:.3} Msamples/s  {:.2} Mrays/s  cpu {cpu:.3}s  {:.3} Msamples/cpu-s",
            samples as f64 / secs / 1e6,
            stats.rays as f64 / secs / 1e6,
            samples as f64 / cpu / 1e6
        );
        times.push(secs);
        last = Some(film);
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    println!(
        "median={median:.3}s  {:.3} Msamples/s",
        samples as f64 / median / 1e6
    );
    let Some(film) = last else {
        return Err("no render".into());
    };
    // .npy version 1.0: magic, header length, a Python dict literal padded to 64 bytes.
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, 3), }}",
        film.height, film.width
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut npy = Vec::with_capacity(10 + header.len() + film.color.len() * 12);
    npy.extend_from_slice(b"\x93NUMPY\x01\x00");
    npy.extend_from_slice(&u16::try_from(header.len())?.to_le_bytes());
    npy.extend_from_slice(header.as_bytes());
    for c in &film.color {
        for v in [c.x, c.y, c.z] {
            npy.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::File::create(format!("{prefix}.npy"))?.write_all(&npy)?;
    chiaro_testkit::scenes::save_png(&film, format!("{prefix}.png"))?;
    Ok(())
}
