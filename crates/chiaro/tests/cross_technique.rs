//! Invariants across techniques (ARCHITECTURE.md, "How correctness is
//! shown"): techniques that should agree do, pixel by pixel, on small images.

use chiaro::scene::{ShadowMethod, Technique};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use chiaro_testkit::{
    diff_films, diff_films_relative_to_first, dump_ppm, phong_and_whitted_at_depth_0, same_surface,
    scenes, smooth_colour, whitted_and_path_direct,
};

fn render(scene: &Scene, settings: &RenderSettings) -> Film {
    chiaro::render(scene, settings, &NoProgress).expect("renders")
}

/// `scene`'s own settings with `technique`.
fn with_technique(scene: &Scene, technique: Technique) -> RenderSettings {
    RenderSettings {
        technique,
        ..scene.render.clone()
    }
}

/// Pixels of `f` inside a surface: finite depth, and the four neighbours
/// see nearly the same depth and normal (no silhouettes or creases).
fn smooth_region(f: &Film) -> impl Fn(usize) -> bool + '_ {
    let w = f.width as usize;
    let h = f.height as usize;
    move |i| {
        let (x, y) = (i % w, i / w);
        if x == 0 || y == 0 || x + 1 >= w || y + 1 >= h || !f.depth[i].is_finite() {
            return false;
        }
        [i - 1, i + 1, i - w, i + w].iter().all(|&j| {
            f.depth[j].is_finite()
                && (f.depth[j] - f.depth[i]).abs() < 0.05 * f.depth[i]
                && f.normal[j].dot(f.normal[i]) > 0.99
        })
    }
}

#[test]
fn phong_scan_conversion_equals_whitted_at_depth_zero() {
    let scene = scenes::shadow_test(64);
    let mut s = with_technique(&scene, Technique::Phong);
    s.shadows = ShadowMethod::None;
    let (raster, traced) = phong_and_whitted_at_depth_0(&mut s, |s| render(&scene, s));
    let mask = same_surface(&raster, &traced);
    let d = diff_films(&raster, &traced, 1e-3, &mask);
    if d.over > 0 {
        dump_ppm(&raster, "phong_vs_whitted_raster");
        dump_ppm(&traced, "phong_vs_whitted_whitted");
    }
    assert!(d.compared > 64 * 64 / 3, "too few pixels compared: {d:?}");
    assert_eq!(d.over, 0, "{d:?}");
}

#[test]
fn phong_and_whitted_shadow_rays_agree_through_transparent_occluders() {
    // Over the shadow test scene: a coloured pane (two triangles) and a
    // closed transparent cube, tilted so that no face of theirs is
    // horizontal. On the horizontal surfaces both techniques call the one
    // shadow-ray query, so the shadows tinted by kt (pane) and kt^2 (cube,
    // crossed twice) are the same.
    use chiaro::scene::{Geometry, Material, Transform};
    let mut scene = scenes::shadow_test(64);
    let pane = scene.add_material(Material {
        transmit: Vec3::new(0.9, 0.5, 0.2),
        ..Material::diffuse("pane", Vec3::splat(0.1))
    });
    let glass = scene.add_material(Material {
        transmit: Vec3::new(0.3, 0.8, 0.6),
        ..Material::diffuse("glass", Vec3::splat(0.1))
    });
    let quad = scene.add_mesh(chiaro_core::geometry::primitives::plane(0.6, 1));
    let cube = scene.add_mesh(chiaro_core::geometry::primitives::cube());
    let pane_at = Transform {
        translate: Vec3::new(0.2, 2.2, 0.8),
        rotate_degrees: Vec3::new(20.0, 0.0, 10.0),
        ..Transform::default()
    };
    let part = (Geometry::Mesh(quad), pane);
    scenes::add_named(&mut scene, "pane", part, pane_at, true);
    let glass_at = Transform {
        translate: Vec3::new(-1.2, 2.6, -1.0),
        rotate_degrees: Vec3::new(30.0, 20.0, 0.0),
        scale: Vec3::splat(0.35),
        ..Transform::default()
    };
    let part = (Geometry::Mesh(cube), glass);
    scenes::add_named(&mut scene, "glass", part, glass_at, false);
    let mut s = with_technique(&scene, Technique::Phong);
    s.shadows = ShadowMethod::Ray;
    let (raster, traced) = phong_and_whitted_at_depth_0(&mut s, |s| render(&scene, s));
    s.shadows = ShadowMethod::None;
    let unshadowed = render(&scene, &s);
    // Horizontal surfaces (not the pane or the cube, which the scan
    // converter blends with what is behind them), away from the edges of
    // shadows and tints (where the two techniques' shading points differ
    // by rounding).
    let w = traced.width as usize;
    let ratio: Vec<Vec3> = (0..traced.color.len())
        .map(|i| traced.color[i] / unshadowed.color[i].max(Vec3::splat(1e-6)))
        .collect();
    let same = same_surface(&raster, &traced);
    let mask = |i: usize| {
        same(i)
            && traced.normal[i].y > 0.999
            && [i - 1, i + 1, i - w, i + w]
                .iter()
                .all(|&j| (ratio[j] - ratio[i]).abs().max_element() < 1e-3)
    };
    let tinted = (0..ratio.len())
        .filter(|&i| mask(i) && ratio[i].max_element() < 0.99 && ratio[i].min_element() > 0.01)
        .count();
    let d = diff_films(&raster, &traced, 1e-3, mask);
    if d.over > 0 {
        dump_ppm(&raster, "transparent_shadows_raster");
        dump_ppm(&traced, "transparent_shadows_whitted");
    }
    assert!(d.compared > 64 * 64 / 4, "too few pixels compared: {d:?}");
    assert!(tinted > 40, "only {tinted} pixels in a tinted shadow");
    assert_eq!(d.over, 0, "{d:?}");
}

