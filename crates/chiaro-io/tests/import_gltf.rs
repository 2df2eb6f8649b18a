//! glTF import over the shared asset sets: every Khronos sample model loads
//! (or, for unsupported required extensions, fails with the clear error),
//! and every deliberately broken validator file loads or fails, never panics.

use chiaro_core::scene::Geometry;
use chiaro_io::load_scene;
use std::path::{Path, PathBuf};

/// Files above this size are skipped to keep the test fast.
const MAX_BYTES: u64 = 20 << 20;

fn assets() -> Option<PathBuf> {
    chiaro_testkit::shared_assets()
}

fn walk(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, exts, out);
        } else if let Some(e) = p.extension().and_then(|e| e.to_str()) {
            let e = e.to_ascii_lowercase();
            let small = std::fs::metadata(&p).is_ok_and(|m| m.len() <= MAX_BYTES);
            if exts.contains(&e.as_str()) && small {
                out.push(p);
            }
        }
    }
}

/// Sample models that require an extension chiaro does not implement; they
/// must fail with an error naming the extension. (The Draco ones load.)
const NEEDS_UNSUPPORTED: &[(&str, &str)] = &[(
    "IridescenceSuzanne/glTF-Binary/IridescenceSuzanne.glb",
    "KHR_materials_iridescence",
)];

#[test]
fn every_khronos_sample_model_loads() {
    let Some(root) = assets() else { return };
    let dir = root.join("khronos-gltf-sample-assets");
    let mut files = Vec::new();
    walk(&dir, &["gltf", "glb"], &mut files);
    assert!(files.len() >= 40, "found only {} files", files.len());
    let mut failures = Vec::new();
    for f in &files {
        let rel = f
            .strip_prefix(&dir)
            .unwrap_or(f)
            .to_string_lossy()
            .replace('\\', "/");
        let expected = NEEDS_UNSUPPORTED.iter().find(|(p, _)| *p == rel);
        match (load_scene(f), expected) {
            (Ok(l), None) => {
                let tris: usize = l
                    .scene
                    .objects
                    .iter()
                    .map(|o| match o.geometry {
                        Geometry::Mesh(m) => l.scene.meshes[m.index()].indices.len(),
                        Geometry::Sphere { .. } => 0,
                    })
                    .sum();
                if tris == 0 {
                    failures.push(format!("{rel}: loaded without triangles"));
                }
            }
            (Err(e), Some((_, ext))) if e.to_string().contains(ext) => {}
            (Ok(_), Some((_, ext))) => failures.push(format!("{rel}: should need {ext}")),
            (Err(e), _) => failures.push(format!("{rel}: {e}")),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn broken_validator_files_never_panic() {
    let Some(root) = assets() else { return };
    let mut files = Vec::new();
    walk(
        &root.join("gltf-validator-tests"),
        &["gltf", "glb"],
        &mut files,
    );
    assert!(files.len() >= 300, "found only {} files", files.len());
    // Count panics even where the loader's last-resort guard catches them.
    let ((ok, err), panics) = chiaro_testkit::count_panics(|| {
        let (mut ok, mut err) = (0, 0);
        for f in &files {
            let r = std::panic::catch_unwind(|| load_scene(f));
            match r {
                Ok(Ok(_)) => ok += 1,
                Ok(Err(e)) => {
                    assert!(!e.to_string().is_empty());
                    err += 1;
                }
                Err(_) => panic!("{} panicked", f.display()),
            }
        }
        (ok, err)
    });
    println!("validator files: {ok} loaded, {err} refused");
    assert_eq!(panics, 0, "the loader panicked (see stderr)");
    // Every file is either loaded or refused with a message; most have no
    // triangle at all (they test the JSON), which is refused as nothing to
    // render.
    assert_eq!(ok + err, files.len());
    assert!(err > 0);
}
