//! Tests of the BVH: brute-force oracles, structure, and the wide tests' bit
//! identity with the scalar ones.

use super::build::PrimRef;
use super::node::RayPre;
use super::partition::{Plane, grow_sides, partition_by};
use super::scene::TriBlock;
use super::traverse::{Entry, Stack};
use super::*;
use crate::accel::intersect_triangle;
use crate::accel::list::ListAccel;
use crate::accel::{Accelerator, Hit, WatertightRay};
use crate::geometry::Ray;
use crate::prepared::PrepareOptions;
use crate::prepared::PreparedScene;
use crate::sampling::{pixel_rng, sample_uniform_sphere, uniform, uniform2};
use crate::scene::{Geometry, Material, Mesh, Object, Scene, Transform};
use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

/// The Stanford bunny from the shared test assets (read in place, not
/// redistributed), or `None` after a skip message where they are absent.
fn bunny() -> Option<Mesh> {
    read_obj(&chiaro_testkit::shared_asset(
        "common-3d-test-models/stanford-bunny.obj",
    )?)
}

/// A tiny OBJ reader: `v` and `f` lines only (polygons fanned).
fn read_obj(path: &std::path::Path) -> Option<Mesh> {
    let text = std::fs::read_to_string(path).ok()?;
    let mut mesh = Mesh::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it.take(3).filter_map(|s| s.parse().ok()).collect();
                if c.len() == 3 {
                    mesh.positions.push(Vec3::new(c[0], c[1], c[2]));
                }
            }
            Some("f") => {
                let nv = mesh.positions.len() as i64;
                let idx: Vec<u32> = it
                    .filter_map(|s| s.split('/').next()?.parse::<i64>().ok())
                    .map(|i| if i < 0 { nv + i } else { i - 1 } as u32)
                    .collect();
                for k in 1..idx.len().saturating_sub(1) {
                    mesh.indices.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Some(mesh)
}

/// A point uniform in the unit cube, its coordinates drawn x, y, z in turn.
fn unit_cube_point(rng: &mut crate::sampling::Rng) -> Vec3 {
    Vec3::new(uniform(rng), uniform(rng), uniform(rng))
}

/// [`unit_cube_point`] rounded to the grid of eighths, so that box faces
/// and ray origins can share slab planes exactly.
fn grid_point(rng: &mut crate::sampling::Rng) -> Vec3 {
    unit_cube_point(rng).map(|x| (x * 8.0).round() / 8.0)
}

fn scene_of(mesh: Mesh, spheres: &[(Vec3, f32)]) -> Scene {
    let mut s = Scene::default();
    s.add_material(Material::default());
    let m = s.add_mesh(mesh);
    s.objects.push(Object {
        geometry: Geometry::Mesh(m),
        ..Default::default()
    });
    for &(c, r) in spheres {
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: r },
            transform: Transform {
                translate: c,
                ..Default::default()
            },
            ..Default::default()
        });
    }
    s
}

/// Random rays: half from random points in the (grown) bounds in
/// random directions, half aimed at random points of random triangles.
fn random_rays(ps: &PreparedScene<'_>, count: u32, seed: u64) -> Vec<Ray> {
    (0..count)
        .map(|i| {
            let mut rng = pixel_rng(seed, i, 0, 0);
            let o = crate::accel::random_origin(ps, &mut rng);
            if i % 2 == 0 || ps.triangles.is_empty() {
                Ray::new(o, sample_uniform_sphere(uniform2(&mut rng)))
            } else {
                let t = ps.triangles
                    [(uniform(&mut rng) * ps.triangles.len() as f32) as usize % ps.triangles.len()];
                let uv = crate::sampling::sample_uniform_triangle(uniform2(&mut rng));
                let [a, bb, c] = t.map(|k| ps.positions[k as usize]);
                let target = a * uv.x + bb * uv.y + c * (1.0 - uv.x - uv.y);
                Ray::new(o, (target - o) * 0.7)
            }
        })
        .collect()
}

/// `s` prepared with its spheres kept analytic (not tessellated).
fn with_analytic_spheres(s: &Scene) -> PreparedScene<'_> {
    PreparedScene::new(
        s,
        PrepareOptions {
            analytic_spheres: true,
            ..Default::default()
        },
    )
}

