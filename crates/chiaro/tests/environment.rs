//! The environment and the background are one rule in every technique
//! (`chiaro_core::shading::texture::miss_radiance`): a camera ray that
//! escapes sees the environment map when it is drawn as background, else
//! `Scene::background`; reflected rays see the map. And the automatic light
//! of a light-less model lights every technique alike.

use chiaro::scene::{
    Environment, Geometry, ImageTexture, Light, Material, Object, ShadowMethod, Technique, Texture,
    WrapMode,
};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use std::f32::consts::{PI, TAU};

fn render(scene: &Scene, settings: &RenderSettings) -> Film {
    chiaro::render(scene, settings, &NoProgress).expect("renders")
}

/// Map size in texels and the side of its constant blocks.
const MAP_W: u32 = 64;
const MAP_H: u32 = 32;
const BLOCK: u32 = 8;
const ROTATE_Y: f32 = 90.0;

/// The colour of block `(bx, by)`: each block its own, exactly representable
/// (so sums of equal samples and bilinear blends of equal texels are exact).
fn block_colour(bx: u32, by: u32) -> Vec3 {
    Vec3::new(0.125 * (bx + 1) as f32, 0.25 * (by + 1) as f32, 0.5)
}

/// A lat-long map of 8 x 4 constant blocks of 8 x 8 texels.
fn block_map() -> ImageTexture {
    ImageTexture {
        source: "blocks".into(),
        width: MAP_W,
        height: MAP_H,
        texels: (0..MAP_W * MAP_H)
            .map(|i| {
                block_colour(i % MAP_W / BLOCK, i / MAP_W / BLOCK)
                    .extend(1.0)
                    .into()
            })
            .collect(),
        wrap: WrapMode::Repeat,
        ..Default::default()
    }
}

/// A ball of radius 1 at the origin, seen from the default camera (5 units
/// down +z), in front of `map` turned by `ROTATE_Y` about +y.
fn ball_scene(map: ImageTexture, ball: Material, as_background: bool) -> Scene {
    let mut s = Scene::default();
    s.add_material(ball);
    s.objects.push(Object {
        geometry: Geometry::Sphere { radius: 1.0 },
        ..Default::default()
    });
    let t = s.add_texture(Texture::Image(map));
    s.environment = Some(Environment {
        texture: t,
        intensity: 1.0,
        rotate_y_degrees: ROTATE_Y,
        as_background,
    });
    s.background = Vec3::new(0.0625, 0.75, 0.375);
    s.render.width = 48;
    s.render.height = 32;
    s.render.samples = 4;
    s
}

/// The nine directions through a pixel's corners, edge midpoints and centre.
fn pixel_dirs(s: &Scene, x: u32, y: u32) -> impl Iterator<Item = Vec3> + '_ {
    let (w, h) = (s.render.width, s.render.height);
    (0..9).map(move |k| {
        let (fx, fy) = ((k % 3) as f32 * 0.5, (k / 3) as f32 * 0.5);
        s.camera.ray_direction(x as f32 + fx, y as f32 + fy, w, h)
    })
}

/// Angular radius of the ball seen from the eye, plus two pixels' margin
/// (a pixel is about 1.4 degrees here).
fn ball_cone(s: &Scene) -> f32 {
    (1.0 / s.camera.eye.length()).asin() + 0.05
}

/// The block a direction sees, from the map's definition written out
/// independently of the renderer: azimuth from -z towards +x, the map turned
/// right-handed by `ROTATE_Y` (so direction `d` sees the map at `R_y(-a) d`,
/// whose azimuth is larger by `a`); `None` within half a texel of a block
/// edge, where bilinear filtering blends two blocks.
fn block_seen(d: Vec3) -> Option<(u32, u32)> {
    let u = (0.5 + d.x.atan2(-d.z) / TAU + ROTATE_Y / 360.0).rem_euclid(1.0);
    let v = d.y.clamp(-1.0, 1.0).acos() / PI;
    let inside = |t: f32, n: u32| {
        let x = t * n as f32;
        let b = (x / BLOCK as f32).floor();
        let r = x - b * BLOCK as f32;
        (r > 0.55 && r < BLOCK as f32 - 0.55).then_some(b as u32)
    };
    Some((inside(u, MAP_W)?, inside(v, MAP_H)?))
}

