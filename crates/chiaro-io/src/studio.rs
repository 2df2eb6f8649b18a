//! The neutral studio: the environment that lights a model file without
//! lights, computed here rather than read from a file.
//!
//! It follows what glTF viewers light models with (three.js's
//! `RoomEnvironment`, model-viewer's "neutral"): a room that is bright and
//! soft in every direction, so a mirror-like metal reflects something of
//! its own colour wherever it faces, and a few rectangular softboxes,
//! brighter, that give glossy surfaces their highlights and a sense of
//! shape. The dome is brightest overhead and darkest at the floor; the
//! softboxes sit overhead, front right (with the key light), front left
//! (a fill) and behind (a rim).
//!
//! [`neutral_studio_radiance`] is the radiance in a direction (y up, the
//! model's front +z), relative: [`crate::add_studio_environment`] scales it to a
//! chosen mean. [`neutral_studio_texture`] bakes it into a lat-long image
//! laid out as `texture::latlong_uv` reads one, which every technique then
//! uses as any other environment map.

use chiaro_core::Vec3;
use chiaro_core::scene::ImageTexture;
use std::f32::consts::{PI, TAU};

/// A rectangular softbox of the studio: its centre direction (azimuth from
/// the front +z towards +x, elevation above the horizon, degrees), its
/// angular half-sizes (degrees) and its radiance relative to the dome's at
/// the horizon.
struct Softbox {
    azimuth: f32,
    elevation: f32,
    half_width: f32,
    half_height: f32,
    radiance: f32,
}

/// The softboxes: overhead, the key (front right, high, where
/// `default_lights` shines from), a fill (front left, low) and a rim
/// (behind, high).
const SOFTBOXES: [Softbox; 4] = [
    Softbox {
        azimuth: 0.0,
        elevation: 90.0,
        half_width: 22.0,
        half_height: 22.0,
        radiance: 2.0,
    },
    Softbox {
        azimuth: 20.0,
        elevation: 40.0,
        half_width: 16.0,
        half_height: 12.0,
        radiance: 3.0,
    },
    Softbox {
        azimuth: -60.0,
        elevation: 15.0,
        half_width: 10.0,
        half_height: 14.0,
        radiance: 1.5,
    },
    Softbox {
        azimuth: 180.0,
        elevation: 40.0,
        half_width: 25.0,
        half_height: 8.0,
        radiance: 2.5,
    },
];

/// Width of a softbox's soft edge, as a fraction of its half-size.
const SOFT_EDGE: f32 = 0.15;

/// Cubic smoothstep of `t` clamped to `[0, 1]`.
fn smoothstep(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The unit direction at `azimuth` (from +z towards +x) and `elevation`
/// (towards +y), radians.
fn direction(azimuth: f32, elevation: f32) -> Vec3 {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    Vec3::new(ce * sa, se, ce * ca)
}

impl Softbox {
    /// How much of the softbox covers unit direction `d`: 1 inside, 0
    /// outside, smooth across the edge. The box is a rectangle in the
    /// tangent angles round its centre (`atan` of `d` along its right and
    /// up over its centre), so a box overhead is as square as one on the
    /// horizon.
    fn coverage(&self, d: Vec3) -> f32 {
        let c = direction(self.azimuth.to_radians(), self.elevation.to_radians());
        let reference = if c.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
        let right = reference.cross(c).normalize();
        let up = c.cross(right);
        let depth = d.dot(c);
        if depth <= 0.0 {
            return 0.0;
        }
        let x = d.dot(right).atan2(depth).to_degrees().abs() / self.half_width;
        let y = d.dot(up).atan2(depth).to_degrees().abs() / self.half_height;
        smoothstep((1.0 - x) / SOFT_EDGE) * smoothstep((1.0 - y) / SOFT_EDGE)
    }
}

/// The studio's relative radiance (grey, so one number) in unit direction
/// `d`, y up: the dome, `1 + 0.15 sin(e)` above the horizon and `1 + 0.35
/// sin(e)` below it (`e` the elevation: 1.15 at the zenith, 0.65 at the
/// floor), plus each softbox where it covers `d`.
pub fn neutral_studio_radiance(d: Vec3) -> f32 {
    let s = d.y.clamp(-1.0, 1.0);
    let dome = if s >= 0.0 {
        1.0 + 0.15 * s
    } else {
        1.0 + 0.35 * s
    };
    SOFTBOXES
        .iter()
        .fold(dome, |l, b| l + b.radiance * b.coverage(d))
}

/// [`neutral_studio_radiance`] baked into a `width` x `height` lat-long
/// image (texel centres; `u` the azimuth with +z at `u = 0`, -z at 0.5 and
/// +x at 0.75, `v` from the top, as `texture::latlong_uv`), relative
/// radiance, repeating in `u`.
pub fn neutral_studio_texture(width: u32, height: u32) -> ImageTexture {
    let (w, h) = (width.max(1), height.max(1));
    let mut texels = Vec::with_capacity((w * h) as usize);
    for j in 0..h {
        let theta = (j as f32 + 0.5) / h as f32 * PI;
        for i in 0..w {
            let phi = ((i as f32 + 0.5) / w as f32 - 0.5) * TAU;
            let (st, ct) = theta.sin_cos();
            let d = Vec3::new(st * phi.sin(), ct, -st * phi.cos());
            let l = neutral_studio_radiance(d);
            texels.push([l, l, l, 1.0]);
        }
    }
    ImageTexture {
        source: format!("neutral studio ({w}x{h}, computed)"),
        width: w,
        height: h,
        texels,
        ..ImageTexture::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::shading::texture::latlong_uv;

    #[test]
    fn the_dome_is_bright_everywhere_and_the_softboxes_brighter() {
        // Between the floor's 0.65 and the softboxes' peaks; nowhere dark.
        let t = neutral_studio_texture(128, 64);
        let min = t.texels.iter().map(|t| t[0]).fold(f32::INFINITY, f32::min);
        let max = t.texels.iter().map(|t| t[0]).fold(0.0, f32::max);
        assert!(min > 0.6 && min < 0.7, "{min}");
        assert!(max > 3.0 && max < 5.0, "{max}");
        // The key softbox's centre, a direction well clear of every box.
        let key = direction(20f32.to_radians(), 40f32.to_radians());
        assert!(neutral_studio_radiance(key) > 3.5);
        let clear = direction(100f32.to_radians(), -10f32.to_radians());
        let l = neutral_studio_radiance(clear);
        assert!((l - (1.0 - 0.35 * 10f32.to_radians().sin())).abs() < 1e-5);
    }

    #[test]
    fn texels_sit_where_latlong_uv_reads_them() {
        // The texel that `latlong_uv` maps the key softbox's centre to holds
        // the softbox; the one opposite does not.
        let (w, h) = (128, 64);
        let t = neutral_studio_texture(w, h);
        let at = |d: Vec3| {
            let uv = latlong_uv(d);
            let i = ((uv.x * w as f32) as u32).min(w - 1);
            let j = ((uv.y * h as f32) as u32).min(h - 1);
            t.texels[(j * w + i) as usize][0]
        };
        let key = direction(20f32.to_radians(), 40f32.to_radians());
        assert!(at(key) > 3.5, "{}", at(key));
        assert!(at(-key) < 1.2, "{}", at(-key));
    }
}
