//! Tests of shadows (rays, maps, volumes) and transparency in the scan
//! converter: the three shadow methods agree, no acne, camera inside a
//! shadow volume, order-independent transparency, screen-door coverage.

use super::*;
use chiaro_core::geometry::primitives;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{Camera, Geometry, Light, Object, Transform};

fn settings(shadows: ShadowMethod, w: u32, h: u32) -> RenderSettings {
    RenderSettings {
        technique: Technique::Phong,
        width: w,
        height: h,
        shadows,
        shadow_map: chiaro_core::scene::ShadowMapSettings {
            resolution: 1024,
            ..Default::default()
        },
        ..RenderSettings::default()
    }
}

fn render_with(scene: &Scene, s: &RenderSettings, counting: VolumeCounting) -> Film {
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    let f = render_prepared_with(
        &ps,
        s,
        ShadeMode::Phong,
        &RasterOptions {
            volume_counting: counting,
        },
        &NoProgress,
    )
    .expect("render");
    if let Ok(dir) = std::env::var("CHIARO_DUMP") {
        let name = format!(
            "{dir}/{:?}_{:?}_{}_{}.png",
            s.shadows, counting, scene.camera.eye.x, f.width
        );
        let img = image::RgbImage::from_fn(f.width, f.height, |x, y| {
            let c = f.color[(y * f.width + x) as usize];
            image::Rgb([c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8))
        });
        let _ = img.save(name);
    }
    f
}

/// The shared shadow test scene lit by its point light only.
fn light_only(size: u32) -> Scene {
    let mut s = chiaro_testkit::scenes::shadow_test(size);
    s.lights.retain(|l| !matches!(l, Light::Ambient { .. }));
    s
}

/// Per pixel: true where the light contributes nothing.
fn dark(f: &Film) -> Vec<bool> {
    (0..(f.width * f.height) as usize)
        .map(|i| f.color[i].max_element() < 1e-5)
        .collect()
}

/// Pixels of `reference` farther than `r` pixels from any pixel of the other class.
fn away_from_edges(reference: &[bool], w: u32, h: u32, r: i32) -> Vec<bool> {
    let mut out = vec![true; reference.len()];
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let c = reference[(y as u32 * w + x as u32) as usize];
            'n: for dy in -r..=r {
                for dx in -r..=r {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx >= 0
                        && ny >= 0
                        && nx < w as i32
                        && ny < h as i32
                        && reference[(ny as u32 * w + nx as u32) as usize] != c
                    {
                        out[(y as u32 * w + x as u32) as usize] = false;
                        break 'n;
                    }
                }
            }
        }
    }
    out
}

/// Fraction of pixels away from the reference's shadow edges where the
/// classifications differ.
fn disagreement(reference: &[bool], other: &[bool], w: u32, h: u32) -> f32 {
    let keep = away_from_edges(reference, w, h, 2);
    let n = keep.iter().filter(|&&k| k).count();
    let bad = (0..reference.len())
        .filter(|&i| keep[i] && reference[i] != other[i])
        .count();
    bad as f32 / n.max(1) as f32
}

#[test]
fn shadow_map_volume_and_rays_classify_the_same_pixels() {
    let (w, h) = (96, 72);
    let scene = light_only(64);
    let none = dark(&render_with(
        &scene,
        &settings(ShadowMethod::None, w, h),
        VolumeCounting::ZFail,
    ));
    let ray = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Ray, w, h),
        VolumeCounting::ZFail,
    ));
    let map = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Map, w, h),
        VolumeCounting::ZFail,
    ));
    let vol = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Volume, w, h),
        VolumeCounting::ZFail,
    ));
    // The scene has real cast shadows: pixels dark with rays, lit without.
    let cast = (0..none.len()).filter(|&i| ray[i] && !none[i]).count();
    assert!(cast > 150, "only {cast} shadowed pixels");
    let dm = disagreement(&ray, &map, w, h);
    let dv = disagreement(&ray, &vol, w, h);
    assert!(dm < 0.005, "shadow map disagrees with rays on {dm}");
    assert!(dv < 0.005, "shadow volumes disagree with rays on {dv}");
}

#[test]
fn object_precision_shadows_match_shadow_rays_at_every_pixel_centre() {
    // Both methods are exact: unlike shadow maps and volumes they must agree
    // at every pixel centre, edges included (up to points within float
    // epsilon of a shadow boundary).
    let (w, h) = (96, 72);
    let scene = light_only(64);
    let ray = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Ray, w, h),
        VolumeCounting::ZFail,
    ));
    let obj = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Object, w, h),
        VolumeCounting::ZFail,
    ));
    let shadowed = ray.iter().filter(|&&d| d).count();
    assert!(shadowed > 150, "only {shadowed} dark pixels");
    let differ = (0..ray.len()).filter(|&i| ray[i] != obj[i]).count();
    assert!(
        differ <= ray.len() / 500,
        "{differ} of {} pixels differ",
        ray.len()
    );
}

