//! The pinhole perspective camera.

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// A pinhole perspective camera given by eye, target, up and vertical field
/// of view. The aspect ratio comes from the image being rendered.
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

    /// `clip_from_camera`: right-handed perspective projection mapping
    /// depth `near..far` to NDC z `0..1` (Direct3D/Vulkan convention), for
    /// an image of the given aspect ratio (width / height).
    pub fn projection_matrix(&self, aspect: f32) -> Mat4 {
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

    /// The primary rays of a `width x height` image: the frame and the film
    /// plane's scale computed once, for renderers that trace many rays.
    pub fn pixel_rays(&self, width: u32, height: u32) -> PixelRays {
        PixelRays {
            frame: self.frame(),
            tan_half: (self.fov_y_degrees.to_radians() * 0.5).tan(),
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
    tan_half: f32,
    aspect: f32,
    width: f32,
    height: f32,
}

impl PixelRays {
    /// [`Camera::ray_direction`] through film position `(x, y)` in pixels.
    #[inline]
    pub fn direction(&self, x: f32, y: f32) -> Vec3 {
        let f = &self.frame;
        let ndc_x = (2.0 * x / self.width - 1.0) * self.tan_half * self.aspect;
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.tan_half;
        (f.forward + ndc_x * f.right + ndc_y * f.up).normalize()
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
}
