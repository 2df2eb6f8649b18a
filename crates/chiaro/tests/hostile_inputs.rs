//! The small hostile inputs of the reliability review and of issue 47
//! (hostile and degenerate files), each through the path the CLI takes (`chiaro::io::load_scene`, then `chiaro::render`),
//! ending in a clear refusal or a correct render, quickly and in bounded
//! memory. The 5,000 tessellated spheres are in `memory_budget.rs`, the
//! 4096-subdivision plane in chiaro-io's `import_toml.rs` and the CLI's
//! tests.

use chiaro::budget::{ByteSize, MemoryBudget};
use chiaro::scene::{Material, Object, RenderSettings, Scene, ShadowMethod, Technique};
use chiaro::{NoProgress, Vec3};
use chiaro_core::geometry::primitives;
use chiaro_testkit::scenes::{point_light, settings};
use chiaro_testkit::{SPARSE_GLTF_24_GIB, Warnings, assert_contains_all, base64, put};
use std::path::{Path, PathBuf};

/// A fresh directory under the target folder for one test's files.
fn dir(name: &str) -> PathBuf {
    chiaro_testkit::fresh_dir(env!("CARGO_TARGET_TMPDIR"), &format!("hostile-{name}"))
}

/// The warnings of loading `path` (which loads), one a line.
fn load_warnings(path: &Path) -> String {
    chiaro::io::load_scene(path)
        .expect("loads")
        .warnings
        .join("\n")
}

/// Why loading `path` is refused (`refused`: what the test expects to be
/// refused).
fn refusal(path: &Path, refused: &str) -> String {
    chiaro::io::load_scene(path).expect_err(refused).to_string()
}

/// A one-triangle OBJ file whose `mtllib` line names `library`.
fn triangle_with_library(library: &str) -> String {
    format!("mtllib {library}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
}

/// A triangle glTF file with a base-colour texture: its image at
/// `image_uri`, its 60 bytes of positions and texture coordinates at
/// `buffer_uri`.
fn textured_triangle_gltf(image_uri: &str, buffer_uri: &str) -> String {
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "material": 0}}]}}],
        "materials": [{{"pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}}}}}],
        "textures": [{{"source": 0}}], "images": [{{"uri": "{image_uri}"}}],
        "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
          {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 24}}],
        "buffers": [{{"byteLength": 60, "uri": "{buffer_uri}"}}]}}"#
    )
}

/// The loaders' process budget of these tests: 1 GiB, as `--memory-limit 1G`.
fn limit_1g() {
    MemoryBudget::set_process(ByteSize(1 << 30));
}

/// CRC-32 (ISO 3309, as PNG uses), bit by bit.
fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header says 16384 x 16384 grey: what a 261 KB valid file of
/// zeros opens with. Its refusal reads nothing past the header.
fn huge_png() -> Vec<u8> {
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend(16384u32.to_be_bytes());
    ihdr.extend(16384u32.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(13u32.to_be_bytes());
    png.extend(&ihdr);
    png.extend(crc32(&ihdr).to_be_bytes());
    // An empty IDAT and IEND: the header is all the check reads.
    for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
        png.extend(0u32.to_be_bytes());
        png.extend(chunk);
        png.extend(crc32(chunk).to_be_bytes());
    }
    png
}

#[test]
fn a_sparse_accessor_of_2_31_elements_is_refused() {
    limit_1g();
    let path = put(&dir("sparse"), "sparse.gltf", SPARSE_GLTF_24_GIB);
    let msg = refusal(&path, "24 GiB of zeros");
    assert_contains_all(
        &msg,
        &[
            "sparse.gltf",
            "2147483648 elements",
            "memory limit is 1.0 GiB",
        ],
    );
}

#[test]
fn a_16384_square_png_is_refused_as_texture_environment_and_data_uri() {
    limit_1g();
    let d = dir("png");
    put(&d, "big.png", huge_png());
    let expect_refusal = |msg: &str| {
        assert_contains_all(msg, &["big.png", "16384x16384", "1.0 GiB"]);
    };
    // As a material's texture and as the environment of a TOML scene.
    for (i, text) in [
        "[material.m]\ntexture = \"big.png\"\n[[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\n",
        "[environment]\ntexture = \"big.png\"\n[[object]]\nprimitive = \"sphere\"\n",
    ]
    .into_iter()
    .enumerate()
    {
        let scene = put(&d, &format!("s{i}.toml"), text);
        expect_refusal(&refusal(&scene, "refused"));
    }
    // As a data: URI in a glTF file: the texture is dropped with a warning
    // naming the refusal, and the triangle still loads.
    let positions_and_uvs: Vec<u8> = [
        0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0,
    ]
    .iter()
    .flat_map(|f| f.to_le_bytes())
    .collect();
    let gltf = textured_triangle_gltf(
        &format!("data:image/png;base64,{}", base64(&huge_png())),
        &format!(
            "data:application/octet-stream;base64,{}",
            base64(&positions_and_uvs)
        ),
    );
    let path = put(&d, "big.gltf", gltf);
    let loaded = chiaro::io::load_scene(&path).expect("the triangle loads");
    assert_eq!(loaded.scene.triangle_count(), 1);
    // No texture but the studio map of the automatic lighting.
    let env = loaded.scene.environment.as_ref().map(|e| e.texture.index());
    assert!(
        (0..loaded.scene.textures.len()).all(|i| Some(i) == env),
        "{} textures",
        loaded.scene.textures.len()
    );
    let w = loaded.warnings.join("\n");
    assert_contains_all(&w, &["images[0]", "16384x16384", "texture ignored"]);
}

