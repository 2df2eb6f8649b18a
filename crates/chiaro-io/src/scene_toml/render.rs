//! `[render]`: the render settings. serde reads the types and names; the
//! values are checked by [`RenderSettings::validate`], the one check every
//! front shares, whose issues are placed here at the setting's value in the
//! file.

use super::Ctx;
use super::raw::{RawRender, Splat3};
use crate::Result;
use chiaro_core::scene::{DepthCue, RenderSettings, Severity};
use std::collections::HashMap;
use std::ops::Range;

/// Byte spans of the keys under `[render]` by dotted setting path
/// (`render.radiosity.tolerance`): a value's span, or a table's header or
/// key, to place the issues of [`RenderSettings::validate`].
pub(super) type SettingSpans = HashMap<String, Range<usize>>;

/// Records the spans of `render` and every key below it in `root`.
pub(super) fn setting_spans(root: &toml::de::DeTable) -> SettingSpans {
    fn walk(
        path: String,
        key: Range<usize>,
        v: &toml::Spanned<toml::de::DeValue>,
        out: &mut SettingSpans,
    ) {
        let span = match v.get_ref() {
            // A table's span may be empty (dotted keys): its key then.
            toml::de::DeValue::Table(_) if v.span().is_empty() => key,
            _ => v.span(),
        };
        out.insert(path.clone(), span);
        if let toml::de::DeValue::Table(t) = v.get_ref() {
            for (k, v) in t {
                walk(format!("{path}.{}", k.get_ref()), k.span(), v, out);
            }
        }
    }
    let mut out = SettingSpans::new();
    if let Some((k, v)) = root.iter().find(|(k, _)| k.get_ref() == "render") {
        walk("render".into(), k.span(), v, &mut out);
    }
    out
}

impl Ctx<'_> {
    /// The settings of `[render]` as read (defaults for absent keys),
    /// validated by [`Self::check_settings`].
    pub(super) fn render(&self, raw: Option<RawRender>) -> Result<RenderSettings> {
        let mut r = RenderSettings::default();
        let Some(raw) = raw else { return Ok(r) };
        macro_rules! set {
            ($($field:ident),*) => {$(
                if let Some(v) = raw.$field {
                    r.$field = v;
                }
            )*};
        }
        set!(
            technique,
            width,
            height,
            samples,
            seed,
            shadows,
            aa,
            filter,
            light_samples,
            tonemap,
            exposure,
            cull_backfaces,
            shadow_map,
            whitted,
            path,
            radiosity
        );
        r.transparency = raw.transparency;
        r.memory_limit = raw.memory_limit;
        if let Some(dc) = raw.depth_cue {
            let d = DepthCue::default();
            r.depth_cue = Some(DepthCue {
                color: dc.color.map_or(d.color, Splat3::vec3),
                near: dc.near.unwrap_or(d.near),
                far: dc.far.unwrap_or(d.far),
                max_scale: dc.max_scale.unwrap_or(d.max_scale),
                min_scale: dc.min_scale.unwrap_or(d.min_scale),
            });
        }
        self.check_settings(&r)?;
        Ok(r)
    }

    /// Runs [`RenderSettings::validate`] and refuses the settings when it
    /// finds errors: every error, each at its setting's value in the file
    /// (the first one's line and column are the error's). Warnings are left
    /// to the render context, which reports them for every front.
    fn check_settings(&self, r: &RenderSettings) -> Result<()> {
        let mut errors = r
            .validate()
            .into_iter()
            .filter(|i| i.severity == Severity::Error)
            .map(|i| {
                (
                    self.setting_span(&i.path),
                    format!("{}: {}", i.path, i.message),
                )
            });
        let Some((span, first)) = errors.next() else {
            return Ok(());
        };
        let mut message = first;
        for (span, m) in errors {
            message.push_str(&format!("\n{}: {m}", self.where_(span)));
        }
        Err(self.at(span, message))
    }

    /// The span of setting `path` in the file, else of its nearest parent
    /// that is (the `[render]` table at worst), else the file's start.
    fn setting_span(&self, path: &str) -> Range<usize> {
        let mut p = path;
        loop {
            if let Some(s) = self.spans.settings.get(p) {
                return s.clone();
            }
            match p.rsplit_once('.') {
                Some((parent, _)) => p = parent,
                None => return 0..0,
            }
        }
    }
}

/// Whether an issue path names a render setting (`render`, `render.samples`).
pub(super) fn is_setting(path: &str) -> bool {
    path == "render" || path.starts_with("render.")
}
