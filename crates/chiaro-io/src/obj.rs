//! Wavefront OBJ + MTL, read by a small parser of our own (triangulated,
//! one index per vertex), as an [`Imported`] file: one object per OBJ
//! group/material run.
//!
//! Why not tobj: its errors carry no position ("face vertex index out of
//! bounds") and one bad MTL token discards the whole library. Here an OBJ
//! error names `file:line:column`, and a bad MTL statement is a warning
//! naming `file:line` that skips that statement only, keeping the rest of
//! the material and the library (ARCHITECTURE.md, "OBJ and MTL").
//!
//! Supported: `v` (with `w`, or with an RGB vertex colour), `vt`, `vn`, `f`
//! in the `v`, `v/vt`, `v//vn`, `v/vt/vn` forms with positive or negative
//! (relative) indices, polygons of any size (fan-triangulated), `o` / `g`
//! (a new object each), `usemtl` (a new object when the material changes),
//! `mtllib` (names with spaces, or several files on one line); `s`
//! (smoothing groups) is read and ignored, since normals come from `vn` or
//! the crease angle. Points and lines are skipped with a warning. A missing
//! `.mtl` is a warning and the default material is used. Texture
//! coordinates are flipped (`v -> 1 - v`) because chiaro's images have
//! `v = 0` at the top row.
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
//! Colours take one number (grey) or three; `spectral` and `xyz` colours
//! are warnings. Other statements (`map_Ks`, `Tf`, PBR extensions) are
//! ignored. A texture that cannot be loaded is a warning, not an error.

use crate::{Imported, ImportedObject, IoError, Result};
use chiaro_core::scene::{Bump, Material, Mesh, Texture, TextureId};
use chiaro_core::{Mat4, Vec2, Vec3};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::path::{Path, PathBuf};

/// Reads the OBJ file at `path` and the `.mtl` files it names (relative to
/// its directory). Returns its meshes, materials, textures and one object
/// per mesh, or an [`IoError`] naming the file, line and column when it
/// cannot be read or parsed. A missing `.mtl`, a bad MTL statement or a
/// missing texture is a warning in [`Imported::warnings`].
pub fn load_obj_meshes(path: &Path) -> Result<Imported> {
    let bytes = crate::files::read_file(path)?;
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let text = String::from_utf8_lossy(&bytes);
    let mut out = Imported::default();
    let parsed = parse_obj(&text, path, &mut out.warnings)?;
    let mut libs: Vec<MtlMaterial> = Vec::new();
    let mut seen: Vec<PathBuf> = Vec::new();
    for lib in &parsed.mtllibs {
        for file in library_files(dir, lib) {
            if seen.contains(&file) {
                continue;
            }
            seen.push(file.clone());
            match crate::files::read_file(&file) {
                Ok(b) => {
                    let t = String::from_utf8_lossy(&b);
                    libs.extend(parse_mtl(&t, &file, &mut out.warnings));
                }
                Err(e) => out.warnings.push(format!(
                    "{}: material library could not be read ({e}): its materials are \
                     replaced by the default material",
                    path.display(),
                )),
            }
        }
    }
    build(parsed, &libs, Some(dir), path, &mut out)?;
    Ok(out)
}

/// Parses OBJ text held in memory, with the text of its material library
/// (used for any `mtllib`). `name` stands for the file in messages (the
/// library is `name` with the extension `.mtl`). Texture maps cannot be
/// resolved without a directory and are skipped with a warning.
pub fn load_obj_str(obj: &str, mtl: Option<&str>, name: &str) -> Result<Imported> {
    let path = Path::new(name);
    let mut out = Imported::default();
    let parsed = parse_obj(obj, path, &mut out.warnings)?;
    let mut libs = Vec::new();
    if !parsed.mtllibs.is_empty() {
        match mtl {
            Some(text) => libs = parse_mtl(text, &path.with_extension("mtl"), &mut out.warnings),
            None => out.warnings.push(format!(
                "{}: material library could not be read (none given): using the default material",
                path.display()
            )),
        }
    }
    build(parsed, &libs, None, path, &mut out)?;
    Ok(out)
}

