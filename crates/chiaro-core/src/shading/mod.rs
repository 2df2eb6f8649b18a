//! The one local illumination model, shared by every technique.
//!
//! Conventions (stated once, used everywhere):
//! - `n` is the unit shading normal, `wo` the unit direction towards the
//!   viewer and `wi` the unit direction towards the light; both point away
//!   from the surface. `cos_theta_i = n . wi`.
//! - A light sample carries `intensity`: the classic `f_att * Ip * spot`
//!   factor. The radiance a surface reflects from it is
//!   `pi * f(wo, wi) * cos_theta_i * intensity`, where `f` is the BRDF in
//!   1/sr. With `f = kd / pi` this is exactly the textbook Lambert term
//!   `f_att Ip kd (N . L)`, and with inverse-square attenuation it is the
//!   physical reflected radiance (the radiometric convention, ARCHITECTURE.md).
//! - The classic Phong and Blinn specular terms are kept exact:
//!   `pi * f * cos_theta_i = ks (R . V)^n` (or `ks (N . H)^n`), i.e.
//!   `f = ks (R . V)^n / (pi cos_theta_i)`. Torrance-Sparrow is the physical
//!   microfacet BRDF `D G F / (4 cos_theta_i cos_theta_o)`.
//!
//! Techniques differ only in how they decide the *visibility* of each light
//! sample (shadow maps, shadow volumes, shadow rays, none); they all call
//! [`shade_local`] for everything else.

pub mod brdf;
pub mod bsdf;
pub mod dielectric;
pub mod fresnel;
pub mod light_set;
pub mod light_tree;
pub mod lights;
pub mod microfacet;
pub mod point;
pub mod texture;

pub use brdf::{
    SpecularFactors, SurfaceMaterial, eval_brdf_cos, mirror_reflectance, specular_cos_factored,
};
pub use bsdf::{Bsdf, BsdfSample, DeltaSplit, delta_split, luminance};
pub use fresnel::{
    fresnel_conductor, fresnel_dielectric, fresnel_schlick, reflect, refract, schlick_weight,
};
pub use light_set::{
    AliasTable, EmitterGroup, LightPowerTable, SampleKey, environment_power, group_jitter,
    light_power,
};
pub use light_tree::{LightBounds, LightSampler, LightTree};
pub use lights::{LightSample, TriangleEmitter, TriangleSample, sample_light, sample_light_pdf};
pub use point::PointLighting;

use crate::scene::{DepthCue, Light};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A surface point being shaded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingPoint {
    /// Position, world space.
    pub p: Vec3,
    /// Unit shading normal, on the side of `wo` for two-sided surfaces.
    pub n: Vec3,
    /// Unit geometric normal (same side as `n`), used to offset shadow rays.
    pub ng: Vec3,
    /// Unit direction towards the viewer.
    pub wo: Vec3,
}

/// Reflected radiance from one light sample, given its visibility (RGB
/// transmittance in `[0, 1]`: 0 shadowed, 1 lit, a colour through filters).
///
/// Returns `pi * f(wo, wi) * cos_theta_i * intensity * visibility`, linear RGB
/// radiance; zero when the light is behind the surface.
#[inline]
pub fn direct_from_sample(
    m: &SurfaceMaterial,
    sp: &ShadingPoint,
    s: &LightSample,
    visibility: Vec3,
) -> Vec3 {
    if visibility == Vec3::ZERO {
        return Vec3::ZERO;
    }
    PI * eval_brdf_cos(m, sp.n, sp.wo, s.wi) * s.intensity * visibility
}

/// The textbook ambient term `Ia * ka * kd` (ka is relative to the diffuse
/// colour, see [`crate::scene::Material::ambient`]), with the specular
/// lobe's share `ks_ambient` (zero for classic materials) added to `kd`.
#[inline]
pub fn ambient_term(m: &SurfaceMaterial, ia: Vec3) -> Vec3 {
    ia * m.ka * (m.kd + m.ks_ambient)
}

/// Sum of all ambient lights' `color * intensity`.
pub fn ambient_light(lights: &[Light]) -> Vec3 {
    lights
        .iter()
        .filter_map(|l| match l {
            Light::Ambient { .. } => Some(l.power_rgb()),
            _ => None,
        })
        .sum()
}

/// Number of samples a light gets per shading point: area lights get
/// `area_samples` (rounded to a square for stratification), others 1,
/// ambient 0.
pub fn samples_for_light(light: &Light, area_samples: u32) -> u32 {
    match light {
        Light::Ambient { .. } => 0,
        Light::Area { .. } => area_sample_count(area_samples),
        _ => 1,
    }
}

