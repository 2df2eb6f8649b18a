//! The BRDF of the local illumination model: Lambert plus one specular lobe
//! (Phong, Blinn-Phong or Torrance-Sparrow microfacets).

use super::fresnel::{
    fresnel_conductor, fresnel_dielectric, fresnel_schlick, reflect, schlick_weight,
};
use super::microfacet;
use crate::scene::{
    ComplexIor, Distribution, Material, MetallicRoughness, ReflectanceModel, Transmission,
};
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

/// A material's parameters at one surface point, after textures and vertex
/// colours were applied. Plain values, cheap to copy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceMaterial {
    /// Ambient reflectance relative to `kd`.
    pub ka: Vec3,
    /// Lambertian albedo.
    pub kd: Vec3,
    /// Specular coefficient (or F0 for microfacets).
    pub ks: Vec3,
    /// Phong/Blinn exponent.
    pub shininess: f32,
    /// Specular lobe.
    pub model: ReflectanceModel,
    /// Microfacet alpha.
    pub roughness: f32,
    /// Microfacet distribution.
    pub distribution: Distribution,
    /// Mirror reflection weight.
    pub kr: Vec3,
    /// Transmission colour.
    pub kt: Vec3,
    /// Index of refraction.
    pub ior: f32,
    /// Emitted radiance.
    pub emission: Vec3,
    /// The specular lobe's reflectance of uniform (ambient) light, added to
    /// `kd` in the ambient term: F0 for glTF metallic-roughness materials
    /// (so a metal, `kd = 0`, is not black under ambient or environment
    /// light), zero for classic materials (`Ia ka kd` unchanged).
    pub ks_ambient: Vec3,
    /// Clear-coat weight (`Clearcoat::factor` times its texture): 0 for
    /// none ([`clearcoat_cos`]).
    pub clearcoat: f32,
    /// The clear coat's GGX alpha (its perceptual roughness squared).
    pub clearcoat_alpha: f32,
    /// A conductor's complex IOR: `kr` and `ks` are then tints of its
    /// Fresnel reflectance ([`Material::conductor`]).
    pub conductor: Option<ComplexIor>,
}

impl Default for SurfaceMaterial {
    fn default() -> Self {
        Self::from_material(&Material::default())
    }
}

impl SurfaceMaterial {
    /// The untextured parameters of `m`.
    pub fn from_material(m: &Material) -> Self {
        Self {
            ka: m.ambient,
            kd: m.diffuse,
            ks: m.specular,
            shininess: m.shininess,
            model: m.model,
            roughness: m.roughness,
            distribution: m.distribution,
            kr: m.reflect,
            kt: m.transmit,
            ior: m.ior,
            emission: m.emission,
            ks_ambient: if m.metallic_roughness.is_some() {
                m.specular
            } else {
                Vec3::ZERO
            },
            clearcoat: m.clearcoat.map_or(0.0, |c| clean_unit(c.factor, 0.0)),
            clearcoat_alpha: m.clearcoat.map_or(1.0, |c| clearcoat_alpha(c.roughness)),
            conductor: m.conductor,
        }
    }

    /// The untextured parameters of `m` at a point whose vertex colour is
    /// `color`: the colour multiplies the diffuse colour, or for glTF
    /// metallic-roughness the base colour, so it reaches a metal's F0 too
    /// (as in the surface layer's textured evaluation).
    pub fn with_vertex_color(m: &Material, color: Vec3) -> Self {
        let mut sm = Self::from_material(m);
        match m.metallic_roughness {
            Some(mr) => {
                (sm.kd, sm.ks, sm.roughness) = MetallicRoughness::coefficients(
                    mr.base_color * color,
                    mr.metallic,
                    mr.roughness,
                );
                if let Some(t) = m.gltf_transmission {
                    (sm.kd, sm.ks, sm.kt) =
                        Transmission::split(sm.kd, sm.ks, mr.metallic, t.factor, m.ior);
                }
                sm.ks_ambient = sm.ks;
            }
            None => sm.kd *= color,
        }
        sm
    }

    /// The material as local shading takes it where the environment map's
    /// glossy reflection is integrated (`reflected`, by
    /// `texture::environment_specular`): without the specular lobe's ambient
    /// stand-in `ks_ambient`, so the map is not counted twice.
    #[inline]
    pub fn under_environment(self, reflected: bool) -> Self {
        if reflected {
            Self {
                ks_ambient: Vec3::ZERO,
                ..self
            }
        } else {
            self
        }
    }