/// The files an `mtllib` statement names: the whole argument when such a
/// file exists (names may hold spaces), else each word.
fn library_files(dir: &Path, arg: &str) -> Vec<PathBuf> {
    let whole = crate::resolve(dir, arg);
    if whole.is_file() || !arg.contains(char::is_whitespace) {
        return vec![whole];
    }
    arg.split_whitespace()
        .map(|w| crate::resolve(dir, w))
        .collect()
}

/// FxHash (rustc's): the vertex map's keys are small integers, which
/// SipHash would make the loader's slowest step.
#[derive(Default)]
struct FxHasher(u64);

impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

type VertexMap = HashMap<[u32; 3], u32, BuildHasherDefault<FxHasher>>;

/// No `vt` or `vn` index in a face vertex.
const NONE: u32 = u32::MAX;

/// One group/material run of faces, with its own de-duplicated vertices.
#[derive(Default)]
struct Run {
    name: String,
    material: Option<String>,
    map: VertexMap,
    keys: Vec<[u32; 3]>,
    indices: Vec<[u32; 3]>,
}

/// What the OBJ text holds, before materials are attached.
struct ParsedObj {
    positions: Vec<Vec3>,
    /// One colour per position, or empty when no `v` line has one.
    colors: Vec<Option<Vec3>>,
    uvs: Vec<Vec2>,
    normals: Vec<Vec3>,
    runs: Vec<Run>,
    mtllibs: Vec<String>,
}

/// An error at `line` (0-based) and byte offset `at` of `text`.
fn error_at(path: &Path, line_no: usize, line: &str, at: usize, message: String) -> IoError {
    IoError::At {
        path: path.to_path_buf(),
        line: line_no + 1,
        column: line.get(..at).map_or(1, |s| s.chars().count() + 1),
        message,
    }
}

/// The words of `line` with their byte offsets.
fn words(line: &str) -> impl Iterator<Item = (usize, &str)> {
    line.split_ascii_whitespace()
        .map(move |w| (w.as_ptr() as usize - line.as_ptr() as usize, w))
}

/// The text after the first word of `line`, trimmed.
fn rest_after_keyword(line: &str) -> &str {
    let t = line.trim_start();
    t.find(char::is_whitespace).map_or("", |i| t[i..].trim())
}

