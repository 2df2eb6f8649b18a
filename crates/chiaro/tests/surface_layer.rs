//! The surface layer (`PreparedScene::shading_surface`) across techniques,
//! on Khronos' NormalTangentTest (normal-mapped quads beside real geometry
//! of the same shapes): the scan converter, Whitted and the path tracer shade
//! the same normal-mapped, textured surface.

use chiaro::scene::{ShadowMethod, Technique};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use chiaro_testkit::{
    diff_films, diff_films_relative, diff_films_relative_to_first, dump_ppm, same_surface,
    smooth_colour, whitted_and_path_direct,
};
use std::path::Path;
use std::sync::OnceLock;

fn render(scene: &Scene, settings: &RenderSettings) -> Film {
    chiaro::render(scene, settings, &NoProgress).expect("renders")
}

/// The model as the CLI loads it (its own camera framing, default lights).
fn model() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/NormalTangentTest.glb");
        chiaro::io::load_scene(&path).expect("loads").scene
    })
}

/// The same scene with the normal maps removed.
fn without_normal_maps(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    for m in &mut s.materials {
        m.normal_map = None;
    }
    s
}

fn settings(scene: &Scene, size: u32, technique: Technique) -> RenderSettings {
    let mut s = scene.render.clone();
    s.width = size;
    s.height = size;
    s.samples = 1;
    s.shadows = ShadowMethod::None;
    s.technique = technique;
    s.whitted.max_depth = 0;
    s
}

#[test]
fn model_has_normal_maps() {
    let s = model();
    assert!(s.materials.iter().any(|m| m.normal_map.is_some()));
}

#[test]
fn phong_equals_whitted_at_depth_zero_on_a_normal_mapped_model() {
    let scene = model();
    let raster = render(scene, &settings(scene, 128, Technique::Phong));
    let traced = render(scene, &settings(scene, 128, Technique::Whitted));
    let mask = same_surface(&raster, &traced);
    // The untextured test's tolerance: Whitted's camera rays filter the
    // textures and the normal map over the same footprint as the scan
    // converter, so a lookup changes by about the texture's contrast per
    // pixel, and the two place a sample the same up to rounding (about
    // 1e-4 pixel), as on untextured surfaces. Relative above 1: the
    // near-mirror metals reflect the studio's lamps at radiance up to ~30,
    // where that rounding moves the reflected lookup by 1e-4 of the value.
    let d = diff_films_relative(&raster, &traced, 1e-3, &mask);
    eprintln!("phong vs whitted: {d:?}");
    if d.over > 0 {
        dump_ppm(&raster, "surface_phong");
        dump_ppm(&traced, "surface_whitted");
    }
    assert!(
        d.compared > 128 * 128 / 10,
        "too few pixels compared: {d:?}"
    );
    assert_eq!(d.over, 0, "{d:?}");
}

#[test]
fn whitted_and_path_show_the_normal_map() {
    let scene = model();
    let flat = without_normal_maps(scene);
    for technique in [Technique::Whitted, Technique::Path] {
        let mut s = settings(scene, 64, technique);
        s.samples = 16;
        s.path.max_depth = 1;
        let a = render(scene, &s);
        let b = render(&flat, &s);
        // The same sample positions in both renders: outside the mapped
        // quads the films are equal, so every difference is the map's.
        let d = diff_films(&a, &b, 0.05, |i| a.depth[i].is_finite());
        eprintln!("{technique:?} with vs without normal maps: {d:?}");
        assert!(d.over * 10 > d.compared, "{technique:?}: {d:?}");
    }
}

