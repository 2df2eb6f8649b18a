//! Unit tests of the Whitted ray tracer: shading terms, shadow rays,
//! refraction, adaptive sampling, crops and errors.

use super::*;
use chiaro_core::error::CoreError;
use chiaro_core::geometry::primitives;
use chiaro_core::progress::{CountingProgress, NoProgress, Progress};
use chiaro_core::scene::{
    AreaShape, Geometry, Light, Material, MaterialId, Mesh, Object, Scene, Transform,
};
use chiaro_core::shading::{fresnel_dielectric, refract};
use chiaro_testkit::scenes::point_light;

fn lambert(kd: f32) -> Material {
    Material {
        diffuse: Vec3::splat(kd),
        ..Material::default()
    }
}

fn glass(ior: f32, fresnel: bool) -> Material {
    Material {
        diffuse: Vec3::ZERO,
        specular: Vec3::ZERO,
        transmit: Vec3::ONE,
        reflect: Vec3::ZERO,
        ior,
        fresnel,
        ..Material::default()
    }
}

fn add(s: &mut Scene, mesh: Mesh, m: MaterialId, translate: Vec3) {
    let id = s.add_mesh(mesh);
    s.objects.push(Object {
        geometry: Geometry::Mesh(id),
        material: m,
        smooth: false,
        transform: Transform {
            translate,
            ..Default::default()
        },
        ..Default::default()
    });
}

/// A 20 x 20 slab of material `m`, `2 half` thick, centred at the origin.
fn add_slab(s: &mut Scene, half: f32, m: MaterialId) {
    add(
        s,
        primitives::box_mesh(Vec3::new(10.0, half, 10.0)),
        m,
        Vec3::ZERO,
    );
}

fn add_sphere(s: &mut Scene, c: Vec3, r: f32, m: MaterialId) {
    s.objects.push(Object {
        geometry: Geometry::Sphere { radius: r },
        material: m,
        transform: Transform {
            translate: c,
            ..Default::default()
        },
        ..Default::default()
    });
}

/// The tracer over a render context of `s` with `st`.
fn render_with_stats(
    s: &Scene,
    st: &RenderSettings,
    p: &dyn Progress,
) -> Result<(Film, RenderStats)> {
    let ctx = RenderContext::new(s, st, p)?;
    Tracer::new(&ctx).render(&ctx)
}

fn render(s: &Scene, st: &RenderSettings, p: &dyn Progress) -> Result<Film> {
    render_with_stats(s, st, p).map(|(film, _)| film)
}

fn context<'a>(s: &'a Scene, st: &RenderSettings) -> RenderContext<'a> {
    RenderContext::new(s, st, &NoProgress).expect("a valid scene")
}

fn settings(w: u32, h: u32) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        samples: 1,
        ..RenderSettings::default()
    }
}

#[test]
fn an_emissive_mesh_costs_light_samples_shadow_rays_per_point() {
    // 3,200 emissive triangles (a two-sided panel above the floor) and
    // light_samples = 4: at most 4 shadow rays per camera hit, not one
    // per triangle and sample.
    let mut s = floor_scene();
    s.lights.clear();
    let panel = s.add_material(Material {
        emission: Vec3::splat(2.0),
        emission_two_sided: true,
        ..lambert(0.5)
    });
    add(
        &mut s,
        primitives::plane(1.0, 40),
        panel,
        Vec3::new(0.0, 2.0, 0.0),
    );
    let mut st = settings(40, 30);
    st.light_samples = 4;
    st.whitted.max_depth = 0;
    let (film, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
    assert_eq!(stats.camera_rays, 40 * 30);
    let shadow_rays = stats.rays - stats.camera_rays;
    assert!(shadow_rays > 0);
    assert!(
        shadow_rays <= 4 * stats.camera_rays,
        "{shadow_rays} shadow rays for {} camera rays",
        stats.camera_rays
    );
    // The floor is lit by the panel, and no pixel is NaN.
    assert!(film.color.iter().all(|c| c.is_finite()));
    let lit = film.color.iter().filter(|c| c.x > 0.05).count();
    assert!(lit > 40 * 30 / 4, "{lit} lit pixels");
}

/// A floor (y = 0, kd 0.5) lit by a point light at (0, 4, 0) of
/// intensity 16 (inverse square) and an ambient light of 1.
fn floor_scene() -> Scene {
    let mut s = Scene::default();
    let floor = s.add_material(lambert(0.5));
    add(&mut s, primitives::plane(20.0, 1), floor, Vec3::ZERO);
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 1.0,
    });
    s.lights.push(point_light(Vec3::new(0.0, 4.0, 0.0), 16.0));
    s.background = Vec3::new(0.1, 0.2, 0.3);
    s.camera.eye = Vec3::new(0.0, 3.0, 6.0);
    s.camera.look_at = Vec3::ZERO;
    s
}