    /// The material as the back of a one-sided surface shows it
    /// ([`crate::scene::Facing::BackBlack`]): no reflection of any kind
    /// (ambient, diffuse, specular, mirror); emission and transmission kept.
    #[inline]
    pub fn without_reflection(self) -> Self {
        Self {
            ka: Vec3::ZERO,
            kd: Vec3::ZERO,
            ks: Vec3::ZERO,
            kr: Vec3::ZERO,
            ks_ambient: Vec3::ZERO,
            clearcoat: 0.0,
            ..self
        }
    }

    /// True when the specular lobe contributes.
    #[inline]
    pub fn has_specular(&self) -> bool {
        self.ks.max_element() > 0.0
    }

    /// The ideal mirror's reflectance for a viewer at `cos_o = n . wo`:
    /// [`mirror_reflectance`] of `kr`.
    #[inline]
    pub fn mirror_weight(&self, cos_o: f32) -> Vec3 {
        mirror_reflectance(self.kr, self.conductor, cos_o)
    }
}

/// The ideal mirror's reflectance at `cos_o = n . wo`: the fixed weight
/// `kr`, or for a conductor `kr` times its Fresnel reflectance
/// ([`fresnel_conductor`]). The one mirror rule of every technique (the
/// ray tracers' mirror rays, the scan converter's reflection map).
#[inline]
pub fn mirror_reflectance(kr: Vec3, conductor: Option<ComplexIor>, cos_o: f32) -> Vec3 {
    match conductor {
        None => kr,
        Some(c) => kr * fresnel_conductor(cos_o, c.eta, c.k),
    }
}

/// The specular lobe value used by the Phong model: `(R . wi)^n` with R the
/// mirror direction of `wo` about `n`; zero below the surface.
#[inline]
pub fn phong_lobe(n: Vec3, wo: Vec3, wi: Vec3, exponent: f32) -> f32 {
    let r = reflect(wo, n);
    let c = r.dot(wi);
    if c <= 0.0 { 0.0 } else { c.powf(exponent) }
}

/// The Blinn lobe `(N . H)^n` with `H = normalize(wo + wi)`.
#[inline]
pub fn blinn_lobe(n: Vec3, wo: Vec3, wi: Vec3, exponent: f32) -> f32 {
    let h = (wo + wi).try_normalize().unwrap_or(n);
    let c = n.dot(h);
    if c <= 0.0 { 0.0 } else { c.powf(exponent) }
}

/// `x` clamped to `[0, 1]`, `fallback` when not finite.
#[inline]
pub fn clean_unit(x: f32, fallback: f32) -> f32 {
    if x.is_finite() {
        x.clamp(0.0, 1.0)
    } else {
        fallback
    }
}

/// The GGX alpha of a clear coat of perceptual roughness `roughness`: its
/// square, clamped to `[1e-3, 1]` like the base's.
#[inline]
pub fn clearcoat_alpha(roughness: f32) -> f32 {
    let r = clean_unit(roughness, 0.0);
    (r * r).clamp(1e-3, 1.0)
}

/// Index of refraction of a clear coat (glTF `KHR_materials_clearcoat`).
pub const CLEARCOAT_IOR: f32 = 1.5;

/// The clear coat over a base of `f(wo, wi) cos_theta_i = base` (1/sr):
/// `base (1 - c F(cos_o)) + c D G F(wi.h) / (4 cos_o)`, the coat a GGX
/// dielectric of index 1.5 and alpha `m.clearcoat_alpha`, `c` its weight
/// (glTF `KHR_materials_clearcoat`, "Layering", with the Khronos sample
/// viewer's Fresnel of the view angle for the base's attenuation). `cos_i`
/// must be positive.
#[inline]
pub fn clearcoat_cos(
    m: &SurfaceMaterial,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
    cos_i: f32,
    base: Vec3,
) -> Vec3 {
    let (attenuation, coat) = clearcoat_parts(m, n, wo, wi, cos_i);
    base * attenuation + Vec3::splat(coat)
}

