//! Tests of the two-level BVH against brute force and the flat BVH.

use super::*;
use crate::accel::list::ListAccel;
use crate::geometry::offset_ray_origin;
use crate::geometry::primitives::{cube, cylinder, icosphere};
use crate::sampling::{
    pixel_rng, sample_uniform_sphere, sample_uniform_triangle, uniform, uniform2,
};
use crate::scene::{Camera, Material};
use rayon::prelude::*;

/// Objects of [`instanced_scene`] that instance the icosphere.
const ICOSPHERES: usize = 24;

/// One icosphere instanced [`ICOSPHERES`] times under random rotations,
/// non-uniform scales and translations (one instance mirrored, one
/// sheared by a full matrix), a cube with one out-of-range triangle
/// (dropped by `PreparedScene`) instanced twice, a cylinder used once,
/// an analytic sphere and a floor.
fn instanced_scene() -> Scene {
    let mut s = Scene::default();
    s.add_material(Material::default());
    let ico = s.add_mesh(icosphere(1.0, 2));
    let mut broken_cube = cube();
    broken_cube.indices.insert(3, [0, 1, 999]);
    let cube_id = s.add_mesh(broken_cube);
    let cyl = s.add_mesh(cylinder(0.5, 2.0, 24));
    let floor = s.add_mesh(crate::geometry::primitives::plane(12.0, 4));
    let mut rng = pixel_rng(11, 0, 0, 0);
    for k in 0..ICOSPHERES {
        let mut scale = Vec3::new(
            0.3 + 1.2 * uniform(&mut rng),
            0.3 + 1.2 * uniform(&mut rng),
            0.3 + 1.2 * uniform(&mut rng),
        );
        let mut matrix = Mat4::IDENTITY;
        if k == 3 {
            scale.y = -scale.y;
        }
        if k == 5 {
            matrix = Mat4::from_cols(
                Vec4::new(1.0, 0.0, 0.0, 0.0),
                Vec4::new(0.4, 1.0, 0.0, 0.0),
                Vec4::new(0.0, -0.3, 1.0, 0.0),
                Vec4::new(0.0, 0.0, 0.0, 1.0),
            );
        }
        s.objects.push(Object {
            geometry: Geometry::Mesh(ico),
            transform: Transform {
                translate: Vec3::new(
                    (k % 6) as f32 * 3.0 - 7.5,
                    (k / 6) as f32 * 2.5 - 2.0 + uniform(&mut rng),
                    4.0 * uniform(&mut rng) - 2.0,
                ),
                rotate_degrees: Vec3::new(
                    360.0 * uniform(&mut rng),
                    360.0 * uniform(&mut rng),
                    360.0 * uniform(&mut rng),
                ),
                scale,
                matrix,
            },
            ..Object::default()
        });
    }
    for (t, r) in [
        (Vec3::new(-3.0, -3.0, 3.0), 20.0),
        (Vec3::new(3.0, -3.0, 3.0), -35.0),
    ] {
        s.objects.push(Object {
            geometry: Geometry::Mesh(cube_id),
            transform: Transform {
                translate: t,
                rotate_degrees: Vec3::new(0.0, r, 0.0),
                scale: Vec3::new(1.0, 0.5, 0.8),
                ..Transform::default()
            },
            smooth: false,
            ..Object::default()
        });
    }
    s.objects.push(Object {
        geometry: Geometry::Mesh(cyl),
        transform: Transform {
            translate: Vec3::new(0.0, -2.0, 3.5),
            rotate_degrees: Vec3::new(10.0, 0.0, 30.0),
            ..Transform::default()
        },
        ..Object::default()
    });
    place(
        &mut s,
        Geometry::Sphere { radius: 1.2 },
        Vec3::new(0.5, 0.0, 4.0),
    );
    place(&mut s, Geometry::Mesh(floor), Vec3::new(0.0, -4.0, 0.0));
    s.camera = Camera {
        eye: Vec3::new(0.0, 3.0, 18.0),
        look_at: Vec3::new(0.0, 0.0, 0.0),
        fov_y_degrees: 50.0,
        ..Camera::default()
    };
    s
}

fn prepare(s: &Scene, analytic_spheres: bool) -> PreparedScene<'_> {
    PreparedScene::new(
        s,
        PrepareOptions {
            analytic_spheres,
            tessellation: crate::geometry::tessellation::Tessellation::Fixed(16),
        },
    )
}

