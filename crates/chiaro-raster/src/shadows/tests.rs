//! Tests of shadows (rays, maps, volumes) and transparency in the scan
//! converter: the three shadow methods agree, no acne, camera inside a
//! shadow volume, order-independent transparency, screen-door coverage.

use super::*;
use crate::pipeline::*;
use crate::shadows::maps::*;
use crate::shadows::volumes::*;
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_core::geometry::primitives;
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{Camera, Geometry, Light, Object, Transform};
use chiaro_core::scene::{Material, RenderSettings, Scene, ShadeMode, Technique, TransparencyMode};
use chiaro_core::scene::{ShadowMethod, Sidedness};
use chiaro_testkit::Warnings;
use chiaro_testkit::scenes::{add_named, camera, point_light, translate};
use glam::{Vec2, Vec3};

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
    chiaro_testkit::scenes::drop_ambient(&mut s);
    s
}

/// A light-grey diffuse floor: the 2 x 2 plane `y = 0` in 4 x 4 cells,
/// without lights.
fn floor() -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_material(Material::diffuse("floor", Vec3::splat(0.8)));
    let plane = scene.add_mesh(primitives::plane(2.0, 4));
    scene.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: m,
        ..Object::default()
    });
    scene
}

/// Per pixel: true where the light contributes nothing.
fn dark(f: &Film) -> Vec<bool> {
    (0..(f.width * f.height) as usize)
        .map(|i| f.color[i].max_element() < 1e-5)
        .collect()
}

/// [`render_with`] a `w` x `h` frame with [`settings`] for `method` (z-fail
/// counting for volumes).
fn render_plain(scene: &Scene, method: ShadowMethod, w: u32, h: u32) -> Film {
    render_with(scene, &settings(method, w, h), VolumeCounting::ZFail)
}

/// [`dark`] of [`render_plain`].
fn dark_with(scene: &Scene, method: ShadowMethod, w: u32, h: u32) -> Vec<bool> {
    dark(&render_plain(scene, method, w, h))
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
    let none = dark_with(&scene, ShadowMethod::None, w, h);
    let ray = dark_with(&scene, ShadowMethod::Ray, w, h);
    let map = dark_with(&scene, ShadowMethod::Map, w, h);
    let vol = dark_with(&scene, ShadowMethod::Volume, w, h);
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
    let ray = assert_classifies_like_rays(ShadowMethod::Object);
    let shadowed = ray.iter().filter(|&&d| d).count();
    assert!(shadowed > 150, "only {shadowed} dark pixels");
}

/// Asserts that `method` leaves the same pixels of the light-only shadow
/// test dark as shadow rays, but for at most one in 500; returns the
/// rays' dark pixels.
fn assert_classifies_like_rays(method: ShadowMethod) -> Vec<bool> {
    let (w, h) = (96, 72);
    let scene = light_only(64);
    let ray = dark_with(&scene, ShadowMethod::Ray, w, h);
    let other = dark_with(&scene, method, w, h);
    let differ = (0..ray.len()).filter(|&i| ray[i] != other[i]).count();
    assert!(
        differ <= ray.len() / 500,
        "{differ} of {} pixels differ",
        ray.len()
    );
    ray
}

