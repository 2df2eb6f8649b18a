//! Tests of skins posed at rest, two uv sets and every texture slot's
//! `KHR_texture_transform`, on small files built here.

use super::*;
use chiaro_core::scene::Texture;
use chiaro_core::{Vec2, Vec3};

/// Standard base64 (RFC 4648) with padding, for embedding test buffers.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A triangle skinned to two joints. Joint 0 is translated by (10, 0, 0)
/// with an identity inverse bind matrix; joint 1 is rotated 90 degrees
/// about +z under a parent translated by (0, 5, 0), with an inverse bind
/// matrix translating by (-1, 0, 0). Vertex 0 follows joint 0, vertex 1
/// joint 1, vertex 2 half each. The mesh node's own translation (100, 0,
/// 0) must be ignored.
fn skinned_triangle() -> String {
    let positions = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
    let joints: Vec<u8> = vec![0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0];
    let weights = f32_bytes(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0]);
    let mut ibm = Vec::new();
    ibm.extend(f32_bytes(&Mat4::IDENTITY.to_cols_array()));
    ibm.extend(f32_bytes(
        &Mat4::from_translation(Vec3::new(-1.0, 0.0, 0.0)).to_cols_array(),
    ));
    let mut buf = positions;
    buf.extend(&joints);
    buf.extend(&weights);
    buf.extend(&ibm);
    let (s, h) = (0.5f32.sqrt(), 0.5f32.sqrt());
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0, 1, 2]}}],
          "nodes": [
            {{"mesh": 0, "skin": 0, "translation": [100, 0, 0]}},
            {{"translation": [10, 0, 0]}},
            {{"translation": [0, 5, 0], "children": [3]}},
            {{"rotation": [0, 0, {s}, {h}]}}
          ],
          "skins": [{{"joints": [1, 3], "inverseBindMatrices": 3}}],
          "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}}}}]}}],
          "accessors": [
            {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
              "min": [0, 0, 0], "max": [1, 1, 0]}},
            {{"bufferView": 1, "componentType": 5121, "count": 3, "type": "VEC4"}},
            {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"}},
            {{"bufferView": 3, "componentType": 5126, "count": 2, "type": "MAT4"}}
          ],
          "bufferViews": [
            {{"buffer": 0, "byteLength": 36}},
            {{"buffer": 0, "byteOffset": 36, "byteLength": 12}},
            {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
            {{"buffer": 0, "byteOffset": 96, "byteLength": 128}}
          ],
          "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}]}}"#,
        buf.len(),
        base64(&buf)
    )
}

#[test]
fn a_skinned_mesh_is_posed_by_its_joints_at_rest_and_its_node_transform_ignored() {
    let imp = load_gltf_slice(skinned_triangle().as_bytes(), None, Path::new("skin.gltf"))
        .expect("loads");
    assert_eq!(imp.objects.len(), 1);
    // The skinned node's translation (100, 0, 0) is not applied.
    assert_eq!(imp.objects[0].matrix, Mat4::IDENTITY);
    let p = &imp.meshes[imp.objects[0].mesh].positions;
    // Vertex 0: joint 0 only, (0,0,0) + (10,0,0).
    assert!(
        (p[0] - Vec3::new(10.0, 0.0, 0.0)).length() < 1e-5,
        "{}",
        p[0]
    );
    // Vertex 1: (1,0,0) -> bind (0,0,0) -> rotated (0,0,0) -> + (0,5,0).
    assert!(
        (p[1] - Vec3::new(0.0, 5.0, 0.0)).length() < 1e-5,
        "{}",
        p[1]
    );
    // Vertex 2: half of joint 0's (11,1,0) and half of joint 1's: (1,1,0)
    // -> (0,1,0) -> rotated (-1,0,0) -> (-1,5,0); the mean (5,3,0).
    assert!(
        (p[2] - Vec3::new(5.0, 3.0, 0.0)).length() < 1e-5,
        "{}",
        p[2]
    );
    // Posing is not an unsupported feature any more.
    assert!(
        imp.warnings.iter().all(|w| !w.contains("skin")),
        "{:#?}",
        imp.warnings
    );
}

#[test]
fn a_skin_with_too_few_inverse_bind_matrices_is_an_error() {
    let file = skinned_triangle().replace(
        r#""count": 2, "type": "MAT4""#,
        r#""count": 1, "type": "MAT4""#,
    );
    let e = load_gltf_slice(file.as_bytes(), None, Path::new("skin.gltf"))
        .expect_err("one matrix for two joints");
    let msg = e.to_string();
    assert!(
        msg.contains("skin.gltf") && msg.contains("skins[0].inverseBindMatrices"),
        "{msg}"
    );
}

/// A PNG of `w x h` RGBA pixels, as a data URI.
fn png_uri(w: u32, h: u32, rgba: &[[u8; 4]]) -> String {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().expect("png header");
        let flat: Vec<u8> = rgba.iter().flatten().copied().collect();
        writer.write_image_data(&flat).expect("png data");
    }
    format!("data:image/png;base64,{}", base64(&bytes))
}

