//! The environment map as a radiosity source, against closed forms under a
//! constant map: a convex body reflects `rho c` (it sees the whole map over
//! every front hemisphere, and nothing of itself), and a white open box is
//! a white furnace (`L = c` everywhere, whatever its shape).

use super::*;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::{
    Environment, Geometry, ImageTexture, Material, MaterialId, Object, RenderSettings, Texture,
    WrapMode,
};
use chiaro_testkit::scenes::add_unit_box;

/// Gives `s` a constant environment map of radiance `c`.
fn constant_environment(s: &mut Scene, c: Vec3) {
    let t = s.add_texture(Texture::Image(ImageTexture {
        source: "constant".into(),
        width: 16,
        height: 8,
        texels: vec![c.extend(1.0).into(); 16 * 8],
        wrap: WrapMode::Repeat,
        ..Default::default()
    }));
    s.environment = Some(Environment {
        texture: t,
        intensity: 1.0,
        rotate_y_degrees: 30.0,
        as_background: false,
    });
}

fn settings(solver: Solver, ff: Method, patch: f32) -> RenderSettings {
    let mut r = RenderSettings {
        width: 32,
        height: 32,
        ..Default::default()
    };
    r.radiosity.solver = solver;
    r.radiosity.formfactor = ff;
    r.radiosity.patch_size = patch;
    r.radiosity.tolerance = 1e-4;
    r
}

fn solve(scene: &Scene, settings: &RenderSettings) -> RadiositySolution {
    let ctx = RenderContext::new(scene, settings, &NoProgress).expect("valid");
    super::solve(&ctx).expect("solves")
}

/// Per channel: the mean over elements of `l / expect`, its standard error (the elements' estimates are independent: each has
/// its own generator) and the largest deviation from `expect`.
fn element_stats(l: &[Vec3], expect: Vec3) -> (Vec3, Vec3, f32) {
    let n = l.len() as f32;
    let r: Vec<Vec3> = l.iter().map(|l| *l / expect).collect();
    let mean = r.iter().sum::<Vec3>() / n;
    let var = r.iter().map(|x| (*x - mean) * (*x - mean)).sum::<Vec3>() / (n - 1.0);
    let worst = r
        .iter()
        .map(|x| (*x - Vec3::ONE).abs().max_element())
        .fold(0.0f32, f32::max);
    (mean, (var / n).powf(0.5), worst)
}

/// Every solver with ray-cast form factors, and Gauss-Seidel with analytic
/// ones.
const CASES: [(Solver, Method); 4] = [
    (Solver::Jacobi, Method::Raycast),
    (Solver::GaussSeidel, Method::Analytic),
    (Solver::Progressive, Method::Raycast),
    (Solver::Hierarchical, Method::Raycast),
];

#[test]
fn a_convex_body_under_a_constant_map_reflects_rho_times_its_radiance() {
    let (rho, c) = (0.8f32, Vec3::new(0.5, 0.25, 1.0));
    let mut s = Scene::default();
    s.add_material(Material::diffuse("white", Vec3::splat(rho)));
    s.objects.push(Object {
        name: "ball".into(),
        geometry: Geometry::Sphere { radius: 1.0 },
        material: MaterialId(0),
        ..Default::default()
    });
    constant_environment(&mut s, c);
    let expect = c * rho;
    for (solver, ff) in CASES {
        let set = settings(solver, ff, 0.4);
        let sol = solve(&s, &set);
        let (mean, se, worst) = element_stats(sol.element_radiance(), expect);
        let case = format!("{}/{}", solver.name(), ff.name());
        eprintln!(
            "{case}: {} elements, mean ratio {mean} (se {se}), worst {worst:.4}",
            sol.element_count()
        );
        // The mean within four standard errors of the closed form; every
        // element within 10 %.
        let z = ((mean - Vec3::ONE).abs() / se.max(Vec3::splat(1e-6))).max_element();
        assert!(z < 4.0, "{case}: mean ratio {mean}, {z:.1} standard errors");
        assert!(worst < 0.1, "{case}: an element {worst:.3} off");
        // Fixed seeds: the same solution, bit for bit.
        if solver == Solver::Hierarchical {
            assert_eq!(sol.element_radiance(), solve(&s, &set).element_radiance());
        }
    }
}

#[test]
fn a_white_open_box_under_a_constant_map_is_a_furnace() {
    // rho = 1 everywhere: L = c is the solution of the rendering equation
    // inside and outside, so every element shows the map's radiance after
    // any number of bounces (light leaves through the open front).
    let c = Vec3::new(0.75, 0.5, 0.25);
    let mut s = Scene::default();
    s.add_material(Material::diffuse("white", Vec3::ONE));
    add_unit_box(&mut s, [MaterialId(0); 6], false);
    constant_environment(&mut s, c);
    for (solver, ff) in CASES {
        let sol = solve(&s, &settings(solver, ff, 0.2));
        let (mean, se, worst) = element_stats(sol.element_radiance(), c);
        let case = format!("{}/{}", solver.name(), ff.name());
        eprintln!(
            "{case}: {} elements, mean ratio {mean} (se {se}), worst {worst:.4}",
            sol.element_count()
        );
        // The form factors' rows sum to 1 within 1 % (tests.rs), an error
        // that white walls amplify by `1 / (1 - F)` (about 2): the mean
        // within 2 %, every element within 15 % (the gather's noise).
        assert!(
            (mean - Vec3::ONE).abs().max_element() < 0.02,
            "{case}: mean ratio {mean} (se {se})"
        );
        assert!(worst < 0.15, "{case}: an element {worst:.3} off");
    }
}

#[test]
fn without_an_environment_nothing_is_gathered() {
    // The map's intensity at zero is no light at all: the scene without
    // it gives the same solution, bit for bit.
    let mut s = Scene::default();
    s.add_material(Material::diffuse("white", Vec3::splat(0.7)));
    add_unit_box(&mut s, [MaterialId(0); 6], false);
    s.lights.push(chiaro_testkit::scenes::point_light(
        Vec3::new(0.5, 0.8, 0.5),
        1.0,
    ));
    let set = settings(Solver::Hierarchical, Method::Raycast, 0.25);
    let plain = solve(&s, &set);
    constant_environment(&mut s, Vec3::ONE);
    if let Some(env) = &mut s.environment {
        env.intensity = 0.0;
    }
    assert_eq!(plain.element_radiance(), solve(&s, &set).element_radiance());
}
