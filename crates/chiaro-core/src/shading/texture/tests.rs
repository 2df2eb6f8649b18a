//! Tests of texture lookups, noise and patterns, bump and normal maps, and the
//! environment map and its sampling.

use super::environment::environment_uv;
use super::*;
use crate::scene::UvTransform;
use crate::scene::{Filter, ImageTexture, ProceduralKind, Scene, WrapMode};

#[test]
fn wrap_modes() {
    assert_eq!(wrap_index(-1, 4, WrapMode::Repeat), 3);
    assert_eq!(wrap_index(5, 4, WrapMode::Clamp), 3);
    assert_eq!(wrap_index(4, 4, WrapMode::Mirror), 3);
    assert_eq!(wrap_index(-1, 4, WrapMode::Mirror), 0);
}

fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> ImageTexture {
    ImageTexture {
        source: "t".into(),
        width: w,
        height: h,
        texels: (0..w * h)
            .map(|i| {
                let v = f(i % w, i / w);
                [v, v, v, 1.0]
            })
            .collect(),
        wrap: WrapMode::Repeat,
        ..Default::default()
    }
}

#[test]
fn per_axis_wrap_filters_and_uv_transform() {
    // A 4x4 ramp in x (value x / 4): repeat in u, clamp in v.
    let mut img = image(4, 4, |x, _| x as f32 / 4.0);
    img.wrap = WrapMode::Repeat;
    img.wrap_t = Some(WrapMode::Clamp);
    img.mag_filter = Filter::Nearest;
    // u = 1.1 wraps to texel 0; v = 5 clamps to the last row.
    assert_eq!(nearest(&img, Vec2::new(1.1, 5.0)).x, 0.0);
    // Clamped in u too: texel 3.
    img.wrap = WrapMode::Clamp;
    assert_eq!(nearest(&img, Vec2::new(1.1, 0.5)).x, 0.75);
    // Nearest picks the containing texel, linear blends the neighbours.
    assert_eq!(nearest(&img, Vec2::new(0.3, 0.5)).x, 0.25);
    assert!((bilinear(&img, Vec2::new(0.25, 0.5)).x - 0.125).abs() < 1e-6);
    // KHR_texture_transform: scale 2 then offset 0.25 maps u = 0.1 to
    // 0.45 (texel 1); a quarter turn maps (u, v) to (v, -u) (the
    // extension's matrix), so u = 0.6 at v = 0.6 reads u' = 0.6.
    let t = UvTransform {
        offset: Vec2::new(0.25, 0.0),
        rotation: 0.0,
        scale: Vec2::splat(2.0),
    };
    assert!((t.apply(Vec2::new(0.1, 0.2)) - Vec2::new(0.45, 0.4)).length() < 1e-6);
    let r = UvTransform {
        rotation: std::f32::consts::FRAC_PI_2,
        ..UvTransform::default()
    };
    assert!((r.apply(Vec2::new(0.3, 0.6)) - Vec2::new(0.6, -0.3)).length() < 1e-6);
    img.uv_transform = t;
    let tc = TexCoord {
        uv: Vec2::new(0.1, 0.5),
        ..TexCoord::default()
    };
    let v = eval_texture(&Texture::Image(img.clone()), None, &tc);
    assert_eq!(v.x, 0.25);
    // Mip filter none: minification stays on level 0 with the min filter.
    img.uv_transform = UvTransform::default();
    img.min_filter = Filter::Nearest;
    img.mip_filter = None;
    let m = MipMap::new(&img);
    assert_eq!(m.sample(Vec2::new(0.3, 0.5), 2.0).x, 0.25);
}

