//! Wavefront OBJ + MTL, read through tobj (triangulated, one index per
//! vertex), as an [`Imported`] file: one object per OBJ group/material run.
//!
//! Negative (relative) indices and polygons of any size are handled by tobj;
//! points and lines are skipped. A missing or broken `.mtl` is a warning and
//! the default material is used. Texture coordinates are flipped
//! (`v -> 1 - v`) because chiaro's images have `v = 0` at the top row.
//!
//! # MTL mapping
//!
//! | MTL | chiaro [`Material`] |
//! | --- | --- |
//! | `Kd` | `diffuse` (default 0.8) |
//! | `Ka` | `ambient = Ka / Kd` per channel (our ka is relative to kd, so the ambient term `Ia ka kd` equals the file's `Ia Ka`); 0 where `Kd = 0`; default 0.1 |
//! | `Ks`, `Ns` | `specular`, `shininess` |
//! | `Ke` | `emission` (radiance) |
//! | `d` / `Tr` | `transmit = 1 - d` (or `Tr`) when below 1 |
//! | `Ni` | `ior` |
//! | `illum` 0, 1 | no specular (`ks = 0`) |
//! | `illum` 3, 8 | mirror: `reflect = Ks` |
//! | `illum` 4, 6, 7, 9 | glass: `reflect = Ks`, `fresnel = true` for 6 and 7 |
//! | `illum` 5 | Fresnel mirror: `reflect = Ks`, `fresnel = true` |
//! | `map_Kd` | `texture` (decoded as sRGB) |
//! | `map_Ke` | `emission_texture` (sRGB) |
//! | `map_bump`, `bump` | `bump` (height from `-bm`, default 0.02) |
//! | `norm` | `normal_map` (linear) |
//!
//! A texture that cannot be loaded is a warning, not an error.

use crate::{Imported, ImportedObject, IoError, Result};
use chiaro_core::scene::{Bump, Material, Mesh, Texture, TextureId};
use chiaro_core::{Mat4, Vec2, Vec3};
use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

fn options() -> tobj::LoadOptions {
    tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    }
}

/// Reads the OBJ file at `path` and the `.mtl` files it names (relative to
/// its directory). Returns its meshes, materials, textures and one object
/// per mesh, or an [`IoError`] naming the file when it cannot be read or
/// parsed. A missing `.mtl` or texture is a warning in [`Imported::warnings`].
pub fn load_obj_meshes(path: &Path) -> Result<Imported> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let (text, skipped) = without_points_and_lines(&String::from_utf8_lossy(&bytes));
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let loaded = tobj::load_obj_buf(&mut Cursor::new(text.as_bytes()), &options(), |mtl| {
        mtl_or_error(|| {
            let text = std::fs::read_to_string(dir.join(mtl))
                .map_err(|_| tobj::LoadError::OpenFileFailed)?;
            tobj::load_mtl_buf(&mut Cursor::new(mtl_colours(&text).as_bytes()))
        })
    });
    let mut out = build(loaded, Some(dir), path)?;
    note_skipped(&mut out, skipped, path);
    note_undefined(&mut out, &text, path);
    Ok(out)
}

/// Parses OBJ text held in memory, with the text of its material library
/// (used for any `mtllib`). `name` stands for the file in messages. Texture
/// maps cannot be resolved without a directory and are skipped with a
/// warning.
pub fn load_obj_str(obj: &str, mtl: Option<&str>, name: &str) -> Result<Imported> {
    let (text, skipped) = without_points_and_lines(obj);
    let loaded = tobj::load_obj_buf(
        &mut Cursor::new(text.as_bytes()),
        &options(),
        |_| match mtl {
            Some(text) => {
                mtl_or_error(|| tobj::load_mtl_buf(&mut Cursor::new(mtl_colours(text).as_bytes())))
            }
            None => Err(tobj::LoadError::OpenFileFailed),
        },
    );
    let path = Path::new(name);
    let mut out = build(loaded, None, path)?;
    note_skipped(&mut out, skipped, path);
    note_undefined(&mut out, &text, path);
    Ok(out)
}

