//! Tests of `chiaro export`: refusals name the object and feature and
//! write nothing; the Mitsuba file reads back as the scene written; the
//! pbrt file's directives parse back to the scene's numbers.

use super::{Format, export};
use crate::scene_toml::parse_scene;
use chiaro_core::Vec3;
use chiaro_core::scene::{Geometry, Scene};
use std::path::{Path, PathBuf};

/// A fresh temporary directory for one test.
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("chiaro-export-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn toml(text: &str) -> Scene {
    parse_scene(text, Path::new("."), Path::new("t.toml"))
        .expect("test scene parses")
        .scene
}

/// A small box: a flat floor, an emissive one-sided quad, a smooth
/// sphere of each exact material, a point and a directional light.
pub(crate) const SCENE: &str = r#"
[render]
technique = "path"
width = 24
height = 16
samples = 4
[render.path]
max_depth = 5
rr_depth = 3
[camera]
eye = [0, 1, 4]
look_at = [0, 1, 3]
fov = 40
[material.white]
diffuse = [0.7, 0.6, 0.5]
[material.light]
diffuse = 0
emission = [4, 3, 2]
sidedness = "one-sided"
[material.mirror]
diffuse = 0
reflect = 1
[material.gold]
diffuse = 0
specular = 1
model = "torrance-sparrow"
roughness = 0.2
conductor = "Au"
[material.glass]
diffuse = 0
transmit = 1
ior = 1.5
fresnel = true
[[light]]
type = "point"
position = [0, 2, 0]
intensity = 2
[[light]]
type = "directional"
direction = [0, -1, 0.2]
intensity = 0.5
[[object]]
name = "floor"
primitive = "quad"
corner = [-2, 0, 2]
edge_u = [4, 0, 0]
edge_v = [0, 0, -4]
material = "white"
smooth = false
[[object]]
name = "lamp"
primitive = "quad"
corner = [-0.5, 2, -0.5]
edge_u = [1, 0, 0]
edge_v = [0, 0, 1]
material = "light"
smooth = false
[[object]]
primitive = "sphere"
radius = 0.3
material = "mirror"
transform = { translate = [-0.8, 0.3, 0] }
[[object]]
primitive = "sphere"
radius = 0.3
material = "gold"
transform = { translate = [0, 0.3, 0] }
[[object]]
primitive = "sphere"
radius = 0.3
material = "glass"
transform = { translate = [0.8, 0.3, 0] }
[[object]]
name = "block"
primitive = "box"
size = 0.4
material = "white"
smooth = false
transform = { translate = [0, 0.2, -1], rotate_y = 30 }
"#;

#[test]
fn refusals_name_the_object_and_feature_and_write_nothing() {
    let dir = tmp("refuse");
    let cases = [
        (
            "[material.m]\nspecular = 0.5\nmodel = \"phong\"\n",
            "materials[0] (\"m\")",
            "Phong",
        ),
        (
            "[material.m]\ndiffuse = 0\nspecular = 0.5\nmodel = \"torrance-sparrow\"\n",
            "materials[0] (\"m\")",
            "Schlick",
        ),
        (
            "[material.m]\n[[light]]\ntype = \"area\"\nshape = \"sphere\"\ncenter = [0, 3, 0]\nradius = 1\n",
            "lights[0] (area)",
            "emissive material",
        ),
        (
            "[material.m]\nsidedness = \"culled\"\n",
            "materials[0]",
            "culled",
        ),
    ];
    for (k, (extra, location, feature)) in cases.iter().enumerate() {
        let text = format!(
            "{extra}[[object]]\nname = \"ball\"\nprimitive = \"sphere\"\nmaterial = \"m\"\n[[light]]\ntype = \"point\"\nposition = [0, 4, 0]\n"
        );
        let scene = toml(&text);
        for format in [Format::Mitsuba, Format::Pbrt] {
            let out = dir.join(format!("case{k}.out"));
            let e = export(&scene, format, &out)
                .expect_err("refused")
                .to_string();
            assert!(
                e.contains(location) && e.contains(feature),
                "{k} {format:?}: {e}"
            );
            let left: Vec<_> = std::fs::read_dir(&dir).expect("dir").collect();
            assert!(left.is_empty(), "{k}: a refused export wrote {left:?}");
        }
    }
}