fn check_against_oracle(ps: &PreparedScene<'_>, rays: &[Ray]) {
    let list = ListAccel::new(ps);
    let bvh = SceneBvh::new(ps);
    let mismatches: Vec<String> = rays
        .par_iter()
        .filter_map(|r| {
            let a = bvh.intersect(r);
            let b = list.intersect(r);
            let same = match (a, b) {
                (None, None) => true,
                // The same primitive gives the bit-identical distance; a tie
                // on a shared edge may pick either neighbour.
                (Some(a), Some(b)) if a.prim == b.prim => a.t == b.t,
                (Some(a), Some(b)) => (a.t - b.t).abs() <= 1e-5 * b.t.abs().max(1.0),
                _ => false,
            };
            let occ_same = bvh.occluded(r) == b.is_some();
            // The nearest of all the hits visit_hits reports is the
            // closest hit.
            let mut visit_t: Option<f32> = None;
            bvh.visit_hits(r, |h| {
                visit_t = Some(visit_t.map_or(h.t, |t| t.min(h.t)));
                false
            });
            let visit_same = visit_t == b.map(|h| h.t);
            (!same || !occ_same || !visit_same).then(|| format!("{r:?}: bvh {a:?} list {b:?}"))
        })
        .collect();
    assert!(
        mismatches.is_empty(),
        "{} mismatches, first: {}",
        mismatches.len(),
        mismatches[0]
    );
}

#[test]
fn bunny_closest_and_any_hit_match_brute_force() {
    let Some(mesh) = bunny() else {
        return;
    };
    assert!(mesh.indices.len() > 60_000);
    // A patch of the real mesh for the 100k-ray comparison (brute force
    // is O(rays x triangles)), then the whole bunny with fewer rays.
    let mut patch = mesh.clone();
    patch.indices.truncate(2500);
    let s = scene_of(patch, &[]);
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    check_against_oracle(&ps, &random_rays(&ps, 100_000, 1));
    let s = scene_of(mesh, &[(Vec3::new(0.0, 0.1, 0.0), 0.03)]);
    let ps = with_analytic_spheres(&s);
    check_against_oracle(&ps, &random_rays(&ps, 2_000, 2));
}

