//! pbrt-v4 and pbrt-v3 scenes: the tokenizer's and parser's errors (file,
//! line, column), the transform stack, named materials, object instancing,
//! `Include`, the mapping of lights and materials, and hostile input (an
//! error or a scene, never a panic).

use chiaro_core::scene::{
    Distribution, Geometry, Light, PixelFilter, ReflectanceModel, Scene, Sidedness, Technique,
};
use chiaro_core::{Mat4, Vec3};
use chiaro_io::Loaded;
use chiaro_io::pbrt::load_str;
use std::f32::consts::PI;
use std::path::{Path, PathBuf};

/// A camera, film and sampler that render: 32 x 16, 8 samples. The
/// `Scale -1 1 1` keeps the world unmirrored (pbrt's LookAt is left-handed).
const HEAD: &str = r#"Scale -1 1 1
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" 60
Film "rgb" "integer xresolution" 32 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 8
"#;

fn scene(body: &str) -> String {
    format!("{HEAD}WorldBegin\n{body}\n")
}

fn load(text: &str) -> chiaro_io::Result<Loaded> {
    load_str(text, Path::new("."), "t.pbrt")
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&d).expect("test input");
    d
}

/// The world-space position of vertex `v` of the scene's object `o`.
fn vertex(s: &Scene, o: usize, v: usize) -> Vec3 {
    let obj = &s.objects[o];
    let Geometry::Mesh(id) = obj.geometry else {
        panic!("a mesh")
    };
    obj.transform
        .world_from_object()
        .transform_point3(s.meshes[id.index()].positions[v])
}

const TRIANGLE: &str =
    r#"Shape "trianglemesh" "point3 P" [0 0 0  1 0 0  0 1 0] "integer indices" [0 1 2]"#;

