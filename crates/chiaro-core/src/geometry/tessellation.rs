//! How finely analytic primitives become triangles: a fixed count for
//! view-independent uses (radiosity's patches, stored solutions), or one
//! rule by the primitive's projected radius in pixels for the scan
//! converter, so that a sphere a pixel wide costs a few dozen triangles
//! and one filling the screen keeps a smooth silhouette.

use crate::scene::Camera;
use glam::Vec3;
use std::f32::consts::PI;

/// Segments around a primitive when the view is not known (and radiosity's,
/// whose solutions must not depend on the view).
pub const FIXED_SEGMENTS: u32 = 64;
/// The fewest segments around a projected primitive (one a pixel wide or
/// off screen): an octagon, still round at that size.
pub const MIN_SEGMENTS: u32 = 8;
/// The most segments around a projected primitive (its silhouette stays
/// within [`SILHOUETTE_ERROR_PX`] up to a radius of about 3,300 pixels).
pub const MAX_SEGMENTS: u32 = 256;
/// The largest distance, in pixels, between the true silhouette and the
/// polygon's (the sagitta of one segment).
pub const SILHOUETTE_ERROR_PX: f32 = 0.25;
/// The longest segment, in pixels, while the count stays within
/// [`FIXED_SEGMENTS`]: Gouraud lights vertices only, so a small sphere
/// keeps enough of them for its highlight.
pub const SEGMENT_PX: f32 = 2.0;

/// How analytic primitives are tessellated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tessellation {
    /// This many segments around every primitive.
    Fixed(u32),
    /// By each primitive's projected radius in this view
    /// ([`segments_for_radius_px`]).
    Projected(ProjectedView),
}

impl Tessellation {
    /// Segments around a sphere of `radius` (world units) centred at
    /// `center` (world space); at least 3.
    pub fn sphere_segments(&self, center: Vec3, radius: f32) -> u32 {
        match self {
            Self::Fixed(n) => (*n).max(3),
            Self::Projected(view) => segments_for_radius_px(view.radius_px(center, radius)),
        }
    }
}

/// What the projected size of a primitive depends on: the camera's
/// position and direction and its focal length in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedView {
    eye: Vec3,
    forward: Vec3,
    focal_px: f32,
    /// Orthographic cameras: pixels per scene unit, whatever the depth.
    ortho_px: Option<f32>,
}

impl ProjectedView {
    /// The view of `camera` on an image `height` pixels high.
    pub fn new(camera: &Camera, height: u32) -> Self {
        let tan_half = (camera.fov_y_degrees.to_radians() * 0.5).tan();
        Self {
            eye: camera.eye,
            forward: camera.frame().forward,
            focal_px: 0.5 * height as f32 / tan_half.max(1e-6),
            ortho_px: camera
                .orthographic_half_height()
                .map(|hh| 0.5 * height as f32 / hh.max(1e-30)),
        }
    }

    /// The projected radius, in pixels, of a sphere of `radius` at
    /// `center`: `f r / sqrt(z^2 - r^2)` for a sphere at depth `z` (exact
    /// on the axis, larger off it, so never too coarse); infinite for a
    /// sphere across the eye's plane, 0 for one behind the eye.
    pub fn radius_px(&self, center: Vec3, radius: f32) -> f32 {
        let z = (center - self.eye).dot(self.forward);
        let r = radius.abs();
        if let Some(px) = self.ortho_px {
            // Parallel projection: the size on screen ignores the depth.
            return if z < -r { 0.0 } else { px * r };
        }
        if z < -r {
            return 0.0;
        }
        let d2 = z * z - r * r;
        if z <= r || d2 <= 0.0 {
            return f32::INFINITY;
        }
        self.focal_px * r / d2.sqrt()
    }
}

