//! The raw file structures of the `.toml` scene format: what serde reads,
//! before names are resolved and numbers are checked. Every struct rejects
//! unknown keys, and values that later checks must point at are kept in
//! [`toml::Spanned`] so their byte range in the file survives.

use chiaro_core::glam::Vec3;
use chiaro_core::scene::{
    AaMode, Distribution, PathSettings, PixelFilter, ProceduralKind, RadiositySettings,
    ReflectanceModel, ShadeMode, ShadowMapSettings, ShadowMethod, Sidedness, Technique, ToneMap,
    TransparencyMode, WhittedSettings, WrapMode,
};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use std::collections::BTreeMap;
use std::fmt;
use toml::Spanned;

/// A value with its byte range in the file.
pub(crate) type Sp<T> = Spanned<T>;
/// An optional spanned value.
pub(crate) type Opt<T> = Option<Spanned<T>>;

/// Three numbers `[x, y, z]`.
pub(crate) type V3 = [f32; 3];

/// A number written either as one scalar (meaning all three channels) or as
/// an array of three: `ambient = 0.1` or `ambient = [0.1, 0.1, 0.2]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Splat3 {
    /// One number for all three components.
    Scalar(f32),
    /// Three numbers.
    Vector(Vec3),
}

impl Splat3 {
    /// The value as a vector (a scalar repeated).
    pub(crate) fn vec3(self) -> Vec3 {
        match self {
            Splat3::Scalar(s) => Vec3::splat(s),
            Splat3::Vector(v) => v,
        }
    }
}

struct Splat3Visitor;

impl<'de> Visitor<'de> for Splat3Visitor {
    type Value = Splat3;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or an array of 3 numbers")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Splat3, E> {
        Ok(Splat3::Scalar(v as f32))
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Splat3, E> {
        Ok(Splat3::Scalar(v as f32))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Splat3, E> {
        Ok(Splat3::Scalar(v as f32))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Splat3, A::Error> {
        let mut out = [0.0f32; 3];
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = seq
                .next_element::<f32>()?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?;
        }
        if seq.next_element::<de::IgnoredAny>()?.is_some() {
            return Err(de::Error::invalid_length(4, &self));
        }
        Ok(Splat3::Vector(Vec3::from(out)))
    }
}

impl<'de> Deserialize<'de> for Splat3 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(Splat3Visitor)
    }
}

/// `attenuation = "none" | "inverse_square" | { c1, c2, c3 }`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum AttenuationSpec {
    /// `"none"`.
    None,
    /// `"inverse_square"`.
    InverseSquare,
    /// `{ c1, c2, c3 }`, any omitted coefficient 0 (c1 defaults to 1).
    Empirical(EmpiricalAttenuation),
}

/// The coefficients of `min(1 / (c1 + c2 d + c3 d^2), 1)`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EmpiricalAttenuation {
    #[serde(default = "one")]
    pub c1: f32,
    #[serde(default)]
    pub c2: f32,
    #[serde(default)]
    pub c3: f32,
}

fn one() -> f32 {
    1.0
}

struct AttenuationVisitor;

impl<'de> Visitor<'de> for AttenuationVisitor {
    type Value = AttenuationSpec;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(r#""none", "inverse_square" or a table { c1, c2, c3 }"#)
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<AttenuationSpec, E> {
        match v {
            "none" => Ok(AttenuationSpec::None),
            "inverse_square" => Ok(AttenuationSpec::InverseSquare),
            _ => Err(E::invalid_value(de::Unexpected::Str(v), &self)),
        }
    }
    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<AttenuationSpec, A::Error> {
        EmpiricalAttenuation::deserialize(de::value::MapAccessDeserializer::new(map))
            .map(AttenuationSpec::Empirical)
    }
}

impl<'de> Deserialize<'de> for AttenuationSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(AttenuationVisitor)
    }
}

/// A texture: `"path.png"` or a table
/// `{ procedural = "marble", scale, color_a, color_b, use_uv }` /
/// `{ image = "path.png", wrap, wrap_t }`, with `height` for bump maps.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TextureSpec {
    /// An image file, relative to the scene file.
    Path(String),
    /// The table form.
    Table(TextureTable),
}

