//! What a technique cannot show: `chiaro::limitations` on the shipped
//! scenes, the warnings a render emits (once each, naming the objects),
//! the README's table, and the warning for a scene that nothing lights.

use chiaro::limitations::{Feature, limitations, markdown_table};
use chiaro::{NoProgress, Scene, Technique, Vec3};
use chiaro_testkit::Warnings;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn load(name: &str) -> Scene {
    chiaro::io::load_scene(&repo().join("scenes").join(name))
        .expect("loads")
        .scene
}

/// The objects named for `feature`, or `None` when it is not listed.
fn named(scene: &Scene, t: Technique, feature: Feature) -> Option<Vec<String>> {
    limitations(scene, t)
        .into_iter()
        .find(|l| l.feature == feature)
        .map(|l| l.objects)
}

#[test]
fn whitted_scene_in_radiosity_names_the_mirror_and_the_glass() {
    let s = load("whitted.toml");
    let mirror = "sphere (mirror)".to_string();
    let glass = "sphere (glass)".to_string();
    let t = Technique::Radiosity;
    assert_eq!(
        named(&s, t, Feature::Mirrors),
        Some(vec![mirror.clone(), glass.clone()])
    );
    assert_eq!(
        named(&s, t, Feature::Transparency),
        Some(vec![glass.clone()])
    );
    assert_eq!(
        named(&s, t, Feature::Highlights),
        Some(vec![mirror.clone(), glass.clone()])
    );
    assert_eq!(named(&s, t, Feature::NormalMaps), None);
    // The scan converter refracts nothing; Whitted shows it all.
    assert_eq!(
        named(&s, Technique::Phong, Feature::Refraction),
        Some(vec![glass])
    );
    assert!(limitations(&s, Technique::Whitted).is_empty());
    // The path tracer lacks only the ambient term.
    let path: Vec<Feature> = limitations(&s, Technique::Path)
        .iter()
        .map(|l| l.feature)
        .collect();
    assert_eq!(path, [Feature::AmbientLight]);
    // Gouraud misses what falls inside the floor's two triangles.
    assert_eq!(
        named(&s, Technique::Gouraud, Feature::InsideLargePolygons),
        Some(vec!["plane".to_string()])
    );
}

#[test]
fn transparency_scene_names_the_panes() {
    let s = load("transparency.toml");
    let see_through = vec![
        "red pane".to_string(),
        "blue pane".to_string(),
        "green ball".to_string(),
    ];
    assert_eq!(
        named(&s, Technique::Radiosity, Feature::Transparency),
        Some(see_through.clone())
    );
    assert_eq!(
        named(&s, Technique::Phong, Feature::Refraction),
        Some(see_through.clone())
    );
    assert_eq!(
        named(&s, Technique::Hybrid, Feature::SpecularIndirect),
        Some(see_through)
    );
    assert_eq!(named(&s, Technique::Phong, Feature::Transparency), None);
}

#[test]
fn a_render_warns_once_per_limitation_naming_the_objects() {
    let s = load("whitted.toml");
    let settings = chiaro_testkit::scenes::settings(&s, Technique::Preview, 8, 6, 1);
    let w = Warnings::default();
    chiaro::render(&s, &settings, &w).expect("renders");
    let got = w.into_vec();
    let expected: Vec<String> = limitations(&s, Technique::Preview)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(got, expected);
    assert!(
        got.iter()
            .any(|w| w.starts_with("preview cannot show mirror reflections")
                && w.contains("`sphere (mirror)`, `sphere (glass)`")),
        "{got:?}"
    );
}

#[test]
fn long_lists_end_with_a_count() {
    let mut s = load("whitted.toml");
    let ball = s.objects[1].clone();
    for i in 0..5 {
        s.objects.push(chiaro::scene::Object {
            name: format!("ball {i}"),
            ..ball.clone()
        });
    }
    let l = limitations(&s, Technique::Radiosity)
        .into_iter()
        .find(|l| l.feature == Feature::Mirrors)
        .expect("mirrors");
    assert_eq!(l.objects.len(), 7);
    assert!(
        l.to_string()
            .ends_with("`sphere (glass)`, `ball 0` and 4 more)"),
        "{l}"
    );
}

#[test]
fn every_technique_is_described_once_by_its_renderer() {
    for t in Technique::ALL {
        let described: Vec<_> = chiaro::renderer(t)
            .descriptions()
            .iter()
            .filter(|d| d.technique == t)
            .collect();
        assert_eq!(described.len(), 1, "{}: {described:?}", t.name());
        let d = described[0];
        assert!(!d.method.is_empty() && !d.shows.is_empty(), "{}", t.name());
        assert_eq!(d.title.to_lowercase(), t.name(), "{}", t.name());
    }
}

#[test]
fn the_scan_converters_sample_cap_is_its_own_settings_check() {
    let mut s = chiaro::RenderSettings {
        technique: Technique::Phong,
        samples: 100,
        ..Default::default()
    };
    let warned = |s: &chiaro::RenderSettings| {
        chiaro::settings_issues(s)
            .iter()
            .any(|i| i.path == "render.samples" && i.severity == chiaro::scene::Severity::Warning)
    };
    assert!(warned(&s), "phong at 100 samples is capped, and says so");
    s.technique = Technique::Path;
    assert!(!warned(&s), "the path tracer takes 100 samples");
    s.technique = Technique::Flat;
    s.samples = 64;
    assert!(!warned(&s), "64 is within the cap");
}