/// Segments around a circle of `r_px` pixels: enough that each is at most
/// [`SEGMENT_PX`] long up to [`FIXED_SEGMENTS`] of them, and beyond that
/// enough that the silhouette strays at most [`SILHOUETTE_ERROR_PX`]
/// (the sagitta `r (1 - cos(pi / n))`), within [`MIN_SEGMENTS`] and
/// [`MAX_SEGMENTS`]; even, so that a sphere has half as many stacks.
pub fn segments_for_radius_px(r_px: f32) -> u32 {
    if r_px.is_nan() {
        return FIXED_SEGMENTS;
    }
    let by_edge = (2.0 * PI * r_px / SEGMENT_PX).min(FIXED_SEGMENTS as f32);
    let by_silhouette = if r_px > SILHOUETTE_ERROR_PX {
        PI / (1.0 - SILHOUETTE_ERROR_PX / r_px).acos()
    } else {
        0.0
    };
    let n = by_edge
        .max(by_silhouette)
        .ceil()
        .clamp(MIN_SEGMENTS as f32, MAX_SEGMENTS as f32) as u32;
    n + n % 2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_grow_with_the_projected_radius_within_the_bounds() {
        assert_eq!(segments_for_radius_px(0.0), MIN_SEGMENTS);
        assert_eq!(segments_for_radius_px(1.0), MIN_SEGMENTS);
        assert_eq!(segments_for_radius_px(5.0), 16);
        // Up to about 20 px the 2 px edge rule; then today's 64 until the
        // silhouette needs more.
        assert_eq!(segments_for_radius_px(30.0), FIXED_SEGMENTS);
        assert_eq!(segments_for_radius_px(150.0), FIXED_SEGMENTS);
        assert_eq!(segments_for_radius_px(f32::INFINITY), MAX_SEGMENTS);
        assert_eq!(segments_for_radius_px(f32::NAN), FIXED_SEGMENTS);
        let mut last = 0;
        for r in [0.5f32, 2.0, 8.0, 20.0, 100.0, 300.0, 1000.0, 5000.0] {
            let n = segments_for_radius_px(r);
            assert!(n >= last && n.is_multiple_of(2), "{r}: {n}");
            last = n;
            // Where the bounds allow, the silhouette's error holds.
            if n < MAX_SEGMENTS {
                let sagitta = r * (1.0 - (PI / n as f32).cos());
                assert!(sagitta <= SILHOUETTE_ERROR_PX * 1.01, "{r}: {sagitta}");
            }
        }
    }

    #[test]
    fn the_projected_radius_follows_distance_and_image_height() {
        let cam = Camera {
            eye: Vec3::ZERO,
            look_at: Vec3::NEG_Z,
            fov_y_degrees: 90.0,
            ..Camera::default()
        };
        let view = ProjectedView::new(&cam, 200);
        // f = 100 px; a unit sphere 10 away: 100 / sqrt(99) px.
        let r = view.radius_px(Vec3::new(0.0, 0.0, -10.0), 1.0);
        assert!((r - 100.0 / 99f32.sqrt()).abs() < 1e-3, "{r}");
        assert!(
            (ProjectedView::new(&cam, 400).radius_px(Vec3::new(0.0, 0.0, -10.0), 1.0) - 2.0 * r)
                .abs()
                < 1e-3
        );
        // Off the axis at the same depth it is never smaller.
        assert!(view.radius_px(Vec3::new(8.0, 0.0, -10.0), 1.0) >= r);
        assert_eq!(view.radius_px(Vec3::new(0.0, 0.0, 10.0), 1.0), 0.0);
        assert_eq!(
            view.radius_px(Vec3::new(0.0, 0.0, -0.5), 1.0),
            f32::INFINITY
        );
        let t = Tessellation::Projected(view);
        assert_eq!(
            t.sphere_segments(Vec3::new(0.0, 0.0, 10.0), 1.0),
            MIN_SEGMENTS
        );
        assert_eq!(Tessellation::Fixed(64).sphere_segments(Vec3::ZERO, 1.0), 64);
    }
}
