//! The BSDF of a surface point: every lobe the scene format has (Lambert,
//! Phong, Blinn, Torrance-Sparrow with GGX or Beckmann, ideal mirror, Fresnel
//! dielectric or fixed kr/kt transmission) as three paired pure functions,
//! [`Bsdf::eval`], [`Bsdf::sample`] and [`Bsdf::pdf`], in the manner of
//! yocto-gl's `eval_bsdfcos` / `sample_bsdfcos` / `sample_bsdfcos_pdf` and
//! pbrt-v4's `BSDF`.
//!
//! The non-delta lobes are evaluated by the local model's one function,
//! [`eval_brdf_cos`]; the mirror/glass split is [`delta_split`], which the
//! Whitted tracer uses with both branches and [`Bsdf::sample`] stochastically.
//! Directions follow the module's conventions: `wo`, `wi` point away from
//! the surface, `n` is the unit shading normal on the side of `wo`.
//!
//! A Fresnel dielectric with a Torrance-Sparrow roughness of at least
//! [`MIN_ROUGH_ALPHA`] has a rough transmission lobe instead of the delta
//! one ([`super::dielectric`]): non-delta, so [`Bsdf::eval`] and
//! [`Bsdf::pdf`] see it on both sides of the surface, for the side the
//! layer was made for ([`Bsdf::seen_from`]).

use super::brdf::{SurfaceMaterial, eval_brdf_cos};
use super::dielectric::{
    MIN_ROUGH_ALPHA, rough_dielectric_eval, rough_dielectric_pdf, sample_rough_dielectric,
};
use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet;
use crate::geometry::Frame;
use crate::sampling::{
    cosine_hemisphere_pdf, phong_lobe_pdf, sample_cosine_hemisphere, sample_phong_lobe,
};
use crate::scene::Distribution;
use crate::scene::ReflectanceModel;
use glam::{Vec2, Vec3};

/// Rec. 709 luminance of a linear RGB colour: the lobe selection weight.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// The index of refraction the layer uses: `ior` when finite and positive,
/// else 1 (no bending, no reflection), so that a bad value set in code
/// (files are validated) makes a surface invisible rather than NaN.
#[inline]
pub fn valid_ior(ior: f32) -> f32 {
    if ior.is_finite() && ior > 0.0 {
        ior
    } else {
        1.0
    }
}

/// One sampled scattering direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Unit incident direction (away from the surface).
    pub wi: Vec3,
    /// Throughput multiplier: `f cos / pdf` for the non-delta lobes (with
    /// the mixture pdf), the delta lobe's weight over its probability
    /// otherwise. Its expectation over samples is the albedo for `wo`.
    pub weight: Vec3,
    /// Solid-angle pdf of the non-delta mixture at `wi` (1/sr); 0 for
    /// delta lobes.
    pub pdf: f32,
    /// True for the mirror and transmission lobes (delta distributions).
    pub delta: bool,
}

/// How [`Bsdf::sample`] chooses a lobe, fixed by the material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lobes {
    /// Selection weights: diffuse, glossy, mirror, transmission (luminances).
    /// A Fresnel dielectric's reflection is part of its transmission lobe.
    pub weights: [f32; 4],
    /// Their sum.
    pub total: f32,
    /// `wd / total` and `ws / total`: the non-delta mixture's lobe
    /// probabilities (0 when `total` is not positive).
    pub p_diffuse: f32,
    pub p_glossy: f32,
    /// The lobe choice's value when only one lobe can be chosen (the middle
    /// of its interval of `[0, total)`): its number is then not needed.
    pub single: Option<f32>,
    /// True when the specular lobe contributes (`has_specular`).
    pub specular: bool,
    /// `kd / p_diffuse`: the throughput weight of a diffuse sample of a
    /// material without specular lobe.
    pub lambert_weight: Vec3,
    /// True when the transmission lobe is the rough dielectric (a Fresnel
    /// dielectric of Torrance-Sparrow roughness at least [`MIN_ROUGH_ALPHA`];
    /// at ior 1 a thin wall), a non-delta lobe.
    pub rough: bool,
    /// `wt / total` when `rough`, else 0: the rough lobe's share of the
    /// non-delta mixture.
    pub p_transmission: f32,
    /// The clear coat's share of the lobe choice (its selection weight,
    /// [`COAT_SELECTION`] times the coat's weight, over `total`); 0 without
    /// a coat. The coat's interval of `[0, total)` is the last.
    pub p_coat: f32,
}

/// Selection weight of a clear coat of weight 1: about its reflectance
/// averaged over the hemisphere and grazing views, so that its sharp
/// highlight is sampled without starving the base.
pub const COAT_SELECTION: f32 = 0.25;

impl Lobes {
    /// The lobe choice of `m` (`fresnel`: the material's Fresnel flag).
    pub fn new(m: &SurfaceMaterial, fresnel: bool) -> Self {
        let t = luminance(m.kt);
        let r = if fresnel && t > 0.0 {
            0.0
        } else {
            luminance(m.kr)
        };
        let weights = [luminance(m.kd), luminance(m.ks), r, t];
        let [wd, ws, wr, wt] = weights;
        let wc = if m.clearcoat > 0.0 {
            COAT_SELECTION * m.clearcoat
        } else {
            0.0
        };
        let total = wd + ws + wr + wt + wc;
        // (With `total > 0`, a lone non-zero weight is the positive one.)
        let single = wc == 0.0 && weights.iter().filter(|&&w| w != 0.0).count() == 1;
        let single = match weights.iter().position(|&w| w > 0.0) {
            Some(k) if single => Some(weights[..k].iter().sum::<f32>() + 0.5 * weights[k]),
            _ => None,
        };
        let (p_diffuse, p_glossy) = if total > 0.0 {
            (wd / total, ws / total)
        } else {
            (0.0, 0.0)
        };
        let rough = fresnel
            && t > 0.0
            && m.model == ReflectanceModel::TorranceSparrow
            && m.roughness >= MIN_ROUGH_ALPHA;
        Self {
            rough,
            p_transmission: if rough && total > 0.0 {
                wt / total
            } else {
                0.0
            },
            p_coat: if total > 0.0 { wc / total } else { 0.0 },
            weights,
            total,
            p_diffuse,
            p_glossy,
            single,
            specular: m.has_specular(),
            lambert_weight: m.kd / p_diffuse,
        }
    }
}

/// The scattering function at a surface point: the material's parameters
/// there, its Fresnel flag and the lobe choice derived from them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bsdf {
    /// The material's parameters at the point.
    pub m: SurfaceMaterial,
    /// Transmission is a Fresnel dielectric (`Material::fresnel`).
    pub fresnel: bool,
    /// The lobe choice.
    pub lobes: Lobes,
    /// The relative index of refraction across the surface seen from the
    /// side the layer is evaluated for ([`Self::seen_from`]): `ior` from
    /// outside (the default), `1 / ior` from inside. Read by the rough
    /// dielectric lobe's [`Self::eval`] and [`Self::pdf`] only.
    pub eta: f32,
}