/// The radiance seen along a ray from `from` towards `to`.
/// A white one-sided quad area light `corner + s edge_u + t edge_v` of
/// `intensity`.
fn quad_light(corner: Vec3, edge_u: Vec3, edge_v: Vec3, intensity: f32) -> Light {
    Light::Area {
        shape: AreaShape::Quad {
            corner,
            edge_u,
            edge_v,
        },
        color: Vec3::ONE,
        intensity,
        two_sided: false,
    }
}

/// A unit delta light sample straight above the origin, at height 4.
fn overhead_sample() -> LightSample {
    LightSample {
        wi: Vec3::Y,
        distance: 4.0,
        point: Vec3::new(0.0, 4.0, 0.0),
        intensity: Vec3::ONE,
        is_delta: true,
    }
}

fn look(t: &Tracer<'_>, from: Vec3, to: Vec3) -> Vec3 {
    let mut st = TraceState::new(pixel_rng(0, 0, 0, 0));
    t.trace(&Ray::new(from, to - from), 0, Vec3::ONE, &mut st)
}

fn max_diff(a: &Film, b: &Film) -> f32 {
    a.color
        .iter()
        .zip(&b.color)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f32::max)
}

#[test]
fn snell_tir_and_fresnel_closed_forms() {
    // Snell: n1 sin(theta_i) = n2 sin(theta_t) at known angles.
    for (n1, n2) in [(1.0f32, 1.5f32), (1.0, 1.33), (1.5, 1.0), (2.4, 1.0)] {
        let crit = if n1 > n2 { (n2 / n1).asin() } else { 10.0 };
        for deg in [0.0f32, 15.0, 30.0, 45.0, 60.0, 80.0] {
            let th = deg.to_radians();
            let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
            match refract(wo, Vec3::Y, n1 / n2) {
                Some(wt) => {
                    assert!(th < crit);
                    let sin_t = wt.x;
                    assert!(
                        (n1 * th.sin() - n2 * sin_t).abs() < 1e-5,
                        "{n1}->{n2} at {deg}"
                    );
                    assert!(wt.y < 0.0);
                    // Fresnel: R + T = 1 with T from the transmission
                    // amplitudes (Hecht, Optics, eqs. 4.43-4.44, 4.62).
                    let (ci, ct) = (th.cos(), (-wt.y));
                    let ts = 2.0 * n1 * ci / (n1 * ci + n2 * ct);
                    let tp = 2.0 * n1 * ci / (n2 * ci + n1 * ct);
                    let t = (n2 * ct) / (n1 * ci) * 0.5 * (ts * ts + tp * tp);
                    let r = fresnel_dielectric(ci, n1, n2);
                    assert!((r + t - 1.0).abs() < 1e-5, "R {r} + T {t}");
                }
                None => assert!(th > crit, "{n1}->{n2}: TIR at {deg} below critical"),
            }
        }
        // Normal incidence: ((n1 - n2) / (n1 + n2))^2.
        let r0 = ((n1 - n2) / (n1 + n2)).powi(2);
        assert!((fresnel_dielectric(1.0, n1, n2) - r0).abs() < 1e-6);
        // TIR exactly past asin(n2 / n1).
        if n1 > n2 {
            let dir = |a: f32| Vec3::new(-a.sin(), a.cos(), 0.0);
            assert!(refract(dir(crit - 1e-4), Vec3::Y, n1 / n2).is_some());
            assert!(refract(dir(crit + 1e-4), Vec3::Y, n1 / n2).is_none());
            assert_eq!(fresnel_dielectric((crit + 1e-4).cos(), n1, n2), 1.0);
            assert!(fresnel_dielectric((crit - 1e-4).cos(), n1, n2) < 1.0);
        }
    }
}