#[test]
fn gouraud_and_phong_agree_on_flat_lit_faces_only_where_they_should() {
    // Gouraud interpolates vertex colours, Phong shades per pixel: on the
    // specular sphere they must differ, on the diffuse faceted box (one
    // normal per face, distant light) they nearly agree.
    let scene = scenes::shadow_test(64);
    let mut s = with_technique(&scene, Technique::Phong);
    let phong = render(&scene, &s);
    s.technique = Technique::Gouraud;
    let gouraud = render(&scene, &s);
    let d = diff_films(&phong, &gouraud, 0.02, |_| true);
    assert!(
        d.over > 0,
        "the specular sphere must shade differently: {d:?}"
    );
}

#[test]
fn path_tracer_at_depth_one_equals_direct_local_shading() {
    // Direct light only, inverse-square point light, no ambient: the path
    // tracer's mean per pixel equals Whitted's depth-0 shading with shadow rays.
    let mut scene = scenes::shadow_test(48);
    chiaro_testkit::scenes::drop_ambient(&mut scene);
    let mut s = scene.render.clone();
    s.samples = 64;
    let (whitted, path) = whitted_and_path_direct(&mut s, |s| render(&scene, s));
    let mask = smooth_region(&whitted);
    // Silhouettes and shadow edges inside a pixel are sampled differently
    // (stratified vs random), so their pixel means differ by the coverage
    // noise: compare only pixels away from image edges (every neighbour
    // within 10% of the pixel), relative to brightness.
    let flat = smooth_colour(&whitted, 0.1, 0.02);
    let d = diff_films_relative_to_first(&whitted, &path, 0.02, 0.05, |i| mask(i) && flat(i));
    let (compared, bad) = (d.compared, d.over);
    if bad > compared / 100 {
        dump_ppm(&whitted, "depth1_whitted");
        dump_ppm(&path, "depth1_path");
    }
    assert!(compared > 200, "{compared}");
    assert!(
        bad <= compared / 50,
        "{bad} of {compared} pixels differ by more than 2%"
    );
}

#[test]
fn every_technique_renders_the_test_scene_without_nan() {
    let scene = scenes::shadow_test(24);
    for t in chiaro::Technique::ALL {
        let mut s = scene.render.clone();
        s.technique = t;
        s.samples = 2;
        let film = render(&scene, &s);
        assert!(film.is_clean(), "{}", t.name());
        assert!(
            film.mean().max_element() > 0.01,
            "{} rendered black",
            t.name()
        );
        let _ = Vec3::ZERO;
    }
}

