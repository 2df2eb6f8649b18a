//! The camera: a pinhole perspective camera or an orthographic one.

use crate::geometry::Ray;
use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// How a [`Camera`] projects the scene onto its image.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Projection {
    /// A pinhole at the eye: rays fan out over `fov_y_degrees`.
    #[default]
    Perspective,
    /// Parallel rays along the viewing direction, from a film rectangle
    /// centred on the eye and `2 half_height` scene units high (the width
    /// follows the image's aspect ratio); `fov_y_degrees` is unused.
    Orthographic {
        /// Half the height of the film, scene units (> 0).
        half_height: f32,
    },
}

impl Projection {
    /// True for [`Projection::Perspective`] (serde skips the default).
    pub fn is_perspective(&self) -> bool {
        *self == Projection::Perspective
    }
}

/// A camera given by eye, target, up and its [`Projection`]: a vertical
/// field of view (perspective) or a film half-height (orthographic). The
/// aspect ratio comes from the image being rendered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Camera {
    /// Eye position, world space.
    pub eye: Vec3,
    /// Point the camera looks at, world space.
    pub look_at: Vec3,
    /// Approximate up direction; orthogonalised against the view direction.
    pub up: Vec3,
    /// Vertical field of view in degrees (0 < fov < 180).
    pub fov_y_degrees: f32,
    /// Near clip distance for the scan converter (scene units, > 0).
    pub near: f32,
    /// Far clip distance for the scan converter (scene units, > near).
    pub far: f32,
    /// Perspective (the default) or orthographic.
    #[serde(skip_serializing_if = "Projection::is_perspective")]
    pub projection: Projection,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            eye: Vec3::new(0.0, 0.0, 5.0),
            look_at: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_degrees: 45.0,
            near: 0.01,
            far: 1.0e5,
            projection: Projection::Perspective,
        }
    }
}

/// A camera the scene offers by name (a glTF camera, a TOML
/// `[cameras.NAME]` table), chosen with `--camera NAME`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedCamera {
    /// The name it is chosen by.
    pub name: String,
    /// The camera.
    pub camera: Camera,
}

/// Camera frame: right, up and forward (the viewing direction) unit vectors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraFrame {
    /// +x of the image, world space.
    pub right: Vec3,
    /// +y of the image (up), world space.
    pub up: Vec3,
    /// The viewing direction, world space.
    pub forward: Vec3,
}

impl Camera {
    /// The orthonormal frame of this camera. Falls back to a stable up vector
    /// when `up` is parallel to the viewing direction.
    pub fn frame(&self) -> CameraFrame {
        let forward = (self.look_at - self.eye)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        let mut right = forward.cross(self.up).try_normalize();
        if right.is_none() {
            let alt = if forward.y.abs() < 0.9 {
                Vec3::Y
            } else {
                Vec3::X
            };
            right = forward.cross(alt).try_normalize();
        }
        let right = right.unwrap_or(Vec3::X);
        let up = right.cross(forward);
        CameraFrame { right, up, forward }
    }

    /// `camera_from_world`: the right-handed view matrix (camera looks down -z).
    pub fn view_matrix(&self) -> Mat4 {
        let f = self.frame();
        Mat4::from_cols(
            f.right.extend(0.0),
            f.up.extend(0.0),
            (-f.forward).extend(0.0),
            self.eye.extend(1.0),
        )
        .inverse()
    }

    /// The half-height of the orthographic film, `None` for a perspective
    /// camera.
    pub fn orthographic_half_height(&self) -> Option<f32> {
        match self.projection {
            Projection::Perspective => None,
            Projection::Orthographic { half_height } => Some(half_height),
        }
    }

