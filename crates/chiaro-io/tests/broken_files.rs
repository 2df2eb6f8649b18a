//! Every message about a broken file is in the project's words: the corpus
//! in `tests/data/broken/` (see its README) holds one small file for each
//! kind of error a third-party parser reports (ply, png, jpeg, hdr, exr,
//! gltf, toml), and no message (error or warning) may show a Rust `Debug`
//! form or leave the file unnamed.

use chiaro_io::images::load_texture;
use chiaro_testkit::assert_contains_all;
use std::path::{Path, PathBuf};

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/broken")
}

/// Fragments that only a `Debug` form prints.
const DEBUG_PATTERNS: &[&str] = &["Some(", "Ok(", "Err(", "Valid(", "as i128", "as u128"];

/// `Name { field:` (a struct's `Debug`), or one of [`DEBUG_PATTERNS`].
fn debug_form(msg: &str) -> Option<String> {
    if let Some(p) = DEBUG_PATTERNS.iter().find(|p| msg.contains(**p)) {
        return Some((*p).to_string());
    }
    let words: Vec<&str> = msg.split_whitespace().collect();
    words.windows(3).find_map(|w| {
        let name = w[0].trim_start_matches(['(', '[', '\'', '"']);
        let is_type = name.chars().next().is_some_and(char::is_uppercase)
            && name.chars().all(|c| c.is_alphanumeric() || c == ':');
        (is_type && w[1] == "{" && w[2].ends_with(':')).then(|| w.join(" "))
    })
}

#[test]
fn the_pattern_catches_debug_forms() {
    for debug in [
        "ParseError { location: LineCol { line: 1 } }",
        "Format((Ascii, Some(Version { major: 2 })))",
        "while decoding ChunkType { type: IDAT, critical: true } chunk",
        "attributes: Valid(Normals) refers to accessor 65536",
        "got the whole number 18446744073709551616` as i128",
    ] {
        assert!(debug_form(debug).is_some(), "{debug}");
    }
    for plain in [
        "x.ply:4: malformed PLY: expected a number, found `zero`",
        "scene.toml:2:9: `width` must be a whole number { 0 or more }",
    ] {
        assert_eq!(debug_form(plain), None, "{plain}");
    }
}

/// The messages (error, or warnings) of reading `path` as chiaro reads a
/// file of its kind.
fn messages(path: &Path) -> Vec<String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default();
    match ext {
        "png" | "jpg" | "hdr" | "exr" => match load_texture(path, true) {
            Ok(_) => vec![],
            Err(e) => vec![e.to_string()],
        },
        _ => match chiaro_io::load_scene(path) {
            Ok(loaded) => loaded.warnings,
            Err(e) => vec![e.to_string()],
        },
    }
}

#[test]
fn no_message_in_the_broken_corpus_shows_a_debug_form() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(corpus())
        .expect("corpus")
        .map(|e| e.expect("entry").path())
        .filter(|p| {
            let ext = p.extension().and_then(|e| e.to_str()).unwrap_or_default();
            !matches!(ext, "md" | "mtl")
        })
        .collect();
    files.sort();
    assert!(files.len() >= 30, "{} files", files.len());
    let mut failures = Vec::new();
    for path in &files {
        let msgs = messages(path);
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("?");
        println!("{name}:");
        if msgs.is_empty() {
            failures.push(format!("{name}: read without an error or warning"));
        }
        for m in &msgs {
            println!("    {m}");
            if let Some(p) = debug_form(m) {
                failures.push(format!("{name}: `{p}` in: {m}"));
            }
            if !m.contains(name) && !m.contains(".png") && !m.contains(".exr") {
                failures.push(format!("{name}: the file is not named in: {m}"));
            }
            if m.contains("\n\t") {
                failures.push(format!("{name}: a parser's indented detail in: {m}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The cases of issue 47, word for word where the issue quotes them.
#[test]
fn the_issue_cases_read_as_plain_words() {
    let msg = |f: &str| messages(&corpus().join(f)).join("\n");
    // The messages of `f` hold every one of `words`.
    let says = |f: &str, words: &[&str]| assert_contains_all(&msg(f), words);
    // A 10,000-deep table header on line 11 is reported on line 11.
    let m = msg("deep-header.toml");
    assert!(m.contains("deep-header.toml:11:"), "{m}");
    assert!(m.contains("nested"), "{m}");
    // An integer past 64 bits: no stray backtick, no `as i128`.
    let m = msg("bigint.toml");
    assert!(m.contains("bigint.toml:2:9:"), "{m}");
    assert!(
        m.contains("got the whole number 18446744073709551616") && !m.contains("616`"),
        "{m}"
    );
    // An attribute's accessor out of range names the semantic plainly.
    let m = msg("attribute-out-of-range.gltf");
    assert!(m.contains("NORMAL refers to accessor 65536"), "{m}");
    // PLY: the line and what was found.
    says("bad-float.ply", &["bad-float.ply:11:3:", "`zero`"]);
    says(
        "property-before-element.ply",
        &[":3:", "before any `element`"],
    );
    // Mitsuba XML: file, line and column, and what was expected.
    let m = msg("bad-xml.xml");
    assert!(
        m.contains("bad-xml.xml:4:3:") && m.contains("'bsdf'") && !m.contains(" at 4:3"),
        "{m}"
    );
    says(
        "unknown-plugin.xml",
        &["unknown-plugin.xml:3:3:", "\"teapot\""],
    );
    says(
        "missing-attribute.xml",
        &["missing-attribute.xml:2:3:", "filename"],
    );
    says(
        "unset-parameter.xml",
        &["unset-parameter.xml:3:5:", "$size"],
    );
    // PNG: the chunk by its name.
    let m = msg("idat-corrupt.png");
    assert!(m.contains("idat-corrupt.png") && m.contains("IDAT"), "{m}");
}