/// The samples every area light gets for the `light_samples` setting
/// `area_samples`: rounded to a square `k x k` (at least 1).
#[inline]
fn area_sample_count(area_samples: u32) -> u32 {
    let k = (area_samples.max(1) as f32).sqrt().round().max(1.0) as u32;
    k * k
}

/// The stratified 2D sample `i` of `count` (a square number) jittered by `jitter`
/// in `[0,1)^2`; with `jitter = (0.5, 0.5)` the strata centres.
#[inline]
pub fn stratum(i: u32, count: u32, jitter: Vec2) -> Vec2 {
    let k = (count as f32).sqrt().round().max(1.0) as u32;
    let (sx, sy) = (i % k, i / k);
    Vec2::new(
        (sx as f32 + jitter.x) / k as f32,
        (sy as f32 + jitter.y) / k as f32,
    )
}

/// Which sub-sample of its pixel a shading point is: a pixel of `of`
/// sub-samples spreads each light's stratified samples over them (sub-sample
/// `index` takes its share of the strata, [`SampleShare::strata`]) instead
/// of giving every sub-sample the whole set, so supersampling does not
/// multiply the light samples and the pixel still sees the full pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleShare {
    /// The sub-sample, in `0..of`.
    pub index: u32,
    /// The pixel's number of sub-samples (at least 1).
    pub of: u32,
}

impl SampleShare {
    /// A shading point that takes every light sample (one sample per pixel,
    /// a vertex, a polygon centre).
    pub const WHOLE: Self = Self { index: 0, of: 1 };

    /// Sub-sample `index` of `of` (`of` at least 1, `index` taken modulo it).
    pub fn new(index: u32, of: u32) -> Self {
        let of = of.max(1);
        Self {
            index: index % of,
            of,
        }
    }

    /// The samples of a light's `count`-sample pattern this sub-sample
    /// takes, and what their sum is divided by. With `n = of >= 2`:
    /// for `count >= n` sub-sample `s` takes samples `[ceil(s k / n),
    /// ceil((s + 1) k / n))` and divides by `k / n`; for `count < n` it
    /// takes sample `floor(s k / n)`, shared by `c` sub-samples, and divides
    /// by `k c / n`. Either way the mean over the pixel's sub-samples weighs
    /// every sample `1 / k`, as one point taking the whole pattern does.
    /// The whole share returns `(0..count, count)`.
    #[inline]
    pub fn strata(self, count: u32) -> (std::ops::Range<u32>, f32) {
        let (s, n, k) = (
            u64::from(self.index),
            u64::from(self.of.max(1)),
            u64::from(count),
        );
        if n == 1 || k == 0 {
            return (0..count, count.max(1) as f32);
        }
        let ceil_div = |a: u64, b: u64| a.div_ceil(b) as u32;
        if k >= n {
            let (lo, hi) = (ceil_div(s * k, n), ceil_div((s + 1) * k, n));
            (lo..hi, k as f32 / n as f32)
        } else {
            let i = s * k / n;
            // The sub-samples s' with floor(s' k / n) = i.
            let c = ceil_div((i + 1) * n, k) - ceil_div(i * n, k);
            let i = i as u32;
            (i..i + 1, (k * u64::from(c)) as f32 / n as f32)
        }
    }
}

/// Everything [`shade_local`] needs besides the surface.
#[derive(Debug, Clone, Copy)]
pub struct LocalLighting<'a> {
    /// The scene's lights.
    pub lights: &'a [Light],
    /// Samples per area light (squared to a stratified grid).
    pub area_samples: u32,
    /// Include the ambient term (false for direct-only comparisons with the
    /// path tracer, and for the hybrid technique, which uses radiosity).
    pub ambient: bool,
    /// The emissive triangles sampled as one light (`EmitterGroup::samples`
    /// samples chosen by power, not `area_samples` per triangle); `None`:
    /// every light on its own.
    pub group: Option<&'a EmitterGroup>,
    /// The share of each light's samples this point takes
    /// ([`SampleShare::WHOLE`] but for a pixel's sub-samples).
    pub share: SampleShare,
}

