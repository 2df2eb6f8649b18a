//! Tests of the scan-conversion renderer against ray casting and closed forms.

use super::*;
use crate::gouraud::*;
use crate::pipeline::shading::*;
use crate::pipeline::triangles::*;
use crate::pipeline::vertex::*;
use crate::pipeline::visibility::*;
use crate::raster::Rect;
use crate::shadows::*;
use chiaro_core::accel::Accelerator;
use chiaro_core::accel::list::ListAccel;
use chiaro_core::error::CoreError;
use chiaro_core::film::{Film, TileRect};
use chiaro_core::geometry::{Ray, primitives};
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::PixelFilter;
use chiaro_core::scene::{
    Attenuation, Camera, DepthCue, Environment, Geometry, ImageTexture, Light, Object,
    ReflectanceModel, SpotLight, Texture, Transform, WrapMode,
};
use chiaro_core::scene::{Material, RenderSettings, Scene, ShadeMode, Technique};
use chiaro_core::scene::{ShadowMethod, Sidedness};
use chiaro_core::shading::PointLighting;
use chiaro_core::shading::texture::environment_radiance;
use chiaro_core::shading::{LocalLighting, ShadingPoint, SurfaceMaterial, shade_local};
use chiaro_testkit::scenes::{add_named, add_object, camera, point_light, translate};
use glam::{Vec2, Vec3};

fn settings(technique: Technique, w: u32, h: u32) -> RenderSettings {
    RenderSettings {
        technique,
        width: w,
        height: h,
        shadows: ShadowMethod::None,
        ..RenderSettings::default()
    }
}

/// A sphere on a floor, lit by two point lights, a spotlight, a directional
/// light and ambient light; Blinn, Phong and Torrance-Sparrow materials.
fn test_scene() -> Scene {
    let mut s = Scene::default();
    let shiny = s.add_material(Material {
        name: "shiny".into(),
        diffuse: Vec3::new(0.7, 0.3, 0.2),
        specular: Vec3::splat(0.4),
        shininess: 30.0,
        model: ReflectanceModel::Blinn,
        ..Material::default()
    });
    let floor = s.add_material(Material {
        name: "floor".into(),
        diffuse: Vec3::new(0.3, 0.6, 0.3),
        specular: Vec3::splat(0.3),
        model: ReflectanceModel::TorranceSparrow,
        roughness: 0.3,
        ..Material::default()
    });
    let plane = s.add_mesh(primitives::plane(3.0, 4));
    let ball = (Geometry::Sphere { radius: 1.0 }, shiny);
    add_named(&mut s, "", ball, Transform::default(), true);
    let below = translate(Vec3::new(0.0, -1.0, 0.0));
    add_named(&mut s, "", (Geometry::Mesh(plane), floor), below, true);
    s.lights = vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.2,
        },
        Light::Point {
            position: Vec3::new(2.0, 3.0, 2.0),
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 10.0,
            attenuation: Attenuation::InverseSquare,
        },
        Light::Point {
            position: Vec3::new(-3.0, 2.0, 1.0),
            color: Vec3::new(0.3, 0.4, 1.0),
            intensity: 1.0,
            attenuation: Attenuation::Empirical {
                c1: 1.0,
                c2: 0.1,
                c3: 0.01,
            },
        },
        Light::Spot(SpotLight {
            position: Vec3::new(0.0, 4.0, 0.0),
            direction: Vec3::NEG_Y,
            color: Vec3::ONE,
            intensity: 8.0,
            attenuation: Attenuation::InverseSquare,
            exponent: 4.0,
            cone_degrees: 30.0,
            cone_softness_degrees: 5.0,
            flaps: Vec::new(),
        }),
        Light::Directional {
            direction: Vec3::new(-1.0, -1.0, -0.5).normalize(),
            color: Vec3::ONE,
            intensity: 0.3,
        },
    ];
    s.camera = camera(Vec3::new(0.5, 1.5, 5.0), Vec3::new(0.0, -0.3, 0.0), 40.0);
    s
}

/// [`test_scene`] with its first three lights (ambient and the two point
/// lights): the lights of the point-light model.
fn point_lit_scene() -> Scene {
    let mut s = test_scene();
    s.lights.truncate(3);
    s
}