/// A quad whose base colour texture reads TEXCOORD_1 and whose normal map
/// reads TEXCOORD_0 with a `KHR_texture_transform`; the occlusion texture
/// reads a third set, TEXCOORD_2.
fn two_set_quad() -> String {
    let positions = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0]);
    let uv0 = f32_bytes(&[0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]);
    // The second set mirrors u.
    let uv1 = f32_bytes(&[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
    let uv2 = f32_bytes(&[0.5; 8]);
    let indices: Vec<u8> = vec![0, 1, 2, 0, 2, 3];
    let mut buf = positions;
    buf.extend(&uv0);
    buf.extend(&uv1);
    buf.extend(&uv2);
    buf.extend(&indices);
    let image = png_uri(2, 1, &[[255, 0, 0, 255], [0, 255, 0, 255]]);
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "extensionsUsed": ["KHR_texture_transform"],
          "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
          "images": [{{"uri": "{image}"}}],
          "textures": [{{"source": 0}}],
          "materials": [{{
            "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0, "texCoord": 1}}}},
            "normalTexture": {{"index": 0, "extensions": {{"KHR_texture_transform":
               {{"offset": [0.25, 0.5], "rotation": 0.5, "scale": [2, 3]}}}}}},
            "occlusionTexture": {{"index": 0, "texCoord": 2}}
          }}],
          "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1,
              "TEXCOORD_1": 2, "TEXCOORD_2": 3}}, "indices": 4, "material": 0}}]}}],
          "accessors": [
            {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
              "min": [0, 0, 0], "max": [1, 1, 0]}},
            {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
            {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}},
            {{"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"}},
            {{"bufferView": 4, "componentType": 5121, "count": 6, "type": "SCALAR"}}
          ],
          "bufferViews": [
            {{"buffer": 0, "byteLength": 48}},
            {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
            {{"buffer": 0, "byteOffset": 80, "byteLength": 32}},
            {{"buffer": 0, "byteOffset": 112, "byteLength": 32}},
            {{"buffer": 0, "byteOffset": 144, "byteLength": 6}}
          ],
          "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}]}}"#,
        buf.len(),
        base64(&buf)
    )
}

fn image(imp: &Imported, id: Option<chiaro_core::scene::TextureId>) -> ImageTextureRef<'_> {
    let id = id.expect("a texture");
    match &imp.textures[id.index()] {
        Texture::Image(i) => i,
        other => panic!("{other:?}"),
    }
}

type ImageTextureRef<'a> = &'a chiaro_core::scene::ImageTexture;

#[test]
fn each_texture_names_its_uv_set_and_the_mesh_carries_two() {
    let imp =
        load_gltf_slice(two_set_quad().as_bytes(), None, Path::new("uv.gltf")).expect("loads");
    let m = &imp.meshes[0];
    assert_eq!(m.uvs[1], Vec2::new(1.0, 0.0));
    assert_eq!(m.uvs1[1], Vec2::new(0.0, 0.0));
    let mat = &imp.materials[0];
    assert_eq!(image(&imp, mat.texture).uv_set, 1);
    assert_eq!(image(&imp, mat.normal_map).uv_set, 0);
    // The third set is one warning, and its texture reads the first set.
    let occlusion = mat.occlusion.map(|o| o.texture);
    assert_eq!(image(&imp, occlusion).uv_set, 0);
    let third: Vec<_> = imp
        .warnings
        .iter()
        .filter(|w| w.contains("more than two texCoord sets"))
        .collect();
    assert_eq!(third.len(), 1, "{:#?}", imp.warnings);
    assert!(third[0].contains("TEXCOORD_2"), "{}", third[0]);
}

#[test]
fn the_normal_map_keeps_its_texture_transform() {
    let imp =
        load_gltf_slice(two_set_quad().as_bytes(), None, Path::new("uv.gltf")).expect("loads");
    let t = image(&imp, imp.materials[0].normal_map).uv_transform;
    assert_eq!(t.offset, Vec2::new(0.25, 0.5));
    assert_eq!(t.rotation, 0.5);
    assert_eq!(t.scale, Vec2::new(2.0, 3.0));
    // The base colour reference has none: a distinct texture.
    assert!(
        image(&imp, imp.materials[0].texture)
            .uv_transform
            .is_identity()
    );
}