fn parse_obj(text: &str, path: &Path, warnings: &mut Vec<String>) -> Result<ParsedObj> {
    let mut p = ParsedObj {
        positions: Vec::new(),
        colors: Vec::new(),
        uvs: Vec::new(),
        normals: Vec::new(),
        runs: Vec::new(),
        mtllibs: Vec::new(),
    };
    let mut run = Run {
        name: "unnamed_object".into(),
        ..Run::default()
    };
    let mut skipped = 0usize;
    let mut polygon: Vec<u32> = Vec::new();
    let mut short_faces = 0usize;
    let mut dropped = 0usize;
    for (line_no, line) in text.lines().enumerate() {
        // A `#` starts a comment, also after a statement.
        let line = line.split('#').next().unwrap_or("");
        let mut ws = words(line);
        let Some((_, keyword)) = ws.next() else {
            continue;
        };
        // Up to `n` finite numbers after the keyword; errors name the word.
        let mut numbers = |min: usize, max: usize, what: &str| -> Result<([f32; 6], usize)> {
            let mut v = [0.0f32; 6];
            let mut n = 0;
            for (at, w) in ws.by_ref() {
                if n == max {
                    return Err(error_at(
                        path,
                        line_no,
                        line,
                        at,
                        format!("{keyword}: expected at most {max} numbers ({what}), got {w:?}"),
                    ));
                }
                match w.parse::<f32>() {
                    Ok(x) if x.is_finite() => v[n] = x,
                    _ => {
                        return Err(error_at(
                            path,
                            line_no,
                            line,
                            at,
                            format!("{keyword}: expected a finite number, got {w:?}"),
                        ));
                    }
                }
                n += 1;
            }
            if n < min {
                return Err(error_at(
                    path,
                    line_no,
                    line,
                    line.len(),
                    format!("{keyword}: expected {what}, got {n} number(s)"),
                ));
            }
            Ok((v, n))
        };
        match keyword {
            "v" => {
                let (v, n) = numbers(3, 6, "x y z, then w or r g b")?;
                let mut pos = Vec3::new(v[0], v[1], v[2]);
                let mut color = None;
                match n {
                    4 if v[3] != 0.0 => pos /= v[3],
                    4 => {
                        return Err(error_at(
                            path,
                            line_no,
                            line,
                            0,
                            "v: the weight w is 0".into(),
                        ));
                    }
                    6 => color = Some(Vec3::new(v[3], v[4], v[5])),
                    5 => {
                        return Err(error_at(
                            path,
                            line_no,
                            line,
                            0,
                            "v: expected x y z, then w or r g b, got 5 numbers".into(),
                        ));
                    }
                    _ => {}
                }
                if color.is_some() && p.colors.len() < p.positions.len() {
                    p.colors.resize(p.positions.len(), None);
                }
                if color.is_some() || !p.colors.is_empty() {
                    p.colors.push(color);
                }
                p.positions.push(pos);
            }
            "vt" => {
                let (v, _) = numbers(1, 3, "u [v [w]]")?;
                p.uvs.push(Vec2::new(v[0], 1.0 - v[1]));
            }
            "vn" => {
                let (v, _) = numbers(3, 3, "x y z")?;
                p.normals.push(Vec3::new(v[0], v[1], v[2]));
            }
            "f" => {
                polygon.clear();
                for (at, w) in ws {
                    let key = face_vertex(w, &p, &mut dropped)
                        .map_err(|m| error_at(path, line_no, line, at, m))?;
                    let next = run.keys.len() as u32;
                    let id = *run.map.entry(key).or_insert(next);
                    if id == next {
                        run.keys.push(key);
                    }
                    polygon.push(id);
                }
                if polygon.len() < 3 {
                    short_faces += 1;
                    continue;
                }
                for i in 1..polygon.len() - 1 {
                    run.indices.push([polygon[0], polygon[i], polygon[i + 1]]);
                }
            }
            "o" | "g" => {
                if !run.indices.is_empty() {
                    let material = run.material.clone();
                    p.runs.push(std::mem::take(&mut run));
                    run.material = material;
                }
                let name = rest_after_keyword(line);
                run.name = if name.is_empty() {
                    "unnamed_object".into()
                } else {
                    name.into()
                };
            }
            "usemtl" => {
                let name = rest_after_keyword(line);
                if name.is_empty() {
                    warnings.push(format!(
                        "{}:{}: usemtl without a name: ignored",
                        path.display(),
                        line_no + 1
                    ));
                } else if run.material.as_deref() != Some(name) {
                    if !run.indices.is_empty() {
                        let name = run.name.clone();
                        p.runs.push(std::mem::take(&mut run));
                        run.name = name;
                    }
                    run.material = Some(name.into());
                }
            }
            "mtllib" => {
                let name = rest_after_keyword(line);
                if !name.is_empty() {
                    p.mtllibs.push(name.into());
                }
            }
            "l" | "p" => skipped += 1,
            // Smoothing groups, free-form geometry and comments.
            _ => {}
        }
    }
    if !run.indices.is_empty() {
        p.runs.push(run);
    }
    if skipped > 0 {
        warnings.push(format!(
            "{}: {skipped} point/line statement(s) skipped (only faces are drawn)",
            path.display()
        ));
    }
    if dropped > 0 {
        warnings.push(format!(
            "{}: {dropped} texture coordinate or normal index(es) out of bounds: \
             those vertices are read without them",
            path.display()
        ));
    }
    if short_faces > 0 {
        warnings.push(format!(
            "{}: {short_faces} face(s) with fewer than 3 vertices skipped",
            path.display()
        ));
    }
    Ok(p)
}

