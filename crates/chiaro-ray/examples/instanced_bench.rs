//! Instancing benchmark: the workload of `bvh_bench` (a 14 x 14 grid of
//! 5120-triangle icospheres, 1,003,520 triangles, 1000 x 1000 pinhole
//! camera rays from (0, 0, 20) looking down -z with tan(half fov) = 7/20)
//! written as 196 objects instancing one mesh, traced with the flat
//! [`SceneBvh`] over the flattened triangles and with the two-level
//! [`InstancedBvh`] (one object-space BVH of the mesh, 196 instances).
//!
//! ```text
//! cargo run --release -p chiaro-ray --example instanced_bench -- [--threads 2] [--reps 5] [--png DIR]
//!     [--grid 14] [--level 4]
//! ```
//! `--grid N` places N x N instances (the camera widens to frame them) and
//! `--level L` subdivides the icosphere L times (20 * 4^L triangles).
//! Prints, for each accelerator, the build time (median of `--reps`, wall
//! and process CPU time), the memory of nodes and triangle blocks
//! ([`scene_bvh_memory_bytes`], [`InstancedBvh::memory_bytes`]), and
//! closest-hit Mrays/s for the camera rays and for 1M random rays, then
//! how many hits differ between the two. `--png DIR` also renders the
//! scene with the preview technique through each accelerator, writes
//! `DIR/instanced_{flat,two_level}.png` and reports the largest pixel
//! difference. CPU times come from `/proc/self/task/*/schedstat`, steadier
//! than wall time on a shared machine; "cpu-normalised" rates are the rays
//! per second had every thread had a core to itself (rays / (cpu / threads)).

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::accel::instanced::{InstancedBvh, scene_bvh_memory_bytes};
use chiaro_core::context::{AccelBuilder, RenderContext, Renderer};
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{Camera, Geometry, Material, Object, RenderSettings, Scene, Transform};
use chiaro_ray::preview::Preview;
use chiaro_testkit::bench::{bvh_rays, cpu_normalised_note, cpu_seconds, flag_value, median};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Runs `f` `reps` times: the last result, and the medians of wall and CPU
/// seconds (CPU `None` where unavailable).
fn timed<T>(reps: usize, mut f: impl FnMut() -> T) -> (T, f64, Option<f64>) {
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let mut run = || {
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let out = f();
        wall.push(t0.elapsed().as_secs_f64());
        if let (Some(c0), Some(c1)) = (c0, cpu_seconds()) {
            cpu.push(c1 - c0);
        }
        out
    };
    let mut out = run();
    for _ in 1..reps {
        out = run();
    }
    let cpu = (!cpu.is_empty()).then(|| median(&mut cpu));
    (out, median(&mut wall), cpu)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| flag_value(&args, name);
    let threads: usize = arg("--threads").map_or(Ok(2), |s| s.parse())?;
    let reps: usize = arg("--reps").map_or(Ok(5), |s| s.parse())?;
    let png = arg("--png");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;

    // N x N instances of one icosphere of radius 0.45 on a unit grid.
    let n: i32 = arg("--grid").map_or(Ok(14), |s| s.parse())?;
    let level: u32 = arg("--level").map_or(Ok(4), |s| s.parse())?;
    let tan = (n as f32 / 2.0) / 20.0;
    let mut scene = Scene::default();
    scene.add_material(Material::default());
    let mesh = scene.add_mesh(chiaro_core::geometry::primitives::icosphere(
        0.45,
        level.min(8),
    ));
    for i in 0..n {
        for j in 0..n {
            scene.objects.push(Object {
                geometry: Geometry::Mesh(mesh),
                transform: Transform {
                    translate: Vec3::new(
                        i as f32 - (n - 1) as f32 / 2.0,
                        j as f32 - (n - 1) as f32 / 2.0,
                        0.0,
                    ),
                    ..Transform::default()
                },
                ..Object::default()
            });
        }
    }
    scene.camera = Camera {
        eye: Vec3::new(0.0, 0.0, 20.0),
        look_at: Vec3::ZERO,
        fov_y_degrees: 2.0 * tan.atan().to_degrees(),
        ..Camera::default()
    };
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    println!(
        "{} objects instancing one {}-triangle mesh: {} triangles flattened; {threads} threads, {reps} reps",
        scene.objects.len(),
        scene.meshes[0].indices.len(),
        ps.triangles.len()
    );

    // Rays: the pinhole camera of bvh_bench, and random rays.
    let (w, h) = (1000usize, 1000usize);
    let (coherent, incoherent) = bvh_rays(w, h, tan, &ps.bounds);

    let cpu_note = |c: Option<f64>| c.map_or(String::new(), |c| format!(", cpu {c:.3}s"));
    let (flat, fw, fc) = timed(reps, || pool.install(|| SceneBvh::new(&ps)));
    println!(
        "flat SceneBvh     build: median {fw:.3}s{}, {:.1} MiB ({} nodes)",
        cpu_note(fc),
        scene_bvh_memory_bytes(&flat) as f64 / (1 << 20) as f64,
        flat.bvh().node_count()
    );
    let (inst, iw, ic) = timed(reps, || pool.install(|| InstancedBvh::new(&ps)));
    println!(
        "InstancedBvh      build: median {iw:.3}s{}, {:.2} MiB ({} levels, {} instances)",
        cpu_note(ic),
        inst.memory_bytes() as f64 / (1 << 20) as f64,
        inst.level_count(),
        inst.instance_count()
    );

    let accels: [(&str, &dyn Accelerator); 2] = [("flat", &flat), ("two-level", &inst)];
    let mut hits_of: Vec<Vec<Option<u32>>> = Vec::new();
    for (rays_name, rays) in [("camera", &coherent), ("random", &incoherent)] {
        for (name, accel) in accels {
            let (hits, wall, cpu) = timed(reps, || {
                pool.install(|| {
                    rays.par_chunks(4096)
                        .flat_map_iter(|c| c.iter().map(|r| accel.intersect(r).map(|h| h.prim)))
                        .collect::<Vec<_>>()
                })
            });
            let cpu_rate = cpu_normalised_note(rays.len(), cpu, threads, 3);
            println!(
                "{rays_name:<6} {name:<9} intersect: median {wall:.3}s -> {:.2} Mrays/s{cpu_rate}, hit rate {:.3}",
                rays.len() as f64 / wall / 1e6,
                hits.iter().filter(|h| h.is_some()).count() as f64 / rays.len() as f64
            );
            hits_of.push(hits);
        }
    }
    for (k, rays_name) in ["camera", "random"].iter().enumerate() {
        let (a, b) = (&hits_of[2 * k], &hits_of[2 * k + 1]);
        let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
        println!(
            "{rays_name}: {differ} of {} hits name another prim",
            a.len()
        );
    }

    if let Some(dir) = png {
        std::fs::create_dir_all(&dir)?;
        let settings = RenderSettings {
            width: 256,
            height: 256,
            samples: 1,
            ..RenderSettings::default()
        };
        let render = |make: &AccelBuilder<'_>| -> chiaro_core::error::Result<_> {
            let ctx = RenderContext::new(&scene, &settings, &NoProgress)?.with_accelerator(make);
            Preview.render(&ctx).map(|(film, _)| film)
        };
        let film_flat = render(&|p| Box::new(SceneBvh::new(p)))?;
        let film_inst = render(&|p| Box::new(InstancedBvh::new(p)))?;
        let opts = chiaro_io::output::OutputOptions::default();
        for (name, film) in [("flat", &film_flat), ("two_level", &film_inst)] {
            let path = std::path::Path::new(&dir).join(format!("instanced_{name}.png"));
            chiaro_io::output::write_film(film, &path, &opts)?;
        }
        let diffs: Vec<f32> = film_flat
            .color
            .iter()
            .zip(&film_inst.color)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .collect();
        println!(
            "preview 256x256: max pixel difference {:.2e}, {} pixels differ by more than 1/255; wrote {dir}/instanced_{{flat,two_level}}.png",
            diffs.iter().copied().fold(0.0, f32::max),
            diffs.iter().filter(|&&d| d > 1.0 / 255.0).count()
        );
    }
    Ok(())
}