/// The two parts of [`clearcoat_cos`]: the base's factor `1 - c F(cos_o)`
/// and the coat's own `c D G F / (4 cos_o)` (1/sr; colourless). `(1, 0)`
/// when `wo` is below the surface.
#[inline]
pub fn clearcoat_parts(m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3, cos_i: f32) -> (f32, f32) {
    let cos_o = n.dot(wo);
    if cos_o <= 0.0 {
        return (1.0, 0.0);
    }
    let c = m.clearcoat;
    let attenuation = 1.0 - c * fresnel_dielectric(cos_o, 1.0, CLEARCOAT_IOR);
    let Some(h) = (wo + wi).try_normalize() else {
        return (attenuation, 0.0);
    };
    let alpha = m.clearcoat_alpha;
    let d = microfacet::d(Distribution::Ggx, n.dot(h), alpha);
    let g = microfacet::g_smith(Distribution::Ggx, cos_o, cos_i, alpha);
    let f = fresnel_dielectric(wi.dot(h).max(0.0), 1.0, CLEARCOAT_IOR);
    (attenuation, c * d * g * f / (4.0 * cos_o))
}

/// `f(wo, wi) * max(cos_theta_i, 0)` in 1/sr: the BRDF of the local model
/// weighted by the cosine at the light side, under its clear coat if any.
///
/// `n`, `wo`, `wi` must be unit vectors. Zero when `wi` is below the surface.
/// For Phong/Blinn the specular part is `ks * lobe / pi`, so that the local
/// model's `pi * f * cos * Ip` reproduces the textbook `Ip ks (R . V)^n`.
#[inline]
pub fn eval_brdf_cos(m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    let cos_i = n.dot(wi);
    if cos_i <= 0.0 {
        return Vec3::ZERO;
    }
    let mut f = m.kd * (FRAC_1_PI * cos_i);
    if m.has_specular() {
        f += specular_cos(m, n, wo, wi, cos_i);
    }
    if m.clearcoat > 0.0 {
        f = clearcoat_cos(m, n, wo, wi, cos_i, f);
    }
    f
}

/// The specular part of [`eval_brdf_cos`] alone.
#[inline]
pub fn specular_cos(m: &SurfaceMaterial, n: Vec3, wo: Vec3, wi: Vec3, cos_i: f32) -> Vec3 {
    match colourless_lobe(m, n, wo, wi, cos_i) {
        None => Vec3::ZERO,
        Some((value, None)) => m.ks * value,
        Some((value, Some(cos_d))) => match m.conductor {
            None => fresnel_schlick(m.ks, cos_d) * value,
            Some(c) => m.ks * fresnel_conductor(cos_d, c.eta, c.k) * value,
        },
    }
}

/// [`specular_cos`] as an affine function of the specular colour `m.ks`:
/// `specular_cos = ks * scale + offset` (up to rounding), the other
/// parameters of `m` (lobe, exponent, roughness) as given and `m.ks`
/// itself unread. The parts flat and Gouraud shading compute per face or
/// vertex, to apply a textured `ks` (a metal's F0) per pixel.
#[inline]
pub fn specular_cos_factored(
    m: &SurfaceMaterial,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
    cos_i: f32,
) -> SpecularFactors {
    match (colourless_lobe(m, n, wo, wi, cos_i), m.conductor) {
        (None, _) => SpecularFactors::default(),
        (Some((value, None)), _) => SpecularFactors {
            scale: Vec3::splat(value),
            offset: 0.0,
        },
        // A conductor: F = ks F_c, linear in ks.
        (Some((value, Some(cos_d))), Some(c)) => SpecularFactors {
            scale: fresnel_conductor(cos_d, c.eta, c.k) * value,
            offset: 0.0,
        },
        // Schlick: F = F0 (1 - w) + w.
        (Some((value, Some(cos_d))), None) => {
            let w = schlick_weight(cos_d);
            SpecularFactors {
                scale: Vec3::splat((1.0 - w) * value),
                offset: w * value,
            }
        }
    }
}

/// The specular term per unit of the specular colour, and the part that
/// does not depend on it ([`specular_cos_factored`]), in 1/sr.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SpecularFactors {
    /// Multiplies `ks` (the lobe times `1 - w` of Schlick's Fresnel, or
    /// times a conductor's Fresnel reflectance per channel).
    pub scale: Vec3,
    /// Added whatever `ks` is (Schlick's white grazing reflection `w`
    /// times the lobe; zero for the Phong and Blinn lobes).
    pub offset: f32,
}

