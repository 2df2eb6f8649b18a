//! Choosing and placing the camera: `--eye/--look-at/--fov` and `--camera
//! NAME` reproduce a TOML camera bit for bit; automatic framing fills the
//! frame, stands a Z-up model upright with `--up z`, and puts the camera
//! inside a room.

use chiaro::Vec3;
use chiaro::camera::{CameraChoice, UpAxis, apply_camera};
use chiaro::progress::NoProgress;
use chiaro::scene::{Geometry, Material, Object, Scene, Technique, Transform};
use std::path::Path;

const SCENE: &str = r#"
[render]
technique = "phong"
width = 48
height = 36

[camera]
eye = [0, 1, 6]
look_at = [0, 0, 0]

[cameras.side]
eye = [4.5, 2, 1.5]
look_at = [0, 0.3, 0]
fov = 35

[[light]]
type = "point"
position = [2, 4, 3]
intensity = 20

[material.red]
diffuse = [0.8, 0.2, 0.1]
specular = 0.3

[[object]]
primitive = "sphere"
radius = 1
material = "red"

[[object]]
primitive = "plane"
size = 8
transform = { translate = [0, -1, 0] }
"#;

fn load(text: &str) -> Scene {
    chiaro::io::load_scene_str(text, Path::new("."), "cams.toml")
        .expect("loads")
        .scene
}

fn render(scene: &Scene, technique: Technique) -> chiaro::Film {
    let mut s = scene.render.clone();
    s.technique = technique;
    chiaro::render(scene, &s, &NoProgress).expect("renders")
}

#[test]
fn eye_look_at_and_fov_reproduce_a_toml_camera_bit_for_bit() {
    let moved = SCENE.replace(
        "eye = [0, 1, 6]\nlook_at = [0, 0, 0]\n",
        "eye = [4.5, 2, 1.5]\nlook_at = [0, 0.3, 0]\nfov = 35\n",
    );
    let expected = load(&moved);
    let want = render(&expected, Technique::Phong);

    let mut by_flags = load(SCENE);
    let choice =
        CameraChoice::from_flags(None, Some("4.5,2,1.5"), Some("0,0.3,0"), Some("35"), None)
            .expect("parses");
    apply_camera(&mut by_flags, &choice, 48.0 / 36.0).expect("applies");
    assert_eq!(by_flags.camera, expected.camera);
    let got = render(&by_flags, Technique::Phong);
    assert_eq!(got.color, want.color, "--eye/--look-at/--fov");

    let mut by_name = load(SCENE);
    let named = CameraChoice::from_flags(Some("side"), None, None, None, None).expect("parses");
    apply_camera(&mut by_name, &named, 48.0 / 36.0).expect("applies");
    assert_eq!(
        render(&by_name, Technique::Phong).color,
        want.color,
        "--camera side"
    );
    // The default view differs, so the comparison above can fail.
    assert_ne!(render(&load(SCENE), Technique::Phong).color, want.color);
}

/// A model alone (the teapot, white), the background a colour no lit
/// pixel has, rotated by `rotate_x` degrees.
fn model(rotate_x: f32) -> Scene {
    let mut s = Scene::default();
    let m = s.add_material(Material::diffuse("white", Vec3::splat(0.8)));
    let mesh = s.add_mesh(chiaro_core::geometry::teapot::teapot(4));
    s.objects.push(Object {
        geometry: Geometry::Mesh(mesh),
        material: m,
        transform: Transform {
            rotate_degrees: Vec3::new(rotate_x, 0.0, 0.0),
            translate: Vec3::new(3.0, -1.0, 2.0),
            ..Transform::default()
        },
        ..Object::default()
    });
    s.background = Vec3::new(0.0, 0.0, 1.0);
    s.render.width = 80;
    s.render.height = 60;
    s
}

/// Which pixels show the model (not the background colour).
fn coverage(scene: &Scene) -> Vec<bool> {
    let film = render(scene, Technique::Preview);
    film.color.iter().map(|c| *c != scene.background).collect()
}

