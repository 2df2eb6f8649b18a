//! Small analytic scenes built in code, shared by tests across crates.

use chiaro_core::geometry::primitives;
use chiaro_core::scene::{
    Attenuation, Camera, Geometry, Light, Material, Object, Scene, ShadowMethod, Transform,
};
use glam::Vec3;

/// A sphere and a box on a plane, lit by one point light with inverse-square
/// attenuation, seen from above at an angle: the shadow test scene. All
/// geometry is triangles (the sphere tessellated), so every technique sees
/// the same surfaces. `size` is the image side in pixels.
pub fn shadow_test(size: u32) -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material {
        specular: Vec3::splat(0.3),
        shininess: 30.0,
        ..Material::diffuse("white", Vec3::splat(0.7))
    });
    let red = s.add_material(Material {
        specular: Vec3::splat(0.5),
        shininess: 60.0,
        ..Material::diffuse("red", Vec3::new(0.7, 0.15, 0.1))
    });
    let blue = s.add_material(Material::diffuse("blue", Vec3::new(0.15, 0.2, 0.7)));
    let plane = s.add_mesh(primitives::plane(4.0, 8));
    let sphere = s.add_mesh(primitives::uv_sphere(0.8, 32, 16));
    let cube = s.add_mesh(primitives::cube());
    s.objects.push(Object {
        name: "floor".into(),
        geometry: Geometry::Mesh(plane),
        material: white,
        smooth: false,
        ..Default::default()
    });
    s.objects.push(Object {
        name: "ball".into(),
        geometry: Geometry::Mesh(sphere),
        material: red,
        transform: Transform {
            translate: Vec3::new(-0.9, 0.8, 0.3),
            ..Default::default()
        },
        ..Default::default()
    });
    s.objects.push(Object {
        name: "box".into(),
        geometry: Geometry::Mesh(cube),
        material: blue,
        smooth: false,
        transform: Transform {
            translate: Vec3::new(1.2, 0.5, -0.4),
            rotate_degrees: Vec3::new(0.0, 25.0, 0.0),
            scale: Vec3::splat(0.5),
            ..Default::default()
        },
        ..Default::default()
    });
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 0.1,
    });
    s.lights.push(Light::Point {
        position: Vec3::new(-1.5, 5.0, -2.0),
        color: Vec3::ONE,
        intensity: 20.0,
        attenuation: Attenuation::InverseSquare,
    });
    s.camera = Camera {
        eye: Vec3::new(0.0, 4.5, -6.0),
        look_at: Vec3::new(0.0, 0.3, 0.0),
        fov_y_degrees: 45.0,
        ..Camera::default()
    };
    s.render.width = size;
    s.render.height = size;
    s.render.samples = 1;
    s.render.shadows = ShadowMethod::None;
    s
}
