//! Stanford PLY (ASCII, binary little- and big-endian) read through the
//! `ply-rs-bw` crate (the maintained fork of the unmaintained `ply-rs`).
//!
//! Read: the `vertex` element's `x y z`, normals `nx ny nz`, colours
//! `red green blue` (8-bit sRGB, or floats in `[0, 1]`, decoded to linear),
//! texture coordinates `u v` / `s t` / `texture_u texture_v` (flipped to
//! chiaro's top-row `v = 0`), and the `face` element's `vertex_indices` (or
//! `vertex_index`) lists, polygons fan-triangulated. Every other element and
//! property (a range scan's `confidence`, `intensity`, ...) is skipped.

use crate::{Imported, ImportedObject, IoError, Result};
use chiaro_core::budget::MemoryBudget;
use chiaro_core::film::tonemap::srgb_eotf as srgb_to_linear;
use chiaro_core::scene::Mesh;
use chiaro_core::{Mat4, Vec2, Vec3};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::path::Path;

/// Checks every `element NAME COUNT` of the header against the bytes after
/// it, before the parser sizes anything by a count (found by fuzzing: a
/// count of 5e15 in a 1 KB file aborted on allocation). Each element needs
/// at least one byte per property in binary (the list's length for a list)
/// and two in ASCII (a digit and a separator), and at least one byte.
/// Headers the check cannot read are left to the parser's own errors.
fn check_counts(bytes: &[u8]) -> std::result::Result<(), String> {
    let Some(end) = bytes.windows(10).position(|w| w == b"end_header") else {
        return Ok(());
    };
    let body = bytes[end..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(0, |nl| bytes.len() - (end + nl + 1));
    let header = String::from_utf8_lossy(&bytes[..end]);
    // Any version counts here (the parser judges it): a binary encoding, or
    // no readable format line, is held to the strict bytes-per-element bound.
    let format = |l: &str| {
        let words: Vec<&str> = l.split_whitespace().collect();
        match words.as_slice() {
            ["format", enc, ..] => Some(*enc == "ascii"),
            _ => None,
        }
    };
    let ascii = header.lines().find_map(format).unwrap_or(false);
    let mut elements: Vec<(String, u128, u128)> = Vec::new();
    for line in header.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", name, count] => {
                let Ok(count) = count.parse::<u128>() else {
                    return Ok(());
                };
                elements.push(((*name).to_owned(), count, 0));
            }
            ["property", "list", count_type, ..] => {
                if let Some(e) = elements.last_mut() {
                    e.2 += if ascii { 2 } else { type_bytes(count_type) };
                }
            }
            ["property", ty, _] => {
                if let Some(e) = elements.last_mut() {
                    e.2 += if ascii { 2 } else { type_bytes(ty) };
                }
            }
            _ => {}
        }
    }
    let mut need = 0u128;
    for (name, count, per) in &elements {
        need = need.saturating_add(count.saturating_mul((*per).max(1)));
        if need > body as u128 {
            return Err(format!(
                "element `{name}` claims {count} entries, more than the {body} bytes after the header can hold"
            ));
        }
    }
    Ok(())
}

