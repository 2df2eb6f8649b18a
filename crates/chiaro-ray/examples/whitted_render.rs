//! Renders a scene file with the Whitted ray tracer and writes a PNG,
//! printing the time and the rays traced.
//!
//! ```text
//! cargo run --release -p chiaro-ray --example whitted_render -- SCENE.toml OUT.png \
//!     [--size 640x480] [--samples N] [--adaptive] [--threshold T] [--light-samples N] [--threads N]
//! ```

use chiaro_core::context::RenderContext;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{AaMode, Technique};
use chiaro_ray::whitted;
use chiaro_testkit::bench::flag_value;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let chiaro_testkit::scenes::SceneCommandLine {
        args,
        out,
        scene,
        mut settings,
    } = chiaro_testkit::scenes::scene_command_line(
        "usage: whitted_render SCENE OUT.png [--size WxH] [--samples N] [--adaptive] [--light-samples N] [--threads N]",
        Technique::Whitted,
    )?;
    let arg = |name: &str| flag_value(&args, name);
    if let Some(size) = arg("--size") {
        let (w, h) = size.split_once('x').ok_or("--size WxH")?;
        settings.width = w.parse()?;
        settings.height = h.parse()?;
    }
    if let Some(n) = arg("--samples") {
        settings.samples = n.parse()?;
    }
    if let Some(n) = arg("--light-samples") {
        settings.light_samples = n.parse()?;
    }
    if let Some(t) = arg("--threshold") {
        settings.whitted.adaptive_threshold = t.parse()?;
    }
    if args.iter().any(|a| a == "--adaptive") {
        settings.aa = AaMode::Adaptive;
    }
    let threads: usize = arg("--threads").map_or(Ok(0), |s| s.parse())?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let t0 = Instant::now();
    let (film, stats) = pool.install(|| -> chiaro_core::error::Result<_> {
        let ctx = RenderContext::new(&scene, &settings, &NoProgress)?;
        whitted::Tracer::new(&ctx).render(&ctx)
    })?;
    let secs = t0.elapsed().as_secs_f64();
    println!(
        "{}x{} {:?} samples {}: {secs:.3}s, {} rays ({} camera), {:.2} Mrays/s",
        film.width,
        film.height,
        settings.aa,
        settings.samples,
        stats.rays,
        stats.camera_rays,
        stats.rays as f64 / secs / 1e6
    );
    chiaro_testkit::scenes::save_png(&film, out)?;
    Ok(())
}
