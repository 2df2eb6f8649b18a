//! The seven Mitsuba 3 test scene files of the shared assets
//! (`$CHIARO_ASSETS/mitsuba3-test-scenes/tests/scenes/*/*.xml`): each loads
//! through `chiaro::io::load_scene` and renders small with every technique;
//! the path tracer agrees with Mitsuba's reference by its z-test on all
//! seven (the full-budget pass fractions come from
//! `examples/mitsuba_agreement.rs`). Skipped, saying so, where the assets
//! are absent.

use chiaro::Technique;
use chiaro::progress::NoProgress;
use chiaro_testkit::stats::mitsuba_z_test;
use std::path::{Path, PathBuf};

#[path = "common/mitsuba_scene_files.rs"]
mod mitsuba_scene_files;
#[path = "common/techniques.rs"]
mod techniques;
use mitsuba_scene_files::SCENES;

fn scenes_dir() -> Option<PathBuf> {
    let d = chiaro_testkit::shared_assets()?.join("mitsuba3-test-scenes/tests/scenes");
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("skipped: {} is absent", d.display());
        None
    }
}

#[test]
fn every_technique_renders_every_scene() {
    let Some(dir) = scenes_dir() else { return };
    for (file, _) in SCENES {
        let scene = chiaro::io::load_scene(&dir.join(file))
            .unwrap_or_else(|e| panic!("{file}: {e}"))
            .scene;
        techniques::renders_with_every_technique(&scene, file);
    }
}

fn rgb(path: &Path) -> Vec<[f64; 3]> {
    let img = chiaro::io::images::load_texture(path, false).expect("reference image");
    (0..img.texel_count())
        .map(|i| {
            let t = img.texel_at(i);
            [t[0] as f64, t[1] as f64, t[2] as f64]
        })
        .collect()
}

#[test]
fn path_agrees_with_mitsuba() {
    let Some(dir) = scenes_dir() else { return };
    // 32 spp: the z-test scales with the render's own sample count.
    let spp = 32;
    for (file, stem) in SCENES {
        let path = dir.join(file);
        let refs = path.parent().expect("folder").join("refs");
        let reference = rgb(&refs.join(format!("{stem}_ref_rgb.exr")));
        let variance = rgb(&refs.join(format!("{stem}_ref_rgb_var.exr")));
        let scene = chiaro::io::load_scene(&path).expect("loads").scene;
        let mut s = scene.render.clone();
        s.technique = Technique::Path;
        s.samples = spp;
        let film = chiaro::render(&scene, &s, &NoProgress).expect("renders");
        assert_eq!(film.color.len(), reference.len(), "{file}: size");
        let mean: Vec<[f64; 3]> = film
            .color
            .iter()
            .map(|c| [c.x as f64, c.y as f64, c.z as f64])
            .collect();
        let t = mitsuba_z_test(&mean, &reference, &variance, spp as f64);
        assert!(
            t.pass_fraction() >= 0.9975,
            "{file}: {} of {} pixels fail the z-test",
            t.failed,
            t.pixels
        );
    }
}