/// The table form of a texture.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TextureTable {
    pub procedural: Option<ProceduralKind>,
    pub image: Option<String>,
    pub scale: Option<f32>,
    pub color_a: Option<Splat3>,
    pub color_b: Option<Splat3>,
    pub use_uv: Option<bool>,
    pub wrap: Option<WrapMode>,
    pub wrap_t: Option<WrapMode>,
    pub height: Option<f32>,
}

struct TextureVisitor;

impl<'de> Visitor<'de> for TextureVisitor {
    type Value = TextureSpec;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an image path or a table { procedural = ... } / { image = ... }")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<TextureSpec, E> {
        Ok(TextureSpec::Path(v.to_owned()))
    }
    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<TextureSpec, A::Error> {
        TextureTable::deserialize(de::value::MapAccessDeserializer::new(map))
            .map(TextureSpec::Table)
    }
}

impl<'de> Deserialize<'de> for TextureSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(TextureVisitor)
    }
}

/// A conductor's complex IOR: a metal's name (`"Au"`, Mitsuba's table) or
/// `{ eta = [..], k = [..] }` (each a number or three).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum RawConductor {
    /// A named metal.
    Named(String),
    /// Explicit `eta` and `k`.
    Ior(RawComplexIor),
}

/// `{ eta, k }`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawComplexIor {
    pub eta: Splat3,
    pub k: Splat3,
}

struct ConductorVisitor;

impl<'de> Visitor<'de> for ConductorVisitor {
    type Value = RawConductor;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a metal's name (\"Au\") or a table { eta = ..., k = ... }")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<RawConductor, E> {
        Ok(RawConductor::Named(v.to_owned()))
    }
    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<RawConductor, A::Error> {
        RawComplexIor::deserialize(de::value::MapAccessDeserializer::new(map))
            .map(RawConductor::Ior)
    }
}

impl<'de> Deserialize<'de> for RawConductor {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ConductorVisitor)
    }
}

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScene {
    pub render: Option<RawRender>,
    pub camera: Option<Sp<RawCamera>>,
    #[serde(default)]
    pub cameras: BTreeMap<Sp<String>, Sp<RawCamera>>,
    #[serde(default)]
    pub light: Vec<Sp<RawLight>>,
    #[serde(default)]
    pub material: BTreeMap<Sp<String>, Sp<RawMaterial>>,
    #[serde(default)]
    pub object: Vec<Sp<RawObject>>,
    pub environment: Option<Sp<RawEnvironment>>,
    pub background: Opt<Splat3>,
}

/// `[render]`: [`chiaro_core::scene::RenderSettings`] as written in a file
/// (every key optional, `depth_cue.color` a scalar or three numbers).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRender {
    pub technique: Option<Technique>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub samples: Option<u32>,
    pub seed: Option<u64>,
    pub shadows: Option<ShadowMethod>,
    pub transparency: Option<TransparencyMode>,
    pub aa: Option<AaMode>,
    pub filter: Option<PixelFilter>,
    pub light_samples: Option<u32>,
    pub light_selection: Option<chiaro_core::scene::LightSelection>,
    pub depth_cue: Option<RawDepthCue>,
    pub tonemap: Option<ToneMap>,
    pub exposure: Option<f32>,
    pub cull_backfaces: Option<bool>,
    pub shadow_map: Option<ShadowMapSettings>,
    pub whitted: Option<WhittedSettings>,
    pub path: Option<PathSettings>,
    pub radiosity: Option<RadiositySettings>,
    pub memory_limit: Option<chiaro_core::budget::ByteSize>,
}

/// `[render.depth_cue]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDepthCue {
    pub color: Option<Splat3>,
    pub near: Option<f32>,
    pub far: Option<f32>,
    pub max_scale: Option<f32>,
    pub min_scale: Option<f32>,
}

/// `[camera]` and each `[cameras.NAME]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCamera {
    pub eye: Opt<V3>,
    pub look_at: Opt<V3>,
    pub up: Opt<V3>,
    pub fov: Opt<f32>,
    pub near: Opt<f32>,
    pub far: Opt<f32>,
    /// `"perspective"` (the default) or `"orthographic"`.
    pub projection: Opt<String>,
    /// An orthographic camera's film half-height, scene units.
    pub half_height: Opt<f32>,
}