/// The per-pixel ray cast of the same prepared scene, shaded by the same
/// function: the oracle of the cross-technique invariant.
fn ray_cast(ps: &PreparedScene<'_>, w: u32, h: u32) -> Vec<Option<(u32, Vec3)>> {
    let accel = ListAccel::new(ps);
    let cam = &ps.scene.camera;
    let env = LocalLighting {
        lights: &ps.lights,
        area_samples: 16,
        ambient: true,
        group: None,
        share: chiaro_core::shading::SampleShare::WHOLE,
    };
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let ray = Ray::new(cam.eye, d);
            out.push(accel.intersect(&ray).map(|hit| {
                let s = ps.surface(&ray, &hit);
                let m = ps.surface_material(&s);
                let wo = (cam.eye - s.p).normalize();
                let sp = ShadingPoint {
                    p: s.p,
                    n: s.ns,
                    ng: s.ng,
                    wo,
                };
                let c = shade_local(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE);
                (hit.prim, c)
            }));
        }
    }
    out
}

#[test]
fn phong_mode_equals_ray_cast_shading() {
    let scene = test_scene();
    let (w, h) = (48, 40);
    let st = settings(Technique::Phong, w, h);
    let film = render(&scene, &st, &NoProgress).expect("render");
    assert!(film.is_clean());
    // The spheres tessellated as the render tessellates them (by size).
    let ps = PreparedScene::new(
        &scene,
        PrepareOptions {
            analytic_spheres: false,
            tessellation: chiaro_core::context::tessellation(&scene, &st),
        },
    );
    let reference = ray_cast(&ps, w, h);
    let mut compared = 0;
    for (i, r) in reference.iter().enumerate() {
        match r {
            None => {
                assert_eq!(film.depth[i], f32::INFINITY, "pixel {i}");
                assert_eq!(film.color[i], scene.background);
            }
            Some((_, c)) => {
                // Same surface: the depth agrees.
                let cam = &scene.camera;
                let d = cam.ray_direction(
                    (i as u32 % w) as f32 + 0.5,
                    (i as u32 / w) as f32 + 0.5,
                    w,
                    h,
                );
                let t = ListAccel::new(&ps)
                    .intersect(&Ray::new(cam.eye, d))
                    .map_or(f32::INFINITY, |hh| hh.t);
                if (film.depth[i] - t).abs() > 1e-3 * t {
                    continue;
                }
                let diff = (film.color[i] - *c).abs().max_element();
                assert!(
                    diff <= 1e-4 + 1e-4 * c.max_element(),
                    "pixel {i}: {} vs {c}",
                    film.color[i]
                );
                compared += 1;
            }
        }
    }
    assert!(compared > (w * h / 2) as usize, "compared {compared}");
}

#[test]
fn flat_is_constant_per_polygon_and_gouraud_interpolates_vertex_colours() {
    // One quad facing the camera, a near point light (a strong gradient).
    let mut s = Scene::default();
    let m = s.add_material(Material {
        specular: Vec3::splat(0.5),
        ..Material::default()
    });
    let q = s.add_mesh(primitives::quad(
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ));
    add_object(&mut s, Geometry::Mesh(q), m, Transform::default());
    s.lights.push(point_light(Vec3::new(0.5, 0.3, 1.0), 1.0));
    s.camera = camera(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, 60.0);
    let (w, h) = (32, 32);
    let flat = render(&s, &settings(Technique::Flat, w, h), &NoProgress).expect("flat");
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    let mut colours: Vec<[u32; 3]> = flat
        .color
        .iter()
        .zip(&flat.depth)
        .filter(|(_, d)| d.is_finite())
        .map(|(c, _)| c.to_array().map(f32::to_bits))
        .collect();
    colours.sort_unstable();
    colours.dedup();
    assert_eq!(colours.len(), 2, "one colour per triangle");

    let g = render(&s, &settings(Technique::Gouraud, w, h), &NoProgress).expect("gouraud");
    let env = LocalLighting {
        lights: &s.lights,
        area_samples: 1,
        ambient: true,
        group: None,
        share: chiaro_core::shading::SampleShare::WHOLE,
    };
    let vertex = |p: Vec3| {
        let sp = ShadingPoint {
            p,
            n: Vec3::Z,
            ng: Vec3::Z,
            wo: (s.camera.eye - p).normalize(),
        };
        let sm = SurfaceMaterial::from_material(&s.materials[0]);
        shade_local(&sm, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE)
    };
    let accel = ListAccel::new(&ps);
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let d = s.camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let Some(hit) = accel.intersect(&Ray::new(s.camera.eye, d)) else {
                continue;
            };
            let [a, b, c] = ps.triangles[hit.prim as usize].map(|i| ps.positions[i as usize]);
            let expect = vertex(a) * (1.0 - hit.u - hit.v) + vertex(b) * hit.u + vertex(c) * hit.v;
            let got = g.color[(y * w + x) as usize];
            assert!(
                (got - expect).abs().max_element() < 1e-4,
                "{x},{y}: {got} vs {expect}"
            );
            checked += 1;
        }
    }
    assert!(checked > 200);
    // Phong differs from Gouraud under a near light (the highlight is not missed).
    let p = render(&s, &settings(Technique::Phong, w, h), &NoProgress).expect("phong");
    let max_diff = p
        .color
        .iter()
        .zip(&g.color)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(max_diff > 0.01);
}