/// One `v`, `v/vt`, `v//vn` or `v/vt/vn` face vertex as 0-based indices
/// ([`NONE`] where absent), or what is wrong with it. A `vt` or `vn` index
/// out of bounds is dropped and counted in `dropped`.
fn face_vertex(
    word: &str,
    p: &ParsedObj,
    dropped: &mut usize,
) -> std::result::Result<[u32; 3], String> {
    let mut key = [NONE; 3];
    let counts = [p.positions.len(), p.uvs.len(), p.normals.len()];
    let kinds = ["vertex", "texture coordinate", "normal"];
    let mut parts = word.split('/');
    for slot in 0..3 {
        let Some(part) = parts.next() else {
            break;
        };
        if part.is_empty() && slot > 0 {
            continue;
        }
        let i: i64 = part.parse().map_err(|_| {
            format!("f: expected v, v/vt, v//vn or v/vt/vn with whole numbers, got {word:?}")
        })?;
        let n = counts[slot] as i64;
        let index = if i > 0 { i - 1 } else { n + i };
        if i == 0 {
            return Err(format!(
                "f: {} index 0 in {word:?} (OBJ indices start at 1)",
                kinds[slot]
            ));
        }
        if slot > 0 && !(0..n).contains(&index) {
            // tobj read such faces without the attribute; so do we, with a warning.
            *dropped += 1;
            continue;
        }
        if !(0..n).contains(&index) {
            return Err(format!(
                "f: {} index {i} in {word:?} is out of bounds ({n} defined so far)",
                kinds[slot]
            ));
        }
        key[slot] = index as u32;
    }
    if parts.next().is_some() {
        return Err(format!("f: expected at most three indices, got {word:?}"));
    }
    Ok(key)
}

/// One `newmtl` of an MTL library, as read.
#[derive(Debug, Clone, Default, PartialEq)]
struct MtlMaterial {
    name: String,
    ambient: Option<[f32; 3]>,
    diffuse: Option<[f32; 3]>,
    specular: Option<[f32; 3]>,
    emissive: Option<[f32; 3]>,
    shininess: Option<f32>,
    optical_density: Option<f32>,
    dissolve: Option<f32>,
    tr: Option<f32>,
    illumination_model: Option<i64>,
    diffuse_texture: Option<String>,
    emissive_texture: Option<String>,
    normal_texture: Option<String>,
    norm_texture: Option<String>,
}

