//! Step 1: the viewing transformation of the scene's vertices to homogeneous
//! clip space and snapped screen positions, and the eye rays of the samples.

use crate::clip::outcode;
use crate::raster::{DepthKey, Viewport};
use chiaro_core::prepared::PreparedScene;
use glam::Mat4;
use rayon::prelude::*;

use crate::pipeline::exact;
use chiaro_core::scene::Camera;
use glam::{Vec3, Vec3A};

/// A vertex of the scene on the screen, when it is inside the clip volume
/// (16 bytes: the vertex pass writes and setup reads half a million).
pub(crate) struct ScreenVertex {
    /// Inside the near plane and the guard band: `xy` and `key` are valid.
    pub(crate) inside: bool,
    /// Snapped screen position (see [`Viewport::snap`]).
    pub(crate) xy: [i32; 2],
    /// Closeness key `1 / w`.
    pub(crate) key: f32,
}

/// Primary rays exactly as [`chiaro_core::scene::Camera::ray_direction`]
/// computes them, with the camera frame computed once.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rays {
    pub(crate) eye: Vec3,
    pub(crate) right: Vec3,
    pub(crate) up: Vec3,
    pub(crate) forward: Vec3,
    pub(crate) tan_half: f32,
    pub(crate) aspect: f32,
    pub(crate) width: f32,
    pub(crate) height: f32,
    /// An orthographic camera's film half-height (scene units): its rays
    /// start on the film and all run along `forward` (`tan_half` is then 0).
    pub(crate) ortho: Option<f32>,
}

impl Rays {
    pub(crate) fn new(cam: &Camera, width: u32, height: u32) -> Self {
        let f = cam.frame();
        let ortho = cam.orthographic_half_height();
        Self {
            eye: cam.eye,
            right: f.right,
            up: f.up,
            forward: f.forward,
            tan_half: match ortho {
                None => (cam.fov_y_degrees.to_radians() * 0.5).tan(),
                Some(_) => 0.0,
            },
            aspect: width as f32 / height as f32,
            width: width as f32,
            height: height as f32,
            ortho,
        }
    }

    /// The origin of the eye ray through film position `(x, y)`: the eye,
    /// or the film point of an orthographic camera (as
    /// [`chiaro_core::scene::PixelRays::origin`]).
    #[inline]
    pub(crate) fn origin(&self, x: f32, y: f32) -> Vec3A {
        match self.ortho {
            None => self.eye.into(),
            Some(hh) => {
                let ndc_x = (2.0 * x / self.width - 1.0) * hh * self.aspect;
                let ndc_y = (1.0 - 2.0 * y / self.height) * hh;
                (self.eye + ndc_x * self.right + ndc_y * self.up).into()
            }
        }
    }

    /// From `p` towards the viewer, not normalised: `eye - p`, or minus the
    /// viewing direction for an orthographic camera (which side of a
    /// surface the camera sees; the view direction `wo`).
    #[inline]
    pub(crate) fn toward_viewer(&self, p: Vec3A) -> Vec3A {
        match self.ortho {
            None => Vec3A::from(self.eye) - p,
            Some(_) => -Vec3A::from(self.forward),
        }
    }

    /// [`Rays::toward_viewer`] in `Vec3` arithmetic (`eye - p`, for the
    /// callers that computed it so).
    #[inline]
    pub(crate) fn toward_viewer3(&self, p: Vec3) -> Vec3 {
        match self.ortho {
            None => self.eye - p,
            Some(_) => -self.forward,
        }
    }

    /// The distance along the eye ray from its origin to the visible point
    /// `p` (the film's depth): `|p - eye|`, or the depth past the film
    /// plane for an orthographic camera.
    #[inline]
    pub(crate) fn distance(&self, p: Vec3A) -> f32 {
        let eye = Vec3A::from(self.eye);
        match self.ortho {
            None => (p - eye).length(),
            Some(_) => (p - eye).dot(self.forward.into()),
        }
    }

    /// Unit direction through film position `(x, y)` (pixels, top-left origin).
    #[inline]
    pub(crate) fn dir(&self, x: f32, y: f32) -> Vec3 {
        Self::dir_from(self.column(x), self.row(y)).into()
    }

    /// The part of the unnormalised direction through column `x` that does
    /// not depend on the row: `forward + ndc_x right`.
    #[inline]
    pub(crate) fn column(&self, x: f32) -> Vec3A {
        let ndc_x = (2.0 * x / self.width - 1.0) * self.tan_half * self.aspect;
        (self.forward + ndc_x * self.right).into()
    }

    /// The part that depends on the row `y` only: `ndc_y up`.
    #[inline]
    pub(crate) fn row(&self, y: f32) -> Vec3A {
        let ndc_y = (1.0 - 2.0 * y / self.height) * self.tan_half;
        (ndc_y * self.up).into()
    }

    /// [`Rays::dir`] from its [`Rays::column`] and [`Rays::row`] parts
    /// (computed once per tile column and row by the shading pass).
    #[inline]
    pub(crate) fn dir_from(column: Vec3A, row: Vec3A) -> Vec3A {
        exact::normalize(column + row)
    }
}

/// The viewport of a `w` x `h` image that culls back faces, and the one
/// that keeps them.
pub(crate) fn viewports(w: u32, h: u32, depth_key: DepthKey) -> (Viewport, Viewport) {
    let vp_cull = Viewport {
        width: w,
        height: h,
        cull_back: true,
        depth_key,
    };
    let vp_all = Viewport {
        cull_back: false,
        ..vp_cull
    };
    (vp_cull, vp_all)
}

/// Step 1: the scene's vertices to clip space; those inside the clip volume
/// are also snapped and keyed here, once, instead of once per triangle.
pub(crate) fn screen_vertices(
    ps: &PreparedScene<'_>,
    clip_from_world: Mat4,
    vp_all: &Viewport,
) -> Vec<ScreenVertex> {
    ps.positions
        .par_iter()
        .map(|p| {
            let clip = clip_from_world * p.extend(1.0);
            let inside = outcode(clip) == 0;
            ScreenVertex {
                inside,
                xy: if inside { vp_all.snap(clip) } else { [0; 2] },
                // The key `Viewport::setup` gives an unclipped vertex:
                // its barycentric (a unit vector) dotted with (1, 1, 1),
                // exactly 1, over w; or `-z / w`.
                key: match vp_all.depth_key {
                    DepthKey::InvW => 1.0 / clip.w,
                    DepthKey::ZOverW => -clip.z / clip.w,
                },
            }
        })
        .collect()
}