#[test]
fn random_soup_with_spheres_matches_brute_force() {
    let mut rng = pixel_rng(9, 0, 0, 0);
    let mut mesh = Mesh::default();
    for i in 0..3000u32 {
        let c = unit_cube_point(&mut rng) * 10.0;
        for _ in 0..3 {
            mesh.positions.push(c + (unit_cube_point(&mut rng) - 0.5));
        }
        mesh.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let spheres: Vec<(Vec3, f32)> = (0..50)
        .map(|_| (unit_cube_point(&mut rng) * 10.0, 0.3))
        .collect();
    let s = scene_of(mesh, &spheres);
    let ps = with_analytic_spheres(&s);
    check_against_oracle(&ps, &random_rays(&ps, 20_000, 3));
}

#[test]
fn structure_invariants_and_thread_independence() {
    let mut rng = pixel_rng(4, 0, 0, 0);
    let boxes: Vec<Aabb> = (0..20_000)
        .map(|_| {
            let c = unit_cube_point(&mut rng) * 100.0;
            Aabb {
                min: c,
                max: c + Vec3::splat(uniform(&mut rng)),
            }
        })
        .collect();
    let opts = BvhOptions {
        parallel_threshold: 1000,
        ..Default::default()
    };
    let a = Bvh::build_with(&boxes, &opts);
    let serial = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let b = serial.install(|| Bvh::build_with(&boxes, &opts));
    assert!(a.nodes().eq(b.nodes()));
    assert_eq!(a.prim_order, b.prim_order);
    // Every prim appears once; every leaf box contains its prims; every
    // parent box contains its children; leaves are small.
    let mut seen = vec![false; boxes.len()];
    for &p in a.prim_order().iter().filter(|&&p| p != PAD_SLOT) {
        assert!(!seen[p as usize]);
        seen[p as usize] = true;
    }
    assert!(seen.iter().all(|&s| s));
    // Every node but the root is referenced once; child boxes contain
    // their children's boxes and their leaves' prims; leaves cover every
    // slot once.
    let mut referenced = vec![0u32; a.node_count()];
    let mut covered = vec![0u32; a.prim_order().len()];
    for n in a.nodes() {
        for (cb, c) in n.children() {
            match c {
                Child::Leaf { first, count } => {
                    assert!(count <= opts.max_leaf);
                    assert_eq!(first as usize % BLOCK, 0);
                    for s in first..first + count {
                        covered[s as usize] += 1;
                        let pb = boxes[a.prim_order()[s as usize] as usize];
                        assert_eq!(cb.union(pb), cb);
                    }
                }
                Child::Node(k) => {
                    referenced[k as usize] += 1;
                    for (gb, _) in a.node(k as usize).children() {
                        assert_eq!(cb.union(gb), cb);
                    }
                }
            }
        }
    }
    assert_eq!(referenced[0], 0);
    assert!(referenced[1..].iter().all(|&r| r == 1));
    for (&c, &p) in covered.iter().zip(a.prim_order()) {
        assert_eq!(c, (p != PAD_SLOT) as u32);
    }
    assert!(a.depth() < 25, "depth {}", a.depth());
    assert_eq!(std::mem::size_of::<BvhNode>(), 32 * WIDTH);
}

#[test]
fn partition_side_bounds_ignore_the_other_side() {
    // `grow_sides` relies on x86's min/max keeping the receiver's
    // bound beside a NaN; check the bounds it produces on this target.
    let empty = [Vec3A::INFINITY, Vec3A::NEG_INFINITY];
    let (mut l, mut r) = (empty, empty);
    let pts = [
        (Vec3A::new(1.0, -2.0, 3.0), true),
        (Vec3A::new(-4.0, 5.0, 0.5), false),
        (Vec3A::new(2.0, 0.0, -1.0), true),
        (Vec3A::new(7.0, -3.0, 2.0), false),
    ];
    for (c, left) in pts {
        (l, r) = grow_sides(glam::BVec3A::splat(left), c, l, r);
    }
    assert_eq!(l, [Vec3A::new(1.0, -2.0, -1.0), Vec3A::new(2.0, 0.0, 3.0)]);
    assert_eq!(r, [Vec3A::new(-4.0, -3.0, 0.5), Vec3A::new(7.0, 5.0, 2.0)]);
}

/// `partition_by` (block partition plus Lomuto tail) puts exactly the
/// references left of the plane first, keeps the same multiset, and
/// returns each side's exact centroid bounds, for sizes around the
/// block size, all-left and all-right inputs, and sorted and shuffled
/// orders.
#[test]
fn partition_is_exact_at_every_size() {
    let mut rng = pixel_rng(5, 0, 0, 0);
    let sizes = [1, 2, 63, 64, 65, 127, 128, 129, 191, 256, 300, 1000, 4099];
    for (case, &n) in sizes.iter().cycle().take(3 * sizes.len()).enumerate() {
        let mut refs: Vec<PrimRef> = (0..n)
            .map(|i| {
                let p = unit_cube_point(&mut rng);
                let p = if case % 3 == 1 {
                    p * 0.1 + Vec3::X * (i as f32 / n as f32)
                } else {
                    p
                };
                let b = Aabb {
                    min: p,
                    max: p + Vec3::splat(0.01),
                };
                PrimRef::new(&b, i as u32)
            })
            .collect();
        // Limits below, inside and above the centroids' range.
        let limit = [0.5, -1.0, 2.0][case / sizes.len()];
        let plane = Plane {
            lo: Vec3A::ZERO,
            scale: Vec3A::ONE,
            limit: Vec3A::splat(limit),
        };
        let goes_left = |r: &PrimRef| r.centroid().x < limit;
        let mut want: Vec<u32> = refs.iter().map(|r| r.index()).collect();
        let bounds_of = |rs: &[PrimRef]| {
            rs.iter().fold(Aabb::EMPTY, |b, r| {
                b.union(Aabb::from_points([Vec3::from(r.centroid())]))
            })
        };
        let (want_l, want_r): (Vec<PrimRef>, Vec<PrimRef>) =
            refs.iter().partition(|r| goes_left(r));
        let (i, [l, r]) = partition_by::<0>(&mut refs, &plane, false);
        assert_eq!(i, want_l.len(), "n {n} case {case}");
        assert!(refs[..i].iter().all(goes_left), "n {n} case {case}");
        assert!(!refs[i..].iter().any(goes_left), "n {n} case {case}");
        let mut got: Vec<u32> = refs.iter().map(|r| r.index()).collect();
        got.sort_unstable();
        want.sort_unstable();
        assert_eq!(got, want, "n {n} case {case}: not a permutation");
        for (side, (got, want)) in [(l, &want_l), (r, &want_r)].into_iter().enumerate() {
            let want = bounds_of(want);
            if want.is_empty() {
                assert!(got.is_empty(), "n {n} case {case} side {side}");
            } else {
                assert_eq!(
                    (got.min, got.max),
                    (want.min, want.max),
                    "n {n} case {case} side {side}"
                );
            }
        }
    }
}

/// The traversal stack is last in, first out across its three parts
/// (first array, second array, `Vec`), including after popping back
/// below a part's start and pushing again.
#[test]
fn stack_is_lifo_across_its_parts() {
    let e = |i: u32| Entry {
        child: i,
        count: i % 5,
        near: i as f32 * 0.5,
    };
    let mut s = Stack::new();
    let mut model = Vec::new();
    let mut next = 0u32;
    for round in [3usize, 20, 50, 7, 40] {
        for _ in 0..round {
            s.push(e(next));
            model.push(next);
            next += 1;
        }
        for _ in 0..round / 2 {
            let got = s.pop().map(|x| (x.child, x.count, x.near));
            let want = model.pop().map(|i| (e(i).child, e(i).count, e(i).near));
            assert_eq!(got, want);
        }
    }
    while let Some(i) = model.pop() {
        assert_eq!(s.pop().map(|x| x.child), Some(i));
    }
    assert!(s.pop().is_none());
}

#[test]
fn degenerate_inputs() {
    assert_eq!(Bvh::build(&[]).nodes().count(), 0);
    let r = Ray::new(Vec3::ZERO, Vec3::X);
    assert!(!Bvh::build(&[]).traverse_any(&r, |_| true));
    // Many identical boxes (coincident centroids) still build and are all found.
    let b = Aabb {
        min: Vec3::splat(1.0),
        max: Vec3::splat(2.0),
    };
    let bvh = Bvh::build(&vec![b; 100]);
    let ray = Ray::new(Vec3::new(0.0, 1.5, 1.5), Vec3::X);
    let mut found = 0;
    bvh.traverse_any(&ray, |_| {
        found += 1;
        false
    });
    assert_eq!(found, 100);
    // Empty and NaN boxes are dropped.
    let bvh = Bvh::build(&[
        Aabb::EMPTY,
        Aabb {
            min: Vec3::NAN,
            max: Vec3::ONE,
        },
        b,
    ]);
    assert_eq!(bvh.prim_order(), &[2]);
}

#[test]
fn small_nodes_split_when_traversal_is_cheap() {
    // Four small boxes at the corners of a large square: one leaf costs
    // the square's area, a split into single boxes a quarter of it plus
    // four tiny areas when a traversal step costs 0.25 of a block test.
    let boxes: Vec<Aabb> = [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0), (10.0, 10.0)]
        .iter()
        .map(|&(x, y)| Aabb {
            min: Vec3::new(x, y, 0.0),
            max: Vec3::new(x + 0.1, y + 0.1, 0.1),
        })
        .collect();
    let leaves = |b: &Bvh| {
        b.nodes()
            .flat_map(|n| n.children())
            .filter(|(_, c)| matches!(c, Child::Leaf { .. }))
            .count()
    };
    let coarse = BvhOptions {
        fine_leaves_below: 0,
        ..BvhOptions::default()
    };
    assert_eq!(leaves(&Bvh::build_with(&boxes, &coarse)), 1);
    let cheap = Bvh::build_with(
        &boxes,
        &BvhOptions {
            traversal_cost: 0.25,
            ..coarse
        },
    );
    assert!(leaves(&cheap) > 1);
    // Fine leaves (the default for small BVHs) split the block too.
    assert!(leaves(&Bvh::build(&boxes)) > 1);
}

