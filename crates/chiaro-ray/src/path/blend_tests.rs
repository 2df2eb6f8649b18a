//! Shadow rays through glTF BLEND surfaces: next-event estimation lets
//! `1 - alpha` through each crossing (`ShadowCasters::transmittance`), and
//! BSDF sampling passes the surface without breaking the MIS pairing.

use super::*;
use chiaro_core::accel::Accelerator;
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{AlphaMode, Geometry, Material, Mesh, Scene, Transform};
use chiaro_testkit::scenes::{self, add_object, camera};

fn bvh(p: &PreparedScene<'_>) -> Box<dyn Accelerator> {
    Box::new(SceneBvh::new(p))
}

/// The square `|x|, |z| <= half` at height `y`, facing up or down.
fn square(s: &mut Scene, half: f32, y: f32, up: bool, material: &str, m: Material) {
    let mat = s.add_material(m);
    let h = half;
    let mut indices = vec![[0, 1, 2], [0, 2, 3]];
    if up {
        indices = vec![[0, 2, 1], [0, 3, 2]];
    }
    let mesh = s.add_mesh(Mesh {
        name: material.into(),
        positions: vec![
            Vec3::new(-h, y, -h),
            Vec3::new(h, y, -h),
            Vec3::new(h, y, h),
            Vec3::new(-h, y, h),
        ],
        indices,
        ..Mesh::default()
    });
    add_object(s, Geometry::Mesh(mesh), mat, Transform::default());
}

/// A white Lambertian floor (`kd` 0.5) at `y = 0`, lit from above by an
/// emissive square (radiance 40, half-width 0.25, at `y = 2`, facing down)
/// or by a point light of intensity 8 at `(0, 2, 0)`; with `decal`, a white
/// BLEND square of alpha 0.25 at `y = 1` covers the light as seen from the
/// floor the camera sees (the camera sits between it and the floor,
/// looking down).
fn decal_scene(decal: bool, point_light: bool) -> Scene {
    let mut s = Scene::default();
    square(
        &mut s,
        4.0,
        0.0,
        true,
        "floor",
        Material::diffuse("floor", Vec3::splat(0.5)),
    );
    if decal {
        let m = Material {
            alpha: 0.25,
            alpha_mode: AlphaMode::Blend,
            ..Material::diffuse("decal", Vec3::ONE)
        };
        square(&mut s, 2.0, 1.0, true, "decal", m);
    }
    if point_light {
        s.lights
            .push(scenes::point_light(Vec3::new(0.0, 2.0, 0.0), 8.0));
    } else {
        let m = Material {
            emission: Vec3::splat(40.0),
            ..Material::diffuse("light", Vec3::ZERO)
        };
        square(&mut s, 0.25, 2.0, false, "light", m);
    }
    s.camera = camera(Vec3::new(0.0, 0.5, 0.001), Vec3::ZERO, 20.0);
    s.render.width = 16;
    s.render.height = 16;
    s.render.samples = 64;
    s.render.path.max_depth = 2;
    s.render.path.rr_depth = 8;
    s
}

fn render(s: &Scene, kernel: Kernel) -> Film {
    let (film, _) = render_with_kernel(s, &s.render, &NoProgress, &bvh, kernel).expect("renders");
    assert!(film.is_clean(), "{kernel:?}: NaN or negative pixels");
    film
}

/// Mean and standard error over the pixels of `with - 0.75 * without`
/// (red channel): each pixel's difference is an independent estimate of
/// zero when the BLEND decal lets exactly `1 - alpha` through.
fn transmitted_difference(with: &Film, without: &Film) -> (f32, f32, f32) {
    let d: Vec<f32> = with
        .color
        .iter()
        .zip(&without.color)
        .map(|(a, b)| a.x - 0.75 * b.x)
        .collect();
    let n = d.len() as f32;
    let mean = d.iter().sum::<f32>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / (n - 1.0);
    let level = without.color.iter().map(|c| c.x).sum::<f32>() / n;
    (mean, (var / n).sqrt(), level)
}

