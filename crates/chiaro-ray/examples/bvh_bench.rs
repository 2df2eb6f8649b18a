//! BVH benchmark (chiaro's 8-wide BVH, [`SceneBvh`]) on the workload of `benches/embree_bvh.sh`: a 14 x 14
//! grid of 5120-triangle icospheres (1,003,520 triangles), 1000 x 1000
//! coherent pinhole camera rays and 1M incoherent random rays, closest hit,
//! one ray at a time and as packets of [`PACKET`] (camera rays in 4 x 2
//! pixel tiles, random rays eight in a row), on a rayon pool of `--threads`
//! threads. The packets' answers are checked against the single rays'.
//!
//! ```text
//! cargo run --release -p chiaro-ray --example bvh_bench -- [--threads 2] [--reps 5] [--dump DIR]
//!     [--max-leaf 4] [--traversal-cost 1] [--bins 16] [--stats] [--build-only] [--fingerprint]
//! ```
//! `--dump DIR` writes the mesh and both ray sets as `DIR/wl_{V,F,O,D,Or,Dr}.bin`
//! (raw little-endian f32 / u32 triples), the files `embree3_native` reads,
//! so that Embree traces exactly the same rays. Times are wall clock; the
//! `cpu` figures are the process's CPU time over the same interval (from
//! `/proc/self/task/*/schedstat`), steadier when other work shares the
//! machine.

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::Hit;
use chiaro_core::accel::bvh::{BvhOptions, PACKET, SceneBvh};
use chiaro_core::geometry::Ray;
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::scene::{Geometry, Material, Mesh, Object, Scene};
use chiaro_testkit::bench::{
    WordHash, bvh_rays, cpu_normalised_note, cpu_seconds, flag_value, median,
};
use glam::Vec3;
use rayon::prelude::*;
use std::io::Write;
use std::time::Instant;

