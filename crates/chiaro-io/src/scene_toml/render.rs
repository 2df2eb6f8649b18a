//! `[render]`: the render settings.

use super::raw::{Opt, RawRender, Splat3};
use super::{Ctx, span_of};
use crate::Result;
use chiaro_core::scene::{
    DepthCue, FormFactorMethod, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, MAX_SAMPLES, RadiositySettings,
    RadiositySolver, RenderSettings, ShadowMapSettings,
};

impl Ctx<'_> {
    pub(super) fn render(&self, raw: Option<RawRender>) -> Result<RenderSettings> {
        let mut r = RenderSettings::default();
        let Some(raw) = raw else { return Ok(r) };
        r.memory_limit = raw.memory_limit;
        if let Some(t) = raw.technique {
            r.technique = t;
        }
        if let Some(w) = &raw.width {
            r.width = self.in_range_u32(w, "render.width", 1, MAX_IMAGE_SIDE)?;
        }
        if let Some(h) = &raw.height {
            r.height = self.in_range_u32(h, "render.height", 1, MAX_IMAGE_SIDE)?;
        }
        if u64::from(r.width) * u64::from(r.height) > MAX_IMAGE_PIXELS {
            let span = span_of(&raw.height).or(span_of(&raw.width)).unwrap_or(0..0);
            return Err(self.at(
                span,
                format!(
                    "image {}x{} has more than {MAX_IMAGE_PIXELS} pixels",
                    r.width, r.height
                ),
            ));
        }
        if let Some(s) = &raw.samples {
            r.samples = self.in_range_u32(s, "render.samples", 1, MAX_SAMPLES)?;
        }
        if let Some(s) = &raw.light_samples {
            r.light_samples = self.in_range_u32(s, "render.light_samples", 1, MAX_SAMPLES)?;
        }
        if let Some(s) = raw.seed {
            r.seed = s;
        }
        if let Some(s) = raw.shadows {
            r.shadows = s;
        }
        r.transparency = raw.transparency;
        if let Some(a) = raw.aa {
            r.aa = a;
        }
        if let Some(f) = raw.filter {
            r.filter = f;
        }
        if let Some(t) = raw.tonemap {
            r.tonemap = t;
        }
        if let Some(e) = raw.exposure {
            r.exposure = e;
        }
        if let Some(c) = raw.cull_backfaces {
            r.cull_backfaces = c;
        }
        if let Some(dc) = raw.depth_cue {
            let d = DepthCue::default();
            let cue = DepthCue {
                color: dc.color.map_or(d.color, Splat3::vec3),
                near: dc.near.unwrap_or(d.near),
                far: dc.far.as_ref().map_or(d.far, |f| *f.get_ref()),
                max_scale: dc.max_scale.unwrap_or(d.max_scale),
                min_scale: dc.min_scale.unwrap_or(d.min_scale),
            };
            if cue.far <= cue.near {
                return Err(self.at(
                    span_of(&dc.far).unwrap_or(0..0),
                    format!(
                        "render.depth_cue: expected far > near, got near {} far {}",
                        cue.near, cue.far
                    ),
                ));
            }
            r.depth_cue = Some(cue);
        }
        if let Some(sm) = raw.shadow_map {
            let d = ShadowMapSettings::default();
            r.shadow_map = ShadowMapSettings {
                resolution: match &sm.resolution {
                    Some(v) => {
                        self.in_range_u32(v, "render.shadow_map.resolution", 1, MAX_IMAGE_SIDE)?
                    }
                    None => d.resolution,
                },
                bias: sm.bias.unwrap_or(d.bias),
                slope_bias: sm.slope_bias.unwrap_or(d.slope_bias),
                pcf_radius: sm.pcf_radius.unwrap_or(d.pcf_radius),
            };
        }
        if let Some(w) = raw.whitted {
            r.whitted = w;
        }
        if let Some(p) = raw.path {
            r.path = p;
        }
        if let Some(rad) = raw.radiosity {
            let d = RadiositySettings::default();
            // A name from `names` (the valid ones, for the message), parsed by `parse`.
            let pick = |v: &Opt<String>, what: &str, names: &[&str]| match v {
                None => Ok(None),
                Some(s) if names.contains(&s.get_ref().as_str()) => Ok(Some(s.get_ref().clone())),
                Some(s) => Err(self.at(
                    s.span(),
                    format!(
                        "{what}: unknown {:?}, expected one of: {}",
                        s.get_ref(),
                        names.join(", ")
                    ),
                )),
            };
            let solvers = RadiositySolver::ALL.map(RadiositySolver::name);
            let methods = FormFactorMethod::ALL.map(FormFactorMethod::name);
            r.radiosity = RadiositySettings {
                solver: pick(&rad.solver, "render.radiosity.solver", &solvers)?
                    .and_then(|n| RadiositySolver::from_name(&n))
                    .unwrap_or(d.solver),
                formfactor: pick(&rad.formfactor, "render.radiosity.formfactor", &methods)?
                    .and_then(|n| FormFactorMethod::from_name(&n))
                    .unwrap_or(d.formfactor),
                patch_size: match &rad.patch_size {
                    Some(v) => self.non_negative(v, "render.radiosity.patch_size")?,
                    None => d.patch_size,
                },
                hemicube_resolution: match &rad.hemicube_resolution {
                    Some(v) => self.in_range_u32(
                        v,
                        "render.radiosity.hemicube_resolution",
                        1,
                        MAX_IMAGE_SIDE,
                    )?,
                    None => d.hemicube_resolution,
                },
                tolerance: match &rad.tolerance {
                    Some(v) => self.finite_positive(v, "render.radiosity.tolerance")?,
                    None => d.tolerance,
                },
                max_iterations: rad.max_iterations.unwrap_or(d.max_iterations),
            };
        }
        Ok(r)
    }
}