/// Random rays: half from anywhere around the scene in uniform
/// directions, half aimed at random triangles with unnormalised
/// directions.
fn random_rays(ps: &PreparedScene<'_>, count: u32, seed: u64) -> Vec<Ray> {
    (0..count)
        .map(|i| {
            let mut rng = pixel_rng(seed, i, 0, 0);
            let o = crate::accel::random_origin(ps, &mut rng);
            if i % 2 == 0 {
                Ray::new(o, sample_uniform_sphere(uniform2(&mut rng)))
            } else {
                let t = (uniform(&mut rng) * ps.triangles.len() as f32) as u32
                    % ps.triangles.len() as u32;
                let uv = sample_uniform_triangle(uniform2(&mut rng));
                let target = ps.triangle_surface(t, uv.x, uv.y).p;
                Ray::new(o, (target - o) * 0.7)
            }
        })
        .collect()
}

/// The smallest barycentric of a triangle hit (distance to an edge in
/// barycentric units).
fn edge_distance(h: &Hit) -> f32 {
    h.u.min(h.v).min(1.0 - h.u - h.v)
}

/// True when `a` (ours) and `b` (the oracle) are the same hit on prim
/// `prim` of `ray` up to rounding. Away from grazing angles (|cos| of
/// the ray and face normal >= 0.05) `t` must agree within 1e-5
/// relative and the points named by the two `(u, v)` within 1e-5 of
/// the scene's scale (the watertight test's edge functions lose
/// precision with the distance to the ray origin, so barycentrics of a
/// small far triangle carry absolute, not relative, rounding). At
/// grazing angles rounding of
/// the plane moves the hit along the ray by about (error / cos), so
/// the hits must agree across the plane (|dt| |d| |cos| <= 1e-5 of
/// the scene's scale) and our `(u, v)` must name the point at our `t`.
fn same_hit(ps: &PreparedScene<'_>, ray: &Ray, a: &Hit, b: &Hit) -> bool {
    let scale = ray
        .at(b.t)
        .abs()
        .max_element()
        .max(ray.origin.abs().max_element())
        .max(1.0);
    if a.prim >= ps.triangles.len() as u32 {
        return (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0);
    }
    let cos = ps.face_normal(a.prim).dot(ray.dir.normalize()).abs();
    let p = ps.triangle_surface(a.prim, a.u, a.v).p;
    if cos >= 0.05 {
        let q = ps.triangle_surface(b.prim, b.u, b.v).p;
        (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0) && (p - q).length() <= 1e-5 * scale
    } else {
        (a.t - b.t).abs() * ray.dir.length() * cos <= 1e-5 * scale
            && (p - ray.at(a.t)).length() <= 1e-4 * scale
    }
}

/// Compares closest and any hits with the brute-force oracle: the same
/// hit ([`same_hit`]), or a tie on a shared edge (a different prim at
/// the same `t`, both hits within 1e-4 of an edge), at most 1 in 2000
/// rays. Returns the number of such ties.
fn check_against_oracle(ps: &PreparedScene<'_>, accel: &InstancedBvh, rays: &[Ray]) -> usize {
    let list = ListAccel::new(ps);
    let nt = ps.triangles.len() as u32;
    let results: Vec<Result<bool, String>> = rays
        .par_iter()
        .map(|r| {
            let a = accel.intersect(r);
            let b = list.intersect(r);
            let mut tie = false;
            let same = match (a, b) {
                (None, None) => true,
                (Some(a), Some(b)) if a.prim == b.prim => same_hit(ps, r, &a, &b),
                (Some(a), Some(b)) => {
                    tie = true;
                    (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0)
                        && a.prim < nt
                        && b.prim < nt
                        && edge_distance(&a) < 1e-4
                        && edge_distance(&b) < 1e-4
                }
                _ => false,
            };
            let occ_same = accel.occluded(r) == b.is_some();
            if same && occ_same {
                Ok(tie)
            } else {
                Err(format!("{r:?}: instanced {a:?} list {b:?}"))
            }
        })
        .collect();
    let errors: Vec<&String> = results.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(
        errors.is_empty(),
        "{} mismatches of {}, first: {}",
        errors.len(),
        rays.len(),
        errors[0]
    );
    let ties = results.iter().filter(|r| matches!(r, Ok(true))).count();
    assert!(ties * 2000 <= rays.len(), "{ties} edge ties");
    ties
}

#[test]
fn instances_share_one_bottom_level_per_mesh() {
    let s = instanced_scene();
    let ps = prepare(&s, true);
    let bvh = InstancedBvh::new(&ps);
    // Icosphere and cube shared; cylinder, floor and sphere flat.
    assert_eq!(bvh.level_count(), 3);
    assert_eq!(bvh.instance_count(), ICOSPHERES + 2 + 1);
    // The cube keeps 12 of its 13 triangles.
    assert_eq!(duplicated_triangles(&ps), (ICOSPHERES - 1) * 320 + 12);
    // The shared meshes are stored once: less memory than the flat BVH.
    let flat = scene_bvh_memory_bytes(&SceneBvh::new(&ps));
    assert!(
        bvh.memory_bytes() * 5 < flat,
        "{} vs {flat}",
        bvh.memory_bytes()
    );
}