/// The local illumination model at one point: emission (if facing the
/// viewer) + ambient + the sum over lights and light samples of
/// [`direct_from_sample`].
///
/// `visibility(light_index, sample)` returns the RGB transmittance between
/// the point and the sample: this is the one thing a technique supplies.
/// `jitter(light_index, sample_index)` returns the 2D jitter in `[0,1)^2` for
/// area-light sample `sample_index` (return `(0.5, 0.5)` for strata centres).
///
/// Returns linear RGB radiance towards `wo`; never NaN for finite input.
#[inline]
pub fn shade_local(
    m: &SurfaceMaterial,
    sp: &ShadingPoint,
    env: &LocalLighting<'_>,
    jitter: impl FnMut(usize, u32) -> Vec2,
    visibility: impl FnMut(usize, &LightSample) -> Vec3,
) -> Vec3 {
    local_model::<Coloured<false>>(m, sp, env, jitter, visibility).0[0]
}

/// [`shade_local`] split into two parts in one evaluation: returns
/// `[total, rest]`, where `total` is exactly what [`shade_local`] returns and
/// `rest` is exactly what it returns for the same material with `kd = 0`
/// (emission and specular reflection: the part that does not scale with the
/// diffuse colour). `visibility` is called once per light sample, as in
/// [`shade_local`]. Flat and Gouraud shading use `total - rest` as the
/// light of an untextured surface's diffuse colour.
#[inline]
pub fn shade_local_split(
    m: &SurfaceMaterial,
    sp: &ShadingPoint,
    env: &LocalLighting<'_>,
    jitter: impl FnMut(usize, u32) -> Vec2,
    visibility: impl FnMut(usize, &LightSample) -> Vec3,
) -> [Vec3; 2] {
    local_model::<Coloured<true>>(m, sp, env, jitter, visibility).0
}

/// The local model at one point without the surface's colours: the same
/// lights, samples and visibility as [`shade_local`], summed into the parts
/// that multiply `kd`, the ambient reflectance and `ks`, so that
/// [`FactoredLight::radiance`] of a material gives (up to rounding) what
/// [`shade_local`] gives for it at this point. `m` gives the specular
/// lobe's shape (model, exponent, roughness, distribution); its colours,
/// emission and ambient reflectance are not read, and its lobe is
/// evaluated even where its `ks` is zero. Flat and Gouraud shading light a
/// textured surface this way per face or vertex and apply its colours
/// (base colour, a metal's F0) per pixel.
#[inline]
pub fn shade_local_factored(
    m: &SurfaceMaterial,
    sp: &ShadingPoint,
    env: &LocalLighting<'_>,
    jitter: impl FnMut(usize, u32) -> Vec2,
    visibility: impl FnMut(usize, &LightSample) -> Vec3,
) -> FactoredLight {
    local_model::<FactoredLight>(m, sp, env, jitter, visibility)
}

/// The light at a point as [`shade_local_factored`] sums it: radiance per
/// unit of each colour of the local model (linear RGB).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FactoredLight {
    /// What a white Lambertian surface (`kd = 1`) reflects: the sum of
    /// `cos_theta_i * intensity * visibility` over the light samples.
    pub diffuse: Vec3,
    /// The ambient light `Ia` (summed), which the ambient term scales by
    /// `ka (kd + ks_ambient)`.
    pub ambient: Vec3,
    /// The specular lobe per unit of `ks`: the sum of
    /// `pi * scale * intensity * visibility` ([`brdf::SpecularFactors`]).
    pub specular: Vec3,
    /// The specular reflection that does not depend on `ks` (Schlick's
    /// grazing term): the sum of `pi * offset * intensity * visibility`.
    pub specular_offset: Vec3,
}

impl FactoredLight {
    /// The radiance towards the viewer of a surface whose colours are those
    /// of `m` under this light: emission, the ambient term, `kd` times the
    /// diffuse light and, where `m` has a specular lobe, `ks` times the
    /// specular light plus its colourless part. Linear RGB.
    #[inline]
    pub fn radiance(&self, m: &SurfaceMaterial) -> Vec3 {
        let mut c = m.emission + ambient_term(m, self.ambient) + m.kd * self.diffuse;
        if m.has_specular() {
            c += m.ks * self.specular + self.specular_offset;
        }
        c
    }
}

/// What [`local_model`] sums: the model's terms in one form. `sample` adds
/// one light sample in front of the surface with visibility `v`;
/// `add_mean` adds a light's `sum` over its samples divided by `divisor`
/// (their count, or [`SampleShare::strata`]'s divisor).
trait Terms: Copy {
    fn start(m: &SurfaceMaterial) -> Self;
    fn zero() -> Self;
    /// True when the specular lobe is evaluated.
    fn wants_specular(m: &SurfaceMaterial) -> bool;
    fn ambient(&mut self, m: &SurfaceMaterial, ia: Vec3);
    fn sample(
        &mut self,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
        has_specular: bool,
        cos_i: f32,
        s: &LightSample,
        v: Vec3,
    );
    fn add_mean(&mut self, sum: Self, divisor: f32);
}