/// Adds the quad `corner + s u + t v` emitting `image` (white emission
/// times the texture, no diffuse or ambient reflection), so that a pixel
/// shows the texture as filtered at it.
fn emitting_quad(s: &mut Scene, image: ImageTexture, corner: Vec3, u: Vec3, v: Vec3) {
    let tex = s.add_texture(Texture::Image(image));
    let m = s.add_material(Material {
        diffuse: Vec3::ZERO,
        ambient: Vec3::ZERO,
        emission: Vec3::ONE,
        emission_texture: Some(tex),
        ..Material::default()
    });
    let q = s.add_mesh(primitives::quad(corner, u, v));
    s.objects.push(Object {
        geometry: Geometry::Mesh(q),
        material: m,
        ..Object::default()
    });
}

/// A plane seen at a grazing angle whose emission texture is a ramp in u:
/// the rendered value must be the u of the ray-plane hit (no affine distortion).
#[test]
fn textures_are_interpolated_perspective_correctly() {
    let mut s = Scene::default();
    let n = 64u32;
    let texels = (0..n).map(|i| [(i as f32 + 0.5) / n as f32, 0.0, 0.0, 1.0]);
    let mut ramp = ImageTexture::new("ramp".into(), 1, n, texels.collect());
    ramp.wrap = WrapMode::Clamp;
    // Two big triangles, uv u along the depth axis.
    let (u, v) = (Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -40.0));
    emitting_quad(&mut s, ramp, Vec3::new(-2.0, 0.0, 2.0), u, v);
    s.camera = camera(Vec3::new(0.0, 0.5, 2.5), Vec3::new(0.0, 0.0, -5.0), 45.0);
    let (w, h) = (32, 32);
    let film = render(&s, &settings(Technique::Phong, w, h), &NoProgress).expect("render");
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let d = s.camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            if d.y >= -1e-3 {
                continue;
            }
            let t = -s.camera.eye.y / d.y;
            let p = s.camera.eye + d * t;
            if p.x.abs() > 1.9 || p.z < -37.0 || p.z > 1.9 {
                continue;
            }
            // quad uvs: v = 1 at the corner (z = 2), 0 at z = -38.
            let u = (p.z + 38.0) / 40.0;
            let got = film.color[(y * w + x) as usize].x;
            // Mip-mapping a linear ramp keeps it linear away from the ends.
            if u > 0.05 && u < 0.9 {
                assert!((got - u).abs() < 2e-3, "{x},{y}: {got} vs {u}");
                checked += 1;
            }
        }
    }
    assert!(checked > 50, "{checked}");
}