    /// `clip_from_camera`: the right-handed projection mapping depth
    /// `near..far` to NDC z `0..1` (Direct3D/Vulkan convention), for an
    /// image of the given aspect ratio (width / height). Perspective: `w`
    /// is the view depth; orthographic: `w = 1` and NDC z is affine in the
    /// depth.
    pub fn projection_matrix(&self, aspect: f32) -> Mat4 {
        if let Some(hh) = self.orthographic_half_height() {
            // glam's `Mat4::orthographic_rh` (depth to [0, 1]) for the box
            // `[-hh aspect, hh aspect] x [-hh, hh] x [-far, -near]`.
            let r = 1.0 / (self.near - self.far);
            return Mat4::from_cols(
                glam::Vec4::new(1.0 / (hh * aspect), 0.0, 0.0, 0.0),
                glam::Vec4::new(0.0, 1.0 / hh, 0.0, 0.0),
                glam::Vec4::new(0.0, 0.0, r, 0.0),
                glam::Vec4::new(0.0, 0.0, r * self.near, 1.0),
            );
        }
        // Right-handed, depth to [0, 1]: the same matrix as glam's former
        // `Mat4::perspective_rh`, written out because glam 0.34 dropped it.
        let h = 1.0 / (self.fov_y_degrees.to_radians() * 0.5).tan();
        let r = self.far / (self.near - self.far);
        Mat4::from_cols(
            glam::Vec4::new(h / aspect, 0.0, 0.0, 0.0),
            glam::Vec4::new(0.0, h, 0.0, 0.0),
            glam::Vec4::new(0.0, 0.0, r, -1.0),
            glam::Vec4::new(0.0, 0.0, r * self.near, 0.0),
        )
    }

    /// The primary ray direction (unit, world space) through film position
    /// `(x, y)` in pixels, where `(0, 0)` is the top-left corner of the image
    /// and `(width, height)` the bottom-right one.
    pub fn ray_direction(&self, x: f32, y: f32, width: u32, height: u32) -> Vec3 {
        self.pixel_rays(width, height).direction(x, y)
    }

    /// The primary ray (origin, unit direction; world space) through film
    /// position `(x, y)` in pixels, as [`Camera::ray_direction`].
    pub fn ray(&self, x: f32, y: f32, width: u32, height: u32) -> Ray {
        self.pixel_rays(width, height).ray(x, y)
    }

    /// The direction from `p` towards the viewer, not normalised: `eye - p`
    /// (perspective) or minus the viewing direction (orthographic). Tells
    /// which side of a surface the camera sees.
    pub fn toward_viewer(&self, p: Vec3) -> Vec3 {
        match self.projection {
            Projection::Perspective => self.eye - p,
            Projection::Orthographic { .. } => -self.frame().forward,
        }
    }

    /// The primary rays of a `width x height` image: the frame and the film
    /// plane's scale computed once, for renderers that trace many rays.
    pub fn pixel_rays(&self, width: u32, height: u32) -> PixelRays {
        let (half_y, orthographic) = match self.projection {
            Projection::Perspective => ((self.fov_y_degrees.to_radians() * 0.5).tan(), false),
            Projection::Orthographic { half_height } => (half_height, true),
        };
        PixelRays {
            frame: self.frame(),
            eye: self.eye,
            half_y,
            orthographic,
            aspect: width as f32 / height as f32,
            width: width as f32,
            height: height as f32,
        }
    }
}

/// The primary ray directions of one camera and image size
/// ([`Camera::pixel_rays`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelRays {
    frame: CameraFrame,
    eye: Vec3,
    /// Half the film's height: at unit distance from the eye (perspective,
    /// `tan(fov / 2)`) or in scene units (orthographic).
    half_y: f32,
    orthographic: bool,
    aspect: f32,
    width: f32,
    height: f32,
}

impl PixelRays {
    /// The film point `(x, y)` (pixels) relative to its centre, along the
    /// frame's right and up vectors, in units of [`PixelRays::half_y`].
    #[inline]
    fn film(&self, x: f32, y: f32) -> Vec3 {
        let f = &self.frame;
        let ndc_x = (2.0 * x / self.width - 1.0) * self.half_y * self.aspect;
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.half_y;
        ndc_x * f.right + ndc_y * f.up
    }

    /// [`Camera::ray_direction`] through film position `(x, y)` in pixels.
    #[inline]
    pub fn direction(&self, x: f32, y: f32) -> Vec3 {
        if self.orthographic {
            return self.frame.forward;
        }
        let f = &self.frame;
        let ndc_x = (2.0 * x / self.width - 1.0) * self.half_y * self.aspect;
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.half_y;
        (f.forward + ndc_x * f.right + ndc_y * f.up).normalize()
    }