/// MTL text with its `Ka`/`Kd`/`Ks`/`Ke` colours in the three-number form
/// tobj 4.0 reads (it panics on fewer, found by fuzzing): one number is a
/// grey (`Kd 0.5` = `Kd 0.5 0.5 0.5`, as the MTL format defines it); a
/// colour with none or two numbers is dropped (its default stays).
fn mtl_colours(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut words = line.split_whitespace();
        let key = words.next();
        let values: Vec<&str> = words.collect();
        match (key, values.as_slice()) {
            (Some(k @ ("Ka" | "Kd" | "Ks" | "Ke")), [v]) if v.parse::<f32>().is_ok() => {
                out.push_str(&format!("{k} {v} {v} {v}"));
            }
            (Some("Ka" | "Kd" | "Ks" | "Ke"), [] | [_, _]) => {
                out.push('#');
                out.push_str(line);
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

/// Reads a material library through `load`, turning a panic into a parse
/// error (the OBJ then loads with the default material and a warning): a
/// guard for tobj panics [`mtl_colours`] does not foresee.
fn mtl_or_error(load: impl FnOnce() -> tobj::MTLLoadResult) -> tobj::MTLLoadResult {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(load))
        .unwrap_or(Err(tobj::LoadError::MaterialParseError))
}

/// Drops `p` (point) and `l` (polyline) statements: tobj reads a polyline
/// of 3 or 4 vertices as a polygon, which would draw faces that are not in
/// the file. Returns the text and how many statements were dropped.
fn without_points_and_lines(text: &str) -> (String, usize) {
    let mut out = String::with_capacity(text.len());
    let mut skipped = 0;
    for line in text.lines() {
        let first = line.split_whitespace().next();
        if matches!(first, Some("l" | "p")) {
            skipped += 1;
            out.push('#');
        }
        out.push_str(line);
        out.push('\n');
    }
    (out, skipped)
}

/// Warns about `usemtl` names that no loaded material has (tobj drops them
/// silently and the faces get the default material).
fn note_undefined(out: &mut Imported, text: &str, path: &Path) {
    let mut missing: Vec<&str> = Vec::new();
    for line in text.lines() {
        let line = line.trim_start();
        if let Some(name) = line.strip_prefix("usemtl") {
            let name = name.trim();
            if !name.is_empty()
                && !out.materials.iter().any(|m| m.name == name)
                && !missing.contains(&name)
            {
                missing.push(name);
            }
        }
    }
    if !missing.is_empty() {
        out.warnings.push(format!(
            "{}: material(s) {} not defined: the default material is used",
            path.display(),
            missing.join(", ")
        ));
    }
}

fn note_skipped(out: &mut Imported, skipped: usize, path: &Path) {
    if skipped > 0 {
        out.warnings.push(format!(
            "{}: {skipped} point/line statement(s) skipped (only faces are drawn)",
            path.display()
        ));
    }
}

fn build(loaded: tobj::LoadResult, dir: Option<&Path>, path: &Path) -> Result<Imported> {
    let (models, materials) =
        loaded.map_err(|e| IoError::format(path, format!("OBJ parse error: {e}")))?;
    let mut out = Imported::default();
    let materials = match materials {
        Ok(m) => m,
        Err(e) => {
            // tobj reports "no mtllib" as an empty Ok list; an Err means a named library failed.
            out.warnings.push(format!(
                "{}: material library could not be read ({e}): using the default material",
                path.display()
            ));
            Vec::new()
        }
    };
    let mut images: HashMap<(PathBuf, bool), Option<TextureId>> = HashMap::new();
    for m in &materials {
        let mat = material(m, dir, path, &mut out, &mut images);
        out.materials.push(mat);
    }
    for model in models {
        let name = model.name.clone();
        let m = model.mesh;
        let n = m.positions.len() / 3;
        if m.indices.is_empty() {
            continue;
        }
        if m.positions.len() % 3 != 0 || m.indices.len() % 3 != 0 {
            return Err(IoError::format(
                path,
                format!("object {name:?}: malformed vertex or index arrays"),
            ));
        }
        if let Some(bad) = m.indices.iter().find(|&&i| i as usize >= n) {
            return Err(IoError::format(
                path,
                format!("object {name:?}: face index {bad} out of range ({n} vertices)"),
            ));
        }
        let mut mesh = Mesh {
            name: format!("{}:{name}", file_name(path)),
            positions: m
                .positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect(),
            indices: m
                .indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            ..Mesh::default()
        };
        if m.normals.len() == m.positions.len() {
            mesh.normals = m
                .normals
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]).normalize_or_zero())
                .collect();
            if mesh
                .normals
                .iter()
                .any(|v| *v == Vec3::ZERO || !v.is_finite())
            {
                out.warnings.push(format!(
                    "{}: object {name:?} has zero or invalid normals: they will be recomputed",
                    path.display()
                ));
                mesh.normals.clear();
            }
        } else if !m.normals.is_empty() {
            out.warnings.push(format!(
                "{}: object {name:?} gives normals for only some vertices: they will be recomputed",
                path.display()
            ));
        }
        if m.texcoords.len() / 2 == n && m.texcoords.len() % 2 == 0 {
            mesh.uvs = m
                .texcoords
                .chunks_exact(2)
                .map(|c| Vec2::new(c[0], 1.0 - c[1]))
                .collect();
        }
        if m.vertex_color.len() == m.positions.len() {
            mesh.colors = m
                .vertex_color
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect();
        }
        let material = m.material_id.filter(|&i| i < out.materials.len());
        if m.material_id.is_some() && material.is_none() {
            out.warnings.push(format!(
                "{}: object {name:?} uses a material that is not defined: using the default",
                path.display()
            ));
        }
        out.objects.push(ImportedObject {
            name,
            mesh: out.meshes.len(),
            matrix: Mat4::IDENTITY,
            material,
        });
        out.meshes.push(mesh);
    }
    Ok(out)
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Maps one MTL material (see the module table).
fn material(
    m: &tobj::Material,
    dir: Option<&Path>,
    path: &Path,
    out: &mut Imported,
    images: &mut HashMap<(PathBuf, bool), Option<TextureId>>,
) -> Material {
    let d = Material::default();
    let v = |a: Option<[f32; 3]>| a.map(Vec3::from);
    let kd = v(m.diffuse).unwrap_or(d.diffuse).max(Vec3::ZERO);
    let ka = v(m.ambient).map_or(d.ambient, |ka| {
        let ka = ka.max(Vec3::ZERO);
        Vec3::select(
            kd.cmpgt(Vec3::ZERO),
            ka / kd.max(Vec3::splat(1e-30)),
            Vec3::ZERO,
        )
    });
    let ks = v(m.specular).unwrap_or(d.specular).max(Vec3::ZERO);
    let mut mat = Material {
        name: m.name.clone(),
        ambient: ka,
        diffuse: kd,
        specular: ks,
        shininess: m.shininess.unwrap_or(d.shininess).max(0.0),
        emission: v(m.emissive).unwrap_or(Vec3::ZERO).max(Vec3::ZERO),
        ior: m.optical_density.filter(|x| *x > 0.0).unwrap_or(d.ior),
        ..d
    };
    let tr = m
        .unknown_param
        .get("Tr")
        .and_then(|s| s.split_whitespace().next()?.parse::<f32>().ok());
    let opacity = m.dissolve.or(tr.map(|t| 1.0 - t)).unwrap_or(1.0);
    if opacity.is_finite() && opacity < 1.0 {
        mat.transmit = Vec3::splat((1.0 - opacity).clamp(0.0, 1.0));
    }
    match m.illumination_model {
        Some(0 | 1) => mat.specular = Vec3::ZERO,
        Some(3 | 8) => mat.reflect = ks,
        Some(4 | 9) => mat.reflect = ks,
        Some(5) => {
            mat.reflect = ks;
            mat.fresnel = true;
        }
        Some(6 | 7) => {
            mat.reflect = ks;
            mat.fresnel = true;
        }
        _ => {}
    }
    // Non-finite numbers in the MTL become defaults rather than poisoning the scene.
    for c in [
        &mut mat.ambient,
        &mut mat.diffuse,
        &mut mat.specular,
        &mut mat.emission,
        &mut mat.reflect,
        &mut mat.transmit,
    ] {
        if !c.is_finite() {
            *c = Vec3::ZERO;
        }
    }
    if !mat.shininess.is_finite() {
        mat.shininess = d.shininess;
    }
    if !mat.ior.is_finite() {
        mat.ior = d.ior;
    }
    let mut tex = |spec: &str, srgb: bool| -> (Option<TextureId>, Option<f32>) {
        let (file, bm) = parse_map(spec);
        let Some(dir) = dir else {
            out.warnings.push(format!(
                "{}: texture {file:?} skipped (no directory to resolve it)",
                path.display()
            ));
            return (None, bm);
        };
        let full = crate::resolve(dir, &file);
        if let Some(id) = images.get(&(full.clone(), srgb)) {
            return (*id, bm);
        }
        let id = match crate::images::load_texture(&full, srgb) {
            Ok(img) => {
                out.textures.push(Texture::Image(img));
                Some(TextureId(out.textures.len() as u32 - 1))
            }
            Err(e) => {
                out.warnings.push(format!(
                    "{}: material {:?}: texture skipped: {e}",
                    path.display(),
                    m.name
                ));
                None
            }
        };
        images.insert((full, srgb), id);
        (id, bm)
    };
    if let Some(t) = &m.diffuse_texture {
        mat.texture = tex(t, true).0;
    }
    if let Some(t) = m.unknown_param.get("map_Ke") {
        mat.emission_texture = tex(t, true).0;
    }
    if let Some(t) = &m.normal_texture {
        let (id, bm) = tex(t, false);
        if let Some(texture) = id {
            mat.bump = Some(Bump {
                texture,
                height: bm.filter(|h| h.is_finite()).unwrap_or(0.02),
            });
        }
    }
    if let Some(t) = m.unknown_param.get("norm") {
        mat.normal_map = tex(t, false).0;
    }
    mat
}

