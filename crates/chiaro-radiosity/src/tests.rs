//! Whole-crate tests on small scenes built in code: form factors against
//! closed forms, the furnace, reciprocity and row sums, solver agreement
//! and colour bleeding on the Cornell box, settings errors, save/load and
//! the display.

use super::*;
use chiaro_core::geometry::primitives;
use chiaro_core::prepared::PrepareOptions;
use chiaro_core::progress::{NoProgress, Progress};
use chiaro_core::scene::{Geometry, Light, Material, MaterialId, RenderSettings, Transform};
use chiaro_testkit::scenes::{
    CORNELL_GREEN, CORNELL_RED, CORNELL_WHITE, add_object, add_quad, add_unit_box, point_light,
    unit_cornell_box,
};

/// [`super::solve`] through a render context of `scene` with `settings`.
fn solve(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<RadiositySolution, CoreError> {
    super::solve(&RenderContext::new(scene, settings, progress)?)
}

/// [`super::render_solution`] through a render context.
fn render_solution(
    scene: &Scene,
    solution: &RadiositySolution,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    super::render_solution(&RenderContext::new(scene, settings, progress)?, solution)
}

/// The radiosity technique through a render context.
fn render(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<Film, CoreError> {
    Radiosity
        .render(&RenderContext::new(scene, settings, progress)?)
        .map(|(film, _)| film)
}

/// The unit Cornell box (objects: 0 floor, 1 ceiling, 2 back, 3 left
/// (red), 4 right (green), 5 short block, 6 tall block).
fn cornell() -> Scene {
    unit_cornell_box()
}

fn settings(solver: Solver, ff: Method, patch: f32) -> RenderSettings {
    let mut r = RenderSettings {
        width: 48,
        height: 48,
        ..Default::default()
    };
    r.radiosity.solver = solver;
    r.radiosity.formfactor = ff;
    r.radiosity.patch_size = patch;
    r.radiosity.hemicube_resolution = 64;
    r.radiosity.tolerance = 1e-4;
    r
}

/// The form factors of `method` over `mesh`'s elements: hemicubes of `res`
/// pixels in a scene of diagonal `size`, ray-cast visibility through `vis`,
/// `tol` the facing tolerance of the pair methods.
fn form_factors<'a>(
    method: Method,
    mesh: &'a ElementMesh,
    res: u32,
    size: f32,
    vis: Visibility<'a>,
    tol: f32,
) -> Box<dyn FormFactor + 'a> {
    match method {
        Method::Hemicube => Box::new(hemicube::HemicubeFormFactor::new(
            &mesh.elements,
            &mesh.vertices,
            res,
            size,
        )),
        Method::Raycast => Box::new(PairFormFactor::raycast(&mesh.elements, vis, tol)),
        Method::Analytic => Box::new(PairFormFactor::analytic(&mesh.elements, tol)),
    }
}

/// `F` from object 0 to object 1 of `scene`, summed over elements:
/// `F_01 = sum_{i in 0} A_i sum_{j in 1} F_ij / A_0`.
fn object_form_factor(scene: &Scene, patch: f32, method: Method, res: u32) -> f32 {
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    let mesh = mesh::build(&ps, patch, false, &NoProgress).expect("mesh");
    let accel = chiaro_core::accel::instanced::build_accelerator(&ps);
    let size = ps.bounds.diagonal();
    let vis = Visibility {
        accel: accel.as_ref(),
        eps: size * 1e-4,
    };
    let ff = form_factors(method, &mesh, res, size, vis, size * 1e-6);
    let obj = |e: &Element| mesh.sources[e.source as usize].object;
    let n = mesh.elements.len();
    let mut col = vec![0.0; n];
    let mut sum = 0.0f64;
    for j in 0..n {
        if obj(&mesh.elements[j]) != 1 {
            continue;
        }
        ff.column(j, &mut col);
        for (i, e) in mesh.elements.iter().enumerate() {
            if obj(e) == 0 {
                sum += (e.area * col[i]) as f64;
            }
        }
    }
    let a0: f32 = mesh
        .elements
        .iter()
        .filter(|e| obj(e) == 0)
        .map(|e| e.area)
        .sum();
    (sum / a0 as f64) as f32
}