/// The PLY parser's error in the project's words: the line (and the
/// column of the bad value where the parser says it), what was expected,
/// and what the line holds. ply-rs-bw's own text nests its grammar's
/// `Debug` output under `\tString:` and `\tError:` lines; only the facts
/// are kept.
fn parse_error(e: &ply_rs_bw::parser::ParseError, path: &Path) -> IoError {
    let text = e.to_string();
    let body = match e.line() {
        Some(n) => text.strip_prefix(&format!("Line {n}: ")).unwrap_or(&text),
        None => &text,
    };
    let headline = body.lines().next().unwrap_or_default().trim();
    // The line as the parser quotes it (`String: '...'`).
    let quoted = body
        .split_once("String: '")
        .map(|(_, rest)| rest.split('\'').next().unwrap_or_default().trim());
    // The grammar's column of the first bad character (`error at 1:5:`).
    let column = body
        .split_once("error at 1:")
        .and_then(|(_, rest)| rest.split(':').next()?.parse::<usize>().ok())
        .or_else(|| {
            let (_, rest) = body.split_once("column: ")?;
            rest.split(',').next()?.parse::<usize>().ok()
        });
    let bad_word = |line: &str, col: usize| {
        let start = line
            .char_indices()
            .take_while(|(i, _)| *i < col.saturating_sub(1))
            .filter(|(_, c)| c.is_whitespace())
            .last()
            .map_or(0, |(i, _)| i + 1);
        line[start..]
            .split_whitespace()
            .next()
            .unwrap_or_default()
            .to_string()
    };
    let has = |s: &str| body.contains(s);
    let what = if headline.starts_with("Expected magic number") {
        "expected `ply` alone on the first line".to_string()
    } else if headline.starts_with("Property") && has("without preceding element") {
        "a `property` line before any `element` line".to_string()
    } else if headline.starts_with("Found contradicting format") {
        "a second `format` line that disagrees with the first".to_string()
    } else if headline.starts_with("Invalid version") || headline.starts_with("No format line") {
        "expected a `format ascii 1.0`, `format binary_little_endian 1.0` or \
         `format binary_big_endian 1.0` line"
            .to_string()
    } else if headline.starts_with("Invalid element") {
        "expected `element NAME COUNT`".to_string()
    } else if headline.starts_with("Couldn't parse line") {
        "a header line chiaro cannot read: expected `format ...`, `element NAME COUNT`, \
         `property TYPE NAME`, `property list COUNT_TYPE TYPE NAME`, `comment ...` or \
         `end_header` (types: char, uchar, short, ushort, int, uint, float, double and \
         their int8 ... float64 names)"
            .to_string()
    } else if has("but found nothing") {
        "the line holds fewer values than the header declares".to_string()
    } else if has("Couldn't parse element line") || has("Parse error.") {
        "expected numbers separated by spaces".to_string()
    } else if has("Couldn't parse element at index") {
        "a list entry is not a number of the declared type".to_string()
    } else if has("Expected") && has("list elements") {
        "a list holds fewer entries than its count says".to_string()
    } else {
        crate::plain::third_party(headline)
    };
    let found = match (quoted, column) {
        (Some(line), Some(col)) if !line.is_empty() => {
            format!(", found `{}` in `{line}`", bad_word(line, col))
        }
        (Some(line), None) if !line.is_empty() => format!(" (the line reads `{line}`)"),
        _ => String::new(),
    };
    let message = format!("malformed PLY: {what}{found}");
    match e.line() {
        Some(line) => IoError::At {
            path: path.to_path_buf(),
            line,
            column: column.unwrap_or(1),
            message,
        },
        None => IoError::format(path, message),
    }
}

/// Bytes of one binary PLY scalar of type `ty` (1 for an unknown name: the
/// parser refuses those itself).
fn type_bytes(ty: &str) -> u128 {
    match ty {
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
        "double" | "float64" => 8,
        _ => 1,
    }
}

/// Largest PLY file read (bytes).
const MAX_FILE_BYTES: u64 = 2 << 30;

/// Reads a `.ply` file as one mesh placed at the origin with the default
/// material, or an [`IoError`] naming the file and what is wrong.
pub fn load_ply(path: &Path) -> Result<Imported> {
    let bytes = crate::files::read_file_within(path, MemoryBudget::process(), MAX_FILE_BYTES)?;
    load_ply_slice(&bytes, path)
}

/// Reads PLY bytes held in memory; `path` names the input in messages.
pub fn load_ply_slice(bytes: &[u8], path: &Path) -> Result<Imported> {
    let ply = parse(bytes, path)?;
    imported_from(&ply, path)
}

