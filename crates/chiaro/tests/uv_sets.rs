//! A texture that names the second uv set (`ImageTexture::uv_set = 1`, a
//! mesh's `uvs1`, glTF `TEXCOORD_1`) is looked up there by every technique:
//! the one rule lives in the surface layer's texture lookup.

use chiaro::scene::{
    Camera, Geometry, ImageTexture, Light, Material, MeshId, Object, Technique, Texture,
};
use chiaro::{NoProgress, Scene, Vec3};
use chiaro_core::Vec2;
use chiaro_core::geometry::primitives;

/// A white quad facing the camera whose base colour texture (red left
/// half, green right half) is read through `uv_set`; the first set points
/// at red, the second at green.
fn scene(uv_set: u8) -> Scene {
    let mut s = Scene::default();
    let tex = s.add_texture(Texture::Image(ImageTexture {
        uv_set,
        ..ImageTexture::new(
            "red|green".into(),
            2,
            1,
            vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0]],
        )
    }));
    let m = s.add_material(Material {
        texture: Some(tex),
        ambient: Vec3::splat(0.2),
        ..Material::diffuse("quad", Vec3::ONE)
    });
    let mut mesh = primitives::quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::X * 2.0, Vec3::Y * 2.0);
    let n = mesh.positions.len();
    mesh.uvs = vec![Vec2::new(0.25, 0.5); n];
    mesh.uvs1 = vec![Vec2::new(0.75, 0.5); n];
    let id: MeshId = s.add_mesh(mesh);
    s.objects.push(Object {
        geometry: Geometry::Mesh(id),
        material: m,
        ..Default::default()
    });
    s.lights.push(Light::Directional {
        direction: Vec3::NEG_Z,
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s.camera = Camera {
        eye: Vec3::new(0.0, 0.0, 3.0),
        look_at: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        near: 0.01,
        far: 100.0,
        ..Default::default()
    };
    s.render.width = 24;
    s.render.height = 24;
    s.render.samples = 4;
    s
}

#[test]
fn every_technique_reads_the_uv_set_a_texture_names() {
    for uv_set in [0u8, 1] {
        let mut s = scene(uv_set);
        for technique in Technique::ALL {
            s.render.technique = technique;
            let film = chiaro::render(&s, &s.render, &NoProgress)
                .unwrap_or_else(|e| panic!("{technique:?}: {e}"));
            let c = film.get(12, 12);
            let (want, other) = if uv_set == 1 { (c.y, c.x) } else { (c.x, c.y) };
            assert!(
                want > 0.05 && want > 10.0 * other,
                "{technique:?} with uv_set {uv_set}: centre {c}"
            );
        }
    }
}
