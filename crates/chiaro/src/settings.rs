//! `--set key=value`: override any render setting by its dotted path.
//!
//! Works on the serde form of [`RenderSettings`], so every field, present and
//! future, is reachable without a hand-written table, and an unknown key is
//! an error that lists the known ones.
//!
//! ```
//! let mut s = chiaro::RenderSettings::default();
//! chiaro::settings::apply_override(&mut s, "shadows", "map").unwrap();
//! chiaro::settings::apply_override(&mut s, "shadow_map.resolution", "512").unwrap();
//! assert_eq!(s.shadow_map.resolution, 512);
//! assert!(chiaro::settings::apply_override(&mut s, "shadow_map.resolutoin", "1").is_err());
//! ```

use chiaro_core::error::CoreError;
use chiaro_core::scene::{DepthCue, RenderSettings, TransparencyMode};

/// Every settable key, dotted, sorted.
pub fn known_keys() -> Vec<String> {
    let full = RenderSettings {
        transparency: Some(TransparencyMode::Filtered),
        depth_cue: Some(DepthCue::default()),
        memory_limit: Some(chiaro_core::budget::ByteSize(1)),
        light_selection: chiaro_core::scene::LightSelection::Tree,
        ..RenderSettings::default()
    };
    let mut keys = Vec::new();
    if let Ok(toml::Value::Table(t)) = toml::Value::try_from(&full) {
        collect_keys(&t, "", &mut keys);
    }
    keys.sort();
    keys
}

fn collect_keys(t: &toml::Table, prefix: &str, out: &mut Vec<String>) {
    for (k, v) in t {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(sub) => collect_keys(sub, &key, out),
            _ => out.push(key),
        }
    }
}

/// Parses a command-line value: a TOML literal (`64`, `0.5`, `true`,
/// `[0, 0, 1]`, `"x"`) or, failing that, a bare string (`map`).
fn parse_value(text: &str) -> toml::Value {
    match toml::from_str::<toml::Table>(&format!("v = {text}")) {
        Ok(mut t) => t
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(text.into())),
        Err(_) => toml::Value::String(text.into()),
    }
}

/// Sets `key` (a dotted path such as `shadow_map.resolution` or `technique`)
/// to `value` in `settings`. Errors: an unknown key (listing the known ones),
/// or a value of the wrong kind (saying what was expected).
pub fn apply_override(
    settings: &mut RenderSettings,
    key: &str,
    value: &str,
) -> Result<(), CoreError> {
    let known = known_keys();
    if !known.iter().any(|k| k == key) && !known.iter().any(|k| k.starts_with(&format!("{key}."))) {
        return Err(CoreError::UnknownSetting {
            key: key.into(),
            hint: chiaro_io::plain::suggestion(key, known.iter().map(String::as_str)),
            known: known.join(", "),
        });
    }
    let bad = |message: String| CoreError::BadSetting {
        key: key.into(),
        message,
    };
    let mut root = match toml::Value::try_from(&*settings) {
        Ok(toml::Value::Table(t)) => t,
        _ => return Err(bad("internal: settings do not serialise to a table".into())),
    };
    let parts: Vec<&str> = key.split('.').collect();
    let mut table = &mut root;
    for part in &parts[..parts.len() - 1] {
        let entry = table
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = match entry {
            toml::Value::Table(t) => t,
            _ => return Err(bad(format!("`{part}` is not a table"))),
        };
    }
    let leaf = parts[parts.len() - 1];
    table.insert(leaf.to_string(), parse_value(value));
    let parsed: RenderSettings =
        toml::Value::Table(root)
            .try_into()
            .map_err(|e: toml::de::Error| {
                bad(format!(
                    "cannot use `{value}`: {}",
                    chiaro_io::plain::plain_serde_message(e.message(), Some(leaf))
                ))
            })?;
    *settings = parsed;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::scene::{ShadowMethod, Technique};

    /// The message of an override that must be refused.
    fn refusal(s: &mut RenderSettings, key: &str, value: &str) -> String {
        apply_override(s, key, value)
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn overrides_nested_and_enum_fields() {
        let mut s = RenderSettings::default();
        apply_override(&mut s, "technique", "whitted").expect("known");
        apply_override(&mut s, "shadows", "volume").expect("known");
        apply_override(&mut s, "whitted.max_depth", "3").expect("known");
        apply_override(&mut s, "transparency", "screen-door").expect("known");
        apply_override(&mut s, "depth_cue.far", "12.5").expect("known");
        assert_eq!(s.filter, chiaro_core::scene::PixelFilter::Box);
        apply_override(&mut s, "filter", "tent").expect("known");
        assert_eq!(s.filter, chiaro_core::scene::PixelFilter::Tent);
        assert_eq!(s.technique, Technique::Whitted);
        assert_eq!(s.shadows, ShadowMethod::Volume);
        assert_eq!(s.whitted.max_depth, 3);
        assert_eq!(s.transparency, Some(TransparencyMode::ScreenDoor));
        assert_eq!(s.depth_cue.map(|d| d.far), Some(12.5));
    }

    #[test]
    fn unknown_key_lists_known_ones() {
        let mut s = RenderSettings::default();
        let msg = refusal(&mut s, "shadow", "map");
        assert!(
            msg.contains("unknown setting `shadow`")
                && msg.contains("shadows")
                && msg.contains("shadow_map.resolution"),
            "{msg}"
        );
    }

    #[test]
    fn radiosity_names_are_typed_and_a_bad_one_lists_the_valid_ones() {
        let mut s = RenderSettings::default();
        apply_override(&mut s, "radiosity.solver", "gauss-seidel").expect("known");
        apply_override(&mut s, "radiosity.formfactor", "hemicube").expect("known");
        assert_eq!(
            s.radiosity.solver,
            chiaro_core::scene::RadiositySolver::GaussSeidel
        );
        assert_eq!(
            s.radiosity.formfactor,
            chiaro_core::scene::FormFactorMethod::Hemicube
        );
        let msg = refusal(&mut s, "radiosity.solver", "magic");
        assert!(
            msg.contains("radiosity.solver") && msg.contains("gauss-seidel"),
            "{msg}"
        );
        let msg = refusal(&mut s, "radiosity.formfactor", "voodoo");
        assert!(
            msg.contains("hemicube") && msg.contains("analytic"),
            "{msg}"
        );
    }

    #[test]
    fn wrong_type_is_an_error_and_leaves_settings_alone() {
        let mut s = RenderSettings::default();
        let before = s.clone();
        assert!(apply_override(&mut s, "width", "wide").is_err());
        assert!(apply_override(&mut s, "shadows", "sometimes").is_err());
        assert_eq!(s, before);
    }
}
