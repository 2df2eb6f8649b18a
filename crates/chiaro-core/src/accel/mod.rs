//! Ray acceleration: the [`Accelerator`] trait, the brute-force
//! [`list::ListAccel`] (the test oracle), and the BVH ([`bvh::Bvh`], with the
//! scene-level [`bvh::SceneBvh`]), whose large arrays live in
//! huge-page-advised memory ([`pages::HugeArray`]).

pub mod alpha;
pub mod bvh;
pub mod cull;
pub mod instanced;
pub mod list;
pub mod pages;

use crate::geometry::Ray;

/// A ray-primitive intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Primitive index in the [`crate::prepared::PreparedScene`] (triangles
    /// first, then analytic spheres).
    pub prim: u32,
    /// Barycentric coordinates of vertices 1 and 2 for triangles (vertex 0
    /// has `1 - u - v`); for spheres unused.
    pub u: f32,
    /// See `u`.
    pub v: f32,
}

/// Finds what a ray hits. Implementations must give the same answers.
pub trait Accelerator: Send + Sync {
    /// The closest hit with `t` in `(ray.t_min, ray.t_max)`.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;
    /// The closest hit the eye sees along a camera ray: [`Self::intersect`]
    /// without the backs of single-sided (`Sidedness::Culled`) materials
    /// ([`cull::Culled`]). Every other ray uses `intersect`.
    fn intersect_camera(&self, ray: &Ray) -> Option<Hit> {
        self.intersect(ray)
    }
    /// True if anything is hit with `t` in `(ray.t_min, ray.t_max)`.
    fn occluded(&self, ray: &Ray) -> bool;
    /// [`Self::intersect`] of each of `rays` into `hits` (of the same
    /// length). Accelerators may trace coherent rays (a tile of camera
    /// rays) together; the answers are `intersect`'s bit for bit.
    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        debug_assert_eq!(rays.len(), hits.len());
        for (r, h) in rays.iter().zip(hits) {
            *h = self.intersect(r);
        }
    }
    /// [`Self::intersect_camera`] of each of `rays` into `hits`, as
    /// [`Self::intersect_packet`].
    fn intersect_camera_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        debug_assert_eq!(rays.len(), hits.len());
        for (r, h) in rays.iter().zip(hits) {
            *h = self.intersect_camera(r);
        }
    }
    /// [`Self::occluded`] of each of `rays` into `occluded` (of the same
    /// length), as [`Self::intersect_packet`] (shadow rays towards one
    /// light).
    fn occluded_packet(&self, rays: &[Ray], occluded: &mut [bool]) {
        debug_assert_eq!(rays.len(), occluded.len());
        for (r, o) in rays.iter().zip(occluded) {
            *o = self.occluded(r);
        }
    }
    /// Calls `visit(hit)` for every intersection with `t` in
    /// `(ray.t_min, ray.t_max)`, in no particular order (a sphere crossed
    /// twice reports both roots), until `visit` returns true; returns true
    /// if it did. Shadow rays use it to skip objects that cast no shadow
    /// and to attenuate light through transparent surfaces.
    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool;
}

/// Watertight ray-triangle intersection (Woop, Benthin and Wald 2013),
/// returning `(t, u, v)` with `u`, `v` the barycentrics of `p1` and `p2`.
/// Rays through a shared edge hit exactly one of its two triangles (or
/// both, never neither).
#[inline]
pub fn intersect_triangle(
    ray: &Ray,
    p0: glam::Vec3,
    p1: glam::Vec3,
    p2: glam::Vec3,
) -> Option<(f32, f32, f32)> {
    WatertightRay::new(ray).intersect(p0, p1, p2)
}

