//! `chiaro export` round trip (issue 45, item 6): a scene written once in
//! TOML, exported to Mitsuba 3 XML and read back by chiaro's own Mitsuba
//! reader renders bit for bit the same with the path tracer. (The scene's
//! fields are compared in `chiaro-io`'s export tests; pbrt's export is
//! checked there structurally until a pbrt reader exists.)

use chiaro::Technique;
use chiaro::progress::NoProgress;

/// A small box: flat quads and a box, an emissive one-sided quad, and a
/// sphere of each exact material (mirror, rough gold, glass).
const SCENE: &str = r#"
[render]
technique = "path"
width = 32
height = 24
samples = 8
[render.path]
max_depth = 6
[camera]
eye = [0, 1, 4]
look_at = [0, 1, 3]
fov = 45
[material.white]
diffuse = [0.7, 0.6, 0.5]
[material.red]
diffuse = [0.6, 0.1, 0.1]
sidedness = "one-sided"
[material.light]
diffuse = 0.2
emission = [6, 5, 4]
sidedness = "one-sided"
[material.mirror]
diffuse = 0
reflect = [0.9, 0.9, 0.8]
[material.gold]
diffuse = 0
specular = 1
model = "torrance-sparrow"
roughness = 0.25
conductor = "Au"
[material.copper]
diffuse = 0
reflect = 1
conductor = { eta = [0.2, 0.92, 1.1], k = [3.9, 2.45, 2.14] }
[material.glass]
diffuse = 0
transmit = [1, 0.95, 0.9]
ior = 1.5
fresnel = true
[[object]]
name = "floor"
primitive = "quad"
corner = [-2, 0, 2]
edge_u = [4, 0, 0]
edge_v = [0, 0, -4]
material = "white"
smooth = false
[[object]]
name = "back"
primitive = "quad"
corner = [-2, 0, -2]
edge_u = [4, 0, 0]
edge_v = [0, 3, 0]
material = "red"
smooth = false
[[object]]
name = "lamp"
primitive = "quad"
corner = [-0.5, 2.5, -0.5]
edge_u = [1, 0, 0]
edge_v = [0, 0, 1]
material = "light"
smooth = false
[[object]]
primitive = "sphere"
radius = 0.3
material = "mirror"
transform = { translate = [-0.9, 0.3, 0] }
[[object]]
primitive = "sphere"
radius = 0.3
material = "gold"
transform = { translate = [-0.2, 0.3, 0.2] }
[[object]]
primitive = "sphere"
radius = 0.3
material = "copper"
transform = { translate = [0.5, 0.3, -0.3] }
[[object]]
primitive = "sphere"
radius = 0.3
material = "glass"
transform = { translate = [0.9, 0.4, 0.6] }
[[object]]
name = "block"
primitive = "box"
size = 0.5
material = "white"
smooth = false
transform = { translate = [0, 0.25, -1.2], rotate_y = 30 }
"#;

#[test]
fn toml_exported_to_mitsuba_and_read_back_renders_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("chiaro-export-roundtrip-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let toml = dir.join("box.toml");
    std::fs::write(&toml, SCENE).expect("scene written");
    let scene = chiaro::io::load_scene(&toml).expect("loads").scene;
    let xml = dir.join("box.xml");
    let done = chiaro::io::export::export(&scene, chiaro::io::export::Format::Mitsuba, &xml)
        .expect("exports");
    assert!(done.warnings.is_empty(), "{:?}", done.warnings);
    let back = chiaro::io::load_scene(&xml).expect("reads back");
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    let back = back.scene;
    assert_eq!(back.render.technique, Technique::Path);
    let settings = scene.render.clone();
    let a = chiaro::render(&scene, &settings, &NoProgress).expect("renders");
    let b = chiaro::render(&back, &settings, &NoProgress).expect("renders");
    let lit = a.color.iter().filter(|c| c.max_element() > 0.0).count();
    assert!(lit > a.color.len() / 2, "the scene is lit: {lit} pixels");
    let differ = a
        .color
        .iter()
        .zip(&b.color)
        .filter(|(x, y)| x.to_array().map(f32::to_bits) != y.to_array().map(f32::to_bits))
        .count();
    assert_eq!(differ, 0, "{differ} of {} pixels differ", a.color.len());
    let _ = std::fs::remove_dir_all(&dir);
}
