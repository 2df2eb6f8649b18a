//! One sidedness rule for every technique (ARCHITECTURE.md, "Sidedness"):
//! formats that say nothing about sidedness (OBJ here) are two-sided, so a
//! tree whose needles are single-sided quads shows its foliage in every
//! technique, as the path tracer shows it; and a one-sided material's back
//! is drawn black in every technique.

use chiaro::scene::{Light, Material, ShadowMethod, Sidedness, Technique};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use chiaro_testkit::scenes::{load_text, obj_box};
use std::fmt::Write as _;

/// A stand-in for an OBJ pine: a closed box trunk and `needles` single
/// quads (one face each, as such models are made) of random orientation
/// around it, from a fixed-seed generator.
fn tree_obj(needles: usize) -> String {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        // xorshift64*: uniform in [0, 1).
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut obj = String::from("# a tree of single-sided quads\n");
    // The trunk: a 0.2 x 2 x 0.2 box wound outwards.
    let (lo, hi) = (Vec3::new(-0.1, 0.0, -0.1), Vec3::new(0.1, 2.0, 0.1));
    obj_box(&mut obj, 0, lo, hi, false);
    // The needles: 0.5 x 0.15 quads about the upper trunk, each turned at
    // random, so that the camera sees the backs of about half of them.
    for k in 0..needles {
        let h = 0.8 + 1.2 * rnd();
        let r = 0.7 * (2.0 - h) / 1.2 + 0.1;
        let a = std::f32::consts::TAU * rnd();
        let c = Vec3::new(r * a.cos(), h, r * a.sin());
        let axis = |u: f32, v: f32| {
            let (t, p) = (std::f32::consts::TAU * u, std::f32::consts::PI * v);
            Vec3::new(p.sin() * t.cos(), p.cos(), p.sin() * t.sin())
        };
        let e1 = axis(rnd(), rnd());
        let e2 = e1.cross(axis(rnd(), rnd())).normalize_or(Vec3::Y) * 0.15;
        let e1 = e1 * 0.5;
        for p in [c - e1 - e2, c + e1 - e2, c + e1 + e2, c - e1 + e2] {
            let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
        }
        let b = 9 + 4 * k;
        let _ = writeln!(obj, "f {} {} {} {}", b, b + 1, b + 2, b + 3);
    }
    obj
}

/// The tree, seen from the side, lit by a point light near the camera,
/// on a black background.
fn tree_scene() -> Scene {
    let mut scene = load_text("tree.obj", &tree_obj(48));
    scene.camera.eye = Vec3::new(0.3, 1.3, 4.5);
    scene.camera.look_at = Vec3::new(0.0, 1.1, 0.0);
    scene.camera.up = Vec3::Y;
    scene.environment = None;
    scene.background = Vec3::ZERO;
    scene.lights = vec![Light::Point {
        position: Vec3::new(1.0, 2.5, 4.0),
        color: Vec3::ONE,
        intensity: 20.0,
        attenuation: Default::default(),
    }];
    scene
}

/// A 96 x 96 render; without shadows, so that every face turned
/// towards the light near the camera is lit (the needles shadow each other).
fn render(scene: &Scene, technique: Technique, samples: u32) -> Film {
    let s = RenderSettings {
        technique,
        width: 96,
        height: 96,
        samples,
        shadows: ShadowMethod::None,
        ..scene.render.clone()
    };
    chiaro::render(scene, &s, &NoProgress).expect("renders")
}

/// The pixels that show a surface (finite depth).
fn mask(f: &Film) -> Vec<bool> {
    f.depth.iter().map(|d| d.is_finite()).collect()
}

#[test]
fn obj_materials_are_two_sided() {
    let scene = tree_scene();
    assert!(
        scene
            .materials
            .iter()
            .all(|m| m.sidedness == Sidedness::TwoSided)
    );
}

