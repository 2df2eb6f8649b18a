//! Materials: the classic coefficients of the seeds plus the physical ones.

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
    /// Draw and shade both faces (no back-face culling, normals flipped to
    /// face the viewer).
    pub two_sided: bool,
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
            two_sided: false,
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

    /// True if the surface emits light.
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// True if the surface lets light through.
    pub fn is_transparent(&self) -> bool {
        self.transmit.max_element() > 0.0
    }

    /// True if the ray tracers should spawn a mirror ray.
    pub fn is_reflective(&self) -> bool {
        self.reflect.max_element() > 0.0 || (self.fresnel && self.is_transparent())
    }
}
