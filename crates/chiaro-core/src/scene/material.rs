//! Materials: the lecture notes' classic coefficients plus the physical ones.

use super::TextureId;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Which specular lobe the local illumination model uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ReflectanceModel {
    /// Phong's `(R . V)^n`.
    #[default]
    Phong,
    /// Blinn's `(N . H)^n` with the half vector H.
    Blinn,
    /// Torrance-Sparrow / Cook-Torrance microfacets: `D G F / (4 cos_i cos_o)`
    /// with Schlick's Fresnel (F0 = ks) and Smith masking.
    TorranceSparrow,
}

/// Microfacet normal distribution for [`ReflectanceModel::TorranceSparrow`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Distribution {
    /// Beckmann (1963), the distribution of Cook and Torrance (1982).
    Beckmann,
    /// GGX / Trowbridge-Reitz (Walter et al. 2007).
    #[default]
    Ggx,
}

/// How a transmitting surface (kt > 0) is drawn by the scan converter, which
/// cannot refract (the ray tracers always refract).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum TransparencyMode {
    /// `I = (1 - kt) I_front + kt I_behind`, front specular kept.
    Interpolated,
    /// A dither mask covering a fraction `1 - kt` of the pixels.
    ScreenDoor,
    /// The surface tints what is behind it by its transmit colour.
    #[default]
    Filtered,
}

/// A bump map: a scalar height field whose gradient perturbs the normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bump {
    /// The height texture (its luminance is the height in `[0, 1]`).
    pub texture: TextureId,
    /// Height, in scene units, of a texture value of 1.
    pub height: f32,
}

/// glTF 2.0's metallic-roughness parameters (glTF 2.0 spec, appendix B),
/// evaluated per point: the base colour (these factors times
/// [`Material::texture`] and the vertex colour) goes to the diffuse colour
/// of a dielectric and to the specular colour (F0) of a metal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MetallicRoughness {
    /// `baseColorFactor` (RGB; alpha is [`Material::alpha`]).
    pub base_color: Vec3,
    /// `metallicFactor`.
    pub metallic: f32,
    /// `roughnessFactor` (perceptual roughness; the microfacet alpha is its square).
    pub roughness: f32,
    /// `metallicRoughnessTexture`: roughness in G, metallic in B (linear),
    /// multiplying the factors.
    pub texture: Option<TextureId>,
}

impl Default for MetallicRoughness {
    fn default() -> Self {
        Self {
            base_color: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            texture: None,
        }
    }
}

impl MetallicRoughness {
    /// The chiaro coefficients `(kd, ks, alpha)` of base colour `base`,
    /// metallic `metallic` and perceptual roughness `roughness`:
    /// `kd = base (1 - metallic)`, `ks = mix(0.04, base, metallic)` (F0 of
    /// Schlick's Fresnel), `alpha = roughness^2` clamped to `[1e-3, 1]`.
    pub fn coefficients(base: Vec3, metallic: f32, roughness: f32) -> (Vec3, Vec3, f32) {
        let metallic = if metallic.is_finite() {
            metallic.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let rough = if roughness.is_finite() {
            roughness.clamp(0.0, 1.0)
        } else {
            1.0
        };
        let base = base.max(Vec3::ZERO);
        (
            base * (1.0 - metallic),
            Vec3::splat(0.04).lerp(base, metallic),
            (rough * rough).clamp(1e-3, 1.0),
        )
    }
}

/// glTF `KHR_materials_transmission` of a metallic-roughness material: the
/// fraction of the dielectric part (`1 - metallic`) that is a Fresnel
/// dielectric tinted by the base colour instead of Lambertian.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transmission {
    /// `transmissionFactor` in `[0, 1]`.
    pub factor: f32,
    /// `transmissionTexture` (linear; R multiplies the factor).
    pub texture: Option<TextureId>,
}