#[test]
fn parallel_and_serial_builds_drop_the_same_unusable_boxes() {
    // Boxes on a line, every seventh empty or NaN; a threshold of 2
    // takes the parallel paths (reference collection, binning,
    // partition, subtrees) everywhere, the default none of them here.
    let boxes: Vec<Aabb> = (0..3000)
        .map(|i| match i % 7 {
            3 => Aabb::EMPTY,
            5 => Aabb {
                min: Vec3::new(f32::NAN, 0.0, 0.0),
                max: Vec3::ONE,
            },
            _ => {
                let p = Vec3::new(
                    i as f32 * 0.37 % 11.0,
                    (i * 13 % 17) as f32,
                    i as f32 * 0.01,
                );
                Aabb {
                    min: p,
                    max: p + Vec3::splat(0.25),
                }
            }
        })
        .collect();
    let serial = Bvh::build(&boxes);
    let parallel = Bvh::build_with(
        &boxes,
        &BvhOptions {
            parallel_threshold: 2,
            ..BvhOptions::default()
        },
    );
    let kept = |b: &Bvh| {
        let mut v: Vec<u32> = b
            .prim_order()
            .iter()
            .copied()
            .filter(|&p| p != PAD_SLOT)
            .collect();
        v.sort_unstable();
        v
    };
    let expected: Vec<u32> = (0..3000).filter(|i| i % 7 != 3 && i % 7 != 5).collect();
    assert_eq!(kept(&serial), expected);
    assert_eq!(kept(&parallel), expected);
    // The same tree either way: the build does not depend on how it is
    // split into tasks.
    assert_eq!(serial.node_count(), parallel.node_count());
    assert_eq!(serial.bounds(), parallel.bounds());
}

#[test]
fn rays_leaving_a_surface_do_not_hit_it_again() {
    let mesh = bunny().unwrap_or_else(|| crate::geometry::primitives::uv_sphere(1.0, 64, 32));
    let s = scene_of(mesh, &[(Vec3::new(5.0, 0.0, 0.0), 0.5)]);
    let ps = with_analytic_spheres(&s);
    let bvh = SceneBvh::new(&ps);
    crate::accel::assert_rays_leave_surfaces(&ps, &bvh, (Vec3::new(5.0, 0.0, 0.0), 0.5), 4);
}

