//! Tests of the glTF import: conversions, warnings, and errors for malformed or
//! unsupported files.

use super::buffers::{check_uri, decode_base64};
use super::*;
use chiaro_core::Vec3;
use chiaro_core::scene::Light;

/// A triangle, a perspective camera, a point and a spot light, a
/// metallic material, all in one embedded file.
const SCENE: &str = r#"{
      "asset": {"version": "2.0"},
      "extensionsUsed": ["KHR_lights_punctual"],
      "extensions": {"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 3.14159265, "color": [1, 0.5, 0.25]},
        {"type": "spot", "intensity": 6.2831853,
         "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}}
      ]}},
      "scene": 0,
      "scenes": [{"nodes": [0, 1, 2, 3]}],
      "nodes": [
        {"mesh": 0, "translation": [0, 0, -2]},
        {"camera": 0, "translation": [0, 0, 3]},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 4, 0]},
        {"extensions": {"KHR_lights_punctual": {"light": 1}},
         "rotation": [-0.7071068, 0, 0, 0.7071068], "translation": [0, 5, 0]}
      ],
      "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0, 1],
        "metallicFactor": 1.0, "roughnessFactor": 0.5}, "doubleSided": true}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
    }"#;

/// Each unsupported feature is one warning naming the file and the JSON
/// pointer of its first occurrence, with the count of the others.
#[test]
fn unsupported_features_are_one_warning_each_with_a_json_pointer() {
    let json: serde_json::Value = serde_json::from_str(
        r#"{
              "extensionsUsed": ["KHR_materials_anisotropy", "KHR_texture_transform", "EXT_foo"],
              "scene": 1,
              "scenes": [{"nodes": []}, {"nodes": [0]}],
              "nodes": [{"mesh": 0, "skin": 0, "weights": [0.5]}],
              "skins": [{"joints": [0]}],
              "animations": [{"channels": [], "samplers": []}],
              "cameras": [{"type": "orthographic"}],
              "materials": [
                {"name": "a"},
                {"extensions": {"KHR_materials_anisotropy": {}}},
                {"extensions": {"KHR_materials_anisotropy": {}, "KHR_materials_sheen": {}},
                 "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                   "metallicRoughnessTexture": {"index": 0, "texCoord": 1}}}
              ],
              "meshes": [{"primitives": [{"attributes": {}, "targets": [{}]},
                                         {"attributes": {}, "targets": [{}]}]}],
              "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "range": 2}]}}
            }"#,
    )
    .expect("json");
    let w = unsupported_features(&json, Path::new("m.gltf"));
    let has = |s: &str| w.iter().filter(|x| x.contains(s)).count();
    for expected in [
        "m.gltf: extension KHR_materials_anisotropy is not supported and is ignored: \
             at /materials/1/extensions/KHR_materials_anisotropy (and 2 more)",
        "m.gltf: extension KHR_materials_sheen is not supported and is ignored: \
             at /materials/2/extensions/KHR_materials_sheen",
        "m.gltf: extension EXT_foo is not supported and is ignored: at /extensionsUsed/2",
        "m.gltf: animations are ignored: at /animations/0",
        "m.gltf: morph targets are ignored (the base shape is loaded): \
             at /meshes/0/primitives/0/targets (and 2 more)",
        "m.gltf: light `range` is ignored (inverse-square fall-off everywhere): \
             at /extensions/KHR_lights_punctual/lights/0/range",
        "m.gltf: scenes other than the default one are not loaded: at /scenes/0",
    ] {
        assert_eq!(has(expected), 1, "{expected} in {w:#?}");
    }
    // Supported extensions are not warned about; nothing else is.
    assert_eq!(has("KHR_texture_transform"), 0, "{w:#?}");
    // Skins are posed and two texCoord sets are read: neither is warned about.
    assert_eq!(has("skin") + has("texCoord"), 0, "{w:#?}");
    assert_eq!(w.len(), 7, "{w:#?}");
    // Orthographic cameras are read (`nodes.rs`), not warned about.
    assert_eq!(has("orthographic"), 0, "{w:#?}");
}

/// Through the loader: the warning reaches `Imported::warnings` once.
#[test]
fn an_unsupported_material_extension_is_warned_about_with_its_path() {
    let file = SCENE
        .replace(
            r#""extensionsUsed": ["KHR_lights_punctual"],"#,
            r#""extensionsUsed": ["KHR_lights_punctual", "KHR_materials_anisotropy"],"#,
        )
        .replace(
            r#""doubleSided": true}"#,
            r#""doubleSided": true, "extensions": {"KHR_materials_anisotropy": {"clearcoatFactor": 1}}}"#,
        );
    let imp = load_gltf_slice(file.as_bytes(), None, Path::new("s.gltf")).expect("loads");
    let w: Vec<_> = imp
        .warnings
        .iter()
        .filter(|w| w.contains("KHR_materials_anisotropy"))
        .collect();
    assert_eq!(w.len(), 1, "{:#?}", imp.warnings);
    assert!(
        w[0].starts_with("s.gltf: ")
            && w[0].contains("at /materials/0/extensions/KHR_materials_anisotropy"),
        "{}",
        w[0]
    );
}

