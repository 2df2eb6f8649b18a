//! Property tests (proptest) for invariants that are cheap to state: the
//! vertex weld, the BVH against a brute-force triangle loop, the sampling
//! functions and their pdfs, the lat-long map and the alias table. Case
//! counts are bounded so that the whole file runs in about a second.

use crate::accel::bvh::SceneBvh;
use crate::accel::{Accelerator, intersect_triangle};
use crate::geometry::Ray;
use crate::geometry::normals::{Work, weld};
use crate::prepared::{PrepareOptions, PreparedScene};
use crate::sampling::{
    cosine_hemisphere_pdf, phong_lobe_pdf, sample_concentric_disk, sample_cosine_hemisphere,
    sample_phong_lobe, sample_uniform_hemisphere, sample_uniform_sphere, sample_uniform_triangle,
};
use crate::scene::{Geometry, Material, Mesh, Object, Scene};
use crate::shading::light_set::AliasTable;
use crate::shading::texture::latlong_uv;
use glam::{Vec2, Vec3};
use proptest::prelude::*;
use std::f32::consts::{PI, TAU};

/// A point on a coarse lattice (spacing `0.05`) plus a jitter below the
/// spacing, so that welds at a tolerance of 0.1 both happen and do not.
fn lattice_point() -> impl Strategy<Value = Vec3> {
    (
        prop::array::uniform3(-8i32..8),
        prop::array::uniform3(0.0f32..0.05),
    )
        .prop_map(|(k, j)| Vec3::from_array(k.map(|k| k as f32 * 0.05)) + Vec3::from_array(j))
}

fn unit_square() -> impl Strategy<Value = Vec2> {
    (0.0f32..1.0, 0.0f32..1.0).prop_map(|(x, y)| Vec2::new(x, y))
}