/// Mean colour per Cornell wall (floor, ceiling, back, left, right) over the
/// pixels whose first hit lies on that wall's plane, outside the blocks' and
/// the light's footprints, and whose four neighbours see the same wall (so
/// that no pixel straddling an edge, whose colour and depth depend on where
/// its samples fell, enters a mean).
fn wall_means(scene: &Scene, f: &Film) -> [Vec3; 5] {
    let wall_of = |x: u32, y: u32| -> Option<usize> {
        let i = f.index(x, y);
        let d = f.depth[i];
        if !d.is_finite() {
            return None;
        }
        let dir = scene
            .camera
            .ray_direction(x as f32 + 0.5, y as f32 + 0.5, f.width, f.height);
        let p = scene.camera.eye + dir * d;
        // 10 mm tolerance: depths come from sub-pixel samples.
        if p.y < 10.0 {
            Some(0)
        } else if p.y > 539.0 && !(200.0..356.0).contains(&p.x) {
            Some(1)
        } else if p.z > 549.0 {
            Some(2)
        } else if p.x > 540.0 {
            Some(3)
        } else if p.x < 10.0 {
            Some(4)
        } else {
            None
        }
    };
    let mut sum = [Vec3::ZERO; 5];
    let mut n = [0u32; 5];
    for y in 1..f.height.saturating_sub(1) {
        for x in 1..f.width.saturating_sub(1) {
            let Some(k) = wall_of(x, y) else { continue };
            let inside = [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)]
                .iter()
                .all(|&(a, b)| wall_of(a, b) == Some(k));
            if inside {
                sum[k] += f.color[f.index(x, y)];
                n[k] += 1;
            }
        }
    }
    for (k, &c) in n.iter().enumerate() {
        assert!(c >= 20, "wall {k}: only {c} interior pixels");
    }
    std::array::from_fn(|k| sum[k] / n[k] as f32)
}

#[test]
fn radiosity_matches_the_path_tracer_on_the_diffuse_cornell_box() {
    // A converged radiosity solution and a converged path tracer must agree
    // on a purely Lambertian scene: within 4% relative error per wall.
    let scene = scenes::cornell_box(40);
    let mut s = with_technique(&scene, Technique::Radiosity);
    s.samples = 1;
    s.radiosity.solver = chiaro::scene::RadiositySolver::Hierarchical;
    s.radiosity.formfactor = chiaro::scene::FormFactorMethod::Raycast;
    s.radiosity.patch_size = 40.0;
    // At the default tolerance (0.01), which also sets the BF refinement
    // threshold of the hierarchical solver.
    s.radiosity.tolerance = 0.01;
    let rad = render(&scene, &s);
    s.technique = Technique::Path;
    // Enough samples that the reference's own noise on a wall mean is well
    // under the bound (about 1 %).
    s.samples = 1024;
    s.path.max_depth = 64;
    let path = render(&scene, &s);
    let (a, b) = (wall_means(&scene, &rad), wall_means(&scene, &path));
    let names = ["floor", "ceiling", "back", "left (red)", "right (green)"];
    for k in 0..5 {
        // Relative error of the wall's colour, summed over channels (a
        // per-channel ratio would be dominated by the red wall's near-zero
        // blue, where the reference itself is noisiest).
        let rel = (a[k] - b[k]).abs().dot(Vec3::ONE) / b[k].dot(Vec3::ONE).max(1e-4);
        eprintln!(
            "{}: radiosity {} path {} ({:.1}%)",
            names[k],
            a[k],
            b[k],
            rel * 100.0
        );
        assert!(
            rel < 0.04,
            "{}: radiosity {} vs path {} ({:.1}%)",
            names[k],
            a[k],
            b[k],
            rel * 100.0
        );
    }
    // Colour bleeding: the ceiling is lit by red and green walls' light.
    assert!(a[1].x > a[1].z && b[1].x > b[1].z);
}

#[test]
fn post_filter_antialiasing_changes_only_edges() {
    // aa=post renders one sample per pixel and filters it (FXAA): inside
    // smooth regions the picture is the one-sample picture.
    let scene = scenes::shadow_test(48);
    let mut s = with_technique(&scene, Technique::Phong);
    s.samples = 1;
    let plain = render(&scene, &s);
    s.aa = chiaro::scene::AaMode::Post;
    s.samples = 16; // ignored by the post filter
    let post = render(&scene, &s);
    assert!(post.is_clean());
    let mask = smooth_region(&plain);
    let inside = diff_films(&plain, &post, 0.02, &mask);
    let all = diff_films(&plain, &post, 1e-4, |_| true);
    assert!(all.over > 0, "the filter changed nothing: {all:?}");
    assert!(inside.over * 20 <= inside.compared, "{inside:?}");
}
