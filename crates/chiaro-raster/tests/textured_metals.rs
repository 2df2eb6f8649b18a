//! Flat and Gouraud shading keep a textured metallic-roughness surface's
//! colours: the light computed per face or vertex is coloured per sample
//! by the base colour texture and the F0 it gives a metal, so the pictures
//! follow Phong shading's (issue 42: DamagedHelmet rendered grey-white in
//! flat and Gouraud, textured in Phong).

use chiaro_core::context::{RenderContext, Renderer};
use chiaro_core::film::Film;
use chiaro_core::geometry::primitives;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{
    Filter, Geometry, ImageTexture, Light, Material, MetallicRoughness, ReflectanceModel,
    RenderSettings, Scene, ShadowMethod, Technique, Texture, Transform, WrapMode,
};
use chiaro_raster::ScanConversion;
use chiaro_testkit::scenes::{add_named, camera, set_environment, sky_image};
use glam::Vec3;

/// A sphere seen from -z, its left half (u < 0.5) a metal (metallic 1,
/// roughness 0.45) and its right half a dielectric (metallic 0, roughness
/// 0.6) by the metallic-roughness texture (its factors are 1), both with a
/// base colour texture of gold and red checks; lit by a directional light,
/// a dim ambient light and a blue sky environment (not the background).
fn board() -> Scene {
    let mut s = Scene::default();
    let (gold, red) = ([1.0, 0.71, 0.29, 1.0], [0.85, 0.12, 0.08, 1.0]);
    let checks = ImageTexture {
        source: "checks".into(),
        width: 16,
        height: 8,
        texels: (0..128)
            .map(|i| {
                if (i % 16 + i / 16) % 2 == 0 {
                    gold
                } else {
                    red
                }
            })
            .collect(),
        wrap: WrapMode::Repeat,
        mag_filter: Filter::Nearest,
        ..Default::default()
    };
    // glTF's metallic-roughness texture: roughness in G, metallic in B.
    let halves = ImageTexture {
        source: "halves".into(),
        width: 2,
        height: 1,
        texels: vec![[0.0, 0.45, 1.0, 1.0], [0.0, 0.6, 0.0, 1.0]],
        wrap: WrapMode::Clamp,
        mag_filter: Filter::Nearest,
        min_filter: Filter::Nearest,
        ..Default::default()
    };
    let base = s.add_texture(Texture::Image(checks));
    let mr = s.add_texture(Texture::Image(halves));
    let (diffuse, specular, roughness) = MetallicRoughness::coefficients(Vec3::ONE, 1.0, 1.0);
    let material = s.add_material(Material {
        diffuse,
        specular,
        roughness,
        model: ReflectanceModel::TorranceSparrow,
        ambient: Vec3::ONE,
        texture: Some(base),
        metallic_roughness: Some(MetallicRoughness {
            base_color: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            texture: Some(mr),
        }),
        ..Material::default()
    });
    let sphere = s.add_mesh(primitives::uv_sphere(1.0, 48, 24));
    let object = (Geometry::Mesh(sphere), material);
    add_named(&mut s, "ball", object, Transform::default(), true);
    s.camera = camera(Vec3::new(0.0, 0.6, -3.4), Vec3::ZERO, 40.0);
    s.lights = vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.05,
        },
        Light::Directional {
            direction: Vec3::new(-0.4, -0.6, 0.7).normalize(),
            color: Vec3::ONE,
            intensity: 1.2,
        },
    ];
    set_environment(&mut s, sky_image(), 0.3, 0.0, false);
    s
}

fn render(scene: &Scene, technique: Technique) -> Film {
    let settings = RenderSettings {
        technique,
        width: 96,
        height: 96,
        shadows: ShadowMethod::None,
        ..RenderSettings::default()
    };
    let ctx = RenderContext::new(scene, &settings, &NoProgress).expect("valid scene");
    ScanConversion::DEFAULT.render(&ctx).expect("renders").0
}

/// Per channel mean of the pixels of `film` in columns `columns` that
/// show the sphere.
fn mean(film: &Film, columns: std::ops::Range<u32>) -> Vec3 {
    let (mut sum, mut n) = (Vec3::ZERO, 0.0);
    for (i, (c, d)) in film.color.iter().zip(&film.depth).enumerate() {
        let x = i as u32 % film.width;
        if d.is_finite() && columns.contains(&x) {
            sum += *c;
            n += 1.0;
        }
    }
    sum / n
}

/// Pearson correlation of channel `k` of `a` and `b` over the pixels where
/// both show the sphere.
fn correlation(a: &Film, b: &Film, k: usize) -> f64 {
    let pairs: Vec<(f64, f64)> = (0..a.color.len())
        .filter(|&i| a.depth[i].is_finite() && b.depth[i].is_finite())
        .map(|i| (f64::from(a.color[i][k]), f64::from(b.color[i][k])))
        .collect();
    let n = pairs.len() as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.0 / n, y + p.1 / n));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in &pairs {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// On each half (metal, dielectric) the per-channel means of flat and
/// Gouraud shading are within 0.75-1.33 of Phong shading's, and over the
/// sphere each channel correlates with Phong's by more than 0.85 (0.95-0.99
/// measured): the checks show on both halves. Before the colours were
/// applied per sample the whole sphere was lit as the untextured factors'
/// white metal (means 0.36-2.3x Phong's, correlations 0.05-0.14).
#[test]
fn flat_and_gouraud_keep_a_textured_metals_colours() {
    let scene = board();
    let phong = render(&scene, Technique::Phong);
    let halves = [("metal", 0..48), ("dielectric", 48..96)];
    for technique in [Technique::Flat, Technique::Gouraud] {
        let film = render(&scene, technique);
        for (name, columns) in halves.clone() {
            let want = mean(&phong, columns.clone());
            let got = mean(&film, columns);
            let ratio = got / want;
            assert!(
                ratio.cmpge(Vec3::splat(0.75)).all() && ratio.cmple(Vec3::splat(1.33)).all(),
                "{technique:?} {name}: mean {got} vs Phong's {want} (ratio {ratio})"
            );
        }
        for k in 0..3 {
            let r = correlation(&film, &phong, k);
            assert!(r > 0.85, "{technique:?} channel {k}: correlation {r}");
        }
    }
}
