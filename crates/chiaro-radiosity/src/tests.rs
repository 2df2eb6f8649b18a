//! Whole-crate tests on small scenes built in code: form factors against
//! closed forms, the furnace, reciprocity and row sums, solver agreement
//! and colour bleeding on the Cornell box, settings errors, save/load and
//! the display.

use super::*;
use chiaro_core::geometry::primitives;
use chiaro_core::prepared::PrepareOptions;
use chiaro_core::progress::{NoProgress, Progress};
use chiaro_core::scene::RenderSettings;
use chiaro_core::scene::{
    AreaShape, Attenuation, Camera, Geometry, Light, Material, Object, Transform,
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

const WHITE: Vec3 = Vec3::new(0.725, 0.71, 0.68);
const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);

fn add_quad(s: &mut Scene, corner: Vec3, eu: Vec3, ev: Vec3, material: u32) {
    let m = s.add_mesh(primitives::quad(corner, eu, ev));
    s.objects.push(Object {
        geometry: Geometry::Mesh(m),
        material: chiaro_core::scene::MaterialId(material),
        smooth: false,
        ..Default::default()
    });
}

/// The unit box's walls, all facing inwards: floor, ceiling, back, left,
/// right, and (if `closed`) front, as objects 0..5 (6).
fn unit_box(s: &mut Scene, mats: [u32; 6], closed: bool) {
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    add_quad(s, Vec3::ZERO, z, x, mats[0]);
    add_quad(s, y, x, z, mats[1]);
    add_quad(s, Vec3::ZERO, x, y, mats[2]);
    add_quad(s, Vec3::ZERO, y, z, mats[3]);
    add_quad(s, x, z, y, mats[4]);
    if closed {
        add_quad(s, z, y, x, mats[5]);
    }
}