#[test]
fn distant_checker_is_filtered_to_its_mean_by_mip_mapping() {
    let mut s = Scene::default();
    let n = 256u32;
    let checker = ImageTexture {
        source: "checker".into(),
        width: n,
        height: n,
        texels: (0..n * n)
            .map(|i| {
                let v = ((i % n + i / n) % 2) as f32;
                [v, v, v, 1.0]
            })
            .collect(),
        wrap: WrapMode::Repeat,
        ..Default::default()
    };
    let (u, v) = (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
    emitting_quad(&mut s, checker, Vec3::new(-1.0, -1.0, 0.0), u, v);
    s.camera = camera(Vec3::new(0.0, 0.0, 2.5), Vec3::ZERO, 50.0);
    // 16x16 pixels over 256x256 texels: lod about 4, every pixel averages out.
    let film = render(&s, &settings(Technique::Phong, 16, 16), &NoProgress).expect("render");
    for (c, d) in film.color.iter().zip(&film.depth) {
        if d.is_finite() {
            assert!((c.x - 0.5).abs() < 0.02, "{}", c.x);
        }
    }
}

#[test]
fn other_techniques_and_bad_sizes_are_refused() {
    let s = test_scene();
    for t in [Technique::Whitted, Technique::Path, Technique::Radiosity] {
        assert!(matches!(
            render(&s, &settings(t, 8, 8), &NoProgress),
            Err(CoreError::Unsupported(_))
        ));
    }
    assert!(render(&s, &settings(Technique::Phong, 0, 8), &NoProgress).is_err());
}

#[test]
fn camera_inside_a_crossing_triangle_renders_the_visible_part() {
    // The floor triangle extends behind the camera; the floor must be drawn
    // below the horizon with finite, correct depths, nothing above.
    let mut s = Scene::default();
    s.add_material(Material::default());
    let mesh = s.add_mesh(chiaro_core::scene::Mesh {
        positions: vec![
            Vec3::new(-50.0, -1.0, -50.0),
            Vec3::new(0.0, -1.0, 50.0),
            Vec3::new(50.0, -1.0, -50.0),
        ],
        indices: vec![[0, 1, 2]],
        ..Default::default()
    });
    s.objects.push(Object {
        geometry: Geometry::Mesh(mesh),
        ..Object::default()
    });
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s.camera = Camera {
        eye: Vec3::ZERO,
        look_at: Vec3::new(0.0, 0.0, -1.0),
        near: 0.05,
        ..Camera::default()
    };
    let (w, h) = (24, 24);
    let film = render(&s, &settings(Technique::Phong, w, h), &NoProgress).expect("render");
    assert!(film.is_clean());
    for y in 0..h {
        for x in 0..w {
            let d = s.camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let i = (y * w + x) as usize;
            let t = -1.0 / d.y;
            let q = d * t;
            let inside = q.z > -49.0 && q.x.abs() < 0.5 * (50.0 - q.z) - 1.0;
            if d.y < -1e-3 && inside {
                assert!((film.depth[i] - t).abs() < 1e-3 * t, "{x},{y}");
                assert!((film.color[i].x - 0.08).abs() < 1e-5);
            } else if d.y > 1e-3 {
                assert_eq!(film.depth[i], f32::INFINITY);
            }
        }
    }
}

#[test]
fn supersampling_averages_edges_and_keeps_interiors() {
    let s = test_scene();
    let one = render(&s, &settings(Technique::Flat, 32, 32), &NoProgress).expect("1 spp");
    let mut st = settings(Technique::Flat, 32, 32);
    st.samples = 4;
    let four = render(&s, &st, &NoProgress).expect("4 spp");
    assert!(four.is_clean());
    // Silhouette pixels get values strictly between sphere and background.
    let bg = s.background;
    let mixed = four
        .color
        .iter()
        .zip(&one.color)
        .filter(|(a, b)| (**a - **b).abs().max_element() > 1e-3 && **a != bg)
        .count();
    assert!(mixed > 10);
    let mean_diff = (four.mean() - one.mean()).abs().max_element();
    assert!(mean_diff < 0.02, "{mean_diff}");
}

#[test]
fn environment_is_background_and_reflection() {
    let mut s = test_scene();
    let env_img = chiaro_testkit::scenes::sky_image();
    let t = s.add_texture(Texture::Image(env_img));
    s.environment = Some(Environment {
        texture: t,
        intensity: 2.0,
        rotate_y_degrees: 0.0,
        as_background: true,
    });
    let st = settings(Technique::Phong, 24, 24);
    let plain = render(&s, &st, &NoProgress).expect("render");
    let rays = Rays::new(&s.camera, 24, 24);
    for (i, d) in plain.depth.iter().enumerate() {
        if !d.is_finite() {
            let dir = rays.dir((i % 24) as f32 + 0.5, (i / 24) as f32 + 0.5);
            let e = environment_radiance(&s, dir);
            assert!((plain.color[i] - e).abs().max_element() < 1e-6);
        }
    }
    // A mirror coefficient adds kr * environment on the sphere.
    s.materials[0].reflect = Vec3::splat(0.5);
    let mirror = render(&s, &st, &NoProgress).expect("render");
    let brighter = plain
        .color
        .iter()
        .zip(&mirror.color)
        .filter(|(a, b)| b.z > a.z + 0.1)
        .count();
    assert!(brighter > 20);
}

#[test]
fn two_sided_back_faces_are_lit_one_sided_black_and_culled_culled() {
    let mut s = Scene::default();
    let m = s.add_material(Material {
        sidedness: Sidedness::Culled,
        ..Material::default()
    });
    // Quad facing -z, camera on +z: we see its back.
    let q = s.add_mesh(primitives::quad(
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
    ));
    s.objects.push(Object {
        geometry: Geometry::Mesh(q),
        material: m,
        ..Object::default()
    });
    s.lights.push(point_light(Vec3::new(0.0, 0.0, 2.0), 4.0));
    let st = settings(Technique::Phong, 16, 16);
    let culled = render(&s, &st, &NoProgress).expect("render");
    assert!(culled.depth.iter().all(|d| d.is_infinite()));
    // `cull_backfaces` off does not show it either.
    let mut st_off = st.clone();
    st_off.cull_backfaces = false;
    let culled = render(&s, &st_off, &NoProgress).expect("render");
    assert!(culled.depth.iter().all(|d| d.is_infinite()));
    s.materials[0].sidedness = Sidedness::TwoSided;
    for t in [Technique::Flat, Technique::Gouraud, Technique::Phong] {
        let lit = render(&s, &settings(t, 16, 16), &NoProgress).expect("render");
        let c = lit.color[8 * 16 + 8];
        assert!(c.x > 0.3, "{t:?}: {c}");
        assert!(lit.normal[8 * 16 + 8].z > 0.99);
    }
    // One-sided: drawn, and black.
    s.materials[0].sidedness = Sidedness::OneSided;
    for t in [Technique::Flat, Technique::Gouraud, Technique::Phong] {
        let f = render(&s, &settings(t, 16, 16), &NoProgress).expect("render");
        assert!(f.depth[8 * 16 + 8].is_finite(), "{t:?}");
        assert_eq!(f.color[8 * 16 + 8], Vec3::ZERO, "{t:?}");
    }
}

#[test]
fn depth_cue_blends_with_distance() {
    let s = test_scene();
    let mut st = settings(Technique::Gouraud, 16, 16);
    let plain = render(&s, &st, &NoProgress).expect("render");
    st.depth_cue = Some(DepthCue {
        color: Vec3::new(0.0, 0.0, 1.0),
        near: 0.0,
        far: 1.0,
        max_scale: 0.0,
        min_scale: 0.0,
    });
    let cued = render(&s, &st, &NoProgress).expect("render");
    for i in 0..plain.color.len() {
        if plain.depth[i].is_finite() {
            assert_eq!(cued.color[i], Vec3::new(0.0, 0.0, 1.0));
        }
    }
}

#[test]
fn crop_window_matches_the_full_render_and_leaves_the_rest_black() {
    let mut s = test_scene();
    s.background = Vec3::new(0.2, 0.3, 0.4);
    // One transparent material, so that A-buffer fragments are cropped too.
    s.materials[0].transmit = Vec3::splat(0.5);
    let (w, h) = (48u32, 40u32);
    let window = [7u32, 5, 37, 29];
    for (technique, shadows, samples) in [
        (Technique::Phong, ShadowMethod::None, 1),
        (Technique::Phong, ShadowMethod::Volume, 2),
        (Technique::Gouraud, ShadowMethod::Ray, 1),
        (Technique::Flat, ShadowMethod::Map, 3),
    ] {
        let full_settings = RenderSettings {
            shadows,
            samples,
            ..settings(technique, w, h)
        };
        let full = render(&s, &full_settings, &NoProgress).expect("full");
        let cropped = render(
            &s,
            &RenderSettings {
                crop: Some(window),
                ..full_settings.clone()
            },
            &NoProgress,
        )
        .expect("cropped");
        let mut inside_lit = 0;
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let inside = x >= window[0] && x < window[2] && y >= window[1] && y < window[3];
                if inside {
                    assert_eq!(cropped.color[i], full.color[i], "{technique:?} ({x}, {y})");
                    assert_eq!(cropped.depth[i].to_bits(), full.depth[i].to_bits());
                    assert_eq!(cropped.normal[i], full.normal[i]);
                    inside_lit += usize::from(full.color[i] != Vec3::ZERO);
                } else {
                    assert_eq!(cropped.color[i], Vec3::ZERO, "{technique:?} ({x}, {y})");
                    assert_eq!(cropped.depth[i], f32::INFINITY);
                    assert_eq!(cropped.normal[i], Vec3::ZERO);
                }
            }
        }
        assert!(inside_lit > 600, "{technique:?}: {inside_lit}");
    }
    // A window outside the image draws nothing.
    let st = RenderSettings {
        crop: Some([60, 0, 80, 10]),
        ..settings(Technique::Phong, w, h)
    };
    let empty = render(&s, &st, &NoProgress).expect("empty crop");
    assert!(empty.color.iter().all(|&c| c == Vec3::ZERO));
    assert!(empty.depth.iter().all(|d| d.is_infinite()));
}