/// `[total, rest]` of [`shade_local`] and [`shade_local_split`]: `rest`
/// only computed when `SPLIT`, zero otherwise. Every operation on `total`
/// is the same whether or not `SPLIT`, and the operations on `rest` are
/// those `total` performs with `kd = 0` (the diffuse terms then add exact
/// zeros), so the split is exact.
#[derive(Clone, Copy)]
struct Coloured<const SPLIT: bool>([Vec3; 2]);

impl<const SPLIT: bool> Terms for Coloured<SPLIT> {
    #[inline(always)]
    fn start(m: &SurfaceMaterial) -> Self {
        Self([m.emission, if SPLIT { m.emission } else { Vec3::ZERO }])
    }

    #[inline(always)]
    fn zero() -> Self {
        Self([Vec3::ZERO; 2])
    }

    #[inline(always)]
    fn wants_specular(m: &SurfaceMaterial) -> bool {
        m.has_specular()
    }

    #[inline(always)]
    fn ambient(&mut self, m: &SurfaceMaterial, ia: Vec3) {
        self.0[0] += ambient_term(m, ia);
        if SPLIT {
            // The specular share does not scale with kd.
            self.0[1] += ia * m.ka * m.ks_ambient;
        }
    }

    /// [`direct_from_sample`] / `eval_brdf_cos` inlined with the specular
    /// lobe evaluated once for both parts.
    #[inline(always)]
    fn sample(
        &mut self,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
        has_specular: bool,
        cos_i: f32,
        s: &LightSample,
        v: Vec3,
    ) {
        let spec = if has_specular {
            brdf::specular_cos(m, sp.n, sp.wo, s.wi, cos_i)
        } else {
            Vec3::ZERO
        };
        let mut f = m.kd * (std::f32::consts::FRAC_1_PI * cos_i);
        if has_specular {
            f += spec;
        }
        // The clear coat over both (`eval_brdf_cos`).
        let (f, spec) = if m.clearcoat > 0.0 {
            let (a, coat) = brdf::clearcoat_parts(m, sp.n, sp.wo, s.wi, cos_i);
            (f * a + Vec3::splat(coat), spec * a + Vec3::splat(coat))
        } else {
            (f, spec)
        };
        self.0[0] += PI * f * s.intensity * v;
        if SPLIT {
            // eval_brdf_cos with kd = 0 is `spec` (zero without specular).
            self.0[1] += PI * spec * s.intensity * v;
        }
    }

    #[inline(always)]
    fn add_mean(&mut self, sum: Self, divisor: f32) {
        if divisor == 1.0 {
            // `x / 1.0 == x` exactly: skip the divisions.
            self.0[0] += sum.0[0];
            if SPLIT {
                self.0[1] += sum.0[1];
            }
        } else {
            self.0[0] += sum.0[0] / divisor;
            if SPLIT {
                self.0[1] += sum.0[1] / divisor;
            }
        }
    }
}

impl Terms for FactoredLight {
    #[inline(always)]
    fn start(_: &SurfaceMaterial) -> Self {
        Self::default()
    }

    #[inline(always)]
    fn zero() -> Self {
        Self::default()
    }

    #[inline(always)]
    fn wants_specular(_: &SurfaceMaterial) -> bool {
        // The colour applied later may have a lobe where this one has none.
        true
    }

    #[inline(always)]
    fn ambient(&mut self, _: &SurfaceMaterial, ia: Vec3) {
        self.ambient += ia;
    }

    /// [`direct_from_sample`] with `kd = 1` for the diffuse part and the
    /// specular lobe factored by its colour ([`brdf::specular_cos_factored`]).
    #[inline(always)]
    fn sample(
        &mut self,
        m: &SurfaceMaterial,
        sp: &ShadingPoint,
        _: bool,
        cos_i: f32,
        s: &LightSample,
        v: Vec3,
    ) {
        let light = s.intensity * v;
        let mut spec = brdf::specular_cos_factored(m, sp.n, sp.wo, s.wi, cos_i);
        let mut diffuse = std::f32::consts::FRAC_1_PI * cos_i;
        if m.clearcoat > 0.0 {
            // The clear coat attenuates both parts and adds its colourless lobe.
            let (a, coat) = brdf::clearcoat_parts(m, sp.n, sp.wo, s.wi, cos_i);
            diffuse *= a;
            spec.scale *= a;
            spec.offset = spec.offset * a + coat;
        }
        self.diffuse += PI * diffuse * light;
        self.specular += PI * spec.scale * light;
        self.specular_offset += PI * spec.offset * light;
    }