#[test]
fn mip_pyramid_sizes_means_and_lod() {
    let img = image(8, 4, |x, y| ((x + y) % 2) as f32);
    let m = MipMap::new(&img);
    let sizes: Vec<(u32, u32)> = m.levels.iter().map(|l| (l.width, l.height)).collect();
    assert_eq!(sizes, vec![(8, 4), (4, 2), (2, 1), (1, 1)]);
    // Box filtering keeps the mean: a checker becomes uniform grey.
    assert!((m.levels[1].texel(1, 1)[0] - 0.5).abs() < 1e-6);
    // One texel per pixel is level 0; four texels per pixel is level 2.
    assert_eq!(m.lod(Vec2::new(1.0 / 8.0, 0.0), Vec2::ZERO), 0.0);
    assert!((m.lod(Vec2::new(4.0 / 8.0, 0.0), Vec2::new(0.0, 1.0 / 4.0)) - 2.0).abs() < 1e-6);
    assert_eq!(m.lod(Vec2::splat(f32::NAN), Vec2::ZERO), 0.0);
    assert!((m.sample(Vec2::splat(0.3), 3.0).x - 0.5).abs() < 1e-6);
}

#[test]
fn perlin_noise_is_bounded_smooth_and_zero_on_the_lattice() {
    let mut max = 0.0f32;
    for i in 0..2000 {
        let p = Vec3::new(
            i as f32 * 0.173,
            (i % 37) as f32 * 0.311,
            (i % 11) as f32 * 0.77,
        );
        let n = perlin_noise(p);
        assert!((-1.0..=1.0).contains(&n));
        max = max.max(n.abs());
        // Continuity: a tiny step changes little.
        assert!((perlin_noise(p + Vec3::splat(1e-4)) - n).abs() < 1e-2);
    }
    assert!(max > 0.3, "noise is not flat");
    assert_eq!(perlin_noise(Vec3::new(3.0, -2.0, 7.0)), 0.0);
    assert!(turbulence(Vec3::new(0.3, 0.4, 0.5), 4) >= 0.0);
}

#[test]
fn patterns_are_in_range_and_checker_alternates() {
    assert_eq!(
        pattern(ProceduralKind::Checker, Vec3::new(0.5, 0.5, 0.5)),
        0.0
    );
    assert_eq!(
        pattern(ProceduralKind::Checker, Vec3::new(1.5, 0.5, 0.5)),
        1.0
    );
    assert_eq!(
        pattern(ProceduralKind::Checker, Vec3::new(-0.5, 0.5, 0.5)),
        1.0
    );
    assert_eq!(
        pattern(ProceduralKind::Dimples, Vec3::new(0.5, 0.5, 0.5)),
        1.0
    );
    assert!(pattern(ProceduralKind::Dimples, Vec3::new(1.0, 2.0, 3.0)).abs() < 1e-6);
    for kind in [
        ProceduralKind::Wood,
        ProceduralKind::Marble,
        ProceduralKind::Noise,
        ProceduralKind::Dimples,
    ] {
        for i in 0..200 {
            let v = pattern(kind, Vec3::new(i as f32 * 0.37, 0.2, i as f32 * 0.11));
            assert!((0.0..=1.0).contains(&v), "{kind:?}: {v}");
        }
    }
}

#[test]
fn bump_and_normal_map_closed_forms() {
    let n = Vec3::Z;
    // A linear height h = s x on the plane z = 0: normal (-s, 0, 1)/|..|.
    let s = 0.5;
    let g = uv_surface_gradient(n, Vec3::X, Vec3::Y, s, 0.0);
    let b = bump_normal(n, g);
    assert!((b - Vec3::new(-s, 0.0, 1.0).normalize()).length() < 1e-6);
    // The flat normal-map texel leaves the normal unchanged; (1, .5, .5)
    // tilts it onto the tangent.
    let t = Vec4::new(1.0, 0.0, 0.0, 1.0);
    assert!((normal_map_normal(n, t, Vec3::new(0.5, 0.5, 1.0)) - n).length() < 1e-6);
    assert!((normal_map_normal(n, t, Vec3::new(1.0, 0.5, 0.5)) - Vec3::X).length() < 1e-6);
    // The bitangent sign flips y.
    let up = normal_map_normal(n, t, Vec3::new(0.5, 1.0, 0.5));
    let down = normal_map_normal(n, Vec4::new(1.0, 0.0, 0.0, -1.0), Vec3::new(0.5, 1.0, 0.5));
    assert!((up + down).length() < 1e-6);
}