/// The scalar properties of a PLY file's `vertex` and `face` elements
/// other than those [`load_ply_slice`] reads (Mitsuba's mesh attributes:
/// `color_0`, `weight_0`, ...), by name, one value per element.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExtraProperties {
    /// Per-vertex properties.
    pub vertex: Vec<(String, Vec<f32>)>,
    /// Per-face properties.
    pub face: Vec<(String, Vec<f32>)>,
    /// For each face, how many triangles its fan gave (0 for a skipped
    /// face), in the order [`load_ply_slice`] emits them.
    pub triangles_per_face: Vec<u32>,
}

/// Reads a PLY file as [`load_ply`] does, with its [`ExtraProperties`].
pub fn load_ply_with_properties(path: &Path) -> Result<(Imported, ExtraProperties)> {
    let bytes = crate::files::read_file_within(path, MemoryBudget::process(), MAX_FILE_BYTES)?;
    let ply = parse(&bytes, path)?;
    let imported = imported_from(&ply, path)?;
    const READ: [&str; 14] = [
        "x",
        "y",
        "z",
        "nx",
        "ny",
        "nz",
        "red",
        "green",
        "blue",
        "u",
        "v",
        "s",
        "t",
        "vertex_indices",
    ];
    let extra = |name: &str| -> Vec<(String, Vec<f32>)> {
        let Some(list) = ply.payload.get(name) else {
            return Vec::new();
        };
        let Some(first) = list.first() else {
            return Vec::new();
        };
        let mut keys: Vec<&String> = first
            .iter()
            .filter(|(k, v)| !READ.contains(&k.as_str()) && scalar(v).is_some())
            .map(|(k, _)| k)
            .collect();
        keys.sort();
        keys.into_iter()
            .map(|k| {
                let vals = list
                    .iter()
                    .map(|e| e.get(k).and_then(scalar).unwrap_or(0.0) as f32)
                    .collect();
                (k.clone(), vals)
            })
            .collect()
    };
    let faces = ply.payload.get("face").map_or(&[][..], |f| &f[..]);
    let triangles_per_face = faces
        .iter()
        .map(|f| {
            let list = f.get("vertex_indices").or_else(|| f.get("vertex_index"));
            list.and_then(index_list)
                .map_or(0, |l| l.len().saturating_sub(2) as u32)
        })
        .collect();
    Ok((
        imported,
        ExtraProperties {
            vertex: extra("vertex"),
            face: extra("face"),
            triangles_per_face,
        },
    ))
}

/// Parses PLY bytes (counts checked first, a parser panic caught).
fn parse(bytes: &[u8], path: &Path) -> Result<ply_rs_bw::ply::Ply<DefaultElement>> {
    check_counts(bytes).map_err(|m| IoError::format(path, format!("malformed PLY: {m}")))?;
    // The parser is not known to panic; a panic on unforeseen input is still an error.
    let parsed = std::panic::catch_unwind(|| {
        Parser::<DefaultElement>::new().read_ply(&mut std::io::Cursor::new(bytes))
    });
    match parsed {
        Ok(Ok(p)) => Ok(p),
        Ok(Err(e)) => Err(parse_error(&e, path)),
        Err(_) => Err(IoError::format(
            path,
            "malformed PLY: the reader failed on this file",
        )),
    }
}