/// `s` prepared for scan conversion (spheres tessellated).
fn tessellated(s: &Scene) -> PreparedScene<'_> {
    PreparedScene::new(
        s,
        PrepareOptions {
            analytic_spheres: false,
            ..PrepareOptions::default()
        },
    )
}

/// A shading context for tests: `mode` everywhere, no shadows, with the
/// point-light model and base materials when `point` (which needs point and
/// ambient lights only).
fn test_ctx<'a, 's>(
    ps: &'a PreparedScene<'s>,
    st: &'a RenderSettings,
    mode: ShadeMode,
    point: bool,
) -> Ctx<'a, 's> {
    let s = ps.scene;
    Ctx {
        ps,
        settings: st,
        rays: Rays::new(&s.camera, st.width, st.height),
        lighting: LocalLighting {
            lights: &ps.lights,
            area_samples: 1,
            ambient: true,
            group: None,
            share: chiaro_core::shading::SampleShare::WHOLE,
        },
        object_mode: vec![mode; s.objects.len()],
        shadows: Shadows::None,
        group_rays: None,
        class: Vec::new(),
        point_lighting: if point {
            PointLighting::new(&ps.lights, true)
        } else {
            None
        },
        bases: if point {
            s.materials
                .iter()
                .map(SurfaceMaterial::from_material)
                .collect()
        } else {
            Vec::new()
        },
        lean_frame: point,
        one_mode: None,
        one_material: None,
    }
}