#[test]
fn latlong_convention() {
    assert!((latlong_uv(Vec3::NEG_Z) - Vec2::new(0.5, 0.5)).length() < 1e-6);
    assert!((latlong_uv(Vec3::X) - Vec2::new(0.75, 0.5)).length() < 1e-6);
    assert!(latlong_uv(Vec3::Y).y.abs() < 1e-6);
    let mut scene = Scene::default();
    let t = scene.add_texture(Texture::Image(image(4, 2, |x, _| x as f32)));
    set_environment(&mut scene, t, 2.0, 0.0, true);
    // -z is u = 0.5: between texels 1 and 2 (values 1 and 2) -> 1.5, times 2.
    assert!((environment_radiance(&scene, Vec3::NEG_Z).x - 3.0).abs() < 1e-5);
    assert_eq!(
        background_radiance(&scene, Vec3::NEG_Z),
        environment_radiance(&scene, Vec3::NEG_Z)
    );
}

/// One bright texel at the map's `-z` (u = 0.5, on the horizon); after
/// `rotate_y = a` it must be seen at `R_y(a) (-z) = (-sin a, 0, -cos a)`,
/// the direction a right-handed rotation of the world by `a` about +y
/// turns `-z` to (as an object's `rotate_y` does).
#[test]
fn rotate_y_turns_the_map_right_handed() {
    // 8 x 4 texels; texel (3, 1)'s centre is u = 3.5 / 8 = 0.4375,
    // v = 1.5 / 4 = 0.375. Make it the only bright one.
    let img = image(8, 4, |x, y| if (x, y) == (3, 1) { 100.0 } else { 0.0 });
    let mut scene = Scene::default();
    let t = scene.add_texture(Texture::Image(img));
    let texel_dir = |rot_deg: f32| {
        // The texel's direction in the unrotated map, turned by rot_deg.
        let (u, v) = (0.4375_f32, 0.375_f32);
        let phi = (u - 0.5) * std::f32::consts::TAU; // azimuth from -z towards +x
        let theta = v * std::f32::consts::PI; // from +y
        let d = Vec3::new(
            theta.sin() * phi.sin(),
            theta.cos(),
            -theta.sin() * phi.cos(),
        );
        glam::Quat::from_rotation_y(rot_deg.to_radians()) * d
    };
    for rot in [0.0_f32, 90.0, -90.0, 180.0, 30.0, 450.0] {
        set_environment(&mut scene, t, 1.0, rot, true);
        let d = texel_dir(rot);
        let seen = environment_radiance(&scene, d).x;
        assert!((seen - 100.0).abs() < 1e-2, "rotate_y {rot}: {seen} at {d}");
        // The unrotated direction sees darkness once the turn exceeds the
        // bilinear footprint (one texel, 45 degrees).
        if (45.0..=315.0).contains(&rot.rem_euclid(360.0)) {
            let off = environment_radiance(&scene, texel_dir(0.0)).x;
            assert!(off < 1e-3, "rotate_y {rot}: {off}");
        }
    }
    // Pinned by hand: rotate_y = 90 takes the map's -z to -x, so a texel
    // at the map's centre column is seen looking down -x.
    let centre = image(8, 4, |x, _| if x == 3 || x == 4 { 1.0 } else { 0.0 });
    let c = scene.add_texture(Texture::Image(centre));
    set_environment(&mut scene, c, 1.0, 90.0, true);
    assert!((environment_radiance(&scene, Vec3::NEG_X).x - 1.0).abs() < 1e-6);
    assert!(environment_radiance(&scene, Vec3::NEG_Z).x.abs() < 1e-6);
    assert!(environment_radiance(&scene, Vec3::X).x.abs() < 1e-6);
}