    #[inline(always)]
    fn add_mean(&mut self, sum: Self, divisor: f32) {
        let k = 1.0 / divisor;
        self.diffuse += sum.diffuse * k;
        self.ambient += sum.ambient * k;
        self.specular += sum.specular * k;
        self.specular_offset += sum.specular_offset * k;
    }
}

/// The body of [`shade_local`], [`shade_local_split`] and
/// [`shade_local_factored`]: the emission, the ambient lights and every
/// light sample summed into the terms `T`.
#[inline(always)]
fn local_model<T: Terms>(
    m: &SurfaceMaterial,
    sp: &ShadingPoint,
    env: &LocalLighting<'_>,
    mut jitter: impl FnMut(usize, u32) -> Vec2,
    mut visibility: impl FnMut(usize, &LightSample) -> Vec3,
) -> T {
    let mut out = T::start(m);
    let has_specular = T::wants_specular(m);
    // A group's lights are sampled together, after the others.
    let group = env
        .group
        .filter(|g| g.range.start < g.range.end && g.range.end <= env.lights.len());
    let (before, after) = match group {
        Some(g) => (&env.lights[..g.range.start], g.range.end),
        None => (env.lights, env.lights.len()),
    };
    let singles = before.iter().enumerate().chain(
        env.lights[after..]
            .iter()
            .enumerate()
            .map(|(k, l)| (after + k, l)),
    );
    // One light sample in front of the surface, visibility asked only there.
    let mut add = |sum: &mut T, li: usize, s: &LightSample| {
        let cos_i = s.wi.dot(sp.n);
        if cos_i <= 0.0 {
            return;
        }
        let v = visibility(li, s);
        if v == Vec3::ZERO {
            return;
        }
        sum.sample(m, sp, has_specular, cos_i, s, v);
    };
    // Every area light has the same pattern, every other light one sample:
    // their shares, found once per point.
    let area_count = area_sample_count(env.area_samples);
    let (area_share, single_share) = (env.share.strata(area_count), env.share.strata(1));
    for (li, light) in singles {
        let (count, (strata, divisor)) = match light {
            Light::Ambient { .. } => {
                if env.ambient {
                    out.ambient(m, light.power_rgb());
                }
                continue;
            }
            Light::Area { .. } => (area_count, area_share.clone()),
            _ => (1, single_share.clone()),
        };
        let mut sum = T::zero();
        for i in strata {
            let j = jitter(li, i);
            // A single sample is its stratum's jitter itself (stratum(0, 1, j) == j).
            let u = if count == 1 { j } else { stratum(i, count, j) };
            if let Some(s) = sample_light(light, sp.p, u) {
                add(&mut sum, li, &s);
            }
        }
        out.add_mean(sum, divisor);
    }
    if let Some(g) = group {
        // Each sample picks a light by power and is weighted by 1 / (pick
        // probability): the mean estimates the sum over the group's lights.
        let count = EmitterGroup::samples(env.area_samples);
        let (strata, divisor) = env.share.strata(count);
        let mut sum = T::zero();
        for i in strata {
            let (li, pick, u) = g.pick(sp.p, sp.ng, i, count, jitter(g.range.start, i));
            if pick <= 0.0 {
                continue;
            }
            if let Some(mut s) = sample_light(&env.lights[li], sp.p, u) {
                s.intensity /= pick;
                add(&mut sum, li, &s);
            }
        }
        out.add_mean(sum, divisor);
    }
    out
}

/// Depth cueing (Foley et al. 16.1.3): blend the shaded colour `c` towards
/// the cue colour by distance `d` from the eye.
pub fn depth_cue(c: Vec3, d: f32, cue: &DepthCue) -> Vec3 {
    let span = cue.far - cue.near;
    let t = if span > 0.0 {
        ((d - cue.near) / span).clamp(0.0, 1.0)
    } else if d >= cue.far {
        1.0
    } else {
        0.0
    };
    let s = cue.max_scale + (cue.min_scale - cue.max_scale) * t;
    s * c + (1.0 - s) * cue.color
}

