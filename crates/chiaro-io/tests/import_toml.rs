//! The `.toml` scene format: every section of the format builds the
//! expected scene, and every kind of bad input gives an error at the exact
//! line and column of the offending value.

use chiaro_core::Vec3;
use chiaro_core::scene::{
    AreaShape, Attenuation, Geometry, Light, ProceduralKind, ReflectanceModel, ShadeMode,
    Technique, Texture,
};
use chiaro_io::{IoError, load_scene_str};
use std::path::Path;

/// Parses `text` and returns the error's (line, column, message).
fn error_at(text: &str) -> (usize, usize, String) {
    match load_scene_str(text, Path::new("/nonexistent-dir"), "t.toml") {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(IoError::At {
            line,
            column,
            message,
            path,
        }) => {
            assert_eq!(path, Path::new("t.toml"));
            (line, column, message)
        }
        Err(other) => panic!("expected a positioned error, got {other}"),
    }
}

#[test]
fn unknown_key_is_refused_at_its_position() {
    let (l, c, m) = error_at("[camera]\neye = [0, 0, 5]\nfocal = 3\n");
    assert_eq!((l, c), (3, 1), "{m}");
    assert!(m.contains("unknown key `focal`"), "{m}");
    let (l, c, m) = error_at("[material.a]\ndiffuse = 0.5\nshiny = 3\n");
    assert_eq!((l, c), (3, 1), "{m}");
    assert!(
        m.contains("shininess"),
        "the message lists the expected keys: {m}"
    );
    let (_, _, m) = error_at("[material.a]\ndifuse = 0.5\n");
    assert!(m.contains("did you mean `diffuse`?"), "{m}");
}