#[test]
fn mitsuba_export_reads_back_as_the_scene() {
    let dir = tmp("mitsuba");
    let scene = toml(SCENE);
    let out = dir.join("box.xml");
    let done = export(&scene, Format::Mitsuba, &out).expect("exports");
    // The quad (one mesh for the floor and the lamp, a file per material)
    // and the box as PLY files, the XML last.
    assert_eq!(done.files.len(), 4, "{:?}", done.files);
    assert_eq!(done.files.last(), Some(&out));
    assert!(done.warnings.is_empty(), "{:?}", done.warnings);
    let back = crate::mitsuba::load(&out, &crate::LoadOptions::default())
        .expect("chiaro reads its own export")
        .scene;
    let (a, b) = (&scene, &back);
    assert_eq!((b.render.width, b.render.height), (24, 16));
    assert_eq!(b.render.samples, 4);
    assert_eq!((b.render.path.max_depth, b.render.path.rr_depth), (5, 3));
    assert_eq!(b.camera.eye, a.camera.eye);
    assert!((b.camera.look_at - a.camera.look_at).length() < 1e-6);
    assert!((b.camera.up - a.camera.up).length() < 1e-6);
    assert!((b.camera.fov_y_degrees - a.camera.fov_y_degrees).abs() < 1e-4);
    assert_eq!(b.objects.len(), a.objects.len());
    for (oa, ob) in a.objects.iter().zip(&b.objects) {
        let (ma, mb) = (
            &a.materials[oa.material.index()],
            &b.materials[ob.material.index()],
        );
        let phys = |m: &chiaro_core::scene::Material| {
            (
                m.diffuse,
                m.specular,
                m.reflect,
                m.transmit,
                m.emission,
                m.conductor,
                m.fresnel,
                m.sidedness,
                m.emission_two_sided,
            )
        };
        assert_eq!(phys(ma), phys(mb), "{}", oa.name);
        if ma.specular != Vec3::ZERO {
            assert_eq!(
                (ma.roughness, ma.distribution),
                (mb.roughness, mb.distribution)
            );
        }
        if ma.fresnel {
            assert_eq!(ma.ior, mb.ior);
        }
        assert_eq!(oa.smooth, ob.smooth);
        match (oa.geometry, ob.geometry) {
            (Geometry::Sphere { radius: ra }, Geometry::Sphere { radius: rb }) => {
                assert_eq!(ra, rb);
                assert_eq!(
                    oa.transform.world_from_object(),
                    ob.transform.world_from_object()
                );
            }
            (Geometry::Mesh(ia), Geometry::Mesh(ib)) => {
                assert_eq!(
                    oa.transform.world_from_object(),
                    ob.transform.world_from_object()
                );
                let (ma, mb) = (&a.meshes[ia.index()], &b.meshes[ib.index()]);
                assert_eq!(ma.positions, mb.positions);
                assert_eq!(ma.indices, mb.indices);
            }
            other => panic!("{}: geometry {other:?}", oa.name),
        }
    }
    // The lights: inverse-square point and directional, within rounding
    // (Mitsuba's intensities carry chiaro's factor pi).
    assert_eq!(b.lights.len(), 2);
    for (la, lb) in a.lights.iter().zip(&b.lights) {
        let (pa, pb) = (la.power_rgb(), lb.power_rgb());
        assert!(
            (pa - pb).abs().max_element() < 1e-6 * pa.max_element(),
            "{la:?} {lb:?}"
        );
        assert_eq!(la.kind(), lb.kind());
    }
}