#[test]
fn settings_camera_and_defaults() {
    let s = load(&scene("")).expect("test input").scene;
    assert_eq!(
        (s.render.width, s.render.height, s.render.samples),
        (32, 16, 8)
    );
    assert_eq!(s.render.technique, Technique::Path);
    assert_eq!(s.render.path.max_depth, 5, "pbrt's default maxdepth");
    assert!((s.camera.eye - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-6);
    assert!((s.camera.look_at - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    // Landscape: the fov is vertical.
    assert!((s.camera.fov_y_degrees - 60.0).abs() < 1e-4);
    // Portrait: the fov spans the (shorter) width.
    let text = "Scale -1 1 1\nLookAt 0 0 5 0 0 0 0 1 0\nCamera \"perspective\" \"float fov\" 60\nFilm \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 32\nIntegrator \"path\" \"integer maxdepth\" 3\nPixelFilter \"box\"\nWorldBegin\n";
    let s = load(text).expect("test input").scene;
    let expect = 2.0 * ((30f32.to_radians()).tan() * 2.0).atan().to_degrees();
    assert!(
        (s.camera.fov_y_degrees - expect).abs() < 1e-3,
        "{}",
        s.camera.fov_y_degrees
    );
    assert_eq!(s.render.path.max_depth, 3);
    assert_eq!(s.render.filter, PixelFilter::Box);
}

/// pbrt's orthographic screen window spans [-1, 1] along the shorter
/// image axis by default, in camera space units; `screenwindow` sets it.
#[test]
fn orthographic_camera_screen_window() {
    let ortho = |film: &str, extra: &str| {
        format!(
            "Scale -1 1 1\nLookAt 0 0 5 0 0 0 0 1 0\nCamera \"orthographic\" {extra}\n{film}\nPixelFilter \"box\"\nWorldBegin\n"
        )
    };
    let wide = "Film \"rgb\" \"integer xresolution\" 32 \"integer yresolution\" 16";
    let tall = "Film \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 32";
    let half = |text: &str| {
        let l = load(text).expect("test input");
        (l.scene.camera.orthographic_half_height(), l.warnings)
    };
    assert_eq!(half(&ortho(wide, "")).0, Some(1.0));
    // Portrait: the width spans [-1, 1], the height twice that.
    assert_eq!(half(&ortho(tall, "")).0, Some(2.0));
    let (h, w) = half(&ortho(wide, "\"float screenwindow\" [-4 4 -2 2]"));
    assert_eq!(h, Some(2.0));
    assert!(w.is_empty(), "{w:?}");
    // A window off the axis or of another aspect: approximate, said once.
    let (h, w) = half(&ortho(wide, "\"float screenwindow\" [-1 3 -1 1]"));
    assert_eq!(h, Some(1.0));
    assert!(w.iter().any(|w| w.contains("screenwindow")), "{w:?}");
    let s = load(&ortho(wide, "")).expect("test input").scene;
    assert!((s.camera.eye - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-6);
    assert!((s.camera.look_at - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
}

#[test]
fn transform_stack_and_named_coordinate_systems() {
    let body = format!(
        r#"AttributeBegin
  Translate 1 2 3
  {TRIANGLE}
  AttributeBegin
    Scale 2 2 2
    CoordinateSystem "doubled"
    {TRIANGLE}
  AttributeEnd
  Rotate 90 0 0 1
  {TRIANGLE}
AttributeEnd
{TRIANGLE}
TransformBegin
  ConcatTransform [1 0 0 0  0 1 0 0  0 0 1 0  5 0 0 1]
  {TRIANGLE}
TransformEnd
Transform [1 0 0 0  0 1 0 0  0 0 1 0  0 7 0 1]
CoordSysTransform "doubled"
{TRIANGLE}
Identity
{TRIANGLE}"#
    );
    let s = load(&scene(&body)).expect("test input").scene;
    let x = |o: usize, v: usize| vertex(&s, o, v);
    let near = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    assert!(near(x(0, 1), Vec3::new(2.0, 2.0, 3.0)), "{}", x(0, 1));
    assert!(near(x(1, 1), Vec3::new(3.0, 2.0, 3.0)), "{}", x(1, 1));
    // Rotate applies to the object before the translation: +x turns to +y.
    assert!(near(x(2, 1), Vec3::new(1.0, 3.0, 3.0)), "{}", x(2, 1));
    assert!(
        near(x(3, 1), Vec3::new(1.0, 0.0, 0.0)),
        "the attribute restored the transform"
    );
    // pbrt's matrices are written column by column: translation last.
    assert!(near(x(4, 1), Vec3::new(6.0, 0.0, 0.0)), "{}", x(4, 1));
    // CoordSysTransform replaced the transform by the saved one.
    assert!(near(x(5, 1), Vec3::new(3.0, 2.0, 3.0)), "{}", x(5, 1));
    assert!(near(x(6, 1), Vec3::new(1.0, 0.0, 0.0)));
}

#[test]
fn look_at_is_pbrts() {
    // pbrt's LookAt: camera +x = up x dir, a left-handed frame.
    let m =
        chiaro_io::pbrt::look_at(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO, Vec3::Y).expect("frame");
    let world_from_camera = m.inverse();
    assert!((world_from_camera.transform_vector3(Vec3::X) - Vec3::X).length() < 1e-6);
    assert!(
        (world_from_camera.transform_point3(Vec3::ZERO) - Vec3::new(0.0, 0.0, -5.0)).length()
            < 1e-6
    );
    assert!(chiaro_io::pbrt::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y).is_none());
}

#[test]
fn a_plain_look_at_mirrors_the_world_not_the_camera() {
    // No `Scale -1 1 1`: pbrt shows world +x on the right; chiaro's camera
    // (right = forward x up = -x here) sees the mirrored world the same way.
    let text = format!(
        "LookAt 0 0 -5  0 0 0  0 1 0\nCamera \"perspective\"\nWorldBegin\nTranslate 2 0 0\n{TRIANGLE}\nLightSource \"point\" \"point3 from\" [3 0 0]\n"
    );
    let s = load(&text).expect("test input").scene;
    let right = s.camera.frame().right;
    let p = vertex(&s, 0, 0);
    assert!(
        p.dot(right) > 1.9,
        "the object at pbrt's +x is on the image's right: {p} {right}"
    );
    let Light::Point { position, .. } = s.lights[0] else {
        panic!("a point light")
    };
    assert!(position.dot(right) > 2.9, "{position}");
    // The mirrored triangle keeps its front: the transform's determinant
    // is negative, which chiaro's preparation turns back.
    assert!(s.objects[0].transform.world_from_object().determinant() < 0.0);
}

#[test]
fn named_materials_textures_and_v3_names() {
    let body = r#"MakeNamedMaterial "red" "string type" "diffuse" "rgb reflectance" [0.8 0.1 0.1]
MakeNamedMaterial "gold" "string type" "conductor" "spectrum eta" "metal-Au-eta" "spectrum k" "metal-Au-k"
Texture "checks" "spectrum" "checkerboard" "float uscale" 4 "float vscale" 4 "rgb tex1" [1 1 1] "rgb tex2" [0 0 0]
NamedMaterial "red"
Shape "sphere"
NamedMaterial "gold"
Shape "sphere"
Material "diffuse" "texture reflectance" "checks"
Shape "sphere"
Material "matte" "color Kd" [0.2 0.3 0.4]
Shape "sphere"
Material "glass" "float index" 1.33
Shape "sphere"
Material "dielectric" "spectrum eta" "glass-BK7"
Shape "sphere"
Material "mirror"
Shape "sphere""#;
    let loaded = load(&scene(body)).expect("test input");
    let s = &loaded.scene;
    let mat = |o: usize| &s.materials[s.objects[o].material.index()];
    assert_eq!(mat(0).name, "red");
    assert_eq!(mat(0).diffuse, Vec3::new(0.8, 0.1, 0.1));
    assert_eq!(mat(0).sidedness, Sidedness::TwoSided);
    // Gold: a mirror with the Fresnel of its complex IOR (pbrt's named
    // spectra reduced to RGB), yellow at normal incidence.
    let gold = mat(1);
    let ior = gold.conductor.expect("complex IOR");
    let f = chiaro_core::shading::fresnel_conductor(1.0, ior.eta, ior.k);
    assert!(
        f.x > f.z && gold.reflect == Vec3::ONE && gold.diffuse == Vec3::ZERO,
        "{gold:?}"
    );
    assert!(mat(2).texture.is_some());
    assert_eq!(mat(3).diffuse, Vec3::new(0.2, 0.3, 0.4));
    assert!(mat(4).fresnel && (mat(4).ior - 1.33).abs() < 1e-6);
    assert!((mat(5).ior - 1.5168).abs() < 1e-4);
    assert_eq!(mat(6).reflect, Vec3::splat(0.9));
    // The conductor is exact (no warning); the named glass says it is
    // approximate, naming the file, line and column of its directive.
    let w = loaded.warnings.join("\n");
    assert!(!w.contains("t.pbrt:8:1"), "{w}");
    assert!(
        w.contains("t.pbrt:20:1: Material \"dielectric\"") && w.contains("d-line"),
        "{w}"
    );
    // Undefined names are errors where they are used.
    let e = load(&scene("NamedMaterial \"nothing\""))
        .expect_err("undefined")
        .to_string();
    assert!(e.contains("t.pbrt:7:15") && e.contains("nothing"), "{e}");
}

/// Conductors get `Material::conductor`: explicit RGB eta and k, pbrt-v4's
/// `reflectance` as eta 1 and k = 2 sqrt(r) / sqrt(1 - r) (whose Fresnel at
/// normal incidence is r), and pbrt-v3's rough `metal` (copper by default)
/// on the GGX lobe; rough dielectrics on the rough dielectric lobe.
#[test]
fn conductors_take_their_complex_ior() {
    let body = r#"Material "conductor" "rgb eta" [0.2 0.9 1.1] "rgb k" [3.9 2.4 2.2]
Shape "sphere"
Material "conductor" "rgb reflectance" [0.9 0.5 0.25] "float roughness" 0.04
Shape "sphere"
Material "metal" "float roughness" 0.1
Shape "sphere"
Material "dielectric" "float eta" 1.5 "float roughness" 0.09
Shape "sphere""#;
    let loaded = load(&scene(body)).expect("test input");
    let s = &loaded.scene;
    let mat = |o: usize| &s.materials[s.objects[o].material.index()];
    let ior = mat(0).conductor.expect("complex IOR");
    assert_eq!(
        (ior.eta, ior.k),
        (Vec3::new(0.2, 0.9, 1.1), Vec3::new(3.9, 2.4, 2.2))
    );
    assert_eq!(mat(0).reflect, Vec3::ONE);
    let ior = mat(1).conductor.expect("complex IOR");
    let f = chiaro_core::shading::fresnel_conductor(1.0, ior.eta, ior.k);
    assert!(
        (f - Vec3::new(0.9, 0.5, 0.25)).abs().max_element() < 1e-5,
        "{f}"
    );
    assert_eq!(mat(1).model, ReflectanceModel::TorranceSparrow);
    assert_eq!(mat(1).distribution, Distribution::Ggx);
    // pbrt-v4 remaps roughness to alpha = sqrt(roughness).
    assert!((mat(1).roughness - 0.2).abs() < 1e-6);
    assert_eq!(mat(1).specular, Vec3::ONE);
    let copper = mat(2).conductor.expect("complex IOR");
    assert!(copper.k.x > copper.k.z, "{copper:?}");
    assert_eq!(mat(2).model, ReflectanceModel::TorranceSparrow);
    let glass = mat(3);
    assert!(glass.fresnel && glass.model == ReflectanceModel::TorranceSparrow);
    assert!((glass.roughness - 0.3).abs() < 1e-6 && glass.distribution == Distribution::Ggx);
    let w = loaded.warnings.join("\n");
    assert!(
        !w.contains("conductor") && !w.contains("metal") && !w.contains("dielectric"),
        "{w}"
    );
}

#[test]
fn mix_of_two_diffuse_materials_is_their_blend() {
    let body = r#"MakeNamedMaterial "a" "string type" "diffuse" "rgb reflectance" [1 0 0]
MakeNamedMaterial "b" "string type" "diffuse" "rgb reflectance" [0 0 1]
Material "mix" "string materials" ["a" "b"] "float amount" 0.25
Shape "sphere"
LightSource "point" "rgb I" [1 1 1] "point3 from" [0 3 0]"#;
    let loaded = load(&scene(body)).expect("test input");
    let m = &loaded.scene.materials[loaded.scene.objects[0].material.index()];
    assert!(
        (m.diffuse - Vec3::new(0.75, 0.0, 0.25)).length() < 1e-6,
        "{m:?}"
    );
    assert!(
        !loaded.warnings.iter().any(|w| w.contains("mix")),
        "{:?}",
        loaded.warnings
    );
    // No PixelFilter: pbrt's Gaussian, said once at the Film.
    assert_eq!(loaded.scene.render.filter, PixelFilter::Tent);
    assert!(
        loaded
            .warnings
            .iter()
            .any(|w| w.starts_with("t.pbrt:4:1: Film \"rgb\": approximate")
                && w.contains("Gaussian")),
        "{:?}",
        loaded.warnings
    );
}

#[test]
fn object_instances_share_meshes() {
    let body = format!(
        r#"ObjectBegin "tri"
  Translate 0 0 1
  {TRIANGLE}
  Shape "sphere" "float radius" 0.5
ObjectEnd
AttributeBegin
  Translate 10 0 0
  ObjectInstance "tri"
AttributeEnd
AttributeBegin
  Translate 20 0 0
  Scale 2 2 2
  ObjectInstance "tri"
AttributeEnd"#
    );
    let s = load(&scene(&body)).expect("test input").scene;
    assert_eq!(s.objects.len(), 4, "only the instances are drawn");
    assert_eq!(s.meshes.len(), 1, "one mesh shared by both instances");
    let near = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    assert!(
        near(vertex(&s, 0, 1), Vec3::new(11.0, 0.0, 1.0)),
        "{}",
        vertex(&s, 0, 1)
    );
    assert!(
        near(vertex(&s, 2, 1), Vec3::new(22.0, 0.0, 2.0)),
        "{}",
        vertex(&s, 2, 1)
    );
    let Geometry::Sphere { radius } = s.objects[3].geometry else {
        panic!("a sphere")
    };
    assert!((radius - 1.0).abs() < 1e-6);
    let c = s.objects[3]
        .transform
        .world_from_object()
        .transform_point3(Vec3::ZERO);
    assert!(near(c, Vec3::new(20.0, 0.0, 2.0)), "{c}");
    let e = load(&scene("ObjectInstance \"none\""))
        .expect_err("undefined")
        .to_string();
    assert!(e.contains("t.pbrt:7:16"), "{e}");
}

#[test]
fn include_splices_and_refuses_itself() {
    let dir = tmp_dir("pbrt-include");
    std::fs::create_dir_all(dir.join("parts")).expect("test input");
    std::fs::write(
        dir.join("parts/geometry.pbrt"),
        format!("Material \"diffuse\" \"rgb reflectance\" [0.1 0.2 0.3]\n{TRIANGLE}\n"),
    )
    .expect("test input");
    std::fs::write(
        dir.join("main.pbrt"),
        scene("Include \"parts/geometry.pbrt\"\nImport \"parts/geometry.pbrt\""),
    )
    .expect("test input");
    let loaded = chiaro_io::load_scene(&dir.join("main.pbrt")).expect("test input");
    assert_eq!(loaded.scene.objects.len(), 2);
    std::fs::write(
        dir.join("self.pbrt"),
        "WorldBegin\n  Include \"self.pbrt\"\n",
    )
    .expect("test input");
    let e = chiaro_io::load_scene(&dir.join("self.pbrt"))
        .expect_err("self")
        .to_string();
    assert!(
        e.contains("self.pbrt:2:11") && e.contains("includes itself"),
        "{e}"
    );
    // An error inside an included file names that file.
    std::fs::write(dir.join("bad.pbrt"), "\n\n   Shape \"teapot\"\n").expect("test input");
    std::fs::write(dir.join("outer.pbrt"), "WorldBegin\nInclude \"bad.pbrt\"\n")
        .expect("test input");
    let e = chiaro_io::load_scene(&dir.join("outer.pbrt"))
        .expect_err("bad")
        .to_string();
    assert!(e.contains("bad.pbrt:3:10") && e.contains("teapot"), "{e}");
}

#[test]
fn lights_in_chiaros_units() {
    let body = r#"LightSource "point" "rgb I" [2 4 6] "point3 from" [0 1 0]
LightSource "distant" "point3 from" [0 1 0] "point3 to" [0 0 0] "blackbody L" 6500 "float scale" 2
LightSource "spot" "rgb I" [1 1 1] "float coneangle" 20 "float conedelta" 4
LightSource "infinite" "rgb L" [0.5 0.5 0.5]
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [3 2 1] "bool twosided" true
  Shape "sphere"
AttributeEnd
Shape "sphere""#;
    let loaded = load(&scene(body)).expect("test input");
    let s = &loaded.scene;
    let Light::Point {
        position,
        color,
        intensity,
        ..
    } = &s.lights[0]
    else {
        panic!("a point light")
    };
    assert!((*position - Vec3::Y).length() < 1e-6);
    // Irradiance pi * intensity * color / d^2 = I / d^2.
    assert!((*color * *intensity * PI - Vec3::new(2.0, 4.0, 6.0)).length() < 1e-5);
    let Light::Directional {
        direction, color, ..
    } = &s.lights[1]
    else {
        panic!("a directional light")
    };
    assert!((*direction - Vec3::NEG_Y).length() < 1e-6);
    let lum = 0.2126 * color.x + 0.7152 * color.y + 0.0722 * color.z;
    assert!((lum - 2.0).abs() < 0.05, "{color}");
    let Light::Spot(spot) = &s.lights[2] else {
        panic!("a spot light")
    };
    assert_eq!((spot.cone_degrees, spot.cone_softness_degrees), (20.0, 4.0));
    let env = s.environment.as_ref().expect("environment");
    assert!((env.intensity - 0.5).abs() < 1e-6 && env.as_background);
    let emitter = &s.materials[s.objects[0].material.index()];
    assert_eq!(emitter.emission, Vec3::new(3.0, 2.0, 1.0));
    assert!(emitter.emission_two_sided);
    let plain = &s.materials[s.objects[1].material.index()];
    assert_eq!(
        plain.emission,
        Vec3::ZERO,
        "AttributeEnd ends the area light"
    );
    assert!(
        loaded
            .warnings
            .iter()
            .any(|w| w.starts_with("t.pbrt:9:1: LightSource \"spot\"")),
        "{:?}",
        loaded.warnings
    );
}

#[test]
fn reverse_orientation_and_normals_set_the_front() {
    let body = format!(
        r#"AttributeBegin
  ReverseOrientation
  {TRIANGLE}
AttributeEnd
{TRIANGLE}
Shape "trianglemesh" "point3 P" [0 0 0  1 0 0  0 1 0] "integer indices" [0 1 2] "normal N" [0 0 -1  0 0 -1  0 0 -1]"#
    );
    let s = load(&scene(&body)).expect("test input").scene;
    let front = |o: usize| {
        let Geometry::Mesh(id) = s.objects[o].geometry else {
            panic!("a mesh")
        };
        let m = &s.meshes[id.index()];
        let [a, b, c] = m.indices[0].map(|i| m.positions[i as usize]);
        (b - a).cross(c - a).z.signum()
    };
    assert_eq!((front(0), front(1), front(2)), (-1.0, 1.0, -1.0));
}

#[test]
fn pbrt_v3_infinite_light_is_resampled() {
    let dir = tmp_dir("pbrt-env");
    // A 4 x 2 lat-long map: its top row (+z in pbrt-v3's light space) bright.
    let mut img = image::Rgb32FImage::new(4, 2);
    for x in 0..4 {
        img.put_pixel(x, 0, image::Rgb([4.0, 4.0, 4.0]));
        img.put_pixel(x, 1, image::Rgb([1.0, 1.0, 1.0]));
    }
    let path = dir.join("sky.hdr");
    image::DynamicImage::ImageRgb32F(img)
        .save(&path)
        .expect("test input");
    // Rotate -90 about x turns pbrt's +z (the map's top) to +y.
    let body = "AttributeBegin\nRotate -90 1 0 0\nLightSource \"infinite\" \"string mapname\" \"sky.hdr\"\nAttributeEnd\n";
    let s = load_str(&scene(body), &dir, "t.pbrt")
        .expect("test input")
        .scene;
    let env = s.environment.as_ref().expect("environment");
    let chiaro_core::scene::Texture::Image(t) = &s.textures[env.texture.index()] else {
        panic!("an image")
    };
    // chiaro's map: row 0 is +y (up).
    let top = t.texel(0, 0)[0];
    let bottom = t.texel(0, t.height - 1)[0];
    assert!(top > 3.0 && bottom < 1.5, "{top} {bottom}");
    let _ = Mat4::IDENTITY;
}

/// Broken files: each an error at `t.pbrt:LINE:COL`.
#[test]
fn broken_files_name_line_and_column() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "WorldBegin\n  Frobnicate",
            "t.pbrt:2:3",
            "unknown directive",
        ),
        (
            "WorldBegin\nShape \"sphere\" \"float radius\" [ 1",
            "t.pbrt:",
            "end of the file",
        ),
        (
            "WorldBegin\nShape \"sphere\" \"float radius\" \"big\"",
            "t.pbrt:2:31",
            "number",
        ),
        (
            "WorldBegin\nShape \"sphere\" \"floot radius\" 1",
            "t.pbrt:2:16",
            "unknown parameter type",
        ),
        (
            "WorldBegin\nShape \"sphere\" \"float radius\" -1",
            "t.pbrt:2:16",
            "positive",
        ),
        ("LookAt 0 0 0 0 0 0 0 1 0", "t.pbrt:1:1", "LookAt"),
        ("Translate 1 2", "t.pbrt:1:", "end of the file"),
        (
            "WorldBegin\nAttributeEnd",
            "t.pbrt:2:1",
            "without a matching",
        ),
        ("\"sphere\"", "t.pbrt:1:1", "expected a directive"),
        (
            "Camera \"spherical\"",
            "t.pbrt:1:8",
            "perspective and orthographic",
        ),
        (
            "Camera \"orthographic\" \"float screenwindow\" [1 -1 0 1]",
            "t.pbrt:1:",
            "screenwindow",
        ),
        (
            "WorldBegin\nShape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 3]",
            "t.pbrt:2:",
            "out of range",
        ),
        (
            "WorldBegin\nMaterial \"plasma\"\nShape \"sphere\"",
            "t.pbrt:2:1",
            "unknown material",
        ),
        (
            "WorldBegin\nTexture \"t\" \"spectrum\" \"wrinkled\"",
            "t.pbrt:2:",
            "refused",
        ),
        (
            "WorldBegin\nShape \"sphere\" \"float radius\" 1e999",
            "t.pbrt:2:31",
            "out of range",
        ),
        (
            "Film \"rgb\" \"integer xresolution\" 0",
            "t.pbrt:1:12",
            "positive",
        ),
    ];
    for (text, at, what) in cases {
        let e = load(text).expect_err(text).to_string();
        assert!(e.contains(at) && e.contains(what), "{text:?}: {e}");
    }
}

/// Hostile input: every prefix of a full scene and deterministic byte
/// mutations of it load or fail with an error, never a panic.
#[test]
fn hostile_input_never_panics() {
    let full = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.pbrt"),
    )
    .expect("the shipped box");
    let extra = "\nAttributeBegin\nObjectBegin \"o\"\nShape \"sphere\"\nObjectEnd\nObjectInstance \"o\"\nTexture \"c\" \"spectrum\" \"checkerboard\"\nMaterial \"mix\" \"string materials\" [\"a\" \"b\"]\nLightSource \"infinite\"\nShape \"bilinearmesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0 1 1 0]\nAttributeEnd\n";
    let text = format!("{full}{extra}");
    let bytes = text.as_bytes();
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let run = |b: &[u8]| {
        if let Ok(t) = std::str::from_utf8(b) {
            let _ = load_str(t, Path::new("/nonexistent"), "t.pbrt");
        }
    };
    for cut in (0..bytes.len()).step_by(97) {
        run(&bytes[..cut]);
    }
    let alphabet = b"[]\"# 0-1e9.xAttributeEndObjectBeginShape";
    for _ in 0..3000 {
        let mut b = bytes.to_vec();
        for _ in 0..(1 + next() % 8) {
            let i = (next() as usize) % b.len();
            match next() % 3 {
                0 => b[i] = alphabet[(next() as usize) % alphabet.len()],
                1 => {
                    b.remove(i);
                }
                _ => b.insert(i, alphabet[(next() as usize) % alphabet.len()]),
            }
        }
        run(&b);
    }
}

#[test]
fn plymesh_is_read_once_and_instanced() {
    let dir = tmp_dir("pbrt-ply");
    std::fs::write(
        dir.join("tri.ply"),
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )
    .expect("test input");
    let body = r#"ObjectBegin "p"
  Shape "plymesh" "string filename" "tri.ply"
ObjectEnd
Translate 3 0 0
ObjectInstance "p"
Translate 3 0 0
ObjectInstance "p"
Shape "plymesh" "string filename" "tri.ply""#;
    let s = load_str(&scene(body), &dir, "t.pbrt")
        .expect("test input")
        .scene;
    assert_eq!(s.objects.len(), 3);
    assert_eq!(s.meshes.len(), 1, "one copy of the file's mesh");
    let near = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    assert!(
        near(vertex(&s, 0, 1), Vec3::new(4.0, 0.0, 0.0)),
        "{}",
        vertex(&s, 0, 1)
    );
    assert!(
        near(vertex(&s, 1, 1), Vec3::new(7.0, 0.0, 0.0)),
        "{}",
        vertex(&s, 1, 1)
    );
    assert!(
        near(vertex(&s, 2, 1), Vec3::new(7.0, 0.0, 0.0)),
        "{}",
        vertex(&s, 2, 1)
    );
    assert!(!s.objects[0].smooth, "no normals: flat, as pbrt");
    let e = load_str(
        &scene("Shape \"plymesh\" \"string filename\" \"missing.ply\""),
        &dir,
        "t.pbrt",
    )
    .expect_err("missing")
    .to_string();
    assert!(e.contains("t.pbrt:7:1") && e.contains("missing.ply"), "{e}");
}

#[test]
fn pbrt_v4_equal_area_map_is_resampled() {
    let dir = tmp_dir("pbrt-env-v4");
    // An 8 x 8 equal-area map, bright only at its centre (light-space +z).
    let mut img = image::Rgb32FImage::new(8, 8);
    for (x, y, p) in img.enumerate_pixels_mut() {
        let centre = (3..=4).contains(&x) && (3..=4).contains(&y);
        *p = image::Rgb(if centre { [8.0; 3] } else { [0.5; 3] });
    }
    image::DynamicImage::ImageRgb32F(img)
        .save(dir.join("sky.hdr"))
        .expect("test input");
    // Rotate -90 about x: light-space +z is world +y.
    let body = "AttributeBegin\nRotate -90 1 0 0\nLightSource \"infinite\" \"string filename\" \"sky.hdr\" \"float scale\" 2\nAttributeEnd\n";
    let loaded = load_str(&scene(body), &dir, "t.pbrt").expect("test input");
    let s = &loaded.scene;
    let env = s.environment.as_ref().expect("environment");
    assert!((env.intensity - 2.0).abs() < 1e-6);
    let chiaro_core::scene::Texture::Image(t) = &s.textures[env.texture.index()] else {
        panic!("an image")
    };
    assert_eq!((t.width, t.height), (16, 8));
    assert!(t.texel(5, 0)[0] > 4.0, "up is bright: {:?}", t.texel(5, 0));
    assert!(
        (t.texel(5, t.height - 1)[0] - 0.5).abs() < 1e-3,
        "down is not"
    );
    assert!(
        loaded.warnings.iter().any(|w| w.contains("equal-area")),
        "{:?}",
        loaded.warnings
    );
}
