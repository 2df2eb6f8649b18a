//! The Cornell box written by hand three times, in pbrt-v4
//! (`scenes/cornell-box.pbrt`), pbrt-v3 (`scenes/cornell-box-v3.pbrt`) and
//! Mitsuba 3 (`scenes/cornell-box.xml`), from the numbers of
//! `scenes/cornell-box.toml`: the three load to the same scene within float
//! rounding (world-space triangles with their materials, emitters, camera,
//! render settings), every technique renders the pbrt box, and its path
//! image agrees with the TOML box's within the renders' standard error.
//! A mirror-asymmetric pbrt scene checks that pbrt's left-handed `LookAt`
//! does not come out mirrored.

use chiaro::Technique;
use chiaro::Vec3;
use chiaro::progress::NoProgress;
use chiaro::scene::{Geometry, Scene};
use std::path::{Path, PathBuf};

#[path = "common/techniques.rs"]
mod techniques;

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

fn load(name: &str) -> chiaro::io::Loaded {
    chiaro::io::load_scene(&scenes().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// One world-space triangle (started at its smallest corner, winding
/// kept) with what its material shows: albedo, emission, whether the
/// emission and the shading are two-sided.
type Tri = ([[f32; 3]; 3], [f32; 3], [f32; 3], bool, bool);

fn triangles(s: &Scene) -> Vec<Tri> {
    let mut out = Vec::new();
    for o in &s.objects {
        let Geometry::Mesh(id) = o.geometry else {
            panic!("the box has only meshes")
        };
        let mesh = &s.meshes[id.index()];
        let m = o.transform.world_from_object();
        let flip = m.determinant() < 0.0;
        for (f, t) in mesh.indices.iter().enumerate() {
            let mut p = t.map(|i| m.transform_point3(mesh.positions[i as usize]).to_array());
            if flip {
                p.swap(1, 2);
            }
            let start = (0..3)
                .min_by(|&a, &b| p[a].partial_cmp(&p[b]).expect("finite"))
                .unwrap_or(0);
            let p = [p[start], p[(start + 1) % 3], p[(start + 2) % 3]];
            let mat = mesh.face_materials.get(f).copied().unwrap_or(o.material);
            let mat = &s.materials[mat.index()];
            out.push((
                p,
                mat.diffuse.to_array(),
                mat.emission.to_array(),
                mat.emission_two_sided,
                mat.sidedness == chiaro::scene::Sidedness::TwoSided,
            ));
        }
    }
    out.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    out
}

fn close(a: &[f32], b: &[f32], eps: f32) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| (x - y).abs() <= eps * (1.0 + x.abs().max(y.abs())))
}

fn assert_same_scene(a: &Scene, b: &Scene, what: &str) {
    let (ta, tb) = (triangles(a), triangles(b));
    assert_eq!(ta.len(), tb.len(), "{what}: triangle count");
    for (x, y) in ta.iter().zip(&tb) {
        for k in 0..3 {
            assert!(close(&x.0[k], &y.0[k], 1e-6), "{what}: {x:?} vs {y:?}");
        }
        assert!(
            close(&x.1, &y.1, 1e-6) && close(&x.2, &y.2, 1e-6),
            "{what}: {x:?} vs {y:?}"
        );
        assert_eq!((x.3, x.4), (y.3, y.4), "{what}: sidedness of {x:?}");
    }
    let (ca, cb) = (a.camera, b.camera);
    assert!(
        close(&ca.eye.to_array(), &cb.eye.to_array(), 1e-6),
        "{what}: {ca:?} vs {cb:?}"
    );
    let (fa, fb) = (ca.frame(), cb.frame());
    for (u, v) in [
        (fa.forward, fb.forward),
        (fa.up, fb.up),
        (fa.right, fb.right),
    ] {
        assert!(
            close(&u.to_array(), &v.to_array(), 1e-6),
            "{what}: {fa:?} vs {fb:?}"
        );
    }
    assert!(
        (ca.fov_y_degrees - cb.fov_y_degrees).abs() < 1e-4,
        "{what}: fov"
    );
    assert_eq!(a.lights, b.lights, "{what}: lights");
    assert_eq!(a.environment, b.environment, "{what}: environment");
    let (ra, rb) = (&a.render, &b.render);
    assert_eq!(
        (
            ra.width,
            ra.height,
            ra.samples,
            ra.path.max_depth,
            ra.filter,
            ra.technique
        ),
        (
            rb.width,
            rb.height,
            rb.samples,
            rb.path.max_depth,
            rb.filter,
            rb.technique
        ),
        "{what}: render settings"
    );
}