    /// The origin of the primary ray through film position `(x, y)`: the
    /// eye (perspective) or the film point (orthographic).
    #[inline]
    pub fn origin(&self, x: f32, y: f32) -> Vec3 {
        if self.orthographic {
            self.eye + self.film(x, y)
        } else {
            self.eye
        }
    }

    /// [`Camera::ray`]: the primary ray through film position `(x, y)`.
    #[inline]
    pub fn ray(&self, x: f32, y: f32) -> Ray {
        Ray::new(self.origin(x, y), self.direction(x, y))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_ray_looks_at_target() {
        let cam = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            look_at: Vec3::new(1.0, 2.0, -7.0),
            ..Default::default()
        };
        let d = cam.ray_direction(50.0, 40.0, 100, 80);
        assert!((d - Vec3::NEG_Z).length() < 1e-6);
    }

    #[test]
    fn ray_and_projection_agree() {
        let cam = Camera {
            eye: Vec3::new(0.3, -0.2, 4.0),
            look_at: Vec3::new(0.1, 0.5, 0.0),
            ..Default::default()
        };
        let (w, h) = (64u32, 48u32);
        let clip_from_world = cam.projection_matrix(w as f32 / h as f32) * cam.view_matrix();
        for &(x, y) in &[(3.5f32, 7.25f32), (60.0, 1.0), (32.0, 24.0)] {
            let p = cam.eye + cam.ray_direction(x, y, w, h) * 3.0;
            let c = clip_from_world * p.extend(1.0);
            let sx = (c.x / c.w * 0.5 + 0.5) * w as f32;
            let sy = (0.5 - c.y / c.w * 0.5) * h as f32;
            assert!(
                (sx - x).abs() < 1e-3 && (sy - y).abs() < 1e-3,
                "{sx},{sy} vs {x},{y}"
            );
        }
    }

    fn ortho() -> Camera {
        Camera {
            eye: Vec3::new(0.3, -0.2, 4.0),
            look_at: Vec3::new(0.1, 0.5, 0.0),
            projection: Projection::Orthographic { half_height: 1.5 },
            ..Default::default()
        }
    }

    #[test]
    fn orthographic_rays_are_parallel_from_the_film() {
        let cam = ortho();
        let (w, h) = (64u32, 48u32);
        let f = cam.frame();
        // Every ray has the viewing direction; the corners of the film lie
        // half_height above and half_height * aspect right of the eye.
        let r = cam.ray(64.0, 0.0, w, h);
        assert!((r.dir - f.forward).length() < 1e-6);
        let expect = cam.eye + f.right * (1.5 * 64.0 / 48.0) + f.up * 1.5;
        assert!((r.origin - expect).length() < 1e-5, "{:?}", r.origin);
        let c = cam.ray(32.0, 24.0, w, h);
        assert!((c.origin - cam.eye).length() < 1e-6);
        assert!((cam.toward_viewer(Vec3::splat(7.0)) + f.forward).length() < 1e-6);
    }

    #[test]
    fn orthographic_ray_and_projection_agree() {
        let cam = ortho();
        let (w, h) = (64u32, 48u32);
        let clip_from_world = cam.projection_matrix(w as f32 / h as f32) * cam.view_matrix();
        for &(x, y, t) in &[
            (3.5f32, 7.25f32, 0.5f32),
            (60.0, 1.0, 3.0),
            (32.0, 24.0, 9.0),
        ] {
            let r = cam.ray(x, y, w, h);
            let c = clip_from_world * (r.origin + r.dir * t).extend(1.0);
            assert!((c.w - 1.0).abs() < 1e-6);
            let sx = (c.x * 0.5 + 0.5) * w as f32;
            let sy = (0.5 - c.y * 0.5) * h as f32;
            assert!(
                (sx - x).abs() < 1e-3 && (sy - y).abs() < 1e-3,
                "{sx},{sy} vs {x},{y}"
            );
            // NDC depth: (t - near) / (far - near).
            let z = (t - cam.near) / (cam.far - cam.near);
            assert!((c.z - z).abs() < 1e-6, "{} vs {z}", c.z);
        }
    }
}
