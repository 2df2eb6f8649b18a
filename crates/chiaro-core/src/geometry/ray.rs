//! Rays.

use glam::Vec3;

/// A ray `origin + t * dir` for `t` in `(t_min, t_max)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin, world space.
    pub origin: Vec3,
    /// Direction (not necessarily unit; hits report `t` in its units).
    pub dir: Vec3,
    /// Smallest accepted hit distance.
    pub t_min: f32,
    /// Largest accepted hit distance.
    pub t_max: f32,
}

impl Ray {
    /// A ray from `origin` along `dir` with `t` in `(0, inf)`.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    /// A segment ray from `origin` to (just before) `target`: `dir = target - origin`,
    /// `t` in `(0, 1 - eps)`.
    pub fn segment(origin: Vec3, target: Vec3) -> Self {
        Self {
            origin,
            dir: target - origin,
            t_min: 0.0,
            t_max: 1.0 - 1e-4,
        }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Offsets a surface point along its geometric normal `ng`, towards the side
/// of `dir`, by an amount that scales with the point's magnitude, so that a
/// ray leaving the surface does not hit it again (after pbrt-v4's
/// `OffsetRayOrigin`, with a conservative scale-relative error bound).
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let scale = p.abs().max_element().max(1.0);
    let eps = scale * 2e-5;
    let offset = if ng.dot(dir) >= 0.0 {
        ng * eps
    } else {
        -ng * eps
    };
    p + offset
}
