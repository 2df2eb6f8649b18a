//! Buffers and their URIs: external files, base64 data URIs (RFC 2397) and
//! percent-decoding (RFC 3986), each checked before the gltf crate reads it.

use super::in_err;
use crate::Result;
use chiaro_core::budget::MemoryBudget;
use std::path::Path;

/// Reads the external buffer `uri` (a `file:` URI or a path relative to
/// `base`, percent-decoded) through [`crate::files::read_file_within`],
/// padded to a multiple of four bytes as the gltf crate pads it.
fn external_buffer(
    uri: &str,
    base: &Path,
    budget: MemoryBudget,
) -> std::result::Result<gltf::buffer::Data, String> {
    let file = if let Some(rest) = uri.strip_prefix("file://").or(uri.strip_prefix("file:")) {
        std::path::PathBuf::from(percent_decode(rest))
    } else if uri.contains(':') {
        return Err(format!(
            "unsupported URI scheme in {uri:?}: expected a relative path, file: or data:"
        ));
    } else {
        base.join(percent_decode(uri))
    };
    let mut bytes =
        crate::files::read_file_within(&file, budget, u64::MAX).map_err(|e| e.to_string())?;
    while bytes.len() % 4 != 0 {
        bytes.push(0);
    }
    Ok(gltf::buffer::Data(bytes))
}

/// Loads every buffer, checking URIs before handing them to the gltf crate.
pub(super) fn load_buffers(
    doc: &gltf::Document,
    base: Option<&Path>,
    mut blob: Option<Vec<u8>>,
    path: &Path,
    budget: MemoryBudget,
) -> Result<Vec<gltf::buffer::Data>> {
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let loc = format!("buffers[{}]", buffer.index());
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            check_uri(uri).map_err(|m| in_err(path, format!("{loc}.uri"), m))?;
            if !uri.starts_with("data:") && base.is_none() {
                return Err(in_err(
                    path,
                    format!("{loc}.uri"),
                    "external buffer without a directory",
                ));
            }
        }
        let data = match (buffer.source(), base) {
            // External files go through the one safe reader (regular files
            // only, size checked against the budget before reading).
            (gltf::buffer::Source::Uri(uri), Some(base)) if !uri.starts_with("data:") => {
                external_buffer(uri, base, budget)
                    .map_err(|m| in_err(path, format!("{loc}.uri"), m))?
            }
            (source, _) => gltf::buffer::Data::from_source_and_blob(source, base, &mut blob)
                .map_err(|e| in_err(path, loc.clone(), format!("cannot load buffer: {e}")))?,
        };
        if data.len() < buffer.length() {
            return Err(in_err(
                path,
                loc,
                format!(
                    "buffer holds {} bytes but byteLength says {}",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// A relative URI must percent-decode to UTF-8 (the gltf crate would panic otherwise).
pub(super) fn check_uri(uri: &str) -> std::result::Result<(), String> {
    if uri.contains(':') {
        return Ok(());
    }
    String::from_utf8(percent_decode_bytes(uri))
        .map(|_| ())
        .map_err(|_| format!("URI {uri:?} does not decode to UTF-8"))
}

pub(super) fn percent_decode(s: &str) -> String {
    String::from_utf8_lossy(&percent_decode_bytes(s)).into_owned()
}

/// Decodes `%XX` escapes (RFC 3986); malformed escapes are kept as they are.
fn percent_decode_bytes(s: &str) -> Vec<u8> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let Some(v) = std::str::from_utf8(&bytes[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    out
}

/// Standard base64 (RFC 4648), padding optional.
pub(super) fn decode_base64(s: &str) -> std::result::Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return Err("invalid base64 data".into()),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Ok(out)
}