#[test]
fn plane_at_grazing_light_has_no_acne() {
    // A floor lit at 85 degrees from its normal by a directional light,
    // and by a spot: with shadow maps every floor pixel stays lit.
    let mut scene = floor();
    let a = 85f32.to_radians();
    scene.lights.push(Light::Directional {
        direction: Vec3::new(a.sin(), -a.cos(), 0.2).normalize(),
        color: Vec3::ONE,
        intensity: 1.0,
    });
    scene.camera = camera(Vec3::new(0.0, 3.0, -3.0), Vec3::ZERO, 45.0);
    let (w, h) = (48, 48);
    for res in [256, 1024] {
        let mut s = settings(ShadowMethod::Map, w, h);
        s.shadow_map.resolution = res;
        let lit = render_with(&scene, &s, VolumeCounting::ZFail);
        let free = render_plain(&scene, ShadowMethod::None, w, h);
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
    scene.camera = camera(Vec3::new(-0.8, 0.25, 0.65), Vec3::new(0.6, 0.0, 2.5), 70.0);
    let ray = dark_with(&scene, ShadowMethod::Ray, w, h);
    let zfail = dark_with(&scene, ShadowMethod::Volume, w, h);
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
    let tilted = Transform {
        rotate_degrees: Vec3::new(0.0, 0.0, 20.0),
        ..Transform::default()
    };
    let part = (Geometry::Mesh(plane), red);
    add_named(&mut scene, "", part, Transform::default(), true);
    add_named(&mut scene, "", (Geometry::Mesh(plane), blue), tilted, true);
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
        let f = render_plain(&scene, ShadowMethod::None, w, h);
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
        let f = render_plain(&scene, ShadowMethod::None, w, h);
        let shown = f.color.iter().filter(|c| c.x > 0.5).count();
        let frac = shown as f32 / (w * h) as f32;
        assert!((frac - (1.0 - kt)).abs() < 0.01, "kt {kt}: coverage {frac}");
    }
}