#[test]
fn cameras_lights_and_materials_convert() {
    let imp = load_gltf_slice(SCENE.as_bytes(), None, Path::new("s.gltf")).expect("loads");
    assert_eq!(imp.meshes.len(), 1);
    assert_eq!(imp.meshes[0].indices, vec![[0, 1, 2]]);
    let o = &imp.objects[0];
    assert!((o.matrix.transform_point3(Vec3::ZERO) - Vec3::new(0.0, 0.0, -2.0)).length() < 1e-6);
    // yfov in radians becomes degrees; the camera looks down -z from z = 3.
    assert_eq!(imp.cameras[0].name, "camera0");
    let c = imp.cameras[0].camera;
    assert!((c.fov_y_degrees - 0.5f32.to_degrees()).abs() < 1e-4);
    assert!((c.eye - Vec3::new(0.0, 0.0, 3.0)).length() < 1e-6);
    assert!((c.look_at - c.eye - Vec3::NEG_Z).length() < 1e-6);
    // Candela / pi = Ip.
    match &imp.lights[0] {
        Light::Point {
            position,
            color,
            intensity,
            ..
        } => {
            assert!((*intensity - 1.0).abs() < 1e-6);
            assert_eq!(*color, Vec3::new(1.0, 0.5, 0.25));
            assert!((*position - Vec3::new(0.0, 4.0, 0.0)).length() < 1e-6);
        }
        other => panic!("{other:?}"),
    }
    match &imp.lights[1] {
        Light::Spot(s) => {
            assert!((s.intensity - 2.0).abs() < 1e-6);
            // Rotated -90 degrees about x: -z turns into -y.
            assert!(
                (s.direction - Vec3::NEG_Y).length() < 1e-5,
                "{}",
                s.direction
            );
            assert!((s.cone_degrees - 0.5f32.to_degrees()).abs() < 1e-4);
            assert!((s.cone_softness_degrees - 0.3f32.to_degrees()).abs() < 1e-4);
        }
        other => panic!("{other:?}"),
    }
    // Metal: no diffuse, F0 = base colour, alpha = roughness^2.
    let m = &imp.materials[0];
    assert_eq!(m.diffuse, Vec3::ZERO);
    assert_eq!(m.specular, Vec3::new(1.0, 0.5, 0.0));
    assert_eq!(m.roughness, 0.25);
    assert_eq!(m.sidedness, chiaro_core::scene::Sidedness::TwoSided);
    assert!(m.emission_two_sided);
}

#[test]
fn out_of_range_index_is_an_error_not_a_panic() {
    // u8 indices 0, 1, 7 in a second buffer: 7 is past the 3 vertices.
    let bad = SCENE
        .replace(
            r#""attributes": {"POSITION": 0}, "material": 0"#,
            r#""attributes": {"POSITION": 0}, "material": 0, "indices": 1"#,
        )
        .replace(
            r#""bufferViews": [{"buffer": 0, "byteLength": 36}]"#,
            r#""bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 1, "byteLength": 3}]"#,
        )
        .replace(
            r#""min": [0, 0, 0], "max": [1, 1, 0]}]"#,
            r#""min": [0, 0, 0], "max": [1, 1, 0]},
                   {"bufferView": 1, "componentType": 5121, "count": 3, "type": "SCALAR"}]"#,
        )
        .replace(
            r#"AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]"#,
            r#"AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"},
                   {"byteLength": 4, "uri": "data:application/octet-stream;base64,AAEHAA=="}]"#,
        );
    let e = load_gltf_slice(bad.as_bytes(), None, Path::new("bad.gltf")).expect_err("index 7");
    let msg = e.to_string();
    assert!(
        msg.contains("meshes[0].primitives[0].indices") && msg.contains("index 7"),
        "{msg}"
    );
    // An accessor that claims more data than its buffer view holds.
    let short = SCENE.replace(
        r#""count": 3, "type": "VEC3""#,
        r#""count": 300, "type": "VEC3""#,
    );
    let e = load_gltf_slice(short.as_bytes(), None, Path::new("g.gltf")).expect_err("short");
    assert!(e.to_string().contains("accessors[0]"), "{e}");
    // Bad JSON gives line and column.
    let e = load_gltf_slice(b"{\n  \"asset\": ,\n}", None, Path::new("j.gltf")).expect_err("json");
    assert!(matches!(e, IoError::At { line: 2, .. }), "{e}");
    // A truncated GLB header.
    let e = load_gltf_slice(
        b"glTF\x02\x00\x00\x00\x04\x00\x00\x00",
        None,
        Path::new("h.glb"),
    );
    assert!(e.is_err());
}