/// The mean radiance of a constant map is its value times the
/// intensity; a map bright only above the horizon gives half of that
/// (the upper hemisphere is half the solid angle); no map gives zero.
#[test]
fn environment_mean_radiance_closed_forms() {
    let mut scene = Scene::default();
    assert_eq!(environment_mean_radiance(&scene), Vec3::ZERO);
    let t = scene.add_texture(Texture::Image(image(64, 32, |_, _| 2.0)));
    set_environment(&mut scene, t, 1.5, 30.0, false);
    let m = environment_mean_radiance(&scene);
    assert!((m.x - 3.0).abs() < 1e-3, "{m}");
    let sky = image(64, 32, |_, y| if y < 16 { 1.0 } else { 0.0 });
    let t = scene.add_texture(Texture::Image(sky));
    set_environment(&mut scene, t, 1.0, 0.0, false);
    let m = environment_mean_radiance(&scene);
    assert!((m.x - 0.5).abs() < 0.02, "{m}");
}

/// A rotated map with a bright texel, a ramp and three black rows
/// (the middle one has zero density: the bilinear mean over it is 0).
fn spot_scene(rot: f32) -> Scene {
    let img = image(32, 16, |x, y| {
        if (x, y) == (20, 5) {
            500.0
        } else if (11..=13).contains(&y) {
            0.0
        } else {
            0.1 + 0.05 * x as f32
        }
    });
    let mut scene = Scene::default();
    let t = scene.add_texture(Texture::Image(img));
    set_environment(&mut scene, t, 2.0, rot, true);
    scene
}

/// The environment light's density per solid angle integrates to 1
/// over the sphere (midpoint rule in theta and phi, so the Jacobian
/// `2 pi^2 sin(theta)` is tested too), and is positive wherever the
/// lookup's radiance is (also beside a lone bright texel, which the
/// bilinear lookup spreads into its neighbours).
#[test]
fn environment_light_pdf_integrates_to_one() {
    use std::f32::consts::{PI, TAU};
    for rot in [0.0, 30.0, -100.0] {
        let scene = spot_scene(rot);
        let light = EnvironmentLight::new(&scene).expect("a light");
        let (nt, np) = (1024, 2048);
        let mut total = 0.0f64;
        for i in 0..nt {
            let theta = (i as f32 + 0.5) / nt as f32 * PI;
            let mut row = 0.0f64;
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * TAU;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                row += f64::from(light.pdf(d));
            }
            total += row * f64::from(theta.sin());
        }
        total *= f64::from(PI / nt as f32) * f64::from(TAU / np as f32);
        assert!((total - 1.0).abs() < 2e-3, "rotate {rot}: {total}");
    }
    // Only one texel lit: every direction with radiance has density.
    let mut scene = Scene::default();
    let t = scene.add_texture(Texture::Image(image(16, 8, |x, y| {
        if (x, y) == (5, 2) { 1.0 } else { 0.0 }
    })));
    set_environment(&mut scene, t, 1.0, 45.0, true);
    let light = EnvironmentLight::new(&scene).expect("a light");
    let mut lit = 0;
    for i in 0..200 {
        for j in 0..400 {
            let theta = (i as f32 + 0.5) / 200.0 * PI;
            let phi = (j as f32 + 0.5) / 400.0 * TAU;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            if environment_radiance(&scene, d).x > 0.0 {
                lit += 1;
                assert!(light.pdf(d) > 0.0, "{d}: radiance without density");
            }
        }
    }
    assert!(lit > 100, "{lit}");
    // No map, a black map, zero intensity: no light.
    assert!(EnvironmentLight::new(&Scene::default()).is_none());
    let mut black = spot_scene(0.0);
    black.environment.as_mut().expect("env").intensity = 0.0;
    assert!(EnvironmentLight::new(&black).is_none());
}

