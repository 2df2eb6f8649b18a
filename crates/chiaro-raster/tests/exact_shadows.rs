//! Exact shadow methods against each other: object-precision
//! (Atherton-Weiler-Greenberg) fragments, Bouknight-Kelley scan-line shadows
//! and shadow rays classify the same pixel centres; lit fragments tile the
//! lit part of each polygon.

use chiaro_core::Vec3;
use chiaro_core::accel::Accelerator;
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::geometry::{Ray, face_normal, offset_ray_origin};
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::scene::{Attenuation, Geometry, Light, Material, Mesh, Object, Scene};
use chiaro_raster::shadows::object_precision::ObjectShadows;
use chiaro_raster::shadows::scanline::scanline_visibility;
use chiaro_raster::zbuffer::NO_ITEM;

/// Ray-traced visibility of light position `l` from `p` on a surface with
/// geometric normal `ng` (the renderer's shadow-ray convention).
fn ray_lit(bvh: &SceneBvh, p: Vec3, ng: Vec3, l: Vec3) -> bool {
    let wi = (l - p).normalize();
    !bvh.occluded(&Ray::segment(offset_ray_origin(p, ng, wi), l))
}

#[test]
fn object_scanline_and_ray_shadows_classify_every_pixel_alike() {
    let scene = chiaro_testkit::scenes::shadow_test(64);
    let ps = PreparedScene::new(&scene, PrepareOptions::default());
    let li = ps
        .lights
        .iter()
        .position(|l| matches!(l, Light::Point { .. }))
        .expect("point light");
    let Light::Point { position: l, .. } = ps.lights[li] else {
        unreachable!()
    };
    let (w, h) = (64u32, 64u32);
    let obj = ObjectShadows::build(&ps, li).expect("object shadows");
    let scan = scanline_visibility(&ps, &scene.camera, w, h, li).expect("scanline");
    let bvh = SceneBvh::new(&ps);
    let (mut n, mut shadowed, mut obj_bad, mut scan_bad) = (0, 0, 0, 0);
    let mut img = vec![[0u8; 3]; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let t = scan.visible[i];
            if t == NO_ITEM {
                continue;
            }
            let [a, b, c] = ps.triangles[t as usize].map(|k| ps.positions[k as usize]);
            let ng = face_normal(a, b, c).expect("non-degenerate");
            // The visible point: the pixel-centre ray on the triangle's plane.
            let d = scene
                .camera
                .ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let s = (a - scene.camera.eye).dot(ng) / d.dot(ng);
            let p = scene.camera.eye + d * s;
            let ray = ray_lit(&bvh, p, ng, l);
            let o = obj.lit_fraction(t, p) == 1.0;
            let sc = scan.lit[i] == 1.0;
            n += 1;
            shadowed += usize::from(!ray);
            obj_bad += usize::from(o != ray);
            img[i] = match (o, sc == o && o == ray) {
                (_, false) => [255, 0, 0],
                (true, _) => [230, 230, 230],
                (false, _) => [40, 40, 120],
            };
            scan_bad += usize::from(sc != ray);
        }
    }
    if let Ok(dir) = std::env::var("CHIARO_DUMP") {
        let im = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(img[(y * w + x) as usize]));
        let _ = im.save(format!("{dir}/exact_shadows_{w}.png"));
    }
    assert!(n > 2500, "only {n} covered pixels");
    assert!(shadowed > 100, "only {shadowed} shadowed pixels");
    // Exact methods: identical up to points within float epsilon of a
    // shadow boundary.
    let bound = n / 500;
    assert!(obj_bad <= bound, "object vs ray: {obj_bad} of {n} differ");
    assert!(
        scan_bad <= bound,
        "scanline vs ray: {scan_bad} of {n} differ"
    );
    println!("{n} pixels, {shadowed} shadowed, object {obj_bad}, scanline {scan_bad} differ");
    println!(
        "{} fragments, {} candidate pairs, {} shadow polygons",
        obj.fragment_count(),
        scan.candidate_pairs,
        scan.shadow_polygons
    );
}

