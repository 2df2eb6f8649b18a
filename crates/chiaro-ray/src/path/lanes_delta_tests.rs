//! The lock-step kernel against the scalar loop at delta vertices (mirror,
//! smooth conductor, glass from outside and inside, total internal
//! reflection): every sample bit for bit, and the kernel, not the scalar
//! loop, sampling those vertices.

use super::*;
use chiaro_core::scene::ComplexIor;

/// The delta vertices the kernel samples (this thread) while `f` runs.
fn kernel_deltas(f: impl FnOnce()) -> u64 {
    let count = || lanes::KERNEL_DELTAS.with(|c| c.get());
    let before = count();
    f();
    count() - before
}

fn glass(s: &mut Scene) -> chiaro_core::scene::MaterialId {
    s.add_material(Material {
        transmit: Vec3::ONE,
        ior: 1.5,
        fresnel: true,
        ..Material::diffuse("glass", Vec3::ZERO)
    })
}

#[test]
fn kernel_keeps_mirror_and_conductor_vertices() {
    // A mirror sphere, a gold-like smooth conductor sphere and the green
    // wall a mirror: chains of mirror bounces, each in the kernel.
    let mut s = mitsuba_cbox(10);
    let mirror = s.add_material(Material {
        reflect: Vec3::ONE,
        ..Material::diffuse("mirror", Vec3::ZERO)
    });
    let gold = s.add_material(Material {
        reflect: Vec3::ONE,
        conductor: Some(ComplexIor {
            eta: Vec3::new(0.18, 0.42, 1.37),
            k: Vec3::new(3.42, 2.35, 1.77),
        }),
        ..Material::diffuse("gold", Vec3::ZERO)
    });
    add_sphere(&mut s, mirror, 0.3, Vec3::new(-0.45, -0.6, -0.3));
    add_sphere(&mut s, gold, 0.3, Vec3::new(0.45, -0.6, 0.3));
    let green = s.material_by_name("green").expect("shipped").index();
    s.materials[green] = Material {
        reflect: Vec3::splat(0.9),
        ..Material::diffuse("green", Vec3::ZERO)
    };
    s.render.samples = 19;
    s.render.path.max_depth = 10;
    s.render.path.rr_depth = 3;
    let n = kernel_deltas(|| assert!(assert_samples_agree(&s, "mirrors") > 1000));
    assert!(n > 100, "{n} delta vertices in the kernel");
}

#[test]
fn kernel_keeps_glass_seen_from_outside_and_inside() {
    // A glass sphere in the box (entered and left: Fresnel choices from
    // both sides, each moving the lane's pairs on), then a glass block
    // beside it, inside which light that came in through one face meets
    // the next beyond the critical angle (41.8 degrees): total internal
    // reflection.
    let mut s = mitsuba_cbox(10);
    let g = glass(&mut s);
    add_sphere(&mut s, g, 0.35, Vec3::new(0.2, -0.5, 0.2));
    s.render.samples = 21;
    s.render.path.max_depth = 12;
    s.render.path.rr_depth = 2;
    let n = kernel_deltas(|| assert!(assert_samples_agree(&s, "glass sphere") > 1000));
    assert!(n > 100, "{n} delta vertices in the kernel");
    let block = s.add_mesh(primitives::box_mesh(Vec3::new(0.25, 0.3, 0.25)));
    let at = Transform {
        translate: Vec3::new(-0.4, -0.5, -0.1),
        ..Default::default()
    };
    add_object(&mut s, Geometry::Mesh(block), g, at);
    let n = kernel_deltas(|| assert!(assert_samples_agree(&s, "glass block") > 1000));
    assert!(n > 200, "{n} delta vertices in the kernel");
    assert_kernels_agree(&s, "glass block, films");
}

#[test]
fn kernel_keeps_the_glass_and_mirror_box() {
    // The Mitsuba comparison's scene, then the mixed box of
    // `delta_box` (fixed-weight mirror-and-transmission: a lobe number).
    let mut s = repo_scene("benches/glass_cbox.toml", 10);
    s.render.samples = 17;
    let n = kernel_deltas(|| assert!(assert_samples_agree(&s, "glass box") > 1000));
    assert!(n > 100, "{n} delta vertices in the kernel");
    let mut s = delta_box(10);
    one_emitter_triangle(&mut s);
    let n = kernel_deltas(|| assert!(assert_samples_agree(&s, "delta box") > 1000));
    assert!(n > 100, "{n} delta vertices in the kernel");
}