#[test]
fn a_point_light_through_a_blend_decal_is_three_quarters_at_depth_one() {
    // Depth 1: L = kd Ip cos / d^2 = 0.5 * 8 / 4 = 1 without the decal,
    // 0.75 through it. A delta light and one light: no noise but the
    // camera jitter's over a floor lit almost uniformly.
    for kernel in [Kernel::Lanes, Kernel::Scalar, Kernel::Reference] {
        let mut with = decal_scene(true, true);
        with.render.path.max_depth = 1;
        let mut without = decal_scene(false, true);
        without.render.path.max_depth = 1;
        let (a, b) = (render(&with, kernel), render(&without, kernel));
        for (pa, pb) in a.color.iter().zip(&b.color) {
            assert!((pb.x - 1.0).abs() < 0.01, "{kernel:?}: unshadowed {pb}");
            assert!(
                (pa.x - 0.75 * pb.x).abs() <= 1e-5 * pb.x,
                "{kernel:?}: {} vs 0.75 x {}",
                pa.x,
                pb.x
            );
        }
    }
}

#[test]
fn an_area_light_through_a_blend_decal_is_three_quarters_with_mis() {
    // Depth 2 with an emissive-triangle light: next-event estimation (its
    // shadow ray through the decal) and BSDF sampling (passing the decal
    // with probability 1 - alpha) both reach the light, MIS-weighted. The
    // floor's radiance through the decal is 0.75 of what it is without it:
    // the per-pixel difference `with - 0.75 without` must be zero within
    // four standard errors (measured across the 256 pixels). Counting the
    // pass as a bounce, or resetting the MIS state there, biases it.
    for kernel in [Kernel::Lanes, Kernel::Scalar, Kernel::Reference] {
        let with = render(&decal_scene(true, false), kernel);
        let without = render(&decal_scene(false, false), kernel);
        let (mean, se, level) = transmitted_difference(&with, &without);
        assert!(level > 0.1, "{kernel:?}: the floor is lit ({level})");
        assert!(
            mean.abs() <= 4.0 * se + 1e-4 * level,
            "{kernel:?}: with - 0.75 without = {mean} (standard error {se}, level {level})"
        );
        assert!(se < 0.02 * level, "{kernel:?}: too noisy to tell ({se})");
    }
}

#[test]
fn lanes_hand_blend_scenes_to_the_scalar_loop_bit_for_bit() {
    let s = decal_scene(true, false);
    let (a, ra) =
        render_with_kernel(&s, &s.render, &NoProgress, &bvh, Kernel::Scalar).expect("renders");
    let (b, rb) =
        render_with_kernel(&s, &s.render, &NoProgress, &bvh, Kernel::Lanes).expect("renders");
    assert_eq!(ra, rb, "ray counts");
    let bits = |f: &Film| {
        f.color
            .iter()
            .flat_map(|c| c.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    assert!(bits(&a) == bits(&b), "colours differ");
}

#[test]
fn the_decal_seen_by_the_camera_composites_over_the_floor() {
    // From above the decal, at depth 1 under the point light: the decal
    // reflects alpha kd Ip cos / d^2 = 0.25 * 1 * 8 / 1 = 2 and passes
    // 0.75 of the floor behind it (1 through the decal's 0.75 shadow: 0.75),
    // so the pixel estimates 2 + 0.75 * 0.75 = 2.5625 (the pass is no bounce,
    // so the floor still gets its depth-1 light sample).
    let mut s = decal_scene(true, true);
    s.camera.eye = Vec3::new(0.0, 1.5, 0.001);
    s.render.path.max_depth = 1;
    s.render.samples = 256;
    for kernel in [Kernel::Scalar, Kernel::Reference] {
        let film = render(&s, kernel);
        let (mean, se) = {
            let v: Vec<f32> = film.color.iter().map(|c| c.x).collect();
            let n = v.len() as f32;
            let m = v.iter().sum::<f32>() / n;
            let var = v.iter().map(|x| (x - m).powi(2)).sum::<f32>() / (n - 1.0);
            (m, (var / n).sqrt())
        };
        let expect = 2.0 + 0.75 * 0.75;
        assert!(
            (mean - expect).abs() <= 4.0 * se + 0.02 * expect,
            "{kernel:?}: {mean} (standard error {se}) vs {expect}"
        );
    }
}