/// The specular lobe of `m` without its colour, the one body of
/// [`specular_cos`] and [`specular_cos_factored`]: `(value, cos_d)` where
/// the term is `ks * value` (Phong, Blinn: `cos_d` is `None`) or
/// `fresnel_schlick(ks, cos_d) * value` (Torrance-Sparrow, `cos_d = wi . h`);
/// `None` where it is zero.
#[inline(always)]
fn colourless_lobe(
    m: &SurfaceMaterial,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
    cos_i: f32,
) -> Option<(f32, Option<f32>)> {
    match m.model {
        ReflectanceModel::Phong => Some((phong_lobe(n, wo, wi, m.shininess) * FRAC_1_PI, None)),
        ReflectanceModel::Blinn => {
            if n.dot(wo) <= 0.0 {
                return None;
            }
            Some((blinn_lobe(n, wo, wi, m.shininess) * FRAC_1_PI, None))
        }
        ReflectanceModel::TorranceSparrow => {
            let cos_o = n.dot(wo);
            if cos_o <= 0.0 {
                return None;
            }
            let h = (wo + wi).try_normalize()?;
            let alpha = m.roughness.max(1e-3);
            let d = microfacet::d(m.distribution, n.dot(h), alpha);
            let g = microfacet::g_smith(m.distribution, cos_o, cos_i, alpha);
            // D G F / (4 cos_i cos_o) * cos_i
            Some((d * g / (4.0 * cos_o), Some(wi.dot(h).max(0.0))))
        }
    }
}