/// Asserts that every method's `F` from object 0 to object 1 of `s`
/// (elements of `patch` size, hemicubes of 128 pixels) is `expect` within
/// 1 % (analytic, ray-cast) or 2 % (hemicube).
fn assert_methods_match(s: &Scene, patch: f32, expect: f32) {
    for (method, tol) in [
        (Method::Analytic, 0.01),
        (Method::Raycast, 0.01),
        (Method::Hemicube, 0.02),
    ] {
        let f = object_form_factor(s, patch, method, 128);
        assert!(
            ((f - expect) / expect).abs() < tol,
            "{}: {f} vs {expect}",
            method.name()
        );
    }
}

#[test]
fn perpendicular_rectangles_all_methods_match_closed_form() {
    // A 1 x 1.5 floor and a 1 x 1 wall sharing the unit edge along x.
    let mut s = Scene::default();
    s.add_material(Material::default());
    add_quad(
        &mut s,
        Vec3::ZERO,
        Vec3::new(0.0, 0.0, 1.5),
        Vec3::X,
        MaterialId(0),
    );
    add_quad(&mut s, Vec3::ZERO, Vec3::X, Vec3::Y, MaterialId(0));
    assert_methods_match(&s, 0.15, perpendicular_rectangles(1.5, 1.0, 1.0));
}

#[test]
fn coaxial_discs_all_methods_match_closed_form() {
    let mut s = Scene::default();
    s.add_material(Material::default());
    let (r, h, seg) = (1.0f32, 1.0f32, 48u32);
    for (y, flip) in [(0.0f32, false), (h, true)] {
        let m = s.add_mesh(primitives::disk(r, seg));
        let place = Transform {
            translate: Vec3::new(0.0, y, 0.0),
            rotate_degrees: Vec3::new(if flip { 180.0 } else { 0.0 }, 0.0, 0.0),
            ..Default::default()
        };
        add_object(&mut s, Geometry::Mesh(m), MaterialId(0), place);
    }
    // The polygonal discs have the area of a disc of this radius.
    let r_eq = (0.5 * seg as f32 * (std::f32::consts::TAU / seg as f32).sin()
        / std::f32::consts::PI)
        .sqrt()
        * r;
    assert_methods_match(&s, 0.25, disc_to_disc(r_eq, r_eq, h));
}

#[test]
fn closed_box_form_factors_are_reciprocal_and_rows_sum_to_one() {
    let mut s = Scene::default();
    s.add_material(Material::default());
    add_unit_box(&mut s, [MaterialId(0); 6], true);
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    let mesh = mesh::build(&ps, 0.5, false, &NoProgress).expect("mesh");
    let accel = chiaro_core::accel::instanced::build_accelerator(&ps);
    let vis = Visibility {
        accel: accel.as_ref(),
        eps: 1e-4,
    };
    let el = &mesh.elements;
    let n = el.len();
    for method in [Method::Raycast, Method::Hemicube] {
        let vis = Visibility {
            accel: vis.accel,
            eps: vis.eps,
        };
        let ff = form_factors(method, &mesh, 256, 2.0, vis, 1e-6);
        // f[i][j] = F_ij, from the method's natural output.
        let mut f = vec![vec![0.0f32; n]; n];
        for i in 0..n {
            let mut c = vec![0.0; n];
            if method == Method::Hemicube {
                assert!(ff.row(i, &mut c));
                f[i] = c;
            } else {
                ff.column(i, &mut c);
                for (fj, cj) in f.iter_mut().zip(&c) {
                    fj[i] = *cj;
                }
            }
        }
        for (i, row) in f.iter().enumerate() {
            let sum: f32 = row.iter().sum();
            assert!(
                (sum - 1.0).abs() < 0.01,
                "{}: row {i} sums to {sum}",
                method.name()
            );
        }
        let mut worst = 0.0f32;
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (el[i].area * f[i][j], el[j].area * f[j][i]);
                // A hemicube samples F_ij at the centre of i only, which is
                // not accurate for near pairs (Wallace et al. 1989): check it
                // on pairs farther apart than a few element sizes.
                let near = el[i].c.distance_squared(el[j].c) < 9.0 * el[i].area.max(el[j].area);
                // It also aliases: an element covering few pixels has a
                // large relative error, so check pairs with F above 0.01
                // (a few hundred pixels at this resolution).
                if method == Method::Hemicube && (near || f[i][j].min(f[j][i]) < 0.01) {
                    continue;
                }
                if a.max(b) > 1e-3 * el[i].area {
                    worst = worst.max((a - b).abs() / a.max(b));
                }
            }
        }
        let limit = if method == Method::Hemicube {
            0.1
        } else {
            0.05
        };
        assert!(
            worst < limit,
            "{}: reciprocity error {worst}",
            method.name()
        );
    }
}