impl Bsdf {
    /// The BSDF of `m` with the material's Fresnel flag.
    pub fn new(m: SurfaceMaterial, fresnel: bool) -> Self {
        Self {
            lobes: Lobes::new(&m, fresnel),
            eta: valid_ior(m.ior),
            m,
            fresnel,
        }
    }

    /// The layer as seen from outside (`front`) or from inside the surface:
    /// [`Self::eta`] is `ior` or `1 / ior`.
    #[inline]
    pub fn seen_from(self, front: bool) -> Self {
        let ior = valid_ior(self.m.ior);
        Self {
            eta: if front { ior } else { 1.0 / ior },
            ..self
        }
    }

    /// False when the material scatters nothing (every lobe weight zero):
    /// [`Self::sample`] then returns `None` without reading its numbers.
    #[inline]
    pub fn scatters(&self) -> bool {
        self.lobes.total > 0.0 || self.lobes.total.is_nan()
    }

    /// True when [`Self::sample`] reads its lobe number `u_lobe` (more than
    /// one lobe to choose from). A caller whose sampler stratifies decisions
    /// skips the number otherwise, so that later decisions keep theirs.
    #[inline]
    pub fn needs_lobe_number(&self) -> bool {
        self.lobes.single.is_none()
    }

    /// `f(wo, wi) |cos_theta_i|` of the non-delta lobes (1/sr):
    /// [`eval_brdf_cos`], plus the rough dielectric's reflection and
    /// refraction (for the side of [`Self::eta`]). Delta lobes contribute
    /// nothing to any given `wi`.
    #[inline]
    pub fn eval(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_eta(n, wo, wi, self.eta)
    }

    /// [`Self::eval`] across a relative index `eta`.
    #[inline]
    fn eval_eta(&self, n: Vec3, wo: Vec3, wi: Vec3, eta: f32) -> Vec3 {
        let f = eval_brdf_cos(&self.m, n, wo, wi);
        if !self.lobes.rough {
            return f;
        }
        let m = &self.m;
        f + rough_dielectric_eval(m.distribution, m.roughness, eta, m.kt, n, wo, wi)
    }

    /// Solid-angle pdf (1/sr) with which [`Self::sample`] returns `wi`
    /// through its non-delta lobes (the probability of choosing a lobe
    /// times its pdf); 0 below the surface unless the rough dielectric
    /// refracts there (for the side of [`Self::eta`]). For MIS.
    #[inline]
    pub fn pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        self.pdf_eta(n, wo, wi, self.eta)
    }

    /// [`Self::pdf`] across a relative index `eta`.
    #[inline]
    fn pdf_eta(&self, n: Vec3, wo: Vec3, wi: Vec3, eta: f32) -> f32 {
        let lobes = &self.lobes;
        if lobes.total <= 0.0 {
            return 0.0;
        }
        let rough = || {
            let m = &self.m;
            lobes.p_transmission * rough_dielectric_pdf(m.distribution, m.roughness, eta, n, wo, wi)
        };
        let cos_i = n.dot(wi);
        if cos_i <= 0.0 {
            return if lobes.rough { rough() } else { 0.0 };
        }
        let mut pdf = lobes.p_diffuse * cosine_hemisphere_pdf(cos_i);
        if lobes.weights[1] > 0.0 {
            pdf += lobes.p_glossy * glossy_pdf(&self.m, n, wo, wi);
        }
        if lobes.rough {
            pdf += rough();
        }
        if lobes.p_coat > 0.0 {
            pdf += lobes.p_coat
                * microfacet::reflection_pdf(Distribution::Ggx, self.m.clearcoat_alpha, n, wo, wi);
        }
        pdf
    }

    /// A direction `wi` drawn from one of the non-delta lobes, weighted by
    /// the whole mixture: `f cos / pdf` with the mixture's pdf.
    fn mixture_sample(&self, n: Vec3, wo: Vec3, wi: Vec3, eta: f32) -> Option<BsdfSample> {
        let pdf = self.pdf_eta(n, wo, wi, eta);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight: self.eval_eta(n, wo, wi, eta) / pdf,
            pdf,
            delta: false,
        })
    }

    /// Samples an incident direction for `wo`: a lobe chosen in proportion
    /// to its weight's luminance by `u_lobe` in `[0, 1)` (not read when
    /// [`Self::needs_lobe_number`] is false), its direction from `u` in
    /// `[0, 1)^2`, and for a Fresnel dielectric the choice between reflection
    /// and refraction from `u_fresnel()`, called only when both are possible
    /// (so a caller draws that number only then).
    ///
    /// `n` and `ng` are the unit shading and geometric normals on the side
    /// of `wo`; `front` is true when `wo` is outside the surface (the
    /// transmission lobe then enters the medium). `None` when the material
    /// scatters nothing or the direction falls below either normal's
    /// horizon (the sample is lost: [`Self::pdf`] does not renormalise).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn sample(
        &self,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        front: bool,
        u_lobe: f32,
        u: Vec2,
        u_fresnel: impl FnOnce() -> f32,
    ) -> Option<BsdfSample> {
        let (m, lobes, fresnel) = (&self.m, &self.lobes, self.fresnel);
        let [wd, ws, wr, wt] = lobes.weights;
        let total = lobes.total;
        if total <= 0.0 {
            return None;
        }
        let pick = match lobes.single {
            Some(pick) => pick,
            None => u_lobe * total,
        };
        // The relative index across the surface from the side of `wo` (read
        // by the rough dielectric only).
        let eta = match (lobes.rough, front) {
            (false, _) => 1.0,
            (true, true) => valid_ior(m.ior),
            (true, false) => 1.0 / valid_ior(m.ior),
        };
        if pick < wd + ws {
            // A non-delta lobe: sample one, weight by the mixture pdf.
            let frame = Frame::from_normal(n);
            let wi = if pick < wd {
                frame.to_world(sample_cosine_hemisphere(u))
            } else {
                sample_glossy(m, n, wo, u)?
            };
            if n.dot(wi) <= 0.0 || ng.dot(wi) <= 0.0 {
                return None;
            }
            if !lobes.specular && !lobes.rough && lobes.p_coat == 0.0 {
                // Lambert alone: f cos / pdf = (kd cos / pi) / (p_d cos / pi).
                let p_d = lobes.p_diffuse;
                return Some(BsdfSample {
                    wi,
                    weight: lobes.lambert_weight,
                    pdf: p_d * cosine_hemisphere_pdf(n.dot(wi)),
                    delta: false,
                });
            }
            return self.mixture_sample(n, wo, wi, eta);
        }
        if lobes.p_coat > 0.0 && pick >= wd + ws + wr + wt {
            // The clear coat: a GGX reflection, weighted by the mixture.
            let wi = sample_reflection(Distribution::Ggx, m.clearcoat_alpha, n, wo, u)?;
            if n.dot(wi) <= 0.0 || ng.dot(wi) <= 0.0 {
                return None;
            }
            return self.mixture_sample(n, wo, wi, eta);
        }
        let p_r = wr / total;
        let p_t = wt / total;
        if pick < wd + ws + wr {
            // The mirror: kr, or kr times a conductor's Fresnel.
            return Some(BsdfSample {
                wi: reflect(wo, n),
                weight: m.mirror_weight(n.dot(wo)) / p_r,
                pdf: 0.0,
                delta: true,
            });
        }
        if lobes.rough {
            // The rough dielectric: its direction, weighted by the mixture.
            let wi =
                sample_rough_dielectric(m.distribution, m.roughness, eta, n, wo, u, u_fresnel)?;
            if n.dot(wi) * ng.dot(wi) <= 0.0 {
                return None;
            }
            return self.mixture_sample(n, wo, wi, eta);
        }
        // Transmission: one branch of the split Whitted traces both of.
        let split = delta_split(m, fresnel, n, wo, front);
        let delta = |wi, weight| {
            Some(BsdfSample {
                wi,
                weight,
                pdf: 0.0,
                delta: true,
            })
        };
        if fresnel {
            // A dielectric: reflect with probability F (1 under total
            // internal reflection), else refract tinted by kt; each branch's
            // weight over its probability is 1 or kt.
            return match split.refracted {
                Some(wi) if u_fresnel() >= split.fresnel => delta(wi, m.kt / p_t),
                _ => delta(split.reflected, Vec3::ONE / p_t),
            };
        }
        // Fixed weights: refract by kt, or under total internal reflection
        // reflect by kt.
        delta(split.refracted.unwrap_or(split.reflected), m.kt / p_t)
    }
}