/// `sample` draws texels with the density's probabilities (chi-square
/// over the texels, those expecting under 5 samples pooled), returns
/// `pdf()`'s density and the lookup's radiance.
#[test]
fn environment_light_sampling_matches_its_pdf() {
    let scene = spot_scene(30.0);
    let light = EnvironmentLight::new(&scene).expect("a light");
    let env = scene.environment.as_ref().expect("env");
    let (w, h) = (32usize, 16usize);
    let n = 200_000;
    let mut counts = vec![0u32; w * h];
    let mut rng = crate::sampling::pixel_rng(5, 6, 7, 8);
    for _ in 0..n {
        let s = light
            .sample(crate::sampling::uniform2(&mut rng))
            .expect("not at a pole");
        assert!((s.wi.length() - 1.0).abs() < 1e-5);
        let pdf = light.pdf(s.wi);
        assert!((pdf - s.pdf).abs() <= 2e-3 * s.pdf, "{} vs {pdf}", s.pdf);
        assert_eq!(s.radiance, environment_radiance(&scene, s.wi));
        let uv = environment_uv(env, s.wi);
        let cell = |x: f32, n: usize| ((x * n as f32) as usize).min(n - 1);
        counts[cell(uv.y, h) * w + cell(uv.x, w)] += 1;
    }
    // Each texel's probability: its density on the unit square over w h.
    let (mut chi2, mut bins) = (0.0f64, 0usize);
    let (mut pool_e, mut pool_o) = (0.0f64, 0.0f64);
    for y in 0..h {
        for x in 0..w {
            let p = light.dist.pdf(Vec2::new(
                (x as f32 + 0.5) / w as f32,
                (y as f32 + 0.5) / h as f32,
            ));
            let e = f64::from(p) / (w * h) as f64 * f64::from(n);
            let o = f64::from(counts[y * w + x]);
            if e < 5.0 {
                (pool_e, pool_o) = (pool_e + e, pool_o + o);
            } else {
                chi2 += (o - e) * (o - e) / e;
                bins += 1;
            }
        }
    }
    if pool_e > 0.0 {
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1.0);
        bins += 1;
    }
    // Wilson-Hilferty: chi2 / k to a standard normal.
    let k = (bins - 1) as f64;
    let z = ((chi2 / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt();
    assert!(
        z < 4.5,
        "chi-square {chi2:.1} over {k} degrees of freedom: z = {z:.2}"
    );
    // The middle black row is never drawn; the bright texel (500 among
    // values up to 1.65) takes a third of the samples (its neighbours
    // share its bilinear spread).
    assert!(counts[12 * w..13 * w].iter().all(|&c| c == 0));
    assert!(
        counts[5 * w + 20] as f32 > 0.25 * n as f32,
        "{}",
        counts[5 * w + 20]
    );
}

/// `background = false`: the camera sees `scene.background`, every other
/// ray the environment.
#[test]
fn miss_radiance_rule() {
    let mut scene = Scene {
        background: Vec3::new(0.25, 0.5, 0.75),
        ..Scene::default()
    };
    assert_eq!(miss_radiance(&scene, Vec3::Z, true), scene.background);
    assert_eq!(miss_radiance(&scene, Vec3::Z, false), scene.background);
    let t = scene.add_texture(Texture::Image(image(4, 2, |_, _| 2.0)));
    for as_background in [true, false] {
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 1.5,
            rotate_y_degrees: 0.0,
            as_background,
        });
        let camera = if as_background {
            Vec3::splat(3.0)
        } else {
            scene.background
        };
        assert_eq!(miss_radiance(&scene, Vec3::Z, true), camera);
        assert_eq!(background_radiance(&scene, Vec3::Z), camera);
        assert_eq!(miss_radiance(&scene, Vec3::Z, false), Vec3::splat(3.0));
    }
}