#[test]
fn cached_bary_equals_ray_plane_bary_exactly() {
    let s = test_scene();
    let ps = tessellated(&s);
    let st = settings(Technique::Phong, 32, 24);
    let ctx = test_ctx(&ps, &st, ShadeMode::Phong, false);
    let mut cache = TriCache::new();
    let nt = ps.triangles.len() as u32;
    assert!(nt > 10);
    let mut checked = 0;
    for k in 0..200u32 {
        let t = (k * 7919) % nt;
        // Twice: a miss, then a hit of the same entry.
        for _ in 0..2 {
            let td = ctx.tri_data(t, &mut cache, &PolyShading::default());
            assert_eq!(td.t, t);
            let [p0, p1, p2] = td.p.map(Vec3::from);
            let d = ctx.rays.dir(k as f32 * 0.37 % 32.0, k as f32 * 0.11 % 24.0);
            let a = td.bary(d.into());
            let b = ray_plane_bary(ctx.rays.eye, d, p0, p1, p2);
            assert_eq!(a.map(|v| v.to_array()), b.map(|v| v.to_array()));
            checked += usize::from(a.is_some());
        }
    }
    assert!(checked > 300);
}

#[test]
fn lean_samples_equal_shade_sample_bit_for_bit() {
    let mut s = test_scene();
    // Point and ambient lights only, so that PointLighting applies.
    s.lights.truncate(3);
    let mut rng = chiaro_testkit::XorShift64(0x9e37_79b9_7f4a_7c15u64);
    let mut next = move || rng.unit();
    let (w, h) = (40u32, 30u32);
    let mut checked = 0;
    for model in [ReflectanceModel::Phong, ReflectanceModel::Blinn] {
        s.materials[0].model = model;
        let ps = tessellated(&s);
        // Arbitrary vertex illumination for the Gouraud corners.
        let poly = PolyShading {
            vertex_front: (0..ps.positions.len())
                .map(|_| Split {
                    diffuse: Vec3::new(next(), next(), next()),
                    rest: Vec3::new(next(), next(), next()),
                })
                .collect(),
            ..PolyShading::default()
        };
        for mode in [ShadeMode::Phong, ShadeMode::Gouraud, ShadeMode::Flat] {
            let st = settings(Technique::Phong, w, h);
            let ctx = test_ctx(&ps, &st, mode, true);
            assert!(ctx.point_lighting.is_some());
            let mut cache = TriCache::new();
            let nt = ps.triangles.len() as u32;
            for k in 0..300u32 {
                let t = (k * 7919) % nt;
                let td = *ctx.tri_data(t, &mut cache, &poly);
                // A back the eye sees (two-sided by default) is not lean.
                assert_eq!(td.lean, !ctx.flipped(t), "t {t}");
                if !td.lean {
                    continue;
                }
                for _ in 0..4 {
                    let (sx, sy) = (next() * w as f32, next() * h as f32);
                    let dir = Rays::dir_from(ctx.rays.column(sx), ctx.rays.row(sy));
                    let a = lean_sample(&ctx, &td, sx, sy, dir);
                    let share = chiaro_core::shading::SampleShare::WHOLE;
                    let b = shade_sample(&ctx, &poly, &td, sx, sy, dir, None, false, share);
                    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                    assert_eq!(bits(a.color), bits(b.color), "{mode:?} {model:?} t {t}");
                    assert_eq!(a.depth.to_bits(), b.depth.to_bits());
                    assert_eq!(bits(a.normal), bits(b.normal));
                    checked += usize::from(a.color != Vec3::ZERO);
                }
            }
        }
    }
    // (Before the sidedness rule every triangle was lean: over 3000.)
    assert!(checked > 2500, "{checked}");
}

