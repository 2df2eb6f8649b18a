//! The path tracer's own rays through chiaro's BVH alone: renders a scene
//! once on one thread through an accelerator that records every
//! closest-hit and shadow ray it is asked to trace, then times
//! [`SceneBvh`] on those rays again, in the order the renderer traced them,
//! one call at a time through `&dyn Accelerator` (as the renderer calls
//! it). `--dump DIR` writes the scene's triangles and both ray sets
//! (`DIR/wl_{V,F,C,S}.bin`: vertex and index triples, and per ray origin,
//! direction, `t_min`, `t_max` as little-endian f32), which
//! `benches/embree_path_rays.sh` traces with native Embree 3.
//!
//! ```text
//! cargo run --release -p chiaro-ray --example path_rays -- [SCENE.toml] [--spp 16] [--reps 5] [--dump DIR]
//! ```
//!
//! Prints, per repetition, nanoseconds per closest-hit ray and per shadow
//! ray (wall clock and process CPU time), then their medians.

use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::accel::{Accelerator, Hit};
use chiaro_core::context::{RenderContext, Renderer};
use chiaro_core::geometry::Ray;
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::NoProgress;
use chiaro_ray::path;
use chiaro_testkit::bench::{cpu_seconds, flag_value, median};
use std::io::Write;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The recorded rays: closest-hit, shadow.
type Log = Arc<Mutex<(Vec<Ray>, Vec<Ray>)>>;

/// [`SceneBvh`], recording the rays it traces.
struct Recorder {
    bvh: SceneBvh,
    log: Log,
}

impl Accelerator for Recorder {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if let Ok(mut log) = self.log.lock() {
            log.0.push(*ray);
        }
        self.bvh.intersect(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if let Ok(mut log) = self.log.lock() {
            log.1.push(*ray);
        }
        self.bvh.occluded(ray)
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        self.bvh.for_each_hit(ray, visit)
    }
}

fn write_words(path: String, words: impl Iterator<Item = [u8; 4]>) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    for w in words {
        out.write_all(&w)?;
    }
    out.flush()
}

fn ray_words(rays: &[Ray]) -> impl Iterator<Item = [u8; 4]> + '_ {
    rays.iter().flat_map(|r| {
        let o = r.origin.to_array();
        let d = r.dir.to_array();
        [o[0], o[1], o[2], d[0], d[1], d[2], r.t_min, r.t_max].map(f32::to_le_bytes)
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| flag_value(&args, name);
    let scene_path = args
        .get(1)
        .filter(|a| !a.starts_with("--"))
        .map_or("scenes/mitsuba-cbox.toml", String::as_str);
    let spp: u32 = arg("--spp").map_or(Ok(16), |s| s.parse())?;
    let reps: usize = arg("--reps").map_or(Ok(5), |s| s.parse())?;
    let scene = chiaro_io::load_scene(Path::new(scene_path))?.scene;
    let mut settings = scene.render.clone();
    settings.samples = spp;

    // Record: one render on one thread (the rays in the renderer's order).
    let log: Log = Arc::default();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let make = |p: &PreparedScene<'_>| -> Box<dyn Accelerator> {
        Box::new(Recorder {
            bvh: SceneBvh::new(p),
            log: log.clone(),
        })
    };
    pool.install(|| {
        let ctx = RenderContext::new(&scene, &settings, &NoProgress)?.with_accelerator(&make);
        path::PathTracing::LANES.render(&ctx)
    })?;
    let (closest, shadow) = std::mem::take(&mut *log.lock().map_err(|_| "poisoned log")?);
    println!(
        "{scene_path}, {spp} spp: {} closest-hit rays, {} shadow rays",
        closest.len(),
        shadow.len()
    );

    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    if let Some(dir) = arg("--dump") {
        std::fs::create_dir_all(&dir)?;
        let v = ps
            .positions
            .iter()
            .flat_map(|p| p.to_array().map(f32::to_le_bytes));
        write_words(format!("{dir}/wl_V.bin"), v)?;
        let f = ps.triangles.iter().flat_map(|t| t.map(u32::to_le_bytes));
        write_words(format!("{dir}/wl_F.bin"), f)?;
        write_words(format!("{dir}/wl_C.bin"), ray_words(&closest))?;
        write_words(format!("{dir}/wl_S.bin"), ray_words(&shadow))?;
        println!("wrote the triangles and rays to {dir}/wl_{{V,F,C,S}}.bin");
    }

    // Replay, as the renderer calls the accelerator.
    let own = SceneBvh::new(&ps);
    let bvh: &dyn Accelerator = std::hint::black_box(&own);
    let (mut c_ns, mut s_ns, mut c_cpu, mut s_cpu) = (vec![], vec![], vec![], vec![]);
    for rep in 0..reps.max(1) {
        let (t0, k0) = (Instant::now(), cpu_seconds());
        let hits = closest
            .iter()
            .filter(|r| bvh.intersect(r).is_some())
            .count();
        let (t1, k1) = (Instant::now(), cpu_seconds());
        let occluded = shadow.iter().filter(|r| bvh.occluded(r)).count();
        let (t2, k2) = (Instant::now(), cpu_seconds());
        let per = |s: f64, n: usize| s * 1e9 / n.max(1) as f64;
        c_ns.push(per((t1 - t0).as_secs_f64(), closest.len()));
        s_ns.push(per((t2 - t1).as_secs_f64(), shadow.len()));
        if let (Some(k0), Some(k1), Some(k2)) = (k0, k1, k2) {
            c_cpu.push(per(k1 - k0, closest.len()));
            s_cpu.push(per(k2 - k1, shadow.len()));
        }
        println!(
            "rep {rep}: closest {:.1} ns/ray ({hits} hits), shadow {:.1} ns/ray ({occluded} occluded)",
            c_ns[rep], s_ns[rep]
        );
    }
    println!(
        "chiaro SceneBvh median: closest {:.1} ns/ray (cpu {:.1}), shadow {:.1} ns/ray (cpu {:.1})",
        median(&mut c_ns),
        median(&mut c_cpu),
        median(&mut s_ns),
        median(&mut s_cpu)
    );
    Ok(())
}