/// A one-material scene from triangles (each its own object) and one light.
fn scene_of(tris: &[[Vec3; 3]], light: Light) -> Scene {
    let mut s = Scene::default();
    let m = s.add_material(Material::diffuse("m", Vec3::splat(0.5)));
    for t in tris {
        let mesh = s.add_mesh(Mesh {
            positions: t.to_vec(),
            indices: vec![[0, 1, 2]],
            ..Mesh::default()
        });
        s.objects.push(Object {
            geometry: Geometry::Mesh(mesh),
            material: m,
            smooth: false,
            ..Object::default()
        });
    }
    s.lights.push(light);
    s
}

/// Two triangles making the axis-aligned quad `[x0, x1] x [z0, z1]` at
/// height `y`, facing up.
fn quad(x0: f32, x1: f32, z0: f32, z1: f32, y: f32) -> [[Vec3; 3]; 2] {
    let p = |x, z| Vec3::new(x, y, z);
    [
        [p(x0, z0), p(x0, z1), p(x1, z1)],
        [p(x0, z0), p(x1, z1), p(x1, z0)],
    ]
}

fn tri_area(t: [Vec3; 3]) -> f32 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
}

/// Checks that the fragments of triangle 0 and 1 (the floor quad) have
/// total area `lit` and do not overlap, and that sampled points are inside
/// a fragment exactly when the shadow ray reaches the light.
fn check_tiling(scene: &Scene, light_pos: Vec3, lit: f32, what: &str) {
    let ps = PreparedScene::new(scene, PrepareOptions::default());
    let obj = ObjectShadows::build(&ps, 0).expect("build");
    let bvh = SceneBvh::new(&ps);
    let mut total = 0.0;
    let mut rng = chiaro_testkit::XorShift64(0x9e37_79b9_7f4a_7c15u64);
    let mut rnd = move || rng.unit();
    let (mut bad, mut samples) = (0, 0);
    for t in 0..2u32 {
        let frags = obj.fragments(t);
        total += frags.iter().map(|f| f.area()).sum::<f32>();
        let tri = ps.triangles[t as usize].map(|k| ps.positions[k as usize]);
        let ng = face_normal(tri[0], tri[1], tri[2]).expect("tri");
        for _ in 0..4000 {
            let (mut u, mut v) = (rnd(), rnd());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v;
            // Fragments containing p (strictly, in the fragment's plane).
            // Clipping can leave two corners a float apart (the fragment's
            // world corners are f32), and an edge that short has no usable
            // direction: such corners are merged first, and the winding
            // comes from the fragment's signed area.
            let inside = frags
                .iter()
                .filter(|f| {
                    let mut q: Vec<Vec3> = Vec::with_capacity(f.points.len());
                    for &x in &f.points {
                        if q.last().is_none_or(|&l: &Vec3| (x - l).length() > 1e-5) {
                            q.push(x);
                        }
                    }
                    while q.len() > 1 && (q[0] - q[q.len() - 1]).length() <= 1e-5 {
                        q.pop();
                    }
                    let k = q.len();
                    if k < 3 {
                        return false;
                    }
                    let winding: f32 = (1..k - 1)
                        .map(|i| (q[i] - q[0]).cross(q[i + 1] - q[0]).dot(ng))
                        .sum::<f32>()
                        .signum();
                    (0..k).all(|i| {
                        let (a, b) = (q[i], q[(i + 1) % k]);
                        (b - a).cross(p - a).dot(ng) * winding > 1e-7
                    })
                })
                .count();
            assert!(inside <= 1, "{what}: {inside} fragments overlap at {p}");
            let lit_here = ray_lit(&bvh, p, ng, light_pos);
            samples += 1;
            bad += usize::from((obj.lit_fraction(t, p) == 1.0) != lit_here);
        }
    }
    assert!(
        (total - lit).abs() <= 1e-4 * lit.max(1.0),
        "{what}: fragments cover {total}, lit area {lit}"
    );
    assert!(
        bad * 1000 <= samples,
        "{what}: {bad} of {samples} samples differ from rays"
    );
}