/// The node test used in traversal (eight AVX lanes on x86-64-v3)
/// and the portable four-lane one give the same entry distances, bit
/// for bit, and the same hit masks, including the NaN slabs of a ray
/// parallel to a box face with its origin on the face, and unused
/// (inverted) lanes.
#[test]
fn node_test_matches_the_four_lane_one() {
    let mut rng = pixel_rng(11, 0, 0, 0);
    let mut hits = 0;
    for k in 0..20_000 {
        let mut node = BvhNode::EMPTY;
        let used = k % WIDTH + 1;
        for lane in 0..used {
            let a = grid_point(&mut rng);
            let e = unit_cube_point(&mut rng) * 0.5;
            let b = Aabb { min: a, max: a + e };
            node.set_lane(lane, &b, lane as u32, 0);
        }
        let o = if k % 3 == 0 {
            // On the grid the boxes' corners lie on: slab planes.
            grid_point(&mut rng)
        } else {
            unit_cube_point(&mut rng) * 3.0 - 1.0
        };
        // Towards a random point among the boxes.
        let aim = unit_cube_point(&mut rng) * 1.5;
        let mut dir =
            (aim - o).normalize_or(Vec3::X) + sample_uniform_sphere(uniform2(&mut rng)) * 0.1;
        if k % 3 == 0 {
            // Zero components: infinite inverses, NaN products.
            dir[k % 3] = 0.0;
            if k % 2 == 0 {
                dir[(k + 1) % 3] = -0.0;
            }
        }
        let ray = Ray::new(o, dir);
        let pre = RayPre::new(&ray);
        let org = ray.origin.to_array().map(Vec4::splat);
        let inv = pre.recip.to_array().map(Vec4::splat);
        let t_max = if k % 2 == 0 { f32::INFINITY } else { 1.5 };
        let (near, mask) = node.intersect(&pre, 1e-4, t_max);
        let (near4, mask4) = node.intersect4(&org, &inv, &pre, 1e-4, t_max);
        assert_eq!(mask, mask4, "case {k}");
        assert_eq!(near.map(f32::to_bits), near4.map(f32::to_bits), "case {k}");
        assert_eq!(mask >> used, 0, "case {k}: an unused lane hit");
        hits += mask.count_ones();
    }
    assert!(hits > 2_000, "only {hits} box hits");
}

#[test]
fn four_wide_triangle_test_is_bit_identical_to_scalar() {
    let mut rng = pixel_rng(7, 0, 0, 0);
    let mut edge_cases = 0;
    for k in 0..4000 {
        let mut blk = TriBlock::EMPTY;
        let mut tris = [[Vec3::ZERO; 3]; BLOCK];
        for (lane, t) in tris.iter_mut().enumerate() {
            for p in t.iter_mut() {
                *p = unit_cube_point(&mut rng);
            }
            if k % 2 == 0 {
                // Axis-aligned grid triangles: rays through vertices and
                // edges take the double-precision fallback.
                *t = [Vec3::ZERO, Vec3::X, Vec3::Y].map(|p| p + Vec3::Z * lane as f32 * 0.1);
            }
            for (v, p) in t.iter().enumerate() {
                for a in 0..3 {
                    blk.v[3 * v + a][lane] = p[a];
                }
            }
        }
        let o = if k % 2 == 0 {
            let g = |x: f32| (x * 4.0).round() / 4.0;
            Vec3::new(g(uniform(&mut rng)), g(uniform(&mut rng)), 3.0)
        } else {
            Vec3::new(0.5, 0.5, 3.0)
        };
        let dir = if k % 2 == 0 {
            -Vec3::Z
        } else {
            sample_uniform_sphere(uniform2(&mut rng)) - Vec3::Z * 2.0
        };
        let wr = WatertightRay::new(&Ray::new(o, dir));
        let lanes = (k % 15 + 1) as u32;
        let r = blk.intersect(&wr, lanes);
        for (i, t) in tris.iter().enumerate() {
            let want = if lanes >> i & 1 == 1 {
                wr.intersect(t[0], t[1], t[2])
            } else {
                None
            };
            let got = (r.mask >> i & 1 == 1).then_some((r.t[i], r.u[i], r.v[i]));
            assert_eq!(got, want, "case {k} lane {i}");
            edge_cases += want.is_some_and(|(_, u, v)| u == 0.0 || v == 0.0) as u32;
        }
    }
    assert!(edge_cases > 10, "only {edge_cases} edge hits");
}