#[test]
fn readme_and_architecture_show_the_tables_the_code_knows() {
    let table = markdown_table();
    let methods = chiaro::limitations::methods_table();
    for t in Technique::ALL {
        let d = chiaro::description(t).expect("described");
        for (_, text) in d.cannot_show {
            assert!(table.contains(text), "{} {text}", t.name());
        }
        assert!(methods.contains(d.method), "{}", t.name());
    }
    for doc in ["README.md", "ARCHITECTURE.md"] {
        let text = std::fs::read_to_string(repo().join(doc)).expect("reads");
        assert!(
            text.contains(&table),
            "{doc} must hold the table of `chiaro::limitations::markdown_table()`:\n{table}"
        );
    }
    let readme = std::fs::read_to_string(repo().join("README.md")).expect("reads");
    assert!(
        readme.contains(&methods),
        "README.md must hold the table of `chiaro::limitations::methods_table()`:\n{methods}"
    );
}

const DARK: &str = r#"
background = [0, 0, 0]
[render]
width = 8
height = 6
samples = 1
[camera]
eye = [0, 1, -4]
look_at = [0, 0, 0]
[material.grey]
diffuse = [0.5, 0.5, 0.5]
[[object]]
primitive = "sphere"
material = "grey"
"#;

#[test]
fn a_scene_that_nothing_lights_is_said_to_render_black() {
    let loaded = chiaro::io::load_scene_str(DARK, Path::new("."), "dark.toml").expect("loads");
    let warned: Vec<&String> = loaded
        .warnings
        .iter()
        .filter(|w| w.contains("no lights"))
        .collect();
    assert_eq!(warned.len(), 1, "{:?}", loaded.warnings);
    assert!(warned[0].starts_with("dark.toml:"), "{}", warned[0]);
    // It is true: phong renders it black, preview (its own eye light) does not.
    let s = loaded.scene;
    let mut settings = s.render.clone();
    settings.technique = Technique::Phong;
    let film = chiaro::render(&s, &settings, &NoProgress).expect("renders");
    assert!(film.color.iter().all(|c| *c == Vec3::ZERO));
    settings.technique = Technique::Preview;
    let film = chiaro::render(&s, &settings, &NoProgress).expect("renders");
    assert!(film.color.iter().any(|c| c.max_element() > 0.1));
    // An emissive material lights it: no warning.
    let lit = DARK.replace("diffuse = [0.5, 0.5, 0.5]", "emission = [1, 1, 1]");
    let loaded = chiaro::io::load_scene_str(&lit, Path::new("."), "lit.toml").expect("loads");
    assert!(
        loaded.warnings.iter().all(|w| !w.contains("no lights")),
        "{:?}",
        loaded.warnings
    );
}

#[test]
fn rough_glass_is_drawn_smooth_by_whitted_and_blurred_by_path() {
    let rough = DARK.replace(
        "diffuse = [0.5, 0.5, 0.5]",
        "diffuse = [0, 0, 0]\ntransmit = [1, 1, 1]\nfresnel = true\nmodel = \"torrance-sparrow\"\nroughness = 0.3",
    );
    let s = chiaro::io::load_scene_str(&rough, Path::new("."), "rough.toml")
        .expect("loads")
        .scene;
    for t in [Technique::Whitted, Technique::Hybrid] {
        let names = named(&s, t, Feature::RoughTransmission).map(|v| v.len());
        assert_eq!(names, Some(1), "{}", t.name());
    }
    assert_eq!(named(&s, Technique::Path, Feature::RoughTransmission), None);
    // Smooth glass is no limitation.
    let smooth = rough.replace("roughness = 0.3", "roughness = 0.001");
    let s = chiaro::io::load_scene_str(&smooth, Path::new("."), "smooth.toml")
        .expect("loads")
        .scene;
    assert_eq!(
        named(&s, Technique::Whitted, Feature::RoughTransmission),
        None
    );
}

#[test]
fn a_clear_coat_reflects_other_objects_only_in_path() {
    let mut s = chiaro::io::load_scene_str(DARK, Path::new("."), "coat.toml")
        .expect("loads")
        .scene;
    for m in &mut s.materials {
        m.clearcoat = Some(chiaro::scene::Clearcoat::default());
    }
    for t in [
        Technique::Flat,
        Technique::Gouraud,
        Technique::Phong,
        Technique::Whitted,
        Technique::Hybrid,
    ] {
        let names = named(&s, t, Feature::ClearCoat).map(|v| v.len());
        assert_eq!(names, Some(1), "{}", t.name());
    }
    assert_eq!(named(&s, Technique::Path, Feature::ClearCoat), None);
    // A coat of factor 0 is no coat.
    for m in &mut s.materials {
        m.clearcoat = Some(chiaro::scene::Clearcoat {
            factor: 0.0,
            ..Default::default()
        });
    }
    assert_eq!(named(&s, Technique::Phong, Feature::ClearCoat), None);
}