#[test]
fn plane_at_grazing_light_has_no_acne() {
    // A floor lit at 85 degrees from its normal by a directional light,
    // and by a spot: with shadow maps every floor pixel stays lit.
    let mut scene = Scene::default();
    let m = scene.add_material(Material::diffuse("floor", Vec3::splat(0.8)));
    let plane = scene.add_mesh(primitives::plane(2.0, 4));
    scene.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: m,
        ..Object::default()
    });
    let a = 85f32.to_radians();
    scene.lights.push(Light::Directional {
        direction: Vec3::new(a.sin(), -a.cos(), 0.2).normalize(),
        color: Vec3::ONE,
        intensity: 1.0,
    });
    scene.camera = Camera {
        eye: Vec3::new(0.0, 3.0, -3.0),
        look_at: Vec3::ZERO,
        ..Camera::default()
    };
    let (w, h) = (48, 48);
    for res in [256, 1024] {
        let mut s = settings(ShadowMethod::Map, w, h);
        s.shadow_map.resolution = res;
        let lit = render_with(&scene, &s, VolumeCounting::ZFail);
        let free = render_with(
            &scene,
            &settings(ShadowMethod::None, w, h),
            VolumeCounting::ZFail,
        );
        let covered = (0..lit.color.len()).filter(|&i| free.color[i].max_element() > 0.0);
        let mut n = 0;
        for i in covered {
            n += 1;
            let (a, b) = (lit.color[i], free.color[i]);
            assert!(
                (a - b).abs().max_element() <= 1e-4 * b.max_element().max(1.0),
                "res {res} pixel {i}: {a} vs {b}"
            );
        }
        assert!(n > 500);
    }
}

#[test]
fn camera_inside_a_shadow_volume_is_right_with_z_fail() {
    // The eye sits in the ball's shadow, just above the floor.
    let (w, h) = (48, 48);
    let mut scene = light_only(48);
    scene.camera = Camera {
        eye: Vec3::new(-0.8, 0.25, 0.65),
        look_at: Vec3::new(0.6, 0.0, 2.5),
        fov_y_degrees: 70.0,
        ..Camera::default()
    };
    let ray = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Ray, w, h),
        VolumeCounting::ZFail,
    ));
    let zfail = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Volume, w, h),
        VolumeCounting::ZFail,
    ));
    let zpass = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Volume, w, h),
        VolumeCounting::ZPass,
    ));
    let d_fail = disagreement(&ray, &zfail, w, h);
    let d_pass = disagreement(&ray, &zpass, w, h);
    assert!(d_fail < 0.005, "z-fail disagrees on {d_fail}");
    // Crow's z-pass count starts at 0 at the eye, which is wrong here.
    assert!(
        d_pass > 0.015,
        "z-pass should fail inside a volume: {d_pass}"
    );
}

/// Two unit-ambient-lit quads seen from above: `a` horizontal at y = 0 and
/// `b` tilted about the z axis, so they intersect along x = 0 (b is in
/// front for x > 0).
fn crossing_quads(mode: TransparencyMode, kt: f32) -> Scene {
    let mut scene = Scene::default();
    let mat = |name: &str, kd: Vec3| Material {
        ambient: Vec3::ONE,
        transmit: Vec3::splat(kt),
        transparency: mode,
        ..Material::diffuse(name, kd)
    };
    let red = scene.add_material(mat("red", Vec3::X));
    let blue = scene.add_material(mat("blue", Vec3::Z));
    let plane = scene.add_mesh(primitives::plane(1.0, 2));
    scene.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: red,
        ..Object::default()
    });
    scene.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: blue,
        transform: Transform {
            rotate_degrees: Vec3::new(0.0, 0.0, 20.0),
            ..Transform::default()
        },
        ..Object::default()
    });
    scene.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 1.0,
    });
    scene.camera = Camera {
        eye: Vec3::new(0.0, 5.0, 0.0),
        look_at: Vec3::ZERO,
        up: Vec3::Z,
        fov_y_degrees: 20.0,
        ..Camera::default()
    };
    scene
}