/// The per-ray part of the watertight ray-triangle test (Woop, Benthin and
/// Wald 2013, "Watertight Ray/Triangle Intersection", JCGT 2(1)): the axis
/// permutation and shear, computed once per ray and reused for every
/// triangle it meets. [`intersect_triangle`] is `WatertightRay::new(ray)
/// .intersect(..)`, so both give bit-identical answers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatertightRay {
    /// Ray origin.
    pub origin: glam::Vec3,
    /// Accepted parameter range `(t_min, t_max)`.
    pub t_min: f32,
    /// See `t_min`.
    pub t_max: f32,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    /// Precomputes the shear of `ray` (any non-zero direction).
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        Self::with_inverse(ray, ray.dir.recip())
    }

    /// [`WatertightRay::new`] given `inv = ray.dir.recip()`, which the
    /// BVH's slab test computes anyway: the shear's `1 / d[kz]` is then
    /// read from it (the same division, so the same bits) rather than
    /// divided again. The permutation is taken from small tables and the
    /// components are indexed as arrays, so set-up is branch-free apart
    /// from the swap (a ray's set-up is a large part of its cost in a small
    /// scene, where it meets only a node or two).
    #[inline(always)]
    pub fn with_inverse(ray: &Ray, inv: glam::Vec3) -> Self {
        /// The axis after each axis, cyclically.
        const NEXT: [usize; 3] = [1, 2, 0];
        let d = ray.dir.to_array();
        // Permute so that z is the largest direction component.
        let kz = ray.dir.abs().max_position();
        let (mut kx, mut ky) = (NEXT[kz], NEXT[NEXT[kz]]);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = inv.to_array()[kz];
        Self {
            origin: ray.origin,
            t_min: ray.t_min,
            t_max: ray.t_max,
            kx,
            ky,
            kz,
            sx: d[kx] * sz,
            sy: d[ky] * sz,
            sz,
        }
    }

    /// Intersects the triangle `(p0, p1, p2)`: `(t, u, v)` with `t` in
    /// `(t_min, t_max)` and `u`, `v` the barycentrics of `p1` and `p2`.
    #[inline]
    pub fn intersect(
        &self,
        p0: glam::Vec3,
        p1: glam::Vec3,
        p2: glam::Vec3,
    ) -> Option<(f32, f32, f32)> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let (sx, sy, sz) = (self.sx, self.sy, self.sz);
        let a = p0 - self.origin;
        let b = p1 - self.origin;
        let c = p2 - self.origin;
        let ax = a[kx] - sx * a[kz];
        let ay = a[ky] - sy * a[kz];
        let bx = b[kx] - sx * b[kz];
        let by = b[ky] - sy * b[kz];
        let cx = c[kx] - sx * c[kz];
        let cy = c[ky] - sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Recompute in double precision on edges (the paper's fallback).
            let (cxd, cyd, bxd, byd, axd, ayd) = (
                cx as f64, cy as f64, bx as f64, by as f64, ax as f64, ay as f64,
            );
            u = (cxd * byd - cyd * bxd) as f32;
            v = (axd * cyd - ayd * cxd) as f32;
            w = (bxd * ayd - byd * axd) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = sz * a[kz];
        let bz = sz * b[kz];
        let cz = sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        if !(t > self.t_min && t < self.t_max) {
            return None;
        }
        // u weights p0, v weights p1, w weights p2.
        Some((t, v * inv, w * inv))
    }
}

/// Ray-sphere intersection, `(t)` of the nearest root in range.
#[inline]
pub fn intersect_sphere(ray: &Ray, center: glam::Vec3, radius: f32) -> Option<f32> {
    let oc = ray.origin - center;
    let a = ray.dir.length_squared();
    let half_b = oc.dot(ray.dir);
    let c = oc.length_squared() - radius * radius;
    // Numerically robust discriminant (Hearn/Baker via "Ray Tracing Gems" ch. 7).
    let l = oc - ray.dir * (half_b / a);
    let disc = radius * radius - l.length_squared();
    if disc < 0.0 {
        return None;
    }
    let sq = (a * disc).sqrt();
    let q = -half_b - sq.copysign(half_b);
    let (mut t0, mut t1) = (c / q, q / a);
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > ray.t_min && t0 < ray.t_max {
        Some(t0)
    } else if t1 > ray.t_min && t1 < ray.t_max {
        Some(t1)
    } else {
        None
    }
}

/// Both hits of a sphere in `(ray.t_min, ray.t_max)`, nearer first (the
/// second is `None` when the ray leaves the range inside the sphere).
pub(crate) fn sphere_roots(ray: &Ray, center: glam::Vec3, radius: f32) -> [Option<f32>; 2] {
    let Some(t0) = intersect_sphere(ray, center, radius) else {
        return [None, None];
    };
    let rest = Ray { t_min: t0, ..*ray };
    [Some(t0), intersect_sphere(&rest, center, radius)]
}