impl Transmission {
    /// The coefficients `(kd, ks, kt)` of a point whose metallic-roughness
    /// coefficients are `kd`, `ks` (F0), with metallic `metallic` and
    /// transmission `t` (factor times texture), for a material of index of
    /// refraction `ior`: the fraction `t` of the diffuse colour becomes the
    /// transmission colour `kt` (glTF: the base colour tints the
    /// transmitted light). Unless the surface is thin-walled (ior 1, which
    /// neither bends nor reflects), the Fresnel dielectric then reflects
    /// that fraction's share of the specular lobe, `0.04 (1 - metallic) t`,
    /// which is taken off `ks`.
    pub fn split(kd: Vec3, ks: Vec3, metallic: f32, t: f32, ior: f32) -> (Vec3, Vec3, Vec3) {
        let t = if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let metallic = if metallic.is_finite() {
            metallic.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let ks = if ior == 1.0 {
            ks
        } else {
            (ks - Vec3::splat(0.04 * (1.0 - metallic) * t)).max(Vec3::ZERO)
        };
        (kd * (1.0 - t), ks, kd * t)
    }
}

/// A clear coat (glTF `KHR_materials_clearcoat`): a smooth or rough
/// dielectric layer of index 1.5 over the material, reflecting a fraction
/// `factor F` of the light and passing the rest to the base.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Clearcoat {
    /// `clearcoatFactor`: the layer's coverage in `[0, 1]`.
    pub factor: f32,
    /// `clearcoatRoughnessFactor`: perceptual roughness (alpha is its square).
    pub roughness: f32,
    /// `clearcoatTexture` (linear; R multiplies the factor).
    pub texture: Option<TextureId>,
    /// `clearcoatRoughnessTexture` (linear; G multiplies the roughness).
    pub roughness_texture: Option<TextureId>,
}

impl Default for Clearcoat {
    fn default() -> Self {
        Self {
            factor: 1.0,
            roughness: 0.0,
            texture: None,
            roughness_texture: None,
        }
    }
}

/// An ambient-occlusion texture (glTF `occlusionTexture`): its R channel
/// scales the ambient term, `1 + strength (R - 1)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Occlusion {
    /// The texture (linear; R is used).
    pub texture: TextureId,
    /// glTF `strength` in `[0, 1]`.
    pub strength: f32,
}

/// How the alpha of the base colour (factor, texture and vertex colour) is
/// used (glTF `alphaMode`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AlphaMode {
    /// Alpha is ignored.
    #[default]
    Opaque,
    /// Points with alpha below `cutoff` are not drawn; the rest are opaque.
    Mask {
        /// glTF `alphaCutoff`.
        cutoff: f32,
    },
    /// The surface covers a fraction alpha of what lies behind it.
    Blend,
}

/// Which faces of a surface the eye sees and how its back is shaded: one
/// rule for every technique (ARCHITECTURE.md, "Sidedness"). A triangle's
/// front is the side its counter-clockwise normal faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Sidedness {
    /// Both faces are drawn and shaded facing the viewer (normals flipped
    /// on the back): glTF `doubleSided: true`, and every format that says
    /// nothing about sidedness (OBJ, PLY, TOML by default).
    #[default]
    TwoSided,
    /// Both faces are drawn; the back reflects nothing, so it is black
    /// (Mitsuba's one-sided BSDFs). A transmissive surface is still shaded
    /// on the side the ray arrives from (the inside of a glass).
    OneSided,
    /// The eye does not see the back (glTF `doubleSided: false`): camera
    /// rays pass it and the scan converter culls it; every other ray sees
    /// both faces, shaded as `TwoSided` ("Single-sided culling").
    Culled,
}

/// How a viewer sees a surface: from the result of [`Sidedness::seen_from`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Facing {
    /// The front: shade with the normals as they are.
    Front,
    /// The back, shaded with both normals flipped towards the viewer.
    Back,
    /// The back of a one-sided surface: it reflects nothing.
    BackBlack,
}

impl Sidedness {
    /// How a viewer at cosine `cos_o = ng . wo` (geometric normal, unit
    /// direction to the viewer) sees the surface: [`Facing::Front`] when
    /// `cos_o >= 0`, else [`Facing::BackBlack`] for a one-sided surface that
    /// does not transmit and [`Facing::Back`] otherwise. Whether the eye
    /// sees a back at all is [`Sidedness::eye_sees_back`].
    pub fn seen_from(self, cos_o: f32, transmissive: bool) -> Facing {
        if cos_o >= 0.0 {
            Facing::Front
        } else if self == Sidedness::OneSided && !transmissive {
            Facing::BackBlack
        } else {
            Facing::Back
        }
    }