/// Every hit along `ray`, sorted by prim and `t`.
fn all_hits(accel: &dyn Accelerator, ray: &Ray) -> Vec<Hit> {
    let mut hits = Vec::new();
    let stopped = accel.for_each_hit(ray, &mut |h| {
        hits.push(*h);
        false
    });
    assert!(!stopped, "no visit asked to stop");
    hits.sort_by(|a, b| a.prim.cmp(&b.prim).then(a.t.total_cmp(&b.t)));
    hits
}

#[test]
fn every_hit_matches_brute_force() {
    let s = instanced_scene();
    for analytic in [true, false] {
        let ps = prepare(&s, analytic);
        let nt = ps.triangles.len() as u32;
        let list = ListAccel::new(&ps);
        let accels: [Box<dyn Accelerator>; 2] = [
            Box::new(InstancedBvh::new(&ps)),
            Box::new(SceneBvh::new(&ps)),
        ];
        let rays = random_rays(&ps, 4000, 11 + analytic as u64);
        let mut total = 0;
        for accel in &accels {
            for r in &rays {
                let want = all_hits(&list, r);
                let got = all_hits(accel.as_ref(), r);
                // Hits near an edge may be reported by either neighbour
                // (watertightness promises at least one); the rest must
                // be the same hits on the same prims.
                let firm = |v: &[Hit]| -> Vec<Hit> {
                    v.iter()
                        .filter(|h| h.prim >= nt || edge_distance(h) >= 1e-4)
                        .copied()
                        .collect()
                };
                let (w, g) = (firm(&want), firm(&got));
                assert_eq!(w.len(), g.len(), "{r:?}: {want:?} vs {got:?}");
                for (b, a) in w.iter().zip(&g) {
                    assert!(
                        a.prim == b.prim && same_hit(&ps, r, a, b),
                        "{r:?}: {a:?} vs {b:?}"
                    );
                }
                total += w.len();
                // Stopping at the first hit reports it.
                let mut seen = 0;
                let stopped = accel.for_each_hit(r, &mut |_| {
                    seen += 1;
                    true
                });
                assert_eq!(stopped, !got.is_empty());
                assert_eq!(seen, usize::from(stopped));
            }
        }
        // Rays cross several surfaces: the comparison is not vacuous.
        assert!(total > rays.len() * 2, "{total} hits");
    }
}

#[test]
fn closest_and_any_hit_match_brute_force() {
    let s = instanced_scene();
    for analytic in [true, false] {
        let ps = prepare(&s, analytic);
        let bvh = InstancedBvh::new(&ps);
        let count = if analytic { 20_000 } else { 8000 };
        let rays = random_rays(&ps, count, 3 + analytic as u64);
        let ties = check_against_oracle(&ps, &bvh, &rays);
        println!(
            "analytic spheres {analytic}: {ties} edge ties in {}",
            rays.len()
        );
    }
}

#[test]
fn rays_with_finite_extent_match_brute_force() {
    // Segments between random surface points (shadow-ray shaped):
    // t_max limits both the top and the bottom level.
    let s = instanced_scene();
    let ps = prepare(&s, true);
    let bvh = InstancedBvh::new(&ps);
    let nt = ps.triangles.len() as u32;
    let rays: Vec<Ray> = (0..4000u32)
        .map(|i| {
            let mut rng = pixel_rng(21, i, 0, 0);
            let mut point = || {
                let t = (uniform(&mut rng) * nt as f32) as u32 % nt;
                let uv = sample_uniform_triangle(uniform2(&mut rng));
                let sh = ps.triangle_surface(t, uv.x, uv.y);
                sh.p + sh.ng * 0.05
            };
            let (a, b) = (point(), point());
            Ray::segment(a, b)
        })
        .collect();
    check_against_oracle(&ps, &bvh, &rays);
}

#[test]
fn scenes_without_sharing_or_geometry() {
    let mut s = Scene::default();
    s.add_material(Material::default());
    let ps = prepare(&s, true);
    let bvh = InstancedBvh::new(&ps);
    assert_eq!(bvh.instance_count(), 0);
    assert!(bvh.intersect(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::X)));
    // A mesh used once and a sphere: one flat level, same hits.
    let m = s.add_mesh(icosphere(1.0, 1));
    place(&mut s, Geometry::Mesh(m), Vec3::ZERO);
    place(
        &mut s,
        Geometry::Sphere { radius: 0.5 },
        Vec3::new(3.0, 0.0, 0.0),
    );
    let ps = prepare(&s, true);
    let bvh = InstancedBvh::new(&ps);
    assert_eq!((bvh.level_count(), bvh.instance_count()), (1, 1));
    assert_eq!(duplicated_triangles(&ps), 0);
    check_against_oracle(&ps, &bvh, &random_rays(&ps, 4000, 9));
}

