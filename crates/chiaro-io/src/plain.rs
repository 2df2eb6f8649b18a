//! Messages a person reads: serde's type and key errors in plain words, with
//! "did you mean" suggestions for misspelt keys, names and values.

/// The candidate closest to `word` when it is close enough to be a likely
/// misspelling (case-insensitive; Jaro-Winkler similarity of at least 0.8,
/// or one containing the other), `None` otherwise.
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let w = word.to_ascii_lowercase();
    if w.is_empty() {
        return None;
    }
    let mut best: Option<(f64, &str)> = None;
    for c in candidates {
        let lc = c.to_ascii_lowercase();
        if lc == w {
            return Some(c);
        }
        let mut score = strsim::jaro_winkler(&w, &lc);
        if w.len() >= 3 && (lc.contains(&w) || w.contains(&lc)) {
            score = score.max(0.85);
        }
        if score >= 0.8 && best.is_none_or(|(s, _)| score > s) {
            best = Some((score, c));
        }
    }
    best.map(|(_, c)| c)
}

/// `" (did you mean `x`?)"` for [`did_you_mean`]'s answer, or an empty string.
pub fn suggestion<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    did_you_mean(word, candidates)
        .map(|c| format!(" (did you mean `{c}`?)"))
        .unwrap_or_default()
}

/// serde's message in plain words: `invalid type: string "256", expected
/// u32` becomes `` `key` must be a whole number (0 or more), got the text
/// "256" `` (`key` is the setting's name when known), and an unknown field or
/// variant gets a "did you mean". Other messages are returned unchanged.
pub fn plain_serde_message(message: &str, key: Option<&str>) -> String {
    let message = message.trim();
    let subject = key.map_or_else(|| "the value".to_string(), |k| format!("`{k}`"));
    if let Some(rest) = message
        .strip_prefix("invalid type: ")
        .or_else(|| message.strip_prefix("invalid value: "))
        && let Some((got, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "{subject} must be {}, got {}",
            plain_expected(expected),
            plain_got(got)
        );
    }
    for (prefix, what) in [("unknown field `", "key"), ("unknown variant `", "value")] {
        if let Some(rest) = message.strip_prefix(prefix)
            && let Some((word, tail)) = rest.split_once('`')
        {
            let names = expected_names(tail);
            let hint = suggestion(word, names.iter().map(String::as_str));
            let list = if names.is_empty() {
                String::new()
            } else {
                format!("; expected one of {}", names.join(", "))
            };
            return format!("unknown {what} `{word}`{hint}{list}");
        }
    }
    message.to_string()
}

/// A third-party parser's message (png, jpeg, hdr, exr, ply, gltf, toml)
/// in plain words: on one line, its decoder prefix named by format
/// (`Format error decoding Png:` becomes `corrupt PNG data:`), and any
/// `Debug` form the library printed rewritten: `Name { type: IDAT, .. }`
/// becomes `IDAT` (a struct's `type` field, else its name), and
/// `Some(x)`, `Ok(x)`, `Err(x)`, `Valid(x)` become `x`.
pub fn third_party(message: &str) -> String {
    let mut m = message.split_whitespace().collect::<Vec<_>>().join(" ");
    for (from, to) in [
        ("Format error decoding Png:", "corrupt PNG data:"),
        ("Format error decoding Jpeg:", "corrupt JPEG data:"),
        ("Format error decoding Hdr:", "corrupt Radiance HDR data:"),
        ("Format error decoding OpenExr:", "corrupt OpenEXR data:"),
        ("I/O errors ", ""),
    ] {
        m = m.replace(from, to);
    }
    for wrapper in ["Some(", "Ok(", "Err(", "Valid("] {
        while let Some(start) = find_word(&m, wrapper) {
            let open = start + wrapper.len() - 1;
            let Some(close) = matching(&m, open, '(', ')') else {
                break;
            };
            m = format!("{}{}{}", &m[..start], &m[open + 1..close], &m[close + 1..]);
        }
    }
    // `Name { field: value, .. }`, innermost last.
    while let Some(open) = m.find(" { ") {
        let name_start = m[..open].rfind([' ', '(', '\'', '"']).map_or(0, |i| i + 1);
        let name = &m[name_start..open];
        let Some(close) = matching(&m, open + 1, '{', '}') else {
            break;
        };
        let body = &m[open + 3..close];
        let keep = body
            .split(", ")
            .find_map(|f| f.strip_prefix("type: "))
            .map_or_else(|| name.to_string(), |t| t.trim().to_string());
        m = format!("{}{keep}{}", &m[..name_start], &m[close + 1..]);
    }
    m.trim().trim_end_matches('.').to_string()
}

