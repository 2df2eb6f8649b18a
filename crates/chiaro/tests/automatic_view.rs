//! What a model file without camera or lights gets (issue 42): the front
//! view, the neutral studio and its key light, the room lights of an
//! interior; measured on renders as a user would see them (the file loaded
//! by `chiaro::io::load_scene`, rendered at exposure 0 with the clamp tone
//! map).

use chiaro::scene::{Light, Technique};
use chiaro::{Film, NoProgress, RenderSettings, Scene, Vec3};
use chiaro_core::shading::bsdf::luminance;
use chiaro_testkit::base64;
use chiaro_testkit::scenes::obj_box;
use std::path::{Path, PathBuf};

fn render(scene: &Scene, technique: Technique, size: (u32, u32), samples: u32) -> Film {
    let settings = RenderSettings {
        technique,
        width: size.0,
        height: size.1,
        samples,
        ..scene.render.clone()
    };
    chiaro::render(scene, &settings, &NoProgress).expect("renders")
}

/// A file under the system's temporary folder, unique to this process and
/// `name`.
fn temp_file(name: &str, text: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("chiaro-{}-{name}", std::process::id()));
    std::fs::write(&p, text).expect("writes the temporary file");
    p
}

/// A glTF file of `meshes` (each a list of positions and a material index,
/// drawn as a triangle list) placed by `nodes` (a mesh index and the node's
/// JSON properties besides `mesh`, e.g. `"scale": [-1, 1, 1]`), with
/// `materials` given as JSON; no camera, no light.
fn gltf(meshes: &[(Vec<[f32; 3]>, usize)], nodes: &[(usize, &str)], materials: &str) -> String {
    let mut buffer = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut json_meshes = Vec::new();
    for (i, (positions, material)) in meshes.iter().enumerate() {
        let offset = buffer.len();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in positions {
            for k in 0..3 {
                buffer.extend_from_slice(&p[k].to_le_bytes());
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        views.push(format!(
            r#"{{"buffer": 0, "byteOffset": {offset}, "byteLength": {}}}"#,
            12 * positions.len()
        ));
        accessors.push(format!(
            r#"{{"bufferView": {i}, "componentType": 5126, "count": {}, "type": "VEC3", "min": {lo:?}, "max": {hi:?}}}"#,
            positions.len()
        ));
        json_meshes.push(format!(
            r#"{{"primitives": [{{"attributes": {{"POSITION": {i}}}, "material": {material}}}]}}"#
        ));
    }
    let json_nodes: Vec<String> = nodes
        .iter()
        .map(|(mesh, extra)| {
            let sep = if extra.is_empty() { "" } else { ", " };
            format!(r#"{{"mesh": {mesh}{sep}{extra}}}"#)
        })
        .collect();
    let roots: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0,
  "scenes": [{{"nodes": [{}]}}],
  "nodes": [{}],
  "meshes": [{}],
  "materials": {materials},
  "accessors": [{}],
  "bufferViews": [{}],
  "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}]}}"#,
        roots.join(", "),
        json_nodes.join(", "),
        json_meshes.join(", "),
        accessors.join(", "),
        views.join(", "),
        buffer.len(),
        base64(&buffer)
    )
}

/// The two triangles of the axis-aligned rectangle from `lo` to `hi` in
/// the plane z = 0, facing +z.
fn rect(lo: [f32; 2], hi: [f32; 2]) -> Vec<[f32; 3]> {
    let (a, b, c, d) = (
        [lo[0], lo[1], 0.0],
        [hi[0], lo[1], 0.0],
        [hi[0], hi[1], 0.0],
        [lo[0], hi[1], 0.0],
    );
    vec![a, b, c, a, c, d]
}

/// A closed unit cube's 12 triangles, facing out.
fn cube() -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            // Two tangent axes in a right-handed order for the outward normal.
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |a: f32, b: f32| {
                let mut p = [0.0; 3];
                p[axis] = sign;
                p[u] = a;
                p[v] = b;
                p
            };
            let q = [
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(1.0, 1.0),
                corner(-1.0, 1.0),
            ];
            if sign > 0.0 {
                out.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
            } else {
                out.extend([q[0], q[2], q[1], q[0], q[3], q[2]]);
            }
        }
    }
    out
}