#[test]
fn build_accelerator_matches_brute_force_on_both_sides_of_the_threshold() {
    // 3 and 8 instances of a 5120-triangle mesh: 10240 and 35840
    // duplicated triangles, below and above the threshold.
    for (count, two_level) in [(3, false), (8, true)] {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let m = s.add_mesh(icosphere(1.0, 4));
        for k in 0..count {
            s.objects.push(Object {
                geometry: Geometry::Mesh(m),
                transform: Transform {
                    translate: Vec3::new(2.5 * k as f32, 0.0, 0.0),
                    scale: Vec3::new(1.0, 0.5 + 0.1 * k as f32, 1.0),
                    ..Transform::default()
                },
                ..Object::default()
            });
        }
        let ps = prepare(&s, true);
        assert_eq!(
            duplicated_triangles(&ps) >= MIN_DUPLICATED_TRIANGLES,
            two_level
        );
        let accel = build_accelerator(&ps);
        let list = ListAccel::new(&ps);
        for r in random_rays(&ps, 600, 17) {
            let (a, b) = (accel.intersect(&r), list.intersect(&r));
            match (a, b) {
                (None, None) => {}
                (Some(a), Some(b)) if a.prim == b.prim => {
                    assert!(same_hit(&ps, &r, &a, &b), "{r:?}: {a:?} vs {b:?}")
                }
                (Some(a), Some(b)) => assert!(
                    (a.t - b.t).abs() <= 1e-5 * b.t && edge_distance(&a) < 1e-4,
                    "{r:?}: {a:?} vs {b:?}"
                ),
                _ => panic!("{r:?}: {a:?} vs {b:?}"),
            }
            assert_eq!(accel.occluded(&r), b.is_some(), "{r:?}");
        }
    }
}

#[test]
fn rays_leaving_a_surface_do_not_hit_it_again() {
    let s = instanced_scene();
    let ps = prepare(&s, true);
    let bvh = InstancedBvh::new(&ps);
    let sphere = ps.spheres[0];
    crate::accel::assert_rays_leave_surfaces(&ps, &bvh, (sphere.center, sphere.radius), 8);
}

/// A small shaded image: Lambert under a point light with shadow rays,
/// one ray per pixel centre, as linear grey values (0 for background).
fn render(ps: &PreparedScene<'_>, accel: &dyn Accelerator, w: u32, h: u32) -> Vec<f32> {
    let cam = &ps.scene.camera;
    let light = Vec3::new(6.0, 12.0, 10.0);
    (0..w * h)
        .into_par_iter()
        .map(|k| {
            let (x, y) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
            let ray = Ray::new(cam.eye, cam.ray_direction(x, y, w, h));
            let Some(hit) = accel.intersect(&ray) else {
                return 0.0;
            };
            let sh = ps.surface(&ray, &hit);
            let ng = if sh.ng.dot(ray.dir) > 0.0 {
                -sh.ng
            } else {
                sh.ng
            };
            let ns = if sh.ns.dot(ng) < 0.0 { -sh.ns } else { sh.ns };
            let to_light = light - sh.p;
            let cos = ns.dot(to_light.normalize()).max(0.0);
            let origin = offset_ray_origin(sh.p, ng, to_light);
            let lit = cos > 0.0 && !accel.occluded(&Ray::segment(origin, light));
            0.1 + if lit { 0.8 * cos } else { 0.0 }
        })
        .collect()
}

#[test]
fn render_matches_the_flat_bvh() {
    let s = instanced_scene();
    let ps = prepare(&s, true);
    let (w, h) = (64, 64);
    let flat = render(&ps, &SceneBvh::new(&ps), w, h);
    let inst = render(&ps, &InstancedBvh::new(&ps), w, h);
    // The image is not trivial: most pixels see geometry, some of it
    // in shadow.
    let covered = flat.iter().filter(|&&v| v > 0.0).count();
    let shadowed = flat.iter().filter(|&&v| v == 0.1).count();
    assert!(covered > 2000 && shadowed > 50, "{covered} {shadowed}");
    // Object-space intersection rounds differently, so a pixel may
    // differ only at float noise or where a ray grazes a silhouette
    // or a shadow ray passes exactly along an edge.
    let differing: Vec<(usize, f32, f32)> = flat
        .iter()
        .zip(&inst)
        .enumerate()
        .filter(|(_, (a, b))| (*a - *b).abs() > 1.0 / 255.0)
        .map(|(i, (a, b))| (i, *a, *b))
        .collect();
    assert!(differing.len() <= 3, "{differing:?}");
}

/// Adds an object of `geometry` (material 0, smooth) moved by `offset`.
fn place(s: &mut Scene, geometry: Geometry, offset: Vec3) {
    s.objects.push(Object {
        geometry,
        transform: Transform {
            translate: offset,
            ..Transform::default()
        },
        ..Object::default()
    });
}