#[test]
fn a_tree_of_single_sided_quads_shows_its_foliage_in_every_technique() {
    let scene = tree_scene();
    let path = mask(&render(&scene, Technique::Path, 4));
    let covered = path.iter().filter(|&&m| m).count();
    // The trunk alone covers about 1.5 % of the frame; the foliage far more.
    assert!(covered > 96 * 96 / 20, "path covers {covered} pixels");
    // Coverage within 3 % of path's, and the same pixels but for needle
    // edges (the pixel centre here, path's first jittered sample there).
    let agrees = |here: usize, differ: usize| {
        here.abs_diff(covered) * 100 <= 3 * covered && differ * 100 <= 8 * covered
    };
    for t in [
        Technique::Flat,
        Technique::Gouraud,
        Technique::Phong,
        Technique::Whitted,
        Technique::Preview,
        Technique::Radiosity,
    ] {
        let f = render(&scene, t, 1);
        if let Ok(dir) = std::env::var("CHIARO_SIDEDNESS_DEBUG") {
            let p = std::path::Path::new(&dir).join(format!("tree-{}.png", t.name()));
            chiaro::io::output::write_film(&f, &p, &Default::default()).expect("writes");
        }
        let m = mask(&f);
        let here = m.iter().filter(|&&m| m).count();
        let differ = m.iter().zip(&path).filter(|(a, b)| a != b).count();
        eprintln!("{t:?}: {here} pixels against path's {covered}, {differ} differ");
        assert!(
            agrees(here, differ),
            "{t:?}: {here} pixels against path's {covered}, {differ} differ"
        );
        // The foliage is lit: its backs are shaded facing the viewer, so
        // the drawn pixels are not mostly black.
        if t != Technique::Radiosity {
            let dark = (0..m.len())
                .filter(|&i| m[i] && f.color[i].max_element() < 1e-3)
                .count();
            assert!(
                dark * 4 < here,
                "{t:?}: {dark} of {here} drawn pixels black"
            );
        }
    }
    // The control: with the needles' backs culled, as the scan converter
    // culled every material that was not two-sided before the rule, flat
    // shading loses the needles seen from behind (those in front of others
    // uncover what is behind them).
    let mut culled = scene.clone();
    for m in &mut culled.materials {
        m.sidedness = Sidedness::Culled;
    }
    let m = mask(&render(&culled, Technique::Flat, 1));
    let here = m.iter().filter(|&&m| m).count();
    let differ = m.iter().zip(&path).filter(|(a, b)| a != b).count();
    eprintln!("Flat, backs culled: {here} pixels against path's {covered}, {differ} differ");
    assert!(!agrees(here, differ), "culled: {here} of {covered}");
}

/// A one-sided material (Mitsuba's convention) seen from behind: drawn,
/// black, in every technique; from the front, lit.
#[test]
fn a_one_sided_back_is_black_in_every_technique() {
    let obj = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n";
    let mut scene = load_text("quad.obj", obj);
    scene.environment = None;
    scene.background = Vec3::ZERO;
    scene.camera.look_at = Vec3::ZERO;
    scene.camera.up = Vec3::Y;
    for m in &mut scene.materials {
        *m = Material {
            sidedness: Sidedness::OneSided,
            ..Material::diffuse(&m.name, Vec3::splat(0.8))
        };
    }
    for back in [false, true] {
        let z = if back { -3.0 } else { 3.0 };
        scene.camera.eye = Vec3::new(0.2, 0.1, z);
        scene.lights = vec![Light::Point {
            position: Vec3::new(0.5, 0.5, z),
            color: Vec3::ONE,
            intensity: 10.0,
            attenuation: Default::default(),
        }];
        for t in Technique::ALL {
            let f = render(&scene, t, 1);
            let i = 48 * 96 + 48;
            let c = f.color[i];
            assert!(f.depth[i].is_finite(), "{t:?} back {back}: not drawn");
            if back {
                assert_eq!(c, Vec3::ZERO, "{t:?}: the back of a one-sided quad");
            } else {
                assert!(c.x > 0.05, "{t:?}: the front of a one-sided quad: {c}");
            }
        }
    }
}

/// `render.cull_backfaces` is a speed option: on every shipped scene the
/// scan converter's picture is the same with it on and off.
#[test]
fn cull_backfaces_never_changes_a_picture() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("the scenes folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 6, "{} shipped scenes", files.len());
    for file in &files {
        let name = file.display();
        let scene = chiaro::io::load_scene(file).expect("loads").scene;
        for t in [Technique::Flat, Technique::Gouraud, Technique::Phong] {
            let mut s = RenderSettings {
                technique: t,
                width: 64,
                height: 48,
                samples: 4,
                ..scene.render.clone()
            };
            s.cull_backfaces = true;
            let on = chiaro::render(&scene, &s, &NoProgress).expect("renders");
            s.cull_backfaces = false;
            let off = chiaro::render(&scene, &s, &NoProgress).expect("renders");
            let bits = |f: &Film| -> Vec<[u32; 3]> {
                f.color
                    .iter()
                    .map(|c| c.to_array().map(f32::to_bits))
                    .collect()
            };
            assert!(
                bits(&on) == bits(&off),
                "{name} {t:?}: cull_backfaces changed the picture"
            );
        }
    }
}
