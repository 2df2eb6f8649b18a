//! Textures: decoded images (linear RGBA `f32`, or the 8-bit codes of an
//! 8-bit file decoded at each lookup) and procedural solid textures.

use glam::{Mat2, Vec2, Vec3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::sync::{Arc, LazyLock};

/// What happens to texture coordinates outside `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WrapMode {
    /// Tile the image.
    #[default]
    Repeat,
    /// Clamp to the edge texels.
    Clamp,
    /// Tile with every other copy mirrored.
    Mirror,
}

/// A texture filter: the nearest texel or a bilinear blend of four.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Filter {
    /// The nearest texel (or mip level).
    Nearest,
    /// Linear interpolation between texels (or between two mip levels).
    #[default]
    Linear,
}

/// An affine map applied to the texture coordinates before the lookup
/// (glTF's `KHR_texture_transform`): `uv' = T * R * S * uv`, with `R` a
/// rotation by `rotation` radians counter-clockwise in uv space as the
/// extension defines it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct UvTransform {
    /// Translation, added last.
    pub offset: Vec2,
    /// Rotation in radians.
    pub rotation: f32,
    /// Per-axis scale, applied first.
    pub scale: Vec2,
}

impl Default for UvTransform {
    fn default() -> Self {
        Self {
            offset: Vec2::ZERO,
            rotation: 0.0,
            scale: Vec2::ONE,
        }
    }
}

impl UvTransform {
    /// The linear part as a column-major 2x2 matrix (applies to uv derivatives).
    pub fn linear(&self) -> Mat2 {
        let (s, c) = self.rotation.sin_cos();
        // The extension's matrix: [[c, s], [-s, c]] (rows) times the scale.
        Mat2::from_cols(Vec2::new(c, -s), Vec2::new(s, c)) * Mat2::from_diagonal(self.scale)
    }

    /// Applies the transform to `uv`.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        self.linear() * uv + self.offset
    }

    /// True for the identity.
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }
}

/// How the colour codes of [`Texels8`] become linear values (alpha is
/// always `code / 255`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Encoding8 {
    /// sRGB-encoded colour (base colour, emission): the sRGB EOTF.
    Srgb,
    /// Linear data (normal, metallic-roughness, occlusion maps): `code / 255`.
    Unorm,
}

/// The 256 linear values of each encoding's codes, built once.
struct Decode8 {
    srgb: [f32; 256],
    unorm: [f32; 256],
}

static DECODE8: LazyLock<Decode8> = LazyLock::new(|| Decode8 {
    srgb: crate::film::tonemap::srgb8_to_linear_table(),
    unorm: std::array::from_fn(|v| v as f32 / 255.0),
});

/// The texels of an 8-bit image as its file holds them (RGBA codes,
/// row-major from the top-left), decoded at each lookup. Four bytes a texel
/// instead of sixteen; clones share the codes (the mip-map's level 0 and a
/// scene's imported textures are not copies).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Texels8 {
    /// How colour codes map to linear values.
    pub encoding: Encoding8,
    #[serde(serialize_with = "ser_codes", deserialize_with = "de_codes")]
    codes: Arc<[[u8; 4]]>,
}

fn ser_codes<S: Serializer>(codes: &Arc<[[u8; 4]]>, s: S) -> Result<S::Ok, S::Error> {
    codes.as_ref().serialize(s)
}

fn de_codes<'de, D: Deserializer<'de>>(d: D) -> Result<Arc<[[u8; 4]]>, D::Error> {
    Vec::<[u8; 4]>::deserialize(d).map(Arc::from)
}

impl Texels8 {
    /// Texels from their RGBA codes.
    pub fn new(encoding: Encoding8, codes: Vec<[u8; 4]>) -> Self {
        Self {
            encoding,
            codes: Arc::from(codes),
        }
    }

    /// The RGBA codes.
    pub fn codes(&self) -> &[[u8; 4]] {
        &self.codes
    }

    /// Texel `i` as linear RGBA: the same `f32` values an image decoded to
    /// `f32` at load holds, bit for bit.
    #[inline]
    pub fn decode(&self, i: usize) -> [f32; 4] {
        let t = &*DECODE8;
        let [r, g, b, a] = self.codes[i];
        let colour = match self.encoding {
            Encoding8::Srgb => &t.srgb,
            Encoding8::Unorm => &t.unorm,
        };
        [
            colour[usize::from(r)],
            colour[usize::from(g)],
            colour[usize::from(b)],
            t.unorm[usize::from(a)],
        ]
    }
}