#[test]
fn intersecting_transparent_quads_blend_in_order_on_both_sides() {
    let (w, h) = (32, 32);
    for mode in [TransparencyMode::Interpolated, TransparencyMode::Filtered] {
        let scene = crossing_quads(mode, 0.5);
        let f = render_with(
            &scene,
            &settings(ShadowMethod::None, w, h),
            VolumeCounting::ZFail,
        );
        // Screen x grows towards world -x (camera looking down -y with up +z).
        let left = f.color[(16 * w + 6) as usize]; // world x > 0: blue in front
        let right = f.color[(16 * w + 25) as usize]; // world x < 0: red in front
        let (front, back) = match mode {
            // (1 - kt) I_front + kt ((1 - kt) I_back + kt * 0)
            TransparencyMode::Interpolated => (0.5, 0.25),
            // I_front + kt (I_back + kt * 0)
            _ => (1.0, 0.5),
        };
        let ok = |c: Vec3, e: Vec3| (c - e).abs().max_element() < 1e-3;
        assert!(
            ok(left, Vec3::new(back, 0.0, front)),
            "{mode:?} left {left}"
        );
        assert!(
            ok(right, Vec3::new(front, 0.0, back)),
            "{mode:?} right {right}"
        );
    }
}

#[test]
fn screen_door_coverage_equals_one_minus_kt() {
    let (w, h) = (64, 64);
    for kt in [0.25f32, 0.6] {
        let mut scene = crossing_quads(TransparencyMode::ScreenDoor, kt);
        scene.objects.truncate(1);
        scene.camera.fov_y_degrees = 10.0; // the quad fills the image
        let f = render_with(
            &scene,
            &settings(ShadowMethod::None, w, h),
            VolumeCounting::ZFail,
        );
        let shown = f.color.iter().filter(|c| c.x > 0.5).count();
        let frac = shown as f32 / (w * h) as f32;
        assert!((frac - (1.0 - kt)).abs() < 0.01, "kt {kt}: coverage {frac}");
    }
}

#[test]
fn transparent_casters_tint_shadow_maps_and_rays_alike() {
    // A blue-filtering quad between a point light and the floor.
    let mut scene = Scene::default();
    let floor = scene.add_material(Material::diffuse("floor", Vec3::splat(0.8)));
    let glass = scene.add_material(Material {
        transmit: Vec3::new(0.2, 0.4, 0.9),
        two_sided: true,
        ..Material::diffuse("glass", Vec3::ZERO)
    });
    let plane = scene.add_mesh(primitives::plane(2.0, 2));
    let small = scene.add_mesh(primitives::plane(0.5, 1));
    scene.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: floor,
        ..Object::default()
    });
    scene.objects.push(Object {
        geometry: Geometry::Mesh(small),
        material: glass,
        transform: Transform {
            translate: Vec3::new(0.0, 1.0, 0.0),
            ..Transform::default()
        },
        ..Object::default()
    });
    scene.lights.push(Light::Point {
        position: Vec3::new(0.0, 3.0, 0.0),
        color: Vec3::ONE,
        intensity: 5.0,
        attenuation: chiaro_core::scene::Attenuation::InverseSquare,
    });
    scene.camera = Camera {
        eye: Vec3::new(0.0, 6.0, -0.01),
        look_at: Vec3::ZERO,
        fov_y_degrees: 20.0,
        ..Camera::default()
    };
    let (w, h) = (32, 32);
    let mut s_none = settings(ShadowMethod::None, w, h);
    s_none.transparency = Some(TransparencyMode::ScreenDoor);
    let none = render_with(&scene, &s_none, VolumeCounting::ZFail);
    let centre = (16 * w + 16) as usize;
    for method in [ShadowMethod::Ray, ShadowMethod::Map] {
        let mut s = settings(method, w, h);
        s.transparency = Some(TransparencyMode::ScreenDoor);
        // Screen-door with kt ~ 0.5: look at a sample where the floor shows.
        let f = render_with(&scene, &s, VolumeCounting::ZFail);
        let i = (0..f.color.len())
            .filter(|&i| (i as i64 - centre as i64).abs() < 3)
            .find(|&i| f.normal[i].y > 0.5 && f.depth[i] > 5.5)
            .unwrap_or(centre);
        let ratio = f.color[i] / none.color[i];
        assert!(
            (ratio - Vec3::new(0.2, 0.4, 0.9)).abs().max_element() < 0.02,
            "{method:?}: {ratio}"
        );
    }
}

#[test]
fn scanline_shadows_render_like_shadow_rays() {
    // Scan-line shadows in the renderer: exact at pixel centres, so they
    // classify like shadow rays (and like object precision).
    let (w, h) = (96, 72);
    let scene = light_only(64);
    let ray = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Ray, w, h),
        VolumeCounting::ZFail,
    ));
    let line = dark(&render_with(
        &scene,
        &settings(ShadowMethod::Scanline, w, h),
        VolumeCounting::ZFail,
    ));
    let differ = (0..ray.len()).filter(|&i| ray[i] != line[i]).count();
    assert!(
        differ <= ray.len() / 500,
        "{differ} of {} pixels differ",
        ray.len()
    );
    let _ = CoreError::Cancelled;
}