    /// False when camera rays skip the back and the scan converter culls it
    /// ([`Sidedness::Culled`]).
    pub fn eye_sees_back(self) -> bool {
        self != Sidedness::Culled
    }
}

/// A conductor's complex index of refraction `eta + i k` per RGB channel,
/// relative to the outside medium: its Fresnel reflectance
/// ([`crate::shading::fresnel_conductor`]) replaces the fixed mirror weight
/// and Schlick's Fresnel (see [`Material::conductor`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ComplexIor {
    /// Real part, the refractive index.
    pub eta: Vec3,
    /// Imaginary part, the extinction coefficient.
    pub k: Vec3,
}

/// A surface material. Colours are linear RGB.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Material {
    /// Name used by the scene file and in messages.
    pub name: String,
    /// ka: ambient reflectance *relative to the diffuse colour*: the ambient
    /// term is `Ia * ka * kd` (Foley's `Ia ka Od`), so textures modulate it.
    pub ambient: Vec3,
    /// kd: Lambertian albedo (BRDF `kd / pi`), also the albedo for radiosity
    /// and path tracing.
    pub diffuse: Vec3,
    /// ks: specular coefficient (Phong/Blinn weight, or F0 for microfacets).
    pub specular: Vec3,
    /// n: Phong/Blinn exponent.
    pub shininess: f32,
    /// The specular lobe.
    pub model: ReflectanceModel,
    /// Microfacet roughness (GGX/Beckmann alpha) for Torrance-Sparrow.
    pub roughness: f32,
    /// Microfacet distribution for Torrance-Sparrow.
    pub distribution: Distribution,
    /// kr: ideal mirror reflection weight for the ray tracers and environment maps.
    pub reflect: Vec3,
    /// kt: transmission (transparency) colour.
    pub transmit: Vec3,
    /// Index of refraction of the inside of the surface (outside is 1).
    pub ior: f32,
    /// Beer absorption coefficient per scene unit inside the medium.
    pub absorption: Vec3,
    /// True for a dielectric whose reflection/transmission split follows
    /// Fresnel's equations instead of fixed kr/kt.
    pub fresnel: bool,
    /// Scan-conversion transparency mode.
    pub transparency: TransparencyMode,
    /// Diffuse colour texture (multiplies `diffuse`).
    pub texture: Option<TextureId>,
    /// Bump map.
    pub bump: Option<Bump>,
    /// Tangent-space normal map (glTF).
    pub normal_map: Option<TextureId>,
    /// Emitted radiance (area lights, radiosity emitters).
    pub emission: Vec3,
    /// Texture multiplying `emission`.
    pub emission_texture: Option<TextureId>,
    /// Which faces the eye sees and how a back face is shaded (the one
    /// sidedness rule of every technique, ARCHITECTURE.md "Sidedness").
    pub sidedness: Sidedness,
    /// Emits from both faces; else from the front only, as one-sided area
    /// lights (glTF `doubleSided: true`; TOML `emission_two_sided`).
    pub emission_two_sided: bool,
    /// glTF metallic-roughness: when set, `diffuse`, `specular` and
    /// `roughness` are derived from it at every point (and hold its
    /// untextured values).
    pub metallic_roughness: Option<MetallicRoughness>,
    /// Ambient-occlusion texture.
    pub occlusion: Option<Occlusion>,
    /// Alpha of the base colour (glTF `baseColorFactor`'s alpha).
    pub alpha: f32,
    /// How alpha is used.
    pub alpha_mode: AlphaMode,
    /// glTF transmission: splits a metallic-roughness material's diffuse
    /// colour into diffuse and Fresnel-dielectric transmission per point.
    pub gltf_transmission: Option<Transmission>,
    /// A clear coat over every other lobe.
    pub clearcoat: Option<Clearcoat>,
    /// A conductor's complex IOR: when set, the mirror weight is
    /// `kr F(cos_o)` and the Torrance-Sparrow lobe's Fresnel is
    /// `ks F(wi . h)` with F the conductor's Fresnel reflectance, so `kr`
    /// and `ks` are tints (Mitsuba's `specular_reflectance`) instead of the
    /// fixed weight and Schlick's F0.
    pub conductor: Option<ComplexIor>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            ambient: Vec3::splat(0.1),
            diffuse: Vec3::splat(0.8),
            specular: Vec3::ZERO,
            shininess: 20.0,
            model: ReflectanceModel::Phong,
            roughness: 0.3,
            distribution: Distribution::Ggx,
            reflect: Vec3::ZERO,
            transmit: Vec3::ZERO,
            ior: 1.5,
            absorption: Vec3::ZERO,
            fresnel: false,
            transparency: TransparencyMode::Filtered,
            texture: None,
            bump: None,
            normal_map: None,
            emission: Vec3::ZERO,
            emission_texture: None,
            sidedness: Sidedness::TwoSided,
            emission_two_sided: false,
            metallic_roughness: None,
            occlusion: None,
            alpha: 1.0,
            alpha_mode: AlphaMode::Opaque,
            gltf_transmission: None,
            clearcoat: None,
            conductor: None,
        }
    }
}

