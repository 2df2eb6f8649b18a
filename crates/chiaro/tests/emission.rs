//! Emission seen directly, across techniques: a glTF quad with
//! `KHR_materials_emissive_strength` shows `emissiveFactor * strength` in
//! every technique that shades emission (Phong, Whitted, both path kernels
//! and the reference kernel), not the factor alone.

mod common;

use chiaro::scene::Technique;
use chiaro::{Film, NoProgress, Scene, Vec3};
use chiaro_ray::path::Kernel;
use chiaro_testkit::central_mean;
use chiaro_testkit::scenes::{load_text, repo_scene};

/// A 2 x 2 quad in the plane z = 0 facing +z, with a black base colour and
/// the emissive factor (0.1, 0.5, 0.9) times `strength`, seen by a camera
/// on +z (the data URI holds its four positions and six u16 indices).
fn emissive_quad_gltf(strength: f32) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_emissive_strength"],
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0}},
    {{"camera": 0, "translation": [0, 0, 3]}}
  ],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.5, "znear": 0.1}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "materials": [{{
    "pbrMetallicRoughness": {{"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0, "roughnessFactor": 1}},
    "emissiveFactor": [0.1, 0.5, 0.9],
    "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": {strength}}}}}
  }}],
  "buffers": [{{"byteLength": 60, "uri": "data:application/octet-stream;base64,AACAvwAAgL8AAAAAAACAPwAAgL8AAAAAAACAPwAAgD8AAAAAAACAvwAAgD8AAAAAAAABAAIAAAACAAMA"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, -1, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    )
}

fn render(scene: &Scene, technique: Technique, kernel: Option<Kernel>) -> Film {
    let mut s = scene.render.clone();
    s.technique = technique;
    s.width = 32;
    s.height = 32;
    s.samples = if technique == Technique::Path { 16 } else { 1 };
    common::render_cell(scene, &s, kernel)
}

#[test]
fn emissive_strength_is_seen_directly_by_every_technique() {
    for strength in [1.0f32, 4.0, 16.0] {
        let mut scene = load_text("quad.gltf", &emissive_quad_gltf(strength));
        // The quad's own light only: the automatic lights and the studio
        // environment would add their (small, specular) reflection off the
        // black base colour.
        scene.lights.clear();
        scene.environment = None;
        scene.background = Vec3::ZERO;
        let want = Vec3::new(0.1, 0.5, 0.9) * strength;
        let cells = [
            ("phong", render(&scene, Technique::Phong, None)),
            ("whitted", render(&scene, Technique::Whitted, None)),
            ("path (facade)", render(&scene, Technique::Path, None)),
            (
                "path lanes",
                render(&scene, Technique::Path, Some(Kernel::Lanes)),
            ),
            (
                "path scalar",
                render(&scene, Technique::Path, Some(Kernel::Scalar)),
            ),
            (
                "path reference",
                render(&scene, Technique::Path, Some(Kernel::Reference)),
            ),
        ];
        for (name, film) in &cells {
            let got = central_mean(film, 4);
            // Every camera sample sees the emitter: no noise, float error only.
            assert!(
                (got - want).abs().max_element() <= 1e-4 * strength,
                "{name}, emissive strength {strength}: centre {got}, want {want}"
            );
        }
    }
}

/// The gallery's model: its five cubes emit the same colour at 1, 2, 4, 8
/// and 16 times; a camera ray on a cube face sees that much in every
/// technique (the gallery's copy in `scenes/gltf/`, with its licence).
#[test]
fn emissive_strength_test_model_cubes_glow_in_path_as_in_phong() {
    let scene = repo_scene("scenes/gltf/EmissiveStrengthTest.glb", 96);
    let strengths: Vec<f32> = scene
        .materials
        .iter()
        .filter(|m| m.emission != Vec3::ZERO)
        .map(|m| m.emission.x / 0.1)
        .collect();
    let mut sorted = strengths.clone();
    sorted.sort_by(f32::total_cmp);
    for (s, want) in sorted.iter().zip([1.0, 2.0, 4.0, 8.0, 16.0]) {
        assert!(
            (s - want).abs() < 1e-3,
            "emission strengths {strengths:?}, want 1, 2, 4, 8 and 16"
        );
    }
}

/// The scan converter and Whitted (one sample per pixel, depth 0) draw an
/// emitter group's light samples from one per-pixel sequence
/// (`chiaro_core::shading::group_jitter`): on the shipped
/// EmissiveStrengthTest, whose cubes are grouped, they agree to 1e-3 on
/// every pixel where both see the same point, although each pixel picks
/// its own triangles (its glow on the panels is noisy at 16 samples).
#[test]
fn phong_equals_whitted_at_depth_0_under_an_emitter_group() {
    let scene = repo_scene("scenes/gltf/EmissiveStrengthTest.glb", 96);
    let mut s = scene.render.clone();
    s.technique = Technique::Phong;
    s.width = 96;
    s.height = 72;
    s.samples = 1;
    s.shadows = chiaro::scene::ShadowMethod::None;
    s.whitted.max_depth = 0;
    let ps = chiaro_core::prepared::PreparedScene::new(&scene, Default::default());
    assert!(
        chiaro_core::shading::EmitterGroup::of_scene(&ps, s.light_samples.max(1)).is_some(),
        "the cubes are sampled as a group"
    );
    let phong = chiaro::render(&scene, &s, &NoProgress).expect("renders");
    s.technique = Technique::Whitted;
    let whitted = chiaro::render(&scene, &s, &NoProgress).expect("renders");
    let (mut compared, mut over, mut worst) = (0, 0, 0.0f32);
    for i in 0..phong.color.len() {
        let (a, b) = (phong.depth[i], whitted.depth[i]);
        let same = a.is_finite()
            && (a - b).abs() <= 1e-3 * a.max(1.0)
            && phong.normal[i].dot(whitted.normal[i]) > 0.999;
        if !same {
            continue;
        }
        compared += 1;
        let d = (phong.color[i] - whitted.color[i]).abs().max_element();
        worst = worst.max(d);
        over += usize::from(d > 1e-3);
    }
    assert!(
        compared > phong.color.len() / 4,
        "{compared} pixels compared"
    );
    assert!(
        over == 0,
        "{over} of {compared} pixels differ by more than 1e-3 (largest {worst})"
    );
}