/// A later 2.x file loads; one whose minVersion is above 2.0, or that
/// is not glTF 2, is refused naming the file and the version.
#[test]
fn min_version_above_2_0_is_refused() {
    let with = |asset: &str| SCENE.replace(r#""asset": {"version": "2.0"}"#, asset);
    for ok in [
        r#""asset": {"version": "2.1"}"#,
        r#""asset": {"version": "2.1", "minVersion": "2.0"}"#,
    ] {
        load_gltf_slice(with(ok).as_bytes(), None, Path::new("v.gltf")).expect(ok);
    }
    for (bad, want) in [
        (
            r#""asset": {"version": "2.1", "minVersion": "2.1"}"#,
            "v.gltf: asset.minVersion: the file requires glTF 2.1 or later",
        ),
        (
            r#""asset": {"version": "3.0", "minVersion": "3.0"}"#,
            "v.gltf: asset.version",
        ),
        (
            r#""asset": {"version": "2.0", "minVersion": "two"}"#,
            "asset.minVersion",
        ),
    ] {
        let e = load_gltf_slice(with(bad).as_bytes(), None, Path::new("v.gltf"))
            .expect_err(bad)
            .to_string();
        assert!(e.contains(want), "{bad}: {e}");
    }
}

#[test]
fn supported_required_extensions_load_and_points_only_is_an_error() {
    let req = SCENE.replace(
        r#""extensionsUsed": ["KHR_lights_punctual"],"#,
        r#""extensionsUsed": ["KHR_lights_punctual", "KHR_mesh_quantization",
                "KHR_texture_transform"],
              "extensionsRequired": ["KHR_mesh_quantization", "KHR_texture_transform"],"#,
    );
    let imp = load_gltf_slice(req.as_bytes(), None, Path::new("q.gltf")).expect("loads");
    assert_eq!(imp.meshes.len(), 1);
    // The default metallic (1) keeps the base colour on ks.
    let mr = imp.materials[0].metallic_roughness.expect("pbr");
    assert_eq!(mr.base_color, Vec3::new(1.0, 0.5, 0.0));
    // Quantized positions: i16 normalized (32767 = 1.0), 3 vertices.
    let q = SCENE
        .replace(
            r#""componentType": 5126, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            r#""componentType": 5122, "normalized": true, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [32767, 32767, 0]}"#,
        )
        .replace(r#""byteLength": 36}]"#, r#""byteLength": 24, "byteStride": 8}]"#)
        .replace(
            r#""byteLength": 36,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]"#,
            r#""byteLength": 24,
        "uri": "data:application/octet-stream;base64,AAAAAAAAAAD/fwAAAAAAAAAA/38AAAAA"}]"#,
        );
    let imp = load_gltf_slice(q.as_bytes(), None, Path::new("q.gltf")).expect("quantized");
    assert_eq!(
        imp.meshes[0].positions,
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        "quantized positions"
    );
    // Points only: nothing to render is an error naming the primitive.
    let pts = SCENE.replace(
        r#""attributes": {"POSITION": 0}, "material": 0"#,
        r#""attributes": {"POSITION": 0}, "material": 0, "mode": 0"#,
    );
    let e = load_gltf_slice(pts.as_bytes(), None, Path::new("p.gltf")).expect_err("points");
    assert!(e.to_string().contains("nothing to render"), "{e}");
    assert!(e.to_string().contains("meshes[0].primitives[0]"), "{e}");
}

#[test]
fn base64_round_trip() {
    assert_eq!(decode_base64("aGVsbG8=").unwrap_or_default(), b"hello");
    assert_eq!(decode_base64("aGk").unwrap_or_default(), b"hi");
    assert!(decode_base64("a*b").is_err());
}

#[test]
fn bad_percent_encoding_is_refused() {
    assert!(check_uri("a%20b.bin").is_ok());
    assert!(check_uri("a%ff.bin").is_err());
}

