//! Radiosity benchmark: time to converge the Cornell box (unit size, in
//! code, official RGB albedos) to 1% unshot energy, per solver and
//! form-factor method, at several element counts; prints a Markdown table.
//!
//! `cargo run --release -p chiaro-radiosity --example radiosity_bench -- [max_elements] [solver,...]`
//! (see benches/radiosity_bench.sh). Peak memory is read from
//! `/proc/self/status` (VmHWM, the process's high-water mark, so run one
//! configuration per process for exact figures: the script does).

use chiaro_core::Vec3;
use chiaro_core::geometry::primitives;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{
    AreaShape, Geometry, Light, Material, MaterialId, Object, RenderSettings, Scene, Transform,
};

fn quad(s: &mut Scene, c: Vec3, u: Vec3, v: Vec3, m: u32) {
    let id = s.add_mesh(primitives::quad(c, u, v));
    s.objects.push(Object {
        geometry: Geometry::Mesh(id),
        material: MaterialId(m),
        smooth: false,
        ..Default::default()
    });
}

fn cornell() -> Scene {
    let mut s = Scene::default();
    s.add_material(Material::diffuse("white", Vec3::new(0.725, 0.71, 0.68)));
    s.add_material(Material::diffuse("red", Vec3::new(0.63, 0.065, 0.05)));
    s.add_material(Material::diffuse("green", Vec3::new(0.14, 0.45, 0.091)));
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    quad(&mut s, Vec3::ZERO, z, x, 0);
    quad(&mut s, y, x, z, 0);
    quad(&mut s, Vec3::ZERO, x, y, 0);
    quad(&mut s, Vec3::ZERO, y, z, 1);
    quad(&mut s, x, z, y, 2);
    for (half, at, rot) in [
        (Vec3::splat(0.15), Vec3::new(0.34, 0.15, 0.62), -17.0f32),
        (Vec3::new(0.15, 0.3, 0.15), Vec3::new(0.66, 0.3, 0.36), 17.0),
    ] {
        let m = s.add_mesh(primitives::box_mesh(half));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            smooth: false,
            transform: Transform {
                translate: at,
                rotate_degrees: Vec3::new(0.0, rot, 0.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }
    s.lights.push(Light::Area {
        shape: AreaShape::Quad {
            corner: Vec3::new(0.375, 0.999, 0.4),
            edge_u: Vec3::new(0.25, 0.0, 0.0),
            edge_v: Vec3::new(0.0, 0.0, 0.2),
        },
        color: Vec3::new(17.0, 12.0, 4.0),
        intensity: 1.0,
        two_sided: false,
    });
    s
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // Usage: radiosity_bench SOLVER FORMFACTOR PATCH_SIZE
    if args.len() != 4 {
        eprintln!("usage: radiosity_bench SOLVER FORMFACTOR PATCH_SIZE");
        std::process::exit(2);
    }
    let scene = cornell();
    let mut r = RenderSettings::default();
    let (Some(solver), Some(formfactor)) = (
        chiaro_radiosity::Solver::from_name(&args[1]),
        chiaro_radiosity::Method::from_name(&args[2]),
    ) else {
        eprintln!("unknown solver or form-factor method");
        std::process::exit(2);
    };
    r.radiosity.solver = solver;
    r.radiosity.formfactor = formfactor;
    r.radiosity.patch_size = args[3].parse().unwrap_or(0.1);
    r.radiosity.tolerance = 0.01;
    r.radiosity.hemicube_resolution = 64;
    let t = std::time::Instant::now();
    let solved = chiaro_core::context::RenderContext::new(&scene, &r, &NoProgress)
        .and_then(|ctx| chiaro_radiosity::solve(&ctx));
    match solved {
        Ok(sol) => {
            let st = &sol.stats;
            let ceiling = sol.object_mean_radiance(1).unwrap_or(Vec3::ZERO);
            println!(
                "| {} | {} | {} | {} | {:.2} | {} | {:.1e} | {} | {} | {:.0} | {:.4} {:.4} {:.4} |",
                st.solver,
                st.formfactor,
                st.patch_size,
                st.elements,
                t.elapsed().as_secs_f64(),
                st.iterations,
                st.unshot,
                st.leaves,
                st.links,
                peak_rss_mib(),
                ceiling.x,
                ceiling.y,
                ceiling.z
            );
        }
        Err(e) => println!(
            "| {} | {} | {} | - | - | - | - | - | - | - | {e} |",
            args[1], args[2], args[3]
        ),
    }
}