/// The reconstruction filter travels: Mitsuba's tent and Gaussian are
/// chiaro's exactly; pbrt's triangle (radius 1) and Gaussian (sigma 0.5,
/// radius 2) are too, except that pbrt's samples may leave the film (one
/// warning each way).
#[test]
fn the_pixel_filter_reads_back() {
    use chiaro_core::scene::PixelFilter;
    let dir = tmp("filters");
    for filter in [PixelFilter::Box, PixelFilter::Tent, PixelFilter::Gaussian] {
        let mut scene = toml(SCENE);
        scene.render.filter = filter;
        let out = dir.join(format!("{filter:?}.xml"));
        let done = export(&scene, Format::Mitsuba, &out).expect("exports");
        assert!(done.warnings.is_empty(), "{:?}", done.warnings);
        let back = crate::mitsuba::load(&out, &crate::LoadOptions::default()).expect("reads");
        assert_eq!(back.scene.render.filter, filter);
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        let out = dir.join(format!("{filter:?}.pbrt"));
        let done = export(&scene, Format::Pbrt, &out).expect("exports");
        let said = done
            .warnings
            .iter()
            .filter(|w| w.contains("filter"))
            .count();
        assert_eq!(
            said,
            usize::from(filter != PixelFilter::Box),
            "{:?}",
            done.warnings
        );
        let back = crate::pbrt::load(&out).expect("reads");
        assert_eq!(back.scene.render.filter, filter);
        let border = back
            .warnings
            .iter()
            .filter(|w| w.contains("border"))
            .count();
        assert_eq!(
            border,
            usize::from(filter != PixelFilter::Box),
            "{:?}",
            back.warnings
        );
    }
}

/// The numbers after `key` on the first line starting with `key`.
fn numbers_after(text: &str, key: &str) -> Vec<f32> {
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with(key))
        .unwrap_or_else(|| panic!("no {key} line"));
    line.trim_start()[key.len()..]
        .split(|c: char| c.is_whitespace() || c == '[' || c == ']')
        .filter_map(|t| t.parse::<f32>().ok())
        .collect()
}