/// A floor and a box on it under `n` point lights in a row.
fn lit_box(n: usize) -> Scene {
    let mut scene = Scene::default();
    let m = scene.add_material(Material::diffuse("white", Vec3::splat(0.8)));
    let floor = scene.add_mesh(primitives::plane(4.0, 1));
    let cube = scene.add_mesh(primitives::box_mesh(Vec3::splat(0.5)));
    for (mesh, y) in [(floor, 0.0), (cube, 0.5)] {
        let mut o = Object {
            geometry: chiaro::scene::Geometry::Mesh(mesh),
            material: m,
            ..Default::default()
        };
        o.transform.translate = Vec3::new(0.0, y, 0.0);
        scene.objects.push(o);
    }
    scene.lights = (0..n)
        .map(|i| {
            point_light(
                Vec3::new(-2.0 + 4.0 * i as f32 / n as f32, 3.0, 0.5),
                20.0 / n as f32,
            )
        })
        .collect();
    scene.camera.eye = Vec3::new(0.0, 4.0, 6.0);
    scene.camera.look_at = Vec3::ZERO;
    scene
}

/// [`lit_box`] with `n` lights and its settings for `technique` at
/// `width` x `height`, shadows from maps of `resolution` texels a side.
fn lit_box_with_maps(
    n: usize,
    technique: Technique,
    width: u32,
    height: u32,
    resolution: u32,
) -> (Scene, RenderSettings) {
    let scene = lit_box(n);
    let mut s = settings(&scene, technique, width, height, 1);
    s.shadows = ShadowMethod::Map;
    s.shadow_map.resolution = resolution;
    (scene, s)
}

#[test]
fn forty_shadow_mapped_lights_degrade_to_shadow_rays_within_the_budget() {
    let (scene, mut s) = lit_box_with_maps(40, Technique::Phong, 48, 36, 512);
    // 64 MiB of maps (a quarter of 256 MiB): ten 6 MiB cubes, then rays.
    s.memory_limit = Some(ByteSize(256 << 20));
    let e = chiaro::memory_estimate(&scene, &s);
    assert!(e.check(s.memory_budget()).is_ok(), "{e:?}");
    let warnings = Warnings::default();
    let mapped = chiaro::render(&scene, &s, &warnings).expect("renders");
    assert!(mapped.is_clean());
    let w = warnings.joined();
    assert_contains_all(&w, &["lights 10, 11,", "39 use shadow rays", "64 MiB"]);
    // The same picture as shadow rays for every light, up to the maps'
    // bias at the shadow edges.
    s.shadows = ShadowMethod::Ray;
    let rays = chiaro::render(&scene, &s, &NoProgress).expect("renders");
    let diff: f32 = mapped
        .color
        .iter()
        .zip(&rays.color)
        .map(|(a, b)| (*a - *b).abs().element_sum())
        .sum();
    let total: f32 = rays.color.iter().map(|c| c.element_sum()).sum();
    assert!(total > 0.0 && diff / total < 0.03, "{diff} / {total}");
}

#[test]
fn huge_shadow_maps_are_refused_or_replaced_by_rays() {
    let (scene, mut s) = lit_box_with_maps(3, Technique::Gouraud, 32, 24, 16384);
    let msg = chiaro::render(&scene, &s, &NoProgress)
        .expect_err("refused")
        .to_string();
    assert!(msg.contains("render.shadow_map.resolution"), "{msg}");
    // The largest allowed: 1.5 GiB a light, past the 512 MiB share at most.
    s.shadow_map.resolution = 8192;
    let warnings = Warnings::default();
    let film = chiaro::render(&scene, &s, &warnings).expect("renders");
    assert!(film.is_clean());
    let w = warnings.joined();
    assert!(w.contains("lights 0, 1, 2 use shadow rays"), "{w}");
}