#[test]
fn transparent_casters_tint_alike_in_every_shadow_method() {
    // A blue-filtering quad between a point light and the floor: every
    // method tints by its transmit colour (the exact methods through shadow
    // rays that see only transparent casters).
    let mut scene = Scene::default();
    let floor = scene.add_material(Material::diffuse("floor", Vec3::splat(0.8)));
    let glass = scene.add_material(Material {
        transmit: Vec3::new(0.2, 0.4, 0.9),
        sidedness: Sidedness::TwoSided,
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
    scene
        .lights
        .push(point_light(Vec3::new(0.0, 3.0, 0.0), 5.0));
    scene.camera = camera(Vec3::new(0.0, 6.0, -0.01), Vec3::ZERO, 20.0);
    let (w, h) = (32, 32);
    let mut s_none = settings(ShadowMethod::None, w, h);
    s_none.transparency = Some(TransparencyMode::ScreenDoor);
    let none = render_with(&scene, &s_none, VolumeCounting::ZFail);
    let centre = (16 * w + 16) as usize;
    for method in [
        ShadowMethod::Ray,
        ShadowMethod::Map,
        ShadowMethod::Volume,
        ShadowMethod::Object,
        ShadowMethod::Scanline,
    ] {
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
    assert_classifies_like_rays(ShadowMethod::Scanline);
    let _ = CoreError::Cancelled;
}

/// The shipped Cornell box without the ambient light.
fn cornell_box() -> Scene {
    let mut scene = chiaro_testkit::scenes::cornell_box(64);
    chiaro_testkit::scenes::drop_ambient(&mut scene);
    scene
}

/// Area lights replaced by point lights at their centres, so that shadow
/// rays see the hard shadow of the centre that shadow volumes cast.
fn area_lights_at_centres(ps: &mut PreparedScene<'_>) {
    for l in &mut ps.lights {
        if let Light::Area { shape, .. } = l {
            *l = point_light(shape.center(), 1e5);
        }
    }
}

/// Per light of `ps` (each alone), the dark pixels of a `method` render.
fn dark_per_light(
    ps: &mut PreparedScene<'_>,
    method: ShadowMethod,
    w: u32,
    h: u32,
) -> Vec<Vec<bool>> {
    let mut s = settings(method, w, h);
    s.samples = 1;
    let all = std::mem::take(&mut ps.lights);
    let out = all
        .iter()
        .map(|l| {
            ps.lights = vec![l.clone()];
            let f = render_prepared(ps, &s, ShadeMode::Phong, &NoProgress).expect("render");
            dark(&f)
        })
        .collect();
    ps.lights = all;
    out
}

/// Pixels whose 3x3 neighbourhood is all of one class in `mask`.
fn interior(mask: &[bool], w: u32, h: u32) -> Vec<bool> {
    away_from_edges(mask, w, h, 1)
}

/// Shadow volumes against shadow rays to the same point lights: per
/// light, the dark pixels agree except on the rays' shadow silhouettes
/// (pixels whose 3x3 neighbourhood is not all lit or all dark). Returns
/// the number of pixels compared and shadowed.
fn assert_volumes_match_rays(ps: &mut PreparedScene<'_>, w: u32, h: u32) -> (usize, usize) {
    let rays = dark_per_light(ps, ShadowMethod::Ray, w, h);
    let vols = dark_per_light(ps, ShadowMethod::Volume, w, h);
    let (mut n, mut shadowed) = (0, 0);
    for (li, (r, v)) in rays.iter().zip(&vols).enumerate() {
        let keep = interior(r, w, h);
        for i in 0..r.len() {
            if !keep[i] {
                continue;
            }
            n += 1;
            shadowed += usize::from(r[i]);
            assert_eq!(
                r[i],
                v[i],
                "light {li}: pixel ({}, {}) dark with rays {} with volumes {}",
                i as u32 % w,
                i as u32 / w,
                r[i],
                v[i]
            );
        }
    }
    (n, shadowed)
}

#[test]
fn cornell_box_volumes_match_rays_to_the_light_centres() {
    // The emissive quad's two triangle lights have their centres in the
    // quad's own plane: edge-on triangles must cast no volume (they used to
    // shadow the whole upper half of the image).
    let scene = cornell_box();
    let mut ps = PreparedScene::new(&scene, PrepareOptions::default());
    assert_eq!(ps.lights.len(), 2);
    area_lights_at_centres(&mut ps);
    let (n, shadowed) = assert_volumes_match_rays(&mut ps, 64, 64);
    assert!(
        n > 2 * 64 * 64 * 7 / 10,
        "only {n} pixels away from silhouettes"
    );
    assert!(shadowed > 300, "only {shadowed} shadowed pixels");
}

/// A floor, an open shelf quad at height 1 and a closed box whose top face
/// is at height 1, lit by a quad light whose centre lies in the plane
/// `y = 1` of both; the box casts a shadow on the floor.
fn light_in_a_polygon_plane() -> Scene {
    let mut scene = Scene::default();
    let grey = scene.add_material(Material::diffuse("grey", Vec3::splat(0.7)));
    let floor = scene.add_mesh(primitives::plane(4.0, 4));
    let shelf = scene.add_mesh(primitives::plane(1.0, 1));
    let cube = scene.add_mesh(primitives::cube());
    let no_move = Transform::default();
    let part = (Geometry::Mesh(floor), grey);
    add_named(&mut scene, "floor", part, no_move, true);
    let shelf_at = translate(Vec3::new(-2.0, 1.0, 1.0));
    let part = (Geometry::Mesh(shelf), grey);
    add_named(&mut scene, "shelf", part, shelf_at, true);
    let box_at = Transform {
        translate: Vec3::new(0.5, 0.5, 0.0),
        scale: Vec3::splat(0.5),
        ..Transform::default()
    };
    let part = (Geometry::Mesh(cube), grey);
    add_named(&mut scene, "box", part, box_at, false);
    // A 0.4 x 0.4 quad light in the plane y = 1, centre (2, 1, 0).
    scene.lights.push(Light::Area {
        shape: chiaro_core::scene::AreaShape::Quad {
            corner: Vec3::new(1.8, 1.0, -0.2),
            edge_u: Vec3::new(0.0, 0.0, 0.4),
            edge_v: Vec3::new(0.4, 0.0, 0.0),
        },
        color: Vec3::ONE,
        intensity: 20.0,
        two_sided: true,
    });
    scene.camera = camera(Vec3::new(0.0, 5.0, -6.0), Vec3::new(0.0, 0.0, 0.5), 45.0);
    scene
}

#[test]
fn a_light_in_the_plane_of_polygons_gets_the_shadow_rays_shadow() {
    let scene = light_in_a_polygon_plane();
    let mut ps = PreparedScene::new(&scene, PrepareOptions::default());
    area_lights_at_centres(&mut ps);
    let (n, shadowed) = assert_volumes_match_rays(&mut ps, 64, 48);
    assert!(
        n > 64 * 48 * 8 / 10,
        "only {n} pixels away from silhouettes"
    );
    assert!(shadowed > 100, "only {shadowed} shadowed pixels");
    // The quad light itself: volumes cast its centre's shadow, as the exact
    // object-precision method does.
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let (w, h) = (64, 48);
    let render = |m| {
        dark(
            &render_prepared(&ps, &settings(m, w, h), ShadeMode::Phong, &NoProgress)
                .expect("render"),
        )
    };
    let (obj, vol) = (render(ShadowMethod::Object), render(ShadowMethod::Volume));
    let keep = interior(&obj, w, h);
    let differ = (0..obj.len())
        .filter(|&i| keep[i] && obj[i] != vol[i])
        .count();
    assert_eq!(
        differ, 0,
        "volumes and object precision differ on {differ} pixels"
    );
    assert!(obj.iter().filter(|&&d| d).count() > 100);
}

#[test]
fn open_occluders_are_named_in_a_warning_and_still_shadow() {
    // The shelf (an open quad) over the floor under a point light: it gets
    // per-triangle volumes, a warning names it, and the shadow is right.
    let mut scene = light_in_a_polygon_plane();
    scene.lights = vec![point_light(Vec3::new(-2.0, 3.0, 1.0), 10.0)];
    let mut ps = PreparedScene::new(&scene, PrepareOptions::default());
    let (n, shadowed) = assert_volumes_match_rays(&mut ps, 64, 48);
    assert!(n > 64 * 48 * 8 / 10 && shadowed > 100, "{n} {shadowed}");
    let warnings = Warnings::default();
    let s = settings(ShadowMethod::Volume, 16, 12);
    render_prepared(&ps, &s, ShadeMode::Phong, &warnings).expect("render");
    let w = warnings.into_vec();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("\"shelf\"") && w[0].contains("\"floor\""),
        "{}",
        w[0]
    );
    assert!(!w[0].contains("\"box\""), "the box is closed: {}", w[0]);
}

/// `count` point lights in a row over the shadow test scene.
fn many_point_lights(count: usize) -> Scene {
    let mut scene = light_only(32);
    scene.lights = (0..count)
        .map(|i| {
            point_light(
                Vec3::new(-2.0 + 4.0 * i as f32 / count as f32, 4.0, -1.0),
                10.0 / count as f32,
            )
        })
        .collect();
    scene
}

#[test]
fn shadow_maps_stay_within_their_budget() {
    use crate::shadows::maps::ShadowMaps;
    // A 2 GiB job's shadow-map share: 512 MiB.
    let share = chiaro_core::budget::MemoryBudget::new(2 << 30).shadow_map_bytes();
    // The case, planned without allocating: 40 point lights at the
    // default 2048 texels, a cube of 6 x 2048^2 f32 each (96 MiB): five fit
    // in 512 MiB, the other 35 use shadow rays.
    let cube = 6 * 2048 * 2048 * 4u64;
    let (by_ray, bytes) = crate::shadows::plan_budget(&vec![Some(cube); 40], share);
    assert!(bytes <= share);
    assert_eq!(by_ray.iter().filter(|&&r| !r).count(), 5);
    assert!(by_ray[5..].iter().all(|&r| r));
    // Built for real with a small budget: the maps kept stay within it, a
    // warning names the others, and those see the shadow rays' shadows.
    let scene = many_point_lights(40);
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let sm = chiaro_core::scene::ShadowMapSettings {
        resolution: 128,
        ..Default::default()
    };
    let budget = 4 << 20;
    let maps = ShadowMaps::new(&ps, &sm, 1, budget);
    let per_light = 6 * 128 * 128 * 4;
    assert_eq!(maps.bytes, (budget / per_light) * per_light);
    let warning = maps.warning.as_deref().expect("a warning");
    assert!(
        warning.contains("lights 10, 11,") && warning.contains("39 use shadow rays"),
        "{warning}"
    );
    let rays = crate::shadows::rays::RayShadows::new(&ps);
    let p = Vec3::new(-0.9, 0.0, 1.5);
    let ng = Vec3::Y;
    let (mut lit, mut dark) = (0, 0);
    for li in 10..40 {
        let s = chiaro_core::shading::sample_light(&ps.lights[li], p, Vec2::splat(0.5));
        let Some(s) = s else { continue };
        let v = maps.visibility(li, 0, 1, p, ng, &s);
        assert_eq!(v, rays.visibility(p, ng, &s), "light {li}");
        lit += usize::from(v == Vec3::ONE);
        dark += usize::from(v == Vec3::ZERO);
    }
    assert!(lit > 0 && dark > 0, "lit {lit} dark {dark}");
    // A whole render with the default budget and settings finishes.
    let s = settings(ShadowMethod::Map, 32, 24);
    let f = render_prepared(&ps, &s, ShadeMode::Phong, &NoProgress).expect("render");
    assert!(f.color.iter().all(|c| c.is_finite()));
}

/// Shadow-volume triangles of `scene`, all lights.
fn volume_triangles(scene: &Scene) -> usize {
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    let lights = vec![true; ps.lights.len()];
    ShadowVolumes::new(&ps, &lights)
        .per_light(&ps)
        .iter()
        .map(Vec::len)
        .sum()
}

#[test]
fn a_floor_under_everything_casts_no_volume_a_raised_one_does() {
    let scene = light_only(64);
    let floor = scene
        .objects
        .iter()
        .position(|o| o.name == "floor")
        .expect("the test scene has a floor");
    let mut without = scene.clone();
    without.objects.remove(floor);
    assert_eq!(volume_triangles(&scene), volume_triangles(&without));
    // Raised through the ball and the box: parts of them are behind it.
    let mut raised = scene.clone();
    raised.objects[floor].transform.translate.y += 0.3;
    assert!(volume_triangles(&raised) > volume_triangles(&without));
    // (Pictures with such floors still match shadow rays: the
    // `assert_volumes_match_rays` tests above.)
}

/// A sample the rasterizer gives to a triangle may lie a little outside it
/// (snapped edges; on spotlights.toml 2.4e-4 across a floor edge): the
/// object-precision lookup shades it as the triangle's nearest point, so an
/// unshadowed floor stays lit there (before, such samples fell outside every
/// lit fragment and showed isolated shadowed pixels).
#[test]
fn object_precision_lookup_just_outside_a_triangle_is_lit() {
    let mut scene = floor();
    scene.lights.push(Light::Point {
        position: Vec3::new(0.3, 2.0, 0.2),
        color: Vec3::ONE,
        intensity: 1.0,
        attenuation: Default::default(),
    });
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let o = crate::shadows::object_precision::ObjectShadows::build(&ps, 0).expect("builds");
    for (t, tri) in ps.triangles.iter().enumerate() {
        let v = tri.map(|i| ps.positions[i as usize]);
        let centre = (v[0] + v[1] + v[2]) / 3.0;
        for k in 0..3 {
            // The middle of edge k, pushed 2.4e-4 away from the centre.
            let mid = (v[k] + v[(k + 1) % 3]) * 0.5;
            let p = mid + (mid - centre).normalize() * 2.4e-4;
            assert_eq!(o.lit_fraction(t as u32, p), 1.0, "triangle {t} edge {k}");
        }
    }
}

#[test]
fn shadow_volumes_past_their_budget_use_rays_with_a_warning() {
    // 8 point lights over the shadow test scene with a 2 MiB memory limit
    // (a 512 KiB shadow share, under 1 MiB of binned volumes a light): the
    // first lights' volumes fit, the others use shadow rays, a warning names
    // them, and the image is the rays'.
    let scene = many_point_lights(8);
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let mut s = settings(ShadowMethod::Volume, 64, 48);
    s.memory_limit = Some(chiaro_core::budget::ByteSize(2 << 20));
    let warnings = Warnings::default();
    let vol = render_prepared(&ps, &s, ShadeMode::Phong, &warnings).expect("render");
    let w = warnings.into_vec();
    let over: Vec<&String> = w.iter().filter(|w| w.contains("do not fit")).collect();
    assert_eq!(over.len(), 1, "{w:?}");
    assert!(over[0].contains("use shadow rays"), "{}", over[0]);
    // Not every light was refused: some volumes were counted.
    assert!(
        !over[0].contains("light 0") && !over[0].contains("lights 0,"),
        "{}",
        over[0]
    );
    s.shadows = ShadowMethod::Ray;
    let rays = render_prepared(&ps, &s, ShadeMode::Phong, &NoProgress).expect("render");
    let differ = (0..vol.color.len())
        .filter(|&i| (vol.color[i] - rays.color[i]).abs().max_element() > 1e-3)
        .count();
    assert!(differ <= vol.color.len() / 100, "{differ} pixels differ");
}

#[test]
fn an_emitter_group_gets_shadow_rays_under_every_exact_method() {
    // An emissive 12 x 12 grid of quads (triangle lights grouped at one
    // sample each) over the shadow test scene: every exact method
    // builds nothing for the group, says so once, and matches the rays.
    let mut scene = light_only(32);
    let glow = scene.add_material(chiaro_core::scene::Material {
        emission: Vec3::splat(4.0),
        ..chiaro_core::scene::Material::diffuse("glow", Vec3::ZERO)
    });
    let grid = scene.add_mesh(primitives::plane(1.0, 12));
    scene.objects.push(Object {
        name: "glow".into(),
        geometry: Geometry::Mesh(grid),
        material: glow,
        // Facing down, over the scene.
        transform: Transform {
            translate: Vec3::new(0.0, 3.0, 0.0),
            rotate_degrees: Vec3::new(180.0, 0.0, 0.0),
            ..Transform::default()
        },
        ..Object::default()
    });
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let mut s = settings(ShadowMethod::Ray, 48, 36);
    s.light_samples = 1;
    let group = chiaro_core::shading::EmitterGroup::of_scene(&ps, 1).expect("a group");
    let named = format!("{} emissive triangles", group.range.len());
    assert!(group.range.len() > 64, "{named}");
    let rays = render_prepared(&ps, &s, ShadeMode::Phong, &NoProgress).expect("render");
    for method in [
        ShadowMethod::Volume,
        ShadowMethod::Object,
        ShadowMethod::Scanline,
        ShadowMethod::Map,
    ] {
        s.shadows = method;
        let warnings = Warnings::default();
        let f = render_prepared(&ps, &s, ShadeMode::Phong, &warnings).expect("render");
        let w = warnings.into_vec();
        assert_eq!(
            w.iter().filter(|w| w.contains(&named)).count(),
            1,
            "{method:?}: {w:?}"
        );
        if method != ShadowMethod::Map {
            let d = (0..f.color.len())
                .map(|i| (f.color[i] - rays.color[i]).abs().max_element())
                .fold(0.0f32, f32::max);
            assert!(d < 1e-3, "{method:?}: {d}");
        }
    }
}

// Tests of the shadow-map views and of the exact methods' shadow-ray fallback.

#[test]
fn cube_faces_cover_their_directions() {
    let views = cube_views(Vec3::ZERO, 16);
    for d in [
        Vec3::new(1.0, 0.3, -0.2),
        Vec3::new(-0.2, -1.0, 0.5),
        Vec3::new(0.1, 0.2, -0.9),
    ] {
        let v = &views[cube_face(d)];
        let c = v.clip_from_world * d.extend(1.0);
        assert!(c.w > 0.0);
        assert!(
            (c.x / c.w).abs() <= 1.0 && (c.y / c.w).abs() <= 1.0,
            "{d} {c}"
        );
    }
}

/// The shadow-ray fallback of one-sample scan-line renders classifies
/// points exactly as the object-precision fragments it replaces: on
/// random points of every triangle of the shadow test scene they agree
/// except within a hair of a fragment boundary, and both lit and
/// shadowed points occur.
#[test]
fn ray_fallback_classifies_points_like_the_fragments() {
    use chiaro_core::prepared::PrepareOptions;
    use chiaro_core::sampling::{pixel_rng, uniform2};
    let scene = chiaro_testkit::scenes::shadow_test(64);
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let one = RenderSettings {
        technique: chiaro_core::scene::Technique::Phong,
        samples: 1,
        ..RenderSettings::default()
    };
    let four = RenderSettings {
        samples: 4,
        ..one.clone()
    };
    let rays = scanline_fallbacks(&ps, &one).expect("ray fallback");
    let frags = scanline_fallbacks(&ps, &four).expect("fragments");
    let (mut agree, mut total, mut lit, mut dark) = (0u32, 0u32, 0u32, 0u32);
    for (r, f) in rays.iter().zip(&frags) {
        let (Some(r), Some(f)) = (r, f) else { continue };
        assert!(matches!(r, ExactFallback::Ray { .. }));
        assert!(matches!(f, ExactFallback::Fragments(_)));
        for t in 0..ps.triangles.len() as u32 {
            let [a, b, c] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
            for k in 0..32 {
                let mut rng = pixel_rng(7, t, k, 0);
                let u = uniform2(&mut rng);
                let (u, v) = if u.x + u.y > 1.0 {
                    (1.0 - u.x, 1.0 - u.y)
                } else {
                    (u.x, u.y)
                };
                let p = a + (b - a) * u + (c - a) * v;
                let (x, y) = (r.lit_fraction(t, p), f.lit_fraction(t, p));
                total += 1;
                agree += (x == y) as u32;
                lit += (y == 1.0) as u32;
                dark += (y == 0.0) as u32;
            }
        }
    }
    assert!(
        lit > total / 10 && dark > total / 20,
        "lit {lit} dark {dark} of {total}"
    );
    assert!(
        total - agree <= total / 500,
        "{} of {total} points classified differently",
        total - agree
    );
}

/// Under an orthographic camera (whose points at infinity have no screen
/// position, so volumes are extruded to a finite reach) the shadow map,
/// the volumes and the exact methods classify the pixels as rays do.
#[test]
fn shadow_methods_agree_under_an_orthographic_camera() {
    let (w, h) = (96, 72);
    let mut scene = light_only(64);
    scene.camera.projection = chiaro_core::scene::Projection::Orthographic { half_height: 2.0 };
    let none = dark_with(&scene, ShadowMethod::None, w, h);
    let ray = dark_with(&scene, ShadowMethod::Ray, w, h);
    let cast = (0..none.len()).filter(|&i| ray[i] && !none[i]).count();
    assert!(cast > 150, "only {cast} shadowed pixels");
    for method in [
        ShadowMethod::Map,
        ShadowMethod::Volume,
        ShadowMethod::Object,
        ShadowMethod::Scanline,
    ] {
        let d = disagreement(&ray, &dark_with(&scene, method, w, h), w, h);
        assert!(d < 0.005, "{method:?} disagrees with rays on {d}");
    }
}