#[test]
fn the_three_hand_written_boxes_load_to_one_scene() {
    let v4 = load("cornell-box.pbrt");
    let v3 = load("cornell-box-v3.pbrt");
    let xml = load("cornell-box.xml");
    assert!(v4.warnings.is_empty(), "{:?}", v4.warnings);
    assert!(v3.warnings.is_empty(), "{:?}", v3.warnings);
    assert_same_scene(&v4.scene, &v3.scene, "pbrt-v4 vs pbrt-v3");
    assert_same_scene(&v4.scene, &xml.scene, "pbrt-v4 vs Mitsuba");
    // And the TOML box's geometry, materials and camera (its ambient term
    // and radiosity settings are its own).
    let toml = load("cornell-box.toml").scene;
    let (tp, tt) = (triangles(&v4.scene), triangles(&toml));
    assert_eq!(tp.len(), tt.len());
    for (x, y) in tp.iter().zip(&tt) {
        for k in 0..3 {
            assert!(close(&x.0[k], &y.0[k], 1e-6), "TOML: {x:?} vs {y:?}");
        }
        assert!(
            close(&x.1, &y.1, 1e-6) && close(&x.2, &y.2, 1e-6),
            "TOML: {x:?} vs {y:?}"
        );
    }
    assert!(close(
        &v4.scene.camera.eye.to_array(),
        &toml.camera.eye.to_array(),
        1e-6
    ));
    assert!((v4.scene.camera.fov_y_degrees - toml.camera.fov_y_degrees).abs() < 1e-4);
    let (fa, fb) = (v4.scene.camera.frame(), toml.camera.frame());
    assert!((fa.right - fb.right).length() < 1e-6, "{fa:?} vs {fb:?}");
}

#[test]
fn every_technique_renders_the_pbrt_box() {
    let scene = load("cornell-box.pbrt").scene;
    techniques::renders_with_every_technique(&scene, "cornell-box.pbrt");
}

/// Per-pixel mean and variance of the mean over `runs` independent path
/// renders (seeds differ).
fn path_estimate(
    scene: &Scene,
    size: u32,
    spp: u32,
    runs: u64,
    seed0: u64,
) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut s = scene.render.clone();
    s.technique = Technique::Path;
    s.width = size;
    s.height = size;
    s.samples = spp;
    s.path.max_depth = 8;
    let films: Vec<Vec<Vec3>> = (0..runs)
        .map(|k| {
            s.seed = seed0 + k;
            chiaro::render(scene, &s, &NoProgress)
                .expect("renders")
                .color
        })
        .collect();
    let n = films[0].len();
    let r = runs as f32;
    let mut mean = vec![Vec3::ZERO; n];
    let mut var = vec![Vec3::ZERO; n];
    for i in 0..n {
        let m = films.iter().map(|f| f[i]).sum::<Vec3>() / r;
        let v = films.iter().map(|f| (f[i] - m) * (f[i] - m)).sum::<Vec3>() / (r - 1.0);
        mean[i] = m;
        var[i] = v / r;
    }
    (mean, var)
}

#[test]
fn the_pbrt_box_path_image_matches_the_toml_box() {
    let pbrt = load("cornell-box.pbrt").scene;
    let toml = load("cornell-box.toml").scene;
    let size = 32;
    let (ma, va) = path_estimate(&pbrt, size, 16, 6, 100);
    let (mb, vb) = path_estimate(&toml, size, 16, 6, 200);
    // Per pixel and channel, the difference in units of its standard error.
    let mut over = 0;
    let mut total = 0;
    for i in 0..ma.len() {
        for c in 0..3 {
            let d = (ma[i][c] - mb[i][c]).abs();
            let se = (va[i][c] + vb[i][c]).sqrt().max(1e-4);
            total += 1;
            if d > 4.0 * se {
                over += 1;
            }
        }
    }
    // Whole-image means agree within 3 standard errors.
    let mean = |m: &[Vec3]| m.iter().sum::<Vec3>() / m.len() as f32;
    let se = (va.iter().chain(&vb).sum::<Vec3>()).map(f32::sqrt) / ma.len() as f32;
    let d = (mean(&ma) - mean(&mb)).abs();
    eprintln!(
        "pbrt box vs TOML box: {over} of {total} pixel channels beyond 4 SE; image means {} vs {} (SE {se})",
        mean(&ma),
        mean(&mb)
    );
    assert!(d.cmple(3.0 * se + 1e-5).all(), "{d} vs {se}");
    assert!(over as f32 <= 0.01 * total as f32, "{over} of {total}");
}

/// An asymmetric scene: a red sphere left of a blue one as pbrt draws it.
/// pbrt's `LookAt` camera has world +x on the image's right, so with the
/// camera at -z looking at +z, the sphere at +x must be on the right.
#[test]
fn a_plain_look_at_is_not_mirrored() {
    let text = r#"
LookAt 0 0 -5  0 0 0  0 1 0
Camera "perspective" "float fov" 30
Film "rgb" "integer xresolution" 48 "integer yresolution" 32
Sampler "independent" "integer pixelsamples" 1
WorldBegin
LightSource "distant" "point3 from" [0 0 -1] "point3 to" [0 0 0] "rgb L" [3 3 3]
AttributeBegin
  Material "diffuse" "rgb reflectance" [0.9 0 0]
  Translate -1 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "diffuse" "rgb reflectance" [0 0 0.9]
  Translate 1 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
"#;
    let loaded = chiaro::io::pbrt::load_str(text, Path::new("."), "mirror.pbrt").expect("loads");
    let mut s = loaded.scene.render.clone();
    s.technique = Technique::Phong;
    let film = chiaro::render(&loaded.scene, &s, &NoProgress).expect("renders");
    let (w, h) = (film.width as usize, film.height as usize);
    let side = |x0: usize, x1: usize| {
        let mut c = Vec3::ZERO;
        for y in 0..h {
            for x in x0..x1 {
                c += film.color[y * w + x];
            }
        }
        c
    };
    let (left, right) = (side(0, w / 2), side(w / 2, w));
    // Blue (the sphere at +x) on the right, red on the left.
    assert!(
        right.z > 4.0 * right.x && left.x > 4.0 * left.z,
        "left {left}, right {right}"
    );
}