/// The mesh of a parsed PLY file.
fn imported_from(ply: &ply_rs_bw::ply::Ply<DefaultElement>, path: &Path) -> Result<Imported> {
    let mut warnings = Vec::new();
    let Some(vertices) = ply.payload.get("vertex") else {
        return Err(IoError::format(path, "no `vertex` element"));
    };
    let n = vertices.len();
    let mut mesh = Mesh {
        name: path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        ..Mesh::default()
    };
    let has = |k: &str| vertices.first().is_some_and(|v| v.contains_key(k));
    let uv_names = [("u", "v"), ("s", "t"), ("texture_u", "texture_v")]
        .into_iter()
        .find(|(a, b)| has(a) && has(b));
    let normals = has("nx") && has("ny") && has("nz");
    let colors = has("red") && has("green") && has("blue");
    for (i, v) in vertices.iter().enumerate() {
        let get = |k: &str| v.get(k).and_then(scalar);
        let (Some(x), Some(y), Some(z)) = (get("x"), get("y"), get("z")) else {
            return Err(IoError::format(
                path,
                format!("vertex {i}: missing or non-scalar x, y or z"),
            ));
        };
        let p = Vec3::new(x as f32, y as f32, z as f32);
        if !p.is_finite() {
            return Err(IoError::format(
                path,
                format!("vertex {i}: position is not finite"),
            ));
        }
        mesh.positions.push(p);
        if normals {
            let nv = Vec3::new(
                get("nx").unwrap_or(0.0) as f32,
                get("ny").unwrap_or(0.0) as f32,
                get("nz").unwrap_or(0.0) as f32,
            );
            mesh.normals.push(nv.normalize_or_zero());
        }
        if colors {
            let c = ["red", "green", "blue"].map(|k| match v.get(k) {
                Some(Property::UChar(b)) => srgb_to_linear(f32::from(*b) / 255.0),
                Some(Property::UShort(b)) => srgb_to_linear(f32::from(*b) / 65535.0),
                other => other
                    .and_then(scalar)
                    .map_or(1.0, |f| srgb_to_linear((f as f32).clamp(0.0, 1.0))),
            });
            mesh.colors.push(Vec3::from(c));
        }
        if let Some((u, vk)) = uv_names {
            let uv = Vec2::new(
                get(u).unwrap_or(0.0) as f32,
                1.0 - get(vk).unwrap_or(0.0) as f32,
            );
            mesh.uvs.push(if uv.is_finite() { uv } else { Vec2::ZERO });
        }
    }
    // Normals that are zero or not finite are recomputed instead.
    if mesh
        .normals
        .iter()
        .any(|v| !v.is_finite() || *v == Vec3::ZERO)
    {
        warnings.push(format!(
            "{}: some vertex normals are zero or invalid: normals will be computed",
            path.display()
        ));
        mesh.normals.clear();
    }
    let faces = ply.payload.get("face").map_or(&[][..], |f| &f[..]);
    let mut skipped = 0usize;
    for (fi, f) in faces.iter().enumerate() {
        let list = f.get("vertex_indices").or_else(|| f.get("vertex_index"));
        let Some(idx) = list.and_then(index_list) else {
            return Err(IoError::format(
                path,
                format!("face {fi}: no vertex_indices list of integers"),
            ));
        };
        if let Some(bad) = idx.iter().find(|&&i| i < 0 || i as usize >= n) {
            return Err(IoError::format(
                path,
                format!("face {fi}: vertex index {bad} out of range ({n} vertices)"),
            ));
        }
        if idx.len() < 3 {
            skipped += 1;
            continue;
        }
        let idx: Vec<u32> = idx.iter().map(|&i| i as u32).collect();
        for k in 1..idx.len() - 1 {
            mesh.indices.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    if skipped > 0 {
        warnings.push(format!(
            "{}: {skipped} faces with fewer than 3 vertices skipped",
            path.display()
        ));
    }
    if mesh.indices.is_empty() {
        return Err(IoError::format(
            path,
            "nothing to render: the file has no faces (a point cloud?)",
        ));
    }
    Ok(Imported {
        meshes: vec![mesh],
        objects: vec![ImportedObject {
            name: path
                .file_stem()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            mesh: 0,
            matrix: Mat4::IDENTITY,
            material: None,
        }],
        warnings,
        ..Imported::default()
    })
}

/// A scalar property as a float; `None` for a list.
fn scalar(p: &Property) -> Option<f64> {
    Some(match p {
        Property::Char(v) => f64::from(*v),
        Property::UChar(v) => f64::from(*v),
        Property::Short(v) => f64::from(*v),
        Property::UShort(v) => f64::from(*v),
        Property::Int(v) => f64::from(*v),
        Property::UInt(v) => f64::from(*v),
        Property::Float(v) => f64::from(*v),
        Property::Double(v) => *v,
        _ => return None,
    })
}

/// An integer list property as indices; `None` for a scalar or a float list.
fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUChar(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListShort(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUShort(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListInt(v) => v.iter().map(|&i| i64::from(i)).collect(),
        Property::ListUInt(v) => v.iter().map(|&i| i64::from(i)).collect(),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square (a quad face) with colours, normals, uvs and a scanner's
    /// `confidence`, in the given format; `body` writes the binary values.
    fn header(format: &str) -> String {
        format!(
            "ply\nformat {format} 1.0\ncomment test\nelement vertex 4\n\
             property float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float u\nproperty float v\nproperty float confidence\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        )
    }

    const VERTS: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];

    fn binary(big: bool) -> Vec<u8> {
        let fmt = if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut b = header(fmt).into_bytes();
        let f = |b: &mut Vec<u8>, x: f32| {
            b.extend(if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            })
        };
        for [x, y] in VERTS {
            for v in [x, y, 0.0, 0.0, 0.0, 1.0] {
                f(&mut b, v);
            }
            b.extend([255u8, 0, 128]);
            for v in [x, y, 0.5] {
                f(&mut b, v);
            }
        }
        b.push(4);
        for i in 0..4i32 {
            b.extend(if big {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
        b
    }

    fn check(imp: &Imported) {
        let m = &imp.meshes[0];
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        // The quad is fan-triangulated.
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.normals[1], Vec3::Z);
        // sRGB 255 / 0 / 128 decoded to linear.
        assert_eq!(m.colors[0].x, 1.0);
        assert_eq!(m.colors[0].y, 0.0);
        assert!((m.colors[0].z - 0.2158605).abs() < 1e-5, "{}", m.colors[0]);
        // v flipped to chiaro's top-row origin.
        assert_eq!(m.uvs[3], Vec2::new(0.0, 0.0));
        assert_eq!(m.uvs[0], Vec2::new(0.0, 1.0));
        assert_eq!(imp.objects.len(), 1);
    }

    #[test]
    fn ascii_and_both_binary_encodings_read_the_same_mesh() {
        let mut ascii = header("ascii");
        for [x, y] in VERTS {
            ascii.push_str(&format!("{x} {y} 0 0 0 1 255 0 128 {x} {y} 0.5\n"));
        }
        ascii.push_str("4 0 1 2 3\n");
        check(&load_ply_slice(ascii.as_bytes(), Path::new("a.ply")).expect("ascii"));
        check(&load_ply_slice(&binary(false), Path::new("le.ply")).expect("le"));
        check(&load_ply_slice(&binary(true), Path::new("be.ply")).expect("be"));
    }

    #[test]
    fn bad_files_are_errors() {
        let mut ascii = header("ascii");
        for [x, y] in VERTS {
            ascii.push_str(&format!("{x} {y} 0 0 0 1 255 0 128 {x} {y} 0.5\n"));
        }
        // An index past the vertices.
        let bad = format!("{ascii}4 0 1 2 9\n");
        let e = load_ply_slice(bad.as_bytes(), Path::new("b.ply")).expect_err("index");
        assert!(e.to_string().contains("vertex index 9"), "{e}");
        // Truncated binary data.
        let b = binary(false);
        assert!(load_ply_slice(&b[..b.len() - 5], Path::new("t.ply")).is_err());
        // Not a PLY file at all.
        assert!(load_ply_slice(b"hello", Path::new("n.ply")).is_err());
        // A point cloud has nothing to render.
        let pc = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
                  property float y\nproperty float z\nend_header\n0 0 0\n";
        let e = load_ply_slice(pc.as_bytes(), Path::new("p.ply")).expect_err("points");
        assert!(e.to_string().contains("no faces"), "{e}");
    }
}
