//! The lock-step kernel against the scalar loop on surfaces whose material
//! is resolved per hit: textured Lambert and glTF metal/rough materials,
//! normal maps and vertex colours, sample by sample.

use super::tests::{assert_samples_agree, bvh};
use super::*;
use chiaro_core::geometry::{Ray, primitives};
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{
    Distribution, Geometry, ImageTexture, Material, MetallicRoughness, Object, ReflectanceModel,
    Scene, Texture, TextureId, Transform, WrapMode,
};
use chiaro_testkit::scenes::repo_scene;

/// A 7 x 5 image (coprime sides, so texels do not line up with the
/// floor's two triangles) whose texel `(x, y)` has channel `k` equal to
/// `value(x, y, k)`.
fn image(s: &mut Scene, value: impl Fn(u32, u32, usize) -> f32) -> TextureId {
    let (w, h) = (7, 5);
    s.add_texture(Texture::Image(ImageTexture {
        source: "pattern".into(),
        width: w,
        height: h,
        texels: (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                [value(x, y, 0), value(x, y, 1), value(x, y, 2), 1.0]
            })
            .collect(),
        wrap: WrapMode::Repeat,
        ..Default::default()
    }))
}

/// A value in `[lo, hi]` that changes from texel to texel and channel to
/// channel (a small hash, not a smooth pattern).
fn texel(x: u32, y: u32, k: usize, lo: f32, hi: f32) -> f32 {
    let h = (x * 7 + y * 13 + k as u32 * 5) % 11;
    lo + (hi - lo) * h as f32 / 10.0
}

/// A glTF metal/rough material of base colour `base` (the factors at 1:
/// the textures give the values).
fn metal_rough(base: Option<TextureId>, mr: Option<TextureId>) -> Material {
    let (kd, ks, alpha) = MetallicRoughness::coefficients(Vec3::ONE, 1.0, 1.0);
    Material {
        metallic_roughness: Some(MetallicRoughness {
            base_color: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            texture: mr,
        }),
        texture: base,
        specular: ks,
        roughness: alpha,
        model: ReflectanceModel::TorranceSparrow,
        distribution: Distribution::Ggx,
        ..Material::diffuse("metal-rough", kd)
    }
}

/// The environment-lit spheres of the Mitsuba comparison
/// (benches/env_spheres.toml) at 12 x 12 pixels: a floor quad (with uvs)
/// and three analytic spheres under the studio map.
fn env_spheres() -> Scene {
    let mut s = repo_scene("benches/env_spheres.toml", 12);
    s.render.samples = 13;
    s
}

fn material<'s>(s: &'s mut Scene, name: &str) -> &'s mut Material {
    let id = s.material_by_name(name).expect("a bench material");
    &mut s.materials[id.index()]
}

/// Camera rays through the pixel centres of `scene` that hit a surface
/// the lock-step kernel shades from the material resolved at the hit
/// ([`PathTracer::surface_vertex`]: not a plain vertex, and `lock_step`
/// there): how many.
fn resolved_lock_step_hits(scene: &Scene) -> usize {
    let settings = &scene.render;
    let ctx = RenderContext::new(scene, settings, &NoProgress)
        .expect("a context")
        .with_accelerator(&bvh);
    let tracer = PathTracer::new(ctx.analytic(), ctx.analytic_accel(), settings, true);
    let (w, h) = (settings.width, settings.height);
    let cam = &scene.camera;
    let mut n = 0;
    for py in 0..h {
        for px in 0..w {
            let d = cam.ray_direction(px as f32 + 0.5, py as f32 + 0.5, w, h);
            let ray = Ray::new(cam.eye, d);
            let Some(hit) = tracer.accel.intersect_camera(&ray) else {
                continue;
            };
            let plain = tracer.plain_vertex(&ray, hit.t, hit.prim, hit.u, hit.v);
            n += usize::from(plain.is_none() && tracer.surface_vertex(&ray, &hit).1.lock_step);
        }
    }
    n
}