/// One of Warn's flaps: `{ axis = [1, 0, 0], min = -1, max = 1 }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFlap {
    pub axis: V3,
    #[serde(default = "neg_inf")]
    pub min: f32,
    #[serde(default = "pos_inf")]
    pub max: f32,
}

fn neg_inf() -> f32 {
    f32::NEG_INFINITY
}
fn pos_inf() -> f32 {
    f32::INFINITY
}

/// `[[light]]`: one struct for every type; fields that do not apply to the
/// given type are rejected with their position.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLight {
    #[serde(rename = "type")]
    pub kind: Sp<String>,
    pub color: Opt<Splat3>,
    pub intensity: Opt<f32>,
    pub position: Opt<V3>,
    pub direction: Opt<V3>,
    pub look_at: Opt<V3>,
    pub attenuation: Opt<AttenuationSpec>,
    pub exponent: Opt<f32>,
    pub cone: Opt<f32>,
    pub cone_softness: Opt<f32>,
    pub flaps: Opt<Vec<RawFlap>>,
    pub shape: Opt<String>,
    pub corner: Opt<V3>,
    pub edge_u: Opt<V3>,
    pub edge_v: Opt<V3>,
    pub center: Opt<V3>,
    pub normal: Opt<V3>,
    pub radius: Opt<f32>,
    pub two_sided: Opt<bool>,
}

/// `[material.NAME]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMaterial {
    pub ambient: Opt<Splat3>,
    pub diffuse: Opt<Splat3>,
    pub specular: Opt<Splat3>,
    pub shininess: Opt<f32>,
    pub model: Option<ReflectanceModel>,
    pub roughness: Opt<f32>,
    pub distribution: Option<Distribution>,
    pub conductor: Opt<RawConductor>,
    pub reflect: Opt<Splat3>,
    pub transmit: Opt<Splat3>,
    pub ior: Opt<f32>,
    pub absorption: Opt<Splat3>,
    pub fresnel: Option<bool>,
    pub transparency: Option<TransparencyMode>,
    pub texture: Opt<TextureSpec>,
    pub bump: Opt<TextureSpec>,
    pub normal_map: Opt<TextureSpec>,
    pub emission: Opt<Splat3>,
    pub emission_texture: Opt<TextureSpec>,
    pub sidedness: Option<Sidedness>,
    pub emission_two_sided: Option<bool>,
    /// Older spelling: `true` is `sidedness = "two-sided"` with
    /// `emission_two_sided = true`, `false` is `sidedness = "one-sided"`.
    pub two_sided: Option<bool>,
    /// Older spelling: `true` is `sidedness = "culled"`.
    pub cull_backface: Option<bool>,
}

/// `transform = { translate, rotate_x, rotate_y, rotate_z | rotate, scale, matrix }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTransform {
    pub translate: Option<V3>,
    pub rotate_x: Opt<f32>,
    pub rotate_y: Opt<f32>,
    pub rotate_z: Opt<f32>,
    pub rotate: Opt<V3>,
    pub scale: Opt<Splat3>,
    pub matrix: Opt<[f32; 16]>,
}

/// `[[object]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawObject {
    pub name: Option<String>,
    pub mesh: Opt<String>,
    pub primitive: Opt<String>,
    pub material: Opt<String>,
    pub transform: Opt<RawTransform>,
    pub smooth: Option<bool>,
    pub crease_angle: Opt<f32>,
    pub shade: Option<ShadeMode>,
    pub casts_shadows: Option<bool>,
    // Primitive parameters.
    pub radius: Opt<f32>,
    pub size: Opt<Splat3>,
    pub height: Opt<f32>,
    pub segments: Opt<u32>,
    pub stacks: Opt<u32>,
    pub subdivisions: Opt<u32>,
    pub corner: Opt<V3>,
    pub edge_u: Opt<V3>,
    pub edge_v: Opt<V3>,
}

/// `[environment]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawEnvironment {
    pub texture: Sp<String>,
    pub intensity: Option<f32>,
    pub rotate_y: Option<f32>,
    pub background: Option<bool>,
}