/// Directional albedo of the specular lobe for `wo` along the normal,
/// estimated for tests and energy checks: `integral f cos dwi`.
pub fn albedo_estimate(m: &SurfaceMaterial, n: Vec3, wo: Vec3, samples: u32) -> Vec3 {
    // Midpoint rule over the hemisphere in (cos theta, phi).
    let frame = crate::geometry::Frame::from_normal(n);
    let mut sum = Vec3::ZERO;
    let k = samples.max(4);
    for i in 0..k {
        for j in 0..k {
            let cos_t = (i as f32 + 0.5) / k as f32;
            let phi = 2.0 * PI * (j as f32 + 0.5) / k as f32;
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let wi = frame.to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t));
            sum += eval_brdf_cos(m, n, wo, wi);
        }
    }
    sum * (2.0 * PI / (k * k) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vertex_colour_reaches_a_metals_f0_and_a_classic_diffuse_colour() {
        let red = Vec3::new(1.0, 0.0, 0.0);
        let mut metal = Material {
            metallic_roughness: Some(MetallicRoughness {
                base_color: Vec3::splat(0.8),
                metallic: 1.0,
                roughness: 0.5,
                texture: None,
            }),
            ..Material::default()
        };
        let sm = SurfaceMaterial::with_vertex_color(&metal, red);
        assert_eq!(sm.kd, Vec3::ZERO);
        assert_eq!(sm.ks, Vec3::new(0.8, 0.0, 0.0));
        assert_eq!(sm.roughness, 0.25);
        assert_eq!(sm.ks_ambient, sm.ks);
        metal.metallic_roughness = None;
        metal.diffuse = Vec3::splat(0.5);
        let sm = SurfaceMaterial::with_vertex_color(&metal, red);
        assert_eq!(sm.kd, Vec3::new(0.5, 0.0, 0.0));
        assert_eq!(sm.ks, metal.specular);
    }

    fn spec(model: ReflectanceModel, n: f32) -> SurfaceMaterial {
        SurfaceMaterial {
            kd: Vec3::ZERO,
            ks: Vec3::ONE,
            shininess: n,
            model,
            ..SurfaceMaterial::default()
        }
    }

    #[test]
    fn phong_peaks_at_mirror_direction() {
        let m = spec(ReflectanceModel::Phong, 50.0);
        let wo = Vec3::new(1.0, 1.0, 0.0).normalize();
        let mirror = Vec3::new(-1.0, 1.0, 0.0).normalize();
        let peak = eval_brdf_cos(&m, Vec3::Y, wo, mirror).x;
        assert!(
            (peak * PI - 1.0).abs() < 1e-5,
            "ks (R.V)^n = 1 at the mirror direction"
        );
        for d in [0.05f32, 0.1, 0.3] {
            let off = (mirror + Vec3::new(d, 0.0, d)).normalize();
            assert!(eval_brdf_cos(&m, Vec3::Y, wo, off).x < peak);
        }
    }

    #[test]
    fn blinn_lobe_is_wider_than_phong_for_same_exponent() {
        // (N.H) >= (R.V) near the peak: Blinn with the same n is broader.
        let wo = Vec3::new(0.3, 1.0, 0.0).normalize();
        let wi = Vec3::new(-0.8, 1.0, 0.2).normalize();
        let p = eval_brdf_cos(&spec(ReflectanceModel::Phong, 30.0), Vec3::Y, wo, wi).x;
        let b = eval_brdf_cos(&spec(ReflectanceModel::Blinn, 30.0), Vec3::Y, wo, wi).x;
        assert!(b > p);
        // Classic relation: (N.H)^(4n) approximates (R.V)^n near the peak.
        let b4 = eval_brdf_cos(&spec(ReflectanceModel::Blinn, 120.0), Vec3::Y, wo, wi).x;
        assert!((b4 - p).abs() < 0.1 * p.max(1e-3) + 1e-3, "{b4} vs {p}");
    }

    #[test]
    fn lambert_albedo_is_kd() {
        let m = SurfaceMaterial {
            kd: Vec3::splat(0.6),
            ks: Vec3::ZERO,
            ..SurfaceMaterial::default()
        };
        let a = albedo_estimate(&m, Vec3::Z, Vec3::Z, 64);
        assert!((a.x - 0.6).abs() < 2e-3, "{a}");
    }

    #[test]
    fn microfacet_energy_is_bounded() {
        for alpha in [0.1f32, 0.3, 0.7] {
            for dist in [Distribution::Ggx, Distribution::Beckmann] {
                let m = SurfaceMaterial {
                    kd: Vec3::ZERO,
                    ks: Vec3::ONE,
                    model: ReflectanceModel::TorranceSparrow,
                    roughness: alpha,
                    distribution: dist,
                    ..SurfaceMaterial::default()
                };
                let a = albedo_estimate(&m, Vec3::Z, Vec3::Z, 400).x;
                // Energy is lost (rays reflected below the horizon, masking),
                // never gained; nearly none is lost for smooth surfaces.
                assert!(a <= 1.01, "alpha {alpha} {dist:?}: albedo {a}");
                if alpha <= 0.1 {
                    assert!(a > 0.95, "alpha {alpha} {dist:?}: albedo {a}");
                }
            }
        }
    }

    /// `ks * scale + offset` is the specular term, for every lobe, colour
    /// and pair of directions (including below the horizon).
    #[test]
    fn factored_specular_is_the_specular_term() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let models = [
            ReflectanceModel::Phong,
            ReflectanceModel::Blinn,
            ReflectanceModel::TorranceSparrow,
        ];
        let gold = ComplexIor {
            eta: Vec3::new(0.14, 0.37, 1.44),
            k: Vec3::new(3.98, 2.39, 1.6),
        };
        for (model, conductor) in models
            .into_iter()
            .map(|m| (m, None))
            .chain([(ReflectanceModel::TorranceSparrow, Some(gold))])
        {
            for _ in 0..2000 {
                let mut unit = || {
                    Vec3::new(next(), next(), next())
                        .try_normalize()
                        .unwrap_or(Vec3::Y)
                };
                let (wo, wi) = (unit(), unit());
                let m = SurfaceMaterial {
                    ks: Vec3::new(0.9, 0.5, 0.04),
                    model,
                    shininess: 12.0,
                    roughness: 0.2,
                    conductor,
                    ..SurfaceMaterial::default()
                };
                let cos_i = Vec3::Y.dot(wi);
                if cos_i <= 0.0 {
                    continue;
                }
                let want = specular_cos(&m, Vec3::Y, wo, wi, cos_i);
                let f = specular_cos_factored(&m, Vec3::Y, wo, wi, cos_i);
                let got = m.ks * f.scale + Vec3::splat(f.offset);
                let tol = 1e-5 * want.max_element().max(1.0);
                assert!(
                    (got - want).abs().max_element() <= tol,
                    "{model:?}: {got} vs {want}"
                );
                if model != ReflectanceModel::TorranceSparrow || conductor.is_some() {
                    assert_eq!(f.offset, 0.0);
                }
            }
        }
    }

    #[test]
    fn clear_coat_attenuates_the_base_and_adds_its_lobe() {
        let base = SurfaceMaterial {
            kd: Vec3::new(0.8, 0.2, 0.1),
            ks: Vec3::ZERO,
            ..SurfaceMaterial::default()
        };
        let coated = SurfaceMaterial {
            clearcoat: 1.0,
            clearcoat_alpha: 0.2,
            ..base
        };
        let (wo, wi) = (Vec3::Z, Vec3::new(0.6, 0.0, 0.8));
        // Seen head-on, the base keeps 1 - F(0) = 0.96 of its light, and the
        // coat adds a colourless lobe.
        let (a, coat) = clearcoat_parts(&coated, Vec3::Z, wo, wi, wi.z);
        assert!((a - 0.96).abs() < 1e-6, "{a}");
        assert!(coat > 0.0);
        let want = eval_brdf_cos(&base, Vec3::Z, wo, wi) * a + Vec3::splat(coat);
        let got = eval_brdf_cos(&coated, Vec3::Z, wo, wi);
        assert!((got - want).abs().max_element() < 1e-7, "{got} vs {want}");
        // The coat's lobe peaks at the mirror direction; its weight scales it.
        let half = SurfaceMaterial {
            clearcoat: 0.5,
            ..coated
        };
        let mirror = Vec3::Z;
        let (_, c1) = clearcoat_parts(&coated, Vec3::Z, wo, mirror, 1.0);
        let (_, c_half) = clearcoat_parts(&half, Vec3::Z, wo, mirror, 1.0);
        assert!(c1 > coat && (c_half - 0.5 * c1).abs() < 1e-6 * c1);
        // Energy: a white Lambertian base under a coat reflects at most all.
        let white = SurfaceMaterial {
            kd: Vec3::ONE,
            ..coated
        };
        for theta in [0.0f32, 40.0, 75.0] {
            let t = theta.to_radians();
            let wo = Vec3::new(t.sin(), 0.0, t.cos());
            let albedo = albedo_estimate(&white, Vec3::Z, wo, 400).x;
            assert!(albedo <= 1.01, "theta {theta}: {albedo}");
        }
    }

    #[test]
    fn conductor_fresnel_replaces_schlick_and_the_fixed_mirror() {
        let ior = ComplexIor {
            eta: Vec3::splat(0.789),
            k: Vec3::splat(6.15),
        };
        let plain = SurfaceMaterial {
            kd: Vec3::ZERO,
            ks: Vec3::new(1.0, 0.8, 0.6),
            kr: Vec3::new(1.0, 0.9, 0.5),
            model: ReflectanceModel::TorranceSparrow,
            roughness: 0.3,
            ..SurfaceMaterial::default()
        };
        let metal = SurfaceMaterial {
            conductor: Some(ior),
            ..plain
        };
        // Mirror: kr unchanged without a conductor, kr F_c(cos_o) with one.
        for cos_o in [1.0, 0.5, 0.1] {
            assert_eq!(plain.mirror_weight(cos_o), plain.kr);
            let f = fresnel_conductor(cos_o, ior.eta, ior.k);
            assert_eq!(metal.mirror_weight(cos_o), plain.kr * f);
        }
        // Glossy: ks F_c(wi . h) in place of Schlick's F(ks, wi . h).
        let wo = Vec3::new(0.6, 0.8, 0.0);
        let wi = Vec3::new(-0.3, 0.5, 0.2).normalize();
        let h = (wo + wi).normalize();
        let cos_i = Vec3::Y.dot(wi);
        let schlick = specular_cos(&plain, Vec3::Y, wo, wi, cos_i);
        let cond = specular_cos(&metal, Vec3::Y, wo, wi, cos_i);
        let ratio = cond / schlick;
        let want = plain.ks * fresnel_conductor(wi.dot(h), ior.eta, ior.k)
            / fresnel_schlick(plain.ks, wi.dot(h));
        assert!(
            (ratio - want).abs().max_element() < 1e-5,
            "{ratio} vs {want}"
        );
    }

    #[test]
    fn nothing_from_below() {
        let m = spec(ReflectanceModel::Phong, 10.0);
        assert_eq!(eval_brdf_cos(&m, Vec3::Y, Vec3::Y, -Vec3::Y), Vec3::ZERO);
    }
}