/// Asserts that `scene`'s samples agree bit for bit between the loops,
/// that enough of them saw light, that at least `resolved` pixel centres
/// see a per-hit material the kernel shades, and that no lane left the
/// kernel at a vertex (every material of these scenes is lock-step).
fn assert_kernel_shades(scene: &Scene, what: &str, resolved: usize) {
    let hits = resolved_lock_step_hits(scene);
    assert!(hits >= resolved, "{what}: {hits} resolved lock-step hits");
    lanes::HANDED_OFF.set(0);
    assert!(assert_samples_agree(scene, what) > 1000, "{what}: dark");
    let left = lanes::HANDED_OFF.get();
    assert_eq!(
        left, 0,
        "{what}: lanes handed to the scalar loop at a vertex"
    );
}

#[test]
fn lock_step_kernel_equals_the_scalar_loop_on_a_textured_lambert_surface() {
    let mut s = env_spheres();
    let tex = image(&mut s, |x, y, k| texel(x, y, k, 0.1, 0.9));
    material(&mut s, "floor").texture = Some(tex);
    // The analytic Lambert sphere textured too (its uvs are spherical).
    material(&mut s, "matte").texture = Some(tex);
    assert_kernel_shades(&s, "textured Lambert", 60);
}

#[test]
fn lock_step_kernel_equals_the_scalar_loop_on_a_textured_metal_rough_surface() {
    let mut s = env_spheres();
    let base = image(&mut s, |x, y, k| texel(x, y, k, 0.1, 0.9));
    // glTF's channels: roughness in G, metallic in B.
    let mr = image(&mut s, |x, y, k| match k {
        1 => texel(x, y, k, 0.2, 1.0),
        _ => texel(x, y, k, 0.0, 1.0),
    });
    *material(&mut s, "floor") = metal_rough(Some(base), Some(mr));
    *material(&mut s, "rough") = metal_rough(None, Some(mr));
    assert_kernel_shades(&s, "textured metal/rough", 60);
}

#[test]
fn lock_step_kernel_equals_the_scalar_loop_on_a_normal_mapped_surface() {
    let mut s = env_spheres();
    // Tangent-space normals tilted by up to about 27 degrees, encoded as
    // glTF stores them (`0.5 n + 0.5`).
    let map = image(&mut s, |x, y, k| {
        let t = Vec3::new(texel(x, y, 0, -0.5, 0.5), texel(x, y, 1, -0.5, 0.5), 1.0);
        0.5 * t.normalize()[k] + 0.5
    });
    material(&mut s, "floor").normal_map = Some(map);
    let base = image(&mut s, |x, y, k| texel(x, y, k, 0.3, 0.9));
    let mut mapped = metal_rough(Some(base), None);
    mapped.normal_map = Some(map);
    *material(&mut s, "rough") = mapped;
    assert_kernel_shades(&s, "normal-mapped", 60);
}

#[test]
fn lock_step_kernel_equals_the_scalar_loop_on_a_vertex_coloured_surface() {
    let mut s = env_spheres();
    // The Lambert and the rough sphere replaced by meshes of the same
    // size whose vertices carry colours (Lambert, and glTF metal/rough).
    let coloured = |name: &str| {
        let mut m = primitives::uv_sphere(0.5, 24, 12);
        m.name = name.into();
        m.colors = m
            .positions
            .iter()
            .map(|p| (*p * 0.8 + 0.5).clamp(Vec3::splat(0.05), Vec3::ONE))
            .collect();
        m
    };
    let matte = s.material_by_name("matte").expect("a bench material");
    let rough = s.add_material(metal_rough(None, None));
    s.objects
        .retain(|o| !matches!(o.geometry, Geometry::Sphere { .. }));
    for (x, name, material) in [(-1.2, "matte", matte), (0.0, "rough", rough)] {
        let mesh = s.add_mesh(coloured(name));
        s.objects.push(Object {
            geometry: Geometry::Mesh(mesh),
            material,
            transform: Transform {
                translate: Vec3::new(x, 0.5, 0.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }
    assert_kernel_shades(&s, "vertex-coloured", 12);
}