/// A decoded image, row-major from the top-left, RGBA, linear (sRGB is
/// removed for colour textures): either `f32` texels or, for 8-bit files,
/// their codes ([`Texels8`]). Read texels through [`ImageTexture::texel`]
/// and [`ImageTexture::texel_at`], which see both alike.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageTexture {
    /// Where the image came from (for messages and `chiaro info`).
    pub source: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width * height` linear `f32` texels (HDR and 16-bit files, images
    /// built in code); empty when `texels8` holds the image.
    pub texels: Vec<[f32; 4]>,
    /// The `width * height` texels of an 8-bit file; `None` for `f32` images.
    #[serde(default)]
    pub texels8: Option<Texels8>,
    /// Wrap mode for u (glTF's `wrapS`), and for v unless `wrap_t` is set.
    pub wrap: WrapMode,
    /// Wrap mode for v (glTF's `wrapT`); `None`: the same as `wrap`.
    #[serde(default)]
    pub wrap_t: Option<WrapMode>,
    /// Filter when a texel covers more than a pixel.
    #[serde(default)]
    pub mag_filter: Filter,
    /// Filter within a mip level when a pixel covers more than a texel.
    #[serde(default)]
    pub min_filter: Filter,
    /// Filter between mip levels; `None`: no mip-mapping (level 0 only).
    #[serde(default = "default_mip_filter")]
    pub mip_filter: Option<Filter>,
    /// Transform of the texture coordinates before the lookup.
    #[serde(default)]
    pub uv_transform: UvTransform,
    /// Which texture-coordinate set the lookup reads: 0 the mesh's `uvs`,
    /// 1 its `uvs1` (its `uvs` where it has no second set).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub uv_set: u8,
}

fn is_zero(v: &u8) -> bool {
    *v == 0
}

fn default_mip_filter() -> Option<Filter> {
    Some(Filter::Linear)
}

impl Default for ImageTexture {
    fn default() -> Self {
        Self {
            source: String::new(),
            width: 0,
            height: 0,
            texels: Vec::new(),
            texels8: None,
            wrap: WrapMode::Repeat,
            wrap_t: None,
            mag_filter: Filter::Linear,
            min_filter: Filter::Linear,
            mip_filter: default_mip_filter(),
            uv_transform: UvTransform::default(),
            uv_set: 0,
        }
    }
}

impl ImageTexture {
    /// The texel at integer coordinates (already wrapped, in range).
    #[inline]
    pub fn texel(&self, x: u32, y: u32) -> [f32; 4] {
        self.texel_at((y * self.width + x) as usize)
    }

    /// Texel `i` in row-major order, linear RGBA.
    #[inline]
    pub fn texel_at(&self, i: usize) -> [f32; 4] {
        match &self.texels8 {
            Some(t) => t.decode(i),
            None => self.texels[i],
        }
    }

    /// How many texels the image holds (0: it samples as white).
    #[inline]
    pub fn texel_count(&self) -> usize {
        match &self.texels8 {
            Some(t) => t.codes.len(),
            None => self.texels.len(),
        }
    }

    /// The bytes its texels take (shared 8-bit codes counted in full).
    pub fn texel_bytes(&self) -> usize {
        std::mem::size_of_val(self.texels.as_slice())
            + self
                .texels8
                .as_ref()
                .map_or(0, |t| std::mem::size_of_val(t.codes()))
    }

    /// The wrap modes of u and v.
    #[inline]
    pub fn wrap_uv(&self) -> (WrapMode, WrapMode) {
        (self.wrap, self.wrap_t.unwrap_or(self.wrap))
    }

    /// An image with default sampling (repeat, trilinear, no uv transform).
    pub fn new(source: String, width: u32, height: u32, texels: Vec<[f32; 4]>) -> Self {
        Self {
            source,
            width,
            height,
            texels,
            ..Self::default()
        }
    }

    /// An 8-bit image from its `width * height` RGBA codes, colour
    /// sRGB-encoded when `srgb` (else `code / 255`), with default sampling.
    pub fn new_8bit(
        source: String,
        width: u32,
        height: u32,
        codes: Vec<[u8; 4]>,
        srgb: bool,
    ) -> Self {
        let encoding = if srgb {
            Encoding8::Srgb
        } else {
            Encoding8::Unorm
        };
        Self {
            source,
            width,
            height,
            texels8: Some(Texels8::new(encoding, codes)),
            ..Self::default()
        }
    }
}

/// The procedural solid textures, evaluated at the object-space point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProceduralKind {
    /// 3D checkerboard of unit cells.
    Checker,
    /// Concentric wood rings about the y axis, perturbed by noise.
    Wood,
    /// Marble veins: `sin(x + turbulence)`.
    Marble,
    /// Perlin noise in `[0, 1]`.
    Noise,
    /// Dimples: a lattice of spherical dents (a bump-map pattern).
    Dimples,
}

/// A procedural solid texture blending two colours.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Procedural {
    /// Which pattern.
    pub kind: ProceduralKind,
    /// Cells (or rings, or noise features) per scene unit.
    pub scale: f32,
    /// Colour at pattern value 0.
    pub color_a: Vec3,
    /// Colour at pattern value 1.
    pub color_b: Vec3,
    /// Use the uv coordinates (`(u, v, 0)`) instead of the object-space point.
    pub use_uv: bool,
}

/// A texture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Texture {
    /// A decoded image.
    Image(ImageTexture),
    /// A procedural solid texture.
    Procedural(Procedural),
}

/// An environment map: a lat-long (equirectangular) image of radiance around
/// the scene. Direction `+y` is up; `u = 0.5` looks down `-z`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Environment {
    /// The lat-long image.
    pub texture: super::TextureId,
    /// Radiance scale.
    pub intensity: f32,
    /// Rotation about +y, degrees, right-handed as an object's `rotate_y`:
    /// +90 shows the map's `-z` towards `-x`.
    pub rotate_y_degrees: f32,
    /// Camera rays see it where nothing is hit (otherwise they see
    /// `Scene::background`); reflected rays and lighting always use it.
    pub as_background: bool,
}