/// An 8-bit image and its `f32` twin decoded as the loader did before
/// 8-bit storage (the sRGB table or `code / 255` for colour, `code / 255`
/// for alpha): every code appears in every channel.
fn image_8bit_and_f32(srgb: bool) -> (ImageTexture, ImageTexture) {
    let (w, h) = (16u32, 17u32);
    let codes: Vec<[u8; 4]> = (0..w * h)
        .map(|i| {
            let c = |k: u32| ((i * k + k / 2) % 256) as u8;
            [c(1), c(7), c(13), c(29)]
        })
        .collect();
    let table = crate::film::tonemap::srgb8_to_linear_table();
    let colour = |v: u8| {
        if srgb {
            table[usize::from(v)]
        } else {
            f32::from(v) / 255.0
        }
    };
    let texels = codes
        .iter()
        .map(|&[r, g, b, a]| [colour(r), colour(g), colour(b), f32::from(a) / 255.0])
        .collect();
    let mut packed = ImageTexture::new_8bit("t8".into(), w, h, codes, srgb);
    let mut plain = ImageTexture::new("t32".into(), w, h, texels);
    for t in [&mut packed, &mut plain] {
        t.wrap = WrapMode::Mirror;
        t.wrap_t = Some(WrapMode::Repeat);
    }
    (packed, plain)
}

fn bits(v: Vec4) -> [u32; 4] {
    v.to_array().map(f32::to_bits)
}

#[test]
fn eight_bit_texels_look_up_as_their_f32_decode_bit_for_bit() {
    for srgb in [true, false] {
        let (packed, plain) = image_8bit_and_f32(srgb);
        assert_eq!(packed.texels.len(), 0);
        assert_eq!(packed.texel_count(), plain.texels.len());
        assert_eq!(packed.texel_bytes() * 4, plain.texel_bytes());
        for i in 0..plain.texel_count() {
            assert_eq!(
                packed.texel_at(i).map(f32::to_bits),
                plain.texels[i].map(f32::to_bits),
                "texel {i}, srgb {srgb}"
            );
        }
        let (mp, mf) = (MipMap::new(&packed), MipMap::new(&plain));
        assert_eq!(mp.levels.len(), mf.levels.len());
        // Level 0 shares the image's codes; the smaller levels are the same f32.
        let codes = |t: &ImageTexture| t.texels8.as_ref().map(|c| c.codes().as_ptr());
        assert_eq!(codes(&mp.levels[0]), codes(&packed));
        assert!(codes(&packed).is_some());
        for (lp, lf) in mp.levels.iter().zip(&mf.levels).skip(1) {
            assert_eq!(lp.texels8, None);
            assert_eq!(
                lp.texels
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
                lf.texels
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            );
        }
        assert_eq!(mp.extra_bytes() + plain.texel_bytes(), mf.extra_bytes());
        let (tp, tf) = (Texture::Image(packed), Texture::Image(plain));
        for k in 0..400 {
            let uv = Vec2::new(k as f32 * 0.0371 - 3.1, (k % 23) as f32 * 0.113 - 1.2);
            let d = 0.002 * (k % 9) as f32;
            let tc = TexCoord {
                uv,
                duv_dx: Vec2::new(d, 0.3 * d),
                duv_dy: Vec2::new(-0.2 * d, 1.7 * d),
                ..TexCoord::default()
            };
            let (Texture::Image(ip), Texture::Image(ifl)) = (&tp, &tf) else {
                unreachable!()
            };
            assert_eq!(bits(bilinear(ip, uv)), bits(bilinear(ifl, uv)), "{uv}");
            assert_eq!(bits(nearest(ip, uv)), bits(nearest(ifl, uv)), "{uv}");
            assert_eq!(
                bits(eval_texture(&tp, Some(&mp), &tc)),
                bits(eval_texture(&tf, Some(&mf), &tc)),
                "{uv} {d}"
            );
            assert_eq!(
                bits(eval_texture(&tp, None, &tc)),
                bits(eval_texture(&tf, None, &tc))
            );
        }
    }
}