/// [`check_tiling`] of the triangles `tris` under a point light at `light`.
fn point_tiling(tris: &[[Vec3; 3]], light: Vec3, lit: f32, what: &str) {
    check_tiling(&scene_of(tris, point(light)), light, lit, what);
}

fn point(at: Vec3) -> Light {
    Light::Point {
        position: at,
        color: Vec3::ONE,
        intensity: 1.0,
        attenuation: Attenuation::None,
    }
}

#[test]
fn lit_fragments_tile_the_lit_area() {
    let floor = quad(-2.0, 2.0, -2.0, 2.0, 0.0);
    let light = Vec3::new(0.0, 4.0, 0.0);
    let full = 16.0;
    // 1. A square occluder at height 1 under a point light at height 4:
    //    its shadow is scaled by 4 / 3.
    let occ = quad(-0.5, 0.5, -0.3, 0.6, 1.0);
    let mut tris = floor.to_vec();
    tris.extend(occ);
    let shadow = 0.9 * 1.0 * (4.0f32 / 3.0).powi(2);
    point_tiling(&tris, light, full - shadow, "one square");
    // 2. Two overlapping squares at the same height: the union's shadow.
    let mut tris = floor.to_vec();
    tris.extend(quad(-0.9, 0.3, -0.9, 0.3, 2.0));
    tris.extend(quad(-0.3, 0.9, -0.3, 0.9, 2.0));
    let union = 1.2 * 1.2 * 2.0 - 0.6 * 0.6;
    point_tiling(&tris, light, full - union * 4.0, "overlap");
    // 3. Touching: a vertical wall standing on the floor along x = 0.5,
    //    lit from the side; its shadow touches its foot. Wall height 1,
    //    depth [-1, 1] in z, light at x = -1, y = 4: the shadow reaches
    //    x = 0.5 + 1.5 / 3 = 1.0 (similar triangles), a trapezoid in z.
    let light3 = Vec3::new(-1.0, 4.0, 0.0);
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let mut tris = floor.to_vec();
    tris.push([p(0.5, 0.0, -1.0), p(0.5, 1.0, -1.0), p(0.5, 1.0, 1.0)]);
    tris.push([p(0.5, 0.0, -1.0), p(0.5, 1.0, 1.0), p(0.5, 0.0, 1.0)]);
    // The top edge (y = 1, z in [-1, 1]) projects to x = 1.0, z in
    // [-4/3, 4/3]: a trapezoid with parallel sides 2 and 8/3, width 0.5.
    let shadow3 = 0.5 * (2.0 + 8.0 / 3.0) * 0.5;
    point_tiling(&tris, light3, full - shadow3, "touching wall");
    // 4. Coplanar and touching neighbours: more floor triangles in the
    //    same plane, sharing edges, cast nothing.
    let mut tris = floor.to_vec();
    tris.extend(quad(2.0, 3.0, -2.0, 2.0, 0.0));
    tris.push([p(-1.0, 0.0, -1.0), p(-1.0, 0.0, 1.0), p(1.0, 0.0, 1.0)]);
    point_tiling(&tris, light, full, "coplanar");
    // 5. A directional light straight down: the shadow is the occluder.
    let mut tris = floor.to_vec();
    let t = [p(-1.0, 1.5, -1.0), p(0.0, 1.5, 1.0), p(1.0, 1.5, -0.5)];
    tris.push(t);
    let sun = Light::Directional {
        direction: Vec3::NEG_Y,
        color: Vec3::ONE,
        intensity: 1.0,
    };
    check_tiling(
        &scene_of(&tris, sun),
        Vec3::new(0.0, 1e4, 0.0),
        full - tri_area(t),
        "directional",
    );
}
