//! Unsupported features (extensions, animations, morph targets, ...):
//! one warning each, naming the file and the JSON pointer of the first use.

use super::SUPPORTED;
use std::path::Path;

/// The features of the glTF JSON `json` that chiaro ignores or drops, one
/// warning per feature naming `path`, the JSON pointer of its first
/// occurrence and how many more there are: extensions chiaro does not
/// implement (wherever an `extensions` object names one, else their place
/// in `extensionsUsed`), animations (skins are posed at rest), morph
/// targets and weights, a light's `range`, and
/// scenes other than the one loaded. (A material whose textures read more
/// than two `texCoord` sets is warned about as its textures are read.)
pub(super) fn unsupported_features(json: &serde_json::Value, path: &Path) -> Vec<String> {
    use serde_json::Value;
    // (feature, pointers), in the order first met.
    let mut found: Vec<(String, Vec<String>)> = Vec::new();
    let mut add = |feature: String, pointer: String| match found.iter_mut().find(|f| f.0 == feature)
    {
        Some(f) => f.1.push(pointer),
        None => found.push((feature, vec![pointer])),
    };
    fn walk(v: &Value, ptr: &str, add: &mut dyn FnMut(String, String)) {
        match v {
            Value::Object(map) => {
                if let Some(Value::Object(exts)) = map.get("extensions") {
                    for k in exts.keys() {
                        if !SUPPORTED.contains(&k.as_str()) {
                            add(
                                format!("extension {k} is not supported and is ignored"),
                                format!("{ptr}/extensions/{}", escape(k)),
                            );
                        }
                    }
                }
                for (k, child) in map {
                    walk(child, &format!("{ptr}/{}", escape(k)), add);
                }
            }
            Value::Array(items) => {
                for (i, child) in items.iter().enumerate() {
                    walk(child, &format!("{ptr}/{i}"), add);
                }
            }
            _ => {}
        }
    }
    /// RFC 6901 escaping of one pointer token.
    fn escape(k: &str) -> String {
        k.replace('~', "~0").replace('/', "~1")
    }
    let array = |key: &str| {
        json.get(key)
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    walk(json, "", &mut add);
    for (i, ext) in array("extensionsUsed").iter().enumerate() {
        if let Some(ext) = ext.as_str().filter(|e| !SUPPORTED.contains(e)) {
            add(
                format!("extension {ext} is not supported and is ignored"),
                format!("/extensionsUsed/{i}"),
            );
        }
    }
    for (i, _) in array("animations").iter().enumerate() {
        add("animations are ignored".into(), format!("/animations/{i}"));
    }
    let morph = "morph targets are ignored (the base shape is loaded)";
    for (m, mesh) in array("meshes").iter().enumerate() {
        if let Some(prims) = mesh.get("primitives").and_then(Value::as_array) {
            for (p, prim) in prims.iter().enumerate() {
                if prim.get("targets").is_some() {
                    add(morph.into(), format!("/meshes/{m}/primitives/{p}/targets"));
                }
            }
        }
        if mesh.get("weights").is_some() {
            add(morph.into(), format!("/meshes/{m}/weights"));
        }
    }
    for (n, node) in array("nodes").iter().enumerate() {
        if node.get("weights").is_some() {
            add(morph.into(), format!("/nodes/{n}/weights"));
        }
    }
    let lights = json
        .pointer("/extensions/KHR_lights_punctual/lights")
        .and_then(Value::as_array);
    for (l, light) in lights.into_iter().flatten().enumerate() {
        if light.get("range").is_some() {
            add(
                "light `range` is ignored (inverse-square fall-off everywhere)".into(),
                format!("/extensions/KHR_lights_punctual/lights/{l}/range"),
            );
        }
    }
    let loaded = json.get("scene").and_then(Value::as_u64).unwrap_or(0) as usize;
    for (s, _) in array("scenes").iter().enumerate() {
        if s != loaded {
            add(
                "scenes other than the default one are not loaded".into(),
                format!("/scenes/{s}"),
            );
        }
    }
    found
        .into_iter()
        .map(|(feature, ptrs)| {
            let more = match ptrs.len() {
                1 => String::new(),
                n => format!(" (and {} more)", n - 1),
            };
            format!("{}: {feature}: at {}{more}", path.display(), ptrs[0])
        })
        .collect()
}