#[test]
fn an_eight_bit_environment_map_lights_as_its_f32_twin() {
    let (packed, plain) = image_8bit_and_f32(true);
    let lights = [packed, plain].map(|img| {
        let mut scene = Scene::default();
        let t = scene.add_texture(Texture::Image(img));
        set_environment(&mut scene, t, 1.0, 0.0, true);
        let d = glam::Vec3::new(0.3, 0.5, -0.8).normalize();
        (
            environment_mean_radiance(&scene)
                .to_array()
                .map(f32::to_bits),
            environment_radiance(&scene, d).to_array().map(f32::to_bits),
            EnvironmentLight::new(&scene).map(|l| l.pdf(d).to_bits()),
        )
    });
    assert_eq!(lights[0], lights[1]);
    assert!(lights[0].2.is_some());
}

/// Makes `texture` `scene`'s environment: radiance times `intensity`,
/// turned by `rotate_y_degrees` about +y, and the background where
/// `as_background`.
fn set_environment(
    scene: &mut Scene,
    texture: crate::scene::TextureId,
    intensity: f32,
    rotate_y_degrees: f32,
    as_background: bool,
) {
    scene.environment = Some(crate::scene::Environment {
        texture,
        intensity,
        rotate_y_degrees,
        as_background,
    });
}

#[test]
fn one_lookup_gives_the_radiance_and_the_pdf() {
    // `EnvironmentLight::radiance_pdf` equals `environment_radiance` and
    // `pdf` bit for bit, for a turned map and directions of any length.
    let scene = spot_scene(30.0);
    let light = EnvironmentLight::new(&scene).expect("a light");
    let mut rng = crate::sampling::pixel_rng(9, 8, 7, 6);
    for k in 0..20_000 {
        let d = crate::sampling::sample_uniform_sphere(crate::sampling::uniform2(&mut rng))
            * (0.5 + (k % 7) as f32);
        let (l, pdf) = light.radiance_pdf(d);
        assert_eq!(l, environment_radiance(&scene, d));
        assert_eq!(pdf.to_bits(), light.pdf(d).to_bits());
    }
    assert_eq!(light.radiance_pdf(Vec3::ZERO), (Vec3::ZERO, 0.0));
}

#[test]
fn fract_by_floor_is_rem_euclid() {
    // `environment_uv`'s turn of u: `x - floor(x)` for `rem_euclid(1.0)`,
    // the same bits but for the sign of a zero (-0 gives +0, the same
    // texel).
    let mut xs: Vec<f32> = (-30_000..30_000).map(|k| k as f32 * 7.3e-5).collect();
    xs.extend([
        -1e-10,
        1e-10,
        -0.0,
        0.0,
        1.0,
        -1.0,
        2.5,
        -2.5,
        1.0f32.next_down(),
    ]);
    for x in xs {
        let (a, b) = (x - x.floor(), x.rem_euclid(1.0));
        assert!(a.to_bits() == b.to_bits() || (a == 0.0 && b == 0.0), "{x}");
    }
}

