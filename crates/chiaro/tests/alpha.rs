//! glTF alpha in every technique: a quad masked (or blended) by a texture
//! whose left half has alpha 0, in front of a red quad, lit head-on by a
//! directional light. Cut-out texels show the red quad, lit (the light
//! passes through them too); the covered half shows the white front quad.

use chiaro::scene::{
    AlphaMode, Filter, Geometry, ImageTexture, Light, Material, Object, ShadowMethod, Technique,
    Texture,
};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};

fn scene(mode: AlphaMode) -> Scene {
    let mut s = Scene::default();
    let mut img = ImageTexture::new(
        "mask".into(),
        2,
        1,
        vec![[1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 1.0, 1.0]],
    );
    img.mag_filter = Filter::Nearest;
    img.min_filter = Filter::Nearest;
    img.mip_filter = None;
    let tex = s.add_texture(Texture::Image(img));
    let front = s.add_material(Material {
        texture: Some(tex),
        alpha_mode: mode,
        ..Material::diffuse("front", Vec3::ONE)
    });
    let back = s.add_material(Material::diffuse("back", Vec3::new(1.0, 0.0, 0.0)));
    for (z, m, r) in [(0.0, front, 1.0), (-1.0, back, 3.0)] {
        let mesh = s.add_mesh(chiaro_testkit::scenes::square_mesh(r, z));
        s.objects.push(Object {
            geometry: Geometry::Mesh(mesh),
            material: m,
            ..Object::default()
        });
    }
    s.lights.push(Light::Directional {
        direction: Vec3::NEG_Z,
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s.camera.eye = Vec3::new(0.0, 0.0, 4.0);
    s.camera.look_at = Vec3::ZERO;
    s.camera.up = Vec3::Y;
    s.camera.fov_y_degrees = 30.0;
    s.background = Vec3::ZERO;
    s
}

fn render(s: &Scene, technique: Technique, shadows: ShadowMethod) -> Film {
    let mut r: RenderSettings = s.render.clone();
    r.width = 48;
    r.height = 48;
    r.technique = technique;
    r.shadows = shadows;
    r.samples = if technique == Technique::Path { 64 } else { 1 };
    chiaro::render(s, &r, &NoProgress).expect("renders")
}

/// The colour at film position `(x, y)` in `[0, 1]`.
fn at(f: &Film, x: f32, y: f32) -> Vec3 {
    let (px, py) = (
        (x * f.width as f32) as usize,
        (y * f.height as f32) as usize,
    );
    f.color[py * f.width as usize + px]
}

/// Left of the front quad: red (lit); right: white-ish (green > 0.3).
fn check(f: &Film, what: &str) {
    let left = at(f, 0.4, 0.5);
    let right = at(f, 0.6, 0.5);
    assert!(
        left.x > 0.3 && left.y < 0.05 && left.z < 0.05,
        "{what}: cut-out half should show the lit red quad, got {left}"
    );
    assert!(
        right.y > 0.3 && right.z > 0.3,
        "{what}: covered half should show the white quad, got {right}"
    );
}

#[test]
fn masked_quad_shows_the_quad_behind_in_every_technique() {
    let s = scene(AlphaMode::Mask { cutoff: 0.5 });
    for (t, sh) in [
        (Technique::Preview, ShadowMethod::None),
        (Technique::Flat, ShadowMethod::Ray),
        (Technique::Gouraud, ShadowMethod::Ray),
        (Technique::Phong, ShadowMethod::Ray),
        (Technique::Phong, ShadowMethod::None),
        (Technique::Phong, ShadowMethod::Map),
        (Technique::Whitted, ShadowMethod::Ray),
        (Technique::Path, ShadowMethod::Ray),
    ] {
        check(&render(&s, t, sh), &format!("{t:?} shadows {sh:?}"));
    }
}

#[test]
fn blended_quad_shows_its_texture_alpha_pattern() {
    let s = scene(AlphaMode::Blend);
    for t in [Technique::Phong, Technique::Whitted] {
        check(&render(&s, t, ShadowMethod::None), &format!("{t:?}"));
    }
}