#[test]
fn watertight_ray_agrees_with_free_function() {
    let mut rng = pixel_rng(6, 0, 0, 0);
    for _ in 0..1000 {
        let p: Vec<Vec3> = (0..3).map(|_| unit_cube_point(&mut rng)).collect();
        let r = Ray::new(
            Vec3::new(0.5, 0.5, 3.0),
            sample_uniform_sphere(uniform2(&mut rng)) - Vec3::Z * 2.0,
        );
        assert_eq!(
            WatertightRay::new(&r).intersect(p[0], p[1], p[2]),
            intersect_triangle(&r, p[0], p[1], p[2])
        );
    }
}

/// Camera rays over a `w` x `h` image from `eye` towards `target`, in 4 x 2
/// pixel tiles (packet order); the middle pixel's direction is `target -
/// eye` exactly, so with an axis-aligned view it has zero components.
fn tiled_camera_rays(eye: Vec3, target: Vec3, w: u32, h: u32, fov: f32) -> Vec<Ray> {
    let fwd = target - eye;
    let up = if fwd.cross(Vec3::Y).length_squared() > 0.0 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let right = fwd.cross(up).normalize() * fwd.length() * fov;
    let up = right.cross(fwd).normalize() * fwd.length() * fov;
    let mut rays = Vec::new();
    for ty in (0..h).step_by(2) {
        for tx in (0..w).step_by(4) {
            for y in ty..(ty + 2).min(h) {
                for x in tx..(tx + 4).min(w) {
                    let sx = (x as f32 - (w / 2) as f32) / w as f32;
                    let sy = (y as f32 - (h / 2) as f32) / h as f32;
                    rays.push(Ray::new(eye, fwd + right * sx + up * sy));
                }
            }
        }
    }
    rays
}

/// Asserts that the packet queries give every ray's single-ray answers bit
/// for bit (distance, primitive, barycentrics; occlusion), for packets cut
/// at several offsets so that partial packets are covered too.
fn check_packets_match_single(bvh: &SceneBvh, rays: &[Ray], what: &str) {
    let single: Vec<Option<Hit>> = rays.iter().map(|r| bvh.intersect(r)).collect();
    let single_occ: Vec<bool> = rays.iter().map(|r| bvh.occluded(r)).collect();
    let bits = |h: &Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()));
    for skip in [0, 3] {
        let rays = &rays[skip..];
        let mut hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        // Whole slices, and slices of 13 rays (a partial packet each).
        for chunk in [rays.len(), 13] {
            for ((rs, hs), os) in rays
                .chunks(chunk)
                .zip(hits.chunks_mut(chunk))
                .zip(occ.chunks_mut(chunk))
            {
                bvh.intersect_packet(rs, hs);
                bvh.occluded_packet(rs, os);
            }
            for (i, r) in rays.iter().enumerate() {
                assert_eq!(
                    bits(&hits[i]),
                    bits(&single[i + skip]),
                    "{what}: closest hit of {r:?} (ray {i}, chunk {chunk})"
                );
                assert_eq!(
                    occ[i],
                    single_occ[i + skip],
                    "{what}: occlusion of {r:?} (ray {i}, chunk {chunk})"
                );
            }
        }
    }
}

/// A grid of unit quads in the plane z = 0 (shared edges everywhere), a
/// second copy of every fourth quad lying exactly on the first (ties at
/// equal distances), and an icosphere above it.
fn tie_scene() -> Scene {
    let mut mesh = Mesh::default();
    let n = 24u32;
    for j in 0..=n {
        for i in 0..=n {
            mesh.positions.push(Vec3::new(
                i as f32 - n as f32 / 2.0,
                j as f32 - n as f32 / 2.0,
                0.0,
            ));
        }
    }
    let at = |i: u32, j: u32| j * (n + 1) + i;
    for j in 0..n {
        for i in 0..n {
            let q = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
            mesh.indices.push([q[0], q[1], q[2]]);
            mesh.indices.push([q[0], q[2], q[3]]);
            if (i + j) % 4 == 0 {
                // The same quad again, split along the other diagonal.
                mesh.indices.push([q[0], q[1], q[3]]);
                mesh.indices.push([q[1], q[2], q[3]]);
            }
        }
    }
    let sphere = crate::geometry::primitives::icosphere(2.0, 3);
    let base = mesh.positions.len() as u32;
    mesh.positions.extend(
        sphere
            .positions
            .iter()
            .map(|&p| p + Vec3::new(1.5, -2.0, 3.0)),
    );
    mesh.indices
        .extend(sphere.indices.iter().map(|t| t.map(|k| k + base)));
    scene_of(
        mesh,
        &[
            (Vec3::new(-4.0, 3.0, 1.0), 1.0),
            (Vec3::new(-4.0, 3.0, 1.0), 1.0),
            (Vec3::new(5.0, 5.0, 0.5), 2.0),
        ],
    )
}