impl Material {
    /// A named Lambertian material with albedo `kd`.
    pub fn diffuse(name: &str, kd: Vec3) -> Self {
        Self {
            name: name.into(),
            diffuse: kd,
            ..Self::default()
        }
    }

    /// True if the material is evaluated per point from textures (its
    /// coefficients vary over the surface), is BLEND (its coverage, factor
    /// x texture x vertex alpha, scales them per point), or is a glTF metal
    /// (its vertex colours reach F0, which the scan converter's
    /// per-vertex-colour shortcuts do not apply).
    pub fn is_textured(&self) -> bool {
        self.texture.is_some()
            || self.alpha_mode == AlphaMode::Blend
            || self.emission_texture.is_some()
            || self
                .metallic_roughness
                .is_some_and(|m| m.texture.is_some() || m.metallic > 0.0)
            || self.occlusion.is_some()
            || self.gltf_transmission.is_some_and(|t| t.texture.is_some())
            || self
                .clearcoat
                .is_some_and(|c| c.texture.is_some() || c.roughness_texture.is_some())
    }

    /// True if the surface emits light.
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// True if the surface lets light through: a transmit colour, or
    /// `alphaMode: BLEND` (whose per-point coverage the surface layer turns
    /// into straight-through transmission `1 - alpha`).
    pub fn is_transparent(&self) -> bool {
        self.transmit.max_element() > 0.0 || self.alpha_mode == AlphaMode::Blend
    }

    /// True if the material is alpha-tested (`alphaMode: MASK`).
    pub fn is_masked(&self) -> bool {
        matches!(self.alpha_mode, AlphaMode::Mask { .. })
    }

    /// True if the ray tracers should spawn a mirror ray.
    pub fn is_reflective(&self) -> bool {
        self.reflect.max_element() > 0.0 || (self.fresnel && self.is_transparent())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metallic_roughness_closed_forms() {
        let base = Vec3::new(0.8, 0.4, 0.2);
        // A dielectric: base colour to kd, F0 = 0.04.
        let (kd, ks, a) = MetallicRoughness::coefficients(base, 0.0, 0.5);
        assert_eq!((kd, ks, a), (base, Vec3::splat(0.04), 0.25));
        // A metal: no diffuse, F0 = base colour.
        let (kd, ks, _) = MetallicRoughness::coefficients(base, 1.0, 0.0);
        assert_eq!((kd, ks), (Vec3::ZERO, base));
        // Half metal; roughness 0 is clamped to a usable alpha; NaN is refused.
        let (kd, ks, a) = MetallicRoughness::coefficients(base, 0.5, 0.0);
        assert!((kd - base * 0.5).abs().max_element() < 1e-6);
        assert!((ks - (Vec3::splat(0.04) + base) * 0.5).abs().max_element() < 1e-6);
        assert_eq!(a, 1e-3);
        let (kd, ks, a) = MetallicRoughness::coefficients(base, f32::NAN, f32::NAN);
        assert!(kd.is_finite() && ks.is_finite() && a.is_finite());
    }
}