/// The largest relative difference of `a` from `b` over the channels.
fn relative_error(a: Vec3, b: Vec3) -> f32 {
    ((a - b) / b).abs().max_element()
}

/// Solves `s` (elements of `patch` size) with each case's solver and form
/// factors, and hands each solution to `check` with the case's name
/// ("solver/form factors") and tolerance.
fn for_each_solver(
    s: &Scene,
    patch: f32,
    cases: &[(Solver, Method, f32)],
    check: impl Fn(&RadiositySolution, &str, f32),
) {
    for &(solver, ff, tol) in cases {
        let sol = solve(s, &settings(solver, ff, patch), &NoProgress).expect("solve");
        check(&sol, &format!("{}/{}", solver.name(), ff.name()), tol);
    }
}

/// Progressive refinement with ray-cast form factors, elements of `patch`
/// size: the solution of `s`.
fn solve_progressive(s: &Scene, patch: f32) -> RadiositySolution {
    solve(
        s,
        &settings(Solver::Progressive, Method::Raycast, patch),
        &NoProgress,
    )
    .expect("solve")
}

/// A 2 x 2 floor quad of albedo `rho` at y = 0 under a white point light of
/// intensity 8 at height 2 (object 0).
fn lit_floor(rho: f32) -> Scene {
    let mut s = Scene::default();
    s.add_material(Material::diffuse("m", Vec3::splat(rho)));
    add_quad(
        &mut s,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 0.0),
        MaterialId(0),
    );
    s.lights.push(point_light(Vec3::new(0.0, 2.0, 0.0), 8.0));
    s
}

/// The furnace: a closed unit box of albedo `rho` emitting `e` from every
/// wall, whose radiance is `e / (1 - rho)` everywhere.
pub(crate) fn furnace(rho: f32, e: Vec3) -> Scene {
    let mut s = Scene::default();
    let mut m = Material::diffuse("furnace", Vec3::splat(rho));
    m.emission = e;
    s.add_material(m);
    add_unit_box(&mut s, [MaterialId(0); 6], true);
    s
}