/// Parses an MTL library. A statement that cannot be read is a warning
/// naming `path:line` and is skipped; everything else is kept.
fn parse_mtl(text: &str, path: &Path, warnings: &mut Vec<String>) -> Vec<MtlMaterial> {
    let mut out: Vec<MtlMaterial> = Vec::new();
    for (line_no, line) in text.lines().enumerate() {
        // A `#` starts a comment, also after a statement (`Ka 1 0 0 # red`).
        let t = line.split('#').next().unwrap_or("").trim();
        let Some(keyword) = t.split_ascii_whitespace().next() else {
            continue;
        };
        let rest = rest_after_keyword(t);
        let mut warn = |msg: String| {
            warnings.push(format!(
                "{}:{}: {msg}: statement skipped",
                path.display(),
                line_no + 1
            ));
        };
        if keyword == "newmtl" {
            if rest.is_empty() {
                warn("newmtl without a name".into());
                continue;
            }
            out.push(MtlMaterial {
                name: rest.into(),
                ..MtlMaterial::default()
            });
            continue;
        }
        let Some(m) = out.last_mut() else {
            if is_mtl_statement(keyword) {
                warn(format!("{keyword} before any newmtl"));
            }
            continue;
        };
        let color = |rest: &str| -> std::result::Result<[f32; 3], String> {
            let w: Vec<&str> = rest.split_ascii_whitespace().collect();
            if matches!(w.first(), Some(&("spectral" | "xyz"))) {
                return Err(format!("{keyword} {}: only RGB colours are read", w[0]));
            }
            let v: Vec<Option<f32>> = w
                .iter()
                .map(|x| x.parse::<f32>().ok().filter(|x| x.is_finite()))
                .collect();
            match v[..] {
                [Some(g)] => Ok([g; 3]),
                [Some(r), Some(g), Some(b)] => Ok([r, g, b]),
                _ => Err(format!(
                    "{keyword}: expected r g b (or one grey value), got {rest:?}"
                )),
            }
        };
        // One number, after any options such as `d -halo 0.5`.
        let number = |rest: &str| -> std::result::Result<f32, String> {
            let w: Vec<&str> = rest
                .split_ascii_whitespace()
                .filter(|w| !w.starts_with('-') || w.parse::<f32>().is_ok())
                .collect();
            match w[..] {
                [x] => x.parse::<f32>().ok().filter(|x| x.is_finite()),
                _ => None,
            }
            .ok_or_else(|| format!("{keyword}: expected a number, got {rest:?}"))
        };
        let map = |rest: &str| -> std::result::Result<String, String> {
            if rest.is_empty() {
                Err(format!("{keyword}: expected a file name"))
            } else {
                Ok(rest.to_owned())
            }
        };
        let result = match keyword {
            "Ka" => color(rest).map(|c| m.ambient = Some(c)),
            "Kd" => color(rest).map(|c| m.diffuse = Some(c)),
            "Ks" => color(rest).map(|c| m.specular = Some(c)),
            "Ke" => color(rest).map(|c| m.emissive = Some(c)),
            "Ns" => number(rest).map(|x| m.shininess = Some(x)),
            "Ni" => number(rest).map(|x| m.optical_density = Some(x)),
            "d" => number(rest).map(|x| m.dissolve = Some(x)),
            "Tr" => number(rest).map(|x| m.tr = Some(x)),
            "illum" => rest
                .parse::<i64>()
                .map(|x| m.illumination_model = Some(x))
                .map_err(|_| format!("illum: expected a whole number, got {rest:?}")),
            "map_Kd" => map(rest).map(|f| m.diffuse_texture = Some(f)),
            "map_Ke" => map(rest).map(|f| m.emissive_texture = Some(f)),
            "map_bump" | "map_Bump" | "bump" => map(rest).map(|f| m.normal_texture = Some(f)),
            "norm" => map(rest).map(|f| m.norm_texture = Some(f)),
            _ => Ok(()),
        };
        if let Err(msg) = result {
            warn(msg);
        }
    }
    out
}

/// The MTL statements this reader maps (others are ignored silently).
fn is_mtl_statement(keyword: &str) -> bool {
    matches!(
        keyword,
        "Ka" | "Kd"
            | "Ks"
            | "Ke"
            | "Ns"
            | "Ni"
            | "d"
            | "Tr"
            | "illum"
            | "map_Kd"
            | "map_Ke"
            | "map_bump"
            | "map_Bump"
            | "bump"
            | "norm"
    )
}