/// The covered pixels' bounding box as fractions of the frame's width and
/// height, and whether any covered pixel touches the border.
fn extent(mask: &[bool], w: usize, h: usize) -> (f32, f32, bool) {
    let (mut x0, mut x1, mut y0, mut y1) = (w, 0, h, 0);
    for (i, _) in mask.iter().enumerate().filter(|(_, c)| **c) {
        let (x, y) = (i % w, i / w);
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    assert!(x0 <= x1, "nothing covered");
    let border = x0 == 0 || y0 == 0 || x1 == w - 1 || y1 == h - 1;
    (
        (x1 + 1 - x0) as f32 / w as f32,
        (y1 + 1 - y0) as f32 / h as f32,
        border,
    )
}

#[test]
fn a_framed_model_fills_most_of_the_frame_and_stands_upright_with_up_z() {
    let aspect = 80.0 / 60.0;
    let frame = CameraChoice {
        up: Some(UpAxis::Y),
        ..CameraChoice::default()
    };
    let mut y_up = model(0.0);
    apply_camera(&mut y_up, &frame, aspect).expect("frames");
    let a = coverage(&y_up);
    let (fw, fh, border) = extent(&a, 80, 60);
    let fill = fw.max(fh);
    assert!(
        (0.6..=0.95).contains(&fill) && !border,
        "fill {fw} x {fh}, border {border}"
    );

    // The same teapot lying with its up along +z: `--up z` frames it as
    // the Y-up one was (the rotation takes +y to +z and the front +z to
    // -y), so the two images cover the same pixels.
    let mut z_up = model(90.0);
    let upz = CameraChoice {
        up: Some(UpAxis::Z),
        ..CameraChoice::default()
    };
    apply_camera(&mut z_up, &upz, aspect).expect("frames");
    let b = coverage(&z_up);
    let differ = a.iter().zip(&b).filter(|(p, q)| p != q).count();
    assert!(differ * 100 <= a.len(), "{differ} pixels differ");

    // Framed as Y-up, the lying teapot does not look like the standing one.
    let mut lying = model(90.0);
    apply_camera(&mut lying, &frame, aspect).expect("frames");
    let c = coverage(&lying);
    let differ = a.iter().zip(&c).filter(|(p, q)| p != q).count();
    assert!(differ * 20 > a.len(), "only {differ} pixels differ");
}

/// An eye placed closer to a framed model than the framing's near plane
/// (which sits just short of the model) still sees it in the scan
/// converter: the near plane follows the new eye (it stayed, and clipped
/// the whole model away).
#[test]
fn an_eye_close_to_a_framed_model_is_not_clipped_by_the_old_near_plane() {
    let aspect = 80.0 / 60.0;
    let mut s = model(0.0);
    let frame = CameraChoice {
        up: Some(UpAxis::Y),
        ..CameraChoice::default()
    };
    apply_camera(&mut s, &frame, aspect).expect("frames");
    let framed_near = s.camera.near;
    let centre = chiaro::scene_bounds(&s).center();
    // Along the framed view, 80 % of the way to the model's nearest point
    // (the framing puts the near plane at half its depth), well past the
    // old near plane.
    let old_eye = s.camera.eye;
    let eye = old_eye + (centre - old_eye).normalize() * 1.6 * framed_near;
    let choice = CameraChoice {
        eye: Some(eye),
        look_at: Some(centre),
        ..CameraChoice::default()
    };
    apply_camera(&mut s, &choice, aspect).expect("moves");
    assert!(s.camera.near < 0.5 * framed_near, "near {}", s.camera.near);
    let film = render(&s, Technique::Phong);
    let seen = film.color.iter().filter(|c| **c != s.background).count();
    assert!(
        seen * 2 > film.color.len(),
        "phong sees the model in {seen} pixels"
    );
}

#[test]
fn a_room_renders_from_inside_by_default() {
    // A closed 6 x 3 x 8 room, walls facing in, with a table: written as
    // an OBJ and opened as a whole scene, as `chiaro render room.obj` does.
    let mut obj = String::from("o room\n");
    let (x, y, z) = (3.0, 1.5, 4.0);
    for i in 0..8 {
        let s = |b: usize, v: f32| if i & b == 0 { -v } else { v };
        obj += &format!("v {} {} {}\n", s(1, x), s(2, y) + y, s(4, z));
    }
    // Faces wound so that their normals point into the room.
    for f in [
        "1 2 4 3", "5 7 8 6", "1 5 6 2", "3 4 8 7", "1 3 7 5", "2 6 8 4",
    ] {
        obj += &format!("f {f}\n");
    }
    obj += "o table\n";
    for i in 0..8 {
        let s = |b: usize, v: f32| if i & b == 0 { -v } else { v };
        obj += &format!("v {} {} {}\n", s(1, 0.8), s(2, 0.4) + 0.4, s(4, 0.6) - 1.0);
    }
    for f in [
        "9 11 12 10",
        "13 14 16 15",
        "9 10 14 13",
        "11 15 16 12",
        "9 13 15 11",
        "10 12 16 14",
    ] {
        obj += &format!("f {f}\n");
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cameras-room");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let file = dir.join("room.obj");
    std::fs::write(&file, obj).expect("write");
    let mut scene = chiaro::io::load_scene(&file).expect("loads").scene;
    let cam = scene.camera;
    let inside = |p: Vec3| p.x.abs() < x && p.y > 0.0 && p.y < 2.0 * y && p.z.abs() < z;
    assert!(inside(cam.eye), "eye {}", cam.eye);
    assert!(
        cam.look_at.z < -3.9,
        "looks at the far wall: {}",
        cam.look_at
    );
    scene.render.width = 64;
    scene.render.height = 48;
    let film = render(&scene, Technique::Phong);
    let lit = film.color.iter().filter(|c| c.max_element() > 0.02).count();
    assert!(
        lit * 100 >= film.color.len() * 95,
        "{lit} of {} pixels lit",
        film.color.len()
    );
    // The ceiling light reaches the walls directly (not only the ambient
    // term): the picture is several times brighter than by ambient alone.
    let mean = |film: &chiaro::Film| {
        film.color
            .iter()
            .map(|c| c.element_sum() / 3.0)
            .sum::<f32>()
            / film.color.len() as f32
    };
    let lit_mean = mean(&film);
    scene
        .lights
        .retain(|l| matches!(l, chiaro::scene::Light::Ambient { .. }));
    let ambient_mean = mean(&render(&scene, Technique::Phong));
    assert!(
        ambient_mean > 0.0 && lit_mean > 3.0 * ambient_mean,
        "mean {lit_mean}, by the ambient light alone {ambient_mean}"
    );
}
