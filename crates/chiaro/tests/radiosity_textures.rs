//! Radiosity keeps textures: patches are solved with one albedo each, and
//! the picture is drawn with the textured colour at each pixel times the
//! patch irradiance (display-time texture modulation). A checkered floor
//! alone under a point light receives only direct light, so its irradiance
//! does not depend on its albedo: the textured picture divided by the
//! untextured one (albedo the checker's mean) is the texture divided by its
//! mean at every pixel, and the two pictures have the same mean.

use chiaro::{Film, NoProgress, Scene, Vec3};
use std::path::Path;

const A: [f32; 3] = [0.8, 0.5, 0.2];
const B: [f32; 3] = [0.2, 0.4, 0.6];

/// A 4x4 floor seen from straight above its centre, a corner of four
/// checker cells, lit by a point light above the centre: a quarter turn
/// about the vertical axis maps the view onto itself and swaps the colours.
fn floor(diffuse_or_texture: &str) -> Scene {
    let text = format!(
        r#"
background = [0, 0, 0]
camera = {{ eye = [0, 5, 0], look_at = [0, 0, 0], up = [0, 0, 1], fov = 30 }}
light = [{{ type = "point", position = [0, 3, 0], intensity = 9, attenuation = "inverse_square" }}]
[render]
technique = "radiosity"
width = 48
height = 48
samples = 1
[material.floor]
{diffuse_or_texture}
[[object]]
primitive = "plane"
size = 4
material = "floor"
"#
    );
    chiaro::io::load_scene_str(&text, Path::new("."), "floor.toml")
        .expect("loads")
        .scene
}

fn render(scene: &Scene) -> Film {
    let film = chiaro::render(scene, &scene.render, &NoProgress).expect("renders");
    assert!(film.is_clean(), "no NaN or negative pixel");
    film
}

fn mean(film: &Film) -> Vec3 {
    film.color.iter().copied().sum::<Vec3>() / film.color.len() as f32
}

#[test]
fn radiosity_draws_the_texture_times_the_irradiance() {
    let (a, b) = (Vec3::from(A), Vec3::from(B));
    let m = 0.5 * (a + b);
    let textured = render(&floor(&format!(
        "diffuse = [1, 1, 1]\ntexture = {{ procedural = \"checker\", scale = 2, color_a = {A:?}, color_b = {B:?} }}"
    )));
    let plain = render(&floor(&format!("diffuse = {:?}", m.to_array())));

    // Per pixel: textured / plain is a / m or b / m (each channel within 2 %).
    let (ra, rb) = (a / m, b / m);
    let (mut na, mut nb) = (0usize, 0usize);
    let (mut sa, mut sb) = (Vec3::ZERO, Vec3::ZERO);
    for (i, (t, p)) in textured.color.iter().zip(&plain.color).enumerate() {
        assert!(
            p.min_element() > 0.05,
            "pixel {i}: the floor fills the view, got {p}"
        );
        let r = *t / *p;
        let near = |x: Vec3| ((r - x) / x).abs().max_element() < 0.02;
        if near(ra) {
            na += 1;
            sa += *t;
        } else if near(rb) {
            nb += 1;
            sb += *t;
        } else {
            panic!("pixel {i}: textured / untextured = {r}, expected {ra} or {rb}");
        }
    }
    let n = textured.color.len();
    assert!(na * 10 >= n * 4 && nb * 10 >= n * 4, "{na} and {nb} of {n}");
    // The two colours' pixels see the same irradiance (the quarter turn):
    // their means are in the texture's ratio.
    let ratio = (sa / na as f32) / (sb / nb as f32);
    assert!(
        ((ratio - a / b) / (a / b)).abs().max_element() < 0.02,
        "colour ratio {ratio}, texture's {}",
        a / b
    );
    // And the picture's mean is the untextured solve's.
    let (mt, mp) = (mean(&textured), mean(&plain));
    assert!(
        ((mt - mp) / mp).abs().max_element() < 0.01,
        "mean {mt} against the untextured {mp}"
    );
}

#[test]
fn zero_reflectance_gives_black_not_nan() {
    // A black floor: the irradiance cannot be recovered from its radiance
    // (L / rho); it shows black, and a half-black checker keeps its lit half.
    let black = render(&floor("diffuse = [0, 0, 0]"));
    assert!(black.color.iter().all(|c| *c == Vec3::ZERO));
    let half = render(&floor(
        "diffuse = [1, 1, 1]\ntexture = { procedural = \"checker\", scale = 2, color_a = [0.8, 0.8, 0.8], color_b = [0, 0, 0] }",
    ));
    let lit = half.color.iter().filter(|c| c.min_element() > 0.05).count();
    let dark = half.color.iter().filter(|c| **c == Vec3::ZERO).count();
    let n = half.color.len();
    assert!(
        lit * 10 >= n * 4 && dark * 10 >= n * 4,
        "{lit} lit, {dark} black of {n}"
    );
}
