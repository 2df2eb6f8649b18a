//! The orthographic camera in every technique: the scan converter and the
//! ray tracer agree pixel by pixel under it, and a sphere covers the
//! fraction of the image its closed form gives, whatever its distance.

use chiaro::scene::{Camera, Geometry, Material, Projection, ShadowMethod, Technique, Transform};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use chiaro_testkit::{diff_films, dump_ppm, phong_and_whitted_at_depth_0, same_surface, scenes};
use std::f32::consts::PI;

fn render(scene: &Scene, settings: &RenderSettings) -> Film {
    chiaro::render(scene, settings, &NoProgress).expect("renders")
}

/// The shadow test scene seen through an orthographic camera from its own
/// viewpoint, the film 3.2 units high.
fn ortho_shadow_test(size: u32) -> Scene {
    let mut scene = scenes::shadow_test(size);
    scene.camera.projection = Projection::Orthographic { half_height: 1.6 };
    scene
}

#[test]
fn orthographic_phong_equals_whitted_at_depth_zero() {
    let scene = ortho_shadow_test(64);
    let mut s = RenderSettings {
        technique: Technique::Phong,
        ..scene.render.clone()
    };
    s.shadows = ShadowMethod::None;
    let (raster, traced) = phong_and_whitted_at_depth_0(&mut s, |s| render(&scene, s));
    let mask = same_surface(&raster, &traced);
    let d = diff_films(&raster, &traced, 1e-3, &mask);
    if d.over > 0 {
        dump_ppm(&raster, "ortho_phong_vs_whitted_raster");
        dump_ppm(&traced, "ortho_phong_vs_whitted_whitted");
    }
    assert!(d.compared > 64 * 64 / 3, "too few pixels compared: {d:?}");
    assert_eq!(d.over, 0, "{d:?}");
    // Both see the same surfaces at the same depths: the film's depth is
    // the distance past the film plane.
    let both = (0..raster.depth.len())
        .filter(|&i| raster.depth[i].is_finite() && traced.depth[i].is_finite())
        .count();
    assert!(both > 64 * 64 / 2, "{both}");
    for i in 0..raster.depth.len() {
        if mask(i) {
            let (a, b) = (raster.depth[i], traced.depth[i]);
            assert!((a - b).abs() < 1e-3 * b.max(1.0), "pixel {i}: {a} vs {b}");
        }
    }
}

/// One sphere of `radius` on the view axis, `distance` in front of an
/// orthographic camera whose film is `2 half_height` high, on a 2:1 image.
fn sphere_on_axis(radius: f32, distance: f32, half_height: f32) -> Scene {
    let mut s = Scene::default();
    let m = s.add_material(Material::diffuse("grey", Vec3::splat(0.5)));
    s.objects.push(chiaro::scene::Object {
        name: "ball".into(),
        geometry: Geometry::Sphere { radius },
        material: m,
        transform: Transform::default(),
        ..Default::default()
    });
    s.lights.push(chiaro::scene::Light::Ambient {
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s.camera = Camera {
        eye: Vec3::new(0.0, 0.0, distance),
        look_at: Vec3::ZERO,
        near: 0.01,
        far: 10.0 * distance,
        projection: Projection::Orthographic { half_height },
        ..Default::default()
    };
    s.render.width = 160;
    s.render.height = 80;
    s.render.samples = 1;
    s.render.shadows = ShadowMethod::None;
    s
}

/// A sphere of radius r covers pi r^2 / (2 h * 2 h aspect) of the image
/// under a film of half-height h, at any distance, in every technique.
#[test]
fn a_sphere_covers_its_closed_form_fraction_at_any_distance() {
    let (r, h) = (0.6f32, 1.0f32);
    let want = PI * r * r / ((2.0 * h) * (2.0 * h * 2.0));
    for technique in [
        Technique::Preview,
        Technique::Flat,
        Technique::Gouraud,
        Technique::Phong,
        Technique::Whitted,
        Technique::Path,
        Technique::Radiosity,
    ] {
        let mut counts = Vec::new();
        for distance in [3.0f32, 40.0] {
            let scene = sphere_on_axis(r, distance, h);
            let s = RenderSettings {
                technique,
                ..scene.render.clone()
            };
            let film = render(&scene, &s);
            let covered = film.depth.iter().filter(|d| d.is_finite()).count();
            let fraction = covered as f32 / film.depth.len() as f32;
            assert!(
                (fraction - want).abs() < 0.015 * want,
                "{technique:?} at {distance}: {fraction} vs {want}"
            );
            // The nearest point, in the middle, lies distance - r past the film.
            let mid = (40 * 160 + 80) as usize;
            let depth = film.depth[mid];
            assert!(
                (depth - (distance - r)).abs() < 0.02 * r,
                "{technique:?} at {distance}: depth {depth}"
            );
            counts.push(covered);
        }
        // The same pixels at both distances (a tessellated sphere's
        // silhouette may move by a pixel here and there).
        let diff = counts[0].abs_diff(counts[1]);
        assert!(diff <= counts[0] / 100, "{technique:?}: {counts:?}");
    }
}

/// Framing a scene again keeps an orthographic camera orthographic, seeing
/// at the target what the perspective frame sees there.
#[test]
fn framing_again_keeps_the_projection() {
    let mut scene = ortho_shadow_test(32);
    let choice = chiaro::camera::CameraChoice {
        up: Some(chiaro::camera::UpAxis::Y),
        ..Default::default()
    };
    chiaro::camera::apply_camera(&mut scene, &choice, 1.0).expect("frames");
    let c = scene.camera;
    let h = c.orthographic_half_height().expect("still orthographic");
    let framed = chiaro_core::framing::frame_scene(&scene, chiaro::camera::UpAxis::Y, 1.0, None);
    let p = framed.camera;
    let want = (p.look_at - p.eye).length() * (0.5 * p.fov_y_degrees.to_radians()).tan();
    assert!((h - want).abs() < 1e-4 * want, "{h} vs {want}");
    // A field of view makes it perspective again.
    let choice = chiaro::camera::CameraChoice {
        fov: Some(30.0),
        ..Default::default()
    };
    chiaro::camera::apply_camera(&mut scene, &choice, 1.0).expect("applies");
    assert_eq!(scene.camera.projection, Projection::Perspective);
}
