//! Texture evaluation, shared by every technique: image textures (bilinear,
//! and trilinear through [`MipMap`] pyramids), procedural solid textures
//! (checker, wood, marble, noise, dimples, from Perlin noise and turbulence),
//! bump mapping by the height gradient, tangent-space normal maps, and the
//! lat-long environment map and its prefiltered image-based lighting.

mod bump;
mod environment;
mod image;
mod latlong;
mod mipmap;
mod prefiltered;
mod procedural;
#[cfg(test)]
mod tests;

pub use bump::{bump_normal, normal_map_normal, uv_surface_gradient};
pub use environment::{
    EnvironmentLight, EnvironmentSample, EnvironmentSamples, background_radiance,
    environment_mean_radiance, environment_radiance, miss_radiance,
};
use image::filtered;
pub use image::{bilinear, nearest, wrap_index};
pub use latlong::{MAX_ANGLE_ERROR, atan2, latlong_dir, latlong_uv, latlong_uv_lanes, sin_cos};
pub use mipmap::MipMap;
pub use prefiltered::{
    LEVEL_ALPHAS, PrefilteredEnvironment, environment_diffuse, environment_specular,
    specular_albedo_scale_bias, specular_lobe_albedo,
};
pub use procedural::{pattern, perlin_noise, procedural_color, procedural_value, turbulence};

use crate::scene::Texture;
use glam::{Vec2, Vec3, Vec4};

/// Where a texture is looked up: the uv with its screen-space derivatives
/// (zero for "no footprint": the finest level), and the object-space point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TexCoord {
    /// Texture coordinates.
    pub uv: Vec2,
    /// d(uv)/dx per pixel.
    pub duv_dx: Vec2,
    /// d(uv)/dy per pixel.
    pub duv_dy: Vec2,
    /// Object-space point (solid textures).
    pub p_object: Vec3,
    /// The second texture-coordinate set (image textures with `uv_set` 1).
    pub uv1: Vec2,
    /// d(uv1)/dx per pixel.
    pub duv1_dx: Vec2,
    /// d(uv1)/dy per pixel.
    pub duv1_dy: Vec2,
}

/// Evaluates texture `t` at `tc` as linear RGBA: image textures (at the
/// uv set they name, their uv transform applied) through the mip-map `mip` when given, with the image's
/// filters, else its magnification filter on the base image;
/// procedural textures give their colour with alpha 1.
pub fn eval_texture(t: &Texture, mip: Option<&MipMap>, tc: &TexCoord) -> Vec4 {
    match t {
        Texture::Image(img) => {
            let tr = &img.uv_transform;
            // The one place a texture's uv set is chosen, for every technique.
            let (uv, dx, dy) = match img.uv_set {
                1 => (tc.uv1, tc.duv1_dx, tc.duv1_dy),
                _ => (tc.uv, tc.duv_dx, tc.duv_dy),
            };
            let (uv, dx, dy) = if tr.is_identity() {
                (uv, dx, dy)
            } else {
                let l = tr.linear();
                (tr.apply(uv), l * dx, l * dy)
            };
            match mip {
                Some(m) => m.sample_footprint(uv, dx, dy),
                None => filtered(img, uv, img.mag_filter),
            }
        }
        Texture::Procedural(p) => procedural_color(p, tc.p_object, tc.uv).extend(1.0),
    }
}

/// Scalar height of texture `t` at `tc` in `[0, 1]`: the pattern value of a
/// procedural texture, the Rec. 709 luminance of an image.
pub fn eval_height(t: &Texture, mip: Option<&MipMap>, tc: &TexCoord) -> f32 {
    match t {
        Texture::Procedural(p) => procedural_value(p, tc.p_object, tc.uv),
        Texture::Image(_) => {
            let c = eval_texture(t, mip, tc);
            0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
        }
    }
}