#[test]
fn furnace_gives_e_over_one_minus_rho_for_every_solver() {
    let rho = 0.6f32;
    let e = Vec3::new(1.0, 0.5, 0.25);
    let s = furnace(rho, e);
    let expect = e / (1.0 - rho);
    // Every solver with ray-cast form factors, and Gauss-Seidel with the
    // hemicube and analytic ones, each within 1 %. Not progressive with
    // hemicubes: shooting with hemicubes uses F_ji = F_ij A_i / A_j from a
    // hemicube at the shooter's centre only, so power is conserved but its
    // spread carries the point-sampling error of near patches (up to ~7% per
    // element on this coarse mesh).
    let raycast = [Solver::Jacobi, Solver::Progressive, Solver::Hierarchical];
    let cases: Vec<_> = (raycast.map(|solver| (solver, Method::Raycast)).into_iter())
        .chain([Method::Hemicube, Method::Analytic].map(|ff| (Solver::GaussSeidel, ff)))
        .map(|(solver, ff)| (solver, ff, 0.01))
        .collect();
    for_each_solver(&s, 0.34, &cases, |sol, case, tol| {
        // The first element off by `tol` or more (or NaN), if any.
        let off = (sol.element_radiance().iter().enumerate()).find(|(_, l)| {
            relative_error(**l, expect).partial_cmp(&tol) != Some(std::cmp::Ordering::Less)
        });
        assert!(off.is_none(), "{case}: element {off:?} vs {expect}");
    });
}

/// The mean radiance of each of the first `n` objects.
fn object_means(sol: &RadiositySolution, n: u32) -> Vec<Vec3> {
    (0..n)
        .map(|o| sol.object_mean_radiance(o).expect("object"))
        .collect()
}

#[test]
fn solvers_agree_on_the_cornell_box_and_the_ceiling_is_pink() {
    let s = cornell();
    let reference = solve(
        &s,
        &settings(Solver::GaussSeidel, Method::Raycast, 0.25),
        &NoProgress,
    )
    .expect("gs");
    let ref_means = object_means(&reference, 7);
    let cases = [
        (Solver::Jacobi, Method::Raycast, 0.01),
        (Solver::Progressive, Method::Raycast, 0.01),
        (Solver::Hierarchical, Method::Raycast, 0.04),
        // Point-sampled hemicubes are less accurate for near patches
        // (Wallace et al. 1989), and these patches are coarse.
        (Solver::Progressive, Method::Hemicube, 0.1),
        (Solver::GaussSeidel, Method::Hemicube, 0.1),
    ];
    for_each_solver(&s, 0.25, &cases, |sol, case, tol| {
        for (o, (a, b)) in object_means(sol, 7).iter().zip(&ref_means).enumerate() {
            let err = relative_error(*a, *b);
            assert!(err < tol, "{case}: object {o}: {a} vs {b} ({err})");
        }
    });
    // Colour bleeding: the ceiling near the red wall is redder than near the green wall.
    let near_red = reference
        .radiance_at(1, Vec3::new(0.05, 1.0, 0.5), -Vec3::Y)
        .expect("ceiling");
    let near_green = reference
        .radiance_at(1, Vec3::new(0.95, 1.0, 0.5), -Vec3::Y)
        .expect("ceiling");
    assert!(
        near_red.x / near_red.y > 1.1 * near_green.x / near_green.y,
        "{near_red} vs {near_green}"
    );
    // The tall block's face towards the red wall is tinted red.
    assert!(ref_means[1].x > ref_means[1].z);
}

#[test]
fn energy_is_conserved_in_the_open_cornell_box() {
    // Power leaving all surfaces (emission excluded) never exceeds the
    // emitted power times the largest albedo's geometric series.
    let s = cornell();
    let sol = solve_progressive(&s, 0.3);
    let mut emitted = Vec3::ZERO;
    let mut reflected = Vec3::ZERO;
    for (e, t) in sol.triangles().iter().enumerate() {
        let c = t.map(|i| sol.vertices()[i as usize]);
        let a = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
        emitted += sol.element_emission()[e] * a;
        reflected += (sol.element_radiance()[e] - sol.element_emission()[e]) * a;
    }
    let rho_max = CORNELL_WHITE.max(CORNELL_RED).max(CORNELL_GREEN);
    let bound = emitted * rho_max / (Vec3::ONE - rho_max);
    assert!(reflected.cmple(bound).all(), "{reflected} > {bound}");
    assert!(reflected.min_element() > 0.0);
}

