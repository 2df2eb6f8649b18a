//! Ray-casts the built-in Utah teapot through the brute-force accelerator
//! and writes it as a PNG: the teapot's normals must face the camera where
//! it is seen, and the picture must survive the trip through a file.
//!
//! Set `CHIARO_TEAPOT_PNG=/some/file.png` (and optionally
//! `CHIARO_TEAPOT_SIZE=256`) to keep the picture for looking at.

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::list::ListAccel;
use chiaro_core::film::Film;
use chiaro_core::geometry::Ray;
use chiaro_core::geometry::teapot::teapot;
use chiaro_core::glam::Vec3;
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::scene::{Material, Object, Scene};
use chiaro_io::output::{OutputOptions, PaletteMode, read_image_as_film, write_film};

#[test]
fn teapot_ray_cast_faces_the_camera_and_writes() {
    let size: u32 = std::env::var("CHIARO_TEAPOT_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64);
    let mut scene = Scene::default();
    scene.add_material(Material::default());
    let mesh = scene.add_mesh(teapot(6));
    scene.objects.push(Object {
        geometry: chiaro_core::scene::Geometry::Mesh(mesh),
        ..Object::default()
    });
    let prepared = PreparedScene::new(&scene, PrepareOptions::default());
    let accel = ListAccel::new(&prepared);

    // A pinhole camera looking at the pot's middle from the front right.
    let eye = Vec3::new(2.0, 1.5, 2.6);
    let target = Vec3::new(0.1, 0.4, 0.0);
    let forward = (target - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let half = (30.0f32.to_radians() / 2.0).tan();
    let light = Vec3::new(0.4, 1.0, 0.6).normalize();

    let mut film = Film::new(size, size);
    let (mut hits, mut facing) = (0u32, 0u32);
    for y in 0..size {
        for x in 0..size {
            let sx = (2.0 * (x as f32 + 0.5) / size as f32 - 1.0) * half;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / size as f32) * half;
            let dir = (forward + right * sx + up * sy).normalize();
            let ray = Ray::new(eye, dir);
            let Some(hit) = accel.intersect(&ray) else {
                film.set(x, y, Vec3::new(0.05, 0.06, 0.1));
                continue;
            };
            let s = prepared.surface(&ray, &hit);
            hits += 1;
            if s.ns.dot(-dir) > 0.0 {
                facing += 1;
            }
            // Two-sided Lambert plus a little ambient, so inward normals show
            // as dark patches.
            let lambert = s.ns.dot(light).max(0.0);
            let c = Vec3::new(0.9, 0.55, 0.3) * (0.08 + 0.9 * lambert);
            film.set(x, y, c);
            let i = film.index(x, y);
            film.depth[i] = hit.t;
            film.normal[i] = s.ns;
        }
    }
    let coverage = hits as f32 / (size * size) as f32;
    assert!((0.1..0.7).contains(&coverage), "coverage {coverage}");
    // Where the pot is seen, its outward normals face the camera.
    let f = facing as f32 / hits as f32;
    assert!(f > 0.97, "front-facing fraction {f}");

    let dir = std::env::temp_dir().join(format!("chiaro-teapot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let path = dir.join("teapot.png");
    write_film(&film, &path, &OutputOptions::default()).expect("write png");
    let back = read_image_as_film(&path).expect("read png");
    let err = (back.mean() - film.mean()).abs().max_element();
    assert!(err < 2e-3, "mean changed by {err}");

    // The magazine series' VGA bands (one band for the pot's colour) and a dithered
    // 16-colour median cut: both decode to pictures close to the original.
    let variants = [
        (
            "vga",
            PaletteMode::Vga {
                band_colors: vec![Vec3::new(0.9, 0.55, 0.3), Vec3::new(0.05, 0.06, 0.1)],
            },
        ),
        (
            "mc16",
            PaletteMode::MedianCut {
                colors: 16,
                dither: true,
            },
        ),
    ];
    let keep = std::env::var("CHIARO_TEAPOT_PNG").ok();
    for (name, mode) in variants {
        let opts = OutputOptions {
            palette: Some(mode),
            ..OutputOptions::default()
        };
        let p = dir.join(format!("teapot-{name}.png"));
        write_film(&film, &p, &opts).expect("write indexed png");
        let back = read_image_as_film(&p).expect("read indexed png");
        let err = (back.mean() - film.mean()).abs().max_element();
        assert!(err < 0.02, "{name}: mean changed by {err}");
        if let Some(keep) = &keep {
            let kept = keep.replace(".png", &format!("-{name}.png"));
            write_film(&film, std::path::Path::new(&kept), &opts).expect("write kept png");
        }
    }
    if let Some(keep) = keep {
        write_film(
            &film,
            std::path::Path::new(&keep),
            &OutputOptions::default(),
        )
        .expect("write kept png");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