#[test]
fn environment_lanes_give_each_lane_its_one_lane_bits() {
    // `radiance_pdf_lanes` and `sample_lanes` over sixteen lanes, some
    // masked off, against `radiance_pdf` and `sample` (their one-lane
    // case) lane by lane: any direction, the poles, a zero vector, a
    // number pair at the ends of [0, 1); masked lanes give zeros.
    let scene = spot_scene(30.0);
    let light = EnvironmentLight::new(&scene).expect("a light");
    let mut rng = crate::sampling::pixel_rng(3, 1, 4, 1);
    const N: usize = 16;
    for round in 0..500 {
        let mut d = [[0.0f32; N]; 3];
        let mut u = [[0.0f32; N]; 2];
        let m: [bool; N] = std::array::from_fn(|i| (i * 7 + round) % 5 != 0);
        for i in 0..N {
            let v = match (round + i) % 29 {
                0 => Vec3::Y,
                1 => -Vec3::Y * 3.0,
                2 => Vec3::ZERO,
                _ => {
                    crate::sampling::sample_uniform_sphere(crate::sampling::uniform2(&mut rng))
                        * (0.5 + (i % 3) as f32)
                }
            };
            (d[0][i], d[1][i], d[2][i]) = (v.x, v.y, v.z);
            let p = crate::sampling::uniform2(&mut rng);
            (u[0][i], u[1][i]) = match (round + i) % 31 {
                0 => (0.0, 0.0),
                1 => (1.0f32.next_down(), 1.0f32.next_down()),
                _ => (p.x, p.y),
            };
        }
        let (l, pdf) = light.radiance_pdf_lanes(&d, &m);
        let s = light.sample_lanes(&u[0], &u[1], &m);
        for i in 0..N {
            let lane = |v: &[[f32; N]; 3]| Vec3::new(v[0][i], v[1][i], v[2][i]);
            if !m[i] {
                assert_eq!((lane(&l), pdf[i], s.ok[i]), (Vec3::ZERO, 0.0, false));
                continue;
            }
            let (l1, pdf1) = light.radiance_pdf(lane(&d));
            assert_eq!(
                lane(&l).to_array().map(f32::to_bits),
                l1.to_array().map(f32::to_bits)
            );
            assert_eq!(pdf[i].to_bits(), pdf1.to_bits(), "lane {i}");
            let one = light.sample(Vec2::new(u[0][i], u[1][i]));
            assert_eq!(s.ok[i], one.is_some(), "lane {i}");
            if let Some(one) = one {
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!(bits(lane(&s.wi)), bits(one.wi));
                assert_eq!(bits(lane(&s.radiance)), bits(one.radiance));
                assert_eq!(s.pdf[i].to_bits(), one.pdf.to_bits());
                // (The sample's radiance is the lookup's in its direction.)
                assert_eq!(one.radiance, environment_radiance(&scene, one.wi));
            }
        }
    }
}

#[test]
fn bilinear_lanes_give_each_lane_the_scalar_lookup() {
    // Every wrap mode, coordinates inside, outside and not finite, an
    // image without texels; masked lanes read nothing and give zero.
    const N: usize = 16;
    let mut rng = crate::sampling::pixel_rng(2, 7, 1, 8);
    for wrap in [WrapMode::Repeat, WrapMode::Clamp, WrapMode::Mirror] {
        let mut img = image(5, 3, |x, y| (x * 3 + y * 7) as f32 * 0.1);
        img.wrap = wrap;
        let empty = ImageTexture {
            texels: Vec::new(),
            ..img.clone()
        };
        for img in [&img, &empty] {
            for round in 0..200 {
                let m: [bool; N] = std::array::from_fn(|i| (i + round) % 4 != 1);
                let mut u = [0.0f32; N];
                let mut v = [0.0f32; N];
                for i in 0..N {
                    let p = crate::sampling::uniform2(&mut rng);
                    (u[i], v[i]) = (p.x * 3.0 - 1.0, p.y * 3.0 - 1.0);
                }
                u[3] = f32::NAN;
                v[5] = f32::INFINITY;
                let got = image::bilinear_lanes(img, &u, &v, &m);
                for i in 0..N {
                    let want = if m[i] {
                        bilinear(img, Vec2::new(u[i], v[i]))
                    } else {
                        Vec4::ZERO
                    };
                    assert_eq!(bits(got[i]), bits(want), "{wrap:?} lane {i}");
                }
            }
        }
    }
}