/// Loads an OBJ the way `chiaro render file.obj` does and renders it small
/// (`visible`: something in the frame is lit).
fn load_and_render(name: &str, obj: &str, visible: bool) -> chiaro::io::Loaded {
    limit_1g();
    let path = put(&dir(name), &format!("{name}.obj"), obj);
    let loaded = chiaro::io::load_scene(&path).expect("loads");
    let s = settings(&loaded.scene, Technique::Gouraud, 24, 16, 1);
    let film = chiaro::render(&loaded.scene, &s, &NoProgress).expect("renders");
    assert!(film.is_clean());
    if visible {
        assert!(
            film.color.iter().any(|c| c.element_sum() > 0.0),
            "{name}: black"
        );
    }
    loaded
}

#[test]
fn thirty_thousand_identical_faces_load_and_render() {
    let mut obj = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    obj += &"f 1 2 3\n".repeat(30_000);
    let loaded = load_and_render("repeated", &obj, true);
    // The copies are dropped at load, with a warning (issue 47).
    assert_eq!(loaded.scene.triangle_count(), 1);
    let w = loaded.warnings.join("\n");
    assert!(w.contains("29999 faces given twice were dropped"), "{w}");
}

#[test]
fn a_grid_with_one_far_triangle_loads_and_renders() {
    let n = 100;
    let mut obj = String::new();
    for j in 0..=n {
        for i in 0..=n {
            obj += &format!("v {} {} 0\n", i as f32 / n as f32, j as f32 / n as f32);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i + 1;
            obj += &format!(
                "f {a} {} {}\nf {a} {} {}\n",
                a + 1,
                a + n + 2,
                a + n + 2,
                a + n + 1
            );
        }
    }
    obj += "v 1e12 1e12 1e12\nv 1.000001e12 1e12 1e12\nv 1e12 1.000001e12 1e12\n";
    let far = (n + 1) * (n + 1);
    obj += &format!("f {} {} {}\n", far + 1, far + 2, far + 3);
    // Framed to include the far triangle, the grid is below a pixel.
    let loaded = load_and_render("far", &obj, false);
    assert_eq!(loaded.scene.triangle_count(), 20_001);
    let b = chiaro::scene_bounds(&loaded.scene);
    assert!(b.max.x >= 1e12 && b.min.x == 0.0, "{b:?}");
}

/// `scene`'s settings with `technique` at 64x48, one sample a pixel.
fn small(scene: &Scene, technique: Technique) -> RenderSettings {
    settings(scene, technique, 64, 48, 1)
}

/// Renders `scene` with `technique` at 64x48.
fn render_small(scene: &Scene, technique: Technique) -> chiaro::Film {
    chiaro::render(scene, &small(scene, technique), &NoProgress).expect("renders")
}

/// Issue 47: a ten-line OBJ with two faces each given twice made radiosity
/// and hybrid run past 60 s. The copies are dropped at load (with a
/// warning), and both techniques finish at 64x48 within 5 s.
#[test]
fn two_faces_given_twice_render_with_radiosity_and_hybrid() {
    limit_1g();
    let path = put(
        &dir("twice"),
        "twice.obj",
        "v 0.1 0.2 0.3\nv 1.37 0.51 -0.23\nv 1.11 1.73 0.41\nv 0.3 -0.9 1.7\n\
         f 1 2 3\nf 1 2 3\nf 2 1 4\nf 2 1 4\n# two faces, each given twice\n\n",
    );
    let loaded = chiaro::io::load_scene(&path).expect("loads");
    assert_eq!(loaded.scene.triangle_count(), 2);
    let w = loaded.warnings.join("\n");
    assert!(w.contains("2 faces given twice were dropped"), "{w}");
    for t in [Technique::Radiosity, Technique::Hybrid] {
        let film = render_small(&loaded.scene, t);
        assert!(film.is_clean(), "{t:?}");
    }
}