/// A small Cornell box (unit size, official RGB albedos, a ceiling light
/// of radiance (17, 12, 4)). Objects: 0 floor, 1 ceiling, 2 back, 3 left
/// (red), 4 right (green), 5 short block, 6 tall block.
fn cornell() -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material::diffuse("white", WHITE)).0;
    let red = s.add_material(Material::diffuse("red", RED)).0;
    let green = s.add_material(Material::diffuse("green", GREEN)).0;
    unit_box(&mut s, [white, white, white, red, green, white], false);
    for (half, at, rot) in [
        (Vec3::splat(0.15), Vec3::new(0.34, 0.15, 0.62), -17.0f32),
        (Vec3::new(0.15, 0.3, 0.15), Vec3::new(0.66, 0.3, 0.36), 17.0),
    ] {
        let m = s.add_mesh(primitives::box_mesh(half));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            material: chiaro_core::scene::MaterialId(white),
            smooth: false,
            transform: Transform {
                translate: at,
                rotate_degrees: Vec3::new(0.0, rot, 0.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }
    s.lights.push(Light::Area {
        shape: AreaShape::Quad {
            corner: Vec3::new(0.375, 0.999, 0.4),
            edge_u: Vec3::new(0.25, 0.0, 0.0),
            edge_v: Vec3::new(0.0, 0.0, 0.2),
        },
        color: Vec3::new(17.0, 12.0, 4.0),
        intensity: 1.0,
        two_sided: false,
    });
    s.camera = Camera {
        eye: Vec3::new(0.5, 0.5, 2.3),
        look_at: Vec3::new(0.5, 0.5, 0.0),
        up: Vec3::Y,
        fov_y_degrees: 32.0,
        near: 0.01,
        far: 100.0,
    };
    s
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
    let tol = size * 1e-6;
    let hemi;
    let pairs;
    let ff: &dyn FormFactor = match method {
        Method::Hemicube => {
            hemi = hemicube::HemicubeFormFactor::new(&mesh.elements, &mesh.vertices, res, size);
            &hemi
        }
        Method::Raycast => {
            pairs = PairFormFactor::raycast(&mesh.elements, vis, tol);
            &pairs
        }
        Method::Analytic => {
            pairs = PairFormFactor::analytic(&mesh.elements, tol);
            &pairs
        }
    };
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

#[test]
fn perpendicular_rectangles_all_methods_match_closed_form() {
    // A 1 x 1.5 floor and a 1 x 1 wall sharing the unit edge along x.
    let mut s = Scene::default();
    s.add_material(Material::default());
    add_quad(&mut s, Vec3::ZERO, Vec3::new(0.0, 0.0, 1.5), Vec3::X, 0);
    add_quad(&mut s, Vec3::ZERO, Vec3::X, Vec3::Y, 0);
    let expect = perpendicular_rectangles(1.5, 1.0, 1.0);
    for (method, tol) in [
        (Method::Analytic, 0.01),
        (Method::Raycast, 0.01),
        (Method::Hemicube, 0.02),
    ] {
        let f = object_form_factor(&s, 0.15, method, 128);
        assert!(
            ((f - expect) / expect).abs() < tol,
            "{}: {f} vs {expect}",
            method.name()
        );
    }
}

#[test]
fn coaxial_discs_all_methods_match_closed_form() {
    let mut s = Scene::default();
    s.add_material(Material::default());
    let (r, h, seg) = (1.0f32, 1.0f32, 48u32);
    for (y, flip) in [(0.0f32, false), (h, true)] {
        let m = s.add_mesh(primitives::disk(r, seg));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            smooth: false,
            transform: Transform {
                translate: Vec3::new(0.0, y, 0.0),
                rotate_degrees: Vec3::new(if flip { 180.0 } else { 0.0 }, 0.0, 0.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }
    // The polygonal discs have the area of a disc of this radius.
    let r_eq = (0.5 * seg as f32 * (std::f32::consts::TAU / seg as f32).sin()
        / std::f32::consts::PI)
        .sqrt()
        * r;
    let expect = disc_to_disc(r_eq, r_eq, h);
    for (method, tol) in [
        (Method::Analytic, 0.01),
        (Method::Raycast, 0.01),
        (Method::Hemicube, 0.02),
    ] {
        let f = object_form_factor(&s, 0.25, method, 128);
        assert!(
            ((f - expect) / expect).abs() < tol,
            "{}: {f} vs {expect}",
            method.name()
        );
    }
}

#[test]
fn closed_box_form_factors_are_reciprocal_and_rows_sum_to_one() {
    let mut s = Scene::default();
    s.add_material(Material::default());
    unit_box(&mut s, [0; 6], true);
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
        let hemi;
        let pairs;
        let ff: &dyn FormFactor = match method {
            Method::Hemicube => {
                hemi = hemicube::HemicubeFormFactor::new(el, &mesh.vertices, 256, 2.0);
                &hemi
            }
            _ => {
                pairs = PairFormFactor::raycast(
                    el,
                    Visibility {
                        accel: vis.accel,
                        eps: vis.eps,
                    },
                    1e-6,
                );
                &pairs
            }
        };
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

#[test]
fn furnace_gives_e_over_one_minus_rho_for_every_solver() {
    let rho = 0.6f32;
    let e = Vec3::new(1.0, 0.5, 0.25);
    let mut s = Scene::default();
    let mut m = Material::diffuse("furnace", Vec3::splat(rho));
    m.emission = e;
    s.add_material(m);
    unit_box(&mut s, [0; 6], true);
    let expect = e / (1.0 - rho);
    for (solver, ff, tol) in [
        (Solver::Jacobi, Method::Raycast, 0.01),
        (Solver::GaussSeidel, Method::Hemicube, 0.01),
        (Solver::Progressive, Method::Raycast, 0.01),
        (Solver::Hierarchical, Method::Raycast, 0.01),
        (Solver::GaussSeidel, Method::Analytic, 0.01),
        // Not ("progressive", "hemicube"): shooting with hemicubes uses
        // F_ji = F_ij A_i / A_j from a hemicube at the shooter's centre only,
        // so power is conserved but its spread carries the point-sampling
        // error of near patches (up to ~7% per element on this coarse mesh).
    ] {
        let sol = solve(&s, &settings(solver, ff, 0.34), &NoProgress).expect("solve");
        for (k, l) in sol.element_radiance().iter().enumerate() {
            let err = ((*l - expect) / expect).abs().max_element();
            assert!(
                err < tol,
                "{}/{}: element {k} has {l} vs {expect}",
                solver.name(),
                ff.name()
            );
        }
    }
}

fn wall_means(sol: &RadiositySolution) -> Vec<Vec3> {
    (0..7)
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
    let ref_means = wall_means(&reference);
    for (solver, ff, tol) in [
        (Solver::Jacobi, Method::Raycast, 0.01),
        (Solver::Progressive, Method::Raycast, 0.01),
        (Solver::Hierarchical, Method::Raycast, 0.04),
        // Point-sampled hemicubes are less accurate for near patches
        // (Wallace et al. 1989), and these patches are coarse.
        (Solver::Progressive, Method::Hemicube, 0.1),
        (Solver::GaussSeidel, Method::Hemicube, 0.1),
    ] {
        let sol = solve(&s, &settings(solver, ff, 0.25), &NoProgress).expect("solve");
        for (o, (a, b)) in wall_means(&sol).iter().zip(&ref_means).enumerate() {
            let err = ((*a - *b) / *b).abs().max_element();
            assert!(
                err < tol,
                "{}/{}: object {o}: {a} vs {b} ({err})",
                solver.name(),
                ff.name()
            );
        }
    }
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
    let sol = solve(
        &s,
        &settings(Solver::Progressive, Method::Raycast, 0.3),
        &NoProgress,
    )
    .expect("solve");
    let mut emitted = Vec3::ZERO;
    let mut reflected = Vec3::ZERO;
    for (e, t) in sol.triangles().iter().enumerate() {
        let c = t.map(|i| sol.vertices()[i as usize]);
        let a = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
        emitted += sol.element_emission()[e] * a;
        reflected += (sol.element_radiance()[e] - sol.element_emission()[e]) * a;
    }
    let rho_max = WHITE.max(RED).max(GREEN);
    let bound = emitted * rho_max / (Vec3::ONE - rho_max);
    assert!(reflected.cmple(bound).all(), "{reflected} > {bound}");
    assert!(reflected.min_element() > 0.0);
}

#[test]
fn point_light_direct_matches_the_shading_convention() {
    // A single floor quad under a point light: no interreflection, so the
    // radiance is rho * Ip * cos / d^2 (the radiometric convention, ARCHITECTURE.md).
    let mut s = Scene::default();
    s.add_material(Material::diffuse("m", Vec3::splat(0.5)));
    add_quad(
        &mut s,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 0.0),
        0,
    );
    s.lights.push(Light::Point {
        position: Vec3::new(0.0, 2.0, 0.0),
        color: Vec3::ONE,
        intensity: 8.0,
        attenuation: Attenuation::InverseSquare,
    });
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 10.0,
    });
    let sol = solve(
        &s,
        &settings(Solver::Progressive, Method::Raycast, 0.05),
        &NoProgress,
    )
    .expect("solve");
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
    let mut s = Scene::default();
    s.add_material(Material::diffuse("m", Vec3::splat(0.95)));
    add_quad(
        &mut s,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 0.0),
        0,
    );
    s.lights.push(Light::Point {
        position: Vec3::new(0.0, 2.0, 0.0),
        color: Vec3::ONE,
        intensity: 8.0,
        attenuation: Attenuation::InverseSquare,
    });
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
    let sol = solve(
        &s,
        &settings(Solver::Progressive, Method::Raycast, 0.4),
        &NoProgress,
    )
    .expect("solve");
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