fn direction() -> impl Strategy<Value = Vec3> {
    prop::array::uniform3(-1.0f32..1.0)
        .prop_filter("not near zero", |a| Vec3::from_array(*a).length() > 0.05)
        .prop_map(|a| Vec3::from_array(a).normalize())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Every vertex welds to the lowest-indexed representative within the
    /// tolerance (itself when none), representatives are more than the
    /// tolerance apart, and welding the welded positions changes nothing.
    #[test]
    fn weld_is_idempotent_and_stays_within_the_tolerance(
        points in prop::collection::vec(lattice_point(), 1..200),
        tol in prop::sample::select(vec![0.0f32, 0.01, 0.1]),
    ) {
        let w = weld(&points, tol, &mut Work::default());
        prop_assert_eq!(w.len(), points.len());
        for (i, &r) in w.iter().enumerate() {
            let r = r as usize;
            prop_assert!(r <= i);
            prop_assert_eq!(w[r] as usize, r, "a representative welds to itself");
            let d = f64::from(points[i].distance(points[r]));
            prop_assert!(d <= f64::from(tol) * (1.0 + 1e-6), "{} apart, tolerance {}", d, tol);
        }
        let reps: Vec<usize> = (0..points.len()).filter(|&i| w[i] as usize == i).collect();
        for (a, &i) in reps.iter().enumerate() {
            for &j in &reps[a + 1..] {
                prop_assert!(points[i].distance(points[j]) > tol * (1.0 - 1e-6));
            }
        }
        let welded: Vec<Vec3> = w.iter().map(|&r| points[r as usize]).collect();
        prop_assert_eq!(weld(&welded, tol, &mut Work::default()), w);
    }

    /// The BVH's closest hit (slab tests over boxes, then the watertight
    /// triangle test) is the closest hit of a loop over every triangle.
    #[test]
    fn bvh_agrees_with_a_brute_force_triangle_loop(
        tris in prop::collection::vec(prop::array::uniform3(prop::array::uniform3(-2.0f32..2.0)), 1..40),
        rays in prop::collection::vec((prop::array::uniform3(-3.0f32..3.0), direction()), 16),
    ) {
        let mut scene = Scene::default();
        let m = scene.add_material(Material::diffuse("m", Vec3::splat(0.5)));
        let mut mesh = Mesh::default();
        for t in &tris {
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(t.iter().map(|p| Vec3::from_array(*p)));
            mesh.indices.push([base, base + 1, base + 2]);
        }
        let id = scene.add_mesh(mesh);
        scene.objects.push(Object { geometry: Geometry::Mesh(id), material: m, ..Default::default() });
        let ps = PreparedScene::new(&scene, PrepareOptions::default());
        let bvh = SceneBvh::new(&ps);
        for (o, d) in rays {
            let ray = Ray::new(Vec3::from_array(o), d);
            let brute = ps
                .triangles
                .iter()
                .filter_map(|t| {
                    let [a, b, c] = t.map(|i| ps.positions[i as usize]);
                    intersect_triangle(&ray, a, b, c).map(|h| h.0)
                })
                .min_by(f32::total_cmp);
            let hit = bvh.intersect(&ray).map(|h| h.t);
            prop_assert_eq!(hit, brute);
            prop_assert_eq!(bvh.occluded(&ray), brute.is_some());
        }
    }

    /// Direction samplers give unit vectors on their domain, and points on
    /// the disk and the triangle stay inside.
    #[test]
    fn samplers_return_unit_vectors(u in unit_square(), n in 0.0f32..2000.0) {
        let unit = |v: Vec3| (v.length() - 1.0).abs() < 1e-5;
        let c = sample_cosine_hemisphere(u);
        prop_assert!(unit(c) && c.z >= 0.0, "{:?}", c);
        prop_assert!(cosine_hemisphere_pdf(c.z).is_finite());
        let h = sample_uniform_hemisphere(u);
        prop_assert!(unit(h) && h.z >= 0.0, "{:?}", h);
        prop_assert!(unit(sample_uniform_sphere(u)));
        let p = sample_phong_lobe(u, n);
        prop_assert!(unit(p) && p.z >= 0.0, "{:?}", p);
        let pdf = phong_lobe_pdf(p.z, n);
        prop_assert!(pdf.is_finite() && pdf >= 0.0);
        prop_assert!(sample_concentric_disk(u).length() <= 1.0 + 1e-6);
        let b = sample_uniform_triangle(u);
        prop_assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6, "{:?}", b);
    }

    /// The Phong lobe's sampled cosine follows the distribution of its pdf:
    /// `P(cos >= c) = 1 - c^(n+1)` from the pdf, and the sampler inverts
    /// that, so `cos^(n+1)` is the first uniform number; and the pdf
    /// integrates to one over the hemisphere.
    #[test]
    fn phong_lobe_sampling_matches_its_pdf(ux in 0.001f32..1.0, n in 0.0f32..1000.0) {
        let cos_t = sample_phong_lobe(Vec2::new(ux, 0.3), n).z;
        let back = cos_t.powf(n + 1.0);
        prop_assert!((back - ux).abs() < 2e-3 * (1.0 + n / 100.0), "{} vs {}", back, ux);
        // Midpoint rule in cos over [0, 1], times 2 pi for the azimuth.
        let k = 20_000;
        let integral: f64 = (0..k)
            .map(|i| f64::from(phong_lobe_pdf((i as f32 + 0.5) / k as f32, n)))
            .sum::<f64>()
            * f64::from(TAU)
            / f64::from(k);
        prop_assert!((integral - 1.0).abs() < 1e-3, "integral {}", integral);
    }

    /// Cosine-weighted samples follow `P(cos >= c) = 1 - c^2`, the
    /// distribution of `cosine_hemisphere_pdf`, on a stratified grid. The
    /// concentric map sends the grid's squares to rings `2 / k` apart in
    /// radius, so the share is exact to about `4 / k` (1 - r^2 per ring).
    #[test]
    fn cosine_hemisphere_sampling_matches_its_pdf(c in 0.0f32..1.0) {
        let k = 512;
        let above = (0..k * k)
            .filter(|i| {
                let u = Vec2::new(((i % k) as f32 + 0.5) / k as f32, ((i / k) as f32 + 0.5) / k as f32);
                sample_cosine_hemisphere(u).z >= c
            })
            .count();
        let expected = 1.0 - c * c;
        let share = above as f32 / (k * k) as f32;
        prop_assert!((share - expected).abs() < 0.01, "{} above vs {}", share, expected);
    }

    /// Lat-long coordinates stay in `[0, 1]^2` and invert: the direction of
    /// `(u, v)` under the documented convention (`v = 0` is +y, `u = 0.5`
    /// is -z, `u = 0.75` is +x) is the direction they came from.
    #[test]
    fn latlong_round_trip(d in direction()) {
        let uv = latlong_uv(d);
        prop_assert!((0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y), "{:?}", uv);
        let (phi, theta) = ((uv.x - 0.5) * TAU, uv.y * PI);
        let back = Vec3::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos());
        prop_assert!(back.distance(d) < 1e-4, "{:?} -> {:?} -> {:?}", d, uv, back);
    }

    /// The alias table picks index `i` with probability `pmf(i)`, and
    /// `pmf(i)` is `w_i / sum(w)`: measured over a stratified grid of `u`
    /// (1024 per bucket), each index's share is its pmf.
    #[test]
    fn alias_table_probabilities(weights in prop::collection::vec(0.0f32..10.0, 1..24)) {
        let total: f64 = weights.iter().map(|&w| f64::from(w)).sum();
        let Some(t) = AliasTable::new(&weights) else {
            prop_assert!(total == 0.0);
            return Ok(());
        };
        let n = weights.len();
        let m = n * 1024;
        let mut count = vec![0usize; n];
        for k in 0..m {
            let (i, rest) = t.sample((k as f32 + 0.5) / m as f32);
            prop_assert!((0.0..1.0).contains(&rest));
            count[i] += 1;
        }
        for i in 0..n {
            let p = f64::from(weights[i]) / total;
            prop_assert!((f64::from(t.pmf(i)) - p).abs() < 1e-6);
            prop_assert!((count[i] as f64 / m as f64 - p).abs() < 2.0 / 1024.0, "index {}", i);
            if weights[i] == 0.0 {
                prop_assert_eq!(count[i], 0);
            }
        }
    }
}