#[test]
fn total_internal_reflection_reflects_everything() {
    let m = SurfaceMaterial::from_material(&Material {
        reflect: Vec3::splat(0.1),
        ..glass(1.5, false)
    });
    let th = 60f32.to_radians(); // past the critical angle 41.8 degrees
    let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
    let r = specular_rays(&m, false, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
    assert!(r.refracted.is_none());
    assert!((r.reflected.1 - Vec3::splat(1.1)).abs().max_element() < 1e-6);
    let rf = specular_rays(&m, true, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
    assert!(rf.refracted.is_none());
    assert!((rf.reflected.1 - Vec3::ONE).abs().max_element() < 1e-6);
    // Below the critical angle both rays exist and a Fresnel glass splits
    // F / (1 - F).
    let th = 20f32.to_radians();
    let wo = Vec3::new(-th.sin(), th.cos(), 0.0);
    let r = specular_rays(&m, true, Vec3::ZERO, Vec3::Y, Vec3::Y, wo, false);
    let (_, wt) = r.refracted.expect("no TIR at 20 degrees");
    assert!((r.reflected.1.x + wt.x - 1.0).abs() < 1e-6);
}

#[test]
fn slab_exit_is_parallel_with_closed_form_shift() {
    let mut s = Scene::default();
    let g = s.add_material(glass(1.5, true));
    add_slab(&mut s, 0.5, g);
    let ctx_t = context(&s, &settings(8, 8));
    let t = Tracer::new(&ctx_t);
    for deg in [0.0f32, 20.0, 45.0, 70.0, 85.0] {
        let th = deg.to_radians();
        let d_in = Vec3::new(th.sin(), -th.cos(), 0.0);
        let mut ray = Ray::new(Vec3::new(0.0, 0.5, 0.0) - 2.0 * d_in, d_in);
        let mut points = Vec::new();
        for _ in 0..2 {
            let hit = t.accel.intersect(&ray).expect("slab face");
            let sh = t.prepared.surface(&ray, &hit);
            let wo = -ray.dir.normalize();
            let front = sh.ng.dot(wo) >= 0.0;
            let (n, ng) = if front {
                (sh.ns, sh.ng)
            } else {
                (-sh.ns, -sh.ng)
            };
            let m = t.prepared.surface_material(&sh);
            let sr = specular_rays(&m, true, sh.p, n, ng, wo, front);
            ray = sr.refracted.expect("no TIR in a slab").0;
            points.push(sh.p);
        }
        assert!(
            (ray.dir.normalize() - d_in).length() < 1e-5,
            "{deg}: exits along {} not {d_in}",
            ray.dir
        );
        // Inside, the ray runs at theta_t = asin(sin(theta) / 1.5):
        // the exit is tan(theta_t) * thickness further along x.
        let th_t = (th.sin() / 1.5).asin();
        assert!((points[1].y + 0.5).abs() < 1e-5);
        assert!(
            (points[1].x - points[0].x - th_t.tan()).abs() < 1e-4,
            "{deg}: shift {}",
            points[1].x - points[0].x
        );
    }
}

#[test]
fn beer_absorption_through_slab() {
    let mut s = Scene::default();
    let g = s.add_material(Material {
        absorption: Vec3::new(0.5, 1.0, 0.0),
        ..glass(1.5, false)
    });
    add_slab(&mut s, 0.75, g);
    s.background = Vec3::new(1.0, 0.5, 0.25);
    let ctx_t = context(&s, &settings(8, 8));
    let t = Tracer::new(&ctx_t);
    let c = look(&t, Vec3::new(0.0, 3.0, 0.0), Vec3::ZERO);
    let expect = s.background * (-Vec3::new(0.5, 1.0, 0.0) * 1.5).exp();
    assert!((c - expect).abs().max_element() < 1e-4, "{c} vs {expect}");
}

#[test]
fn local_shading_with_and_without_shadow_rays() {
    let mut s = floor_scene();
    let black = s.add_material(lambert(0.0));
    add_sphere(&mut s, Vec3::new(0.0, 2.0, 0.0), 0.5, black);
    // Looking at the origin from the side, under the occluder.
    let from = Vec3::new(3.0, 1.0, 0.0);
    let ambient = 0.1 * 0.5; // Ia ka kd
    let lit = 0.5 * 16.0 / 16.0; // kd Ip / d^2, normal incidence
    let ctx_t = context(&s, &settings(8, 8));
    let t = Tracer::new(&ctx_t);
    let c = look(&t, from, Vec3::ZERO);
    assert!((c.x - ambient).abs() < 1e-5, "shadowed: {c}");
    let none = RenderSettings {
        shadows: ShadowMethod::None,
        ..settings(8, 8)
    };
    let ctx_t = context(&s, &none);
    let t = Tracer::new(&ctx_t);
    let c = look(&t, from, Vec3::ZERO);
    assert!((c.x - ambient - lit).abs() < 1e-4, "unshadowed: {c}");
    // The same through the public visibility query.
    let sample = overhead_sample();
    assert_eq!(t.light_visibility(Vec3::ZERO, Vec3::Y, &sample), Vec3::ONE);
    let ctx_t = context(&s, &settings(8, 8));
    let t = Tracer::new(&ctx_t);
    assert_eq!(t.light_visibility(Vec3::ZERO, Vec3::Y, &sample), Vec3::ZERO);
}

#[test]
fn shadow_rays_are_tinted_by_transparent_surfaces() {
    let mut s = floor_scene();
    let filter = s.add_material(Material {
        transmit: Vec3::new(0.5, 0.25, 1.0),
        ..glass(1.0, false)
    });
    // A thin filter quad between the light and the floor (one crossing).
    add(
        &mut s,
        primitives::quad(
            Vec3::new(-1.0, 2.0, 1.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -2.0),
        ),
        filter,
        Vec3::ZERO,
    );
    let ctx_t = context(&s, &settings(8, 8));
    let t = Tracer::new(&ctx_t);
    let sample = overhead_sample();
    let v = t.light_visibility(Vec3::ZERO, Vec3::Y, &sample);
    assert!(
        (v - Vec3::new(0.5, 0.25, 1.0)).abs().max_element() < 1e-6,
        "{v}"
    );
}

#[test]
fn two_level_bvh_renders_like_the_flat_bvh() {
    use chiaro_core::accel::bvh::SceneBvh;
    use chiaro_core::accel::instanced::{
        InstancedBvh, MIN_DUPLICATED_TRIANGLES, duplicated_triangles,
    };
    let mut s = floor_scene();
    let opaque = s.add_material(lambert(0.7));
    let tinted = s.add_material(Material {
        transmit: Vec3::new(0.6, 0.4, 0.8),
        ..glass(1.0, false)
    });
    // Eight placements of one 5120-triangle sphere, half of them
    // transparent filters (their shadow rays visit every hit).
    let ball = s.add_mesh(primitives::icosphere(0.45, 4));
    for i in 0..8 {
        s.objects.push(Object {
            geometry: Geometry::Mesh(ball),
            material: if i % 2 == 0 { opaque } else { tinted },
            smooth: true,
            transform: Transform {
                translate: Vec3::new(i as f32 - 3.5, 0.6 + 0.3 * (i % 3) as f32, -0.5),
                scale: Vec3::new(1.0, 1.0 + 0.1 * i as f32, 1.0),
                ..Default::default()
            },
            ..Default::default()
        });
    }
    let mut st = settings(48, 32);
    st.light_samples = 1;
    fn flat(ps: &PreparedScene<'_>) -> Box<dyn Accelerator> {
        Box::new(SceneBvh::new(ps))
    }
    fn two_level(ps: &PreparedScene<'_>) -> Box<dyn Accelerator> {
        Box::new(InstancedBvh::new(ps))
    }
    let ctx_flat = context(&s, &st).with_accelerator(&flat);
    let flat_tracer = Tracer::new(&ctx_flat);
    assert!(duplicated_triangles(flat_tracer.prepared) >= MIN_DUPLICATED_TRIANGLES);
    let ctx_two_level = context(&s, &st).with_accelerator(&two_level);
    let two_level_tracer = Tracer::new(&ctx_two_level);
    let two_level = InstancedBvh::new(two_level_tracer.prepared);
    assert_eq!(two_level.instance_count(), 8 + 1);
    let (a, _) = flat_tracer.render(&ctx_flat).expect("flat render");
    let (b, _) = two_level_tracer
        .render(&ctx_two_level)
        .expect("two-level render");
    // Tinted shadows and tinted views through the filters are present.
    let tinted_px = a
        .color
        .iter()
        .filter(|c| (c.x - c.y).abs() > 0.02 && c.z > c.y)
        .count();
    assert!(tinted_px > 20, "{tinted_px} tinted pixels");
    // Object-space rounding may move a silhouette or a shadow edge by a
    // pixel; everything else is the same up to float noise.
    let differ = a
        .color
        .iter()
        .zip(&b.color)
        .filter(|(x, y)| (**x - **y).abs().max_element() > 1e-3)
        .count();
    assert!(differ * 100 <= a.color.len(), "{differ} pixels differ");
}

#[test]
fn soft_shadow_has_umbra_and_penumbra() {
    let mut s = floor_scene();
    s.lights.truncate(1);
    s.lights.push(quad_light(
        Vec3::new(-0.5, 4.0, -0.5),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
        10.0,
    ));
    let black = s.add_material(lambert(0.0));
    add_sphere(&mut s, Vec3::new(0.0, 2.0, 0.0), 0.5, black);
    let mut st = settings(8, 8);
    st.light_samples = 64;
    let ctx_t = context(&s, &st);
    let t = Tracer::new(&ctx_t);
    let mut open = s.clone();
    open.objects.pop();
    let ctx_t_open = context(&open, &st);
    let t_open = Tracer::new(&ctx_t_open);
    let ambient = 0.05;
    let (mut umbra, mut penumbra, mut lit) = (false, false, false);
    for i in 0..=40 {
        let x = i as f32 * 0.05;
        let p = Vec3::new(x, 0.0, 0.0);
        let from = Vec3::new(x, 0.6, 5.0);
        let c = look(&t, from, p).x;
        let full = look(&t_open, from, p).x;
        assert!(c <= full + 1e-5 && c >= ambient - 1e-5);
        let f = (c - ambient) / (full - ambient);
        umbra |= f < 1e-6;
        penumbra |= f > 0.2 && f < 0.8;
        lit |= f > 1.0 - 1e-6;
    }
    assert!(umbra && penumbra && lit, "{umbra} {penumbra} {lit}");
}

#[test]
fn mirror_reflects_kr_of_what_it_sees_up_to_the_depth_limit() {
    let mut s = Scene::default();
    let mirror = s.add_material(Material {
        diffuse: Vec3::ZERO,
        reflect: Vec3::splat(0.75),
        ..Material::default()
    });
    add(&mut s, primitives::plane(5.0, 1), mirror, Vec3::ZERO);
    s.background = Vec3::new(0.2, 0.4, 0.8);
    {
        let ctx_t = context(&s, &settings(8, 8));
        let t = Tracer::new(&ctx_t);
        let c = look(&t, Vec3::new(1.0, 2.0, 0.0), Vec3::ZERO);
        assert!((c - 0.75 * s.background).abs().max_element() < 1e-6, "{c}");
        let mut st = settings(8, 8);
        st.whitted.max_depth = 0;
        let ctx_t = context(&s, &st);
        let t = Tracer::new(&ctx_t);
        assert_eq!(look(&t, Vec3::new(1.0, 2.0, 0.0), Vec3::ZERO), Vec3::ZERO);
    }
    // Two facing mirrors: the weight cutoff ends the recursion.
    let mut st = settings(8, 8);
    st.whitted.max_depth = 1000;
    st.whitted.min_weight = 0.01;
    add(
        &mut s,
        primitives::quad(
            Vec3::new(-5.0, 1.0, -5.0),
            Vec3::new(0.0, 0.0, 10.0),
            Vec3::new(10.0, 0.0, 0.0),
        ),
        mirror,
        Vec3::ZERO,
    );
    let ctx_t = context(&s, &st);
    let t = Tracer::new(&ctx_t);
    let mut state = TraceState::new(pixel_rng(0, 0, 0, 0));
    let ray = Ray::new(Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.01, -1.0, 0.0));
    let c = t.trace(&ray, 0, Vec3::ONE, &mut state);
    // 0.75^k >= 0.01 for k <= 16: 17 rays in all.
    assert_eq!(state.rays, 17);
    assert!(c.is_finite());
}

#[test]
fn glass_sphere_of_ior_one_is_invisible() {
    let mut s = floor_scene();
    let st = settings(32, 24);
    let without = render(&s, &st, &NoProgress).expect("render");
    let g = s.add_material(glass(1.0, true));
    add_sphere(&mut s, Vec3::new(0.3, 1.0, 0.5), 0.8, g);
    let (with, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
    assert!(
        max_diff(&with, &without) < 1e-4,
        "{}",
        max_diff(&with, &without)
    );
    assert!(stats.rays > stats.camera_rays);
    // ... and a real glass sphere is visible.
    s.materials[g.index()].ior = 1.5;
    let real = render(&s, &st, &NoProgress).expect("render");
    assert!(max_diff(&real, &without) > 0.05);
}

#[test]
fn render_is_clean_and_independent_of_thread_count() {
    let mut s = floor_scene();
    s.lights.push(quad_light(
        Vec3::new(-1.0, 3.0, -1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 2.0),
        2.0,
    ));
    let g = s.add_material(Material {
        specular: Vec3::splat(0.5),
        absorption: Vec3::splat(0.3),
        ..glass(1.5, true)
    });
    let m = s.add_material(Material {
        reflect: Vec3::splat(0.5),
        ..lambert(0.2)
    });
    add_sphere(&mut s, Vec3::new(-0.6, 0.7, 0.0), 0.7, g);
    add_sphere(&mut s, Vec3::new(0.9, 0.5, -0.5), 0.5, m);
    for aa in [AaMode::Supersample, AaMode::Adaptive] {
        let st = RenderSettings {
            samples: 3,
            light_samples: 4,
            aa,
            ..settings(24, 20)
        };
        let (a, sa) = render_with_stats(&s, &st, &NoProgress).expect("render");
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let (b, sb) = pool
            .install(|| render_with_stats(&s, &st, &NoProgress))
            .expect("render");
        assert_eq!(a, b, "{aa:?}");
        assert_eq!((sa.rays, sa.camera_rays), (sb.rays, sb.camera_rays));
        assert!(a.is_clean());
        assert!(a.depth.iter().any(|d| d.is_finite()));
    }
}

#[test]
fn adaptive_sampling_refines_only_where_corners_differ() {
    // Nothing but background: exactly one ray per pixel corner of each
    // tile (tiles trace their own border corners).
    let s = Scene::default();
    let st = RenderSettings {
        aa: AaMode::Adaptive,
        ..settings(20, 10)
    };
    let (_, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
    let corners: u64 = chiaro_core::film::tiles(20, 10, TILE)
        .iter()
        .map(|r| u64::from((r.width + 1) * (r.height + 1)))
        .sum();
    assert_eq!(stats.camera_rays, corners);
    // An edge: more rays, and intermediate values along it.
    let mut s = floor_scene();
    s.camera.eye = Vec3::new(0.0, 0.2, 6.0);
    let (f, stats) = render_with_stats(&s, &st, &NoProgress).expect("render");
    assert!(stats.camera_rays > 21 * 11);
    let bg = s.background;
    let column: Vec<Vec3> = (0..10).map(|y| f.get(10, y)).collect();
    assert!(column.iter().any(|c| (*c - bg).abs().max_element() < 1e-6));
    assert!(column.iter().any(|c| (*c - bg).abs().max_element() > 1e-3));
}

#[test]
fn crop_window_matches_the_full_render() {
    let mut s = floor_scene();
    let g = s.add_material(glass(1.5, true));
    add_sphere(&mut s, Vec3::new(0.0, 1.0, 0.0), 0.8, g);
    for aa in [AaMode::Supersample, AaMode::Adaptive] {
        let full_s = RenderSettings {
            aa,
            samples: 2,
            ..settings(40, 30)
        };
        let crop_s = RenderSettings {
            crop: Some([7, 5, 29, 23]),
            ..full_s.clone()
        };
        let full = render(&s, &full_s, &NoProgress).expect("render");
        let crop = render(&s, &crop_s, &NoProgress).expect("render");
        for y in 5..23 {
            for x in 7..29 {
                assert_eq!(full.get(x, y), crop.get(x, y), "{aa:?} at {x},{y}");
            }
        }
        assert_eq!(crop.get(0, 0), Vec3::ZERO);
    }
}

#[test]
fn errors_and_cancellation() {
    let s = floor_scene();
    assert!(matches!(
        render(&s, &settings(0, 4), &NoProgress),
        Err(CoreError::InvalidScene { .. })
    ));
    let post = RenderSettings {
        aa: AaMode::Post,
        ..settings(4, 4)
    };
    // `aa = post` is the facade's filter after a render: a renderer called
    // with it directly supersamples, as the scan converter does.
    let supersample = RenderSettings {
        aa: AaMode::Supersample,
        ..post.clone()
    };
    let (a, b) = (
        render(&s, &post, &NoProgress).expect("renders"),
        render(&s, &supersample, &NoProgress).expect("renders"),
    );
    assert_eq!(a.color, b.color);
    let p = CountingProgress::default();
    p.cancel.store(true, Ordering::Relaxed);
    assert!(matches!(
        render(&s, &settings(4, 4), &p),
        Err(CoreError::Cancelled)
    ));
}

#[test]
fn indirect_hook_replaces_the_ambient_term() {
    let s = floor_scene();
    let st = RenderSettings {
        shadows: ShadowMethod::None,
        ..settings(8, 8)
    };
    let from = Vec3::new(3.0, 1.0, 0.0);
    let ctx_plain = context(&s, &st);
    let plain = look(&Tracer::new(&ctx_plain), from, Vec3::ZERO);
    let ctx_t = context(&s, &st);
    let t = Tracer::new(&ctx_t).with_indirect(|_| Vec3::new(0.2, 0.0, 0.0));
    let hooked = look(&t, from, Vec3::ZERO);
    // Ambient 0.1 * 0.5 removed, kd * 0.2 = 0.1 added (red only).
    assert!((hooked.x - (plain.x - 0.05 + 0.1)).abs() < 1e-5);
    assert!((hooked.y - (plain.y - 0.05)).abs() < 1e-5);
}