#[test]
fn pbrt_export_parses_back_to_the_scene() {
    let dir = tmp("pbrt");
    let scene = toml(SCENE);
    let out = dir.join("box.pbrt");
    let done = export(&scene, Format::Pbrt, &out).expect("exports");
    assert_eq!(done.files, vec![out.clone()]);
    // The one-sided emitter is written two-sided, and says so.
    assert!(
        done.warnings.len() == 1 && done.warnings[0].contains("materials[1] (\"light\")"),
        "{:?}",
        done.warnings
    );
    let text = std::fs::read_to_string(&out).expect("written");
    let c = &scene.camera;
    let look = numbers_after(&text, "LookAt");
    assert_eq!(
        look,
        [c.eye.to_array(), c.look_at.to_array(), c.up.to_array()].concat()
    );
    assert!(text.contains("Scale -1 1 1\nLookAt"));
    // 24 x 16: pbrt's fov spans the shorter side, the vertical one.
    assert_eq!(numbers_after(&text, "Camera"), [c.fov_y_degrees]);
    assert_eq!(numbers_after(&text, "Sampler"), [4.0]);
    assert_eq!(numbers_after(&text, "Integrator"), [5.0]);
    assert_eq!(numbers_after(&text, "Film"), [24.0, 16.0]);
    // Every object, in order: three meshes and three spheres.
    let shapes: Vec<&str> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("Shape \""))
        .map(|l| l.split('"').next().unwrap_or_default())
        .collect();
    assert_eq!(
        shapes,
        [
            "trianglemesh",
            "trianglemesh",
            "sphere",
            "sphere",
            "sphere",
            "trianglemesh"
        ]
    );
    // The floor's positions and indices, through its transform.
    let floor = &scene.meshes[match scene.objects[0].geometry {
        Geometry::Mesh(m) => m.index(),
        Geometry::Sphere { .. } => unreachable!("the floor is a quad"),
    }];
    let p = numbers_after(&text, "\"point3 P\"");
    let want: Vec<f32> = floor.positions.iter().flat_map(|v| v.to_array()).collect();
    assert_eq!(p, want);
    let idx = numbers_after(&text, "\"integer indices\"");
    let want: Vec<f32> = floor.indices.iter().flatten().map(|&i| i as f32).collect();
    assert_eq!(idx, want);
    let t = numbers_after(&text, "Transform");
    assert_eq!(
        t,
        scene.objects[0]
            .transform
            .world_from_object()
            .to_cols_array()
    );
    // Lights: pi times chiaro's intensity (irradiance pi I cos / d^2).
    let point = numbers_after(&text, "LightSource \"point\"");
    assert_eq!(&point[..3], &[0.0, 2.0, 0.0]);
    assert!(
        (point[3] - std::f32::consts::PI * 2.0).abs() < 1e-5,
        "{point:?}"
    );
    // Materials: the conductor's complex IOR, the dielectric's eta, the
    // emitter's radiance before its shape.
    assert!(
        text.contains(
            "\"string type\" [ \"conductor\" ] \"rgb eta\" [ 0.143119 0.374957 1.442479 ]"
        ),
        "{text}"
    );
    assert!(text.contains("\"string type\" [ \"dielectric\" ] \"float eta\" [ 1.5 ]"));
    let area = text
        .find("AreaLightSource \"diffuse\" \"rgb L\" [ 4 3 2 ]")
        .expect("emitter");
    assert!(text[area..].contains("Shape \"trianglemesh\""));
    assert_eq!(text.matches("AttributeBegin").count(), 6);
    assert_eq!(text.matches("AttributeEnd").count(), 6);
}

/// An orthographic camera goes out as Mitsuba's `orthographic` sensor
/// (its film scaled by `to_world`) and pbrt's `Camera "orthographic"`
/// (its screen window), and each reads back to the same camera.
#[test]
fn orthographic_camera_round_trips_through_both_formats() {
    let dir = tmp("ortho");
    let text = SCENE.replace(
        "fov = 40",
        "projection = \"orthographic\"\nhalf_height = 1.25",
    );
    let scene = toml(&text);
    let want = chiaro_core::scene::Projection::Orthographic { half_height: 1.25 };
    assert_eq!(scene.camera.projection, want);
    let half = |c: &chiaro_core::scene::Camera| c.orthographic_half_height().expect("orthographic");
    let out = dir.join("box.xml");
    export(&scene, Format::Mitsuba, &out).expect("exports");
    let back = crate::mitsuba::load(&out, &crate::LoadOptions::default()).expect("reads back");
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    let c = back.scene.camera;
    assert!((half(&c) - 1.25).abs() < 1e-5, "{c:?}");
    assert_eq!(c.eye, scene.camera.eye);
    assert!((c.look_at - scene.camera.look_at).length() < 1e-6);
    assert_eq!((c.near, c.far), (scene.camera.near, scene.camera.far));
    let out = dir.join("box.pbrt");
    export(&scene, Format::Pbrt, &out).expect("exports");
    let written = std::fs::read_to_string(&out).expect("written");
    // 24 x 16: the screen window is the film, 1.5 times wider than high.
    assert_eq!(
        numbers_after(&written, "Camera"),
        [-1.875, 1.875, -1.25, 1.25]
    );
    let back = crate::pbrt::load(&out).expect("reads back");
    let c = back.scene.camera;
    assert!((half(&c) - 1.25).abs() < 1e-5, "{c:?}");
    assert!((c.eye - scene.camera.eye).length() < 1e-6);
    assert!((c.look_at - scene.camera.look_at).length() < 1e-5);
}
