//! Shooting patches above elements: a floor of input triangles much finer
//! than the patch size, solved with patches and element by element.

use super::*;
use chiaro_testkit::scenes::{
    CORNELL_GREEN, CORNELL_RED, CORNELL_WHITE, add_object, add_quad, point_light,
};

/// The unit box with a floor of `2 n^2` triangles (object 0) and walls of
/// two triangles each (objects 1..6), lit by a point light under the
/// ceiling.
fn fine_floor_box(n: u32) -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material::diffuse("white", CORNELL_WHITE));
    let red = s.add_material(Material::diffuse("red", CORNELL_RED));
    let green = s.add_material(Material::diffuse("green", CORNELL_GREEN));
    let floor = s.add_mesh(primitives::plane(0.5, n));
    let place = Transform {
        translate: Vec3::new(0.5, 0.0, 0.5),
        ..Default::default()
    };
    add_object(&mut s, Geometry::Mesh(floor), white, place);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    add_quad(&mut s, y, x, z, white);
    add_quad(&mut s, Vec3::ZERO, x, y, white);
    add_quad(&mut s, Vec3::ZERO, y, z, red);
    add_quad(&mut s, x, z, y, green);
    add_quad(&mut s, z, y, x, white);
    s.lights.push(point_light(Vec3::new(0.5, 0.9, 0.5), 0.5));
    s
}

#[test]
fn patches_shoot_for_fine_triangles_and_agree_with_elements() {
    let s = fine_floor_box(16);
    let mut r = settings(Solver::Progressive, Method::Raycast, 0.34);
    r.radiosity.tolerance = 1e-3;
    let ctx = RenderContext::new(&s, &r, &NoProgress).expect("context");
    let clustered = solve_with(&ctx, true).expect("clustered");
    let elements = solve_with(&ctx, false).expect("element by element");
    let (cs, es) = (&clustered.stats, &elements.stats);
    println!(
        "{} elements, {} patches; {} shots with patches, {} by elements",
        cs.elements, cs.patches, cs.iterations, es.iterations
    );
    // 512 floor triangles (edge 1/16, under half the patch size) plus
    // 5 x 2 x 5^2 wall elements.
    assert_eq!(cs.elements, 512 + 5 * 50);
    let errs: Vec<f32> = object_means(&clustered, 6)
        .iter()
        .zip(&object_means(&elements, 6))
        .enumerate()
        .map(|(o, (a, b))| {
            let err = ((*a - *b) / *b).abs().max_element();
            println!("object {o}: {a} vs {b} ({err:.4})");
            err
        })
        .collect();
    assert_eq!(es.patches, es.elements);
    assert!(cs.patches < cs.elements / 2, "{} patches", cs.patches);
    assert!(
        cs.iterations < es.iterations / 2,
        "{} shots with patches vs {} by elements",
        cs.iterations,
        es.iterations
    );
    for (o, err) in errs.iter().enumerate() {
        assert!(*err < 0.01, "object {o}: {err}");
    }
}

#[test]
fn coarse_meshes_keep_one_element_per_patch() {
    // The Cornell box's input triangles are larger than the patch size: a
    // patch is the element itself, and the solution is the element-by-element one.
    let s = cornell();
    let r = settings(Solver::Progressive, Method::Raycast, 0.25);
    let ctx = RenderContext::new(&s, &r, &NoProgress).expect("context");
    let a = solve_with(&ctx, true).expect("patches");
    let b = solve_with(&ctx, false).expect("elements");
    assert_eq!(a.stats.patches, a.stats.elements);
    assert_eq!(a.element_radiance, b.element_radiance);
    assert_eq!(a.vertex_irradiance, b.vertex_irradiance);
}

/// Cancels at the `n`-th poll.
struct CancelAt(std::sync::atomic::AtomicU32, u32);

impl Progress for CancelAt {
    fn begin(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
    fn cancelled(&self) -> bool {
        self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed) >= self.1
    }
}

#[test]
fn meshing_the_direct_pass_and_shots_poll_for_cancellation() {
    let s = fine_floor_box(8);
    let r = settings(Solver::Progressive, Method::Raycast, 0.25);
    for at in 0..6 {
        let p = CancelAt(Default::default(), at);
        let out = solve(&s, &r, &p);
        assert!(
            matches!(out, Err(CoreError::Cancelled)),
            "poll {at}: {out:?}"
        );
    }
}