#[test]
fn packets_match_single_rays_bit_for_bit() {
    let s = tie_scene();
    let ps = with_analytic_spheres(&s);
    let bvh = SceneBvh::new(&ps);
    // Straight down the z axis (zero x and y components in the middle),
    // obliquely, from inside the grown bounds, and along the grid's plane.
    let views = [
        (Vec3::new(0.0, 0.0, 20.0), Vec3::ZERO),
        (Vec3::new(0.5, 0.5, 9.0), Vec3::new(0.5, 0.5, 0.0)),
        (Vec3::new(14.0, -9.0, 7.0), Vec3::new(-1.0, 2.0, 0.0)),
        (Vec3::new(-20.0, 0.0, 0.0), Vec3::ZERO),
        (Vec3::new(0.0, 0.0, -6.0), Vec3::new(2.0, 0.0, 4.0)),
    ];
    for (k, (eye, target)) in views.into_iter().enumerate() {
        let rays = tiled_camera_rays(eye, target, 64, 48, 0.8);
        check_packets_match_single(&bvh, &rays, &format!("view {k}"));
    }
    // Random rays; axis-aligned ones (two zero components) through vertices
    // and edges of the grid; rays with a short range and a t_min.
    check_packets_match_single(&bvh, &random_rays(&ps, 4000, 7), "random");
    let mut axis = Vec::new();
    for i in -13..13 {
        for j in -13..13 {
            let o = Vec3::new(i as f32 * 0.5, j as f32 * 0.5, 5.0);
            axis.push(Ray::new(o, Vec3::NEG_Z));
            axis.push(Ray::new(o, Vec3::new(0.0, 0.25, -1.0)));
            axis.push(Ray {
                t_min: 4.0,
                t_max: 5.5,
                ..Ray::new(o, Vec3::NEG_Z)
            });
            axis.push(Ray::new(o, Vec3::Z));
        }
    }
    check_packets_match_single(&bvh, &axis, "axis-aligned");
    // The whole bunny, where the shared assets are present.
    if let Some(mesh) = bunny() {
        let s = scene_of(mesh, &[(Vec3::new(0.0, 0.1, 0.0), 0.03)]);
        let ps = with_analytic_spheres(&s);
        let bvh = SceneBvh::new(&ps);
        let c = ps.bounds.center();
        let eye = c + Vec3::new(0.05, 0.02, 0.3);
        check_packets_match_single(
            &bvh,
            &tiled_camera_rays(eye, c, 96, 64, 0.4),
            "bunny camera",
        );
        check_packets_match_single(&bvh, &random_rays(&ps, 4000, 8), "bunny random");
    }
}

#[test]
fn packet_queries_of_other_accelerators_loop_over_single_rays() {
    let s = tie_scene();
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    let list = ListAccel::new(&ps);
    let rays = random_rays(&ps, 200, 11);
    let mut hits = vec![None; rays.len()];
    let mut occ = vec![false; rays.len()];
    list.intersect_packet(&rays, &mut hits);
    list.occluded_packet(&rays, &mut occ);
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(hits[i], list.intersect(r));
        assert_eq!(occ[i], list.occluded(r));
    }
}

#[test]
fn culled_camera_packets_match_single_rays() {
    // Every surface single-sided: camera rays from below the grid pass
    // through its back and meet what lies beyond (or nothing).
    let mut s = tie_scene();
    for m in &mut s.materials {
        m.sidedness = crate::scene::Sidedness::Culled;
    }
    let ps = with_analytic_spheres(&s);
    let accel = crate::accel::cull::Culled::wrap(&ps, Box::new(SceneBvh::new(&ps)));
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()));
    let mut culled = 0;
    for (eye, target) in [
        (Vec3::new(0.0, 0.0, -6.0), Vec3::new(2.0, 0.0, 4.0)),
        (Vec3::new(3.0, -2.0, 9.0), Vec3::new(0.0, 1.0, 0.0)),
    ] {
        let rays = tiled_camera_rays(eye, target, 48, 32, 0.8);
        let mut hits = vec![None; rays.len()];
        accel.intersect_camera_packet(&rays, &mut hits);
        for (r, h) in rays.iter().zip(&hits) {
            assert_eq!(bits(*h), bits(accel.intersect_camera(r)), "{r:?}");
            culled += usize::from(bits(*h) != bits(accel.intersect(r)));
        }
    }
    assert!(culled > 100, "the views see back faces ({culled})");
}