/// The mirror/glass split at a surface point: both delta branches with the
/// weights Whitted's recursion gives them (Whitted 1980, eqs. 2-3; Snell's
/// law via [`refract`], Fresnel via [`fresnel_dielectric`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeltaSplit {
    /// Mirror direction `reflect(wo, n)`.
    pub reflected: Vec3,
    /// Its weight: `kr` (times a conductor's Fresnel reflectance,
    /// [`SurfaceMaterial::mirror_weight`]), or `F` for a Fresnel dielectric; under total
    /// internal reflection the transmitted weight is added.
    pub reflect_weight: Vec3,
    /// Refracted direction; `None` for an opaque surface and under total
    /// internal reflection.
    pub refracted: Option<Vec3>,
    /// Its weight: `kt`, or `(1 - F) kt` for a Fresnel dielectric; zero when
    /// there is no refracted direction.
    pub refract_weight: Vec3,
    /// The Fresnel reflectance `F` of a dielectric (1 under total internal
    /// reflection): the probability with which [`Bsdf::sample`] reflects.
    /// 0 for fixed weights (1 under total internal reflection).
    pub fresnel: f32,
}

/// Both delta branches of `m` for `wo`: see [`DeltaSplit`]. `n` is the unit
/// shading normal on the side of `wo`; `entering` is true when `wo` is on
/// the outside (front) of the surface. A surface is transmissive when some
/// channel of `kt` is positive; its ior goes through [`valid_ior`].
pub fn delta_split(
    m: &SurfaceMaterial,
    fresnel: bool,
    n: Vec3,
    wo: Vec3,
    entering: bool,
) -> DeltaSplit {
    let reflected = reflect(wo, n);
    let kt = m.kt.max_element();
    if kt.is_nan() || kt <= 0.0 {
        return DeltaSplit {
            reflected,
            reflect_weight: m.mirror_weight(n.dot(wo)),
            refracted: None,
            refract_weight: Vec3::ZERO,
            fresnel: 0.0,
        };
    }
    let ior = valid_ior(m.ior);
    let (n1, n2) = if entering { (1.0, ior) } else { (ior, 1.0) };
    let cos_o = n.dot(wo).clamp(0.0, 1.0);
    let refracted = refract(wo, n, n1 / n2);
    let (mut wr, mut wt, f) = if fresnel {
        let f = fresnel_dielectric(cos_o, n1, n2);
        (Vec3::splat(f), (1.0 - f) * m.kt, f)
    } else {
        (m.mirror_weight(cos_o), m.kt, 0.0)
    };
    if refracted.is_none() {
        // Total internal reflection: everything is reflected.
        wr += wt;
        wt = Vec3::ZERO;
    }
    DeltaSplit {
        reflected,
        reflect_weight: wr,
        refracted,
        refract_weight: wt,
        fresnel: if refracted.is_some() { f } else { 1.0 },
    }
}

/// Samples the glossy lobe of `m` around its peak: Phong about the mirror
/// direction, Blinn and Torrance-Sparrow through a half vector.
fn sample_glossy(m: &SurfaceMaterial, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
    match m.model {
        ReflectanceModel::Phong => {
            let r = reflect(wo, n);
            Some(Frame::from_normal(r).to_world(sample_phong_lobe(u, m.shininess)))
        }
        ReflectanceModel::Blinn => {
            let h = Frame::from_normal(n).to_world(sample_phong_lobe(u, m.shininess));
            let wi = reflect(wo, h);
            Some(wi)
        }
        ReflectanceModel::TorranceSparrow => {
            sample_reflection(m.distribution, m.roughness.max(1e-3), n, wo, u)
        }
    }
}

/// `wo` reflected about a microfacet normal drawn by
/// [`microfacet::sample_microfacet_normal`] about `n` (GGX: visible from
/// `wo`), with the solid-angle pdf [`microfacet::reflection_pdf`]. `None`
/// when `wo` is below `n` (GGX then sees no microfacet).
fn sample_reflection(dist: Distribution, alpha: f32, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
    if n.dot(wo) <= 0.0 {
        return None;
    }
    let frame = Frame::from_normal(n);
    let h = microfacet::sample_microfacet_normal(dist, alpha, frame.to_local(wo), u);
    Some(reflect(wo, frame.to_world(h)))
}

/// Solid-angle pdf of [`sample_glossy`] (1/sr): Phong's lobe about the
/// mirror direction; Blinn's half-vector density `p(h)` becomes
/// `p(h) / (4 wo.h)` (Walter et al. 2007, eq. 14); Torrance-Sparrow's is
/// [`microfacet::reflection_pdf`].
fn glossy_pdf(m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
    match m.model {
        ReflectanceModel::Phong => phong_lobe_pdf(reflect(wo, n).dot(wi), m.shininess),
        ReflectanceModel::Blinn => {
            let Some(h) = (wo + wi).try_normalize() else {
                return 0.0;
            };
            let cos_h = n.dot(h);
            let o_h = wo.dot(h);
            if cos_h <= 0.0 || o_h <= 0.0 {
                return 0.0;
            }
            phong_lobe_pdf(cos_h, m.shininess) / (4.0 * o_h)
        }
        ReflectanceModel::TorranceSparrow => {
            microfacet::reflection_pdf(m.distribution, m.roughness.max(1e-3), n, wo, wi)
        }
    }
}