/// Issue 47: `mtllib /dev/zero`, `map_Kd /dev/zero` and glTF image and
/// buffer URIs naming `/dev/zero` were read until an allocation failed.
/// Only regular files are read now: each is refused at once, naming the
/// kind of file (a warning where the file is optional, an error for a
/// buffer the geometry needs).
#[test]
fn devices_named_by_a_scene_are_refused_not_read() {
    limit_1g();
    let d = dir("devices");
    let obj = put(&d, "zero.obj", triangle_with_library("/dev/zero"));
    let w = load_warnings(&obj);
    assert!(
        w.contains("/dev/zero: a character device, not a regular file"),
        "{w}"
    );
    put(&d, "m.mtl", "newmtl m\nKd 1 1 1\nmap_Kd /dev/zero\n");
    put(
        &d,
        "zero.obj",
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl m\nf 1/1 2/1 3/1\n",
    );
    let w = load_warnings(&obj);
    assert!(w.contains("/dev/zero: a character device"), "{w}");
    // glTF: the image is skipped with a warning, the buffer is an error.
    put(&d, "tri.bin", [0u8; 60]);
    let path = put(
        &d,
        "image.gltf",
        textured_triangle_gltf("/dev/zero", "tri.bin"),
    );
    let w = load_warnings(&path);
    assert!(w.contains("/dev/zero: a character device"), "{w}");
    put(
        &d,
        "image.gltf",
        textured_triangle_gltf("tri.png", "/dev/zero"),
    );
    let msg = refusal(&path, "no buffer");
    assert_contains_all(&msg, &["buffers[0].uri", "character device"]);
    // A TOML scene's mesh and texture paths.
    let toml = put(&d, "s.toml", "[[object]]\nmesh = \"/dev/zero\"\n");
    let msg = refusal(&toml, "device");
    assert_contains_all(&msg, &["s.toml:2:8", "character device"]);
}

/// Issue 47: an `mtllib` naming a FIFO blocked forever. It is refused
/// without being opened.
#[test]
#[cfg(unix)]
fn a_fifo_named_by_mtllib_does_not_block() {
    limit_1g();
    let d = dir("fifo");
    let fifo = d.join("pipe.mtl");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("skipped: mkfifo is not available");
        return;
    }
    let w = load_warnings(&put(&d, "pipe.obj", triangle_with_library("pipe.mtl")));
    assert!(
        w.contains("pipe.mtl: a FIFO (named pipe), not a regular file"),
        "{w}"
    );
}

/// Issue 47: an OBJ with one vertex at 1e30 was refused as a NaN
/// `camera.eye`; the refusal names the mesh and the vertex.
#[test]
fn a_vertex_at_1e30_is_named_not_the_camera() {
    limit_1g();
    let path = put(
        &dir("huge"),
        "huge.obj",
        "o spike\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e30 0 0\nf 1 2 3\nf 1 2 4\n",
    );
    let msg = refusal(&path, "refused");
    assert!(
        msg.contains("huge.obj")
            && msg.contains("vertex")
            && msg.contains("(1e30, 0, 0)")
            && !msg.contains("camera.eye"),
        "{msg}"
    );
}

/// Issue 47: a 10,000-deep table header on line 11 was reported at 1:1.
#[test]
fn a_deep_table_header_is_reported_on_its_line() {
    limit_1g();
    let text = "# comment\n".repeat(10) + "[" + &vec!["a"; 10_000].join(".") + "]\n";
    let path = put(&dir("deep"), "deep.toml", text);
    let msg = refusal(&path, "refused");
    assert_contains_all(&msg, &["deep.toml:11:", "10000 levels"]);
}

/// Issue 47: the Khronos Duck with an emissive factor of 5120 took 31.8 s
/// in radiosity (3.7 s as shipped). Needs `CHIARO_ASSETS`; skipped
/// without it.
#[test]
fn the_emissive_duck_solves_within_ten_seconds() {
    let Some(assets) = std::env::var_os("CHIARO_ASSETS") else {
        eprintln!("skipped: CHIARO_ASSETS is not set");
        return;
    };
    limit_1g();
    let src = PathBuf::from(assets).join("khronos-gltf-sample-assets/Duck/glTF");
    let d = dir("duck");
    for f in ["Duck0.bin", "DuckCM.png"] {
        std::fs::copy(src.join(f), d.join(f)).expect("copy");
    }
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(src.join("Duck.gltf")).expect("read")).expect("json");
    for m in json["materials"].as_array_mut().expect("materials") {
        m["emissiveFactor"] = serde_json::json!([5120, 5120, 5120]);
    }
    let path = put(&d, "Duck.gltf", json.to_string());
    let loaded = chiaro::io::load_scene(&path).expect("loads");
    // Work, not time: the solve converges within its tolerance, well
    // before the iteration budget (a stalled solve ran to the budget).
    let s = small(&loaded.scene, Technique::Radiosity);
    let ctx = chiaro::RenderContext::new(&loaded.scene, &s, &NoProgress).expect("valid");
    let stats = chiaro::radiosity_solution(&ctx)
        .expect("solves")
        .stats
        .clone();
    assert!(stats.unshot <= s.radiosity.tolerance, "{stats:?}");
    assert!(
        stats.iterations < s.radiosity.max_iterations / 10,
        "{stats:?}"
    );
    let (film, _) =
        chiaro::render_with(&ctx, chiaro::renderer(Technique::Radiosity)).expect("renders");
    assert!(film.is_clean());
}