/// Replaces NaN and infinite channels by zero and negative values by zero:
/// the guard every technique applies before writing a pixel.
#[inline]
pub fn sanitize(c: Vec3) -> Vec3 {
    // `x.is_finite() && x > 0` is `0 < x < inf` (NaN fails both), tested
    // on the three lanes at once and selected without branches.
    let v = glam::Vec3A::from(c);
    let keep = v.cmpgt(glam::Vec3A::ZERO) & v.cmplt(glam::Vec3A::INFINITY);
    glam::Vec3A::select(keep, v, glam::Vec3A::ZERO).into()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Attenuation;

    fn lambert(kd: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            kd: Vec3::splat(kd),
            ..SurfaceMaterial::default()
        }
    }

    #[test]
    fn lambert_at_known_angles() {
        let m = lambert(0.5);
        for deg in [0.0f32, 30.0, 60.0, 89.0] {
            let t = deg.to_radians();
            let light = Light::Point {
                position: Vec3::new(t.sin(), t.cos(), 0.0) * 2.0,
                color: Vec3::ONE,
                intensity: 4.0,
                attenuation: Attenuation::InverseSquare,
            };
            let sp = ShadingPoint {
                p: Vec3::ZERO,
                n: Vec3::Y,
                ng: Vec3::Y,
                wo: Vec3::Y,
            };
            let env = LocalLighting {
                lights: std::slice::from_ref(&light),
                area_samples: 1,
                ambient: true,
                group: None,
                share: SampleShare::WHOLE,
            };
            let c = shade_local(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE);
            // f_att Ip kd cos = (1/4) * 4 * 0.5 * cos
            let expect = 0.5 * t.cos();
            assert!((c.x - expect).abs() < 1e-5, "{deg}: {} vs {expect}", c.x);
        }
    }

    #[test]
    fn ambient_is_ia_ka_kd() {
        let m = SurfaceMaterial {
            ka: Vec3::splat(0.2),
            kd: Vec3::new(0.5, 1.0, 0.0),
            ..SurfaceMaterial::default()
        };
        let lights = [Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.5,
        }];
        let sp = ShadingPoint {
            p: Vec3::ZERO,
            n: Vec3::Y,
            ng: Vec3::Y,
            wo: Vec3::Y,
        };
        let env = LocalLighting {
            lights: &lights,
            area_samples: 1,
            ambient: true,
            group: None,
            share: SampleShare::WHOLE,
        };
        let c = shade_local(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE);
        assert!((c - Vec3::new(0.05, 0.1, 0.0)).length() < 1e-6);
        let env = LocalLighting {
            ambient: false,
            ..env
        };
        assert_eq!(
            shade_local(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE),
            Vec3::ZERO
        );
    }

    /// An ambient light of colour `ambient`, a point, a directional and a
    /// two-sided area light: every kind local shading sums.
    fn every_light(ambient: Vec3) -> [Light; 4] {
        use crate::scene::AreaShape;
        [
            Light::Ambient {
                color: ambient,
                intensity: 0.3,
            },
            Light::Point {
                position: Vec3::new(1.0, 3.0, 0.5),
                color: Vec3::new(1.0, 0.8, 0.6),
                intensity: 5.0,
                attenuation: Attenuation::InverseSquare,
            },
            Light::Directional {
                direction: Vec3::new(-0.3, -1.0, 0.2),
                color: Vec3::ONE,
                intensity: 0.7,
            },
            Light::Area {
                shape: AreaShape::Quad {
                    corner: Vec3::new(-1.0, 4.0, -1.0),
                    edge_u: Vec3::new(2.0, 0.0, 0.0),
                    edge_v: Vec3::new(0.0, 0.0, 2.0),
                },
                color: Vec3::ONE,
                intensity: 3.0,
                two_sided: true,
            },
        ]
    }

    /// Visibility of [`every_light`]'s samples: the area light's samples
    /// with x < 0 are partly shadowed, to exercise visibility.
    fn part_shadow(li: usize, s: &LightSample) -> Vec3 {
        if li == 3 && s.point.x < 0.0 {
            Vec3::new(0.5, 0.25, 0.0)
        } else {
            Vec3::ONE
        }
    }

    /// The reflectance models local shading evaluates.
    const MODELS: [crate::scene::ReflectanceModel; 3] = [
        crate::scene::ReflectanceModel::Phong,
        crate::scene::ReflectanceModel::Blinn,
        crate::scene::ReflectanceModel::TorranceSparrow,
    ];

    #[test]
    fn split_is_total_and_kd_zero_evaluation_exactly() {
        let lights = every_light(Vec3::ONE);
        let env = LocalLighting {
            lights: &lights,
            area_samples: 4,
            ambient: true,
            group: None,
            share: SampleShare::WHOLE,
        };
        for (k, model) in MODELS.into_iter().enumerate() {
            for ks in [0.0f32, 0.6] {
                let m = SurfaceMaterial {
                    ka: Vec3::splat(0.2),
                    kd: Vec3::new(0.7, 0.3, 0.2),
                    ks: Vec3::splat(ks),
                    shininess: 20.0 + k as f32,
                    model,
                    roughness: 0.3,
                    emission: Vec3::new(0.01, 0.0, 0.02),
                    ..SurfaceMaterial::default()
                };
                let n = Vec3::new(0.1 * k as f32, 1.0, 0.2).normalize();
                let sp = ShadingPoint {
                    p: Vec3::new(0.2, 0.0, -0.1),
                    n,
                    ng: n,
                    wo: Vec3::new(0.3, 1.0, 0.4).normalize(),
                };
                let jitter = |_: usize, _: u32| Vec2::splat(0.5);
                let [total, rest] = shade_local_split(&m, &sp, &env, jitter, part_shadow);
                let no_kd = SurfaceMaterial {
                    kd: Vec3::ZERO,
                    ..m
                };
                assert_eq!(total, shade_local(&m, &sp, &env, jitter, part_shadow));
                assert_eq!(rest, shade_local(&no_kd, &sp, &env, jitter, part_shadow));
                assert!(total.x > rest.x && rest.cmpge(m.emission).all());
            }
        }
    }

    /// The light summed without colours gives, for any colours applied
    /// afterwards, what the model gives for them: every lobe, classic and
    /// metallic-roughness colours (`ks_ambient`), emission, area lights
    /// and a partly shadowed sample.
    #[test]
    fn factored_light_gives_the_model_for_any_colours() {
        use crate::scene::MetallicRoughness;
        let lights = every_light(Vec3::new(1.0, 0.9, 0.8));
        let env = LocalLighting {
            lights: &lights,
            area_samples: 4,
            ambient: true,
            group: None,
            share: SampleShare::WHOLE,
        };
        let jitter = |_: usize, _: u32| Vec2::splat(0.5);
        let n = Vec3::new(0.1, 1.0, 0.2).normalize();
        let sp = ShadingPoint {
            p: Vec3::new(0.2, 0.0, -0.1),
            n,
            ng: n,
            wo: Vec3::new(0.3, 1.0, 0.4).normalize(),
        };
        for model in MODELS {
            let shape = SurfaceMaterial {
                model,
                shininess: 20.0,
                roughness: 0.3,
                ..SurfaceMaterial::default()
            };
            let light = shade_local_factored(&shape, &sp, &env, jitter, part_shadow);
            // Colours: classic with and without a lobe, a red metal and a
            // blue dielectric (F0 = 0.04) of metallic-roughness, emissive.
            let mut colours = vec![
                (Vec3::new(0.7, 0.3, 0.2), Vec3::splat(0.6), Vec3::ZERO),
                (Vec3::new(0.7, 0.3, 0.2), Vec3::ZERO, Vec3::ZERO),
            ];
            for metallic in [1.0, 0.0] {
                let base = Vec3::new(0.9, 0.1, 0.2).lerp(Vec3::new(0.1, 0.2, 0.9), 1.0 - metallic);
                let (kd, ks, _) = MetallicRoughness::coefficients(base, metallic, 0.5);
                colours.push((kd, ks, ks));
            }
            for (kd, ks, ks_ambient) in colours {
                let m = SurfaceMaterial {
                    ka: Vec3::new(0.9, 0.8, 0.7),
                    kd,
                    ks,
                    ks_ambient,
                    emission: Vec3::new(0.01, 0.0, 0.02),
                    ..shape
                };
                let want = shade_local(&m, &sp, &env, jitter, part_shadow);
                let got = light.radiance(&m);
                assert!(
                    (got - want).abs().max_element() <= 1e-5 * want.max_element().max(1.0),
                    "{model:?} kd {kd} ks {ks}: {got} vs {want}"
                );
                assert!(want.min_element() > 0.0);
            }
        }
    }

    #[test]
    fn shares_weigh_every_sample_once_over_the_pixel() {
        // For any pattern size k and sub-sample count n, the mean over the
        // n shares of (1 / divisor) per sample taken weighs each of the k
        // samples 1 / k, and every share takes at least one sample.
        for k in [1u32, 4, 9, 16, 25, 64] {
            for n in [1u32, 2, 3, 4, 5, 7, 16, 64, 100] {
                let mut weight = vec![0.0f64; k as usize];
                for s in 0..n {
                    let (strata, divisor) = SampleShare::new(s, n).strata(k);
                    assert!(!strata.is_empty() && strata.end <= k, "{k} {n} {s}");
                    for i in strata {
                        weight[i as usize] += 1.0 / (f64::from(n) * f64::from(divisor));
                    }
                }
                for (i, w) in weight.iter().enumerate() {
                    assert!((w * f64::from(k) - 1.0).abs() < 1e-5, "{k} {n} {i}: {w}");
                }
            }
        }
        assert_eq!(SampleShare::WHOLE.strata(16), (0..16, 16.0));
        assert_eq!(SampleShare::new(5, 3), SampleShare { index: 2, of: 3 });
    }

    #[test]
    fn shared_samples_average_to_the_whole_pattern() {
        // One point lit by every kind of light, shaded as each of n
        // sub-samples: the mean equals the point shaded with every sample,
        // and a share asks for visibility of its samples only.
        let lights = every_light(Vec3::ONE);
        let whole = LocalLighting {
            lights: &lights,
            area_samples: 16,
            ambient: true,
            group: None,
            share: SampleShare::WHOLE,
        };
        let m = SurfaceMaterial {
            kd: Vec3::new(0.7, 0.3, 0.2),
            ks: Vec3::splat(0.4),
            shininess: 20.0,
            ..SurfaceMaterial::default()
        };
        let sp = ShadingPoint {
            p: Vec3::new(0.2, 0.0, -0.1),
            n: Vec3::Y,
            ng: Vec3::Y,
            wo: Vec3::new(0.3, 1.0, 0.4).normalize(),
        };
        let jitter = |_: usize, i: u32| Vec2::new(0.3 + 0.02 * i as f32, 0.6);
        let want = shade_local(&m, &sp, &whole, jitter, part_shadow);
        for n in [2u32, 3, 16, 64] {
            let mut mean = Vec3::ZERO;
            let mut asked = 0u32;
            for s in 0..n {
                let env = LocalLighting {
                    share: SampleShare::new(s, n),
                    ..whole
                };
                mean += shade_local(&m, &sp, &env, jitter, |li, smp| {
                    asked += u32::from(li == 3);
                    part_shadow(li, smp)
                });
            }
            mean /= n as f32;
            assert!(
                (mean - want).abs().max_element() < 1e-5 * want.max_element(),
                "{n}: {mean} vs {want}"
            );
            // The area light's 16 samples, spread: max(16, n) asked in all.
            assert_eq!(asked, n.max(16), "{n}");
        }
    }

    #[test]
    fn depth_cue_blends_to_cue_colour() {
        let cue = DepthCue {
            color: Vec3::new(0.0, 0.0, 1.0),
            near: 1.0,
            far: 3.0,
            max_scale: 1.0,
            min_scale: 0.0,
        };
        assert_eq!(depth_cue(Vec3::ONE, 0.5, &cue), Vec3::ONE);
        assert_eq!(depth_cue(Vec3::ONE, 5.0, &cue), Vec3::new(0.0, 0.0, 1.0));
        assert!((depth_cue(Vec3::ONE, 2.0, &cue) - Vec3::new(0.5, 0.5, 1.0)).length() < 1e-6);
    }

    #[test]
    fn sanitize_removes_nan() {
        assert_eq!(
            sanitize(Vec3::new(f32::NAN, f32::INFINITY, -1.0)),
            Vec3::ZERO
        );
    }

    #[test]
    fn sanitize_is_the_scalar_guard_bit_for_bit() {
        let scalar = |x: f32| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        let specials = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            1.0,
            -1.0,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        let mut state = 0x853c_49e6_748f_ea9bu64;
        let mut values = specials.to_vec();
        for _ in 0..3000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            values.push(f32::from_bits((state >> 32) as u32));
        }
        for w in values.windows(3) {
            let got = sanitize(Vec3::new(w[0], w[1], w[2]));
            let want = [w[0], w[1], w[2]].map(|x| scalar(x).to_bits());
            assert_eq!(got.to_array().map(f32::to_bits), want, "{w:?}");
        }
    }
}