/// A sparse POSITION accessor of count 2^31 without a buffer view: its
/// zeros would take 24 GiB, refused before anything is sized by it.
#[test]
fn unbacked_accessor_counts_are_checked_against_the_budget() {
    let scene = |count: u64, sparse: u64| {
        format!(
            r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
                "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
                "accessors": [{{"componentType": 5126, "count": {count}, "type": "VEC3",
                  "min": [0, 0, 0], "max": [1, 2, 3],
                  "sparse": {{"count": {sparse}, "indices": {{"bufferView": 0, "componentType": 5125}},
                    "values": {{"bufferView": 1}}}}}}],
                "bufferViews": [{{"buffer": 0, "byteLength": 4}}, {{"buffer": 0, "byteOffset": 4, "byteLength": 12}}],
                "buffers": [{{"byteLength": 16, "uri": "data:application/octet-stream;base64,AQAAAAAAgD8AAABAAABAQA=="}}]}}"#
        )
    };
    let budget = MemoryBudget::new(1 << 30);
    let huge = scene(1 << 31, 1);
    assert!(huge.len() < 1000, "{} bytes", huge.len());
    let e = load_gltf_slice_within(huge.as_bytes(), None, Path::new("sparse.gltf"), budget)
        .expect_err("2^31 zeros");
    let msg = e.to_string();
    assert!(
        msg.contains("sparse.gltf")
            && msg.contains("accessors[0]")
            && msg.contains("2147483648 elements")
            && msg.contains("memory limit is 1.0 GiB"),
        "{msg}"
    );
    // The same accessor with a count that fits: zeros and the one value.
    let small = load_gltf_slice_within(scene(3, 1).as_bytes(), None, Path::new("s.gltf"), budget)
        .expect("loads");
    assert_eq!(
        small.meshes[0].positions,
        vec![Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO]
    );
    // More sparse entries than elements.
    let e = load_gltf_slice_within(scene(1, 2).as_bytes(), None, Path::new("s.gltf"), budget)
        .expect_err("sparse count");
    assert!(e.to_string().contains("sparse count 2 exceeds"), "{e}");
}

/// DamagedHelmet's five 2048 x 2048 8-bit textures are held as their codes
/// (4 bytes a texel, not 16), the scene holds one copy of each, and their
/// mip-maps add only the `f32` levels below level 0.
#[test]
fn damaged_helmet_textures_hold_their_8bit_codes_once() {
    let Some(assets) = chiaro_testkit::shared_assets() else {
        eprintln!("skipped: no shared assets (set CHIARO_ASSETS)");
        return;
    };
    let path =
        assets.join("khronos-gltf-sample-assets/DamagedHelmet/glTF-Binary/DamagedHelmet.glb");
    let imported = load_gltf(&path).expect("DamagedHelmet loads");
    let loaded = crate::whole_scene(imported.clone(), &path).expect("scene");
    use chiaro_core::scene::{ImageTexture, Texture};
    let images = |textures: &[Texture]| -> Vec<ImageTexture> {
        textures
            .iter()
            .filter_map(|t| match t {
                Texture::Image(i) if i.source.contains("DamagedHelmet") => Some(i.clone()),
                _ => None,
            })
            .collect()
    };
    let (ours, theirs) = (images(&loaded.scene.textures), images(&imported.textures));
    assert_eq!(ours.len(), 5);
    let side = 2048 * 2048;
    for (t, i) in ours.iter().zip(&theirs) {
        assert_eq!((t.width, t.height), (2048, 2048), "{}", t.source);
        assert!(t.texels.is_empty(), "{}", t.source);
        assert_eq!(t.texel_bytes(), side * 4, "{}", t.source);
        // The scene's texture shares the import's codes.
        let codes = |t: &ImageTexture| t.texels8.as_ref().map(|c| c.codes().as_ptr());
        assert_eq!(codes(t), codes(i), "{}", t.source);
    }
    let total: usize = ours.iter().map(|t| t.texel_bytes()).sum();
    assert_eq!(total, 5 * side * 4);
    // The pyramid: level 0 shared, levels 1.. as f32 (1024^2 + 512^2 + ... + 1 texels).
    let mip = chiaro_core::shading::texture::MipMap::new(&ours[0]);
    let below: usize = (1..=11).map(|l| (2048usize >> l).pow(2)).sum();
    assert_eq!(mip.extra_bytes(), below * 16);
}

/// An orthographic camera becomes a named camera whose film half-height
/// is `ymag`, looking down the node's -z.
#[test]
fn orthographic_cameras_are_read() {
    let text = SCENE.replace(
        r#""cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}]"#,
        r#""cameras": [{"type": "orthographic",
            "orthographic": {"xmag": 3.0, "ymag": 1.5, "znear": 0.0, "zfar": 50.0}}]"#,
    );
    assert_ne!(text, SCENE);
    let imp = load_gltf_slice(text.as_bytes(), None, Path::new("s.gltf")).expect("loads");
    let c = imp.cameras[0].camera;
    assert_eq!(
        c.projection,
        chiaro_core::scene::Projection::Orthographic { half_height: 1.5 }
    );
    assert!((c.eye - Vec3::new(0.0, 0.0, 3.0)).length() < 1e-6);
    assert!((c.look_at - c.eye - Vec3::NEG_Z).length() < 1e-6);
    assert!(c.near > 0.0 && c.far == 50.0);
}
