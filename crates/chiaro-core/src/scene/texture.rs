//! Textures: decoded images (linear RGB(A) f32) and procedural solid textures.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// What happens to texture coordinates outside `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
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

/// A decoded image. Texels are linear (sRGB already removed for colour
/// textures), row-major from the top-left, RGBA.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct ImageTexture {
    /// Where the image came from (for messages and `chiaro info`).
    pub source: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width * height` texels.
    pub texels: Vec<[f32; 4]>,
    /// Wrap mode for u and v.
    pub wrap: WrapMode,
}

impl ImageTexture {
    /// The texel at integer coordinates (already wrapped, in range).
    #[inline]
    pub fn texel(&self, x: u32, y: u32) -> [f32; 4] {
        self.texels[(y * self.width + x) as usize]
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