#[test]
fn vertex_split_equals_corner_split_of_every_face() {
    let s = point_lit_scene();
    // Vertex colours, so that kd varies per vertex.
    let ps0 = tessellated(&s);
    let mut ps = ps0;
    for (i, c) in ps.colors.iter_mut().enumerate() {
        *c = Vec3::new(
            0.5 + (i % 7) as f32 / 14.0,
            1.0,
            0.25 + (i % 3) as f32 / 4.0,
        );
    }
    let st = settings(Technique::Gouraud, 40, 30);
    let ctx = test_ctx(&ps, &st, ShadeMode::Gouraud, true);
    assert!(ctx.point_lighting.is_some());
    let mut compared = 0;
    for (t, tri) in ps.triangles.iter().enumerate() {
        let base = &ctx.bases[ps.tri_material[t].index()];
        for (k, &v) in tri.iter().enumerate() {
            for back in [false, true] {
                let a = ctx.vertex_split(base, v as usize, back);
                let b = ctx.corner_split(t as u32, k, back);
                // Equal as numbers (a zero's sign aside).
                assert_eq!(a, b, "t {t} corner {k} back {back}");
                compared += usize::from(a.diffuse != Vec3::ZERO);
            }
        }
    }
    assert!(compared > 1000, "{compared}");
}

#[test]
fn uniform_vertex_shading_lights_the_vertices_of_the_samples_triangles() {
    let mut s = point_lit_scene();
    for two_sided in [false, true] {
        s.materials[0].sidedness = if two_sided {
            Sidedness::TwoSided
        } else {
            Sidedness::Culled
        };
        let ps = tessellated(&s);
        let st = settings(Technique::Gouraud, 40, 30);
        let ctx = test_ctx(&ps, &st, ShadeMode::Gouraud, true);
        let base = &ctx.bases[0];
        let nt = ps.triangles.len() as u32;
        // Runs of samples on a few triangles (repeats and gaps included),
        // some of them again in a second tile, and a transparent fragment.
        let listed: Vec<u32> = (0..40u32).map(|k| (k * 7919) % nt).collect();
        let tile = |ids: Vec<u32>, frags: Vec<(u32, f32)>| TileVis {
            rect: TileRect {
                x: 0,
                y: 0,
                width: ids.len() as u32,
                height: 1,
            },
            window: Rect {
                x0: 0,
                y0: 0,
                x1: ids.len() as u32,
                y1: 1,
            },
            ids,
            start: Vec::new(),
            frags,
            counts: Vec::new(),
        };
        let first: Vec<u32> = listed[..30].iter().flat_map(|&t| [t, t, NONE, t]).collect();
        let second: Vec<u32> = listed[20..39].to_vec();
        let vis = [
            tile(first, Vec::new()),
            tile(second, vec![(listed[39], 0.5)]),
        ];
        let out = uniform_vertex_shading(&ctx, &vis, base);
        let mut want_front = vec![Split::default(); ps.positions.len()];
        let mut want_back = Vec::new();
        for &t in &listed {
            let flip = ctx.flipped(t);
            if flip && want_back.is_empty() {
                want_back = vec![Split::default(); ps.positions.len()];
            }
            for &v in &ps.triangles[t as usize] {
                let table = if flip {
                    &mut want_back
                } else {
                    &mut want_front
                };
                table[v as usize] = ctx.vertex_split(base, v as usize, flip);
            }
        }
        assert_eq!(out.vertex_front, want_front, "two-sided {two_sided}");
        assert_eq!(out.vertex_back, want_back, "two-sided {two_sided}");
        assert!(out.corners.is_empty());
        assert!(
            want_front
                .iter()
                .filter(|s| s.diffuse != Vec3::ZERO)
                .count()
                > 20
        );
    }
}

#[test]
fn rendering_into_a_used_film_gives_the_fresh_picture() {
    let s = test_scene();
    let ps = tessellated(&s);
    let (w, h) = (150u32, 90u32);
    // A film of the wrong size, then one holding another picture.
    let mut film = Film::new(7, 5);
    for (technique, crop) in [
        (Technique::Phong, None),
        (Technique::Gouraud, Some([10, 70, 140, 90])),
        (Technique::Flat, None),
        (Technique::Phong, Some([0, 0, 64, 20])),
    ] {
        let st = RenderSettings {
            crop,
            ..settings(technique, w, h)
        };
        let mode = technique.shade_mode().expect("raster technique");
        let opts = RasterOptions::default();
        let fresh = render_prepared_with(&ps, &st, mode, &opts, &NoProgress).expect("fresh");
        let work = RasterWork::default();
        let derived = chiaro_core::context::Derived::default();
        let frame = Frame {
            settings: &st,
            camera: &ps.scene.camera,
            derived: &derived,
        };
        render_work(&ps, frame, mode, &opts, &NoProgress, &mut film, &work).expect("into");
        assert!(film == fresh, "{technique:?} {crop:?}");
    }
}