/// Mean luminance of the pixels that see a surface and pass `keep(x, y)`.
fn mean_where(f: &Film, keep: impl Fn(u32, u32) -> bool) -> (f32, usize) {
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..f.height {
        for x in 0..f.width {
            let i = (y * f.width + x) as usize;
            if f.depth[i].is_finite() && keep(x, y) {
                sum += luminance(f.color[i]);
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f32, n)
}

/// The fraction of the pixels that see a surface whose largest channel is
/// clipped (8-bit 255 at exposure 0 with the clamp tone map), and the
/// fraction that is black (every channel below 1/255 linear).
fn clipped_and_black(f: &Film) -> (f32, f32) {
    let (mut clipped, mut black, mut n) = (0, 0, 0);
    for (c, d) in f.color.iter().zip(&f.depth) {
        if d.is_finite() {
            n += 1;
            clipped += usize::from(c.max_element() >= 0.995);
            black += usize::from(c.max_element() < 1.0 / 255.0);
        }
    }
    assert!(n > 0, "nothing drawn");
    (clipped as f32 / n as f32, black as f32 / n as f32)
}

/// Issue 42: a mirror-like gold board (roughness 0.05) beside a matte white
/// one (albedo 0.8), a camera-less glTF under the automatic lights: the
/// gold half shows at least 0.4 of the matte half's mean luminance in phong
/// and path (with the studio of Poly Haven's dark studio map: 0.13-0.18).
#[test]
fn a_gold_mirror_board_shows_its_colour_under_the_default_studio() {
    let materials = r#"[
    {"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.766, 0.336, 1], "metallicFactor": 1, "roughnessFactor": 0.05}},
    {"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0, "roughnessFactor": 1}}]"#;
    let text = gltf(
        &[
            (rect([-1.0, -0.7], [0.0, 0.7]), 0),
            (rect([0.0, -0.7], [1.0, 0.7]), 1),
        ],
        &[(0, ""), (1, "")],
        materials,
    );
    let path = temp_file("gold-board.gltf", &text);
    let loaded = chiaro::io::load_scene(&path);
    let _ = std::fs::remove_file(&path);
    let scene = loaded.expect("loads").scene;
    assert!(scene.environment.is_some(), "the studio lights it");
    let (w, h) = (96, 72);
    for (t, spp) in [(Technique::Phong, 1), (Technique::Path, 64)] {
        let f = render(&scene, t, (w, h), spp);
        // Seen from the front: gold left of the centre column, matte right.
        let (gold, ng) = mean_where(&f, |x, _| x + 3 < w / 2);
        let (matte, nm) = mean_where(&f, |x, _| x > w / 2 + 3);
        eprintln!("{t:?}: gold {gold} ({ng} px), matte {matte} ({nm} px)");
        assert!(ng > 500 && nm > 500, "{ng} {nm}");
        assert!(gold >= 0.4 * matte, "{t:?}: gold {gold} vs matte {matte}");
        assert!(matte > 0.3, "{t:?}: matte {matte}");
    }
}

/// Issue 42: a white scan (the Stanford bunny, albedo 0.8) under the
/// automatic lights clips under 2 % of its pixels in phong and path (55-66
/// % of the dragon's and armadillo's with a key of intensity 1 over a
/// studio of mean 0.5), and is not dark either (mean luminance over 0.35).
#[test]
fn a_white_scan_under_the_automatic_lights_is_not_clipped() {
    let Some(bunny) = chiaro_testkit::shared_asset("common-3d-test-models/stanford-bunny.obj")
    else {
        return;
    };
    let scene = chiaro::io::load_scene(&bunny).expect("loads").scene;
    for (t, spp) in [(Technique::Phong, 1), (Technique::Path, 16)] {
        let f = render(&scene, t, (96, 72), spp);
        let (clipped, black) = clipped_and_black(&f);
        let (mean, n) = mean_where(&f, |_, _| true);
        eprintln!("{t:?}: {clipped} clipped, {black} black, mean {mean} over {n} px");
        assert!(n > 1000, "{n}");
        assert!(clipped < 0.02, "{t:?}: {clipped} of the bunny clipped");
        assert!(mean > 0.35, "{t:?}: mean {mean}");
    }
}

/// A room without lights, as an OBJ: a closed box whose faces look in (8 x
/// 3 x 5) with a table (a box on four legs), written to a temporary file.
fn room_obj() -> String {
    let mut obj = String::from("o room\n");
    let mut base = 0;
    let mut add_box = |obj: &mut String, lo: Vec3, hi: Vec3, inward: bool| {
        obj_box(obj, base, lo, hi, inward);
        base += 8;
    };
    add_box(
        &mut obj,
        Vec3::new(-4.0, 0.0, -2.5),
        Vec3::new(4.0, 3.0, 2.5),
        true,
    );
    add_box(
        &mut obj,
        Vec3::new(-1.5, 0.7, -0.8),
        Vec3::new(1.5, 0.8, 0.8),
        false,
    );
    for (x, z) in [(-1.4, -0.7), (1.3, -0.7), (-1.4, 0.6), (1.3, 0.6)] {
        add_box(
            &mut obj,
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 0.1, 0.7, z + 0.1),
            false,
        );
    }
    obj
}

/// Issue 42: an OBJ room without lights is lit as a room: a ceiling panel
/// and a fill, no pure white ceiling and table (23 % of the frame under an
/// ambient and a point light), no black under the table, in phong and path.
#[test]
fn a_room_without_lights_is_lit_like_a_room() {
    let path = temp_file("room.obj", &room_obj());
    let loaded = chiaro::io::load_scene(Path::new(&path));
    let _ = std::fs::remove_file(&path);
    let loaded = loaded.expect("loads");
    let scene = loaded.scene;
    assert!(
        scene.lights.iter().any(|l| matches!(l, Light::Area { .. })),
        "{:?}",
        scene.lights
    );
    assert!(scene.environment.is_none(), "walls shut a studio out");
    // Inside, looking along the room.
    let eye = scene.camera.eye;
    assert!(eye.x.abs() < 4.0 && eye.y > 0.0 && eye.y < 3.0 && eye.z.abs() < 2.5);
    for (t, spp) in [(Technique::Phong, 1), (Technique::Path, 32)] {
        let f = render(&scene, t, (96, 72), spp);
        let (clipped, black) = clipped_and_black(&f);
        let (mean, _) = mean_where(&f, |_, _| true);
        eprintln!("{t:?}: {clipped} clipped, {black} black, mean {mean}");
        assert!(clipped < 0.02, "{t:?}: {clipped} clipped");
        assert!(black < 0.02, "{t:?}: {black} black");
        assert!(mean > 0.05, "{t:?}: mean {mean}");
    }
}

/// Issue 42: a glTF whose nodes mirror their meshes (negative scales, one
/// node and a nested pair whose scales cancel) is framed from outside,
/// with the whole model in view and lit (it was framed with the camera
/// inside a mirrored cube's bounds and rendered black).
#[test]
fn a_model_with_negative_scale_nodes_is_framed_and_visible() {
    let materials = r#"[{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0, "roughnessFactor": 1}}]"#;
    for nodes in [
        vec![(0, r#""scale": [-1, 1, 1]"#)],
        vec![(0, r#""scale": [1, -2, 1], "translation": [0, 0, 0]"#)],
        vec![
            (0, r#""scale": [-1, 1, 1], "translation": [-1.5, 0, 0]"#),
            (0, r#""scale": [1, -1, -1], "translation": [1.5, 0, 0]"#),
        ],
    ] {
        let text = gltf(&[(cube(), 0)], &nodes, materials);
        let path = temp_file("mirrored.gltf", &text);
        let loaded = chiaro::io::load_scene(&path);
        let _ = std::fs::remove_file(&path);
        let scene = loaded.expect("loads").scene;
        let b = chiaro::io::world_bounds(&scene);
        let eye = scene.camera.eye;
        assert!(
            (eye - eye.clamp(b.min, b.max)).length() > 0.5 * b.diagonal(),
            "{nodes:?}: eye {eye} in or at bounds {b:?}"
        );
        let f = render(&scene, Technique::Phong, (64, 48), 1);
        let (mean, n) = mean_where(&f, |_, _| true);
        assert!(n > 64 * 48 / 5, "{nodes:?}: {n} px drawn");
        assert!(mean > 0.1, "{nodes:?}: mean {mean}");
        // Nothing cut at the frame's edges: the border rows and columns see
        // no surface.
        let edge = (0..64u32)
            .flat_map(|x| [(x, 0), (x, 47)])
            .chain((0..48u32).flat_map(|y| [(0, y), (63, y)]))
            .filter(|&(x, y)| f.depth[(y * 64 + x) as usize].is_finite())
            .count();
        assert_eq!(edge, 0, "{nodes:?}: {edge} border pixels drawn");
    }
}

/// Issue 42: a Z-up scan read as y up (the bunny turned so that its base
/// is at its lowest z) is shown lying down with a warning that names
/// `--up z`; the bunny as it is (y up) gets no such warning.
#[test]
fn a_z_up_scan_is_named_with_the_flag_that_stands_it_up() {
    let Some(bunny) = chiaro_testkit::shared_asset("common-3d-test-models/stanford-bunny.obj")
    else {
        return;
    };
    let text = std::fs::read_to_string(&bunny).expect("reads the bunny");
    // (x, y, z) -> (x, -z, y): the y-up model turned to stand along +z.
    let turned: String = text
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(rest) => {
                let c: Vec<f32> = rest
                    .split_whitespace()
                    .map(|v| v.parse().expect("a number"))
                    .collect();
                format!("v {} {} {}\n", c[0], -c[2], c[1])
            }
            None => format!("{l}\n"),
        })
        .collect();
    let path = temp_file("bunny-z-up.obj", &turned);
    let loaded = chiaro::io::load_scene(&path);
    let _ = std::fs::remove_file(&path);
    let says_z = |w: &[String]| w.iter().any(|w| w.contains("--up z"));
    let warnings = loaded.expect("loads").warnings;
    assert!(says_z(&warnings), "{warnings:?}");
    let upright = chiaro::io::load_scene(&bunny).expect("loads").warnings;
    assert!(!says_z(&upright), "{upright:?}");
}
