//! The glTF-Asset-Generator Compatibility set (read in place from the
//! shared assets) behaves as its README says: 00-03 load (unknown root and
//! node properties and an unknown `alphaMode2` are ignored; 03's material
//! is used by no primitive, so its `alphaMode` fallback is not seen), 04 (`asset.minVersion` 2.1) and 05 (an
//! unknown required extension) are refused with the file and the reason.

#[test]
fn compatibility_files_load_or_are_refused_as_their_readme_says() {
    let Some(root) = chiaro_testkit::shared_assets() else {
        eprintln!("skipped: the shared assets folder is absent (CI has it)");
        return;
    };
    let dir = root.join("khronos-gltf-asset-generator/Compatibility");
    if !dir.exists() {
        eprintln!("skipped: {} is absent", dir.display());
        return;
    }
    let file = |i: u32| dir.join(format!("Compatibility_0{i}.gltf"));
    for i in 0..4 {
        let loaded = chiaro::io::load_scene(&file(i))
            .unwrap_or_else(|e| panic!("Compatibility_0{i} must load: {e}"));
        assert_eq!(loaded.scene.triangle_count(), 2, "Compatibility_0{i}");
    }
    for (i, want) in [
        (4, "asset.minVersion: the file requires glTF 2.1 or later"),
        (5, "FAKE_materials_quantumRendering"),
    ] {
        let e = chiaro::io::load_scene(&file(i))
            .err()
            .unwrap_or_else(|| panic!("Compatibility_0{i} must be refused"))
            .to_string();
        assert!(
            e.contains(&format!("Compatibility_0{i}.gltf")) && e.contains(want),
            "Compatibility_0{i}: {e}"
        );
    }
}
