//! The gallery in `docs/gallery/` is current: every scene and technique has
//! its picture, each scene file and each cell's settings are those it was
//! made from, each PNG is the one recorded, the README shows the table as
//! generated, and the cells rendered in at most
//! `gallery::RECHECK_SECONDS` re-render within their tolerance. Any
//! failure says to run `gallery::REGENERATE`.

use chiaro::scene::Technique;
use chiaro_tools::gallery::{self, CellTolerance, Manifest};
use std::collections::HashMap;
use std::time::Instant;

fn regenerate() -> String {
    format!("run `{}` to regenerate the gallery", gallery::REGENERATE)
}

fn manifest() -> Manifest {
    let path = gallery::repository_root().join(gallery::MANIFEST);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e}; {}", path.display(), regenerate()));
    serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("{}: {e}; {}", path.display(), regenerate()))
}

#[test]
fn every_scene_and_technique_is_recorded_with_its_scene_hash_and_settings() {
    let root = gallery::repository_root();
    let m = manifest();
    let scenes = gallery::scenes(&root).expect("scenes/ lists");
    assert!(scenes.len() >= 6, "{scenes:?}");
    let mut expected = Vec::new();
    for scene_path in &scenes {
        let (scene, sha) = gallery::load(&root, scene_path).expect("scene loads");
        for t in Technique::ALL {
            let cell = m
                .cells
                .iter()
                .find(|c| &c.scene == scene_path && c.technique == t.name())
                .unwrap_or_else(|| {
                    panic!(
                        "{scene_path} {} is not in the gallery; {}",
                        t.name(),
                        regenerate()
                    )
                });
            assert_eq!(
                cell.scene_sha256,
                sha,
                "{scene_path} changed since the gallery was made; {}",
                regenerate()
            );
            assert_eq!(
                cell.settings,
                gallery::settings_json(&gallery::cell_settings(&scene.render, t)),
                "{scene_path} {}: the gallery's settings changed; {}",
                t.name(),
                regenerate()
            );
            expected.push((scene_path.clone(), t.name().to_string()));
        }
    }
    let recorded: Vec<_> = m
        .cells
        .iter()
        .map(|c| (c.scene.clone(), c.technique.clone()))
        .collect();
    assert_eq!(
        recorded,
        expected,
        "the gallery has cells for scenes or techniques that no longer exist, or another order; {}",
        regenerate()
    );
}

#[test]
fn the_pictures_and_the_readme_table_are_those_recorded() {
    let root = gallery::repository_root();
    let m = manifest();
    for c in &m.cells {
        let path = root.join(gallery::DIR).join(&c.image);
        let (w, h, rgb) =
            gallery::read_png_rgb8(&path).unwrap_or_else(|e| panic!("{e}; {}", regenerate()));
        assert_eq!((w, h), (c.width, c.height), "{}", path.display());
        assert_eq!(
            gallery::sha256_hex(&rgb),
            c.pixels_sha256,
            "{} is not the picture the manifest records; {}",
            path.display(),
            regenerate()
        );
    }
    // No stray pictures beside the recorded ones.
    let listed: Vec<&str> = m.cells.iter().map(|c| c.image.as_str()).collect();
    for entry in std::fs::read_dir(root.join(gallery::DIR)).expect("gallery folder") {
        let name = entry
            .expect("entry")
            .file_name()
            .into_string()
            .expect("UTF-8");
        if name.ends_with(".png") {
            assert!(
                listed.contains(&name.as_str()),
                "{name} is not in the manifest: remove it or {}",
                regenerate()
            );
        }
    }
    let readme = std::fs::read_to_string(root.join(gallery::README)).expect("README");
    assert_eq!(
        gallery::current_table(&readme),
        Some(gallery::readme_table(&m).as_str()),
        "the README's gallery table is not the generated one; {}",
        regenerate()
    );
}

#[test]
fn the_cells_re_render_within_tolerance() {
    let root = gallery::repository_root();
    let m = manifest();
    let start = Instant::now();
    let mut scenes = HashMap::new();
    let (mut checked, mut skipped) = (0, 0);
    for c in &m.cells {
        if c.seconds > gallery::RECHECK_SECONDS {
            skipped += 1;
            continue;
        }
        let technique = Technique::from_name(&c.technique).expect("a known technique");
        let scene = scenes
            .entry(c.scene.clone())
            .or_insert_with(|| gallery::load(&root, &c.scene).expect("scene loads").0);
        let (film, settings, _) = gallery::render_cell(scene, technique).expect("renders");
        let fresh = gallery::display_pixels(&film, &settings);
        let (w, h, stored) = gallery::read_png_rgb8(&root.join(gallery::DIR).join(&c.image))
            .unwrap_or_else(|e| panic!("{e}; {}", regenerate()));
        let tol = CellTolerance::for_technique(technique);
        let (mean, max) =
            gallery::block_difference(&fresh, &stored, w, h, tol.block).expect("same size");
        assert!(
            mean <= tol.mean && max <= tol.max,
            "{} differs from a fresh render (mean {mean:.3}, max {max:.1} levels over {}x{} blocks; \
             tolerance {:.2}, {:.1}); {}",
            c.image,
            tol.block,
            tol.block,
            tol.mean,
            tol.max,
            regenerate()
        );
        checked += 1;
    }
    eprintln!(
        "gallery: {checked} cells re-rendered, {skipped} slower than {} s checked by hash, in {:.1} s",
        gallery::RECHECK_SECONDS,
        start.elapsed().as_secs_f64()
    );
    assert!(
        checked * 2 > m.cells.len(),
        "{checked} of {} re-rendered",
        m.cells.len()
    );
}