/// The first `word` in `s` not preceded by a letter or digit (so `Some(`
/// inside `HasSome(` is left alone).
fn find_word(s: &str, word: &str) -> Option<usize> {
    s.match_indices(word).map(|(i, _)| i).find(|&i| {
        !s[..i]
            .chars()
            .next_back()
            .is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

/// The byte index of the `close` bracket matching the `open` at `at`.
fn matching(s: &str, at: usize, open: char, close: char) -> Option<usize> {
    let mut depth = 0usize;
    for (i, c) in s[at..].char_indices() {
        if c == open {
            depth += 1;
        } else if c == close {
            depth = depth.checked_sub(1)?;
            if depth == 0 {
                return Some(at + i);
            }
        }
    }
    None
}

/// The names of serde's `, expected one of `a`, `b`` (or `` expected `a` ``) tail.
fn expected_names(tail: &str) -> Vec<String> {
    let Some(i) = tail.find("expected") else {
        return Vec::new();
    };
    tail[i..]
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// serde's "expected" phrase (a Rust type or a description) in plain words.
fn plain_expected(expected: &str) -> String {
    let e = expected.trim();
    match e {
        "u8" | "u16" | "u32" | "u64" | "u128" | "usize" => "a whole number (0 or more)".into(),
        "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => "a whole number".into(),
        "f32" | "f64" => "a number".into(),
        "a boolean" => "true or false".into(),
        "a string" => "text in quotes".into(),
        _ if e.starts_with("a sequence") || e.starts_with("an array") => "a list [..]".into(),
        _ if e.starts_with("struct ") || e.starts_with("a map") => "a table { .. }".into(),
        _ => e.to_string(),
    }
}

/// serde's "invalid type" phrase for what was found, in plain words.
fn plain_got(got: &str) -> String {
    let g = got.trim();
    if let Some(s) = g.strip_prefix("string ") {
        return format!("the text {s}");
    }
    for (prefix, name) in [
        ("integer ", "the whole number"),
        ("floating point ", "the number"),
        ("boolean ", ""),
    ] {
        if let Some(v) = g.strip_prefix(prefix) {
            // `` `18446744073709551616` as i128 ``: the number alone.
            let v = v.split(" as ").next().unwrap_or(v).trim_matches('`');
            return if name.is_empty() {
                v.to_string()
            } else {
                format!("{name} {v}")
            };
        }
    }
    match g {
        "sequence" => "a list".into(),
        "map" => "a table".into(),
        _ => g.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggests_close_names_only() {
        let keys = ["diffuse", "specular", "shininess", "emission"];
        assert_eq!(did_you_mean("difuse", keys), Some("diffuse"));
        assert_eq!(did_you_mean("DIFFUSE", keys), Some("diffuse"));
        assert_eq!(did_you_mean("shinyness", keys), Some("shininess"));
        assert_eq!(did_you_mean("zzz", keys), None);
        let techniques = ["phong", "whitted", "radiosity", "hybrid", "path"];
        assert_eq!(did_you_mean("radiostiy", techniques), Some("radiosity"));
        assert_eq!(did_you_mean("", techniques), None);
    }

    #[test]
    fn type_errors_read_as_plain_words() {
        assert_eq!(
            plain_serde_message(r#"invalid type: string "256", expected u32"#, Some("width")),
            r#"`width` must be a whole number (0 or more), got the text "256""#
        );
        assert_eq!(
            plain_serde_message(
                "invalid type: integer `3`, expected a boolean",
                Some("fresnel")
            ),
            "`fresnel` must be true or false, got the whole number 3"
        );
        assert_eq!(
            plain_serde_message("invalid type: string \"x\", expected f32", None),
            "the value must be a number, got the text \"x\""
        );
        assert_eq!(
            plain_serde_message(
                "invalid type: floating point `1.5`, expected a sequence",
                Some("color")
            ),
            "`color` must be a list [..], got the number 1.5"
        );
    }

    #[test]
    fn third_party_debug_forms_are_rewritten() {
        assert_eq!(
            third_party(
                "Format error decoding Png: CRC error: expected 0x1 have 0x2 while decoding \
                 ChunkType { type: IHDR, critical: true, private: false } chunk."
            ),
            "corrupt PNG data: CRC error: expected 0x1 have 0x2 while decoding IHDR chunk"
        );
        assert_eq!(
            third_party("Encoding: Ascii, Version: Some(Version { major: 1, minor: 0 })"),
            "Encoding: Ascii, Version: Version"
        );
        assert_eq!(third_party("x: Valid(Normals)\n\tmore"), "x: Normals more");
        assert_eq!(
            plain_serde_message(
                "invalid type: integer `18446744073709551616` as i128, expected u32",
                Some("width")
            ),
            "`width` must be a whole number (0 or more), got the whole number 18446744073709551616"
        );
    }

    #[test]
    fn unknown_keys_and_values_get_a_suggestion() {
        let m = plain_serde_message(
            "unknown field `difuse`, expected one of `ambient`, `diffuse`, `specular`",
            None,
        );
        assert_eq!(
            m,
            "unknown key `difuse` (did you mean `diffuse`?); expected one of ambient, diffuse, specular"
        );
        let m = plain_serde_message(
            "unknown variant `scanlin`, expected one of `none`, `ray`, `scanline`",
            Some("shadows"),
        );
        assert!(
            m.starts_with("unknown value `scanlin` (did you mean `scanline`?)"),
            "{m}"
        );
        // Anything else is left alone.
        assert_eq!(
            plain_serde_message("missing field `x`", None),
            "missing field `x`"
        );
    }
}