#[test]
fn point_light_direct_matches_the_shading_convention() {
    // A single floor quad under a point light: no interreflection, so the
    // radiance is rho * Ip * cos / d^2 (the radiometric convention, ARCHITECTURE.md).
    let mut s = lit_floor(0.5);
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 10.0,
    });
    let sol = solve_progressive(&s, 0.05);
    let l = sol.radiance_at(0, Vec3::ZERO, Vec3::Y).expect("floor");
    // rho * Ip / d^2 = 0.5 * 8 / 4 = 1 straight below.
    assert!((l.x - 1.0).abs() < 0.02, "{l}");
    let p = Vec3::new(0.8, 0.0, 0.0);
    let d2 = p.distance_squared(Vec3::new(0.0, 2.0, 0.0));
    let expect = 0.5 * 8.0 * (2.0 / d2.sqrt()) / d2;
    let l = sol.radiance_at(0, p, Vec3::Y).expect("floor");
    assert!((l.x - expect).abs() < 0.03 * expect, "{l} vs {expect}");
}

#[test]
fn the_ambient_correction_adds_nothing_where_no_shot_light_lands() {
    // A lone bright floor under a point light, stopped after one shot: its
    // unshot light leaves the scene, so the estimate of what is not yet
    // shot must add nothing (Cohen's closed-room R = 1 / (1 - rho) = 20
    // would add twenty times the unshot radiance).
    let s = lit_floor(0.95);
    let mut r = settings(Solver::Progressive, Method::Raycast, 0.25);
    r.radiosity.max_iterations = 1;
    let sol = solve(&s, &r, &NoProgress).expect("solve");
    let l = sol.radiance_at(0, Vec3::ZERO, Vec3::Y).expect("floor");
    // rho * Ip / d^2 = 0.95 * 8 / 4 straight below.
    assert!((l.x - 1.9).abs() < 0.05, "{l}");
}

#[test]
fn save_load_round_trip_and_refuse_another_scene() {
    let s = cornell();
    let sol = solve_progressive(&s, 0.4);
    let mut bytes = Vec::new();
    sol.save(&mut bytes).expect("save");
    let back = RadiositySolution::load(bytes.as_slice(), &s).expect("load");
    assert_eq!(back, sol);
    let mut other = s.clone();
    other.materials[1].diffuse = Vec3::splat(0.5);
    let err = RadiositySolution::load(bytes.as_slice(), &other).expect_err("other scene");
    assert!(err.to_string().contains("does not match"), "{err}");
    assert!(RadiositySolution::load(&b"{not json"[..], &s).is_err());
    assert!(
        render_solution(
            &other,
            &sol,
            &settings(Solver::Progressive, Method::Raycast, 0.4),
            &NoProgress
        )
        .is_err()
    );
}

#[test]
fn cornell_render_is_clean_and_shows_colour_bleeding() {
    let s = cornell();
    let r = settings(Solver::Hierarchical, Method::Raycast, 0.125);
    let film = render(&s, &r, &NoProgress).expect("render");
    assert!(film.is_clean());
    let (w, h) = (film.width, film.height);
    // Left wall red, right wall green, at mid height.
    let left = film.get(w / 10, h / 2);
    let right = film.get(w - 1 - w / 10, h / 2);
    assert!(
        left.x > 2.0 * left.y && right.y > 1.5 * right.x,
        "{left} {right}"
    );
    if let Ok(dir) = std::env::var("CHIARO_RADIOSITY_PNG") {
        // Look at it: a larger picture of the same kind of solution.
        let mut big = r.clone();
        (big.width, big.height, big.samples) = (256, 256, 4);
        let film = render(&s, &big, &NoProgress).expect("render");
        let (w, h) = (film.width, film.height);
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let c = film.get(x, y);
            let f = |v: f32| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0) as u8;
            image::Rgb([f(c.x), f(c.y), f(c.z)])
        });
        let _ = img.save(format!("{dir}/cornell_radiosity.png"));
    }
}

#[path = "tests_patches.rs"]
mod patches;