/// A material whose textures all read one set other than 0 needs no second
/// set: that set becomes the mesh's `uvs`.
#[test]
fn a_material_on_one_set_reads_it_as_the_first() {
    let file = two_set_quad()
        .replace(
            r#""normalTexture": {"index": 0, "extensions""#,
            r#""normalTexture": {"index": 0, "texCoord": 1, "extensions""#,
        )
        .replace(r#""texCoord": 2}"#, r#""texCoord": 1}"#);
    let imp = load_gltf_slice(file.as_bytes(), None, Path::new("uv.gltf")).expect("loads");
    let m = &imp.meshes[0];
    assert_eq!(
        m.uvs[1],
        Vec2::new(0.0, 0.0),
        "TEXCOORD_1 read as the first set"
    );
    assert!(m.uvs1.is_empty());
    assert_eq!(image(&imp, imp.materials[0].texture).uv_set, 0);
    assert!(imp.warnings.is_empty(), "{:#?}", imp.warnings);
}

/// The Draco-compressed Box and Duck of the Khronos samples decode to the
/// geometry of their uncompressed versions: the same triangle count and
/// bounds (Draco quantizes positions: within a thousandth of the extent)
/// and uvs within the same.
#[test]
fn draco_samples_decode_to_their_uncompressed_geometry() {
    let Some(assets) = chiaro_testkit::shared_assets() else {
        eprintln!("skipped: no shared assets (set CHIARO_ASSETS)");
        return;
    };
    let dir = assets.join("khronos-gltf-sample-assets");
    for model in ["Box", "Duck"] {
        let plain = load_gltf(&dir.join(format!("{model}/glTF/{model}.gltf"))).expect("loads");
        let draco =
            load_gltf(&dir.join(format!("{model}/glTF-Draco/{model}.gltf"))).expect("decodes");
        let bounds = |imp: &Imported| {
            let mut lo = Vec3::splat(f32::MAX);
            let mut hi = Vec3::splat(f32::MIN);
            for o in &imp.objects {
                for p in &imp.meshes[o.mesh].positions {
                    let w = o.matrix.transform_point3(*p);
                    lo = lo.min(w);
                    hi = hi.max(w);
                }
            }
            (lo, hi)
        };
        let tris = |imp: &Imported| -> usize {
            imp.objects
                .iter()
                .map(|o| imp.meshes[o.mesh].indices.len())
                .sum()
        };
        assert_eq!(tris(&plain), tris(&draco), "{model}");
        let ((a, b), (c, d)) = (bounds(&plain), bounds(&draco));
        let tol = (b - a).max_element() * 1e-3;
        assert!(
            (a - c).abs().max_element() <= tol && (b - d).abs().max_element() <= tol,
            "{model}: {a}..{b} vs {c}..{d}"
        );
        let (mp, md) = (&plain.meshes[0], &draco.meshes[0]);
        assert_eq!(mp.uvs.is_empty(), md.uvs.is_empty(), "{model}");
        assert_eq!(md.normals.len(), md.positions.len(), "{model}");
        assert!(
            draco.warnings.iter().all(|w| !w.contains("draco")),
            "{model}: {:#?}",
            draco.warnings
        );
    }
}

/// A Draco extension whose buffer view holds no Draco stream is an error
/// naming the file and the extension, never a panic.
#[test]
fn a_bad_draco_stream_is_an_error_naming_the_extension() {
    let file = r#"{"asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_draco_mesh_compression"],
        "extensionsRequired": ["KHR_draco_mesh_compression"],
        "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0},
          "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}}]}],
        "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": 8}],
        "buffers": [{"byteLength": 8, "uri": "data:application/octet-stream;base64,AAECAwQFBgc="}]}"#;
    let e = load_gltf_slice(file.as_bytes(), None, Path::new("d.gltf")).expect_err("not Draco");
    let msg = e.to_string();
    assert!(
        msg.contains("d.gltf")
            && msg.contains("KHR_draco_mesh_compression")
            && msg.contains("could not be decoded"),
        "{msg}"
    );
}

/// The Khronos skinned samples' rest pose is their bind pose: posed by
/// their joints, their bounds are the POSITION accessor's (SimpleSkin: a
/// 1 x 2 sheet; RiggedSimple: a column 2 wide and 9.15 tall), and every
/// posed object is placed by the identity.
#[test]
fn skinned_samples_at_rest_keep_their_bind_pose_bounds() {
    let Some(assets) = chiaro_testkit::shared_assets() else {
        eprintln!("skipped: no shared assets (set CHIARO_ASSETS)");
        return;
    };
    let dir = assets.join("khronos-gltf-sample-assets");
    for (file, lo, hi) in [
        (
            "SimpleSkin/glTF/SimpleSkin.gltf",
            Vec3::new(-0.5, 0.0, 0.0),
            Vec3::new(0.5, 2.0, 0.0),
        ),
        (
            "RiggedSimple/glTF-Binary/RiggedSimple.glb",
            Vec3::new(-1.0, -4.5751, -1.0),
            Vec3::new(1.0, 4.5751, 1.0),
        ),
    ] {
        let imp = load_gltf(&dir.join(file)).expect("loads");
        let mut a = Vec3::splat(f32::MAX);
        let mut b = Vec3::splat(f32::MIN);
        for o in &imp.objects {
            assert_eq!(o.matrix, Mat4::IDENTITY, "{file}");
            for p in &imp.meshes[o.mesh].positions {
                a = a.min(*p);
                b = b.max(*p);
            }
        }
        assert!(
            (a - lo).abs().max_element() < 1e-3 && (b - hi).abs().max_element() < 1e-3,
            "{file}: {a}..{b}"
        );
    }
}
