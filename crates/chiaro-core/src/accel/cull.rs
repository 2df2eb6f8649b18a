//! Single-sided culling for the ray techniques: [`Culled`] wraps an
//! [`Accelerator`] so that [`Accelerator::intersect_camera`] skips hits on
//! the back of `Sidedness::Culled` materials (glTF `doubleSided: false`),
//! as the scan converter culls them. Only camera rays are culled; reflected,
//! refracted, shadow and path-continuation rays see both sides
//! (ARCHITECTURE.md, "Single-sided culling").
//!
//! A culled hit is skipped by re-tracing from its distance with the same
//! origin and direction (`t_min = hit.t`), as [`super::alpha::AlphaTested`]
//! skips cut-out texels, so what lies behind is met with bit-identical
//! distances. Scenes without a culled material never build the wrapper.

use super::{Accelerator, Hit};
use crate::geometry::Ray;
use crate::prepared::PreparedScene;
use glam::Vec3;

/// An accelerator whose camera rays pass through the backs of single-sided
/// materials (see the module documentation).
pub struct Culled {
    inner: Box<dyn Accelerator>,
    /// Per triangle: its face normal when its material culls, else zero.
    tri_normal: Vec<Vec3>,
    /// Per analytic sphere: its centre when its material culls.
    sphere_center: Vec<Option<Vec3>>,
}

impl std::fmt::Debug for Culled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Culled")
            .field(
                "culled_triangles",
                &self.tri_normal.iter().filter(|n| **n != Vec3::ZERO).count(),
            )
            .finish_non_exhaustive()
    }
}

impl Culled {
    /// `inner` (built over `ps`) with the culling of `ps`; `inner` itself
    /// when no material of `ps` culls.
    pub fn wrap(ps: &PreparedScene<'_>, inner: Box<dyn Accelerator>) -> Box<dyn Accelerator> {
        let culls = |m: crate::scene::MaterialId| {
            ps.scene
                .materials
                .get(m.index())
                .is_some_and(|m| !m.sidedness.eye_sees_back())
        };
        if ps
            .scene
            .materials
            .iter()
            .all(|m| m.sidedness.eye_sees_back())
        {
            return inner;
        }
        let tri_normal = (0..ps.triangles.len())
            .map(|t| {
                if culls(ps.tri_material[t]) {
                    ps.face_normal(t as u32)
                } else {
                    Vec3::ZERO
                }
            })
            .collect();
        let sphere_center = ps
            .spheres
            .iter()
            .map(|s| culls(s.material).then_some(s.center))
            .collect();
        Box::new(Self {
            inner,
            tri_normal,
            sphere_center,
        })
    }

    /// `first` (the inner accelerator's hit of `ray`), or when it is culled
    /// the first hit beyond it that is not.
    fn past_culled(&self, ray: &Ray, first: Option<Hit>) -> Option<Hit> {
        let mut r = *ray;
        let mut hit = first?;
        while self.is_culled(ray, &hit) {
            // Continue past the back face along the same ray.
            r.t_min = hit.t;
            hit = self.inner.intersect(&r)?;
        }
        Some(hit)
    }

    /// True when `hit` is on the back of a culling material: the ray leaves
    /// the surface's front half-space (`ng . dir > 0`).
    fn is_culled(&self, ray: &Ray, hit: &Hit) -> bool {
        let i = hit.prim as usize;
        let nt = self.tri_normal.len();
        if i < nt {
            self.tri_normal[i].dot(ray.dir) > 0.0
        } else {
            self.sphere_center
                .get(i - nt)
                .copied()
                .flatten()
                .is_some_and(|c| (ray.at(hit.t) - c).dot(ray.dir) > 0.0)
        }
    }
}

impl Accelerator for Culled {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.inner.intersect(ray)
    }

    fn intersect_camera(&self, ray: &Ray) -> Option<Hit> {
        self.past_culled(ray, self.inner.intersect(ray))
    }

    fn intersect_camera_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.inner.intersect_packet(rays, hits);
        for (ray, hit) in rays.iter().zip(hits) {
            *hit = self.past_culled(ray, *hit);
        }
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.inner.occluded(ray)
    }

    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.inner.intersect_packet(rays, hits);
    }

    fn occluded_packet(&self, rays: &[Ray], occluded: &mut [bool]) {
        self.inner.occluded_packet(rays, occluded);
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        self.inner.for_each_hit(ray, visit)
    }
}
