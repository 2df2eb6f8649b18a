//! The whole-scene memory estimate: a render that would not fit its budget
//! is refused before anything is allocated, naming the largest consumers.

use chiaro::budget::ByteSize;
use chiaro::scene::{Geometry, Material, Object, Scene, Technique};
use chiaro::{NoProgress, Vec3};
use chiaro_testkit::scenes::settings;

/// `n` unit spheres in a row (the scan converter tessellates each).
fn spheres(n: usize) -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_material(Material::diffuse("white", Vec3::splat(0.8)));
    for i in 0..n {
        let mut o = Object {
            geometry: Geometry::Sphere { radius: 0.4 },
            material: m,
            ..Default::default()
        };
        o.transform.translate = Vec3::new(i as f32 - n as f32 / 2.0, 0.0, -10.0);
        scene.objects.push(o);
    }
    scene
}

#[test]
fn tessellated_spheres_beyond_the_budget_are_refused() {
    let scene = spheres(5000);
    // Radiosity tessellates every sphere with 64 segments, whatever its size.
    let mut settings = settings(&scene, Technique::Radiosity, 16, 16, 1);
    settings.memory_limit = Some(ByteSize(1 << 30));
    let e = chiaro::render(&scene, &settings, &NoProgress).expect_err("19.8M triangles");
    let msg = e.to_string();
    assert!(
        msg.contains("5000 tessellated spheres (19840000 triangles)")
            && msg.contains("memory limit is 1.0 GiB"),
        "{msg}"
    );
    // The scan converter tessellates them by their size in the image (here
    // under a pixel: 8 segments, 48 triangles each), so they fit and render.
    settings.technique = Technique::Gouraud;
    let e = chiaro::memory_estimate(&scene, &settings);
    assert!(
        e.items
            .iter()
            .any(|(w, _)| w == "5000 tessellated spheres (240000 triangles)"),
        "{e:?}"
    );
    assert!(chiaro::render(&scene, &settings, &NoProgress).is_ok());
    // The ray tracers keep spheres analytic: the same scene fits and renders.
    settings.technique = Technique::Preview;
    assert!(chiaro::memory_estimate(&scene, &settings).total() < 1 << 20);
    let film = chiaro::render(&scene, &settings, &NoProgress).expect("renders");
    assert!(film.is_clean());
}

#[test]
fn the_estimate_counts_films_and_dense_radiosity() {
    let scene = spheres(1);
    let mut settings = settings(&scene, Technique::Phong, 8192, 8192, 64);
    settings.memory_limit = Some(ByteSize(1 << 30));
    let msg = chiaro::render(&scene, &settings, &NoProgress)
        .expect_err("64 spp of 64 Mpixel")
        .to_string();
    assert!(
        msg.contains("largest: supersamples 80.0 GiB, film 1.8 GiB"),
        "{msg}"
    );
    settings.technique = Technique::Radiosity;
    settings.width = 8;
    settings.height = 8;
    settings.radiosity.solver = chiaro::scene::RadiositySolver::Jacobi;
    let e = chiaro::memory_estimate(&scene, &settings);
    assert!(
        e.items
            .iter()
            .any(|(w, b)| w == "radiosity matrix" && *b == 3968 * 3968 * 8),
        "{e:?}"
    );
}

#[test]
fn memory_limit_is_a_setting() {
    let mut s = chiaro::RenderSettings::default();
    chiaro::settings::apply_override(&mut s, "memory_limit", "2G").expect("sets");
    assert_eq!(s.memory_limit, Some(ByteSize(2 << 30)));
    assert!(s.memory_budget().limit <= ByteSize(2 << 30));
    assert!(chiaro::settings::apply_override(&mut s, "memory_limit", "two").is_err());
}