#[test]
fn wrong_type_is_refused_at_its_position() {
    let (l, c, m) = error_at("[render]\nwidth = \"wide\"\n");
    assert_eq!((l, c), (2, 9), "{m}");
    assert!(
        m.contains(r#"`width` must be a whole number (0 or more), got the text "wide""#),
        "{m}"
    );
    let (l, c, m) = error_at("[material.a]\ndiffuse = [1, 2]\n");
    assert_eq!((l, c), (2, 11), "{m}");
    assert!(m.contains("3 numbers"), "{m}");
}

#[test]
fn unknown_material_lists_the_known_ones() {
    let text = "[material.matte]\n[material.glass]\ntransmit = 0.9\n\n[[object]]\nprimitive = \"box\"\nmaterial = \"glas\"\n";
    let (l, c, m) = error_at(text);
    assert_eq!((l, c), (7, 12), "{m}");
    assert_eq!(m, r#"unknown material "glas" (known: matte, glass)"#);
}

#[test]
fn nan_and_infinity_are_refused() {
    let (l, c, m) = error_at("[camera]\nfov = nan\n");
    assert_eq!((l, c), (2, 7), "{m}");
    assert!(m.contains("finite"), "{m}");
    let (l, c, m) = error_at("[[light]]\ntype = \"point\"\nposition = [0, -inf, 0]\n");
    assert_eq!((l, c), (3, 16), "{m}");
    let (l, c, m) = error_at("[material.a]\ndiffuse = 1e300\n");
    assert_eq!((l, c), (2, 11), "{m}");
    assert!(m.contains("too large"), "{m}");
}

#[test]
fn zero_and_huge_resolutions_are_refused() {
    let (l, c, m) = error_at("[render]\nwidth = 0\n");
    assert_eq!((l, c), (2, 9), "{m}");
    assert!(m.contains("1..=16384"), "{m}");
    let (l, c, m) = error_at("[render]\nwidth = 64\nheight = 100000\n");
    assert_eq!((l, c), (3, 10), "{m}");
    // Each side within the limit but too many pixels in all.
    let (l, c, m) = error_at("[render]\nwidth = 16000\nheight = 16000\n");
    assert_eq!((l, c), (3, 10), "{m}");
    assert!(m.contains("pixels"), "{m}");
    let (l, c, m) = error_at("[render]\n[render.shadow_map]\nresolution = 0\n");
    assert_eq!((l, c), (3, 14), "{m}");
}

#[test]
fn missing_mesh_file_names_the_file_and_line() {
    let text = "[[object]]\nname = \"pot\"\nmesh = \"models/teapot.obj\"\n";
    let (l, c, m) = error_at(text);
    assert_eq!((l, c), (3, 8), "{m}");
    assert!(
        m.contains("models/teapot.obj") && m.contains("not found"),
        "{m}"
    );
    let (l, c, m) = error_at("[material.a]\ntexture = \"wood.png\"\n");
    assert_eq!((l, c), (2, 11), "{m}");
    assert!(m.contains("wood.png"), "{m}");
}

#[test]
fn semantic_errors_point_at_the_value() {
    // A field that does not apply to the light type.
    let (l, c, m) =
        error_at("[[light]]\ntype = \"directional\"\ndirection = [0, -1, 0]\ncone = 30\n");
    assert_eq!((l, c), (4, 8), "{m}");
    // Unknown enum value.
    let (l, c, m) = error_at("[render]\ntechnique = \"raytrace\"\n");
    assert_eq!((l, c), (2, 13), "{m}");
    assert!(m.contains("whitted"), "{m}");
    // Unknown primitive, and fov out of range.
    let (l, c, _) = error_at("[[object]]\nprimitive = \"torus\"\n");
    assert_eq!((l, c), (2, 13));
    let (l, c, _) = error_at("[camera]\nfov = 180\n");
    assert_eq!((l, c), (2, 7));
    // Syntax error.
    let (l, c, _) = error_at("[render]\nwidth = = 3\n");
    assert_eq!(l, 2, "col {c}");
}

#[test]
fn every_design_section_maps_onto_the_scene() {
    let text = r#"
background = 0.05

[render]
technique = "whitted"
width = 32
height = 24
samples = 4
shadows = "map"
exposure = 0.5
[render.shadow_map]
resolution = 512
[render.whitted]
max_depth = 3
[render.path]
max_depth = 2
[render.radiosity]
solver = "gauss-seidel"
formfactor = "hemicube"
[render.depth_cue]
color = [0.1, 0.1, 0.2]
near = 1
far = 10

[camera]
eye = [278, 273, -800]
look_at = [278, 273, 0]
up = [0, 1, 0]
fov = 39.3

[[light]]
type = "point"
position = [278, 548, 279]
color = [1, 1, 1]
intensity = 1.0
attenuation = { c1 = 1, c2 = 0, c3 = 0.0001 }

[[light]]
type = "spot"
position = [0, 5, 0]
look_at = [0, 0, 0]
exponent = 8
cone = 30
cone_softness = 5
attenuation = "none"
flaps = [{ axis = [1, 0, 0], min = -1, max = 1 }]

[[light]]
type = "area"
shape = "quad"
corner = [0, 5, 0]
edge_u = [1, 0, 0]
edge_v = [0, 0, 1]
intensity = 10

[[light]]
type = "ambient"
color = 0.2

[material.white]
ambient = 0.1
diffuse = [0.73, 0.73, 0.73]
specular = 0.0
shininess = 20
model = "phong"
reflect = 0.0
transmit = 0.0
ior = 1.5
transparency = "filtered"
texture = { procedural = "marble", scale = 4.0, color_a = [0.9, 0.9, 0.9], color_b = [0.2, 0.2, 0.3] }
bump = { procedural = "dimples", height = 0.02 }
emission = [0, 0, 0]

[material.metal]
model = "torrance-sparrow"
roughness = 0.2
specular = [0.9, 0.6, 0.3]

[[object]]
primitive = "teapot"
material = "white"
transform = { translate = [0, 0, 0], rotate_y = 30, scale = 1 }
smooth = true
crease_angle = 30

[[object]]
primitive = "cylinder"
radius = 0.5
height = 2
material = "metal"
shade = "flat"
transform = { rotate = [0, 90, 0], scale = [1, 2, 1] }

[[object]]
primitive = "sphere"
radius = 2
"#;
    let l = load_scene_str(text, Path::new("."), "all.toml").expect("loads");
    let s = &l.scene;
    assert_eq!(s.background, Vec3::splat(0.05));
    assert_eq!(s.render.technique, Technique::Whitted);
    assert_eq!(
        (s.render.width, s.render.height, s.render.samples),
        (32, 24, 4)
    );
    assert_eq!(s.render.shadow_map.resolution, 512);
    assert_eq!(s.render.whitted.max_depth, 3);
    assert_eq!(s.render.path.max_depth, 2);
    assert_eq!(
        s.render.radiosity.solver,
        chiaro_core::scene::RadiositySolver::GaussSeidel
    );
    assert_eq!(s.render.depth_cue.map(|d| d.far), Some(10.0));
    assert!((s.camera.fov_y_degrees - 39.3).abs() < 1e-5);
    assert_eq!(s.lights.len(), 4);
    match &s.lights[0] {
        Light::Point { attenuation, .. } => assert_eq!(
            *attenuation,
            Attenuation::Empirical {
                c1: 1.0,
                c2: 0.0,
                c3: 0.0001
            }
        ),
        other => panic!("{other:?}"),
    }
    match &s.lights[1] {
        Light::Spot(sp) => {
            assert!((sp.direction - Vec3::NEG_Y).length() < 1e-6);
            assert_eq!(
                (sp.exponent, sp.cone_degrees, sp.cone_softness_degrees),
                (8.0, 30.0, 5.0)
            );
            assert_eq!(sp.flaps.len(), 1);
            assert_eq!(sp.attenuation, Attenuation::None);
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        s.lights[2],
        Light::Area {
            shape: AreaShape::Quad { .. },
            ..
        }
    ));
    assert_eq!(s.lights[3].power_rgb(), Vec3::splat(0.2));
    let white = &s.materials[s.material_by_name("white").expect("white").index()];
    let tex = white.texture.expect("texture");
    assert!(matches!(
        s.textures[tex.index()],
        Texture::Procedural(p) if p.kind == ProceduralKind::Marble && p.scale == 4.0
    ));
    let bump = white.bump.expect("bump");
    assert_eq!(bump.height, 0.02);
    let metal = &s.materials[s.material_by_name("metal").expect("metal").index()];
    assert_eq!(metal.model, ReflectanceModel::TorranceSparrow);
    assert_eq!(metal.roughness, 0.2);
    assert_eq!(s.objects.len(), 3);
    assert_eq!(
        s.objects[0].transform.rotate_degrees,
        Vec3::new(0.0, 30.0, 0.0)
    );
    assert!(matches!(s.objects[0].geometry, Geometry::Mesh(_)));
    assert_eq!(s.objects[1].shade_mode, Some(ShadeMode::Flat));
    assert_eq!(s.objects[1].transform.scale, Vec3::new(1.0, 2.0, 1.0));
    assert_eq!(s.objects[2].geometry, Geometry::Sphere { radius: 2.0 });
    // The sphere has no material: it gets the default one.
    assert_eq!(s.materials[s.objects[2].material.index()].name, "default");
}

#[test]
fn obj_and_gltf_as_objects_inside_a_toml_scene() {
    // Both files are in the repository (with their licences), so the test
    // runs on a fresh clone.
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let text = r#"
[material.gold]
diffuse = [0.8, 0.6, 0.2]

[[object]]
mesh = "crates/chiaro-io/tests/data/mcguire-cornell/CornellBox-Original.obj"

[[object]]
name = "duck"
mesh = "scenes/gltf/Duck.glb"
material = "gold"
transform = { translate = [0, 1, 0], scale = 0.01 }
"#;
    let l = load_scene_str(text, root, "mixed.toml").expect("loads");
    let s = &l.scene;
    let gold = s.material_by_name("gold").expect("gold");
    let duck: Vec<_> = s
        .objects
        .iter()
        .filter(|o| o.name.starts_with("duck/"))
        .collect();
    assert!(!duck.is_empty());
    assert!(duck.iter().all(|o| o.material == gold));
    // The Cornell box keeps its own materials, including the emissive light.
    assert!(
        s.materials
            .iter()
            .any(|m| m.name == "light" && m.is_emissive())
    );
    let box_objects = s.objects.len() - duck.len();
    assert!(box_objects >= 5, "{box_objects}");
}

/// A mesh file named by several objects is read once and its meshes and
/// materials are shared by the placements (instances); a material override
/// gets its own copy (its faces drop the file's materials).
#[test]
fn one_mesh_file_placed_twice_shares_its_meshes() {
    let scenes = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes"));
    let text = r#"
[material.gold]
diffuse = [0.8, 0.6, 0.2]

[[object]]
name = "a"
mesh = "meshes/cornell-tall-block.obj"

[[object]]
name = "b"
mesh = "meshes/../meshes/cornell-tall-block.obj"
transform = { translate = [2, 0, 0], rotate = [0, 30, 0] }

[[object]]
name = "c"
mesh = "meshes/cornell-tall-block.obj"
material = "gold"
"#;
    let once = load_scene_str(
        r#"
[[object]]
mesh = "meshes/cornell-tall-block.obj"
"#,
        scenes,
        "once.toml",
    )
    .expect("loads");
    let l = load_scene_str(text, scenes, "twice.toml").expect("loads");
    let s = &l.scene;
    let meshes_of = |prefix: &str| -> Vec<Geometry> {
        s.objects
            .iter()
            .filter(|o| o.name.starts_with(prefix))
            .map(|o| o.geometry)
            .collect()
    };
    let (a, b, c) = (meshes_of("a/"), meshes_of("b/"), meshes_of("c/"));
    assert!(!a.is_empty());
    assert_eq!(a, b, "the same file through another path shares its meshes");
    assert_eq!(a.len(), c.len());
    assert!(a.iter().zip(&c).all(|(x, y)| x != y), "the override copies");
    // Meshes: one copy for a and b, one for c; materials: the file's once,
    // plus gold.
    assert_eq!(s.meshes.len(), 2 * once.scene.meshes.len());
    assert_eq!(s.materials.len(), once.scene.materials.len() + 1);
    // The placements differ only by the transform.
    let pa = s
        .objects
        .iter()
        .find(|o| o.name.starts_with("a/"))
        .expect("a");
    let pb = s
        .objects
        .iter()
        .find(|o| o.name.starts_with("b/"))
        .expect("b");
    assert_eq!(pa.material, pb.material);
    assert_ne!(pa.transform, pb.transform);
}

#[test]
fn primitives_beyond_the_memory_limit_are_refused_before_tessellating() {
    // The documented maximum subdivisions: 33.5M triangles, refused at the
    // parameter under a 1 GiB limit (nothing is tessellated).
    let (line, col, msg) = error_at(
        "[render]\nmemory_limit = \"1G\"\n\n[[object]]\nprimitive = \"plane\"\nsubdivisions = 4096\n",
    );
    assert_eq!((line, col), (6, 16), "{msg}");
    assert!(
        msg.contains("33554432 triangles") && msg.contains("memory limit is 1.0 GiB"),
        "{msg}"
    );
    // Instances add up: one plane of 524,288 triangles fits, 20 do not.
    let mut text = String::from("[render]\nmemory_limit = \"1G\"\n");
    for _ in 0..20 {
        text += "[[object]]\nprimitive = \"plane\"\nsubdivisions = 512\n";
    }
    let (_, _, msg) = error_at(&text);
    assert!(msg.contains("with the primitives before it"), "{msg}");
    // A small limit that fits, read back as bytes.
    let l = load_scene_str(
        "[render]\nmemory_limit = \"64M\"\n[[object]]\nprimitive = \"plane\"\nsubdivisions = 8\n",
        Path::new("."),
        "m.toml",
    )
    .expect("fits");
    assert_eq!(
        l.scene.render.memory_limit,
        Some(chiaro_core::budget::ByteSize(64 << 20))
    );
    let (_, _, msg) = error_at("[render]\nmemory_limit = \"lots\"\n");
    assert!(msg.contains("not a size"), "{msg}");
}

/// `[render]` values are checked by `RenderSettings::validate` (the check
/// `--set`, Python and the web viewer share); its issues are placed at the
/// setting's value, whichever way the key is written, and name the setting.
#[test]
fn settings_errors_come_from_validate_at_the_value() {
    let (l, c, m) = error_at("[render]\nsamples = 0\n");
    assert_eq!((l, c), (2, 11), "{m}");
    assert_eq!(m, "render.samples: expected 1..=65536, got 0");
    let (l, c, m) =
        error_at("[render]\nwidth = 8\n\n[render.radiosity]\nhemicube_resolution = 1\n");
    assert_eq!((l, c), (5, 23), "{m}");
    assert_eq!(
        m,
        "render.radiosity.hemicube_resolution: expected 2..=4096, got 1"
    );
    // Dotted keys and inline tables are found too.
    let (l, c, m) = error_at("[render]\nradiosity.tolerance = 1.5\n");
    assert_eq!((l, c), (2, 23), "{m}");
    assert!(m.starts_with("render.radiosity.tolerance: "), "{m}");
    let (l, c, m) = error_at("[render]\nshadow_map = { resolution = 8 }\n");
    assert_eq!((l, c), (2, 29), "{m}");
    assert!(m.starts_with("render.shadow_map.resolution: "), "{m}");
    // A check that only validate made before: the light samples' bound.
    let (l, c, m) = error_at("[render]\nlight_samples = 100000\n");
    assert_eq!((l, c), (2, 17), "{m}");
    assert_eq!(
        m,
        "render.light_samples: expected 1..=65536 samples per area light, got 100000"
    );
    // An issue about a key the file leaves at its default is placed at the
    // nearest table the file has: `far` defaults to 100.
    let (l, c, m) = error_at("[render]\nwidth = 8\n[render.depth_cue]\nnear = 200\n");
    assert_eq!((l, c), (3, 1), "{m}");
    assert_eq!(
        m,
        "render.depth_cue.far: expected far > near, got near 200 far 100"
    );
    // Names of solvers are serde's: an unknown one is refused at its value
    // with the list.
    let (l, c, m) = error_at("[render.radiosity]\nsolver = \"gauss\"\n");
    assert_eq!((l, c), (2, 10), "{m}");
    assert!(
        m.starts_with("render.radiosity.solver: unknown value `gauss`")
            && m.contains("did you mean `gauss-seidel`")
            && m.contains("hierarchical"),
        "{m}"
    );
}

/// Every settings error is reported, each at its value; the error's own
/// line and column are the first one's.
#[test]
fn every_settings_error_is_reported_with_its_location() {
    let text = "[render]\nsamples = 0\n[render.path]\nmax_depth = 0\n";
    let (l, c, m) = error_at(text);
    assert_eq!((l, c), (2, 11), "{m}");
    assert_eq!(
        m,
        "render.samples: expected 1..=65536, got 0\n\
         t.toml:4:13: render.path.max_depth: expected at least 1 (1 = direct light only)"
    );
}

/// Settings warnings are the render context's to report, not the loader's.
#[test]
fn settings_warnings_are_not_load_warnings() {
    let text = "[render]\ntechnique = \"phong\"\nsamples = 100\n";
    let l = load_scene_str(text, Path::new("."), "t.toml").expect("a warning is not an error");
    assert!(
        l.warnings.iter().all(|w| !w.contains("render.")),
        "{:?}",
        l.warnings
    );
    assert_eq!(l.scene.render.samples, 100);
}

/// Checks `Scene::validate` makes for every scene (camera, material and
/// spot-cone ranges) are made once, there, and placed at the file's key.
#[test]
fn scene_validate_issues_are_placed_at_the_key() {
    let (l, c, m) = error_at("[camera]\neye = [0, 0, 5]\nfov = 180\n");
    assert_eq!((l, c), (3, 7), "{m}");
    assert_eq!(m, "camera.fov: expected 0 < fov < 180 degrees, got 180");
    let (l, c, m) = error_at("[camera]\neye = [0, 1, 2]\nlook_at = [0, 1, 2]\n");
    assert_eq!((l, c), (3, 11), "{m}");
    assert_eq!(m, "camera.look_at: eye and look_at are the same point");
    let (l, c, m) = error_at("[camera]\nnear = 0\n");
    assert_eq!((l, c), (2, 8), "{m}");
    assert!(m.starts_with("camera.near: expected 0 < near < far"), "{m}");
    let (l, c, m) = error_at("[cameras.top]\neye = [0, 9, 0]\nup = [0, 0, 1]\nfov = 0\n");
    assert_eq!((l, c), (4, 7), "{m}");
    assert!(m.starts_with("cameras[0].fov: "), "{m}");
    let (l, c, m) = error_at("[material.a]\n[material.\"b.c\"]\ndiffuse = 0.5\nroughness = 0\n");
    assert_eq!((l, c), (4, 13), "{m}");
    assert_eq!(
        m,
        "materials[1] (b.c).roughness: expected 0 < roughness <= 1, got 0"
    );
    let (l, c, m) = error_at("[material.a]\nspecular = [0.5, -1, 0]\n");
    assert_eq!((l, c), (2, 12), "{m}");
    assert!(
        m.starts_with("materials[0] (a).specular: expected values >= 0"),
        "{m}"
    );
    let (l, c, m) = error_at(
        "[[light]]\ntype = \"point\"\nposition = [0, 1, 0]\n\n[[light]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\ncone = 200\n",
    );
    assert_eq!((l, c), (9, 8), "{m}");
    assert_eq!(
        m,
        "lights[1] (spot).cone: expected 0 < cone <= 180 degrees, got 200"
    );
    // Several errors: each at its key.
    let (l, c, m) = error_at("[camera]\nfov = 0\n[material.a]\nior = 0\n");
    assert_eq!((l, c), (2, 7), "{m}");
    assert!(
        m.contains("\nt.toml:4:7: materials[0] (a).ior: expected a finite number > 0, got 0"),
        "{m}"
    );
}

#[test]
fn material_sidedness_and_its_older_keys() {
    use chiaro_core::scene::Sidedness;
    let of = |keys: &str| {
        let text = format!("[material.m]\ndiffuse = 0.5\n{keys}\n");
        let scene = load_scene_str(&text, Path::new("/nonexistent-dir"), "t.toml")
            .expect("parses")
            .scene;
        let m = scene.materials.iter().find(|m| m.name == "m").expect("m");
        (m.sidedness, m.emission_two_sided)
    };
    // Nothing said: two-sided, emitting from the front.
    assert_eq!(of(""), (Sidedness::TwoSided, false));
    assert_eq!(
        of("sidedness = \"one-sided\""),
        (Sidedness::OneSided, false)
    );
    assert_eq!(of("sidedness = \"culled\""), (Sidedness::Culled, false));
    assert_eq!(
        of("sidedness = \"two-sided\"\nemission_two_sided = true"),
        (Sidedness::TwoSided, true)
    );
    // The older keys.
    assert_eq!(of("two_sided = true"), (Sidedness::TwoSided, true));
    assert_eq!(of("two_sided = false"), (Sidedness::OneSided, false));
    assert_eq!(of("cull_backface = true"), (Sidedness::Culled, false));
    // `sidedness` wins over them.
    assert_eq!(
        of("sidedness = \"culled\"\ntwo_sided = true"),
        (Sidedness::Culled, true)
    );
    let (l, c, m) = error_at("[material.m]\nsidedness = \"both\"\n");
    assert_eq!((l, c), (2, 13), "{m}");
    assert!(m.contains("one-sided"), "{m}");
}

/// `projection = "orthographic"` with `half_height`; perspective stays the
/// default, and the mixed-up keys are refused at their place.
#[test]
fn orthographic_camera_keys() {
    let text = "[camera]\neye = [0, 0, 5]\nprojection = \"orthographic\"\nhalf_height = 2.5\n[cameras.side]\neye = [5, 0, 0]\n";
    let s = load_scene_str(text, Path::new("."), "t.toml")
        .expect("test input")
        .scene;
    assert_eq!(
        s.camera.projection,
        chiaro_core::scene::Projection::Orthographic { half_height: 2.5 }
    );
    assert_eq!(
        s.cameras[0].camera.projection,
        chiaro_core::scene::Projection::Perspective
    );
    let (l, c, m) = error_at("[camera]\nprojection = \"orthographic\"\n");
    assert_eq!((l, c), (2, 14), "{m}");
    assert!(m.contains("needs `half_height`"), "{m}");
    let (l, c, m) =
        error_at("[camera]\nprojection = \"orthographic\"\nhalf_height = 1\nfov = 30\n");
    assert_eq!((l, c), (4, 7), "{m}");
    assert!(m.contains("no `fov`"), "{m}");
    let (l, _, m) = error_at("[camera]\nhalf_height = 1\n");
    assert_eq!(l, 2, "{m}");
    let (l, c, m) = error_at("[camera]\nprojection = \"fisheye\"\n");
    assert_eq!((l, c), (2, 14), "{m}");
    assert!(m.contains("unknown projection"), "{m}");
    let (l, c, m) = error_at("[camera]\nprojection = \"orthographic\"\nhalf_height = -1\n");
    assert_eq!((l, c), (3, 15), "{m}");
    assert!(
        m.starts_with("camera.half_height: expected a finite half-height > 0"),
        "{m}"
    );
}