/// Background pixels whose whole footprint sees one block, with that block.
fn background_pixels(s: &Scene) -> Vec<(u32, u32, (u32, u32))> {
    let cone = ball_cone(s);
    let fwd = (s.camera.look_at - s.camera.eye).normalize();
    let mut out = Vec::new();
    for y in 0..s.render.height {
        for x in 0..s.render.width {
            let dirs: Vec<Vec3> = pixel_dirs(s, x, y).collect();
            if dirs.iter().any(|d| d.angle_between(fwd) < cone) {
                continue;
            }
            let blocks: Vec<_> = dirs.iter().map(|&d| block_seen(d)).collect();
            if let Some(b) = blocks[0]
                && blocks.iter().all(|&c| c == Some(b))
            {
                out.push((x, y, b));
            }
        }
    }
    out
}

#[test]
fn every_technique_sees_the_same_rotated_environment_behind_the_ball() {
    for as_background in [true, false] {
        let scene = ball_scene(
            block_map(),
            Material::diffuse("ball", Vec3::splat(0.5)),
            as_background,
        );
        let pixels = background_pixels(&scene);
        assert!(pixels.len() > 300, "{} pixels", pixels.len());
        let mut blocks: Vec<_> = pixels.iter().map(|p| p.2).collect();
        blocks.sort_unstable();
        blocks.dedup();
        // The turned map shows blocks 5 and 6 across, 1 and 2 down (a map
        // turned the other way would show blocks 1 and 2 across).
        assert_eq!(blocks, [(5, 1), (5, 2), (6, 1), (6, 2)]);
        for t in chiaro::Technique::ALL {
            let mut s = scene.render.clone();
            s.technique = t;
            let film = render(&scene, &s);
            assert!(film.is_clean(), "{}", t.name());
            for &(x, y, (bx, by)) in &pixels {
                let want = if as_background {
                    block_colour(bx, by)
                } else {
                    scene.background
                };
                let got = film.get(x, y);
                assert!(
                    (got - want).abs().max_element() <= 1e-5,
                    "{} (background = {as_background}) at ({x}, {y}): {got} != {want}",
                    t.name()
                );
            }
        }
    }
}

#[test]
fn a_mirror_shows_the_environment_whatever_the_background_flag() {
    // A constant map: every mirror pixel must show it, in every technique
    // with mirror reflection; around the ball the camera sees the colour.
    let c = Vec3::new(0.25, 0.5, 1.0);
    let map = ImageTexture {
        source: "constant".into(),
        width: 4,
        height: 2,
        texels: vec![c.extend(1.0).into(); 8],
        wrap: WrapMode::Repeat,
        ..Default::default()
    };
    let mirror = Material {
        ambient: Vec3::ZERO,
        diffuse: Vec3::ZERO,
        reflect: Vec3::ONE,
        ..Material::diffuse("mirror", Vec3::ZERO)
    };
    let scene = ball_scene(map, mirror, false);
    let cone = ball_cone(&scene) - 0.1;
    let fwd = (scene.camera.look_at - scene.camera.eye).normalize();
    for t in [
        Technique::Phong,
        Technique::Whitted,
        Technique::Hybrid,
        Technique::Path,
    ] {
        let mut s = scene.render.clone();
        s.technique = t;
        let film = render(&scene, &s);
        let (mut on, mut off) = (0, 0);
        for y in 0..s.height {
            for x in 0..s.width {
                let angles: Vec<f32> = pixel_dirs(&scene, x, y)
                    .map(|d| d.angle_between(fwd))
                    .collect();
                let want = if angles.iter().all(|&a| a < cone) {
                    on += 1;
                    c
                } else if angles.iter().all(|&a| a > cone + 0.15) {
                    off += 1;
                    scene.background
                } else {
                    continue;
                };
                let got = film.get(x, y);
                assert!(
                    (got - want).abs().max_element() <= 1e-5,
                    "{} at ({x}, {y}): {got} != {want}",
                    t.name()
                );
            }
        }
        assert!(on > 20 && off > 300, "{on} {off}");
    }
}

/// A regular octahedron as OBJ text, with no material library and no lights.
const OCTAHEDRON: &str = "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n\
f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";