/// Splits an MTL map statement into the file name and the `-bm` multiplier,
/// skipping the other options (`-s u v w`, `-o ...`, `-clamp on`, ...).
fn parse_map(spec: &str) -> (String, Option<f32>) {
    let words: Vec<&str> = spec.split_whitespace().collect();
    let mut bm = None;
    let mut i = 0;
    while i < words.len() && words[i].starts_with('-') && i + 1 < words.len() {
        let opt = words[i];
        i += 1;
        match opt {
            // Up to three numbers.
            "-o" | "-s" | "-t" => {
                let mut taken = 0;
                while taken < 3 && i + 1 < words.len() && words[i].parse::<f32>().is_ok() {
                    i += 1;
                    taken += 1;
                }
            }
            "-mm" => i += 2,
            "-bm" => {
                bm = words.get(i).and_then(|w| w.parse::<f32>().ok());
                i += 1;
            }
            // Every other option takes one word (`-clamp on`, `-imfchan l`, `-texres 512`).
            _ => i += 1,
        }
    }
    let file = words[i.min(words.len())..].join(" ");
    (file, bm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_options_are_skipped() {
        assert_eq!(parse_map("wood.png"), ("wood.png".into(), None));
        assert_eq!(
            parse_map("-bm 0.5 -s 1 1 1 bump map.png"),
            ("bump map.png".into(), Some(0.5))
        );
        assert_eq!(
            parse_map("-clamp on -imfchan l h.png"),
            ("h.png".into(), None)
        );
    }

    #[test]
    fn quad_with_negative_indices_and_mtl() {
        let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl red\nf -4 -3 -2 -1\n";
        let mtl =
            "newmtl red\nKa 0.2 0.1 0\nKd 0.4 0.2 0\nKs 0.5 0.5 0.5\nNs 30\nd 0.25\nillum 3\n";
        let imp = load_obj_str(obj, Some(mtl), "t.obj").expect("loads");
        assert_eq!(imp.meshes.len(), 1);
        assert_eq!(imp.meshes[0].indices, vec![[0, 1, 2], [0, 2, 3]]);
        let m = &imp.materials[0];
        assert_eq!(m.ambient, Vec3::new(0.5, 0.5, 0.0));
        assert_eq!(m.shininess, 30.0);
        assert_eq!(m.transmit, Vec3::splat(0.75));
        assert_eq!(m.reflect, Vec3::splat(0.5));
        assert_eq!(imp.objects[0].material, Some(0));
    }

    #[test]
    fn missing_mtl_is_a_warning() {
        let obj = "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n";
        let imp = load_obj_str(obj, None, "t.obj").expect("loads");
        assert_eq!(imp.objects.len(), 1);
        assert_eq!(imp.objects[0].material, None);
        assert!(!imp.warnings.is_empty());
    }

    #[test]
    fn uvs_are_flipped() {
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0.25\nvt 0 1\nf 1/1 2/2 3/3\n";
        let imp = load_obj_str(obj, None, "t.obj").expect("loads");
        assert_eq!(imp.meshes[0].uvs[1], Vec2::new(1.0, 0.75));
    }
}