#[cfg(test)]
mod tests {
    //! Sampling tests as Mitsuba runs them (`mitsuba/python/chi2.py`): a
    //! chi-square goodness-of-fit test of each lobe's `sample` against its
    //! `pdf`, and a white-furnace test of each lobe's albedo.
    use super::*;
    use crate::sampling::{pixel_rng, uniform, uniform2};
    use crate::scene::ComplexIor;
    use std::f32::consts::PI;

    /// Bins in `cos_theta` over `[-1, 1]` (even: a boundary at the horizon)
    /// and in `phi`.
    const COS_BINS: usize = 10;
    const PHI_BINS: usize = 20;
    /// Simpson intervals per bin side for integrating the pdf (enough for
    /// the refraction of a GGX glass of alpha 0.05 seen from inside).
    const SIMPSON: usize = 64;
    /// The family-wise significance level, split by Sidak's correction.
    const ALPHA: f64 = 0.01;

    fn material(kd: f32, ks: f32, model: ReflectanceModel) -> SurfaceMaterial {
        SurfaceMaterial {
            kd: Vec3::splat(kd),
            ks: Vec3::splat(ks),
            model,
            kr: Vec3::ZERO,
            kt: Vec3::ZERO,
            emission: Vec3::ZERO,
            ..SurfaceMaterial::default()
        }
    }
    fn phong(kd: f32, ks: f32, n: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            shininess: n,
            ..material(kd, ks, ReflectanceModel::Phong)
        }
    }
    fn blinn(kd: f32, ks: f32, n: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            shininess: n,
            ..material(kd, ks, ReflectanceModel::Blinn)
        }
    }
    fn microfacet(kd: f32, ks: f32, dist: Distribution, alpha: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            roughness: alpha,
            distribution: dist,
            ..material(kd, ks, ReflectanceModel::TorranceSparrow)
        }
    }

    /// Every non-delta lobe at a few parameters, alone and mixed with Lambert.
    fn non_delta_lobes() -> Vec<(String, SurfaceMaterial)> {
        let mut v = vec![(
            "lambert".to_string(),
            material(0.7, 0.0, ReflectanceModel::Phong),
        )];
        for n in [1.0, 10.0, 100.0] {
            v.push((format!("phong n={n}"), phong(0.0, 0.6, n)));
        }
        for n in [4.0, 40.0] {
            v.push((format!("blinn n={n}"), blinn(0.0, 0.6, n)));
        }
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for a in [0.1, 0.3, 0.7] {
                v.push((format!("{dist:?} alpha={a}"), microfacet(0.0, 0.9, dist, a)));
            }
        }
        v.push(("lambert+phong".into(), phong(0.5, 0.3, 20.0)));
        v.push(("lambert+blinn".into(), blinn(0.4, 0.4, 30.0)));
        v.push((
            "lambert+ggx".into(),
            microfacet(0.3, 0.5, Distribution::Ggx, 0.2),
        ));
        v.push((
            "lambert+beckmann".into(),
            microfacet(0.3, 0.5, Distribution::Beckmann, 0.5),
        ));
        // Clear coats over Lambert and over a glossy base.
        for (c, a) in [(1.0, 0.1), (0.6, 0.4)] {
            v.push((
                format!("lambert+coat {c} alpha={a}"),
                coated(material(0.7, 0.0, ReflectanceModel::Phong), c, a),
            ));
        }
        v.push((
            "lambert+ggx+coat".into(),
            coated(microfacet(0.3, 0.5, Distribution::Ggx, 0.4), 0.8, 0.1),
        ));
        for a in [0.05, 0.3] {
            v.push((
                format!("ggx conductor alpha={a}"),
                SurfaceMaterial {
                    conductor: Some(GOLD),
                    ..microfacet(0.0, 1.0, Distribution::Ggx, a)
                },
            ));
        }
        v
    }

    /// `m` under a clear coat of weight `c` and GGX alpha `alpha`.
    fn coated(m: SurfaceMaterial, c: f32, alpha: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            clearcoat: c,
            clearcoat_alpha: alpha,
            ..m
        }
    }

    /// Gold's RGB complex IOR.
    const GOLD: ComplexIor = ComplexIor {
        eta: Vec3::new(0.143, 0.375, 1.442),
        k: Vec3::new(3.983, 2.386, 1.603),
    };

    #[test]
    fn conductor_mirror_reflects_its_fresnel() {
        // The sampled mirror and Whitted's split both weigh kr F_c(cos_o).
        let m = SurfaceMaterial {
            kr: Vec3::new(1.0, 0.9, 0.8),
            conductor: Some(GOLD),
            ..material(0.0, 0.0, ReflectanceModel::Phong)
        };
        let bsdf = Bsdf::new(m, false);
        for theta in [0.0, 45.0, 80.0, 89.0] {
            let wo = dir(theta, 0.3);
            let want = m.kr * super::super::fresnel::fresnel_conductor(wo.z, GOLD.eta, GOLD.k);
            let s = bsdf
                .sample(Vec3::Z, Vec3::Z, wo, true, 0.5, Vec2::splat(0.5), || 0.5)
                .expect("a mirror reflects");
            assert!(s.delta && (s.wi - reflect(wo, Vec3::Z)).length() < 1e-6);
            assert!(
                (s.weight - want).abs().max_element() < 1e-6,
                "{theta}: {}",
                s.weight
            );
            let split = delta_split(&m, false, Vec3::Z, wo, true);
            assert_eq!(split.reflect_weight, want);
        }
    }

    /// A unit direction at `theta` degrees from +z.
    fn dir(theta_degrees: f32, phi: f32) -> Vec3 {
        let t = theta_degrees.to_radians();
        Vec3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos())
    }

    /// One sample of `bsdf` for `wo` about `n = ng = +z` (front side).
    fn sample(bsdf: &Bsdf, wo: Vec3, rng: &mut crate::sampling::Rng) -> Option<BsdfSample> {
        let u_lobe = uniform(rng);
        let u = uniform2(rng);
        bsdf.sample(Vec3::Z, Vec3::Z, wo, true, u_lobe, u, || uniform(rng))
    }

    /// `ln Gamma(x)`, Lanczos (Numerical Recipes, `gammln`).
    fn ln_gamma(x: f64) -> f64 {
        const COF: [f64; 6] = [
            76.180_091_729_471_46,
            -86.505_320_329_416_77,
            24.014_098_240_830_91,
            -1.231_739_572_450_155,
            0.120_865_097_386_617_9e-2,
            -0.539_523_938_495_3e-5,
        ];
        let mut y = x;
        let tmp = x + 5.5;
        let tmp = tmp - (x + 0.5) * tmp.ln();
        let mut ser = 1.000_000_000_190_015;
        for c in COF {
            y += 1.0;
            ser += c / y;
        }
        -tmp + (2.506_628_274_631_000_5 * ser / x).ln()
    }

    /// The regularised upper incomplete gamma function `Q(a, x)`, by its
    /// series or its continued fraction (Numerical Recipes, `gammq`).
    fn gamma_q(a: f64, x: f64) -> f64 {
        if x <= 0.0 {
            return 1.0;
        }
        let front = (-x + a * x.ln() - ln_gamma(a)).exp();
        if x < a + 1.0 {
            let (mut ap, mut del) = (a, 1.0 / a);
            let mut sum = del;
            for _ in 0..1000 {
                ap += 1.0;
                del *= x / ap;
                sum += del;
                if del.abs() < sum.abs() * 1e-15 {
                    break;
                }
            }
            1.0 - sum * front
        } else {
            const TINY: f64 = 1e-300;
            let mut b = x + 1.0 - a;
            let mut c = 1.0 / TINY;
            let mut d = 1.0 / b;
            let mut h = d;
            for i in 1..1000 {
                let an = -(i as f64) * (i as f64 - a);
                b += 2.0;
                d = an * d + b;
                if d.abs() < TINY {
                    d = TINY;
                }
                c = b + an / c;
                if c.abs() < TINY {
                    c = TINY;
                }
                d = 1.0 / d;
                let del = d * c;
                h *= del;
                if (del - 1.0).abs() < 1e-15 {
                    break;
                }
            }
            front * h
        }
    }

    #[test]
    fn chi_square_tail_has_its_closed_forms() {
        // Two degrees of freedom: P(X > x) = exp(-x / 2).
        for x in [0.1, 1.0, 5.0, 30.0] {
            let q = gamma_q(1.0, x / 2.0);
            assert!((q - (-x / 2.0f64).exp()).abs() < 1e-12, "{x}: {q}");
        }
        // One degree of freedom at its 0.95 quantile 3.841459.
        assert!((gamma_q(0.5, 3.841_459 / 2.0) - 0.05).abs() < 1e-6);
    }

    /// Mitsuba's chi-square test: `samples` directions drawn by `draw`,
    /// binned on the sphere in `(cos_theta, phi)`, against the integral of
    /// `pdf` over each bin (composite Simpson in theta and phi); bins
    /// expecting fewer than 5 are pooled. Returns the p-value, or an error
    /// for a sample in a bin of zero probability or a pdf that integrates
    /// above 1.
    fn chi2_p_value(
        samples: u32,
        mut draw: impl FnMut() -> Option<Vec3>,
        pdf: impl Fn(Vec3) -> f32,
    ) -> Result<f64, String> {
        let cell = |wi: Vec3| {
            let c = (((wi.z.clamp(-1.0, 1.0) + 1.0) * 0.5 * COS_BINS as f32) as usize)
                .min(COS_BINS - 1);
            let phi = wi.y.atan2(wi.x).rem_euclid(2.0 * PI);
            let p = ((phi / (2.0 * PI) * PHI_BINS as f32) as usize).min(PHI_BINS - 1);
            c * PHI_BINS + p
        };
        let mut observed = vec![0f64; COS_BINS * PHI_BINS];
        for _ in 0..samples {
            if let Some(wi) = draw() {
                observed[cell(wi)] += 1.0;
            }
        }
        let (dc, dp) = (
            2.0 / COS_BINS as f64,
            2.0 * std::f64::consts::PI / PHI_BINS as f64,
        );
        let simpson = |k: usize| match k {
            0 | SIMPSON => 1.0,
            k if k % 2 == 1 => 4.0,
            _ => 2.0,
        };
        let mut expected = vec![0f64; COS_BINS * PHI_BINS];
        for c in 0..COS_BINS {
            // Integrated over theta (dw = sin theta dtheta dphi), in which
            // a lobe near a pole is smooth; in cos theta it is not.
            let theta_hi = (-1.0 + dc * c as f64).clamp(-1.0, 1.0).acos();
            let theta_lo = (-1.0 + dc * (c + 1) as f64).clamp(-1.0, 1.0).acos();
            let dt = theta_hi - theta_lo;
            for p in 0..PHI_BINS {
                let mut s = 0.0;
                for i in 0..=SIMPSON {
                    // (The end points a hair inside the bin: the pdf jumps
                    // at the horizon, and each bin needs its own side's limit.)
                    let x = (i as f64 / SIMPSON as f64).clamp(1e-6, 1.0 - 1e-6);
                    let theta = theta_lo + dt * x;
                    let (r, z) = theta.sin_cos();
                    for j in 0..=SIMPSON {
                        let phi = dp * (p as f64 + j as f64 / SIMPSON as f64);
                        let wi =
                            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                        s += simpson(i) * simpson(j) * r * f64::from(pdf(wi));
                    }
                }
                let h = SIMPSON as f64 * 3.0;
                expected[c * PHI_BINS + p] = s * (dt / h) * (dp / h) * f64::from(samples);
            }
        }
        let total: f64 = expected.iter().sum::<f64>() / f64::from(samples);
        if total > 1.0 + 1e-3 {
            return Err(format!("the pdf integrates to {total}"));
        }
        let (mut chi2, mut cells) = (0.0, 0usize);
        let (mut pool_o, mut pool_e) = (0.0, 0.0);
        for (&o, &e) in observed.iter().zip(&expected) {
            if e == 0.0 {
                if o > 0.0 {
                    return Err(format!("{o} samples in a cell of probability 0"));
                }
            } else if e < 5.0 {
                pool_o += o;
                pool_e += e;
            } else {
                chi2 += (o - e) * (o - e) / e;
                cells += 1;
            }
        }
        if pool_e > 0.0 {
            chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
            cells += 1;
        }
        let dof = cells.saturating_sub(1).max(1) as f64;
        Ok(gamma_q(dof / 2.0, chi2 / 2.0))
    }

    /// Outgoing directions of the tests (near normal and near grazing).
    const WO_THETAS: [f32; 2] = [20.0, 65.0];
    const CHI2_SAMPLES: u32 = 300_000;

    #[test]
    fn every_lobe_samples_its_pdf_chi_square() {
        let lobes = non_delta_lobes();
        let tests = lobes.len() * WO_THETAS.len();
        // Sidak: each test at 1 - (1 - alpha)^(1 / tests).
        let threshold = 1.0 - (1.0 - ALPHA).powf(1.0 / tests as f64);
        let mut failures = Vec::new();
        for (k, (name, m)) in lobes.iter().enumerate() {
            let bsdf = Bsdf::new(*m, false);
            for (j, theta) in WO_THETAS.iter().enumerate() {
                let wo = dir(*theta, 0.3);
                let mut rng = pixel_rng(11, k as u32, j as u32, 0);
                let p = chi2_p_value(
                    CHI2_SAMPLES,
                    || sample(&bsdf, wo, &mut rng).map(|s| s.wi),
                    |wi| bsdf.pdf(Vec3::Z, wo, wi),
                );
                match p {
                    Ok(p) if p >= threshold => {}
                    other => failures.push(format!("{name}, theta_o {theta}: {other:?}")),
                }
            }
        }
        assert!(failures.is_empty(), "below {threshold:.2e}: {failures:#?}");
    }

    #[test]
    fn chi_square_test_rejects_a_wrong_pdf_or_sampler() {
        // The harness must fail when the pdf is off by a factor, or when
        // `sample` draws from another distribution than `pdf` describes.
        let threshold = 1e-6;
        let wo = dir(30.0, 0.3);
        for (name, m) in [
            ("lambert", material(0.7, 0.0, ReflectanceModel::Phong)),
            ("ggx", microfacet(0.0, 0.9, Distribution::Ggx, 0.3)),
        ] {
            let bsdf = Bsdf::new(m, false);
            let mut rng = pixel_rng(5, 0, 0, 0);
            let p = chi2_p_value(
                CHI2_SAMPLES,
                || sample(&bsdf, wo, &mut rng).map(|s| s.wi),
                |wi| 0.9 * bsdf.pdf(Vec3::Z, wo, wi),
            );
            assert!(
                matches!(&p, Ok(v) if *v < threshold),
                "{name} pdf x 0.9: {p:?}"
            );
        }
        let (drawn, claimed) = (
            Bsdf::new(phong(0.0, 0.6, 10.0), false),
            Bsdf::new(phong(0.0, 0.6, 12.0), false),
        );
        let mut rng = pixel_rng(5, 1, 0, 0);
        let p = chi2_p_value(
            CHI2_SAMPLES,
            || sample(&drawn, wo, &mut rng).map(|s| s.wi),
            |wi| claimed.pdf(Vec3::Z, wo, wi),
        );
        assert!(
            matches!(&p, Ok(v) if *v < threshold),
            "phong 10 vs 12: {p:?}"
        );
    }

    /// Mean and standard error of `E[weight]` (zero for lost samples).
    fn mean_weight(bsdf: &Bsdf, wo: Vec3, n: u32, seed: u32) -> (Vec3, Vec3) {
        let mut rng = pixel_rng(23, seed, 0, 0);
        let (mut s, mut s2) = (Vec3::ZERO, Vec3::ZERO);
        for _ in 0..n {
            let w = sample(bsdf, wo, &mut rng).map_or(Vec3::ZERO, |s| s.weight);
            s += w;
            s2 += w * w;
        }
        let mean = s / n as f32;
        let var = (s2 / n as f32 - mean * mean).max(Vec3::ZERO);
        (mean, (var / n as f32).powf(0.5))
    }

    #[test]
    fn white_furnace_albedo_of_every_lobe() {
        // E[weight] is the albedo integral f cos dwi (the midpoint rule in
        // theta of `sphere_albedo`, which resolves a narrow lobe about the
        // normal), at most 1 for these parameters.
        for (k, (name, m)) in non_delta_lobes().iter().enumerate() {
            let bsdf = Bsdf::new(*m, false);
            for theta in [0.0, 30.0, 60.0, 85.0] {
                let wo = dir(theta, 1.1);
                let (mean, se) = mean_weight(&bsdf, wo, 100_000, k as u32);
                // (A lobe of alpha 0.05 seen at grazing needs finer cells.)
                let narrow = m.model == ReflectanceModel::TorranceSparrow && m.roughness < 0.1;
                let albedo = sphere_albedo(&bsdf, wo, if narrow { 1500 } else { 500 });
                let err = (mean - albedo).abs().max_element();
                assert!(
                    err <= 4.0 * se.max_element() + 2e-3,
                    "{name}, theta_o {theta}: E[weight] {mean} against albedo {albedo} (se {se})"
                );
                assert!(mean.max_element() <= 1.0 + 1e-2, "{name} {theta}: {mean}");
            }
        }
    }

    #[test]
    fn lossless_delta_lobes_keep_all_energy() {
        // A mirror of kr = 1: every sample's weight is 1, along the mirror.
        let mirror = Bsdf::new(
            SurfaceMaterial {
                kr: Vec3::ONE,
                ..material(0.0, 0.0, ReflectanceModel::Phong)
            },
            false,
        );
        let wo = dir(40.0, 0.2);
        let mut rng = pixel_rng(3, 0, 0, 0);
        for _ in 0..1000 {
            let s = sample(&mirror, wo, &mut rng).expect("a mirror reflects");
            assert_eq!(s.weight, Vec3::ONE);
            assert!(s.delta && (s.wi - reflect(wo, Vec3::Z)).length() < 1e-6);
        }
        // Glass of kt = 1 with Fresnel: weight 1 whichever branch, and the
        // reflected fraction is F (1 beyond the critical angle inside).
        let glass = Bsdf::new(
            SurfaceMaterial {
                kt: Vec3::ONE,
                ior: 1.5,
                ..material(0.0, 0.0, ReflectanceModel::Phong)
            },
            true,
        );
        let n = 200_000;
        for front in [true, false] {
            for theta in [0.0, 30.0, 45.0, 60.0, 85.0] {
                let wo = dir(theta, 0.7);
                let (n1, n2) = if front { (1.0, 1.5) } else { (1.5, 1.0) };
                let f = fresnel_dielectric(wo.z, n1, n2);
                let mut reflected = 0u32;
                let mut rng = pixel_rng(4, theta as u32, front as u32, 0);
                for _ in 0..n {
                    let u_lobe = uniform(&mut rng);
                    let u = uniform2(&mut rng);
                    let s = glass
                        .sample(Vec3::Z, Vec3::Z, wo, front, u_lobe, u, || uniform(&mut rng))
                        .expect("glass scatters");
                    assert_eq!(s.weight, Vec3::ONE);
                    reflected += u32::from(s.wi.z > 0.0);
                }
                let frac = f64::from(reflected) / f64::from(n);
                let se = (f64::from(f) * (1.0 - f64::from(f)) / f64::from(n)).sqrt();
                assert!(
                    (frac - f64::from(f)).abs() <= 4.0 * se + 1e-9,
                    "front {front}, theta {theta}: reflected {frac}, F {f}"
                );
            }
        }
    }

    #[test]
    fn sampled_delta_weights_average_to_whitted_split() {
        // The stochastic choice of `sample` and the two weighted branches of
        // `delta_split` are one split: E[delta weight] = kr' + kt'.
        let kt = Vec3::new(0.9, 0.5, 0.2);
        for (fresnel, kr, kd) in [(true, 0.0, 0.0), (false, 0.3, 0.1), (true, 0.2, 0.2)] {
            let m = SurfaceMaterial {
                kt,
                kr: Vec3::splat(kr),
                ior: 1.5,
                ..material(kd, 0.0, ReflectanceModel::Phong)
            };
            let bsdf = Bsdf::new(m, fresnel);
            for front in [true, false] {
                for theta in [10.0, 50.0, 80.0] {
                    let wo = dir(theta, 2.0);
                    let split = delta_split(&m, fresnel, Vec3::Z, wo, front);
                    let want = split.reflect_weight + split.refract_weight;
                    let mut rng = pixel_rng(6, theta as u32, front as u32, 0);
                    let n = 200_000;
                    let (mut s, mut s2) = (Vec3::ZERO, Vec3::ZERO);
                    for _ in 0..n {
                        let u_lobe = uniform(&mut rng);
                        let u = uniform2(&mut rng);
                        let w = bsdf
                            .sample(Vec3::Z, Vec3::Z, wo, front, u_lobe, u, || uniform(&mut rng))
                            .filter(|s| s.delta)
                            .map_or(Vec3::ZERO, |s| s.weight);
                        s += w;
                        s2 += w * w;
                    }
                    let mean = s / n as f32;
                    let se = ((s2 / n as f32 - mean * mean).max(Vec3::ZERO) / n as f32).powf(0.5);
                    assert!(
                        (mean - want).abs().max_element() <= 4.0 * se.max_element() + 1e-4,
                        "fresnel {fresnel} kr {kr} front {front} theta {theta}: {mean} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_ior_is_replaced_by_one() {
        // An ior of 1 neither bends nor (with Fresnel) reflects.
        for ior in [f32::NAN, 0.0, -2.0, f32::INFINITY] {
            let m = SurfaceMaterial {
                kt: Vec3::ONE,
                ior,
                ..material(0.0, 0.0, ReflectanceModel::Phong)
            };
            let wo = dir(35.0, 0.4);
            let split = delta_split(&m, true, Vec3::Z, wo, true);
            let t = split.refracted.expect("refracts");
            assert!((t + wo).length() < 1e-6, "ior {ior}: {t}");
            assert_eq!(split.reflect_weight, Vec3::ZERO);
            assert_eq!(split.refract_weight, Vec3::ONE);
        }
    }

    /// A rough glass (Fresnel dielectric, Torrance-Sparrow roughness
    /// `alpha`), with a Lambertian share `kd`.
    fn rough_glass(kd: f32, kt: f32, alpha: f32, dist: Distribution) -> SurfaceMaterial {
        SurfaceMaterial {
            kt: Vec3::splat(kt),
            ior: 1.5,
            roughness: alpha,
            distribution: dist,
            ..material(kd, 0.0, ReflectanceModel::TorranceSparrow)
        }
    }

    /// The rough glasses of the tests, with the side they are seen from.
    fn rough_glasses() -> Vec<(String, SurfaceMaterial, bool)> {
        let mut v = Vec::new();
        for front in [true, false] {
            for a in [0.1, 0.2, 0.6] {
                v.push((
                    format!("ggx glass alpha={a} front={front}"),
                    rough_glass(0.0, 1.0, a, Distribution::Ggx),
                    front,
                ));
            }
            v.push((
                format!("beckmann glass alpha=0.3 front={front}"),
                rough_glass(0.0, 0.8, 0.3, Distribution::Beckmann),
                front,
            ));
            v.push((
                format!("lambert+ggx glass front={front}"),
                rough_glass(0.3, 0.7, 0.25, Distribution::Ggx),
                front,
            ));
        }
        // A thin wall: the same from either side.
        v.push((
            "ggx thin wall alpha=0.3".into(),
            SurfaceMaterial {
                ior: 1.0,
                ..rough_glass(0.0, 1.0, 0.3, Distribution::Ggx)
            },
            true,
        ));
        v
    }

    /// One sample of `bsdf` for `wo` about `n = ng = +z`, from `front`.
    fn sample_side(
        bsdf: &Bsdf,
        wo: Vec3,
        front: bool,
        rng: &mut crate::sampling::Rng,
    ) -> Option<BsdfSample> {
        let u_lobe = uniform(rng);
        let u = uniform2(rng);
        bsdf.sample(Vec3::Z, Vec3::Z, wo, front, u_lobe, u, || uniform(rng))
    }

    #[test]
    fn ggx_sample_weights_are_bounded_by_masking() {
        // With visible normals, a lossless GGX lobe's sample weight
        // f cos / pdf is Smith's G1(wi) <= 1, whatever the view (Heitz 2018,
        // section 2): a white reflector (Schlick F = 1 at ks = 1), and clear
        // glass (kt = 1) from either side and as a thin wall, whose
        // reflection and refraction each weigh F or 1 - F over the same
        // probability. Drawing all normals by D cos instead gives weights
        // up to G o.h / (cos_o cos_h), unbounded at grazing views.
        let mut cases: Vec<(String, Bsdf, bool)> = Vec::new();
        for a in [0.05, 0.3, 0.8] {
            let white = microfacet(0.0, 1.0, Distribution::Ggx, a);
            cases.push((
                format!("white ggx alpha={a}"),
                Bsdf::new(white, false),
                true,
            ));
            for front in [true, false] {
                let glass = Bsdf::new(rough_glass(0.0, 1.0, a, Distribution::Ggx), true);
                cases.push((
                    format!("ggx glass alpha={a} front={front}"),
                    glass.seen_from(front),
                    front,
                ));
            }
            let thin = SurfaceMaterial {
                ior: 1.0,
                ..rough_glass(0.0, 1.0, a, Distribution::Ggx)
            };
            cases.push((format!("thin wall alpha={a}"), Bsdf::new(thin, true), true));
        }
        for (k, (name, bsdf, front)) in cases.iter().enumerate() {
            let alpha = bsdf.m.roughness;
            for theta in [0.0, 45.0, 80.0, 89.0] {
                let wo = dir(theta, 0.4);
                let mut rng = pixel_rng(37, k as u32, theta as u32, 0);
                let mut kept = 0;
                for _ in 0..20_000 {
                    let Some(s) = sample_side(bsdf, wo, *front, &mut rng) else {
                        continue;
                    };
                    let g1 = microfacet::g1(Distribution::Ggx, s.wi.z.abs(), alpha);
                    let w = s.weight;
                    assert!(
                        (w - Vec3::splat(g1)).abs().max_element() <= 2e-3 * g1 + 1e-5,
                        "{name}, theta_o {theta}: weight {w} for wi {}, G1 {g1}",
                        s.wi
                    );
                    assert!(w.max_element() <= 1.0 + 1e-5, "{name} {theta}: {w}");
                    kept += 1;
                }
                assert!(kept > 5_000, "{name}, theta_o {theta}: {kept} samples kept");
            }
        }
    }

    #[test]
    fn rough_dielectric_is_chosen_only_when_rough() {
        // Smooth glass, Phong glass (the shipped scenes' kind) and
        // non-Fresnel transmission keep the delta lobe.
        let rough = rough_glass(0.0, 1.0, 0.3, Distribution::Ggx);
        assert!(Bsdf::new(rough, true).lobes.rough);
        assert!(!Bsdf::new(rough, false).lobes.rough);
        let smooth = SurfaceMaterial {
            roughness: 0.5 * MIN_ROUGH_ALPHA,
            ..rough
        };
        assert!(!Bsdf::new(smooth, true).lobes.rough);
        let phong_glass = SurfaceMaterial {
            model: ReflectanceModel::Phong,
            ..rough
        };
        assert!(!Bsdf::new(phong_glass, true).lobes.rough);
        // A thin wall (ior 1) is rough too.
        let thin = SurfaceMaterial { ior: 1.0, ..rough };
        assert!(Bsdf::new(thin, true).lobes.rough);
    }

    #[test]
    fn rough_dielectric_samples_its_pdf_chi_square() {
        let glasses = rough_glasses();
        let tests = glasses.len() * WO_THETAS.len();
        let threshold = 1.0 - (1.0 - ALPHA).powf(1.0 / tests as f64);
        let mut failures = Vec::new();
        for (k, (name, m, front)) in glasses.iter().enumerate() {
            let bsdf = Bsdf::new(*m, true).seen_from(*front);
            for (j, theta) in WO_THETAS.iter().enumerate() {
                let wo = dir(*theta, 0.3);
                let mut rng = pixel_rng(13, k as u32, j as u32, 0);
                let p = chi2_p_value(
                    CHI2_SAMPLES,
                    || sample_side(&bsdf, wo, *front, &mut rng).map(|s| s.wi),
                    |wi| bsdf.pdf(Vec3::Z, wo, wi),
                );
                match p {
                    Ok(p) if p >= threshold => {}
                    other => failures.push(format!("{name}, theta_o {theta}: {other:?}")),
                }
            }
        }
        assert!(failures.is_empty(), "below {threshold:.2e}: {failures:#?}");
    }

    /// `integral eval dwi` over the sphere by the midpoint rule in
    /// `(theta, phi)` (in which a lobe at a pole is resolved), `2k x k` cells,
    /// summed in `f64` (an `f32` sum of a million cells drifts by percents).
    fn sphere_albedo(bsdf: &Bsdf, wo: Vec3, k: u32) -> Vec3 {
        let mut sum = [0f64; 3];
        let (dt, dp) = (PI / (2 * k) as f32, 2.0 * PI / k as f32);
        for i in 0..2 * k {
            let theta = (i as f32 + 0.5) * dt;
            let (s, c) = theta.sin_cos();
            for j in 0..k {
                let phi = (j as f32 + 0.5) * dp;
                let wi = Vec3::new(s * phi.cos(), s * phi.sin(), c);
                let f = bsdf.eval(Vec3::Z, wo, wi) * s;
                for (acc, v) in sum.iter_mut().zip(f.to_array()) {
                    *acc += f64::from(v);
                }
            }
        }
        Vec3::from_array(sum.map(|v| (v * f64::from(dt * dp)) as f32))
    }

    #[test]
    fn rough_dielectric_white_furnace_and_eval_pdf_agree() {
        // E[weight] (= E[f cos / pdf]) equals the integral of eval, and
        // neither exceeds 1: the lobe loses energy to masking, never gains.
        for (k, (name, m, front)) in rough_glasses().iter().enumerate() {
            let bsdf = Bsdf::new(*m, true).seen_from(*front);
            for theta in [0.0, 30.0, 60.0, 80.0] {
                let wo = dir(theta, 0.9);
                let mut rng = pixel_rng(29, k as u32, theta as u32, 0);
                let n = 100_000;
                let (mut s, mut s2) = (Vec3::ZERO, Vec3::ZERO);
                for _ in 0..n {
                    let w = sample_side(&bsdf, wo, *front, &mut rng).map_or(Vec3::ZERO, |s| {
                        assert!(!s.delta && s.pdf > 0.0, "{name}: {s:?}");
                        s.weight
                    });
                    s += w;
                    s2 += w * w;
                }
                let mean = s / n as f32;
                let se = ((s2 / n as f32 - mean * mean).max(Vec3::ZERO) / n as f32).powf(0.5);
                let albedo = sphere_albedo(&bsdf, wo, 700);
                // (The quadrature of a narrow lobe is coarse: 1 % slack.)
                let err = (mean - albedo).abs().max_element();
                assert!(
                    err <= 4.0 * se.max_element() + 1e-2 * albedo.max_element() + 2e-3,
                    "{name}, theta_o {theta}: E[weight] {mean} against integral {albedo} (se {se})"
                );
                // (Lobes add: Lambert over glass that reflects all of a
                // grazing `wo` inside, by total internal reflection, exceeds 1.)
                if m.kd == Vec3::ZERO {
                    assert!(mean.max_element() <= 1.0 + 1e-2, "{name} {theta}: {mean}");
                }
                // Clear glass seen head-on from outside keeps nearly all.
                if *front && m.kt == Vec3::ONE && theta == 0.0 && m.roughness <= 0.2 {
                    assert!(mean.x > 0.9, "{name}: {mean}");
                }
            }
        }
    }

    #[test]
    fn rough_dielectric_is_reciprocal() {
        // Reflection: f(wo, wi) = f(wi, wo). Refraction from outside (index
        // 1) into glass (eta): f(wo, wi) = eta^2 f(wi, wo) seen from inside,
        // the radiance BTDF's eta_i^2 f(wo, wi) = eta_o^2 f(wi, wo) without
        // its 1 / eta^2 (see the dielectric module).
        let m = rough_glass(0.0, 1.0, 0.3, Distribution::Ggx);
        let outside = Bsdf::new(m, true).seen_from(true);
        let inside = Bsdf::new(m, true).seen_from(false);
        let mut rng = pixel_rng(31, 0, 0, 0);
        let mut checked = 0;
        for _ in 0..2000 {
            let a = dir(85.0 * uniform(&mut rng), 6.3 * uniform(&mut rng));
            let b = dir(85.0 * uniform(&mut rng), 6.3 * uniform(&mut rng));
            // f = eval / |cos_i|.
            let f =
                |bsdf: &Bsdf, n: Vec3, wo: Vec3, wi: Vec3| bsdf.eval(n, wo, wi).x / n.dot(wi).abs();
            let (r1, r2) = (f(&outside, Vec3::Z, a, b), f(&outside, Vec3::Z, b, a));
            assert!((r1 - r2).abs() <= 1e-4 * r1.max(r2) + 1e-6, "{r1} vs {r2}");
            let below = Vec3::new(b.x, b.y, -b.z);
            let t1 = f(&outside, Vec3::Z, a, below);
            let t2 = f(&inside, -Vec3::Z, below, a);
            assert!(
                (t1 - 2.25 * t2).abs() <= 1e-3 * t1.max(2.25 * t2) + 1e-6,
                "{a} {below}: {t1} vs 2.25 x {t2}"
            );
            checked += u32::from(t1 > 0.0);
        }
        assert!(checked > 500, "{checked} refracting pairs");
        // A thin wall is symmetric through it.
        let thin = Bsdf::new(SurfaceMaterial { ior: 1.0, ..m }, true);
        for _ in 0..500 {
            let a = dir(85.0 * uniform(&mut rng), 6.3 * uniform(&mut rng));
            let b = dir(85.0 * uniform(&mut rng), 6.3 * uniform(&mut rng));
            let below = Vec3::new(b.x, b.y, -b.z);
            let t1 = thin.eval(Vec3::Z, a, below).x / b.z;
            let t2 = thin.eval(-Vec3::Z, below, a).x / a.z;
            assert!((t1 - t2).abs() <= 1e-4 * t1.max(t2) + 1e-6, "{t1} vs {t2}");
        }
    }
}
