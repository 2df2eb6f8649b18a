//! Scan-conversion benchmark: the llvmpipe peer's scene (a 14x14 grid of
//! 5120-triangle icospheres, 1,003,520 triangles, 1920x1080, two point
//! lights, `/work/shared/peers/gl_llvmpipe.py`) rendered with flat, Gouraud
//! and Phong shading. Prints ms/frame (median of `frames` after one warm-up)
//! and the peak resident memory; writes PNGs of the frames to `$OUT_DIR` or
//! /tmp when given `--png`.
//!
//! `cargo run --release -p chiaro-raster --example raster_bench -- [frames] [--png] [--no-cull]`

use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{
    Attenuation, Camera, Geometry, Light, Material, Mesh, Object, RenderSettings, Scene, ShadeMode,
    Technique, Transform,
};
use chiaro_core::{Vec2, Vec3};
use std::collections::HashMap;
use std::time::Instant;

/// An icosphere: the icosahedron subdivided `levels` times, projected to the
/// sphere (20 * 4^levels triangles), with exact sphere normals.
fn icosphere(radius: f32, levels: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut p: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut m = |a: u32, b: u32, p: &mut Vec<Vec3>| {
            let k = (a.min(b), a.max(b));
            *mid.entry(k).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                p.len() as u32 - 1
            })
        };
        let mut nf = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut p), m(b, c, &mut p), m(c, a, &mut p));
            nf.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    Mesh {
        name: "icosphere".into(),
        normals: p.clone(),
        uvs: vec![Vec2::ZERO; p.len()],
        positions: p.iter().map(|&v| v * radius).collect(),
        indices: f,
        ..Mesh::default()
    }
}

fn scene() -> Scene {
    let mut s = Scene::default();
    // The peer's model: 0.1 ambient + per light c (kd N.L + (R.V)^32), no attenuation.
    let m = s.add_material(Material {
        ambient: Vec3::new(1.0 / 7.0, 1.0 / 6.0, 0.25),
        diffuse: Vec3::new(0.7, 0.3, 0.2),
        specular: Vec3::ONE,
        shininess: 32.0,
        ..Material::default()
    });
    let mesh = s.add_mesh(icosphere(0.45, 4));
    let n = 14;
    for i in 0..n {
        for j in 0..n {
            s.objects.push(Object {
                geometry: Geometry::Mesh(mesh),
                material: m,
                transform: Transform {
                    translate: Vec3::new(i as f32 - 6.5, j as f32 - 6.5, 0.0),
                    ..Transform::default()
                },
                ..Object::default()
            });
        }
    }
    s.lights = vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.7,
        },
        Light::Point {
            position: Vec3::new(5.0, -5.0, 10.0),
            color: Vec3::ONE,
            intensity: 0.8,
            attenuation: Attenuation::None,
        },
        Light::Point {
            position: Vec3::new(-8.0, 2.0, 6.0),
            color: Vec3::ONE,
            intensity: 0.4,
            attenuation: Attenuation::None,
        },
    ];
    s.camera = Camera {
        eye: Vec3::new(0.0, -4.5, 8.0),
        look_at: Vec3::ZERO,
        up: Vec3::Z,
        fov_y_degrees: 60.0,
        near: 0.1,
        far: 100.0,
    };
    s
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let frames: usize = args.iter().find_map(|a| a.parse().ok()).unwrap_or(5).max(1);
    let png = args.iter().any(|a| a == "--png");
    let cull = !args.iter().any(|a| a == "--no-cull");
    let s = scene();
    let t0 = Instant::now();
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    let prep = t0.elapsed().as_secs_f64() * 1e3;
    println!(
        "scene: {} triangles, {} vertices; prepare {prep:.1} ms; threads {}; cull {cull}",
        ps.triangle_count(),
        ps.positions.len(),
        rayon::current_num_threads()
    );
    for (name, mode, technique) in [
        ("phong", ShadeMode::Phong, Technique::Phong),
        ("gouraud", ShadeMode::Gouraud, Technique::Gouraud),
        ("flat", ShadeMode::Flat, Technique::Flat),
    ] {
        let st = RenderSettings {
            technique,
            width: 1920,
            height: 1080,
            cull_backfaces: cull,
            ..RenderSettings::default()
        };
        let mut times = Vec::new();
        let mut film = None;
        for _ in 0..=frames {
            let t = Instant::now();
            let f = chiaro_raster::render_prepared(&ps, &st, mode, &NoProgress);
            times.push(t.elapsed().as_secs_f64() * 1e3);
            film = f.ok();
        }
        times.remove(0);
        times.sort_by(f64::total_cmp);
        let Some(film) = film else {
            eprintln!("{name}: render failed");
            continue;
        };
        let covered =
            film.depth.iter().filter(|d| d.is_finite()).count() as f64 / film.depth.len() as f64;
        println!(
            "{name}: median {:.1} ms/frame (min {:.1}, max {:.1}, n={frames}); covered {:.1}%; peak RSS {:.0} MiB",
            times[times.len() / 2],
            times[0],
            times[times.len() - 1],
            covered * 100.0,
            peak_rss_mib()
        );
        if png {
            let dir = std::env::var("OUT_DIR").unwrap_or_else(|_| "/tmp".into());
            let img = image::RgbImage::from_fn(film.width, film.height, |x, y| {
                let c = film.get(x, y);
                let e = |v: f32| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8;
                image::Rgb([e(c.x), e(c.y), e(c.z)])
            });
            let path = format!("{dir}/raster_{name}.png");
            if let Err(e) = img.save(&path) {
                eprintln!("{path}: {e}");
            }
        }
    }
}