#[test]
fn path_at_depth_one_equals_direct_local_shading_on_a_normal_mapped_model() {
    let mut scene = model().clone();
    chiaro_testkit::scenes::drop_ambient(&mut scene);
    // The studio environment is a light the path tracer samples at depth 1
    // and Whitted does not integrate (as conformance.rs's depth-one rule
    // skips environment-lit cases): the key light alone.
    scene.environment = None;
    // Lambertian: the model's near-mirror GGX highlights (roughness 0.017)
    // are smaller than a pixel, and the two techniques' 64 sample positions
    // in a pixel see different parts of them; the Lambert term varies with
    // the mapped normal on the scale of the normal map's texels.
    for m in &mut scene.materials {
        m.specular = Vec3::ZERO;
    }
    // Close up on the upper left of the top left normal-mapped dome (a
    // 2048-texel map, about 80 texels over the 64 pixels): Whitted filters
    // the normal map over the pixel's footprint, the path tracer averages
    // its samples' shading on the base level, and the two agree only where
    // the footprint is about a texel (a prefiltered normal does not shade
    // as the mean of the normals it replaces).
    scene.camera = front_view(&scene);
    let cam = &mut scene.camera;
    let dir = cam.ray_direction(78.0, 58.0, 256, 256);
    cam.look_at = cam.eye + dir * (-cam.eye.z / dir.z);
    cam.fov_y_degrees = 1.2;
    let mut s = settings(&scene, 64, Technique::Whitted);
    s.samples = 64;
    let (whitted, path) = whitted_and_path_direct(&mut s, |s| render(&scene, s));
    let mask = same_surface(&whitted, &whitted);
    // As in cross_technique.rs: the two techniques place their samples in
    // a pixel differently, so pixels across an edge of the image (here the
    // normal map's rim and the terminator) differ by their coverage;
    // compare only pixels whose neighbours are within 10 %.
    let smooth = smooth_colour(&whitted, 0.1, 0.02);
    let d = diff_films_relative_to_first(&whitted, &path, 0.02, 0.05, |i| mask(i) && smooth(i));
    let (compared, bad) = (d.compared, d.over);
    eprintln!("path vs whitted: {bad} of {compared} over 2 %: {d:?}");
    if bad > compared / 50 {
        dump_ppm(&whitted, "surface_depth1_whitted");
        dump_ppm(&path, "surface_depth1_path");
    }
    assert!(compared > 64 * 64 / 2, "{compared}");
    assert!(
        bad <= compared / 50,
        "{bad} of {compared} pixels differ by more than 2%"
    );
}

/// Whitted's normal buffer of a close-up of the model around the point seen
/// through pixel `(x, y)` of a 256-pixel render.
fn close_up_normals(x: f32, y: f32) -> Film {
    let mut scene = model().clone();
    scene.camera = front_view(&scene);
    let cam = &mut scene.camera;
    let dir = cam.ray_direction(x, y, 256, 256);
    cam.look_at = cam.eye + dir * (-cam.eye.z / dir.z);
    cam.fov_y_degrees = 5.0;
    render(&scene, &settings(&scene, 64, Technique::Whitted))
}

/// The nearly frontal view the pixel positions of the close-ups were
/// chosen on (the loader's framing before the three-quarter view): from
/// +z, raised by a quarter, the bounding sphere in a 45 degree field.
fn front_view(scene: &Scene) -> chiaro::scene::Camera {
    let b = chiaro::io::world_bounds(scene);
    let radius = (0.5 * b.diagonal()).max(1e-3);
    let distance = 1.1 * radius / 22.5f32.to_radians().sin();
    let eye = b.center() + chiaro::Vec3::new(0.0, 0.25, 1.0).normalize() * distance;
    chiaro::scene::Camera {
        eye,
        look_at: b.center(),
        near: (distance - radius).max(distance * 1e-3) * 0.5,
        far: (distance + radius) * 2.0,
        ..chiaro::scene::Camera::default()
    }
}

/// `(sum n.x (col - mean), sum n.y (row - mean))` over the pixels whose
/// normal is tilted from the quads' (+z): positive, negative for a dome.
fn tilt_correlation(f: &Film) -> (f32, f32) {
    let w = f.width as usize;
    let tilted: Vec<usize> = (0..f.normal.len())
        .filter(|&i| f.depth[i].is_finite() && f.normal[i].z < 0.95)
        .collect();
    let n = tilted.len().max(1) as f32;
    let mean_col = tilted.iter().map(|&i| (i % w) as f32).sum::<f32>() / n;
    let mean_row = tilted.iter().map(|&i| (i / w) as f32).sum::<f32>() / n;
    tilted.iter().fold((0.0, 0.0), |(cx, cy), &i| {
        let nn = f.normal[i];
        (
            cx + nn.x * ((i % w) as f32 - mean_col),
            cy + nn.y * ((i / w) as f32 - mean_row),
        )
    })
}

#[test]
fn normal_mapped_dome_tilts_like_the_real_one() {
    // The top left pair: real geometry on the left, a normal-mapped quad on
    // the right. Both domes' normals tilt right on the right and up at the
    // top (a flipped green channel or bitangent sign makes the mapped one
    // a bowl, README of the model).
    for (what, x) in [("geometry", 59.0), ("normal map", 83.0)] {
        let (cx, cy) = tilt_correlation(&close_up_normals(x, 61.0));
        assert!(cx > 0.0 && cy < 0.0, "{what}: {cx} {cy}");
    }
}