fn build(
    parsed: ParsedObj,
    libs: &[MtlMaterial],
    dir: Option<&Path>,
    path: &Path,
    out: &mut Imported,
) -> Result<()> {
    let mut images: HashMap<(PathBuf, bool), Option<TextureId>> = HashMap::new();
    for m in libs {
        let mat = material(m, dir, path, out, &mut images);
        out.materials.push(mat);
    }
    let mut missing: Vec<&str> = Vec::new();
    for run in &parsed.runs {
        let name = run.name.clone();
        let n = run.keys.len();
        let colored = !parsed.colors.is_empty()
            && run.keys.iter().all(|k| {
                parsed
                    .colors
                    .get(k[0] as usize)
                    .is_some_and(Option::is_some)
            });
        let with_uv = run.keys.iter().filter(|k| k[1] != NONE).count();
        let with_normal = run.keys.iter().filter(|k| k[2] != NONE).count();
        let mut mesh = Mesh {
            name: format!("{}:{name}", file_name(path)),
            positions: run
                .keys
                .iter()
                .map(|k| parsed.positions[k[0] as usize])
                .collect(),
            indices: run.indices.clone(),
            ..Mesh::default()
        };
        if with_uv == n {
            mesh.uvs = run.keys.iter().map(|k| parsed.uvs[k[1] as usize]).collect();
        }
        if with_normal == n {
            mesh.normals = run
                .keys
                .iter()
                .map(|k| parsed.normals[k[2] as usize].normalize_or_zero())
                .collect();
            if mesh.normals.contains(&Vec3::ZERO) {
                out.warnings.push(format!(
                    "{}: object {name:?} has zero or invalid normals: they will be recomputed",
                    path.display()
                ));
                mesh.normals.clear();
            }
        } else if with_normal > 0 {
            out.warnings.push(format!(
                "{}: object {name:?} gives normals for only some vertices: they will be recomputed",
                path.display()
            ));
        }
        if colored {
            mesh.colors = run
                .keys
                .iter()
                .map(|k| parsed.colors[k[0] as usize].unwrap_or(Vec3::ONE))
                .collect();
        }
        let material = run.material.as_deref().and_then(|want| {
            let found = libs.iter().position(|m| m.name == want);
            if found.is_none() && !missing.contains(&want) {
                missing.push(want);
            }
            found
        });
        out.objects.push(ImportedObject {
            name,
            mesh: out.meshes.len(),
            matrix: Mat4::IDENTITY,
            material,
        });
        out.meshes.push(mesh);
    }
    if !missing.is_empty() {
        out.warnings.push(format!(
            "{}: material(s) {} not defined: the default material is used",
            path.display(),
            missing.join(", ")
        ));
    }
    Ok(())
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Maps one MTL material (see the module table).
fn material(
    m: &MtlMaterial,
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
    let opacity = m.dissolve.or(m.tr.map(|t| 1.0 - t)).unwrap_or(1.0);
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
    if let Some(t) = &m.emissive_texture {
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
    if let Some(t) = &m.norm_texture {
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

#[cfg(test)]
mod position_tests {
    use super::*;

    #[test]
    fn a_bad_mtl_statement_is_a_warning_with_its_line_and_the_rest_is_kept() {
        let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl b\nf 1 2 3\n";
        let mtl = "newmtl a\nKd 0.5 0.5 0.5\nnewmtl b\nKa 0 0 0c\nKd 0.2 0.4 0.6 # blue\nNs 12\n";
        let imp = load_obj_str(obj, Some(mtl), "t.obj").expect("loads");
        assert_eq!(imp.materials.len(), 2);
        let b = &imp.materials[1];
        assert_eq!(b.diffuse, Vec3::new(0.2, 0.4, 0.6));
        assert_eq!(b.shininess, 12.0);
        assert_eq!(imp.objects[0].material, Some(1));
        let w: Vec<&String> = imp.warnings.iter().filter(|w| w.contains("Ka")).collect();
        assert_eq!(w.len(), 1, "{:?}", imp.warnings);
        assert!(w[0].starts_with("t.mtl:4: Ka"), "{}", w[0]);
    }

    #[test]
    fn obj_errors_name_line_and_column() {
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1  2 7\n";
        let e = load_obj_str(obj, None, "t.obj").expect_err("out of bounds");
        assert!(
            e.to_string().starts_with("t.obj:5:8: f: vertex index 7"),
            "{e}"
        );
        let e = load_obj_str("v 0 0 0\nv 1 nan 0\n", None, "t.obj").expect_err("nan");
        assert!(
            e.to_string()
                .starts_with("t.obj:2:5: v: expected a finite number"),
            "{e}"
        );
        let e = load_obj_str("v 0 0 0\nf 0 1 1\n", None, "t.obj").expect_err("zero");
        assert!(e.to_string().starts_with("t.obj:2:3:"), "{e}");
    }

    #[test]
    fn groups_materials_and_forms_split_and_share_vertices() {
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
                   g a\nf 1/1/1 2/1/1 3/1/1\nf 1/1/1 3/1/1 4/1/1\n\
                   g b\nusemtl x\nf -4//-1 -3//-1 -2//-1\nusemtl y\nf 1 2 3 4\n";
        let imp = load_obj_str(obj, None, "t.obj").expect("loads");
        let names: Vec<&str> = imp.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["a", "b", "b"]);
        assert_eq!(imp.meshes[0].positions.len(), 4, "shared v/vt/vn vertices");
        assert_eq!(imp.meshes[0].uvs.len(), 4);
        assert_eq!(imp.meshes[1].normals.len(), 3);
        assert_eq!(imp.meshes[2].indices, vec![[0, 1, 2], [0, 2, 3]]);
    }
}