#[test]
fn tent_filter_widens_edges_keeps_interiors_and_crops_exactly() {
    let mut s = test_scene();
    s.background = Vec3::new(0.2, 0.3, 0.4);
    let (w, h) = (48u32, 40u32);
    let base = RenderSettings {
        samples: 4,
        ..settings(Technique::Flat, w, h)
    };
    let boxed = render(&s, &base, &NoProgress).expect("box");
    let tent_settings = RenderSettings {
        filter: PixelFilter::Tent,
        ..base.clone()
    };
    let tent = render(&s, &tent_settings, &NoProgress).expect("tent");
    assert!(tent.is_clean());
    // Depth and normals are not filtered.
    assert_eq!(tent.depth, boxed.depth);
    assert_eq!(tent.normal, boxed.normal);
    // Pixels whose 3x3 neighbourhood is one constant colour in the box
    // image (inside a flat polygon or on the background) keep it; edges
    // differ.
    let (mut same, mut differ) = (0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let c = boxed.get(x, y);
            let flat = (0..3).all(|dy| {
                (0..3).all(|dx| (boxed.get(x + dx - 1, y + dy - 1) - c).abs().max_element() < 1e-6)
            });
            let d = (tent.get(x, y) - c).abs().max_element();
            if flat {
                assert!(d < 1e-5, "({x}, {y}): {d}");
                same += 1;
            } else if d > 1e-4 {
                differ += 1;
            }
        }
    }
    assert!(same > 100 && differ > 20, "{same} {differ}");
    let mean_diff = (tent.mean() - boxed.mean()).abs().max_element();
    assert!(mean_diff < 0.01, "{mean_diff}");
    // A crop window has the values of the full image inside (its border
    // pixels read samples outside it) and is black outside.
    let window = [7u32, 5, 37, 29];
    let cropped = render(
        &s,
        &RenderSettings {
            crop: Some(window),
            ..tent_settings
        },
        &NoProgress,
    )
    .expect("cropped");
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if x >= window[0] && x < window[2] && y >= window[1] && y < window[3] {
                assert_eq!(cropped.color[i], tent.color[i], "({x}, {y})");
                assert_eq!(cropped.depth[i].to_bits(), tent.depth[i].to_bits());
            } else {
                assert_eq!(cropped.color[i], Vec3::ZERO, "({x}, {y})");
                assert_eq!(cropped.depth[i], f32::INFINITY);
                assert_eq!(cropped.normal[i], Vec3::ZERO);
            }
        }
    }
}

/// With one untextured, one-sided Gouraud material and point lights, the
/// shading pass illuminates the vertices itself (`PolyShading::on_demand`):
/// every fetched triangle's corners are `vertex_split` of its vertices,
/// what `uniform_vertex_shading` would have tabulated for them, also after
/// the vertex cache has evicted and refilled its slots.
#[test]
fn on_demand_corners_are_the_vertex_illumination() {
    let mut s = point_lit_scene();
    let one = s.objects[0].material;
    for o in &mut s.objects {
        o.material = one;
    }
    // Two-sided (the default), a back may be seen: not on demand.
    let ps = tessellated(&s);
    let st = settings(Technique::Gouraud, 40, 30);
    let mut ctx = test_ctx(&ps, &st, ShadeMode::Gouraud, true);
    ctx.one_material = Some(ps.tri_material[0]);
    assert!(!on_demand_gouraud(&ctx));
    s.materials[one.index()].sidedness = Sidedness::Culled;
    let ps = tessellated(&s);
    let mut ctx = test_ctx(&ps, &st, ShadeMode::Gouraud, true);
    ctx.one_material = Some(ps.tri_material[0]);
    assert!(on_demand_gouraud(&ctx));
    let base = *uniform_gouraud(&ctx).expect("one Gouraud material");
    let poly = PolyShading {
        on_demand: Some(base),
        ..PolyShading::default()
    };
    let mut cache = TriCache::new();
    let nt = ps.triangles.len() as u32;
    let mut checked = 0;
    for k in 0..4000u32 {
        let t = (k * 7919) % nt;
        let td = *ctx.tri_data(t, &mut cache, &poly);
        assert!(td.lean);
        for (corner, &v) in td.corners.iter().zip(&td.idx) {
            let want = ctx.vertex_split(&base, v, false);
            assert_eq!(*corner, [want.diffuse.into(), want.rest.into()], "t {t}");
            checked += usize::from(want.diffuse != Vec3::ZERO);
        }
    }
    assert!(checked > 1000, "{checked}");
}