/// A random point of `ps`'s bounds grown by a fifth of their extent on
/// every side (a ray origin in the tests' random ray sets).
#[cfg(test)]
pub(crate) fn random_origin(
    ps: &crate::prepared::PreparedScene<'_>,
    rng: &mut crate::sampling::Rng,
) -> glam::Vec3 {
    use crate::sampling::uniform;
    let b = ps.bounds;
    let grow = b.extent() * 0.2;
    b.min - grow
        + (b.extent() + 2.0 * grow) * glam::Vec3::new(uniform(rng), uniform(rng), uniform(rng))
}

/// Asserts that rays leaving a surface of `ps` do not hit it again through
/// `accel` (rustracer's shape-test invariant): 20,000 rays from random
/// points of its triangles and, every `sphere_every`-th, of its analytic
/// sphere `(centre, radius)` (the primitive after the triangles), in
/// directions on both sides down to grazing angles (1e-3 rad), their
/// origins offset by `offset_ray_origin`. Only a sphere may be re-entered,
/// and then far away.
#[cfg(test)]
pub(crate) fn assert_rays_leave_surfaces(
    ps: &crate::prepared::PreparedScene<'_>,
    accel: &dyn Accelerator,
    (centre, radius): (glam::Vec3, f32),
    sphere_every: u32,
) {
    use crate::sampling::{pixel_rng, sample_uniform_sphere, sample_uniform_triangle};
    use crate::sampling::{uniform, uniform2};
    use glam::Vec3;
    let nt = ps.triangles.len() as u32;
    let mut rng = pixel_rng(5, 0, 0, 0);
    for i in 0..20_000u32 {
        let (prim, p, ng) = if i % sphere_every == 0 {
            let d = sample_uniform_sphere(uniform2(&mut rng));
            (nt, centre + radius * d, d)
        } else {
            let t = (uniform(&mut rng) * nt as f32) as u32 % nt;
            let uv = sample_uniform_triangle(uniform2(&mut rng));
            let sh = ps.triangle_surface(t, uv.x, uv.y);
            (t, sh.p, sh.ng)
        };
        // Directions on both sides, down to grazing angles (1e-3 rad).
        let f = crate::geometry::Frame::from_normal(ng);
        let side = if i % 2 == 0 { 1.0 } else { -1.0 };
        let graze = if i % 3 == 0 { 1e-3 } else { uniform(&mut rng) };
        let phi = std::f32::consts::TAU * uniform(&mut rng);
        let cos_t = graze.max(1e-3);
        let sin_t = (1.0 - cos_t * cos_t).sqrt();
        let dir = f.to_world(Vec3::new(
            sin_t * phi.cos(),
            sin_t * phi.sin(),
            side * cos_t,
        ));
        let ray = Ray::new(crate::geometry::offset_ray_origin(p, ng, dir), dir);
        if let Some(h) = accel.intersect(&ray).filter(|h| h.prim == prim) {
            // Only a sphere can be re-entered, and then far away.
            assert!(
                prim >= nt && side < 0.0 && h.t > 1e-2,
                "self-hit {h:?} at {i}"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn triangle_hit_and_barycentrics() {
        let r = Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::NEG_Z);
        let (t, u, v) = intersect_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).expect("hit");
        assert!((t - 1.0).abs() < 1e-6 && (u - 0.25).abs() < 1e-6 && (v - 0.25).abs() < 1e-6);
        let miss = Ray::new(Vec3::new(0.75, 0.75, 1.0), Vec3::NEG_Z);
        assert!(intersect_triangle(&miss, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
    }

    #[test]
    fn shared_edge_is_watertight() {
        // Two triangles sharing the diagonal of the unit square: a ray
        // exactly through the diagonal hits at least one.
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
        for i in 0..=100 {
            let s = i as f32 / 100.0;
            let r = Ray::new(Vec3::new(s, s, 1.0), Vec3::new(0.0, 0.0, -1.0));
            let h = intersect_triangle(&r, a, b, c).is_some()
                || intersect_triangle(&r, a, c, d).is_some();
            assert!(h, "slipped through at {s}");
        }
    }

    #[test]
    fn sphere_roots() {
        let r = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
        assert!((intersect_sphere(&r, Vec3::ZERO, 1.0).expect("hit") - 4.0).abs() < 1e-5);
        let inside = Ray::new(Vec3::ZERO, Vec3::X);
        assert!((intersect_sphere(&inside, Vec3::ZERO, 2.0).expect("hit") - 2.0).abs() < 1e-5);
    }
}