fn write_f32(dir: &str, name: &str, data: impl Iterator<Item = f32>) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(format!("{dir}/wl_{name}.bin"))?);
    for x in data {
        out.write_all(&x.to_le_bytes())?;
    }
    out.flush()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| flag_value(&args, name);
    let threads: usize = arg("--threads").map_or(Ok(2), |s| s.parse())?;
    let reps: usize = arg("--reps").map_or(Ok(5), |s| s.parse())?;
    let dump = arg("--dump");
    let defaults = BvhOptions::default();
    let opts = BvhOptions {
        max_leaf: arg("--max-leaf").map_or(Ok(defaults.max_leaf), |s| s.parse())?,
        traversal_cost: arg("--traversal-cost")
            .map_or(Ok(defaults.traversal_cost), |s| s.parse())?,
        bins: arg("--bins").map_or(Ok(defaults.bins), |s| s.parse())?,
        ..defaults
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;

    // The mesh: 14 x 14 icospheres of radius 0.45 on a unit grid.
    const N: i32 = 14;
    let sphere = chiaro_core::geometry::primitives::icosphere(0.45, 4);
    let (v0, f0) = (sphere.positions, sphere.indices);
    let mut mesh = Mesh::default();
    for i in 0..N {
        for j in 0..N {
            let off = Vec3::new(
                i as f32 - (N - 1) as f32 / 2.0,
                j as f32 - (N - 1) as f32 / 2.0,
                0.0,
            );
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(v0.iter().map(|&p| p + off));
            mesh.normals.extend(v0.iter().map(|&p| p.normalize()));
            mesh.indices.extend(f0.iter().map(|t| t.map(|k| k + base)));
        }
    }
    let mut scene = Scene::default();
    scene.add_material(Material::default());
    let id = scene.add_mesh(mesh);
    scene.objects.push(Object {
        geometry: Geometry::Mesh(id),
        ..Default::default()
    });
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    println!(
        "mesh: {} triangles, {} vertices; {threads} threads; single-ray kernel {}",
        ps.triangles.len(),
        ps.positions.len(),
        chiaro_core::accel::bvh::kernel().name()
    );

    // Rays: the pinhole camera of embree_rays.py, and random rays.
    let (w, h) = (1000usize, 1000usize);
    let tan = (N as f32 / 2.0) / 20.0;
    let (coherent, incoherent) = bvh_rays(w, h, tan, &ps.bounds);

    if let Some(dir) = &dump {
        std::fs::create_dir_all(dir)?;
        write_f32(dir, "V", ps.positions.iter().flat_map(|p| p.to_array()))?;
        let mut out = std::io::BufWriter::new(std::fs::File::create(format!("{dir}/wl_F.bin"))?);
        for t in &ps.triangles {
            for k in t {
                out.write_all(&k.to_le_bytes())?;
            }
        }
        out.flush()?;
        write_f32(dir, "O", coherent.iter().flat_map(|r| r.origin.to_array()))?;
        write_f32(dir, "D", coherent.iter().flat_map(|r| r.dir.to_array()))?;
        write_f32(
            dir,
            "Or",
            incoherent.iter().flat_map(|r| r.origin.to_array()),
        )?;
        write_f32(dir, "Dr", incoherent.iter().flat_map(|r| r.dir.to_array()))?;
        println!("wrote the workload to {dir}/wl_*.bin");
    }

    // Build, median of `reps`.
    let mut builds = Vec::new();
    let mut build_cpu = Vec::new();
    let mut bvh = None;
    for _ in 0..reps.max(1) {
        // The previous build is released first, as the Embree side releases
        // its scene before building the next one.
        drop(bvh.take());
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let b = pool.install(|| SceneBvh::with_options(&ps, &opts));
        builds.push(t0.elapsed().as_secs_f64());
        if let (Some(c0), Some(c1)) = (c0, cpu_seconds()) {
            build_cpu.push(c1 - c0);
        }
        bvh = Some(b);
    }
    let bvh = bvh.ok_or("no build")?;
    let cpu_note = if build_cpu.is_empty() {
        String::new()
    } else {
        format!(", cpu {:.3}s", median(&mut build_cpu))
    };
    println!(
        "chiaro BVH build: median {:.3}s (min {:.3}s{cpu_note}), {} nodes, depth {}",
        median(&mut builds),
        builds[0],
        bvh.bvh().node_count(),
        bvh.bvh().depth()
    );

    if args.iter().any(|a| a == "--fingerprint") {
        // FNV-1a over every node's lanes and the slot order: equal
        // fingerprints mean a build change left the tree as it was.
        let b = bvh.bvh();
        let mut h = WordHash::default();
        for n in b.nodes() {
            n.bounds.iter().flatten().for_each(|&v| h.eat_f32(v));
            n.child.iter().chain(&n.count).for_each(|&v| h.eat(v));
        }
        b.prim_order().iter().for_each(|&v| h.eat(v));
        println!("tree fingerprint {:016x}", h.0);
    }
    if args.iter().any(|a| a == "--build-only") {
        return Ok(());
    }
    if args.iter().any(|a| a == "--stats") {
        for (name, rays) in [("coherent", &coherent), ("incoherent", &incoherent)] {
            let mut tests = 0u64;
            let b = bvh.bvh();
            for r in rays.iter().step_by(100) {
                b.traverse_closest(r, |_, _| {
                    tests += 1;
                    None
                });
            }
            println!(
                "{name}: {:.1} leaf prims tested per ray (no culling)",
                tests as f64 / (rays.len() / 100) as f64
            );
        }
    }
    // The camera rays again in 4 x 2 pixel tiles, one packet each.
    let tiled: Vec<Ray> = (0..h / 2)
        .flat_map(|ty| (0..w / 4).map(move |tx| (tx, ty)))
        .flat_map(|(tx, ty)| (0..8).map(move |k| (4 * tx + k % 4) + w * (2 * ty + k / 4)))
        .map(|i| coherent[i])
        .collect();
    assert_eq!(tiled.len(), coherent.len(), "tiles cover the image");
    let single = |c: &[Ray]| c.iter().filter(|r| bvh.intersect(r).is_some()).count();
    let packets = |c: &[Ray]| {
        let mut hits = [None; PACKET];
        c.chunks(PACKET)
            .map(|p| {
                bvh.intersect_packet(p, &mut hits[..p.len()]);
                hits[..p.len()].iter().filter(|h| h.is_some()).count()
            })
            .sum::<usize>()
    };
    type Trace<'a> = &'a (dyn Fn(&[Ray]) -> usize + Sync);
    let runs: [(&str, &str, &Vec<Ray>, Trace); 4] = [
        ("coherent(camera)", "intersect", &coherent, &single),
        ("coherent(camera)", "packet 4x2", &tiled, &packets),
        ("incoherent(random)", "intersect", &incoherent, &single),
        ("incoherent(random)", "packet 8", &incoherent, &packets),
    ];
    for (name, how, rays, trace) in runs {
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut hits = 0usize;
        for _ in 0..reps.max(1) {
            let (t0, c0) = (Instant::now(), cpu_seconds());
            hits = pool.install(|| rays.par_chunks(4096).map(trace).sum());
            times.push(t0.elapsed().as_secs_f64());
            if let (Some(c0), Some(c1)) = (c0, cpu_seconds()) {
                cpu.push(c1 - c0);
            }
        }
        let med = median(&mut times);
        // CPU-normalised: rays per second if every thread had had a core.
        let cpu = (!cpu.is_empty()).then(|| median(&mut cpu));
        let cpu_note = cpu_normalised_note(rays.len(), cpu, threads, 4);
        println!(
            "{name:<20} {how:<10} threads={threads}: median {med:.4}s -> {:.2} Mrays/s (min {:.4} max {:.4}, hit rate {:.3}{cpu_note})",
            rays.len() as f64 / med / 1e6,
            times[0],
            times[times.len() - 1],
            hits as f64 / rays.len() as f64
        );
    }
    // The packets' answers are the single rays' bit for bit.
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()));
    for (name, rays) in [("camera tiles", &tiled), ("random", &incoherent)] {
        let differ: usize = pool.install(|| {
            rays.par_chunks(4096)
                .map(|c| {
                    let mut hits = vec![None; c.len()];
                    bvh.intersect_packet(c, &mut hits);
                    c.iter()
                        .zip(&hits)
                        .filter(|(r, h)| bits(bvh.intersect(r)) != bits(**h))
                        .count()
                })
                .sum()
        });
        println!(
            "{name}: {differ} of {} packet answers differ from single rays",
            rays.len()
        );
        if differ != 0 {
            return Err(format!("{differ} packet answers differ").into());
        }
    }
    Ok(())
}