#[test]
fn packet_node_test_matches_the_per_ray_one() {
    use super::packet::{PACKET, PacketPre, node_packet, node_per_ray};
    let s = tie_scene();
    let ps = PreparedScene::new(&s, PrepareOptions::default());
    let bvh = SceneBvh::new(&ps);
    let mut rays = random_rays(&ps, 400, 5);
    rays.extend(tiled_camera_rays(
        Vec3::new(0.0, 0.0, 20.0),
        Vec3::ZERO,
        16,
        8,
        0.8,
    ));
    rays.extend(tiled_camera_rays(
        Vec3::new(-20.0, 0.0, 0.0),
        Vec3::ZERO,
        16,
        8,
        0.8,
    ));
    let mut compared = 0;
    for (k, chunk) in rays.chunks_exact(PACKET).enumerate() {
        let rr: [Ray; PACKET] = std::array::from_fn(|i| Ray {
            t_min: [0.0, 0.5][(i + k) % 2],
            ..chunk[i]
        });
        let pre: [RayPre; PACKET] = std::array::from_fn(|i| RayPre::new(&rr[i]));
        let t_min = rr.map(|r| r.t_min);
        let soa = PacketPre::new(&rr, &pre, &t_min);
        let cull: [f32; PACKET] = std::array::from_fn(|i| [f32::INFINITY, 3.0, 12.0][(i + k) % 3]);
        let path: [f32; PACKET] = std::array::from_fn(|i| [f32::NEG_INFINITY, 2.0][(i + k) % 2]);
        for n in bvh.bvh().nodes() {
            for mask in [0xff, 0x5a] {
                let a = node_packet(n, &pre, &soa, &t_min, &cull, mask, &path);
                let b = node_per_ray(n, &pre, &t_min, &cull, mask, &path);
                assert_eq!(a.0, b.0, "rays per child");
                for i in 0..WIDTH {
                    if a.0[i] != 0 {
                        compared += 1;
                        assert_eq!(a.2[i].to_bits(), b.2[i].to_bits(), "order key");
                    }
                    for r in 0..PACKET {
                        if a.0[i] >> r & 1 == 1 {
                            assert_eq!(a.1[i][r].to_bits(), b.1[i][r].to_bits(), "entry");
                        }
                    }
                }
            }
        }
    }
    assert!(compared > 1000, "children met: {compared}");
}

#[test]
fn packet_stack_is_lifo_across_its_parts() {
    let mut s = super::packet::PacketStack::new();
    for i in 0..100u32 {
        s.push(super::packet::PacketEntry {
            child: i,
            ..Default::default()
        });
    }
    for i in (0..100u32).rev() {
        assert_eq!(s.pop().map(|e| e.child), Some(i));
    }
    assert!(s.pop().is_none());
}

/// Every kernel of [`dispatch`](super::dispatch) returns the same hits, bit
/// for bit, as the baseline body: closest hits (distance, prim, u, v) and
/// occlusion, on a soup with analytic spheres, the packet tests' tie scene
/// and (where the assets are) the bunny. On a CPU without AVX-512 the v4
/// entry points run their baseline fallback and the test says so.
#[test]
fn every_kernel_returns_bit_identical_hits() {
    let available = Kernel::available();
    if !available.contains(&Kernel::X86_64V4) {
        eprintln!("no AVX-512 here: the x86-64-v4 clones fall back to the baseline");
    }
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()));
    let check = |ps: &PreparedScene<'_>, rays: &[Ray], what: &str| {
        let bvh = SceneBvh::new(ps);
        let mut hits = 0;
        for r in rays {
            let base = bvh.closest_hit(r);
            hits += base.is_some() as usize;
            assert_eq!(
                bits(super::dispatch::closest_hit_v4(&bvh, r)),
                bits(base),
                "{what}: closest hit of {r:?}"
            );
            assert_eq!(
                super::dispatch::any_hit_v4(&bvh, r),
                bvh.any_hit(r),
                "{what}: occlusion of {r:?}"
            );
            // The dispatched queries agree too, whichever kernel runs.
            assert_eq!(bits(bvh.intersect(r)), bits(base), "{what}: {r:?}");
        }
        assert!(hits > rays.len() / 10, "{what}: only {hits} hits");
    };
    let mut rng = pixel_rng(12, 0, 0, 0);
    let mut mesh = Mesh::default();
    for i in 0..3000u32 {
        let c = grid_point(&mut rng) * 10.0;
        for _ in 0..3 {
            mesh.positions.push(c + (grid_point(&mut rng) - 0.5));
        }
        mesh.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let spheres: Vec<(Vec3, f32)> = (0..50)
        .map(|_| (unit_cube_point(&mut rng) * 10.0, 0.3))
        .collect();
    let s = scene_of(mesh, &spheres);
    let ps = with_analytic_spheres(&s);
    check(&ps, &random_rays(&ps, 50_000, 13), "soup");
    let s = tie_scene();
    let ps = with_analytic_spheres(&s);
    check(&ps, &random_rays(&ps, 20_000, 14), "ties");
    if let Some(mesh) = bunny() {
        let s = scene_of(mesh, &[]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        check(&ps, &random_rays(&ps, 50_000, 15), "bunny");
    }
}
