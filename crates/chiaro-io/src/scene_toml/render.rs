//! `[render]`: the render settings. serde reads the types and names; the
//! values are checked by [`RenderSettings::validate`], the one check every
//! front shares, whose issues are placed here at the setting's value in the
//! file.

use super::Ctx;
use super::raw::{RawRender, Splat3};
use crate::Result;
use chiaro_core::scene::{DepthCue, RenderSettings, Severity};

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
            light_selection,
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
    /// finds errors: every error, each at its setting's value in the file.
    /// Warnings are left to the render context, which reports them for
    /// every front.
    fn check_settings(&self, r: &RenderSettings) -> Result<()> {
        self.refuse(
            r.validate()
                .into_iter()
                .filter(|i| i.severity == Severity::Error)
                .map(|i| (self.key_span(&i.path), format!("{}: {}", i.path, i.message))),
        )
    }
}

/// Whether an issue path names a render setting (`render`, `render.samples`).
pub(super) fn is_setting(path: &str) -> bool {
    path == "render" || path.starts_with("render.")
}