#[test]
fn the_automatic_light_lights_path_and_phong_alike() {
    let dir = std::env::temp_dir().join(format!("chiaro-env-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let file = dir.join("octahedron.obj");
    std::fs::write(&file, OCTAHEDRON).expect("write obj");
    let loaded = chiaro::io::load_scene(&file).expect("loads");
    let _ = std::fs::remove_dir_all(&dir);
    let mut scene = loaded.scene;
    assert!(
        scene
            .lights
            .iter()
            .any(|l| matches!(l, Light::Directional { .. })),
        "{:?}",
        scene.lights
    );
    // The path tracer ignores ambient light by design and phong does not
    // integrate the studio map; compare direct light (the environment is
    // checked by `the_studio_environment_lights_a_metal_in_every_technique`).
    assert!(
        scene.environment.is_some(),
        "the studio environment is added"
    );
    chiaro_testkit::scenes::drop_ambient(&mut scene);
    scene.environment = None;
    let mut s = scene.render.clone();
    s.width = 96;
    s.height = 72;
    s.samples = 4;
    s.shadows = ShadowMethod::Ray;
    s.technique = Technique::Phong;
    let phong = render(&scene, &s);
    s.technique = Technique::Path;
    s.path.max_depth = 1;
    let path = render(&scene, &s);
    // Flat faces under one directional light: every sample of a pixel inside
    // a face sees the same radiance, so the two agree to rounding there.
    let w = s.width as usize;
    let inside = |f: &Film, i: usize| {
        let (x, y) = (i % w, i / w);
        x > 0
            && y > 0
            && x + 1 < w
            && y + 1 < s.height as usize
            && [i, i - 1, i + 1, i - w, i + w]
                .iter()
                .all(|&j| f.depth[j].is_finite() && f.normal[j].dot(f.normal[i]) > 0.9999)
    };
    let (mut lit, mut compared) = (0, 0);
    for i in 0..phong.color.len() {
        if !inside(&phong, i) || !inside(&path, i) {
            continue;
        }
        compared += 1;
        let (a, b) = (phong.color[i], path.color[i]);
        if a.max_element() > 0.05 {
            lit += 1;
        }
        assert!(
            (a - b).abs().max_element() <= 1e-4 * a.max_element().max(1.0),
            "pixel {i}: phong {a} path {b}"
        );
    }
    assert!(compared > 200 && lit > 150, "{compared} {lit}");
}

/// Mean luminance of the pixels whose centre sees a surface.
fn surface_mean(f: &Film) -> f32 {
    let (mut sum, mut n) = (0.0, 0);
    for (c, d) in f.color.iter().zip(&f.depth) {
        if d.is_finite() {
            sum += chiaro_core::shading::bsdf::luminance(*c);
            n += 1;
        }
    }
    assert!(n > 100, "{n} surface pixels");
    sum / n as f32
}

/// A glTF-style gold metal (kd = 0, F0 = base colour) under the automatic
/// lighting of a model without lights (`default_lights` plus the studio
/// environment): phong and whitted (through the ambient light of the map's
/// mean radiance and `ks_ambient`) and path (through the map itself) agree
/// within a factor of 1.5 in mean luminance, and each is at least twice
/// what the key light alone gives. Fails if a technique loses the
/// environment or the ambient stand-in.
#[test]
fn the_studio_environment_lights_a_metal_in_every_technique() {
    use chiaro::scene::{MetallicRoughness, ReflectanceModel};
    let mr = MetallicRoughness {
        base_color: Vec3::new(1.0, 0.78, 0.34),
        metallic: 1.0,
        roughness: 0.5,
        texture: None,
    };
    let (diffuse, specular, roughness) =
        MetallicRoughness::coefficients(mr.base_color, mr.metallic, mr.roughness);
    let mut s = Scene::default();
    s.add_material(Material {
        diffuse,
        specular,
        roughness,
        model: ReflectanceModel::TorranceSparrow,
        metallic_roughness: Some(mr),
        ambient: Vec3::ONE, // as the glTF importer sets it
        ..Material::default()
    });
    s.objects.push(Object {
        geometry: Geometry::Sphere { radius: 1.0 },
        ..Default::default()
    });
    s.lights = chiaro::io::default_lights(&s.camera);
    chiaro::io::add_studio_environment(&mut s);
    let mut settings = s.render.clone();
    settings.width = 48;
    settings.height = 48;
    settings.samples = 64;
    let mut means = Vec::new();
    for t in [Technique::Phong, Technique::Whitted, Technique::Path] {
        settings.technique = t;
        means.push((t, surface_mean(&render(&s, &settings))));
    }
    // The key light alone, in phong: no ambient, no environment.
    let mut key = s.clone();
    key.environment = None;
    chiaro_testkit::scenes::drop_ambient(&mut key);
    settings.technique = Technique::Phong;
    let key_only = surface_mean(&render(&key, &settings));
    eprintln!("metal mean luminance: {means:?}, key light alone {key_only}");
    for &(t, m) in &means {
        assert!(
            m > 2.0 * key_only,
            "{t:?}: {m} vs key light alone {key_only}"
        );
        for &(u, n) in &means {
            assert!(m <= 1.5 * n, "{t:?} {m} vs {u:?} {n}");
        }
    }
}
