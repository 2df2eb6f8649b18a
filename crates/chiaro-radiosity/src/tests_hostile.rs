//! Hostile geometry (issue 47): duplicated, coincident and overlapping
//! faces, light trapped with an albedo of 1, and very bright emitters.
//! Every solver must end, quickly, and say so when it did not converge.

use super::*;
use crate::formfactor::facing;
use chiaro_core::geometry::primitives;
use chiaro_core::scene::{Geometry, Light, Material, Mesh, Object, RenderSettings};
use chiaro_testkit::Warnings;

fn add(s: &mut Scene, mesh: Mesh, material: u32, name: &str) {
    let id = s.add_mesh(mesh);
    s.objects.push(Object {
        name: name.into(),
        geometry: Geometry::Mesh(id),
        material: chiaro_core::scene::MaterialId(material),
        smooth: false,
        ..Object::default()
    });
}

/// Two tilted quads sharing an edge, each given twice (the issue's
/// ten-line OBJ), placed at `offset` from the origin, lit from above.
fn duplicated_quads(offset: Vec3, albedo: f32) -> Scene {
    let p = [
        Vec3::new(0.1, 0.2, 0.3),
        Vec3::new(1.37, 0.51, -0.23),
        Vec3::new(1.11, 1.73, 0.41),
        Vec3::new(-0.17, 1.42, 0.97),
        Vec3::new(0.3, -0.9, 1.7),
        Vec3::new(1.9, -0.3, 2.1),
    ];
    let mesh = Mesh {
        name: "dup".into(),
        positions: p.iter().map(|q| *q + offset).collect(),
        indices: vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 1, 2],
            [0, 2, 3],
            [1, 0, 4],
            [1, 4, 5],
            [1, 0, 4],
            [1, 4, 5],
        ],
        ..Mesh::default()
    };
    let mut s = Scene::default();
    let m = s
        .add_material(Material::diffuse("white", Vec3::splat(albedo)))
        .0;
    add(&mut s, mesh, m, "dup");
    s.lights.push(Light::Directional {
        direction: Vec3::new(-0.3, -1.0, -0.4).normalize(),
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s
}

fn settings(solver: Solver, ff: Method) -> RenderSettings {
    let mut r = RenderSettings::default();
    r.radiosity.solver = solver;
    r.radiosity.formfactor = ff;
    r
}

/// Every solver with each form factor it accepts.
fn every_solver() -> Vec<(Solver, Method)> {
    let mut v = Vec::new();
    for solver in [
        Solver::Jacobi,
        Solver::GaussSeidel,
        Solver::Progressive,
        Solver::Hierarchical,
    ] {
        for ff in [Method::Raycast, Method::Analytic, Method::Hemicube] {
            if !(solver == Solver::Hierarchical && ff == Method::Hemicube) {
                v.push((solver, ff));
            }
        }
    }
    v
}

/// Solves `scene` and returns the solution and its warnings.
fn run(scene: &Scene, settings: &RenderSettings) -> (RadiositySolution, Vec<String>) {
    let w = Warnings::default();
    let sol = solve(&RenderContext::new(scene, settings, &w).expect("valid")).expect("solves");
    (sol, w.into_vec())
}

/// Coplanar elements exchange no light, even far from the origin where the
/// plane distance of a coincident vertex is rounding noise larger than
/// the size-scaled tolerance.
#[test]
fn coincident_and_coplanar_elements_do_not_face() {
    for offset in [0.0, 1e3, 1e5] {
        let o = Vec3::new(offset, -2.0 * offset, 0.5 * offset);
        let p = [
            o + Vec3::new(0.1, 0.2, 0.3),
            o + Vec3::new(1.37, 0.51, -0.23),
            o + Vec3::new(1.11, 1.73, 0.41),
        ];
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
        let a = mesh::Element::new(p, n, Vec3::ONE, Vec3::ZERO, [0; 3], 0);
        // The same triangle, and one overlapping it in the same plane.
        let b = a;
        let q = [p[0], (p[1] + p[2]) * 0.5, p[2] + (p[2] - p[1]) * 0.3];
        let c = mesh::Element::new(q, n, Vec3::ONE, Vec3::ZERO, [0; 3], 1);
        let tol = 3.0 * 1e-6;
        assert!(!facing(&a, &b, tol), "coincident at {offset}");
        assert!(!facing(&a, &c, tol), "overlapping at {offset}");
        // A triangle folded up from an edge does face it.
        let up = [p[0], p[1], p[0] + n + (p[1] - p[0]) * 0.5];
        let m = (up[2] - up[0]).cross(up[1] - up[0]).normalize();
        let d = mesh::Element::new(up, m, Vec3::ONE, Vec3::ZERO, [0; 3], 2);
        assert!(
            facing(&a, &d, tol) == facing(&d, &a, tol),
            "symmetric at {offset}"
        );
    }
}

/// The duplicated faces, near and far from the origin, dim and
/// with an albedo of 1 (where each copy lighting the other face's two
/// copies doubles the gain of the fold and the light grows without
/// bound): every solver and form factor ends within seconds with finite
/// radiance, and warns exactly when it did not converge. (Loading a file
/// drops the duplicates themselves: chiaro-io's `dedupe_faces`.)
#[test]
fn duplicated_faces_end_quickly_with_every_solver() {
    for offset in [Vec3::ZERO, Vec3::new(1e4, 2e4, -5e3)] {
        for albedo in [0.8, 1.0] {
            let scene = duplicated_quads(offset, albedo);
            for (solver, ff) in every_solver() {
                let s = settings(solver, ff);
                let (sol, warnings) = run(&scene, &s);
                let what = format!("{solver:?} {ff:?} at {offset}, albedo {albedo}");
                assert!(sol.element_radiance.iter().all(|v| v.is_finite()), "{what}");
                let converged = sol.stats.unshot < s.radiosity.tolerance;
                assert_eq!(warnings.is_empty(), converged, "{what}: {warnings:?}");
            }
        }
    }
}

/// A closed box whose walls glow and reflect everything (albedo 1):
/// light never leaves, so no solver can converge. Each stops on the stall
/// criterion (or its iteration budget) and warns, naming the solver and
/// an object, instead of running to 100,000 iterations.
#[test]
fn trapped_light_stops_with_a_warning() {
    let mut scene = Scene::default();
    let mut glow = Material::diffuse("white-glow", Vec3::ONE);
    glow.emission = Vec3::splat(0.1);
    let white = scene.add_material(glow).0;
    let mut walls = primitives::box_mesh(Vec3::ONE);
    for t in &mut walls.indices {
        t.swap(1, 2);
    }
    walls.normals.clear();
    add(&mut scene, walls, white, "cell");
    for (solver, ff) in every_solver() {
        let mut s = settings(solver, ff);
        s.radiosity.patch_size = 0.5;
        let (sol, warnings) = run(&scene, &s);
        assert!(
            sol.stats.iterations < 5_000,
            "{solver:?} {ff:?}: {:?}",
            sol.stats
        );
        let w = warnings.join("\n");
        assert!(
            w.contains("radiosity did not converge") && w.contains(solver.name()),
            "{solver:?} {ff:?}: {w:?} {:?}",
            sol.stats
        );
        if solver != Solver::Hierarchical {
            assert!(w.contains("object \"cell\""), "{w}");
        }
    }
}

/// The iteration budget is a count, not a time: a solve cut at 5 shots
/// stops there, warns, and gives the same solution twice.
#[test]
fn the_budget_is_deterministic() {
    let scene = duplicated_quads(Vec3::ZERO, 0.8);
    let mut s = settings(Solver::Progressive, Method::Raycast);
    s.radiosity.max_iterations = 5;
    s.radiosity.tolerance = 1e-6;
    let (a, wa) = run(&scene, &s);
    let (b, _) = run(&scene, &s);
    assert_eq!(a.stats.iterations, 5);
    assert_eq!(a.element_radiance, b.element_radiance);
    assert!(
        wa.iter().any(|w| w.contains("radiosity.max_iterations")),
        "{wa:?}"
    );
}

/// A very bright emitter (radiance 5120, the Duck) over a floor:
/// the solve is relative to the emitted power, so it takes the same
/// iterations as at radiance 1 and scales the result exactly.
#[test]
fn a_very_bright_emitter_converges_like_a_dim_one() {
    let scene_with = |radiance: f32| {
        let mut s = Scene::default();
        let floor = s
            .add_material(Material::diffuse("floor", Vec3::splat(0.7)))
            .0;
        let mut glow = Material::diffuse("glow", Vec3::splat(0.5));
        glow.emission = Vec3::splat(radiance);
        let glow = s.add_material(glow).0;
        add(
            &mut s,
            primitives::quad(Vec3::new(-2.0, 0.0, -2.0), Vec3::Z * 4.0, Vec3::X * 4.0),
            floor,
            "floor",
        );
        let mut ball = primitives::uv_sphere(0.5, 12, 8);
        for p in &mut ball.positions {
            p.y += 1.0;
        }
        add(&mut s, ball, glow, "ball");
        s
    };
    for solver in [Solver::Progressive, Solver::Hierarchical] {
        let s = settings(solver, Method::Raycast);
        let (dim, wd) = run(&scene_with(1.0), &s);
        let (bright, wb) = run(&scene_with(5120.0), &s);
        assert!(wd.is_empty() && wb.is_empty(), "{wd:?} {wb:?}");
        assert_eq!(dim.stats.iterations, bright.stats.iterations, "{solver:?}");
        for (d, b) in dim.element_radiance.iter().zip(&bright.element_radiance) {
            assert!(
                (*b - *d * 5120.0).abs().max_element() <= 1e-3 * b.max_element() + 1e-3,
                "{solver:?}: {d} vs {b}"
            );
        }
    }
}
